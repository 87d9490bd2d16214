"""sliders: a chain of frictional sliders on an incline tilted to the avalanche.

Amon, Blanc & Geminard, "Avalanche precursors in a frictional model".  The
public API:

* ``Scene``: one configured run (validated on construction), composed of its
  friction law (``Coulomb``) and its loading (``Tilt``, ``PushedEnd``);
* ``run(scene, backend="fortran"|"numpy")``: drive the loading to the run's
  end, returns a ``Result`` (save/load in HDF5); ``tilt`` and ``TiltResult``
  are their aliases here, the paper's names (the same function and class;
  inside the package they are ``run`` and ``Result``);
* ``prepare(scene)``: the prepared chain at alpha = 0;
* ``analysis``, ``figures``, ``runs``: the layers above (docs/architecture.md).
"""

import sys

from ._forward import interrupted_while_starting
from ._version import __version__

try:
    from .chain import ChainState
    from .driver import Interrupted, Progress, run
    from .parts.checks import SceneError
    from .parts.friction import Coulomb
    from .parts.loading import PushedEnd, Tilt
    from .preparation import prepare
    from .result import EventSparse, Result
    from .scene import Scene
except KeyboardInterrupt:
    if sys.argv[:1] != ["-m"]:  # an import in a program: its Ctrl-C, as always
        raise
    interrupted_while_starting("sliders")  # `python -m sliders...` (argv[0] is "-m" until found)

# The paper's names (its loading is the tilt; they run and hold any loading alike).
tilt = run
TiltResult = Result

__all__ = [
    "ChainState", "Coulomb", "EventSparse", "Interrupted", "Progress", "PushedEnd", "Result",
    "Scene", "SceneError", "Tilt", "TiltResult", "__version__", "prepare", "run", "tilt",
]
