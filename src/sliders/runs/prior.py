"""``python -m sliders.prior PRIOR.toml --out FILE.h5``: realisations whose material is drawn from a prior.

    mpirun -n 2 python -m sliders.prior mpi_runs/priors/default.toml --out prior.h5
    python -m sliders.prior small.toml --out small.h5 --resume

A prior file::

    [prior]
    realisations = 4000
    design = "sobol"            # "sobol", "latin" or "random" (scipy.stats.qmc), seeded by seed
    seed = 0                    # base seed: row r has the scene seed realisation_seed(seed, r)
    ceiling_step = 0.01         # the ceiling's grid of angles, rad (ceiling_step, 2 ceiling_step, ...)
    ceiling_k = 8               # the smallest distances to threshold kept at each angle
    [scene]                     # the base scene (keys of sliders.Scene; default mode "explore")
    mode = "explore"
    [parameters]                # name -> a number, or one distribution
    mu_d = { uniform = [0.3, 0.8] }
    mu_s_minus_mu_d = { loguniform = [0.02, 0.12] }   # derived: mu_s_mean = mu_d + this
    sigma_mu = { uniform = [0.005, 0.03] }
    xi = { loguniform = [1e-4, 1e-2], zero = 0.5 }    # 0 with probability 0.5
    n_sliders = { choice = [100, 200, 400] }

Distributions: ``uniform = [a, b]``, ``loguniform = [a, b]`` (0 < a < b),
``choice = [v, ...]`` (equal weights; finite numbers or, for ``initial_forces``,
names); ``zero = p`` adds an atom at 0 of weight p to a uniform or loguniform
law.  ``n_sliders`` is an integer: a fixed integer or a choice of integers.
``ceiling_k`` is at most the largest ``n_sliders`` (a chain has no more
distances than sliders).  A prior is refused before anything is drawn when its
plan (about ``PLAN_BYTES_PER_ROW`` bytes a row on every rank) would not fit in
half the memory available, or when it has more than ``MAX_REALISATIONS``
rows.  The unit design (one column per drawn parameter, in name order) goes
through each marginal's inverse CDF (Sobol and random points are sequences:
row r's values depend on r and the seed only; a Latin hypercube is
stratified over all R rows, so its rows also depend on R).  Every row's scene is built and checked
before anything runs; a bad prior or row is refused in one line naming it.

Scheduling is every run command's (``runs.scheduler``, dynamic, one file,
``--resume``; the command's shape: ``runs.command``); a row depends only on its index and the seed, so the
file's content is the same with any number of ranks and after any
interruption.  A row: the catalogue of every event to the avalanche
(``catalogue.Catalogue``), the parameters, alpha_c, the status, and the
"ceiling": at each grid angle below the row's end, the K smallest distances
``mu_s,n cos(alpha) - |F_n|`` of a slider to its threshold.  The run is cut
at every grid angle (the scene's ``alpha_max`` set to it, then the tilt
continued from the state reached): the events are the same, bit for bit, as
one uninterrupted ``sliders.tilt`` (``tests/test_prior.py``), and the state at
the grid angle gives the thresholds (which change at every stop) and the
forces.  The file: ``sliders.io.prior_file``.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .command import (DEFAULT_BACKEND, CommandParser, RunCommand, RunPlan, UsageError,
                      resume_header, check_run_options, input_command_parser, open_output,
                      run_planned)
from .rows import realisation_seeds, status_code
from .scheduler import serve_rows, tilt_interruptibly
from ..io.prior_file import (HANDLERS, catalogue_events, prior_attributes, prior_layout,
                             read_prior_header, write_view)

DESIGNS = ("sobol", "latin", "random")
DISTRIBUTIONS = ("uniform", "loguniform", "choice")
DERIVED = {"mu_s_minus_mu_d": "mu_s_mean"}  # drawn name -> the scene field it gives
DRAWABLE = ("mu_d", "mu_s_mean", "mu_s_minus_mu_d", "sigma_mu", "xi", "n_sliders",
            "spring_length", "initial_forces")
MATERIAL = ("mu_d", "mu_s_mean", "sigma_mu", "xi", "n_sliders",
            "initial_forces")  # always in the file (the last: the preparation)
INTEGERS = ("n_sliders",)  # drawn parameters that are integers (a choice of integers)
MAX_REALISATIONS = 10**7  # rows of one file: the plan is drawn in memory on every rank
PLAN_BYTES_PER_ROW = 160  # the design, every parameter, seed, order and flags of a row
PLAN_MEMORY_SHARE = 0.5  # of the memory available, at most, for the plans of one node
PRIOR_KEYS = ("realisations", "design", "seed", "ceiling_step", "ceiling_k")
DEFAULT_CEILING_STEP = 0.01
DEFAULT_CEILING_K = 8


class PriorError(UsageError, ValueError):
    """A bad prior file: one line naming the table, the parameter or the row (exit status 2)."""

    def __init__(self, message: str, code: int = 2):
        super().__init__(message, code)


# ---------------------------------------------------------------------------
# the prior: marginals, design, rows
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Marginal:
    """One parameter's law: ``kind`` in ("uniform", "loguniform", "choice", "fixed").

    ``values`` are the bounds (uniform, loguniform), the choices, or the
    fixed value; ``zero`` the weight of an atom at 0 (uniform, loguniform);
    ``weights`` the relative weights of the choices (equal if empty).
    """

    name: str
    kind: str
    values: tuple
    zero: float = 0.0
    weights: tuple = ()

    @property
    def drawn(self) -> bool:
        """True unless the value is fixed."""
        return self.kind != "fixed"

    def ppf(self, u: np.ndarray) -> np.ndarray:
        """The values at unit quantiles ``u`` (the inverse CDF)."""
        from scipy import stats

        u = np.asarray(u, dtype=np.float64)
        if self.kind == "fixed":
            return np.full(u.shape, self.values[0])
        if self.kind == "choice":
            w = np.asarray(self.weights or [1.0] * len(self.values), dtype=np.float64)
            edges = np.cumsum(w)[:-1] / w.sum()
            return np.asarray(self.values)[np.searchsorted(edges, u, side="right")]
        a, b = self.values
        rest = np.clip((u - self.zero) / (1.0 - self.zero), 0.0, 1.0)
        law = (stats.uniform(a, b - a) if self.kind == "uniform" else stats.loguniform(a, b))
        return np.where(u < self.zero, 0.0, law.ppf(rest))

    def support(self) -> tuple[float, float]:
        """Smallest and largest value the law gives (numbers only)."""
        vals = list(self.values) + ([0.0] if self.zero > 0 else [])
        return min(vals), max(vals)


def _check_number(where: str, value) -> None:
    """A drawn or fixed value must be a finite number (not a boolean, not NaN)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise PriorError(f"{where}: {value!r} is not a number (true and false are not numbers)")
    if not math.isfinite(value):
        raise PriorError(f"{where}: {value!r} is not a finite number")


