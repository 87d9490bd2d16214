"""The commands users already type, kept working after the code moved into its layer.

``sliders/ensemble.py``, ``study.py``, ``merge.py`` and ``reproduction.py`` are two
lines each: ``python -m sliders.ensemble`` runs the
layer's ``main()``; ``import sliders.ensemble`` gives the layer's module itself
(the same object, so that attributes and monkeypatches reach the real code).
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


def interrupted_while_starting(command: str) -> NoReturn:
    """Ctrl-C while a command imports its modules: one line, nothing written, status 130."""
    sys.stderr.write(f"{command}: interrupted (SIGINT) while starting; nothing written\n")
    raise SystemExit(130)
