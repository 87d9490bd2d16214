"""``python -m sliders.ensemble``, the command users type: the code is ``sliders.runs.ensemble``."""

from ._forward import forward

forward(__name__, "sliders.runs.ensemble")
