"""``python -m sliders.reproduction``, the command users type: the code is ``sliders.runs.reproduction``."""

from ._forward import forward

forward(__name__, "sliders.runs.reproduction")
