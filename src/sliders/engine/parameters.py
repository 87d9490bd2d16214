"""The vocabulary of parameter checks shared by the scene and its parts.

The scene (``sliders.scene``), its friction law (``engine.friction``) and its
loading (``engine.loading``) each check their own values on construction
with these helpers: a bad value raises ``SceneError`` whose one-line message
names the parameter (by the flat key a scene file and the command line use)
and its allowed range.
"""

from __future__ import annotations

import copy
import dataclasses
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


class Part:
    """A part of a scene (its friction law, its loading): a frozen dataclass of
    its own parameters, with their checks, their flat keys and their physics.

    * ``name``: the part's name in a scene file (``loading = "pushed_end"``);
    * ``flat_keys``: the flat scene key of each parameter (scene files and the
      command line hold the flat keys; ``Scene(tilt=0.2, ...)`` builds the part);
    * ``check_own``: the checks of its values alone, on construction;
      ``check(scene)``: the checks against the rest of the scene;
    * ``packed()``: its values in the kernel's packed parameters (by name).

    A part in a scene is bound to it (``scene.loading.scene is scene``): its
    physics reads the chain's springs, the tolerance and the seed there.
    """

    name: str = ""
    flat_keys: dict[str, str] = {}

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, plain_value(str(f.type), getattr(self, f.name)))
        self.check_own()

    def __repr__(self) -> str:
        """Only the parameters that differ from their defaults (``eval(repr(part)) == part``)."""
        changed = [f"{f.name}={getattr(self, f.name)!r}" for f in dataclasses.fields(self)
                   if getattr(self, f.name) != f.default]
        return f"{type(self).__name__}({', '.join(changed)})"

    def check_own(self) -> None:
        """Refuse a bad value of the part's own parameters (``SceneError``)."""

    def check(self, scene) -> None:
        """Refuse a value that does not go with the rest of ``scene`` (``SceneError``)."""

    def flat(self) -> dict:
        """The part's parameters under their flat scene keys."""
        return {key: getattr(self, attr) for key, attr in self.flat_keys.items()}

    @classmethod
    def flat_defaults(cls) -> dict:
        """The flat keys of the part with their default values."""
        defaults = {f.name: f.default for f in dataclasses.fields(cls)}
        return {key: defaults[attr] for key, attr in cls.flat_keys.items()}

    @classmethod
    def from_flat(cls, values: dict, base: "Part | None" = None):
        """The part of the flat keys in ``values`` (others taken from ``base``, else defaults)."""
        own = {f.name: getattr(base, f.name) for f in dataclasses.fields(cls)} if base else {}
        own.update({attr: values[key] for key, attr in cls.flat_keys.items() if key in values})
        return cls(**own)

    def packed(self) -> dict:
        """The part's values in the kernel's packed parameters, by name."""
        return self.flat()

    def bound(self, scene) -> "Part":
        """A copy of the part that knows ``scene`` (the scene does this on construction)."""
        part = copy.copy(self)
        object.__setattr__(part, "scene", scene)
        return part
