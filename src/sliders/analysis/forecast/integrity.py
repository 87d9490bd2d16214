"""A fitted estimator read from a file, checked as data before it forecasts.

A model file's arrays are whatever the file holds: a child index past the
nodes reads outside them, a NaN leaf gives a NaN forecast.  Each class a model
file may hold declares its fitted parts (``FIELDS``: attribute -> ``Spec``)
and ``check_fields`` walks them, then runs the class's ``check_consistent``
for what a declaration cannot say (a tree's nodes forming one tree, nested
edges matching).  ``IntegrityError`` names the first part not of the form
``fit`` writes by its path (``learned_blind.models_.3.left``).  What passes is
a model of the right form, not the right model (the shipped ones are also
checked by their digest, ``io.forecast_model``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: bounds of a fitted model's parts (the shipped model: 700 trees of at most 29 nodes)
MAX_NODES = 1 << 16
MAX_TREES = 100_000
#: largest |leaf value| and |baseline| of a boosted tree (a log remaining angle: -20 to 2)
MAX_LEAF = 1e3
#: most training points a novelty detector may keep (each search reads every one)
MAX_NEIGHBOUR_POINTS = 200_000


class IntegrityError(ValueError):
    """A fitted forecaster's part is not of the form the forecaster writes (one phrase)."""


def require(ok, what: str) -> None:
    """Raise ``IntegrityError(what)`` unless ``ok``."""
    if not ok:
        raise IntegrityError(what)


@dataclass(frozen=True)
class Spec:
    """What one fitted part is.  ``kind``: an array's dtype kinds ("f", "i", "b", "fi"), or
    "number", "int", "choice" (one of ``of``), "str", "part" (an instance of class ``of``,
    checked by its own ``FIELDS``), "list" or "tuple" (``n`` items, at least ``min_size``, each
    ``of``), "dict" (keys within ``keys``, each value ``of``; or ``of`` a table key -> Spec,
    exactly its keys, an optional one may be absent).  An array (a list of numbers is read as
    one) has ``shape`` (else ``ndim`` dimensions and at least ``min_size`` values), is finite
    (``finite=False``: no NaN; None: not checked here), in [lo, hi], non-decreasing along its
    last axis if ``increasing`` ("strictly": increasing).  Any of these may be a function of the
    owner.  ``optional``: may be None or absent; ``when``: checked only if true of the owner."""
    kind: str
    shape: object = None
    ndim: object = 1
    lo: object = None
    hi: object = None
    increasing: object = False
    finite: object = True
    min_size: int = 0
    of: object = None
    n: object = None
    keys: object = None
    optional: bool = False
    when: object = None


def check_fields(obj, where: str = "", fields: dict | None = None) -> None:
    """Every part of ``obj`` its class declares (``FIELDS``), then its ``check_consistent``;
    or the parts ``fields`` declares."""
    own, fields = fields is None, type(obj).FIELDS if fields is None else fields
    for name, spec in fields.items():
        if spec.when is None or spec.when(obj):
            value = getattr(obj, name, None) if spec.optional else getattr(obj, name)
            check_value(value, spec, obj, f"{where}.{name}" if where else name)
    try:
        getattr(obj, "check_consistent", lambda: None)() if own else None
    except IntegrityError as exc:
        raise IntegrityError(f"{where}: {exc}" if where else str(exc)) from None


def check_value(v, s: Spec, owner, what: str) -> None:
    """``v`` as ``s`` declares (module docstring); else ``IntegrityError`` naming ``what``."""
    lo, hi, n, shape, ndim = (x(owner) if callable(x) else x
                              for x in (s.lo, s.hi, s.n, s.shape, s.ndim))
    if v is None and s.optional:
        return
    if s.kind == "part":
        require(isinstance(v, s.of), f"{what} is a {type(v).__name__}, not a {s.of.__name__}")
        return check_fields(v, what)
    if s.kind in ("list", "tuple", "dict"):
        box = {"list": list, "tuple": tuple, "dict": dict}[s.kind]
        items = None if not isinstance(v, box) else v if box is dict else dict(enumerate(v))
        specs = s.of if isinstance(s.of, dict) else dict.fromkeys(items or (), s.of)
        require(items is not None and (n is None or len(items) == n) and len(items) >= s.min_size
                and set(s.keys or specs) >= set(items)
                >= {k for k, spec in specs.items() if not spec.optional},
                f"{what} is not a {s.kind} of {n if n is not None else ', '.join(map(str, specs))}")
        return [check_value(items[k], specs[k], owner, f"{what}.{k}") for k in items]
    if s.kind == "choice":
        return require(any(type(v) is type(c) and v == c for c in s.of),
                       f"{what} = {v!r} is not one of {tuple(s.of)}")
    if s.kind == "str":
        return require(isinstance(v, str), f"{what} is not a text")
    if s.kind in ("number", "int"):
        ok = not isinstance(v, (bool, np.bool_)) and isinstance(
            v, (int, np.integer) if s.kind == "int" else (int, float, np.integer, np.floating))
        lo, hi = -math.inf if lo is None else lo, math.inf if hi is None else hi
        return require(ok and math.isfinite(v) and lo <= v <= hi,
                       f"{what} = {v!r} is not a {'whole ' * (s.kind == 'int')}number in "
                       f"[{lo:g}, {hi:g}]")
    v = np.asarray(v) if isinstance(v, list) else v  # a JSON list of numbers: an array
    require(isinstance(v, np.ndarray), f"{what} is a {type(v).__name__}, not an array")
    require(v.dtype.kind in s.kind, f"{what} has dtype {v.dtype}")
    if shape is not None:
        require(v.shape == tuple(shape), f"{what} has shape {v.shape}, not {tuple(shape)}")
    require(shape is not None or v.ndim == ndim, f"{what} has {v.ndim} dimensions, not {ndim}")
    require(v.size >= s.min_size, f"{what} holds {v.size} values, fewer than {s.min_size}")
    if v.dtype.kind == "f" and s.finite is not None:
        require(np.isfinite(v).all() if s.finite else not np.isnan(v).any(),
                f"{what} holds NaN{' or infinite values' * bool(s.finite)}")
    if v.size:
        require(lo is None or v.min() >= lo, f"{what} holds values below {lo}")
        require(hi is None or v.max() <= hi, f"{what} holds values above {hi}")
    if s.increasing:  # compared, not differenced: +inf padding follows +inf
        up = v[..., 1:] > v[..., :-1] if s.increasing == "strictly" else v[..., 1:] >= v[..., :-1]
        require(up.all(), f"{what} is not increasing")
