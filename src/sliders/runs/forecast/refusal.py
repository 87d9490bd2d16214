"""What a failed forecast command says: its exit status and its one line.

The error boundary (``cli``) reads this module when a command fails, not before: the classes
of its refusals live in the modules of the files they refuse (which import NumPy), and
``--help`` reads none of them.
"""

from __future__ import annotations

import os
import traceback

from ...io.filelock import ClaimError
from ...io.forecast_files import ForecastInputError
from ...io.forecast_model import ModelFileError
from ...io.safeio import describe_os_error, os_reason


def command_line_error(message: str) -> ForecastInputError:
    """The refusal of a command line argparse cannot parse (exit status 2)."""
    return ForecastInputError(message)


def status_and_line(exc: Exception) -> tuple[int, str]:
    """``(exit status, one line)`` of a command that raised ``exc``: 2 for bad input (a
    refused input or output), 1 for an I/O error, memory, or a fault of the package (whose
    traceback ``SLIDERS_DEBUG`` prints)."""
    if isinstance(exc, (ForecastInputError, ModelFileError, ClaimError)):
        return 2, str(exc)
    if isinstance(exc, OSError):
        return 1, describe_os_error(exc, exc.filename) if exc.filename else os_reason(exc)
    if isinstance(exc, MemoryError):
        return 1, "out of memory"
    if os.environ.get("SLIDERS_DEBUG"):
        traceback.print_exception(exc)
    return 1, (f"{type(exc).__name__}: {' '.join(str(exc).split())} (an internal error; "
               "SLIDERS_DEBUG=1 shows where)")
