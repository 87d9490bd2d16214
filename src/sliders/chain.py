"""The chain of sliders: state, elastic forces and elastic energy.

Representation.  Slider ``n`` (0-based here) sits at

    x_n = n * l + u0_n + du_n

where ``u0`` is the prepared configuration and ``du`` the displacement since
preparation.  The dynamics never needs ``l`` or ``u0`` themselves, only

* ``elastic_force0``  E0_n: the elastic force (springs + cantilever) at du = 0,
* ``spring_extension0`` T0_k: extension beyond l of spring k at du = 0, where
  spring k joins slider k-1 and slider k (k = 0 and k = N are the springs to
  the walls; they are absent, and zero, for a free chain),
* ``cantilever_stretch0`` w0_n = u0_n - mean(u0) - c_n at du = 0, c_n being the
  plate anchor offsets (zero when xi = 0).

so the elastic force is

    E_n = E0_n + (du_{n+1} - du_n) - (du_n - du_{n-1}) - xi (du_n - mean(du))

(missing neighbours dropped at free ends; a wall does not move), and the
tangential force of the paper is F_n = E_n + sin(alpha).  Large offsets (l =
1e6, long chains) therefore cost no precision.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ChainState:
    """The chain at rest between events (mutated in place by the backends)."""

    elastic_force0: np.ndarray
    spring_extension0: np.ndarray
    cantilever_stretch0: np.ndarray
    lattice_position0: np.ndarray  # u0_n + n l: prepared positions (for output only)
    mu_s: np.ndarray
    displacement: np.ndarray = field(default=None)  # du, since preparation
    n_stops: np.ndarray = field(default=None)  # stops so far (key of the next draw)
    drive: float = 0.0  # the loading's variable: the tilt alpha (rad), or the driver position D

    def __post_init__(self) -> None:
        n = self.mu_s.size
        if self.displacement is None:
            self.displacement = np.zeros(n)
        if self.n_stops is None:
            self.n_stops = np.zeros(n, dtype=np.int64)

    @property
    def n_sliders(self) -> int:
        """Number of sliders N."""
        return self.mu_s.size

    def copy(self) -> "ChainState":
        """An independent copy (every array copied)."""
        return ChainState(
            self.elastic_force0.copy(), self.spring_extension0.copy(),
            self.cantilever_stretch0.copy(), self.lattice_position0.copy(),
            self.mu_s.copy(), self.displacement.copy(), self.n_stops.copy(), self.drive,
        )

    def positions(self, displacement: np.ndarray | None = None) -> np.ndarray:
        """Absolute positions x_n down the slope."""
        du = self.displacement if displacement is None else displacement
        return self.lattice_position0 + du


def laplacian(du: np.ndarray, walls: bool) -> np.ndarray:
    """Spring part of the elastic force change: (du_{n+1}-du_n) - (du_n-du_{n-1}).

    Works on the last axis, so a stack of configurations (K, N) is fine.
    """
    out = np.zeros(du.shape)
    step = du[..., 1:] - du[..., :-1]  # du_{n+1} - du_n, spring n+1 (np.diff, without its checks)
    out[..., :-1] += step
    out[..., 1:] -= step
    if walls:  # the walls do not move: spring to a wall changes by -du at the end
        out[..., 0] -= du[..., 0]
        out[..., -1] -= du[..., -1]
    return out


def elastic_force(state: ChainState, xi: float, walls: bool, displacement=None) -> np.ndarray:
    """Elastic force E_n (springs + cantilever) for du (default: the state's)."""
    du = state.displacement if displacement is None else displacement
    e = state.elastic_force0 + laplacian(du, walls)
    if xi != 0.0:  # the mean as np.mean computes it (sum, then divided), without its checks
        e = e - xi * (du - np.add.reduce(du, axis=-1, keepdims=True) / du.shape[-1])
    return e


def tangential_force(state: ChainState, xi: float, walls: bool, alpha, displacement=None):
    """The paper's F_t: springs + cantilever + sin(alpha); broadcasts over events."""
    alpha = np.asarray(alpha, dtype=float)
    e = elastic_force(state, xi, walls, displacement)
    return e + np.sin(alpha)[..., None] if alpha.ndim else e + np.sin(alpha)


def elastic_energy(state: ChainState, xi: float, walls: bool, displacement=None) -> float:
    """U = 1/2 sum T_k^2 + xi/2 sum w_n^2 (springs and cantilevers)."""
    du = state.displacement if displacement is None else displacement
    ext = state.spring_extension0.copy()
    ext[1:-1] += np.diff(du)
    if walls:
        ext[0] += du[0]
        ext[-1] -= du[-1]
    u = 0.5 * float(np.dot(ext, ext))
    if xi != 0.0:
        w = state.cantilever_stretch0 + du - du.mean()
        u += 0.5 * xi * float(np.dot(w, w))
    return u