def _check_values(name: str, kind: str, values: list) -> None:
    """The values of a fixed parameter or a choice: names for ``initial_forces``, finite
    numbers otherwise, integers for ``INTEGERS``."""
    where = f"[parameters] {name}"
    if name == "initial_forces":
        if not all(isinstance(v, str) for v in values):
            raise PriorError(f"{where}: give names (the preparations), not {values!r}")
        return
    for v in values:
        _check_number(where, v)
        if name in INTEGERS and not isinstance(v, int):
            raise PriorError(f"{where} = {v!r}: {name} is an integer; give integers "
                             "(a number or choice = [..])")


def parse_marginal(name: str, spec) -> Marginal:
    """One ``[parameters]`` entry: a number, a name, or a table with one distribution."""
    where = f"[parameters] {name}"
    if isinstance(spec, (bool, int, float, str)):
        _check_values(name, "fixed", [spec])
        return Marginal(name, "fixed", (spec,))
    if not isinstance(spec, dict):
        raise PriorError(f"{where}: give a number or a table such as {{ uniform = [a, b] }}")
    kinds = [k for k in spec if k not in ("zero", "weights")]
    unknown = [k for k in kinds if k not in DISTRIBUTIONS]
    if unknown:
        raise PriorError(f"{where}: unknown distribution {unknown[0]!r}; allowed are "
                         f"{DISTRIBUTIONS} (and zero = p for an atom at 0)")
    if len(kinds) != 1:
        raise PriorError(f"{where}: give exactly one distribution of {DISTRIBUTIONS}")
    kind = kinds[0]
    values = spec[kind]
    if not isinstance(values, list) or not values:
        raise PriorError(f"{where}: {kind} needs a non-empty list")
    zero = spec.get("zero", 0.0)
    if isinstance(zero, bool) or not isinstance(zero, (int, float)) or not 0.0 <= zero < 1.0:
        raise PriorError(f"{where}: zero = {zero!r} must be a weight in [0, 1)")
    if kind == "choice":
        if zero:
            raise PriorError(f"{where}: zero = p goes with uniform or loguniform; put 0 among "
                             "the choices instead")
        _check_values(name, kind, values)
        return Marginal(name, kind, tuple(values), weights=_choice_weights(where, spec, values))
    if "weights" in spec:
        raise PriorError(f"{where}: weights = [..] goes with choice = [..]")
    if name in INTEGERS or name == "initial_forces":
        raise PriorError(f"{where}: a {kind} law draws real numbers; {name} takes "
                         f"{'integers' if name in INTEGERS else 'names'}: give choice = [..]")
    if len(values) != 2 or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                   and math.isfinite(v) for v in values):
        raise PriorError(f"{where}: {kind} needs [low, high], two finite numbers")
    a, b = float(values[0]), float(values[1])
    if not a < b:
        raise PriorError(f"{where}: {kind} = [{a!r}, {b!r}] is an empty range (need low < high)")
    if kind == "loguniform" and a <= 0:
        raise PriorError(f"{where}: loguniform = [{a!r}, {b!r}] needs 0 < low")
    return Marginal(name, kind, (a, b), float(zero))


