"""A scene: one configured run (system, loading, integrator, what to record).

Every field is checked on construction; a bad value raises ``SceneError``
whose message names the parameter and the allowed range.  Units are the
paper's dimensionless ones: time in tau = sqrt(m/k), length in g tau^2.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field, fields
from typing import Any

ENDS = ("free", "walls")
RECORDS = ("summary", "displacements", "forces")
AVALANCHE_CRITERIA = ("sliding",)
INITIAL_FORCES = ("uniform", "zero")
BACKENDS = ("fortran", "numpy")

# Verlet needs dt well below the fastest spring period 2 pi / sqrt(4 + xi).
DT_PERIOD_FRACTION = 1.0 / 30.0
# Between walls the rearrangement angles pile up towards pi/2 (Delta alpha is
# proportional to cos alpha: infinitely many events before pi/2), and the
# displacement per event, (mu_s - mu_d) cos alpha, sinks below rounding.
ALPHA_MAX_LIMIT = math.pi / 2 - 1e-6


# Speed modes: named integrator settings (dt, refine_tol, max_event_duration)
# with the accuracy measured by benchmarks/accuracy.py (docs/accuracy.md).
# A field given explicitly overrides its mode's value.
SPEED_MODES: dict[str, dict[str, float]] = {
    # quick looks: no bias detected by 200 paired N = 100 runs; N = 10 event
    # angles to ~1e-3, same events; 7x cheaper than trajectory
    "sketch": {"dt": 3e-2, "refine_tol": 1e-10, "max_event_duration": 1e7},
    # ensembles of 20 to a few hundred runs: no bias resolved by 200 paired
    # N = 100 runs (alpha_c +4e-4 +- 2e-4, below the 20-run noise); 5x cheaper
    "explore": {"dt": 1e-2, "refine_tol": 1e-10, "max_event_duration": 1e7},
    # statistics of any ensemble (1000 runs and more): 11x smaller local
    # error than explore, no bias resolved on alpha_c, P_i, event sizes
    "statistics": {"dt": 3e-3, "refine_tol": 1e-10, "max_event_duration": 1e7},
    # one trajectory: event angles to ~1e-6 for N = 10, same event sequence
    "trajectory": {"dt": 1e-3, "refine_tol": 1e-10, "max_event_duration": 1e7},
    # reference-quality trajectory: angles to ~1e-8
    "reference": {"dt": 1e-4, "refine_tol": 1e-12, "max_event_duration": 1e7},
}
DEFAULT_MODE = "trajectory"


class SceneError(ValueError):
    """An invalid scene parameter; the message names it and its allowed range."""


def fastest_period(xi: float) -> float:
    """Shortest normal-mode period of the chain, 2 pi / sqrt(4 + xi) (in tau)."""
    return 2.0 * math.pi / math.sqrt(4.0 + xi)


def max_time_step(xi: float) -> float:
    """Largest accepted time step: a thirtieth of the fastest spring period."""
    return DT_PERIOD_FRACTION * fastest_period(xi)


@dataclass(frozen=True)
class Scene:
    """One configured tilt run.

    System: ``n_sliders`` (N), ``xi`` (cantilever/neighbour stiffness ratio),
    ``spring_length`` (l), ``mu_d``, ``mu_s_mean``, ``sigma_mu``, ``seed``,
    ``ends`` ("free" chain or between two immobile "walls").
    ``initial_forces`` is the paper's "uniform" preparation or "zero" (every
    spring at rest: with sigma_mu = 0 a scene without any disorder).
    Integrator: ``mode`` names a speed/accuracy setting (``SPEED_MODES``:
    "sketch", "explore", "statistics", "trajectory" (default), "reference";
    README "Speed modes") that gives
    ``dt`` (velocity-Verlet step), ``refine_tol`` (width in tau to which a
    crossing is bracketed) and ``max_event_duration`` (cap on the duration of
    one rearrangement, in tau; hitting it ends the run with status
    ``"event_duration_cap"``, never taken for the avalanche) unless they are
    given explicitly.  ``max_events``
    and ``alpha_max`` (stop tilting there; needed for walls, which never
    avalanche).
    Recording: ``record`` is "summary" (per-event scalars only),
    "displacements" (plus the displacement of every slider that moved, stored
    sparsely) or "forces" (same storage; the tangential force after each
    event is reconstructed from it on demand).
    """

    n_sliders: int = 100
    xi: float = 0.0
    spring_length: float = 10.0
    mu_d: float = 0.55
    mu_s_mean: float = 0.6
    sigma_mu: float = 0.01
    seed: int = 0
    ends: str = "free"
    initial_forces: str = "uniform"
    mode: str = DEFAULT_MODE
    dt: float | None = None
    refine_tol: float | None = None
    max_event_duration: float | None = None
    max_events: int = 10_000_000
    alpha_max: float = ALPHA_MAX_LIMIT
    force_tol: float = 1e-12
    avalanche: str = "sliding"
    record: str = "displacements"
    output: str | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if self.mode not in SPEED_MODES:
            raise SceneError(f"mode={self.mode!r} must be one of {tuple(SPEED_MODES)}")
        from_mode = [name for name in SPEED_MODES[self.mode] if getattr(self, name) is None]
        for name in from_mode:
            object.__setattr__(self, name, SPEED_MODES[self.mode][name])
        try:
            self._check()
        except SceneError as exc:
            named = [name for name in from_mode if str(exc).startswith(name + "=")]
            if not named:
                raise
            raise SceneError(f"{exc}; {named[0]} comes from mode={self.mode!r}: "
                             f"give {named[0]} explicitly") from None

    def _check(self) -> None:
        _check_int("n_sliders", self.n_sliders, 1, None)
        _check_real("xi", self.xi, 0.0, None)
        _check_real("spring_length", self.spring_length, 0.0, None)
        _check_real("mu_d", self.mu_d, 0.0, None)
        _check_real("mu_s_mean", self.mu_s_mean, 0.0, None)
        if not self.mu_s_mean > self.mu_d:
            raise SceneError(
                f"mu_s_mean={self.mu_s_mean!r} must exceed mu_d={self.mu_d!r} "
                "(static friction above dynamic: mu_d < mu_s_mean)"
            )
        _check_real("sigma_mu", self.sigma_mu, 0.0, None)
        _check_int("seed", self.seed, 0, 2**32 - 1)
        if self.ends not in ENDS:
            raise SceneError(f"ends={self.ends!r} must be one of {ENDS}")
        if self.initial_forces not in INITIAL_FORCES:
            raise SceneError(f"initial_forces={self.initial_forces!r} must be one of {INITIAL_FORCES}")
        dt_max = max_time_step(self.xi)
        _check_real("dt", self.dt, 0.0, dt_max, open_low=True,
                    why=f"a thirtieth of the fastest spring period 2*pi/sqrt(4+xi) = "
                        f"{fastest_period(self.xi):.4g} tau")
        _check_real("refine_tol", self.refine_tol, 0.0, self.dt, open_low=True,
                    why="the crossing bracket must close below one time step")
        _check_real("max_event_duration", self.max_event_duration, 0.0, None, open_low=True)
        if self.max_event_duration < 100 * self.dt:
            raise SceneError(
                f"max_event_duration={self.max_event_duration!r} tau must be at least "
                f"100 time steps ({100 * self.dt:g} tau); the last events before the "
                "avalanche last hundreds of tau"
            )
        _check_int("max_events", self.max_events, 1, None)
        _check_real("alpha_max", self.alpha_max, 0.0, ALPHA_MAX_LIMIT, open_low=True,
                    why="pi/2 - 1e-6: towards pi/2 the rearrangements pile up without end "
                        "(Delta alpha ~ cos alpha) and cos alpha sinks below rounding")
        _check_real("force_tol", self.force_tol, 0.0, 1e-6)
        if self.avalanche not in AVALANCHE_CRITERIA:
            raise SceneError(f"avalanche={self.avalanche!r} must be one of {AVALANCHE_CRITERIA}")
        if self.record not in RECORDS:
            raise SceneError(f"record={self.record!r} must be one of {RECORDS}")
        if self.output is not None:
            check_writable("output", self.output)

    # -- convenience -------------------------------------------------------
    @property
    def delta_mu(self) -> float:
        """Delta mu = mu_s_mean - mu_d, the paper's bin half-width."""
        return self.mu_s_mean - self.mu_d

    @property
    def walls(self) -> bool:
        return self.ends == "walls"

    @property
    def alpha_c_bounds(self) -> tuple[float, float]:
        """MODEL.md section 4 bounds with the mean static coefficient, atan(mu_d) and atan(mu_s_mean)."""
        return math.atan(self.mu_d), math.atan(self.mu_s_mean)

    def replace(self, **changes: Any) -> "Scene":
        """A copy with ``changes``; a new ``mode`` brings its own integrator
        settings, except those given in the same call."""
        if "mode" in changes:
            for name in SPEED_MODES[DEFAULT_MODE]:
                changes.setdefault(name, None)
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d.pop("output")
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Scene":
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise SceneError(
                f"unknown scene key(s) {unknown}; allowed keys are {sorted(known - {'output'})}"
            )
        return cls(**d)

    @classmethod
    def from_toml(cls, path: str | os.PathLike[str]) -> "Scene":
        return cls.from_dict(toml_values(path))


