"""Preparation of the chain at alpha = 0 (paper Sec. II-C-1, MODEL.md section 2).

Steps, and the choices made where the paper is silent:

1. Static coefficients mu_{s,n}: keyed Gaussian draws (stop count 0), redrawn
   until above mu_d.
2. Tangential forces f_n uniform in ]-mu_s_mean, mu_s_mean[.  *Own threshold*:
   a force with |f_n| >= mu_{s,n} would be unstable for its own slider, so it is
   redrawn (keyed rejection); the forces stay uniform on
   ]-a_n, a_n[ with a_n = min(mu_s_mean, mu_{s,n}).
3. *Zero sum* (free chain only): the internal forces of a free chain sum to
   zero, so the drawn forces must too.  The residual S = sum f is removed by
   moving every force towards the bound on the side that absorbs S, in
   proportion to its room to that bound: for S > 0,
   f_n -> f_n - S (f_n + a_n) / sum_m (f_m + a_m).  This keeps every force
   strictly inside its own stability range (the room used is a fraction
   S / (S + sum a) < 1 of each slider's room) and perturbs the flat
   distribution by O(1/sqrt(N)) in scale only.  For N = 1 it gives f = 0.
   Between walls no constraint applies: the walls take the net force.
4. Positions from forces: spring tensions are running sums of the forces
   (T_0 = 0 at the left end), positions running sums of the tensions.
5. With xi > 0: l* = (x_N - x_1)/(N - 1), the plate anchors are
   c_n = mean(x) + (n - (N+1)/2) l*, the coupling is switched on and the chain
   is relaxed at alpha = 0 with the dynamics (done by the driver, through the
   same event code as the tilt).
"""

from __future__ import annotations

import numpy as np

from . import keyed_random
from .chain import ChainState
from .scene import Scene

MAX_FORCE_ATTEMPTS = 1000


def draw_initial_forces(scene: Scene, mu_s: np.ndarray) -> np.ndarray:
    """Uniform forces in ]-mu_s_mean, mu_s_mean[, each stable for its own mu_s."""
    n = scene.n_sliders
    if scene.initial_forces == "zero":
        return np.zeros(n)
    sliders = np.arange(n)
    bound = np.minimum(mu_s, scene.mu_s_mean)
    forces = np.full(n, np.nan)
    pending = np.ones(n, dtype=bool)
    for attempt in range(MAX_FORCE_ATTEMPTS):
        idx = sliders[pending]
        u = keyed_random.uniform(scene.seed, idx, keyed_random.PREPARATION_STREAM, attempt)
        f = (2.0 * u - 1.0) * scene.mu_s_mean
        ok = np.abs(f) < bound[idx]
        forces[idx[ok]] = f[ok]
        pending[idx[ok]] = False
        if not pending.any():
            break
    else:  # pragma: no cover - needs mu_s far below mu_s_mean for 1000 draws
        raise RuntimeError("preparation: could not draw stable initial forces")
    if not scene.walls:
        forces = remove_net_force(forces, bound)
    return forces


def remove_net_force(forces: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """Make the forces sum to zero, staying inside ]-bound, bound[ (see module doc)."""
    total = forces.sum()
    if total > 0.0:
        room = forces + bound
        return forces - total * room / room.sum()
    if total < 0.0:
        room = bound - forces
        return forces - total * room / room.sum()
    return forces.copy()


def prepare(scene: Scene) -> ChainState:
    """The prepared chain at alpha = 0, before any coupling relaxation."""
    n = scene.n_sliders
    sliders = np.arange(n)
    mu_s = keyed_random.static_coefficient(
        scene.seed, sliders, 0, scene.mu_s_mean, scene.sigma_mu, scene.mu_d
    )
    forces = draw_initial_forces(scene, mu_s)

    # Spring k joins slider k-1 and k; F_n = T_{n+1} - T_n with T_0 = 0 (left
    # wall spring at rest; absent for a free chain) so T_{n+1} = sum_{j<=n} f_j.
    extension = np.zeros(n + 1)
    extension[1:] = np.cumsum(forces)
    if not scene.walls:
        extension[-1] = 0.0  # free end: no spring (the forces sum to zero)
    u0 = np.zeros(n)
    u0[1:] = np.cumsum(extension[1:n])

    stretch = np.zeros(n)
    e0 = forces.copy()
    if scene.xi > 0.0 and n > 1:
        spacing_excess = (u0[-1] - u0[0]) / (n - 1)  # l* - l
        anchors = (sliders - (n - 1) / 2.0) * spacing_excess
        stretch = u0 - u0.mean() - anchors
        e0 = forces - scene.xi * stretch
    lattice = sliders * scene.spring_length + u0
    return ChainState(
        elastic_force0=e0,
        spring_extension0=extension,
        cantilever_stretch0=stretch,
        lattice_position0=lattice,
        mu_s=mu_s,
    )