def _choice_weights(where: str, spec: dict, values: list) -> tuple:
    """The ``weights`` of a choice: one positive finite number per choice (none: equal)."""
    if "weights" not in spec:
        return ()
    w = spec["weights"]
    if not isinstance(w, list) or len(w) != len(values):
        raise PriorError(f"{where}: weights needs a list of {len(values)} numbers, one per choice")
    for v in w:
        _check_number(f"{where} weights", v)
        if v <= 0:
            raise PriorError(f"{where}: weights = {w!r} must all be > 0")
    return tuple(float(v) for v in w)


@dataclass
class Prior:
    """A parsed prior file: the base scene, the marginals, the design and the rows' settings."""

    spec: dict
    realisations: int
    design: str
    base_seed: int
    base_scene: Any
    marginals: dict
    ceiling_step: float
    ceiling_k: int
    digest: str = ""
    where: str = "prior"
    _values: dict | None = field(default=None, repr=False)

    @property
    def drawn(self) -> list[str]:
        """The names of the drawn parameters, in the design's column order."""
        return sorted(n for n, m in self.marginals.items() if m.drawn)

    def unit_design(self, n: int | None = None) -> np.ndarray:
        """(n, d) points in the unit cube (n: the prior's realisations), seeded by ``base_seed``."""
        from scipy.stats import qmc

        n = self.realisations if n is None else n
        d = len(self.drawn)
        if d == 0:
            return np.zeros((n, 0))
        if self.design == "sobol":
            with warnings.catch_warnings():  # balance needs n = 2^m; the points are valid anyway
                warnings.simplefilter("ignore", UserWarning)
                return qmc.Sobol(d, scramble=True, rng=self.base_seed).random(n)
        if self.design == "latin":
            return qmc.LatinHypercube(d, rng=self.base_seed).random(n)
        return np.random.default_rng(self.base_seed).random((n, d))

    def values(self, n: int | None = None) -> dict[str, np.ndarray]:
        """Every parameter per row (drawn, fixed and derived), (n,) each."""
        if n is None and self._values is not None:
            return self._values
        out = self.values_at(self.unit_design(n))
        if n is None:
            self._values = out
        return out

    def values_at(self, u: np.ndarray) -> dict[str, np.ndarray]:
        """Every parameter (drawn, fixed and derived) at the points ``u`` (rows, drawn) of the unit cube."""
        rows = u.shape[0]
        out = {name: self.marginals[name].ppf(u[:, j]) for j, name in enumerate(self.drawn)}
        for name, m in self.marginals.items():
            if not m.drawn:
                out[name] = m.ppf(np.zeros(rows))
        for name in MATERIAL:
            if name not in out and not (name == "mu_s_mean" and "mu_s_minus_mu_d" in out):
                out[name] = np.full(rows, getattr(self.base_scene, name))
        if "mu_s_minus_mu_d" in out:
            out["mu_s_mean"] = out["mu_d"] + out["mu_s_minus_mu_d"]
        return out

    def seed(self, r: int) -> int:
        """Row ``r``'s scene seed."""
        from ..keyed_random import realisation_seed

        return realisation_seed(self.base_seed, r)

    def scene(self, r: int):
        """Row ``r``'s scene (a SceneError names the parameter)."""
        v = self.values()
        changes = {}
        for name, arr in v.items():
            if name in DERIVED:
                continue
            x = arr[r]
            changes[name] = (int(x) if name == "n_sliders" else str(x) if name == "initial_forces"
                             else float(x))
        return self.base_scene.replace(seed=self.seed(r), **changes)

    def check_rows(self):
        """Build and check every row's scene (one at a time: none is kept); the first bad one
        raises PriorError naming row and parameter.  Returns the scene of the largest chain."""
        from ..parts.checks import SceneError

        largest = None
        for r in range(self.realisations):
            try:
                scene = self.scene(r)
            except SceneError as exc:
                raise PriorError(f"{self.where}: row {r}: {exc}") from None
            if largest is None or scene.n_sliders > largest.n_sliders:
                largest = scene
        return largest

    def seeds(self) -> np.ndarray:
        """Every row's scene seed (``seed(r)`` of each), uint32."""
        return realisation_seeds(self.base_seed, 0, self.realisations)

    def ceiling_alpha(self) -> np.ndarray:
        """The ceiling's grid: multiples of ``ceiling_step`` up to the prior's largest
        atan(mu_s_mean) + a step: the top of the law's support, so that the grid depends
        neither on the draws nor on their number (no row is drawn)."""
        m = self.marginals
        if "mu_s_mean" in m:
            mu_s_top = m["mu_s_mean"].support()[1]
        elif "mu_s_minus_mu_d" in m:
            mu_d_top = m["mu_d"].support()[1] if "mu_d" in m else self.base_scene.mu_d
            mu_s_top = mu_d_top + m["mu_s_minus_mu_d"].support()[1]
        else:
            mu_s_top = self.base_scene.mu_s_mean
        top = float(np.arctan(mu_s_top)) + self.ceiling_step
        n = int(math.ceil(top / self.ceiling_step))
        return np.round(self.ceiling_step * np.arange(1, n + 1), 12)

    def storage_types(self) -> dict[str, np.dtype]:
        """The stored type of each parameter (strings: an index into the choices)."""
        out = {}
        for name, arr in self.values().items():
            out[name] = (np.dtype(np.int8) if arr.dtype.kind in "US" else
                         np.dtype(np.int64) if name == "n_sliders" else np.dtype(np.float64))
        return out

    def choices(self) -> dict[str, list]:
        """The choices of the string-valued parameters (stored as indices)."""
        m = self.marginals.get("initial_forces")
        return {"initial_forces": list(m.values) if m else [self.base_scene.initial_forces]}


