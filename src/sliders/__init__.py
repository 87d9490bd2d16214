"""sliders: a chain of frictional sliders on an incline tilted to the avalanche.

Amon, Blanc & Geminard, "Avalanche precursors in a frictional model".  The
public API:

* ``Scene``: one configured run (validated on construction), composed of its
  friction law (``Coulomb``) and its loading (``Tilt``, ``PushedEnd``);
* ``run(scene, backend="fortran"|"numpy")``: drive the loading to the run's
  end, returns a ``Result`` (save/load in HDF5); ``tilt`` and ``TiltResult``
  are their names for the paper's tilt (the same function and class);
* ``prepare(scene)``: the prepared chain at alpha = 0;
* ``analysis``, ``figures``, ``runs``: the layers above (docs/architecture.md).
"""

from ._version import __version__

from .chain import ChainState
from .driver import Interrupted, Progress, run, tilt
from .parts.checks import SceneError
from .parts.friction import Coulomb
from .parts.loading import PushedEnd, Tilt
from .preparation import prepare
from .result import EventSparse, Result, TiltResult
from .scene import Scene

__all__ = [
    "ChainState", "Coulomb", "EventSparse", "Interrupted", "Progress", "PushedEnd", "Result",
    "Scene", "SceneError", "Tilt", "TiltResult", "__version__", "prepare", "run", "tilt",
]
