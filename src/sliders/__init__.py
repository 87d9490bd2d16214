"""sliders: a chain of frictional sliders on an incline tilted to the avalanche.

Amon, Blanc & Geminard, "Avalanche precursors in a frictional model".  The
public API:

* ``Scene``: one configured run (validated on construction);
* ``tilt(scene, backend="fortran"|"numpy")``: tilt to the avalanche, returns a
  ``TiltResult`` (save/load in HDF5);
* ``prepare(scene)``: the prepared chain at alpha = 0;
* ``analysis``, ``figures``, ``runs``: the layers above (docs/architecture.md).
"""

from ._version import __version__

from .chain import ChainState
from .driver import Interrupted, Progress, tilt
from .preparation import prepare
from .result import EventSparse, TiltResult
from .scene import Scene, SceneError

__all__ = [
    "ChainState", "EventSparse", "Interrupted", "Progress", "Scene", "SceneError", "TiltResult",
    "__version__", "prepare", "tilt",
]