def parse_prior(data: dict, where: str = "prior") -> Prior:
    """A ``Prior`` from the TOML tables; every error is one line starting with ``where``."""
    from ..parts.checks import SceneError
    from ..scene import Scene

    unknown = sorted(set(data) - {"prior", "scene", "parameters"})
    if unknown:
        raise PriorError(f"{where}: unknown table [{unknown[0]}]; allowed are [prior], [scene], "
                         "[parameters]")
    head = data.get("prior", {})
    bad = sorted(set(head) - set(PRIOR_KEYS))
    if bad:
        raise PriorError(f"{where}: unknown key {bad[0]!r} in [prior]; allowed are {PRIOR_KEYS}")
    R = head.get("realisations")
    if isinstance(R, bool) or not isinstance(R, int) or R < 1:
        raise PriorError(f"{where}: [prior] realisations = {R!r} must be an integer >= 1")
    if R > MAX_REALISATIONS:
        raise PriorError(f"{where}: [prior] realisations = {R} is more than one file holds "
                         f"(at most {MAX_REALISATIONS:.0e}: the plan alone would need "
                         f"{R * PLAN_BYTES_PER_ROW / 1e9:.3g} GB of memory on every rank); split "
                         "it into several priors with different seeds")
    design = head.get("design", "sobol")
    if design not in DESIGNS:
        raise PriorError(f"{where}: [prior] design = {design!r} must be one of {DESIGNS}")
    seed = head.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise PriorError(f"{where}: [prior] seed = {seed!r} must be an integer in [0, 2**32)")
    step = head.get("ceiling_step", DEFAULT_CEILING_STEP)
    if isinstance(step, bool) or not isinstance(step, (int, float)) or not 0 < step <= 0.5:
        raise PriorError(f"{where}: [prior] ceiling_step = {step!r} must be in (0, 0.5] rad")
    k = head.get("ceiling_k", DEFAULT_CEILING_K)
    if isinstance(k, bool) or not isinstance(k, int) or k < 1:
        raise PriorError(f"{where}: [prior] ceiling_k = {k!r} must be an integer >= 1")
    scene_values = dict(data.get("scene", {}))
    params = data.get("parameters", {})
    if not isinstance(params, dict) or not params:
        raise PriorError(f"{where}: [parameters] is missing or empty: nothing is drawn")
    for name in params:
        if name not in DRAWABLE:
            import difflib

            close = difflib.get_close_matches(name, DRAWABLE, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise PriorError(f"{where}: unknown parameter {name!r}{hint}; allowed are {DRAWABLE}")
        if name in scene_values or DERIVED.get(name) in scene_values:
            raise PriorError(f"{where}: {name!r} is both in [scene] and in [parameters]")
    if "mu_s_minus_mu_d" in params and "mu_s_mean" in params:
        raise PriorError(f"{where}: give mu_s_mean or mu_s_minus_mu_d in [parameters], not both")
    scene_values.setdefault("mode", "explore")
    if scene_values.get("record", "displacements") != "displacements":
        raise PriorError(f"{where}: [scene] record = {scene_values['record']!r}: a prior ensemble "
                         "keeps the catalogues, which need record = 'displacements'")
    scene_values["record"] = "displacements"
    if "seed" in scene_values:
        raise PriorError(f"{where}: [scene] seed: the rows' seeds come from [prior] seed")
    try:
        base = Scene.from_dict(scene_values)
    except SceneError as exc:
        raise PriorError(f"{where}: [scene] {exc}") from None
    if not base.loading.drive_is_angle:
        raise PriorError(f"{where}: [scene] loading = {base.loading.name!r}: a prior ensemble tilts")
    try:
        marginals = {name: parse_marginal(name, spec) for name, spec in params.items()}
    except PriorError as exc:
        raise PriorError(f"{where}: {exc}") from None
    _check_friction_ranges(marginals, base, where)
    n_top = marginals["n_sliders"].support()[1] if "n_sliders" in marginals else base.n_sliders
    if k > n_top:
        raise PriorError(f"{where}: [prior] ceiling_k = {k} is more than the largest chain "
                         f"(n_sliders up to {n_top}): a chain has one distance to threshold per "
                         "slider; give ceiling_k <= n_sliders")
    spec = {"prior": {"realisations": R, "design": design, "seed": seed, "ceiling_step": step,
                      "ceiling_k": k}, "scene": scene_values, "parameters": params}
    digest = hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:16]
    return Prior(spec, R, design, seed, base, marginals, float(step), k, digest, where)


