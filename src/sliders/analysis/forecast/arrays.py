"""Fitted forecasters as the plain arrays a forecast reads, and back.

``to_arrays`` runs once on fitted forecasters (at the end of ``train``): each
one's parameters and fitted state become a JSON tree of plain values whose
arrays are named and kept apart, and every fitted part of scikit-learn or
crepes becomes the arrays its ``predict`` reads (``evaluators``: the trees of
each quantile regressor, the conformal residuals, the domain check's
detectors).  ``estimator_of`` builds a forecaster back from its tree and
its arrays, each class from a closed table (``classes``), and its
``check_fitted`` is run (its declared fitted parts, every tree,
table and detector among them: ``integrity.check_fields``): no code of the
file, no scikit-learn.

A model file also carries reference forecasts: a few catalogues
(``reference_catalogues``, made here, deterministic) and what the fitted
forecasters gave for them before conversion (``reference_outputs``);
``check_references`` recomputes them from the built forecasters and refuses
the file when one differs by more than ``REFERENCE_TOLERANCE``.
"""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np

from ...io.catalogue import Catalogue
from .base import Forecaster
from .baselines import Climatology, ConditionedClimatology
from .domain import DomainCheck
from .evaluation import ACCURACY_FIELDS
from .estimator import param_names
from .evaluators import NoveltyDetector, QuantileTrees, ResidualTable
from .features import Cuts, feature_matrix
from .integrity import IntegrityError, check_fields, require
from .inverse_rate import LinearInverseRate, PointProcessInverseRate
from .learned import Learned, with_design
from .measurement import Measurement
from .physics import ModelBased

#: the kinds of fitted part kept as the arrays of an evaluator, by the tree's key
EVALUATORS = {"trees": QuantileTrees, "residuals": ResidualTable, "detector": NoveltyDetector}
#: the fitted objects of scikit-learn and crepes that the converter reads, by class name (so
#: that converting imports neither): the evaluator each becomes
FITTED = {"HistGradientBoostingRegressor": "trees", "ConformalPredictiveSystem": "residuals",
          "Pipeline": "detector"}
#: how far a recomputed reference forecast may lie from the one recorded (radians, or a
#: parameter on its learned scale), relative to the value when it is above 1
REFERENCE_TOLERANCE = 1e-12
#: a name of an array (and of the parts of the tree): letters, digits, '_' and '.'
NAME = re.compile(r"[A-Za-z0-9_.]{1,200}")
#: the columns of a reference catalogue, in ``Catalogue``'s order
CATALOGUE_COLUMNS = ("alpha", "size", "displacement", "first", "last")
#: the dtypes of the arrays: booleans, 64-bit integers, 64-bit floats
DTYPES = {"b": np.dtype(bool), "i": np.dtype("<i8"), "u": np.dtype("<i8"), "f": np.dtype("<f8")}


class ConversionError(ValueError):
    """A fitted object with no array form (one line naming it)."""


def classes(posterior: bool = True) -> dict:
    """``{name: class}`` of every estimator a model file holds (the only classes it may name);
    the posterior's only if ``posterior`` (its module imports scipy.stats, a second)."""
    known = [Climatology, ConditionedClimatology, DomainCheck, LinearInverseRate,
             PointProcessInverseRate, Learned, ModelBased]
    if posterior:
        from .posterior import ParameterPosterior

        known.append(ParameterPosterior)
    return {c.__name__: c for c in known}


def to_arrays(estimators: dict) -> tuple[dict, dict]:
    """``(tree, arrays)`` of fitted estimators ``{method: estimator}``: a JSON tree of their
    parameters and fitted state, whose arrays (``{name: array}``) it names."""
    arrays: dict = {}
    known = classes()
    wrong = next((m for m, e in estimators.items() if known.get(type(e).__name__) is not type(e)),
                 None)
    if wrong is not None:
        raise ConversionError(f"{wrong!r} holds a {type(estimators[wrong]).__name__}, not an "
                              "estimator of this package")
    tree = {m: _encode(e, _name(m), arrays, known) for m, e in estimators.items()}
    return tree, arrays


def _name(*parts) -> str:
    name = ".".join(str(p) for p in parts)
    if not NAME.fullmatch(name):
        raise ConversionError(f"{name!r} is not a name of an array (letters, digits, '_', '.')")
    return name


