"""``python -m sliders.merge``, the command users type: the code is ``sliders.runs.merge``."""

from ._forward import forward

forward(__name__, "sliders.runs.merge")