def _check_friction_ranges(marginals: dict, base, where: str) -> None:
    """Refuse up front a prior whose ranges allow mu_d >= mu_s_mean (one line)."""
    if "mu_s_minus_mu_d" in marginals:
        low = marginals["mu_s_minus_mu_d"].support()[0]
        if low <= 0:
            raise PriorError(f"{where}: [parameters] mu_s_minus_mu_d reaches {low!r} <= 0, which "
                             "gives mu_d >= mu_s_mean")
        return
    d_hi = marginals["mu_d"].support()[1] if "mu_d" in marginals else base.mu_d
    s_lo = marginals["mu_s_mean"].support()[0] if "mu_s_mean" in marginals else base.mu_s_mean
    if d_hi >= s_lo:
        raise PriorError(f"{where}: [parameters] mu_d up to {d_hi!r} and mu_s_mean from {s_lo!r} "
                         "allow mu_d >= mu_s_mean; draw mu_s_minus_mu_d > 0 instead")


def load_prior(path, data: bytes | None = None) -> Prior:
    """The prior of a TOML file (see the module's docstring); PriorError on any bad entry.
    ``data``: the file's bytes, when they were read elsewhere (MPI rank 0)."""
    from ..scene import read_toml

    where = f"prior file {str(path)!r}"
    return parse_prior(read_toml(path, where, PriorError, data), where)


