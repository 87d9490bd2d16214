"""The commands users already type, kept working after the code moved into its layer, and the
public names a module reads from the package's layers at first use.

``sliders/ensemble.py``, ``study.py``, ``merge.py`` and ``reproduction.py`` are two
lines each: ``python -m sliders.ensemble`` runs the
layer's ``main()``; ``import sliders.ensemble`` gives the layer's module itself
(the same object, so that attributes and monkeypatches reach the real code).
``sliders`` and ``sliders.forecast`` read their public names at first use
(``names_at_first_use``), so that a command's ``--help`` imports none of them.
"""

from __future__ import annotations

import importlib
import sys
from typing import NoReturn


def forward(name: str, target: str) -> None:
    """Run ``target.main()`` when ``name`` is ``"__main__"``, else make ``name`` an alias of ``target``.

    Parameters
    ----------
    name : str
        The forwarding module's ``__name__``.
    target : str
        The module that holds the code, e.g. ``"sliders.runs.ensemble"``.
    """
    if name != "__main__":
        sys.modules[name] = importlib.import_module(target)
        return
    try:
        module = importlib.import_module(target)
    except KeyboardInterrupt:
        interrupted_while_starting(target.rsplit('.', 1)[-1])
    sys.exit(module.main())


def names_at_first_use(module: str, names: dict[str, tuple[str, str]]):
    """A module's ``__getattr__`` (PEP 562): each of ``names``, ``{name: (module of sliders,
    attribute)}``, imported at first use and kept in ``module`` (the next use reads it there)."""

    def __getattr__(name: str):
        try:
            where, attribute = names[name]
        except KeyError:
            raise AttributeError(f"module {module!r} has no attribute {name!r}") from None
        value = getattr(importlib.import_module(f"sliders.{where}"), attribute)
        setattr(sys.modules[module], name, value)
        return value

    return __getattr__


def interrupted_while_starting(command: str) -> NoReturn:
    """Ctrl-C while a command imports its modules: one line, nothing written, status 130."""
    sys.stderr.write(f"{command}: interrupted (SIGINT) while starting; nothing written\n")
    raise SystemExit(130)