def _encode(value, name: str, arrays: dict, known: dict):
    if value is None or isinstance(value, (bool, str, np.bool_)):
        return value if not isinstance(value, np.bool_) else bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in DTYPES:
            raise ConversionError(f"{name}: an array of {value.dtype}, not of numbers")
        arrays[name] = np.ascontiguousarray(value, dtype=DTYPES[value.dtype.kind])
        return {"array": name}
    if isinstance(value, tuple):
        return {"tuple": [_encode(v, _name(name, i), arrays, known) for i, v in enumerate(value)]}
    if isinstance(value, list):
        return [_encode(v, _name(name, i), arrays, known) for i, v in enumerate(value)]
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value):
            raise ConversionError(f"{name}: a dict whose keys are not all strings")
        return {"dict": {k: _encode(v, _name(name, k), arrays, known) for k, v in value.items()}}
    kind = FITTED.get(type(value).__name__) or next(
        (k for k, c in EVALUATORS.items() if type(value) is c), None)
    if kind is not None:
        part = value if isinstance(value, EVALUATORS[kind]) else _evaluator(kind, value, name)
        for k, a in part.arrays().items():
            arrays[_name(name, k)] = a
        return {kind: name}
    if known.get(type(value).__name__) is type(value):
        return {"object": type(value).__name__,
                "state": {k: _encode(v, _name(name, k), arrays, known)
                          for k, v in vars(value).items()}}
    raise ConversionError(f"{name}: a {type(value).__name__} has no array form")


def _evaluator(kind: str, value, name: str):
    """The evaluator of a fitted scikit-learn or crepes object, checked to be of the form it
    reproduces."""
    if kind == "trees":
        ok = (value.loss == "quantile" and value.n_trees_per_iteration_ == 1
              and getattr(value, "is_categorical_", None) is None
              and all(len(it) == 1 and not it[0].nodes["is_categorical"].any()
                      for it in value._predictors))
    elif kind == "residuals":
        ok = value.mondrian and not value.normalized and isinstance(value.binned_alphas, tuple)
    else:
        steps = [type(s).__name__ for _, s in value.steps]
        lof = value.steps[-1][1]
        ok = (steps == ["SimpleImputer", "StandardScaler", "LocalOutlierFactor"]
              and value.steps[0][1].indicator_ is None and lof.novelty
              and lof.effective_metric_ == "euclidean")
    if not ok:
        raise ConversionError(f"{name}: a {type(value).__name__} of a form the evaluators do not "
                              "reproduce")
    part = EVALUATORS[kind].of(value)
    check_fields(part, name)
    return part


def _decode(node, arrays: dict, known: dict, used: set, where: str):
    if node is None or isinstance(node, (bool, int, float, str)):
        return node
    if isinstance(node, list):
        return [_decode(v, arrays, known, used, f"{where}.{i}") for i, v in enumerate(node)]
    require(isinstance(node, dict) and len(node) in (1, 2), f"{where}: not a part of a model")
    key = next(iter(node))
    if key == "tuple" and isinstance(node[key], list):
        return tuple(_decode(v, arrays, known, used, f"{where}.{i}")
                     for i, v in enumerate(node[key]))
    if key == "dict" and isinstance(node[key], dict):
        return {k: _decode(v, arrays, known, used, f"{where}.{k}") for k, v in node[key].items()}
    if key == "array" and isinstance(node[key], str):
        require(node[key] in arrays, f"array {node[key]!r} is missing")
        used.add(node[key])
        return arrays[node[key]]
    if key in EVALUATORS and isinstance(node[key], str):  # its arrays, checked by its owner
        return EVALUATORS[key].from_arrays(arrays, node[key], used)
    if key == "object" and set(node) == {"object", "state"}:
        cls = known.get(node["object"]) if isinstance(node["object"], str) else None
        require(cls is not None, f"{where}: names {str(node['object'])[:60]!r}, no estimator "
                                 "of this package")
        state = node["state"]
        require(isinstance(state, dict), f"{where}: a state that is not a table")
        params = set(param_names(cls))
        bad = next((k for k in state if not (isinstance(k, str) and k.isidentifier() and not
                    k.startswith("_") and (k in params or k.endswith("_")))), None)
        require(bad is None, f"{where}: {str(bad)[:60]!r} is neither a parameter nor a fitted "
                             f"part of a {cls.__name__}")
        obj = cls.__new__(cls)
        obj.__dict__.update({k: _decode(v, arrays, known, used, f"{where}.{k}")
                             for k, v in state.items()})
        return obj
    raise IntegrityError(f"{where}: not a part of a model")


