"""Loadings: how the drive parameter lambda enters the chain.

A loading is a part of the scene (``Scene(loading=Tilt(...))`` or
``PushedEnd(...)``, ``parts.part.Part``): it owns its parameters,
their checks, their packing for the kernel, what it allows, and everything
the event integrator must know about the drive (what else it needs, the
chain's ``xi`` and ``walls`` or the scene's ``force_tol``, comes in as
arguments):

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

from dataclasses import dataclass

from ..chain import elastic_force, tangential_force
from .checks import SceneError, check_real
from .part import Part

# Between walls the rearrangement angles pile up towards pi/2 (Delta alpha is
# proportional to cos alpha: infinitely many events before pi/2), and the
# displacement per event, (mu_s - mu_d) cos alpha, sinks below rounding.
ALPHA_MAX_LIMIT = math.pi / 2 - 1e-6
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


class Loading(Part):
    """What every loading provides (``Tilt`` and ``PushedEnd`` are the two).

    Beyond a part's parameters, checks and packing (``Part``): the kernel's
    code of the protocol (``code``), what the drive is (``drive_is_angle``,
    ``drive_label``, ``drive_unit``) and the physics the
    event integrator asks for, each method below.  A loading that only the
    NumPy reference runs needs no ``code`` (tests/test_scene_parts.py adds one).
    """

    code: int | None = None
    drive_is_angle = False  # the drive is the incline's angle: the tilt's statistics apply
    drive_label = "drive lambda"  # the drive in words, as results print it
    drive_unit = ""

    def packed(self) -> dict:
        """Every loading slot of the kernel's parameters: the protocol's code, its
        own values, and the other loadings' slots at their defaults (unread)."""
        if self.code is None:
            raise SceneError(f"loading={self.name!r} has no Fortran twin: run it with "
                             "backend='numpy'")
        slots = {key: value for cls in LOADINGS.values() for key, value in cls.flat_defaults().items()}
        return {**slots, **self.flat(), "loading": self.code}

    def tangential(self, elastic: np.ndarray, weight: float, drive: float, du: np.ndarray):
        """Tangential force on every slider: elastic force plus the weight."""
        return elastic + weight

    def weight(self, drive: float) -> float:
        """Tangential force the drive adds to every slider."""
        raise NotImplementedError

    def normal(self, drive: float) -> float:
        """Normal load that scales friction."""
        raise NotImplementedError

    def forces(self, state, xi: float, walls: bool, drives, displacement=None) -> np.ndarray:
        """F_t of every slider at rest at each drive (``tangential`` in the same
        order) for a chain of cantilever stiffness ``xi``, between walls or not;
        broadcasts over drives and (G, N) displacements, for analysis."""
        raise NotImplementedError

    def incline_at(self, drives) -> np.ndarray:
        """The incline's angle (rad) at each drive: the drive itself for the tilt."""
        raise NotImplementedError

    def next_instability(self, elastic: np.ndarray, mu: np.ndarray, drive: float, du: np.ndarray,
                         force_tol: float):
        """The next critical drive >= ``drive``: (drive, trigger indices, directions)."""
        raise NotImplementedError

    def beyond_limit(self, drive: float) -> bool:
        """The drive went past the scene's end of loading."""
        raise NotImplementedError

    def work(self, weight: float, step: np.ndarray, drive: float, du_start: np.ndarray) -> float:
        """Work of the loading on the event's displacements (gravity's)."""
        return weight * float(step.sum())

    def spanning_ends_run(self) -> bool:
        """Whether the first event in which every slider moved ends the run."""
        return False

    def runaway(self, moving: np.ndarray, direction: np.ndarray, weight: float,
                kinetic: float, walls: bool) -> bool:
        """Whether the event has become a runaway that ends the run (the avalanche)."""
        return False


@dataclass(frozen=True, repr=False)
class Tilt(Loading):
    """The paper's loading: lambda = alpha, the incline's tilt, up to ``alpha_max``.

    Every slider feels its weight's component sin(alpha) along the incline
    and presses with cos(alpha) on it (units of m g).  ``alpha_max``
    (radians, at most pi/2 - 1e-6) ends the run (needed between walls, which
    never avalanche).
    """

    alpha_max: float = ALPHA_MAX_LIMIT

    name = "tilt"
    code = 0  # sliders_contract: loading_tilt
    flat_keys = {"alpha_max": "alpha_max"}
    drive_is_angle = True
    drive_label = "alpha"
    drive_unit = "rad"

    def check_own(self) -> None:
        """alpha_max in (0, pi/2 - 1e-6]."""
        check_real("alpha_max", self.alpha_max, 0.0, ALPHA_MAX_LIMIT, open_low=True,
                   why="pi/2 - 1e-6: towards pi/2 the rearrangements pile up without end "
                       "(Delta alpha ~ cos alpha) and cos alpha sinks below rounding")

    def incline_at(self, drives) -> np.ndarray:
        """The incline's angle at each drive: the drive, the tilt alpha itself."""
        return np.asarray(drives, dtype=float)

    def weight(self, alpha: float) -> float:
        """Tangential force the drive adds to every slider (sin alpha)."""
        return math.sin(alpha)

    def normal(self, alpha: float) -> float:
        """Normal load that scales friction (cos alpha)."""
        return math.cos(alpha)

    def forces(self, state, xi: float, walls: bool, drives, displacement=None) -> np.ndarray:
        """F_t of every slider at rest at each drive (the paper's E + sin alpha);
        broadcasts over drives and (G, N) displacements, for analysis."""
        return tangential_force(state, xi, walls, drives, displacement)

    def next_instability(self, elastic: np.ndarray, mu: np.ndarray, alpha: float, du=None,
                         force_tol: float = 0.0):
        """The next critical tilt in closed form (module function ``next_instability``;
        the closed form is exact, ``force_tol`` does not enter it)."""
        return next_instability(elastic, mu, alpha)

    def beyond_limit(self, alpha: float) -> bool:
        """The drive went past the scene's end of loading (alpha_max)."""
        return alpha > self.alpha_max

    def runaway(self, moving: np.ndarray, direction: np.ndarray, weight: float,
                kinetic: float, walls: bool) -> bool:
        """The paper's avalanche: a free chain all sliding down with the weight
        beating kinetic friction, so that the centre of mass accelerates."""
        return (not walls and moving.all() and np.all(direction > 0.0)
                and weight > kinetic)


