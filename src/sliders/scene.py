"""A scene: one configured run (system, loading, integrator, what to record).

Every field is checked on construction; a bad value raises ``SceneError``
whose message names the parameter and the allowed range.  Units are the
paper's dimensionless ones: time in tau = sqrt(m/k), length in g tau^2.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from dataclasses import dataclass, field, fields
from typing import Any

ENDS = ("free", "walls")
RECORDS = ("summary", "displacements", "forces")
AVALANCHE_CRITERIA = ("sliding",)
INITIAL_FORCES = ("uniform", "zero", "history")
BACKENDS = ("fortran", "numpy")
LOADINGS = ("tilt", "pushed_end")

# Verlet needs dt well below the fastest spring period 2 pi / sqrt(4 + xi).
DT_PERIOD_FRACTION = 1.0 / 30.0
# Between walls the rearrangement angles pile up towards pi/2 (Delta alpha is
# proportional to cos alpha: infinitely many events before pi/2), and the
# displacement per event, (mu_s - mu_d) cos alpha, sinks below rounding.
ALPHA_MAX_LIMIT = math.pi / 2 - 1e-6

# What double precision can resolve (the integrator converges or is refused).
# 1. The crossing bisection halves [lo, hi] within one step [0, dt] until
#    hi - lo <= refine_tol.  Near dt neighbouring doubles are ulp(dt) apart;
#    once the bracket is one ulp wide its midpoint rounds onto an end and the
#    bracket stops shrinking: with refine_tol < ulp(dt) the loop never ends
#    (``--refine-tol 1e-20`` at dt = 1e-3, ulp = 2.2e-19, did exactly that).
#    refine_tol >= RESOLUTION_ULPS * ulp(dt) keeps at least that many
#    representable midpoints in every bracket still to be halved.
# 2. The event clock t (which max_event_duration caps) advances by dt per
#    full step; t + dt == t once dt < ulp(t) / 2, and the cap would never be
#    reached.  dt >= RESOLUTION_ULPS * ulp(max_event_duration) keeps every
#    full step visible on the clock up to the cap.  (Refined steps, shorter
#    than dt, only happen at crossings, each of which changes the moving set.)
#    At dt = 1e-3 this allows caps up to 1.1e12 tau.
RESOLUTION_ULPS = 4
# the lattice positions n*l (and sums of a few of them) must stay far below the largest float
LATTICE_HEADROOM = 1e6

# Memory estimate (``Scene.memory_estimate``), measured on this code: arrays
# per slider (state, forces, kernel work arrays, initial and final states),
# bytes per event record, sparse displacement entries per event (index +
# value) and the number of events of a run to its avalanche (about 2.4 N,
# measured for N = 100 to 1000).
BYTES_PER_SLIDER = 400
BYTES_PER_EVENT = len(("alpha", "n_moved", "n_stops", "n_steps", "slider_steps", "duration",
                       "work_gravity", "elastic_change", "dissipation")) * 8
BYTES_PER_SPARSE_ENTRY = 16
EVENTS_PER_SLIDER = 3.0


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
    """One configured tilt run, validated on construction.

    Units: time tau = sqrt(m/k), length g tau^2, force m g, angles in radians.
    The defaults are the paper's values.  An invalid value raises
    ``SceneError`` naming it and its allowed range.

    Parameters
    ----------
    n_sliders : int
        N, the number of sliders.
    xi : float
        Stiffness of the cantilever springs to the upper plate, in units of
        the springs between neighbours (paper: 0 or 0.001).
    spring_length : float
        Natural length l of the springs between neighbours, g tau^2.
    mu_d, mu_s_mean, sigma_mu : float
        Dynamic friction coefficient; mean and width of the Gaussian static
        coefficients (each drawn above ``mu_d``).
    seed : int
        Key of every random draw (0 to 2**32 - 1).
    ends : {"free", "walls"}
        A free chain, or a chain between two immobile walls.
    initial_forces : {"uniform", "zero", "history"}
        The paper's preparation (forces uniform in ]-mu_s_mean, mu_s_mean[),
        every spring at rest (with sigma_mu = 0: a scene without disorder), or
        a chain with a history: brought to its last stable state before an
        avalanche (another seed) and tilted back to 0 (``sliders.preparation``).
    mode : {"sketch", "explore", "statistics", "trajectory", "reference"}
        Named speed/accuracy setting (``SPEED_MODES``, docs/howto/speed_modes.md)
        that gives ``dt``, ``refine_tol`` and ``max_event_duration`` unless
        they are given.
    dt : float, optional
        Velocity-Verlet time step, tau.
    refine_tol : float, optional
        Width, in tau, to which a crossing (a slider starting or stopping) is
        bracketed within a step.
    max_event_duration : float, optional
        Cap on the duration of one rearrangement, tau; hitting it ends the
        run with status ``"event_duration_cap"``, never taken for the avalanche.
    max_events : int
        Stop after this many rearrangements.
    alpha_max : float
        Stop tilting at this angle, radians (needed between walls, which
        never avalanche); at most pi/2 - 1e-6.
    force_tol : float
        Tolerance, m g, of the stability test of a resting slider.
    avalanche : str
        Avalanche criterion ("sliding": every slider moving downwards with
        tan(alpha) > mu_d).
    loading : {"tilt", "pushed_end"}
        The paper's quasi-static tilt (the drive is the angle alpha), or the
        Burridge-Knopoff loading: the incline fixed at ``tilt`` and slider 1
        pushed down the chain by a driver on a spring; the drive is then the
        driver's position D (g tau^2), stored where the tilt's alpha is.
    tilt : float
        pushed_end only: the fixed incline, radians, in [0, atan(mu_d)) so
        that every slip stops.
    drive_stiffness : float
        pushed_end only: stiffness K of the driver's spring, units of k.
    drive_max : float
        pushed_end only: the driver's limit, g tau^2 (the run ends there).
    record : {"summary", "displacements", "forces"}
        Per-event scalars only; plus the displacement of every slider that
        moved, stored sparsely; or the same storage with the tangential force
        after each event reconstructed from it on demand.
    output : str, optional
        Where a command-line run writes its result (not part of the scene).

    Examples
    --------
    >>> Scene(n_sliders=400, xi=0.001, seed=1).replace(mode="explore")
    Scene(n_sliders=400, xi=0.001, seed=1, mode='explore')
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
    loading: str = "tilt"
    tilt: float = 0.0
    drive_stiffness: float = 1.0
    drive_max: float = 1e9
    record: str = "displacements"
    output: str | None = field(default=None, compare=False)

    def __repr__(self) -> str:
        """Only what differs from the defaults (integrator values: from the mode's),
        so that ``eval(repr(scene)) == scene``."""
        defaults = {f.name: f.default for f in fields(self)}
        defaults.update(SPEED_MODES[self.mode])
        changed = [f"{f.name}={getattr(self, f.name)!r}" for f in fields(self)
                   if f.name != "output" and getattr(self, f.name) != defaults[f.name]]
        return f"Scene({', '.join(changed)})"

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, _plain_value(f.name, f.type, getattr(self, f.name)))
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
        extent = float(self.n_sliders) * self.spring_length  # the last lattice position
        if not math.isfinite(extent * LATTICE_HEADROOM):
            longest = sys.float_info.max / LATTICE_HEADROOM / self.n_sliders
            raise SceneError(f"spring_length={self.spring_length!r} is out of range for "
                             f"n_sliders={self.n_sliders}: the lattice positions n*l would "
                             f"overflow (allowed up to about {longest:.3g})")
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
        if self.initial_forces == "history" and (self.ends == "walls" or self.loading != "tilt"):
            raise SceneError("initial_forces='history' tilts a free chain to its avalanche; it "
                             "needs ends='free' and loading='tilt'")
        dt_max = max_time_step(self.xi)
        _check_real("dt", self.dt, 0.0, dt_max, open_low=True,
                    why=f"a thirtieth of the fastest spring period 2*pi/sqrt(4+xi) = "
                        f"{fastest_period(self.xi):.4g} tau")
        _check_real("refine_tol", self.refine_tol, RESOLUTION_ULPS * math.ulp(self.dt), self.dt,
                    why="at least 4 ulps of dt (double precision cannot halve a narrower "
                        "bracket) and at most one time step")
        _check_real("max_event_duration", self.max_event_duration, 0.0, None, open_low=True)
        if self.max_event_duration < 100 * self.dt:
            raise SceneError(
                f"max_event_duration={self.max_event_duration!r} tau must be at least "
                f"100 time steps ({100 * self.dt:g} tau); the last events before the "
                "avalanche last hundreds of tau"
            )
        if self.dt < RESOLUTION_ULPS * math.ulp(self.max_event_duration):
            longest = self.dt / (RESOLUTION_ULPS * math.ulp(1.0))
            raise SceneError(
                f"max_event_duration={self.max_event_duration!r} tau is out of range: allowed "
                f"up to about {longest:.3g} tau at dt={self.dt!r} (beyond, a time step of dt is "
                "below 4 ulps of the event clock, which would stop advancing before the cap)"
            )
        _check_int("max_events", self.max_events, 1, None)
        _check_real("alpha_max", self.alpha_max, 0.0, ALPHA_MAX_LIMIT, open_low=True,
                    why="pi/2 - 1e-6: towards pi/2 the rearrangements pile up without end "
                        "(Delta alpha ~ cos alpha) and cos alpha sinks below rounding")
        _check_real("force_tol", self.force_tol, 0.0, 1e-6)
        if self.avalanche not in AVALANCHE_CRITERIA:
            raise SceneError(f"avalanche={self.avalanche!r} must be one of {AVALANCHE_CRITERIA}")
        if self.loading not in LOADINGS:
            raise SceneError(f"loading={self.loading!r} must be one of {LOADINGS}")
        _check_real("tilt", self.tilt, 0.0, math.atan(self.mu_d), why="below atan(mu_d), "
                    "so that every slip of the pushed chain stops")
        if self.loading == "tilt" and self.tilt != 0.0:
            raise SceneError(f"tilt={self.tilt!r} is the fixed incline of loading='pushed_end'; "
                             "with loading='tilt' the angle is the drive (leave tilt at 0)")
        if self.loading == "pushed_end" and self.tilt == math.atan(self.mu_d):
            raise SceneError(f"tilt={self.tilt!r} must be below atan(mu_d)={math.atan(self.mu_d):.10g}"
                             " (at it the pushed chain never stops sliding)")
        if self.loading == "pushed_end" and self.record == "forces":
            raise SceneError("record='forces' rebuilds the forces of the tilt; with "
                             "loading='pushed_end' use record='displacements'")
        _check_real("drive_stiffness", self.drive_stiffness, 0.0, None, open_low=True)
        _check_real("drive_max", self.drive_max, 0.0, None, open_low=True)
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
        """True between two immobile walls (``ends="walls"``), False for a free chain."""
        return self.ends == "walls"

    @property
    def alpha_c_bounds(self) -> tuple[float, float]:
        """Bounds of the avalanche angle in radians, atan(mu_d) and atan(mu_s_mean)
        (docs/model.md, "The avalanche"; the upper one holds with the mean static coefficient)."""
        return math.atan(self.mu_d), math.atan(self.mu_s_mean)

    def replace(self, **changes: Any) -> "Scene":
        """A copy with ``changes``; a new ``mode`` brings its own integrator
        settings, except those given in the same call."""
        if "mode" in changes:
            for name in SPEED_MODES[DEFAULT_MODE]:
                changes.setdefault(name, None)
        return dataclasses.replace(self, **changes)

    def memory_estimate(self) -> int:
        """Bytes a run of this scene needs (an upper estimate; see BYTES_PER_* above).

        Events: ``max_events`` or ~3 N (a run to its avalanche), whichever is
        smaller; sparse displacements (record != "summary"): one entry per
        slider and event in the worst case of system-spanning events, bounded
        by 3 N events of N sliders only when N is small: min(N, 64) entries
        per event (measured means: 4-30)."""
        n = self.n_sliders
        events = min(self.max_events, EVENTS_PER_SLIDER * n + 100)
        total = BYTES_PER_SLIDER * n + BYTES_PER_EVENT * events
        if self.record != "summary":
            total += BYTES_PER_SPARSE_ENTRY * events * min(n, 64)
        return int(total)

    def to_dict(self) -> dict[str, Any]:
        """Every field but ``output`` as plain Python values (the scene files' keys)."""
        d = dataclasses.asdict(self)
        d.pop("output")
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Scene":
        """The scene of ``to_dict``'s keys; an unknown key raises SceneError with a close match."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise SceneError(f"unknown scene key(s) {unknown}{_hint(unknown[0], known)}; allowed "
                             f"keys are {sorted(known - {'output'})}")
        return cls(**d)

    @classmethod
    def from_toml(cls, path: str | os.PathLike[str]) -> "Scene":
        """The scene of a TOML file (keys of ``to_dict``, at top level or under ``[scene]``)."""
        return cls.from_dict(toml_values(path))


def read_toml(path, where: str, error: type[Exception], data: bytes | None = None) -> dict[str, Any]:
    """The tables of a TOML file (or of ``data``, its bytes as read elsewhere: MPI rank 0);
    a missing, unreadable or invalid file raises ``error`` with one line that starts with
    ``where``."""
    import tomllib

    try:
        if data is not None:
            return tomllib.loads(data.decode("utf-8"))
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except UnicodeDecodeError as exc:
        raise error(f"{where} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except FileNotFoundError:
        raise error(f"{where} does not exist") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{where} is not valid TOML: {exc}") from None
    except OSError as exc:
        raise error(f"{where} cannot be read ({exc.strerror})") from None


def toml_values(path: str | os.PathLike[str], text: bytes | None = None) -> dict[str, Any]:
    """The scene keys of a TOML file (its [scene] table, or the top level), as written
    (``text``: the file's bytes, when they were read elsewhere)."""
    where = f"scene file {str(path)!r}"
    data = read_toml(path, where, SceneError, text)
    known = {f.name for f in fields(Scene)} - {"output"}
    if "scene" in data:
        outside = [k for k in data if k != "scene"]
        if outside:
            raise SceneError(f"{where}: key {outside[0]!r} stands outside the [scene] table"
                             f"{_hint(outside[0], known)}; with a [scene] table every key must be "
                             "inside it")
        values = data["scene"]
        if not isinstance(values, dict):
            raise SceneError(f"{where}: 'scene' must be a table ([scene])")
    else:
        values = data
    for k, v in values.items():
        if isinstance(v, (dict, list)) and not (isinstance(v, list) and k in known):
            kind = "table" if isinstance(v, dict) else "array"
            raise SceneError(f"{where}: {kind} {k!r} is not a scene key{_hint(k, known)}; "
                             f"allowed keys are {sorted(known)}")
    return dict(values)


def _hint(key: str, known) -> str:
    import difflib

    close = difflib.get_close_matches(key, sorted(known), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _plain_value(name: str, kind: str, value):
    """Python and NumPy scalars alike, as plain Python numbers and strings.

    A NumPy float becomes the shortest decimal that round-trips in its own
    precision (np.float32(0.001) -> 0.001, not 0.0010000000474974513), which is
    what was written.  Booleans are left for the checks to refuse.
    """
    try:
        import numpy as np
    except ImportError:  # pragma: no cover - numpy is a dependency
        return value
    if isinstance(value, (bool, np.bool_)) or value is None:
        return value
    if kind.startswith("int"):
        if isinstance(value, np.integer):
            return int(value)
    elif kind.startswith("float"):
        if isinstance(value, np.floating):
            return float(str(value))
        if isinstance(value, (int, np.integer)):
            return float(value)
    elif kind.startswith("str") and isinstance(value, np.str_):
        return str(value)
    return value


def check_tilt_statistics(scene: Scene) -> None:
    """Refuse a loading whose runs the tilt's statistics cannot describe (ensembles, studies)."""
    if scene.loading != "tilt":
        raise SceneError(f"loading={scene.loading!r}: ensembles and studies gather the tilt's "
                         "statistics (alpha_c, precursors by angle); run it one realisation at "
                         "a time: python -m sliders tilt --loading pushed_end")


def check_memory(scene: Scene, ranks: int = 1) -> None:
    """Refuse a scene whose run would need more memory than the machine has available;
    ``ranks``: processes of one node running such scenes at once (their needs add up)."""
    need = scene.memory_estimate() * max(1, int(ranks))
    available = available_memory()
    if available is not None and need > available:
        each = f" ({ranks} ranks on this node, {need / ranks / 1e9:.3g} GB each)" if ranks > 1 else ""
        raise SceneError(
            f"n_sliders={scene.n_sliders} with record={scene.record!r} and "
            f"max_events={scene.max_events} needs about {need / 1e9:.3g} GB{each}, more than the "
            f"{available / 1e9:.3g} GB available (MemAvailable); use record='summary', fewer "
            f"sliders{', fewer ranks per node' if ranks > 1 else ''} or a lower max_events"
        )


def available_memory() -> int | None:
    """MemAvailable of /proc/meminfo in bytes (None where there is no such file)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


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
        if existed:
            with open(p, "ab"):
                pass
        else:  # probe the folder, never the target: another run may be creating it
            import tempfile

            with tempfile.TemporaryFile(dir=parent):
                pass
    except OSError as exc:
        what = "exists and is not writable" if existed else f"cannot be created in {parent!r}"
        raise SceneError(f"{name}={p!r} {what} ({exc.strerror})") from None
