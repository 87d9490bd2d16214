"""``python -m sliders.reproduction``, the command users type: the code is ``sliders.analysis.reproduction``."""

from ._forward import forward

forward(__name__, "sliders.analysis.reproduction")