@dataclass(frozen=True, repr=False)
class PushedEnd(Loading):
    """The Burridge-Knopoff loading: lambda = D, the position of a driver tied
    by a spring of stiffness K (``stiffness``, units of k) to slider 1.

    The incline is fixed at ``incline`` (radians, below atan(mu_d) so that
    every slip stops): every slider feels
    sin(incline) and presses with cos(incline).  Slider 1 (index 0) also
    feels K (D - du_1), which changes during an event as it moves (the
    driver stands still).  Only slider 1's force depends on D, so the next
    instability is its threshold crossing,
    D = du_1 + (mu_1 cos(incline) - E_1 - sin(incline)) / K.
    The run ends after the first event in which every slider moved (the
    system-spanning slip, the onset of sliding) or beyond ``drive_max``
    (g tau^2).  Flat scene keys: ``incline``, ``driver_stiffness``, ``drive_max``.
    """

    incline: float = 0.0
    stiffness: float = 1.0
    drive_max: float = 1e9

    name = "pushed_end"
    code = 1  # sliders_contract: loading_pushed_end
    flat_keys = {"incline": "incline", "driver_stiffness": "stiffness", "drive_max": "drive_max"}
    drive_label = "driver position D"
    drive_unit = "g tau^2"

    def check_own(self) -> None:
        """incline >= 0 (its upper bound, atan(mu_d), is the friction's: ``check``),
        stiffness > 0, drive_max > 0."""
        check_real("incline", self.incline, 0.0, None)
        check_real("driver_stiffness", self.stiffness, 0.0, None, open_low=True)
        check_real("drive_max", self.drive_max, 0.0, None, open_low=True)

    def check(self, scene) -> None:
        """The incline below the friction's ``max_stable_incline()`` (atan(mu_d) for
        Coulomb: every slip stops), and no record='forces'."""
        bound = scene.friction.max_stable_incline()
        check_real("incline", self.incline, 0.0, bound,
                   why="below atan(mu_d), so that every slip of the pushed chain stops")
        if self.incline == bound:
            raise SceneError(f"incline={self.incline!r} must be below atan(mu_d)={bound:.10g}"
                             " (at it the pushed chain never stops sliding)")
        if scene.record == "forces":
            raise SceneError("record='forces' rebuilds the forces of the tilt; with "
                             "loading='pushed_end' use record='displacements'")

    def tangential(self, elastic: np.ndarray, weight: float, drive: float, du: np.ndarray):
        """Elastic force plus the weight, plus the driver's spring on slider 1."""
        force = elastic + weight
        force[0] += self.stiffness * (drive - du[0])
        return force

    def incline_at(self, drives) -> np.ndarray:
        """The fixed incline, at every driver position."""
        return np.full(np.shape(drives), self.incline, dtype=float)

    def weight(self, drive: float) -> float:
        """Tangential component of the weight at the fixed incline."""
        return math.sin(self.incline)

    def normal(self, drive: float) -> float:
        """Normal load at the fixed incline."""
        return math.cos(self.incline)

    def forces(self, state, xi: float, walls: bool, drives, displacement=None) -> np.ndarray:
        """F_t of every slider at rest at each driver position (``tangential``
        in the same order); broadcasts over drives and (G, N) displacements."""
        drives = np.asarray(drives, dtype=float)
        du = state.displacement if displacement is None else np.asarray(displacement, dtype=float)
        force = elastic_force(state, xi, walls, du) + math.sin(self.incline)
        force = np.array(np.broadcast_to(force, np.broadcast_shapes(force.shape,
                                                                    drives.shape + (1,))))
        force[..., 0] += self.stiffness * (drives - du[..., 0])
        return force

    def next_instability(self, elastic: np.ndarray, mu: np.ndarray, drive: float, du: np.ndarray,
                         force_tol: float):
        """The drive at which slider 1 starts downwards (every other slider is
        stable and does not feel D): its force E_1 + sin + K (D - du_1)
        reaches mu_1 cos + force_tol."""
        threshold = mu[0] * math.cos(self.incline) + force_tol
        critical = du[0] + (threshold - elastic[0] - math.sin(self.incline)) / self.stiffness
        return max(critical, drive), np.array([0]), np.array([1.0])

    def beyond_limit(self, drive: float) -> bool:
        """The driver went past its limit (drive_max)."""
        return drive > self.drive_max

    def work(self, weight: float, step: np.ndarray, drive: float, du_start: np.ndarray) -> float:
        """Work of gravity plus the work of the driver's spring on slider 1 as
        it moves by s = step_1 against a fixed driver: K (D - du_1) s - K s^2/2."""
        s = float(step[0])
        return weight * float(step.sum()) + self.stiffness * ((drive - du_start[0]) * s - 0.5 * s * s)

    def spanning_ends_run(self) -> bool:
        """The first event in which every slider moved is the onset of sliding
        (the incline is below the avalanche angle, so every slip stops: no runaway)."""
        return True


# The loadings a scene file can name (``loading = "..."``), by name.
LOADINGS = {cls.name: cls for cls in (Tilt, PushedEnd)}
