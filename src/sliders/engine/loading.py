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

from ..chain import elastic_force, tangential_force

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
    def tangential(elastic: np.ndarray, weight: float, drive: float, du: np.ndarray):
        """Tangential force on every slider: elastic force plus the weight."""
        return elastic + weight

    @staticmethod
    def weight(alpha: float) -> float:
        """Tangential force the drive adds to every slider (sin alpha)."""
        return math.sin(alpha)

    @staticmethod
    def normal(alpha: float) -> float:
        """Normal load that scales friction (cos alpha)."""
        return math.cos(alpha)

    def forces(self, state, drives, displacement=None) -> np.ndarray:
        """F_t of every slider at rest at each drive (the paper's E + sin alpha);
        broadcasts over drives and (G, N) displacements, for analysis."""
        return tangential_force(state, self.scene.xi, self.scene.walls, drives, displacement)

    def next_instability(self, elastic: np.ndarray, mu: np.ndarray, alpha: float, du=None):
        """The next critical tilt in closed form (module function ``next_instability``)."""
        return next_instability(elastic, mu, alpha)

    def beyond_limit(self, alpha: float) -> bool:
        """The drive went past the scene's end of loading (alpha_max)."""
        return alpha > self.scene.alpha_max

    @staticmethod
    def work(weight: float, step: np.ndarray, drive: float, du_start: np.ndarray) -> float:
        """Work of gravity on the event's displacements."""
        return weight * float(step.sum())

    @staticmethod
    def spanning_ends_run() -> bool:
        """The tilt runs on after system-spanning events (the avalanche ends it)."""
        return False

    def runaway(self, moving: np.ndarray, direction: np.ndarray, weight: float,
                kinetic: float) -> bool:
        """The paper's avalanche: a free chain all sliding down with the weight
        beating kinetic friction, so that the centre of mass accelerates."""
        return (not self.scene.walls and moving.all() and np.all(direction > 0.0)
                and weight > kinetic)


class PushedEndLoading:
    """The Burridge-Knopoff loading: lambda = D, the position of a driver tied
    by a spring of stiffness K (``drive_stiffness``, units of k) to slider 1.

    The incline's tilt is fixed (``scene.tilt``): every slider feels sin(tilt)
    and presses with cos(tilt).  Slider 1 (index 0) also feels K (D - du_1),
    which changes during an event as it moves (the driver stands still).
    Only slider 1's force depends on D, so the next instability is its
    threshold crossing, D = du_1 + (mu_1 cos(tilt) - E_1 - sin(tilt)) / K.
    The run ends after the first event in which every slider moved: the
    system-spanning slip, the onset of sliding.
    """

    name = "pushed_end"

    def __init__(self, scene):
        self.scene = scene
        self.stiffness = scene.drive_stiffness

    def tangential(self, elastic: np.ndarray, weight: float, drive: float, du: np.ndarray):
        """Elastic force plus the weight, plus the driver's spring on slider 1."""
        force = elastic + weight
        force[0] += self.stiffness * (drive - du[0])
        return force

    def weight(self, drive: float) -> float:
        """Tangential component of the weight at the fixed tilt."""
        return math.sin(self.scene.tilt)

    def normal(self, drive: float) -> float:
        """Normal load at the fixed tilt."""
        return math.cos(self.scene.tilt)

    def forces(self, state, drives, displacement=None) -> np.ndarray:
        """F_t of every slider at rest at each driver position (``tangential``
        in the same order); broadcasts over drives and (G, N) displacements."""
        sc = self.scene
        drives = np.asarray(drives, dtype=float)
        du = state.displacement if displacement is None else np.asarray(displacement, dtype=float)
        force = elastic_force(state, sc.xi, sc.walls, du) + math.sin(sc.tilt)
        force = np.array(np.broadcast_to(force, np.broadcast_shapes(force.shape,
                                                                    drives.shape + (1,))))
        force[..., 0] += self.stiffness * (drives - du[..., 0])
        return force

    def driver_force(self, drive: float, du: np.ndarray) -> float:
        """Force of the driver's spring on slider 1."""
        return self.stiffness * (drive - du[0])

    def next_instability(self, elastic: np.ndarray, mu: np.ndarray, drive: float, du: np.ndarray):
        """The drive at which slider 1 starts downwards (every other slider is
        stable and does not feel D): its force E_1 + sin + K (D - du_1)
        reaches mu_1 cos + force_tol."""
        sc = self.scene
        threshold = mu[0] * math.cos(sc.tilt) + sc.force_tol
        critical = du[0] + (threshold - elastic[0] - math.sin(sc.tilt)) / self.stiffness
        return max(critical, drive), np.array([0]), np.array([1.0])

    def beyond_limit(self, drive: float) -> bool:
        """The driver went past its limit (drive_max)."""
        return drive > self.scene.drive_max

    def work(self, weight: float, step: np.ndarray, drive: float, du_start: np.ndarray) -> float:
        """Work of gravity plus the work of the driver's spring on slider 1 as
        it moves by s = step_1 against a fixed driver: K (D - du_1) s - K s^2/2."""
        s = float(step[0])
        return weight * float(step.sum()) + self.stiffness * ((drive - du_start[0]) * s - 0.5 * s * s)

    def runaway(self, moving, direction, weight, kinetic) -> bool:
        """Never during an event: the tilt is below the avalanche angle, so every
        slip stops; the run ends after a system-spanning slip instead."""
        return False

    @staticmethod
    def spanning_ends_run() -> bool:
        """The first event in which every slider moved is the onset of sliding."""
        return True


LOADINGS = {"tilt": TiltLoading, "pushed_end": PushedEndLoading}


def loading_for(scene):
    """The loading protocol of a scene."""
    return LOADINGS[scene.loading](scene)