def check_plan_memory(prior: Prior, node_ranks: int = 1) -> None:
    """Refuse, before anything is drawn, a prior whose plan (``PLAN_BYTES_PER_ROW`` a row on
    each of the ``node_ranks`` ranks of this node) would not fit in ``PLAN_MEMORY_SHARE`` of
    the memory available."""
    from ..scene import available_memory

    need = prior.realisations * PLAN_BYTES_PER_ROW * node_ranks
    free = available_memory()
    if free is not None and need > PLAN_MEMORY_SHARE * free:
        raise PriorError(f"{prior.where}: [prior] realisations = {prior.realisations}: planning "
                         f"them needs about {need / 1e9:.3g} GB of memory on this node "
                         f"({node_ranks} rank(s)), {free / 1e9:.3g} GB are available; split the "
                         "prior into several with different seeds")


# ---------------------------------------------------------------------------
# one row
# ---------------------------------------------------------------------------
def smallest_distances(distance: np.ndarray, k: int) -> np.ndarray:
    """The ``k`` smallest of ``distance``, increasing (NaN-padded when there are fewer)."""
    out = np.full(k, np.nan)
    m = min(k, distance.size)
    out[:m] = np.sort(np.partition(distance, m - 1)[:m]) if m else []
    return out


def run_with_ceiling(scene, grid: np.ndarray, k: int, backend: str = "fortran", progress=None,
                     tilt=None):
    """Tilt ``scene`` to its end, cut at every angle of ``grid``: the catalogue, the ceiling, the pieces.

    Returns ``(catalogue, ceiling, pieces)``: the events (the same as one
    uninterrupted tilt), the (G, k) smallest distances ``mu_s,n cos(alpha) -
    |F_n|`` at each grid angle (NaN at and past the end of the run) and the
    ``TiltResult`` of every piece (the last one has the run's status and
    alpha_c).  ``tilt(scene, backend, progress, state=...)`` runs a piece
    (default: ``sliders.driver.run``).
    """
    from ..io.catalogue import Catalogue

    if tilt is None:
        from ..driver import run as plain

        def tilt(sc, be, pr, state=None):
            return plain(sc, be, state=state, progress=pr)

    ceiling = np.full((grid.size, k), np.nan)
    pieces = []
    state = None
    for j, g in enumerate(grid):
        if g >= scene.alpha_max:
            break
        piece = tilt(scene.replace(alpha_max=float(g)), backend, progress, state=state)
        pieces.append(piece)
        if piece.status != "alpha_max":
            break
        force = piece.force_at([g])[0]
        ceiling[j] = smallest_distances(piece.final.mu_s * math.cos(g) - np.abs(force), k)
        state = piece.final
    if not pieces or pieces[-1].status == "alpha_max" and pieces[-1].scene.alpha_max < scene.alpha_max:
        pieces.append(tilt(scene, backend, progress, state=state))
    cats = [Catalogue.from_result(p) for p in pieces]
    cat = Catalogue(*(np.concatenate([getattr(c, name) for c in cats])
                      for name in ("alpha", "size", "displacement", "first", "last")))
    return cat, ceiling, pieces


def compute_prior_row(prior: Prior, r: int, backend: str, grid: np.ndarray, progress=None) -> dict:
    """Row ``r`` of the prior file: its catalogue, parameters, alpha_c, status and ceiling."""
    from ..io.prior_file import PARAMETERS

    started = time.perf_counter()
    scene = prior.scene(r)

    def piece(sc, be, pr, state=None):
        return tilt_interruptibly(sc, be, pr, state=state)

    cat, ceiling, pieces = run_with_ceiling(scene, grid, prior.ceiling_k, backend, progress, piece)
    last = pieces[-1]
    row: dict[str, Any] = {
        "status": status_code(last.status),
        "alpha_c": float(last.alpha_c),
        "n_events": len(cat),
        "slider_steps": int(sum(p.total_slider_steps for p in pieces)),
        "ceiling_distance": ceiling,
        "events": catalogue_events(cat),
    }
    choices = prior.choices()
    for name, arr in prior.values().items():
        x = arr[r]
        row[PARAMETERS + name] = choices[name].index(str(x)) if name in choices else x
    row["wall_time"] = time.perf_counter() - started
    return row


