"""A scene: one configured run (chain, friction law, loading, integrator, what to record).

The friction law and the loading are parts of the scene that own their
parameters and checks (``parts.friction``, ``parts.loading``); scene files
and the command line hold their flat keys (``scene_keys``).  Every value is
checked on construction; a bad value raises ``SceneError`` whose message
names the parameter and the allowed range.  Units are the
paper's dimensionless ones: time in tau = sqrt(m/k), length in g tau^2.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
import sys
import tempfile
import tomllib
from dataclasses import dataclass, field, fields
from typing import Any, NamedTuple

from .parts.checks import SceneError, check_choice, check_int, check_real, plain_value
from .parts.friction import FRICTIONS, Coulomb, Friction
from .parts.loading import LOADINGS, Loading, Tilt

ENDS = ("free", "walls")
RECORDS = ("summary", "displacements", "forces")
AVALANCHE_CRITERIA = ("sliding",)
INITIAL_FORCES = ("uniform", "zero", "history")
BACKENDS = ("fortran", "numpy")

# Verlet needs dt well below the fastest spring period 2 pi / sqrt(4 + xi).
DT_PERIOD_FRACTION = 1.0 / 30.0

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
BYTES_PER_EVENT = len(("drive", "n_moved", "n_stops", "n_steps", "slider_steps", "duration",
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


def fastest_period(xi: float) -> float:
    """Shortest normal-mode period of the chain, 2 pi / sqrt(4 + xi) (in tau)."""
    return 2.0 * math.pi / math.sqrt(4.0 + xi)


def max_time_step(xi: float) -> float:
    """Largest accepted time step: a thirtieth of the fastest spring period."""
    return DT_PERIOD_FRACTION * fastest_period(xi)


def _flat_key(key: str, doc: str) -> property:
    """A read-only attribute of the scene: the value of a part's flat key (``flat_value``)."""
    return property(lambda scene: scene.flat_value(key), doc=doc)


