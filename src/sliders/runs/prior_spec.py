"""A prior ensemble's specification: the prior file read, checked, and its rows' materials drawn.

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

``python -m sliders.prior`` (``runs.prior``) runs its rows.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .command import UsageError
from .rows import realisation_seeds
from ..keyed_random import realisation_seed
from ..parts import materials
from ..parts.checks import SceneError
from ..scene import Scene, available_memory, read_toml

DESIGNS = ("sobol", "latin", "random")
DISTRIBUTIONS = ("uniform", "loguniform", "choice")
DERIVED = materials.DERIVED  # drawn name -> the scene field it gives
GAP = materials.MU_S_GAP  # mu_s_mean - mu_d, drawn instead of mu_s_mean
#: the scene fields of the materials (parts.materials), in the records' order
MATERIAL_FIELDS = tuple(m.derived or m.scene_key for m in materials.MATERIALS)
DRAWABLE = (*(n for m in materials.MATERIALS for n in ((m.derived, m.name) if m.derived
                                                       else (m.scene_key,))),
            "spring_length", "initial_forces")
MATERIAL = (*MATERIAL_FIELDS, "initial_forces")  # always in the file (the last: the preparation)
INTEGERS = tuple(m.scene_key for m in materials.MATERIALS
                 if m.integer)  # drawn parameters that are integers (a choice of integers)
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
            if name not in out and not any(d == name and g in out for g, d in DERIVED.items()):
                out[name] = np.full(rows, getattr(self.base_scene, name))
        for gap, name in DERIVED.items():
            if gap in out:
                out[name] = materials.derive(gap, out)
        return out

    def seed(self, r: int) -> int:
        """Row ``r``'s scene seed."""
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
        elif GAP in m:
            mu_d_top = m["mu_d"].support()[1] if "mu_d" in m else self.base_scene.mu_d
            mu_s_top = materials.mu_s_mean(mu_d_top, m[GAP].support()[1])
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
            close = difflib.get_close_matches(name, DRAWABLE, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise PriorError(f"{where}: unknown parameter {name!r}{hint}; allowed are {DRAWABLE}")
        if name in scene_values or DERIVED.get(name) in scene_values:
            raise PriorError(f"{where}: {name!r} is both in [scene] and in [parameters]")
    for gap, name in DERIVED.items():
        if gap in params and name in params:
            raise PriorError(f"{where}: give {name} or {gap} in [parameters], not both")
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
    if GAP in marginals:
        low = marginals[GAP].support()[0]
        if low <= 0:
            raise PriorError(f"{where}: [parameters] {GAP} reaches {low!r} <= 0, which "
                             "gives mu_d >= mu_s_mean")
        return
    d_hi = marginals["mu_d"].support()[1] if "mu_d" in marginals else base.mu_d
    s_lo = marginals["mu_s_mean"].support()[0] if "mu_s_mean" in marginals else base.mu_s_mean
    if d_hi >= s_lo:
        raise PriorError(f"{where}: [parameters] mu_d up to {d_hi!r} and mu_s_mean from {s_lo!r} "
                         f"allow mu_d >= mu_s_mean; draw {GAP} > 0 instead")


def load_prior(path, data: bytes | None = None) -> Prior:
    """The prior of a TOML file (see the module's docstring); PriorError on any bad entry.
    ``data``: the file's bytes, when they were read elsewhere (MPI rank 0)."""
    where = f"prior file {str(path)!r}"
    return parse_prior(read_toml(path, where, PriorError, data), where)


def check_plan_memory(prior: Prior, node_ranks: int = 1) -> None:
    """Refuse, before anything is drawn, a prior whose plan (``PLAN_BYTES_PER_ROW`` a row on
    each of the ``node_ranks`` ranks of this node) would not fit in ``PLAN_MEMORY_SHARE`` of
    the memory available."""
    need = prior.realisations * PLAN_BYTES_PER_ROW * node_ranks
    free = available_memory()
    if free is not None and need > PLAN_MEMORY_SHARE * free:
        raise PriorError(f"{prior.where}: [prior] realisations = {prior.realisations}: planning "
                         f"them needs about {need / 1e9:.3g} GB of memory on this node "
                         f"({node_ranks} rank(s)), {free / 1e9:.3g} GB are available; split the "
                         "prior into several with different seeds")