# -- reference forecasts ------------------------------------------------------------------
def reference_catalogues() -> list:
    """``[(Catalogue, Measurement)]``: the catalogues a model file's reference forecasts are of.

    A pile's 150 events accelerating towards an avalanche near 31°, with
    displacements and movers, recorded perfectly; its angles and sizes only, the
    events of 2 sliders or more, a twentieth of a degree of angle error, a tenth
    missed; 40 events early in the tilt, sizes in an arbitrary unit; a pile
    of 50 sliders, told, at 12° with 6 events; and the first as a camera records it
    (displacements in its unit, positions as fractions of the pile's length, 100-300
    sliders told).
    """
    rng = np.random.default_rng(20261128)
    u = np.sort(rng.random(150))
    alpha = np.radians(31.0 - 31.0 * np.exp(-3.0 * u))
    size = np.maximum(1, np.round(rng.pareto(1.5, 150) + 1)).astype(np.int64)
    first = rng.integers(0, 150, 150)
    last = np.minimum(first + size - 1 + rng.integers(0, 3, 150), 199)
    disp = size * (1e-3 + 1e-3 * rng.random(150))
    full = Catalogue(alpha, size, disp, first, last, tilt_now=float(alpha[-1]) + 1e-3)
    keep = size >= 2
    blind = Catalogue(alpha[keep], size[keep], disp[keep], first[keep], last[keep],
                      tilt_now=full.tilt_now).angles_and_sizes()
    early = Catalogue(alpha[:40], 0.37 * size[:40], disp[:40], first[:40], last[:40],
                      tilt_now=float(alpha[39]) + 0.01).angles_and_sizes()
    few = Catalogue(alpha[:6], size[:6], disp[:6], first[:6], last[:6],
                    tilt_now=math.radians(12.0))
    camera = Catalogue(alpha, size, 37.0 * disp, (first + 0.5) / 200, (last + 0.5) / 200,
                       tilt_now=full.tilt_now)
    return [(full, Measurement()),
            (blind, Measurement(angle_resolution=math.radians(0.05), min_size=2.0,
                                missed_fraction=0.1)),
            (early, Measurement(size_unit="arbitrary", min_size=0.37)),
            (few, Measurement(n_sliders=50)),
            (camera, Measurement(angle_resolution=math.radians(0.05), n_sliders=100,
                                 n_sliders_high=300, displacement_unit="arbitrary",
                                 position_unit="fraction"))]


def reference_cuts(cases=None):
    """The ``features.Cuts`` of ``cases`` (default: ``reference_catalogues``), each measured as
    it was."""
    cases = reference_catalogues() if cases is None else cases
    return Cuts([c for c, _ in cases], np.full(len(cases), -1, dtype=np.int64),
                measurement=[m for _, m in cases])


def reference_outputs(estimators: dict, cuts=None) -> dict:
    """``{name: array}`` of what each estimator gives for the reference catalogues: a
    forecaster's quantiles, fallbacks and levels (a learned one's regressors' outputs too, and
    its domain verdicts if it has a domain check); the posterior's quantiles and domain
    verdicts."""
    cuts = reference_cuts() if cuts is None else cuts
    if "features" not in cuts.cache and any(isinstance(e, Learned) for e in estimators.values()):
        cuts = replace(cuts, cache={**cuts.cache, "features": feature_matrix(cuts)})
    out = {}
    for method, e in estimators.items():
        if isinstance(e, Forecaster):
            q, fb, lv = e.quantiles(cuts, levels=True)
            out.update({f"{method}.quantiles": q, f"{method}.fallback": fb,
                        f"{method}.levels": lv})
            if hasattr(e, "_raw_log_remaining"):  # every regressor's, not only those forecasts read
                out[f"{method}.raw"] = e._raw_log_remaining(cuts)
        else:
            out[f"{method}.quantiles"] = np.asarray(e.quantiles(cuts), dtype=np.float64)
        if hasattr(e, "domain"):
            out[f"{method}.inside"] = np.asarray(e.domain(cuts)[0], dtype=bool)
    return out


def check_references(estimators: dict, recorded: dict, cuts=None) -> None:
    """The reference forecasts recomputed from ``estimators`` against those ``recorded``;
    ``integrity.IntegrityError`` naming the first that differs by more than
    ``REFERENCE_TOLERANCE`` (or is missing)."""
    now = reference_outputs(estimators, cuts)
    for name in sorted(set(now) | set(recorded)):
        require(name in recorded and name in now, f"reference forecast {name!r} is " + (
            "of no estimator of the file" if name in recorded else "missing"))
        a, b = np.asarray(now[name], dtype=float), np.asarray(recorded[name], dtype=float)
        with np.errstate(invalid="ignore"):  # integers and booleans: equal
            require(a.shape == b.shape and (
                (np.abs(a - b) <= REFERENCE_TOLERANCE * np.maximum(1.0, np.abs(b)))
                | (a == b) | (np.isnan(a) & np.isnan(b))).all(),
                f"reference forecast {name!r} is not reproduced (the arrays give another "
                "forecast than the fitted forecasters did)")


