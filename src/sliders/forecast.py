"""``python -m sliders.forecast``, the command users type: the code is ``sliders.runs.forecast``."""

from ._forward import forward

forward(__name__, "sliders.runs.forecast")