@dataclass(frozen=True, init=False)
class Scene:
    """One configured run, composed of its chain, its friction law and its
    loading, validated on construction.

    Units: time tau = sqrt(m/k), length g tau^2, force m g, angles in radians.
    The defaults are the paper's values.  An invalid value raises
    ``SceneError`` naming it and its allowed range.

    The friction law and the loading are parts (``Coulomb``, ``Tilt``,
    ``PushedEnd``) that own their parameters and checks.  Their parameters
    can also be given as flat keywords, the keys of scene files and of the
    command line, which build the parts: ``Scene(mu_d=0.5)`` is
    ``Scene(friction=Coulomb(mu_d=0.5))``, ``Scene(loading="pushed_end",
    incline=0.2)`` is ``Scene(loading=PushedEnd(incline=0.2))``; the flat values
    are readable as attributes (``scene.mu_d``, ``scene.incline``, ...).

    Parameters
    ----------
    n_sliders : int
        N, the number of sliders.
    xi : float
        Stiffness of the cantilever springs to the upper plate, in units of
        the springs between neighbours (paper: 0 or 0.001).
    spring_length : float
        Natural length l of the springs between neighbours, g tau^2.
    friction : Coulomb
        The friction law (flat keys ``mu_d``, ``mu_s_mean``, ``sigma_mu``:
        dynamic coefficient; mean and width of the Gaussian static
        coefficients, each drawn above ``mu_d``).
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
    force_tol : float
        Tolerance, m g, of the stability test of a resting slider.
    avalanche : str
        Avalanche criterion ("sliding": every slider moving downwards with
        tan(alpha) > mu_d).
    loading : Tilt, PushedEnd or their name {"tilt", "pushed_end"}
        The paper's quasi-static tilt, the drive the angle alpha (flat key
        ``alpha_max``: the end of the tilt, radians, at most pi/2 - 1e-6);
        or the Burridge-Knopoff loading: the incline fixed and slider 1
        pushed down the chain by a driver on a spring, the drive the
        driver's position D, g tau^2 (flat keys ``incline``: the fixed incline
        in [0, atan(mu_d)); ``driver_stiffness``: K, units of k;
        ``drive_max``: the driver's limit).  docs/loadings.md.
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
    >>> Scene(n_sliders=8, loading="pushed_end", incline=0.2, driver_stiffness=2.0)
    Scene(n_sliders=8, loading=PushedEnd(incline=0.2, stiffness=2.0))
    """

    n_sliders: int = 100
    xi: float = 0.0
    spring_length: float = 10.0
    friction: Friction = Coulomb()
    seed: int = 0
    ends: str = "free"
    initial_forces: str = "uniform"
    mode: str = DEFAULT_MODE
    dt: float | None = None
    refine_tol: float | None = None
    max_event_duration: float | None = None
    max_events: int = 10_000_000
    force_tol: float = 1e-12
    avalanche: str = "sliding"
    loading: Loading = Tilt()
    record: str = "displacements"
    output: str | None = field(default=None, compare=False)

    def __init__(self, n_sliders: int = 100, *, xi: float = 0.0, spring_length: float = 10.0,
                 friction: Friction | str | None = None, seed: int = 0, ends: str = "free",
                 initial_forces: str = "uniform", mode: str = DEFAULT_MODE,
                 dt: float | None = None, refine_tol: float | None = None,
                 max_event_duration: float | None = None, max_events: int = 10_000_000,
                 force_tol: float = 1e-12, avalanche: str = "sliding",
                 loading: Loading | str | None = None, record: str = "displacements",
                 output: str | None = None, **flat: Any) -> None:
        given = dict(locals())
        _refuse_renamed_keys(flat)
        for f in fields(self):
            if f.name not in PARTS:
                object.__setattr__(self, f.name, plain_value(f.type, given[f.name]))
        for role in PARTS:
            keys = _part_keys(role, given[role])
            own = {k: flat.pop(k) for k in list(flat) if k in keys}
            object.__setattr__(self, role, build_part(role, given[role], own))
        if flat:
            raise TypeError(f"Scene() got an unexpected keyword argument {next(iter(flat))!r}")
        self._fill_from_mode()

    def __repr__(self) -> str:
        """Only what differs from the defaults (integrator values: from the mode's),
        so that ``eval(repr(scene)) == scene`` (with the parts' names at hand)."""
        defaults = {f.name: f.default for f in fields(self)}
        defaults.update(SPEED_MODES[self.mode])
        changed = [f"{f.name}={getattr(self, f.name)!r}" for f in fields(self)
                   if f.name != "output" and getattr(self, f.name) != defaults[f.name]]
        return f"Scene({', '.join(changed)})"

    def _fill_from_mode(self) -> None:
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
        check_int("n_sliders", self.n_sliders, 1, None)
        check_real("xi", self.xi, 0.0, None)
        check_real("spring_length", self.spring_length, 0.0, None)
        extent = float(self.n_sliders) * self.spring_length  # the last lattice position
        if not math.isfinite(extent * LATTICE_HEADROOM):
            longest = sys.float_info.max / LATTICE_HEADROOM / self.n_sliders
            raise SceneError(f"spring_length={self.spring_length!r} is out of range for "
                             f"n_sliders={self.n_sliders}: the lattice positions n*l would "
                             f"overflow (allowed up to about {longest:.3g})")
        check_int("seed", self.seed, 0, 2**32 - 1)
        check_choice("ends", self.ends, ENDS)
        check_choice("initial_forces", self.initial_forces, INITIAL_FORCES)
        if self.initial_forces == "history" and (self.walls or not self.loading.drive_is_angle):
            raise SceneError("initial_forces='history' tilts a free chain to its avalanche; it "
                             "needs ends='free' and loading='tilt'")
        self._check_integrator()
        check_int("max_events", self.max_events, 1, None)
        check_real("force_tol", self.force_tol, 0.0, 1e-6)
        check_choice("avalanche", self.avalanche, AVALANCHE_CRITERIA)
        check_choice("record", self.record, RECORDS)
        self.friction.check(self)
        self.loading.check(self)
        if self.output is not None:
            check_writable("output", self.output)

    def _check_integrator(self) -> None:
        dt_max = max_time_step(self.xi)
        check_real("dt", self.dt, 0.0, dt_max, open_low=True,
                   why=f"a thirtieth of the fastest spring period 2*pi/sqrt(4+xi) = "
                       f"{fastest_period(self.xi):.4g} tau")
        check_real("refine_tol", self.refine_tol, RESOLUTION_ULPS * math.ulp(self.dt), self.dt,
                   why="at least 4 ulps of dt (double precision cannot halve a narrower "
                       "bracket) and at most one time step")
        check_real("max_event_duration", self.max_event_duration, 0.0, None, open_low=True)
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

    # -- the parts' flat values (the keys of scene files) ------------------
    def flat_value(self, key: str) -> Any:
        """The value of a part's flat key: its part's, or the default of the loading
        (friction law) that owns the key when the scene has another one."""
        for role in PARTS:
            part = getattr(self, role)
            if key in part.flat_keys:
                return getattr(part, part.flat_keys[key])
        return _flat_defaults()[key]

    mu_d = _flat_key("mu_d", "Dynamic friction coefficient (``friction.mu_d``).")
    mu_s_mean = _flat_key("mu_s_mean", "Mean static friction coefficient (``friction.mu_s_mean``).")
    sigma_mu = _flat_key("sigma_mu", "Width of the static coefficients (``friction.sigma_mu``).")
    alpha_max = _flat_key("alpha_max", "End of the tilt, radians (``Tilt.alpha_max``).")
    incline = _flat_key("incline", "The fixed incline of the pushed end, radians "
                                   "(``PushedEnd.incline``; 0 under the tilt, whose angle is the "
                                   "drive).")
    driver_stiffness = _flat_key("driver_stiffness",
                                 "K of the pushed end's driver spring (``PushedEnd.stiffness``).")
    drive_max = _flat_key("drive_max", "The pushed end's driver limit (``PushedEnd.drive_max``).")

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
        """A copy with ``changes`` (fields, parts or flat keys); a new ``mode``
        brings its own integrator settings, except those given in the same
        call; flat keys of a part change that part's values only."""
        if "mode" in changes:
            for name in SPEED_MODES[DEFAULT_MODE]:
                changes.setdefault(name, None)
        values = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in PARTS}
        for role in PARTS:
            current = getattr(self, role)
            given = changes.pop(role, None)
            keys = _part_keys(role, given if given is not None else current)
            own = {k: changes.pop(k) for k in list(changes) if k in keys}
            values[role] = build_part(role, given, own, current)
        return Scene(**{**values, **changes})

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
        """The scene's flat keys as plain Python values (the scene files' keys): the
        fields but the parts and ``output``, the parts' names (where there is a choice)
        and flat keys, and the other registered kinds' flat keys at their defaults."""
        flat = {f.name: getattr(self, f.name) for f in fields(self)
                if f.name not in PARTS and f.name != "output"}
        flat.update(_flat_defaults())
        for role, (_, registry, _) in PARTS.items():
            part = getattr(self, role)
            if len(registry) > 1 or part.name not in registry:  # one law: files need not name it
                flat[role] = part.name
            flat.update(part.flat())
        return {k: flat[k] for k in sorted(flat, key=_file_order)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Scene":
        """The scene of ``to_dict``'s keys; an unknown key raises SceneError with a close match."""
        _refuse_renamed_keys(d)
        known = {key.name for key in scene_keys()} | {"output"}
        unknown = sorted(set(d) - known)
        if unknown:
            raise SceneError(f"unknown scene key(s) {unknown}{_hint(unknown[0], known)}; allowed "
                             f"keys are {sorted(known - {'output'})}")
        return cls(**d)

    @classmethod
    def from_stored(cls, d: dict[str, Any]) -> "Scene":
        """The scene of a file's stored keys (``to_dict`` when it was written): a key
        since renamed (``RENAMED_KEYS``) is read under its name now."""
        return cls.from_dict({RENAMED_KEYS[k][0] if k in RENAMED_KEYS else k: v
                              for k, v in d.items()})

    @classmethod
    def from_toml(cls, path: str | os.PathLike[str]) -> "Scene":
        """The scene of a TOML file (keys of ``to_dict``, at top level or under ``[scene]``)."""
        return cls.from_dict(toml_values(path))


# The scene's parts: the field, its base class, the registry of its kinds by
# name (what a scene file's key names) and the default kind.
PARTS = {"friction": (Friction, FRICTIONS, Coulomb), "loading": (Loading, LOADINGS, Tilt)}
# The order of the keys in a scene file (keys of parts added later follow, sorted).
FILE_KEYS = ("n_sliders", "xi", "spring_length", "mu_d", "mu_s_mean", "sigma_mu", "seed", "ends",
             "initial_forces", "mode", "dt", "refine_tol", "max_event_duration", "max_events",
             "alpha_max", "force_tol", "avalanche", "loading", "incline", "driver_stiffness",
             "drive_max", "record")


# Keys that files written earlier hold: their name now, what it is, and what the
# old word means instead (``tilt`` names the loading, ``drive`` the loading's
# variable).  Files written with an old key still load (``Scene.from_stored``); a
# scene given one now is refused with a line that names the key now.
RENAMED_KEYS = {
    "tilt": ("incline", "the pushed end's fixed incline", "tilt names the loading, loading='tilt'"),
    "drive_stiffness": ("driver_stiffness", "the stiffness of the pushed end's driver spring",
                        "drive names the loading's variable"),
}


def _refuse_renamed_keys(keys) -> None:
    """Refuse a renamed key, with one line that names its key now."""
    for old, (new, what, why) in RENAMED_KEYS.items():
        if old in keys:
            raise SceneError(f"{old}={keys[old]!r} is not a scene key: {what} is {new}= ({why})")


def _file_order(key: str) -> tuple:
    return (0, FILE_KEYS.index(key), "") if key in FILE_KEYS else (1, 0, key)


def _flat_defaults() -> dict[str, Any]:
    """Every registered part's flat keys with their defaults."""
    return {key: value for _, registry, _ in PARTS.values() for cls in registry.values()
            for key, value in cls.flat_defaults().items()}


def _part_keys(role: str, given) -> set[str]:
    """The flat keys that belong to the part ``role``: every registered kind's,
    and those of the given part object."""
    _, registry, _ = PARTS[role]
    keys = {key for cls in registry.values() for key in cls.flat_keys}
    return keys | set(getattr(given, "flat_keys", ()))


def build_part(role: str, given, flat: dict[str, Any], current=None):
    """The part ``role`` ("friction" or "loading") of a scene: ``given`` (a part
    object, its name, or None for ``current``'s kind, else the default) with the
    flat keys ``flat`` of its own; a flat key of another kind must keep its
    default (files hold them all)."""
    base, registry, default = PARTS[role]
    if isinstance(given, base):
        part = given
        clash = sorted(set(flat) & set(part.flat_keys))
        if clash:
            raise SceneError(f"{clash[0]}={flat[clash[0]]!r} is a parameter of {role}={part!r}: "
                             "give it there, not beside it")
    else:
        kind = type(current) if given is None and current is not None else default
        if given is not None:
            if not isinstance(given, str) or given not in registry:
                raise SceneError(f"{role}={given!r} must be one of {tuple(registry)}")
            kind = registry[given]
        part = kind.from_flat(flat, current if type(current) is kind else None)
    defaults = _flat_defaults()
    for key, value in flat.items():
        if key not in part.flat_keys and value != defaults[key]:
            owner = next(cls.name for cls in registry.values() if key in cls.flat_keys)
            raise SceneError(f"{key}={value!r} is a parameter of {role}={owner!r}; with "
                             f"{role}={part.name!r} leave it out")
    return part


class SceneKey(NamedTuple):
    """One flat key of a scene file and of the command line."""

    name: str
    type: type
    default: Any


def scene_keys() -> tuple[SceneKey, ...]:
    """The flat keys of a scene (file order): the fields but the parts and ``output``,
    the parts' names and every registered kind's flat keys, with type and default."""
    kinds = {"int": int, "float": float, "str": str}
    keys = {f.name: SceneKey(f.name, kinds[f.type.split(" ")[0]], f.default)
            for f in fields(Scene) if f.name not in PARTS and f.name != "output"}
    for role, (_, registry, default) in PARTS.items():
        if len(registry) > 1:
            keys[role] = SceneKey(role, str, default.name)
        for cls in registry.values():
            types = {f.name: f.type for f in fields(cls)}
            for key, attr in cls.flat_keys.items():
                keys[key] = SceneKey(key, kinds[types[attr]], cls.flat_defaults()[key])
    return tuple(keys[k] for k in sorted(keys, key=_file_order))


def read_toml(path, where: str, error: type[Exception], data: bytes | None = None) -> dict[str, Any]:
    """The tables of a TOML file (or of ``data``, its bytes as read elsewhere: MPI rank 0);
    a missing, unreadable or invalid file raises ``error`` with one line that starts with
    ``where``."""
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
    known = {key.name for key in scene_keys()}
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
    close = difflib.get_close_matches(key, sorted(known), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def check_tilt_statistics(scene: Scene) -> None:
    """Refuse a loading whose runs the tilt's statistics cannot describe (ensembles, studies)."""
    if not scene.loading.drive_is_angle:
        raise SceneError(f"loading={scene.loading.name!r}: ensembles and studies gather the tilt's "
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
            with tempfile.TemporaryFile(dir=parent):
                pass
    except OSError as exc:
        what = "exists and is not writable" if existed else f"cannot be created in {parent!r}"
        raise SceneError(f"{name}={p!r} {what} ({exc.strerror})") from None
