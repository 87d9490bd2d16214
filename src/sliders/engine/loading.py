"""Loading protocols: how the drive parameter lambda enters the chain.

A loading owns everything the event integrator must know about the drive:

* the tangential force it adds to every slider's elastic force (``weight``)
  and the normal load that scales friction (``normal``), both functions of
  lambda only, fixed during an event (quasi-static driving);
* the closed-form next critical lambda at which a resting slider destabilises
  (``next_instability``), with the sliders that start there and their
  directions;
* the work it does on the sliders in an event (``work``) and the run's end by
  runaway (``runaway``).

The Fortran twin is ``fortran/sliders_loading.f90``; both must round alike
(bit-identical events).
"""

from __future__ import annotations

import math

import numpy as np

TIE_TOL = 1e-12  # sliders whose instability angles tie within this start together
# The transcendentals of next_instability: NumPy's; a caller may put the C
# library's here (as keyed_random.TRANSCENDENTALS).
TRANSCENDENTALS = {"asin": np.arcsin, "atan": np.arctan, "hypot": np.hypot}


def next_instability(elastic: np.ndarray, mu: np.ndarray, alpha: float):
    """Smallest angle >= alpha at which some resting slider destabilises.

    Downwards: E + sin a = mu cos a, i.e. R sin(a - phi) = -E with
    R = sqrt(1 + mu^2), phi = atan(mu); on [0, pi/2] the left side only grows,
    so the root phi + asin(-E/R) is the one, if E >= -1 (else it lies beyond
    pi/2).  Upwards: E + sin a = -mu cos a, R sin(a + phi) = -E; the left side
    falls only beyond pi/2 - phi, so the root is pi - phi - asin(-E/R), which
    lies in [0, pi/2] only if E <= -1.
    Returns (angle, trigger indices, directions +1 down / -1 up).
    """
    math_fn = TRANSCENDENTALS
    radius = math_fn["hypot"](1.0, mu)
    phi = math_fn["atan"](mu)
    ratio = -elastic / radius
    inside = np.abs(ratio) <= 1.0
    s = math_fn["asin"](np.where(inside, ratio, 0.0))
    down = np.where(inside & (elastic >= -1.0), phi + s, np.inf)
    up = np.where(inside & (elastic <= -1.0), np.pi - phi - s, np.inf)
    root = np.maximum(np.minimum(down, up), alpha)
    angle = float(root.min())
    triggers = np.flatnonzero(root <= angle + TIE_TOL)
    directions = np.where(down[triggers] <= up[triggers], 1.0, -1.0)
    return angle, triggers, directions


class TiltLoading:
    """The paper's loading: lambda = alpha, the incline's tilt.

    Every slider feels its weight's component sin(alpha) along the incline
    and presses with cos(alpha) on it (units of m g).
    """

    name = "tilt"

    def __init__(self, scene):
        self.scene = scene

    @staticmethod
    def weight(alpha: float) -> float:
        """Tangential force the drive adds to every slider (sin alpha)."""
        return math.sin(alpha)

    @staticmethod
    def normal(alpha: float) -> float:
        """Normal load that scales friction (cos alpha)."""
        return math.cos(alpha)

    def next_instability(self, elastic: np.ndarray, mu: np.ndarray, alpha: float):
        """The next critical tilt in closed form (module function ``next_instability``)."""
        return next_instability(elastic, mu, alpha)

    def beyond_limit(self, alpha: float) -> bool:
        """The drive went past the scene's end of loading (alpha_max)."""
        return alpha > self.scene.alpha_max

    @staticmethod
    def work(weight: float, step: np.ndarray) -> float:
        """Work of gravity on the event's displacements."""
        return weight * float(step.sum())

    def runaway(self, moving: np.ndarray, direction: np.ndarray, weight: float,
                kinetic: float) -> bool:
        """The paper's avalanche: a free chain all sliding down with the weight
        beating kinetic friction, so that the centre of mass accelerates."""
        return (not self.scene.walls and moving.all() and np.all(direction > 0.0)
                and weight > kinetic)


def loading_for(scene):
    """The loading protocol of a scene."""
    return TiltLoading(scene)
