"""A part of a scene: the frozen dataclass of a friction law or of a loading.

A part owns its parameters (checked on construction with ``parts.checks``),
their flat keys in scene files, their packing for the kernel and its
physics.  It holds no scene: whatever its physics needs beyond its own
parameters (the chain's stiffness, the tolerance, the seed, another part's
answer) comes in as an argument of the method that needs it.
"""

from __future__ import annotations

import dataclasses

from .checks import plain_value


class Part:
    """A part of a scene (its friction law, its loading): a frozen dataclass of
    its own parameters, with their checks, their flat keys and their physics.

    * ``name``: the part's name in a scene file (``loading = "pushed_end"``);
    * ``flat_keys``: the flat scene key of each parameter (scene files and the
      command line hold the flat keys; ``Scene(incline=0.2, ...)`` builds the part);
    * ``check_own``: the checks of its values alone, on construction;
      ``check(scene)``: the checks against the rest of the scene;
    * ``packed()``: its values in the kernel's packed parameters (by name).

    A part keeps no reference to a scene: its methods take what they need
    (the chain's ``xi`` and ``walls``, ``force_tol``, ``seed``) as arguments.
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
