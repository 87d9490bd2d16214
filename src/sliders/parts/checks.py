"""The vocabulary of parameter checks shared by the scene and its parts.

The scene (``sliders.scene``), its friction law (``parts.friction``) and its
loading (``parts.loading``) each check their own values on construction
with these helpers: a bad value raises ``SceneError`` whose one-line message
names the parameter (by the flat key a scene file and the command line use)
and its allowed range.
"""

from __future__ import annotations

import math

import numpy as np


class SceneError(ValueError):
    """An invalid scene parameter; the message names it and its allowed range."""


def plain_value(kind: str, value):
    """Python and NumPy scalars alike, as plain Python numbers and strings.

    ``kind`` is the annotation of the parameter ("int", "float", "str", ...).
    A NumPy float becomes the shortest decimal that round-trips in its own
    precision (np.float32(0.001) -> 0.001, not 0.0010000000474974513), which is
    what was written.  Booleans are left for the checks to refuse.
    """
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


def check_real(name, value, low, high, *, open_low=False, why=None) -> None:
    """Refuse a value that is not a finite real number in [low, high] ((low, high] if open_low)."""
    rng = range_text(low, high, open_low)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{name}={value!r} must be a real number in {rng}")
    if not math.isfinite(value):
        raise SceneError(f"{name}={value!r} must be finite, in {rng}")
    too_low = low is not None and (value <= low if open_low else value < low)
    too_high = high is not None and value > high
    if too_low or too_high:
        extra = f" ({why})" if why else ""
        raise SceneError(f"{name}={value!r} is out of range: allowed {rng}{extra}")


def check_int(name, value, low, high) -> None:
    """Refuse a value that is not an integer in [low, high]."""
    rng = range_text(low, high, False)
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise SceneError(f"{name}={value!r} must be an integer in {rng}")
    if (low is not None and value < low) or (high is not None and value > high):
        raise SceneError(f"{name}={value!r} is out of range: allowed {rng}")


def check_choice(name, value, allowed) -> None:
    """Refuse a value that is not one of ``allowed``."""
    if value not in allowed:
        raise SceneError(f"{name}={value!r} must be one of {tuple(allowed)}")


def range_text(low, high, open_low) -> str:
    """The interval [low, high] as printed in the messages ("(0, +inf)", ...)."""
    lo = "-inf" if low is None else f"{low:.10g}"
    hi = "+inf" if high is None else f"{high:.10g}"
    return f"{'(' if open_low or low is None else '['}{lo}, {hi}{')' if high is None else ']'}"
