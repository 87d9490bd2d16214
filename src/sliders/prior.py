"""``python -m sliders.prior``, the command users type: the code is ``sliders.runs.prior``."""

from ._forward import forward

forward(__name__, "sliders.runs.prior")
