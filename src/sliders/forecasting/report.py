"""What the forecast of a catalogue (``predict.Prediction``) and the posterior of its pile
(``infer.Inference``) share: a report of JSON values read by key, ``to_dict()`` (the
``--json`` object), ``lines()`` and ``str()`` (the text output), ``figure()`` (a matplotlib
Figure) and ``plot(path)`` (that picture written whole as a PNG, through
``figures.style.png_bytes``); and the one name of a forecast's interval that every output
prints (``interval_name``).
"""

from __future__ import annotations

import copy

from ..analysis.forecast.base import NOMINAL_COVERAGE
from ..io.safeio import publish_bytes


def interval_name(method_dict: dict, method: str) -> str:
    """What a method's interval is, in the words every output uses (``predict``'s lines,
    ``--follow``'s update and ALARM lines, the picture): ``method_dict`` is the method's entry
    of ``to_dict()["methods"]``."""
    if method_dict["calibrated"]:
        return f"{NOMINAL_COVERAGE * 100:.0f} % interval"
    fallback = method_dict.get("fallback", False)
    if fallback and method != "learned":
        return "climatology's 10-90 % range, uncalibrated"
    if fallback:  # the learned forecaster out of its domain
        return "widened interval, uncalibrated"
    return "interval, uncalibrated"


class Report:
    """A report of a catalogue: its JSON values (``to_dict``, read by key), its text
    (``lines``) and its picture (``figure``, ``plot``).  Subclasses give ``lines`` and
    ``figure``."""

    def __init__(self, report: dict):
        self._report = report

    def __getitem__(self, key):
        """A value of ``to_dict()``."""
        return self._report[key]

    def to_dict(self) -> dict:
        """The report as JSON values: what the command's ``--json`` prints."""
        return copy.deepcopy(self._report)

    def lines(self) -> list[str]:
        """The text output, one line each."""
        raise NotImplementedError

    def __str__(self) -> str:
        """The text output (``lines``)."""
        return "\n".join(self.lines())

    def figure(self, **options):
        """The picture, a matplotlib Figure."""
        raise NotImplementedError

    def png(self, **options) -> bytes:
        """The picture (``figure(**options)``) as PNG bytes at the bench picture's resolution."""
        from ..figures.bench import BENCH_DPI
        from ..figures.style import png_bytes

        return png_bytes(self.figure(**options), BENCH_DPI)

    def plot(self, path, **options) -> None:
        """Write the picture to ``path`` (PNG), whole or not at all (a temporary file beside it,
        then renamed over it); ``options`` as ``figure``'s."""
        publish_bytes(str(path), self.png(**options), overwrite=True)