def toml_values(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The scene keys of a TOML file (its [scene] table, or the top level), as written."""
    import tomllib

    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise SceneError(f"scene file {str(path)!r} does not exist") from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"scene file {str(path)!r} is not valid TOML: {exc}") from None
    return dict(data.get("scene", data))


def _check_real(name, value, low, high, *, open_low=False, why=None) -> None:
    rng = _range_text(low, high, open_low)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{name}={value!r} must be a real number in {rng}")
    if not math.isfinite(value):
        raise SceneError(f"{name}={value!r} must be finite, in {rng}")
    too_low = low is not None and (value <= low if open_low else value < low)
    too_high = high is not None and value > high
    if too_low or too_high:
        extra = f" ({why})" if why else ""
        raise SceneError(f"{name}={value!r} is out of range: allowed {rng}{extra}")


def _check_int(name, value, low, high) -> None:
    rng = _range_text(low, high, False)
    if isinstance(value, bool) or not isinstance(value, int):
        try:
            import numpy as np

            ok = isinstance(value, np.integer)
        except ImportError:  # pragma: no cover
            ok = False
        if not ok:
            raise SceneError(f"{name}={value!r} must be an integer in {rng}")
    if (low is not None and value < low) or (high is not None and value > high):
        raise SceneError(f"{name}={value!r} is out of range: allowed {rng}")


def _range_text(low, high, open_low) -> str:
    lo = "-inf" if low is None else f"{low:.10g}"
    hi = "+inf" if high is None else f"{high:.10g}"
    return f"{'(' if open_low or low is None else '['}{lo}, {hi}{')' if high is None else ']'}"


def check_writable(name: str, path: str | os.PathLike[str]) -> None:
    """Refuse a path whose file cannot be created or written."""
    p = os.fspath(path)
    if p == "" or os.path.isdir(p):
        raise SceneError(f"{name}={p!r} is a directory or empty; give a file path to write")
    parent = os.path.dirname(os.path.abspath(p)) or "."
    if not os.path.isdir(parent):
        raise SceneError(f"{name}={p!r}: directory {parent!r} does not exist")
    existed = os.path.exists(p)
    try:  # the honest test (permission bits say nothing for root or read-only mounts)
        with open(p, "ab"):
            pass
    except OSError as exc:
        what = "exists and is not writable" if existed else f"cannot be created in {parent!r}"
        raise SceneError(f"{name}={p!r} {what} ({exc.strerror})") from None
    if not existed:
        os.remove(p)
