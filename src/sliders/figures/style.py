"""One print style for every figure: the paper's one-column width, fonts of 7-9 pt.

The paper is a two-column revtex article, so each figure is printed one
column wide (3.4 in, 8.6 cm).  Every figure of the package is drawn at that
size (a figure legible in print is legible on a screen too), with lines and
markers thick enough to survive printing, and written as a vector PDF and a
PNG of ``PNG_DPI`` dots per inch.
"""

from __future__ import annotations

import io
import os

import matplotlib

if os.environ.get("MPLBACKEND") is None:
    matplotlib.use("Agg")

COLUMN_WIDTH = 3.4  # inches: one column of a two-column revtex article
PNG_DPI = 300  # the least a print shop accepts for line art with text

# Sequential maps whose lightness falls monotonically, so that in greyscale
# "the darker the points, the larger the displacement" still holds.
DISPLACEMENT_CMAP = "inferno_r"
ORDER_CMAP = "viridis"  # slider number, angle: ordered quantities, greyscale-readable

STYLE = {
    "font.size": 8,
    "axes.labelsize": 8,
    "axes.titlesize": 7,
    "legend.fontsize": 7,
    "legend.handlelength": 1.8,
    "legend.borderaxespad": 0.3,
    "legend.labelspacing": 0.25,
    "xtick.labelsize": 7,
    "ytick.labelsize": 7,
    "axes.linewidth": 0.6,
    "xtick.major.width": 0.6,
    "ytick.major.width": 0.6,
    "xtick.major.size": 2.5,
    "ytick.major.size": 2.5,
    "xtick.minor.width": 0.4,
    "ytick.minor.width": 0.4,
    "lines.linewidth": 1.0,
    "lines.markersize": 3.0,
    "errorbar.capsize": 1.5,
    "figure.dpi": 100,
    "savefig.dpi": PNG_DPI,
    "savefig.pad_inches": 0.02,
    "pdf.fonttype": 42,  # TrueType in the PDF: text stays text
    "figure.constrained_layout.use": True,
    "figure.constrained_layout.h_pad": 0.02,
    "figure.constrained_layout.w_pad": 0.02,
}


def panel_label(ax, text: str) -> None:
    """(a), (b) ... in the upper left corner of a panel, as in the paper."""
    ax.text(0.015, 0.975, text, transform=ax.transAxes, va="top", ha="left",
            fontweight="bold", fontsize=8, zorder=10,
            bbox=dict(boxstyle="square,pad=0.1", facecolor="white", edgecolor="none", alpha=0.85))


def save_figure(fig, out_dir, name: str, formats=("png", "pdf"), dpi: int = PNG_DPI,
                palette_png: bool = False) -> list[str]:
    """Write ``name``.png (``dpi``) and ``name``.pdf (vector) in ``out_dir``; returns the paths.

    The figures are laid out at their final size, so no tight bounding box
    is taken: the saved width is exactly the figure's width.  ``palette_png``
    stores the PNG with a 256-colour palette (3-4 times smaller, for files
    kept in git; the eye does not see the difference on these figures).
    """
    if out_dir is None:
        return []
    os.makedirs(out_dir, exist_ok=True)
    paths = []
    for ext in formats:
        p = os.path.join(os.fspath(out_dir), f"{name}.{ext}")
        fig.savefig(p, dpi=dpi)
        if ext == "png" and palette_png:
            _to_palette(p, dpi)
        paths.append(p)
    return paths


def _to_palette(path: str, dpi: int) -> None:
    from PIL import Image

    with Image.open(path) as im:
        small = im.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT,
                                           dither=Image.Dither.NONE)
    small.save(path, optimize=True, dpi=(dpi, dpi))


def png_bytes(fig, dpi: int) -> bytes:
    """``fig`` as PNG bytes at ``dpi`` (drawn on an Agg canvas of its own, no pyplot state: safe
    in a thread), to be written whole by the caller (``io.safeio.publish_bytes``)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()
