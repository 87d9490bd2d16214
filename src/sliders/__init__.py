"""sliders: a chain of frictional sliders on an incline tilted to the avalanche.

Amon, Blanc & Geminard, "Avalanche precursors in a frictional model".  The
public API:

* ``Scene``: one configured run (validated on construction), composed of its
  friction law (``Coulomb``) and its loading (``Tilt``, ``PushedEnd``);
* ``run(scene, backend="fortran"|"numpy")``: drive the loading to the run's
  end, returns a ``Result`` (save/load in HDF5); ``tilt`` is its alias
  here, the paper's name (the same function; inside the package it is ``run``);
* ``prepare(scene)``: the prepared chain at alpha = 0;
* ``analysis``, ``figures``, ``runs``: the layers above (docs/architecture.md).
"""

from ._forward import names_at_first_use as _names_at_first_use
from ._version import __version__

#: the public names, each read from its module at first use: ``import sliders`` costs
#: nothing more than its version (a command's ``--help`` needs no more)
_PUBLIC = {
    "ChainState": ("chain", "ChainState"),
    "Interrupted": ("driver", "Interrupted"),
    "Progress": ("driver", "Progress"),
    "run": ("driver", "run"),
    "SceneError": ("parts.checks", "SceneError"),
    "Coulomb": ("parts.friction", "Coulomb"),
    "PushedEnd": ("parts.loading", "PushedEnd"),
    "Tilt": ("parts.loading", "Tilt"),
    "prepare": ("preparation", "prepare"),
    "PreparationInterrupted": ("preparation", "PreparationInterrupted"),
    "EventSparse": ("result", "EventSparse"),
    "Result": ("result", "Result"),
    "Scene": ("scene", "Scene"),
    # the paper's name (its loading is the tilt; it runs any loading alike)
    "tilt": ("driver", "run"),
}

__all__ = sorted([*_PUBLIC, "__version__"])


__getattr__ = _names_at_first_use(__name__, _PUBLIC)


def __dir__():
    return sorted({*globals(), *_PUBLIC})