# ---------------------------------------------------------------------------
# command line and run
# ---------------------------------------------------------------------------
def build_parser(rank: int = 0) -> CommandParser:
    """The command line of ``python -m sliders.prior`` (help printed by rank 0 only)."""
    p = input_command_parser(
        "python -m sliders.prior",
        "Run a prior ensemble: every row draws its material from the prior (a seeded "
        "scipy.stats.qmc design) and keeps the catalogue of every event up to the avalanche and "
        "the ceiling, over MPI ranks with dynamic scheduling, into one HDF5 file.",
        rank, "prior", "PRIOR.toml", "prior file: [prior], [scene], [parameters]")
    p.set_defaults(storage="gather")  # ragged events: rank 0 writes (sliders.io.prior_file)
    return p


def plan_prior(args, prior: Prior) -> RunPlan:
    """Rank 0, holding the claim: a new file or a resume of the same prior."""

    out = args.out
    backend = args.backend or DEFAULT_BACKEND
    head = resume_header(args, read_prior_header)
    resume = head is not None
    R = prior.realisations
    done = np.zeros(R, dtype=bool)
    attrs = None
    if resume:
        attrs = head["attrs"]
        if attrs.get("prior_digest") != prior.digest:
            raise UsageError(f"--resume: {out!r} holds a different prior; start a new file or "
                             "resume with the prior file that made it")
        if args.backend is not None and attrs["backend"] != args.backend:
            raise UsageError(f"--resume: {out!r} was computed with --backend {attrs['backend']}")
        backend = attrs["backend"]
        done = head["done"]
        if head["damaged"]:
            sys.stderr.write(f"prior: note: {len(head['damaged'])} finished row(s) of {out} fail "
                             "their checksums; recomputing them\n")
    if attrs is None:
        attrs = prior_attributes(prior.spec, prior.digest, prior.base_seed, R, backend,
                                 sorted(prior.values()), prior.ceiling_k)
        attrs["parameter_choices"] = json.dumps(prior.choices())
    layout = prior_layout(R, prior.seeds(), prior.storage_types(), prior.ceiling_alpha(),
                          prior.ceiling_k, attrs)
    # the largest chains first (cost ~ N^2), so that the last rows to finish are short ones
    order = np.argsort(-np.asarray(prior.values()["n_sliders"], dtype=np.int64), kind="stable")
    pending = order[~done[order]]
    return RunPlan(layout, backend, resume, done, pending)


def prepare_prior(args, inputs, world) -> Prior:
    """The prior, every row's scene and the memory checked (every rank, rank 0's bytes)."""
    from ..io.storage import check_room
    from ..scene import check_memory

    check_run_options(args, world.comm, world.have_mpi)
    prior = load_prior(args.prior, inputs[args.prior])
    check_plan_memory(prior, world.node_ranks)  # before any row is drawn
    if not (args.resume and os.path.exists(args.out)):
        # a count no disk could hold is refused before any row is drawn; a row holds at
        # least its ceiling (G x K distances) and a few scalars, its events come on top
        check_room(args.out, prior.realisations,
                   8 * prior.ceiling_alpha().size * prior.ceiling_k + 256)
    check_memory(prior.check_rows(), world.node_ranks)  # every row, before anything runs
    return prior


def run_prior(comm, args, prior, plan: RunPlan) -> int:
    """Create or open the file, serve the rows, report (every rank)."""
    handler = open_output(comm, args, plan, HANDLERS, "gather")
    if handler is None:
        return 1
    grid = plan.layout.grids["ceiling_alpha"]

    def compute(r: int, progress):
        return compute_prior_row(prior, int(r), plan.backend, grid, progress)

    ctx = {"compute_row": compute, "interval": args.progress_interval, "quiet": args.quiet,
           "label": ("prior", "rows")}
    if comm.rank == 0 and not args.quiet:
        sys.stderr.write(f"prior: {'resuming' if plan.resume else 'starting'} "
                         f"{plan.pending.size} of {plan.total} rows (backend {plan.backend}) "
                         f"on {comm.size} rank(s) -> {args.out}\n")
        sys.stderr.flush()
    return serve_rows(comm, handler, plan.pending, plan.total, ctx, args.out,
                      lambda: write_view(args.out, prior.base_scene.to_dict()))


def main(argv: list[str] | None = None) -> int:
    """``python -m sliders.prior PRIOR.toml --out FILE.h5``: run (or resume) a prior ensemble; the exit code."""
    return run_planned(RunCommand("prior", build_parser, prepare_prior, plan_prior, run_prior,
                                   input_option=("prior", "prior file")), argv)


if __name__ == "__main__":
    sys.exit(main())
