"""Angles as people write them: ``27.5deg``, ``0.48 rad`` or a bare number, one parser for every command.

The model works in radians (``Scene`` docstring: time tau, length g tau^2,
force m g, angles in radians).  Every command-line option that takes an angle
(``--alpha-max``, ``--tilt``, ``--tilt-now``, ...) reads it with
``parse_angle``, and every help text shows an angle with ``format_angle``
(radians and degrees).
"""

from __future__ import annotations

import math

DEGREE = math.pi / 180.0
ANGLE_UNITS = {"deg": DEGREE, "degree": DEGREE, "degrees": DEGREE, "°": DEGREE,
               "rad": 1.0, "radian": 1.0, "radians": 1.0}


def parse_angle(text: str, default_scale: float = 1.0, error: type[Exception] = ValueError) -> float:
    """``"27.5deg"``, ``"0.48 rad"`` or a bare number (in ``default_scale`` radians a unit) -> radians.

    Parameters
    ----------
    text : str
        The angle as written: a number with an optional unit of ``ANGLE_UNITS``.
    default_scale : float
        Radians per unit of a bare number (1 for radians, ``DEGREE`` for degrees).
    error : type of Exception
        Raised, with one line, for a text that is not a finite angle.

    Returns
    -------
    float
        The angle in radians.
    """
    t = str(text).strip().lower()
    for unit in sorted(ANGLE_UNITS, key=len, reverse=True):
        if t.endswith(unit):
            number, scale = t[:-len(unit)].strip(), ANGLE_UNITS[unit]
            break
    else:
        number, scale = t, default_scale
    try:
        x = float(number)
    except ValueError:
        raise error(f"angle {text!r} not understood (e.g. 27.5deg or 0.48rad)") from None
    if not math.isfinite(x):
        raise error(f"angle {text!r} is not finite")
    return x * scale


def format_angle(radians: float) -> str:
    """An angle for a reader: ``"1.5708 rad (90 deg)"``."""
    return f"{radians:.8g} rad ({math.degrees(radians):.6g} deg)"
