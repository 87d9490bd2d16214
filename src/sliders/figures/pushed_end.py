"""The figure of the second loading protocol: the chain pushed at one end.

``fig_pushed_end`` draws, for one run of ``loading="pushed_end"``,

(a) the precursors: where each slip front arrested (the largest slider
    number that moved) against the driver's position D when it started, up
    to the system-spanning slip, the onset of sliding;
(b) the tangential force along the chain just before a few of the
    precursors that reached further than every earlier one (the first to
    pass 10, 30, 50, 70 and 90 % of the chain, and the onset of sliding),
    coloured by D, in the manner of the paper's force panels.

``python -m sliders.figures --only pushed_end`` draws it (the Fortran kernel
by default, about 5 s; ``--backend numpy`` gives the same events at xi = 0).
"""

from __future__ import annotations

import math

import numpy as np

from .style import COLUMN_WIDTH, ORDER_CMAP, STYLE, panel_label, save_figure
import matplotlib.pyplot as plt  # noqa: E402  (after figure_style chose the backend)
from matplotlib import colors as mcolors  # noqa: E402

from ..parts.loading import PushedEnd  # noqa: E402
from ..scene import Scene  # noqa: E402
from ..driver import run

NAME = "pushed_end"
# A chain long enough for fronts of many lengths (about 37 500 events to the
# onset of sliding, 5 s on the kernel; the NumPy reference would take hours).
FIGURE_SCENE = Scene(n_sliders=100, seed=2, loading="pushed_end", driver_stiffness=1.0,
                     mode="explore")


def pushed_end_run(scene: Scene = FIGURE_SCENE, backend: str = "fortran"):
    """The figure's run."""
    return run(scene, backend=backend)


def arrest_positions(result) -> np.ndarray:
    """Slider number (1-based) at which each event's front arrested: the
    largest one that moved (fronts start at the pushed slider 1)."""
    ptr, index = result.displacement.ptr, result.displacement.index
    return np.array([index[a:b].max() + 1 for a, b in zip(ptr[:-1], ptr[1:])], dtype=int)


def forces_before(result, events: np.ndarray) -> np.ndarray:
    """Tangential force on every slider just before each of ``events`` starts
    (at the drive it starts at), rebuilt from the recorded displacements."""
    before = np.vstack([result.initial.displacement[None, :], result.displacement_after()[:-1]])
    sc = result.scene
    return sc.loading.forces(result.initial, sc.xi, sc.walls, result.drive[events],
                             before[events])


def record_fronts(arrest: np.ndarray) -> np.ndarray:
    """Events whose front reached further than every earlier one."""
    best = np.maximum.accumulate(arrest)
    return np.flatnonzero(np.r_[True, arrest[1:] > best[:-1]])


def profile_events(arrest: np.ndarray, n_sliders: int,
                   fractions=(0.1, 0.3, 0.5, 0.7, 0.9, 1.0)) -> np.ndarray:
    """The first event whose front reached each fraction of the chain (each
    once, in order): a few profiles a reader can tell apart."""
    reach = np.maximum.accumulate(arrest)
    firsts = [int(np.argmax(reach >= f * n_sliders)) for f in fractions
              if reach[-1] >= f * n_sliders]
    return np.unique(firsts)


def fig_pushed_end(result, out_dir="figures", name: str = NAME):
    """The precursor lengths against the drive, and the force profiles before them."""
    sc = result.scene
    if not isinstance(sc.loading, PushedEnd):
        raise ValueError(f"fig_pushed_end needs a run of loading='pushed_end', not {sc.loading.name!r}")
    drive = result.drive
    arrest = arrest_positions(result)
    growing = record_fronts(arrest)
    shown = profile_events(arrest, sc.n_sliders)
    profiles = forces_before(result, shown)

    with plt.rc_context(STYLE):
        fig, (ax_a, ax_b) = plt.subplots(2, 1, figsize=(COLUMN_WIDTH, 4.2))
        ax_a.plot(drive, arrest, ".", ms=1.5, color="0.55", label="every slip")
        ax_a.plot(drive[growing], arrest[growing], "o", ms=2.5, mfc="none", color="C0",
                  label="farthest so far")
        if result.status == "sliding":
            ax_a.plot(drive[-1], arrest[-1], "*", ms=7, color="C3", label="onset of sliding", zorder=4)
        ax_a.set_xlabel(r"driver position $D$ [$g\tau^2$]")
        ax_a.set_ylabel("arrest position [slider]")
        ax_a.set_ylim(0, sc.n_sliders + 1)
        ax_a.legend(loc="upper left", bbox_to_anchor=(0.07, 1.0), fontsize="x-small",
                    frameon=True, framealpha=0.9, edgecolor="none")
        ax_a.set_title(f"N = {sc.n_sliders}, incline = {sc.incline:g}, K = {sc.driver_stiffness:g} k, "
                       f"{result.n_events} events")
        panel_label(ax_a, "(a)")

        norm = mcolors.Normalize(0.0, drive[shown].max())
        cmap = plt.get_cmap(ORDER_CMAP)
        position = np.arange(1, sc.n_sliders + 1)
        for row, k in enumerate(shown):
            ax_b.plot(position, profiles[row], lw=0.7, color=cmap(norm(drive[k])))
            ax_a.plot(drive[k], arrest[k], "o", ms=3.5, color=cmap(norm(drive[k])), zorder=3)
        levels = ((sc.mu_s_mean, r"$\bar\mu_s\cos(\mathrm{incline})$"),
                  (sc.mu_d, r"$\mu_d\cos(\mathrm{incline})$"))
        for (mu, label), above in zip(levels, (True, False)):  # mean threshold, kinetic
            level = mu * math.cos(sc.incline)
            ax_b.axhline(level, ls="--", lw=0.6, color="0.3")
            ax_b.annotate(label, (0.5, level), xycoords=("axes fraction", "data"),
                          xytext=(0, 2 if above else -2), textcoords="offset points",
                          ha="center", va="bottom" if above else "top", fontsize="x-small",
                          color="0.3", bbox=dict(fc="white", ec="none", pad=0.3, alpha=0.9))
        ax_b.set_ylim(top=sc.mu_s_mean * math.cos(sc.incline) + 0.15)
        ax_b.set_xlabel("slider $n$ (driver at $n = 1$) [1]")
        ax_b.set_ylabel(r"$F_t$ before the slip [$mg$]")
        fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax_b, label=r"$D$ [$g\tau^2$]")
        panel_label(ax_b, "(b)")
    save_figure(fig, out_dir, name)
    return fig
