"""The estimator rules of scikit-learn, kept without importing it.

A forecaster, the domain check and the posterior are estimators as
scikit-learn means it: every parameter an argument of ``__init__`` stored
under its own name, what ``fit`` learns ending in ``_``, ``get_params`` and
``set_params`` (so that ``sklearn.base.clone`` copies them).  They fit with
scikit-learn and crepes, but a fitted one is read from a model file of plain
arrays and forecasts with NumPy (``evaluators``): so their common base is this
one, which a forecast can import without scikit-learn (two seconds).
"""

from __future__ import annotations

import functools
import inspect


class Estimator:
    """``get_params``, ``set_params`` and a repr of the parameters that differ from their defaults."""

    def get_params(self, deep: bool = True) -> dict:
        """``{parameter: value}`` of the arguments of ``__init__``."""
        return {name: getattr(self, name) for name in param_names(type(self))}

    def set_params(self, **params) -> "Estimator":
        """Set parameters by name; an unknown name is a ``ValueError``."""
        names = param_names(type(self))
        for name, value in params.items():
            if name not in names:
                raise ValueError(f"{name!r} is not a parameter of {type(self).__name__} "
                                 f"({', '.join(names)})")
            setattr(self, name, value)
        return self

    def __repr__(self) -> str:
        defaults = {p.name: p.default for p in inspect.signature(type(self).__init__).parameters
                    .values() if p.default is not p.empty} if type(self).__init__ is not \
            object.__init__ else {}
        shown = [f"{k}={v!r}" for k, v in self.get_params().items()
                 if k not in defaults or not _same(v, defaults[k])]
        return f"{type(self).__name__}({', '.join(shown)})"


def _same(a, b) -> bool:
    try:
        return bool(a == b) and type(a) is type(b)
    except (TypeError, ValueError):
        return a is b


@functools.cache
def param_names(cls) -> tuple[str, ...]:
    """The parameters of an estimator class: the arguments of its ``__init__``, sorted."""
    init = cls.__init__
    if init is object.__init__:
        return ()
    return tuple(sorted(p.name for p in inspect.signature(init).parameters.values()
                        if p.name != "self" and p.kind != p.VAR_KEYWORD))
