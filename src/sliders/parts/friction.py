"""Friction laws: static threshold, kinetic force and what is drawn at a stop.

A friction law is a part of the scene (``Scene(friction=Coulomb(...))``,
``parts.part.Part``): it owns its parameters, their checks and their
packing for the kernel, and takes what else it needs as arguments.

The event integrator asks the friction law three things, each at event level
(the per-step loop only uses the numbers they return):

* ``static_threshold(mu_s, normal, force_tol)``: the tangential force a
  resting slider withstands (plus the scene's ``force_tol``, so that a slider
  exactly at threshold stays put);
* ``kinetic_force(normal)``: the magnitude of the friction on a moving
  slider, which opposes its direction of motion;
* ``draw_at_stop(seed, sliders, n_stops)``: the new static coefficient of a
  slider that comes to rest (keyed by the scene's ``seed``).

Another part asks it one thing: ``max_stable_incline()``, the steepest fixed
incline on which every slip stops (the pushed end's bound).

The Fortran twin is ``fortran/sliders_friction.f90`` (bit-identical rounding).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import keyed_random
from .checks import SceneError, check_real
from .part import Part


class Friction(Part):
    """What every friction law provides (``Coulomb`` is the one): a part
    (``Part``) with the three answers the event integrator asks for, and the
    one a loading asks (``max_stable_incline``)."""

    fortran_twin = False  # the kernel has this law (fortran/sliders_friction.f90)

    def packed(self) -> dict:
        """The law's values in the kernel's packed parameters (refused without a Fortran twin)."""
        if not self.fortran_twin:
            raise SceneError(f"friction={self.name!r} has no Fortran twin: run it with "
                             "backend='numpy'")
        return self.flat()

    def static_threshold(self, mu_s, normal: float, force_tol: float):
        """abs(F) beyond which a resting slider starts (``force_tol`` added)."""
        raise NotImplementedError

    def kinetic_force(self, normal: float) -> float:
        """Friction on a moving slider (opposite to its motion)."""
        raise NotImplementedError

    def draw_at_stop(self, seed: int, sliders: np.ndarray, n_stops: np.ndarray) -> np.ndarray:
        """Static coefficients of ``sliders`` at their ``n_stops``-th stop (keyed by ``seed``)."""
        raise NotImplementedError

    def max_stable_incline(self) -> float:
        """The incline (radians) below which every slip stops: the kinetic friction
        beats the weight there."""
        raise NotImplementedError


@dataclass(frozen=True, repr=False)
class Coulomb(Friction):
    """Coulomb friction with a static coefficient redrawn at every stop.

    Threshold mu_s N, kinetic force ``mu_d`` N; at its k-th stop slider n draws
    mu_s(seed, n, k) from the keyed Gaussian (``mu_s_mean``, ``sigma_mu``)
    above ``mu_d`` (static friction above dynamic: mu_d < mu_s_mean).
    """

    mu_d: float = 0.55
    mu_s_mean: float = 0.6
    sigma_mu: float = 0.01

    name = "coulomb"
    fortran_twin = True
    flat_keys = {"mu_d": "mu_d", "mu_s_mean": "mu_s_mean", "sigma_mu": "sigma_mu"}

    def check_own(self) -> None:
        """mu_d >= 0, mu_s_mean > mu_d, sigma_mu >= 0, all finite."""
        check_real("mu_d", self.mu_d, 0.0, None)
        check_real("mu_s_mean", self.mu_s_mean, 0.0, None)
        if not self.mu_s_mean > self.mu_d:
            raise SceneError(
                f"mu_s_mean={self.mu_s_mean!r} must exceed mu_d={self.mu_d!r} "
                "(static friction above dynamic: mu_d < mu_s_mean)"
            )
        check_real("sigma_mu", self.sigma_mu, 0.0, None)

    @property
    def delta_mu(self) -> float:
        """Delta mu = mu_s_mean - mu_d, the paper's bin half-width."""
        return self.mu_s_mean - self.mu_d

    def static_threshold(self, mu_s, normal: float, force_tol: float):
        """abs(F) beyond which a resting slider starts (plus the scene's force_tol,
        so that a slider exactly at threshold stays put)."""
        return mu_s * normal + force_tol

    def kinetic_force(self, normal: float) -> float:
        """Friction on a moving slider (opposite to its motion)."""
        return self.mu_d * normal

    def draw_at_stop(self, seed: int, sliders: np.ndarray, n_stops: np.ndarray) -> np.ndarray:
        """Static coefficients of ``sliders`` at their ``n_stops``-th stop, keyed by
        ``seed`` (RuntimeError if the keyed draw fails)."""
        return keyed_random.static_coefficient(seed, sliders, n_stops, self.mu_s_mean,
                                               self.sigma_mu, self.mu_d)

    def max_stable_incline(self) -> float:
        """atan(mu_d): below it the kinetic friction mu_d cos beats the weight's sin."""
        return math.atan(self.mu_d)


# The friction laws a scene file can name (``friction = "..."``), by name.
FRICTIONS = {cls.name: cls for cls in (Coulomb,)}