def catalogue_arrays(cases) -> dict:
    """``{name: array}`` of catalogues and their measurements (``reference_catalogues``)."""
    cats = [c for c, _ in cases]
    ms = [m for _, m in cases]
    camera = any(c.first.dtype.kind == "f" for c in cats)  # positions as fractions: floats
    out = {f"catalogue.{col}": np.concatenate([np.asarray(getattr(c, col)) for c in cats])
           .astype(np.float64 if col in ("alpha", "size", "displacement") or camera else np.int64)
           for col in CATALOGUE_COLUMNS}
    out["catalogue.start"] = np.concatenate([[0], np.cumsum([len(c) for c in cats])]).astype(np.int64)
    out["catalogue.tilt_now"] = np.array([c.tilt_now for c in cats], dtype=np.float64)
    out["catalogue.measurement"] = np.array([[m.angle_resolution, m.min_size, m.missed_fraction,
                                              float(m.size_unit == "arbitrary"),
                                              float(m.n_sliders or 0), float(m.n_sliders_high or 0),
                                              float(m.displacement_unit == "arbitrary"),
                                              float(m.position_unit == "fraction")] for m in ms])
    return out


def model_file_parts(estimators: dict, provenance: dict) -> tuple[dict, dict]:
    """``(header, arrays)`` of a model file of fitted ``estimators`` (``{method: estimator}``,
    fitted with scikit-learn and crepes or built from arrays): their array form, and the
    reference forecasts they give for ``reference_catalogues``."""
    cases = reference_catalogues()
    content, arrays = to_arrays(estimators)
    refs = reference_outputs(estimators, reference_cuts(cases))
    arrays.update({f"reference.{k}": np.ascontiguousarray(v, dtype=DTYPES[np.asarray(v).dtype.kind])
                   for k, v in {**catalogue_arrays(cases), **refs}.items()})
    return {"content": content, "provenance": provenance}, arrays


def estimator_of(node: dict, method: str, arrays: dict):
    """The estimator ``method`` of ``to_arrays``'s tree ``node`` (of a class of ``classes``),
    built from its ``arrays`` (every one read by a part), its ``check_fitted`` run and its
    expected-accuracy table checked (``evaluation.ACCURACY_FIELDS``):
    ``integrity.IntegrityError`` naming the first part not of the form ``to_arrays`` writes."""
    require(isinstance(node, dict) and "object" in node, f"{method!r} holds no estimator")
    used: set = set()
    estimator = _decode(node, arrays, classes(node["object"] == "ParameterPosterior"), used,
                        method)
    unread = sorted(set(arrays) - used)
    require(not unread, f"array {unread[0] if unread else ''!r} is read by no part")
    check_fields(estimator, method)
    check_fields(estimator, method, ACCURACY_FIELDS)
    return estimator


def references_of(arrays: dict) -> tuple[dict, Cuts]:
    """``(recorded, cuts)``: a model file's reference forecasts (``reference.*``) by name, and
    the cuts of ``reference_catalogues`` (features made once), which must be the catalogues the
    file carries (the first of them; five measurement columns in a file before a camera's)."""
    refs = {k[len("reference."):]: v for k, v in arrays.items() if k.startswith("reference.")}
    stored = {k: v for k, v in refs.items() if k.startswith("catalogue.")}
    cases = reference_catalogues()[:stored.get("catalogue.tilt_now", np.zeros(0)).size]
    require(cases, "it carries no reference catalogues (their tilts reached)")
    made = catalogue_arrays(cases)
    m = made["catalogue.measurement"]
    if stored.get("catalogue.measurement", m).shape[-1:] == (5,) and not m[:, 5:].any():
        made["catalogue.measurement"] = m[:, :5]
    require(set(stored) == set(made) and all(np.array_equal(v, made[k]) for k, v in stored.items()),
            "the reference catalogues are not those of this version's reference forecasts")
    return ({k: v for k, v in refs.items() if k not in stored},
            with_design(reference_cuts(cases), "camera"))
