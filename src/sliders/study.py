"""``python -m sliders.study``, the command users type: the code is ``sliders.runs.study``."""

from ._forward import forward

forward(__name__, "sliders.runs.study")
