"""What the forecast subcommands share: the defaults their options show, the progress log, the
provenance of what they write, JSON values.

Imports neither NumPy nor scikit-learn: the parser (``cli``) reads the defaults here, and
``--help`` costs no more than Python and argparse.
"""

from __future__ import annotations

import math
import sys
import time

from .._version import __version__
from ..analysis.forecast.registry import METHODS

#: leads before the avalanche at which the test runs are cut, degrees
DEFAULT_LEADS_DEG = (0.25, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0)
#: fixed tilts at which the test runs are cut, radians
DEFAULT_TILTS = (0.1, 0.2, 0.3, 0.4, 0.5)
#: the alarm: "the avalanche within DELTA", judged every STEP over the last WINDOW, degrees
ALARM_DELTA_DEG, ALARM_WINDOW_DEG, ALARM_STEP_DEG = 1.0, 6.0, 0.25
#: the lead at which the forecasters' targets are stated, degrees
TARGET_LEAD_DEG = 3.0
#: boosting iterations of ``train``'s model: each iteration adds 7 trees per learned forecaster
#: to the model file (150 iterations of 31 leaves made an 8 MB file)
TRAIN_MAX_ITER = 100
#: boosting iterations of the posterior (``train --fit posterior``): 35 regressors of 45 trees (4.5 MB)
POSTERIOR_MAX_ITER = 45
#: piles simulated at posterior draws by ``infer``'s predictive check
CHECK_DRAWS = 24
#: which learned forecaster ``--method learned`` picks for a catalogue, by its columns and its
#: measurement (``catalogue.record_kind``): every feature (displacements and movers in the
#: model's units), a camera's (displacements in any unit, positions if given), angles and sizes
#: only, or those told the pile's size
LEARNED_BY_RECORD = {"complete": "learned", "camera": "learned_camera", "blind": "learned_blind",
                     "sized": "learned_sized"}
LEARNED_METHODS = tuple(LEARNED_BY_RECORD.values())
#: the choices of ``predict --method`` (the registry's): "learned" picks the learned forecaster
#: for the columns given (every feature, a camera's, or angles and sizes only)
PREDICT_METHODS = ("learned", *(m for m in METHODS if m not in LEARNED_METHODS), "all")


def progress_log(quiet: bool):
    """``log(*parts)``: a progress line on stderr, or nothing with ``--quiet``."""
    if quiet:
        return lambda *a: None
    return lambda *a: print(*a, file=sys.stderr, flush=True)


def provenance(argv) -> dict:
    """Versions and command of a file this command writes (the installed distributions' versions)."""

    from importlib.metadata import PackageNotFoundError, version

    def installed(package: str) -> str:
        try:
            return version(package)
        except PackageNotFoundError:
            return "?"

    return {"sliders": __version__, "python": sys.version.split()[0],
            **{p: installed(p) for p in ("numpy", "scikit-learn", "crepes")},
            "command": "python -m sliders.forecast " + " ".join(argv),
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def jsonable(x):
    """``x`` with NumPy values as JSON ones (a non-finite number as None)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if hasattr(x, "tolist"):  # a NumPy array or scalar
        return jsonable(x.tolist())
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    return x


def probability_limits(bounds) -> tuple[float, float]:
    """The least and the greatest probability the text states as a number, from the forecast's
    ``probability_bounds`` (two decimals, within [0.01, 0.99]): beyond them it gives a bound."""
    lo, hi = max(bounds[0], 0.01), min(bounds[1], 0.99)
    return math.ceil(lo * 100 - 1e-9) / 100, math.floor(hi * 100 + 1e-9) / 100


def probability_text(p: float, bounds) -> str:
    """``p`` to two decimals, or ``< lo`` / ``> hi`` beyond what the forecast resolves
    (``probability_limits``; a probability clipped to a limit, as JSON's, reads as the bound)."""
    lo, hi = probability_limits(bounds)
    if p <= lo:
        return f"< {lo:.2f}"
    if p >= hi:
        return f"> {hi:.2f}"
    return f"= {p:.2f}"


def clipped_probability(p: float, bounds) -> float:
    """``p`` within the limits the text states it by (``probability_limits``)."""
    lo, hi = probability_limits(bounds)
    return min(max(p, lo), hi)
