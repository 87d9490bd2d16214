"""A GIF of one tilt: the chain's forces against the stability limits as alpha grows.

``python -m sliders.figures --animate [--scene FILE.toml]``.  Each frame is
the resting chain at one angle: the tangential force F_t of every slider
(against its number n) between the stability limit mu_s cos(alpha) and
its mirror, with the arrest limit (2 mu_d - mu_s) cos(alpha).  The sliders
that moved since the previous frame flash (large red markers); the last
frames show the avalanche.  Angles are evenly spaced from 0 to alpha_c.
"""

from __future__ import annotations

import math
import os

import numpy as np

from .style import COLUMN_WIDTH, STYLE
import matplotlib.pyplot as plt  # noqa: E402  (after figure_style chose the backend)
from matplotlib.animation import PillowWriter  # noqa: E402
from ..analysis.observables import valid_limit
from ..driver import run
from ..parts.checks import SceneError
from ..scene import Scene

ANIMATION_FRAMES = 72  # frames from alpha = 0 to alpha_c
FINAL_FRAMES = 10  # frames holding the avalanche
FRAMES_PER_SECOND = 12
GIF_DPI = 130  # 442 px wide: the GIF is for a screen


def animation_scene(path=None):
    """Scene A (N = 10, xi = 0, seed 1, the paper's parameters) or the scene of a TOML file.

    A scene that would record only a summary records displacements instead:
    the animation needs to know which sliders moved.
    """
    if path is None:
        return Scene(n_sliders=10, xi=0.0, seed=1, record="displacements")
    scene = Scene.from_toml(path)
    if not scene.loading.drive_is_angle:
        raise SceneError(f"{path}: loading={scene.loading.name!r}: the animation draws the forces "
                         "against the tilt's stability limits; the pushed chain has its own "
                         "figure (--only pushed_end)")
    return scene if scene.record != "summary" else scene.replace(record="displacements")


def moved_between(result, angles) -> np.ndarray:
    """(F, N) bool: slider n moved in an event with angles[f-1] < alpha_k <= angles[f]."""
    d = result.displacement
    a = np.asarray(result.alpha, dtype=float)
    frame_of_event = np.searchsorted(angles, a, side="left")  # first frame at or after alpha_k
    moved = np.zeros((len(angles), result.scene.n_sliders), dtype=bool)
    for k in range(d.n_events):
        f = frame_of_event[k]
        if f < len(angles):
            idx, _ = d.event(k)
            moved[f, idx] = True
    return moved


def animate_tilt(scene, out_dir="figures", name: str | None = None, backend: str = "fortran",
                 frames: int = ANIMATION_FRAMES, fps: int = FRAMES_PER_SECOND,
                 dpi: int = GIF_DPI) -> str:
    """Tilt ``scene`` to its end and write ``<out_dir>/<name>.gif``; returns the path."""
    result = run(scene, backend=backend)
    sc = result.scene
    n = sc.n_sliders
    end, _ = valid_limit(result)
    # the chain is at rest below alpha_c only: the last frame stops just short of it
    angles = np.linspace(0.0, end * (1.0 - 1e-9), frames)
    forces = result.force_at(angles)
    moved = moved_between(result, angles)
    avalanche = result.status == "avalanche"
    slider = np.arange(1, n + 1)
    big = n > 40
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_WIDTH, 2.6))
        lim = 1.1 * sc.mu_s_mean
        ax.set_xlim(0.5, n + 0.5)
        # forces stay within +-mu_s: the band below -1.1 mu_s holds the legend
        ax.set_ylim(-1.75 * lim, lim)
        ax.set_yticks([-0.5, -0.25, 0.0, 0.25, 0.5])
        ax.set_xlabel("slider $n$ (down the slope) [1]")
        ax.set_ylabel(r"$\tilde F_t$ [$mg$]")
        stab, = ax.plot([], [], "k--", lw=0.9, label=r"$\pm\bar\mu_s\cos\alpha$: stability")
        stab_low, = ax.plot([], [], "k--", lw=0.9)
        arrest, = ax.plot([], [], "k:", lw=0.9, label=r"$(2\mu_d-\bar\mu_s)\cos\alpha$: arrest")
        rest, = ax.plot([], [], "o" if not big else "-", color="tab:blue", ms=4 if not big else 0,
                        lw=0.6, label="at rest")
        flash, = ax.plot([], [], "o", color="tab:red", ms=6 if not big else 2.5, mew=0,
                         label="moved (flash)")
        ax.legend(loc="lower center", fontsize=7, frameon=False, ncol=2, columnspacing=0.8,
                  handlelength=1.5)
        title = ax.set_title("")
        edge = np.array([0.5, n + 0.5])

        def draw(f):
            hold = f >= frames
            g = min(f, frames - 1)
            a = angles[g]
            c = math.cos(a)
            stab.set_data(edge, [sc.mu_s_mean * c] * 2)
            stab_low.set_data(edge, [-sc.mu_s_mean * c] * 2)
            arrest.set_data(edge, [(2 * sc.mu_d - sc.mu_s_mean) * c] * 2)
            rest.set_data(slider, forces[g])
            m = np.ones(n, dtype=bool) if (hold and avalanche) else moved[g]
            flash.set_data(slider[m], forces[g][m])
            events = int(np.searchsorted(result.alpha, a, side="right"))
            # plain text (no mathtext): a title that changes every frame is laid out anew
            if hold:
                what = (f"avalanche at αc = {result.alpha_c:.3f} rad" if avalanche
                        else f"end: {result.status}")
                title.set_text(f"N = {n}, ξ = {sc.xi:g}: {what}")
            else:
                title.set_text(f"N = {n}, ξ = {sc.xi:g}: α = {a:.3f} rad, "
                               f"{events} rearrangements")

        # lay the figure out once, on the widest title, then freeze it: a
        # constrained layout redone on every frame costs most of the rendering
        draw(frames)
        fig.canvas.draw()
        fig.set_layout_engine("none")
        os.makedirs(out_dir, exist_ok=True)
        if name is None:
            name = "tilt_animation"
        path = os.path.join(os.fspath(out_dir), f"{name}.gif")
        writer = PillowWriter(fps=fps)
        # one draw per frame (FuncAnimation.save draws each frame twice)
        with writer.saving(fig, path, dpi):
            for f in range(frames + FINAL_FRAMES):
                draw(f)
                writer.grab_frame()
        plt.close(fig)
    return path
