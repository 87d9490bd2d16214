"""Friction laws: static threshold, kinetic force and what is drawn at a stop.

The event integrator asks the friction law three things, each at event level
(the per-step loop only uses the numbers they return):

* ``static_threshold``: the tangential force a resting slider withstands
  (plus the scene's ``force_tol``, so that a slider exactly at threshold
  stays put);
* ``kinetic_force``: the magnitude of the friction on a moving slider, which
  opposes its direction of motion;
* ``draw_at_stop``: the new static coefficient of a slider that comes to rest.

The Fortran twin is ``fortran/sliders_friction.f90`` (bit-identical rounding).
"""

from __future__ import annotations

import numpy as np

from .. import keyed_random


class CoulombFriction:
    """Coulomb friction with a static coefficient redrawn at every stop.

    Threshold mu_s N, kinetic force mu_d N; at its k-th stop slider n draws
    mu_s(seed, n, k) from the keyed Gaussian (mu_s_mean, sigma_mu) above mu_d.
    """

    name = "coulomb"

    def __init__(self, scene):
        self.scene = scene

    def static_threshold(self, mu_s, normal: float):
        """abs(F) beyond which a resting slider starts."""
        return mu_s * normal + self.scene.force_tol

    def kinetic_force(self, normal: float) -> float:
        """Friction on a moving slider (opposite to its motion)."""
        return self.scene.mu_d * normal

    def draw_at_stop(self, sliders: np.ndarray, n_stops: np.ndarray) -> np.ndarray:
        """Static coefficients of ``sliders`` at their ``n_stops``-th stop
        (RuntimeError if the keyed draw fails)."""
        sc = self.scene
        return keyed_random.static_coefficient(sc.seed, sliders, n_stops, sc.mu_s_mean,
                                               sc.sigma_mu, sc.mu_d)


def friction_for(scene):
    """The friction law of a scene."""
    return CoulombFriction(scene)
