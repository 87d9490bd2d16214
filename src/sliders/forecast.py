"""``python -m sliders.forecast``, the command users type: the code is ``sliders.runs.forecast.cli``."""

from ._forward import forward

forward(__name__, "sliders.runs.forecast.cli")
