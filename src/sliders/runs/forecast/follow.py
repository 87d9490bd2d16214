"""``python -m sliders.forecast predict FILE --follow``: the live forecast's command.

The options, and the file's existence, are checked before the model is loaded; then
``ForecastModel.follow`` (the loop, ``sliders.forecasting.follower.Follower``) yields the updates and this prints
them: each update's line and the alarm's lines it raised (``--json``: the update's JSON object,
one a line, the alarm's lines on stderr); the notices (a bad row, a file read again) and the
stop's line on stderr; at ``# avalanche`` the run's score (``--json``: ``{"summary": ...}`` as
the last line).  Exit status: 0 at ``# avalanche``, at ``--until`` and at the end of standard
input; 130 for SIGINT and 143 for SIGTERM, whatever call they interrupt (a FIFO's open, a write
to a full pipe).
"""

from __future__ import annotations

import json
import os
import sys

from ...forecasting.alarm import RunScore
from ...forecasting.follower import check_source, rate_option
from ...forecasting.predict import load_model
from ..signals import raise_stopped
from .cli import measurement_options
from .predict import check_predict_options


def follow_command(args, argv=None) -> int:
    """``predict --follow``: the options and the file checked, the model loaded once, then the
    updates printed until a stop (module docstring); returns the exit status."""
    check_predict_options(args)
    if args.tilt_rate is not None:
        rate_option(args.tilt_rate)
    check_source(args.catalogue)
    model = load_model(args.model, lazy=True)
    follower = model.follow(
        args.catalogue, tilt_now=args.tilt_now, tilt_rate=args.tilt_rate, until=args.until,
        within=args.within, **measurement_options(args), method=args.method, alarm_threshold=getattr(args, "alarm_threshold", None),
        alarm_release=getattr(args, "alarm_release", None),
        on_alarm=getattr(args, "on_alarm", None), plot=args.plot, on_signal=raise_stopped)
    updates = iter(follower)
    try:
        for update in updates:
            if args.json:
                _out(update.json_line())
                for line in update.alarm_lines:
                    _err(line)
            else:
                _out("\n".join(update.lines()))
        if follower.summary is not None:
            _out(json.dumps({"summary": follower.summary}) if args.json
                 else "\n".join(RunScore.lines(follower.summary)))
    except KeyboardInterrupt as exc:  # a signal while an update was printed
        follower.stop_by_signal(exc)
    except BrokenPipeError:  # the reader of the output left
        _drop_unwritten_output()
        follower.stop("output closed", "the output was closed: stopped")
    finally:
        updates.close()
    stop = follower.stopped
    if stop.status:
        _drop_unwritten_output()
    _err(stop.line)
    return stop.status


def _out(text: str) -> None:
    print(text, flush=True)


def _err(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _drop_unwritten_output() -> None:
    """Standard output to /dev/null: what a stopped follow had not written yet (to a pipe its
    reader does not empty) is dropped, so that the exit's flush cannot block."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, ValueError, OSError):
        return
    if os.isatty(fd):
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, fd)
    finally:
        os.close(null)
