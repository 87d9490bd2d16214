"""``python -m sliders.forecast predict FILE --follow``: a live forecast of a growing catalogue.

The model is loaded once; the file is followed as ``tail -F`` does: polled
every ``POLL_SECONDS``, its complete lines kept and a partial last line held
until its newline; a file truncated, rewritten from its start or replaced (a
new inode at the path) is read again from its start, and a line on stderr says
so.  The tilt reached is the last ``# tilt-now ANGLE`` line of the file, or
``--tilt-now``, advanced at ``--tilt-rate`` by the wall clock, and never below
the last event's angle.  At each poll everything that arrived is read first
(the lines are parsed again only when complete lines arrived: an idle follower
costs a stat and an empty read) and the latest state alone is forecast (a
burst of rows is one update), when rows arrived or the tilt advanced (by the
clock: at most every ``CLOCK_SECONDS``).

Each update prints one line (``--json``: the ``predict --json`` object and
``rows``, the complete rows read, and ``alarm``; JSON Lines); the alarm's
crossings of its threshold print an ALARM line (stderr with ``--json``), and
``--plot`` is replaced whole at each update.  A bad row gets the batch mode's
line naming it, once, and the file is followed on (a corrected or replaced file
is read again).  It stops with status 0 on SIGINT or SIGTERM, at ``--until``,
or on a ``# avalanche`` line.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import json
import math
import os
import signal
import sys
import time

from ...io.forecast_files import ForecastInputError, angle_option, parse_angle
from ..signals import handled
from .catalogue import measurement_of, read_source
from .predict import (at_tilt, check_predict_options, load_model, probability_text,
                      within_option)

#: the file is polled this often, seconds (idle: a stat and an empty read each time)
POLL_SECONDS = 0.15
#: with --tilt-rate and no new row, a forecast at most this often, seconds
CLOCK_SECONDS = 1.0
#: the head of the file compared at each poll: a file rewritten from its start is read again
HEAD_BYTES = 256


def _heap_trimmer():
    """glibc's ``malloc_trim`` (a function of one argument), or None on another C library."""
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None


_MALLOC_TRIM = _heap_trimmer()


def release_freed_memory() -> None:
    """Hand the heap's freed pages back to the system.  A forecast of a long catalogue frees
    what it allocated, but glibc keeps the freed heap mapped: without this the follower's
    resident memory would stay at its largest forecast's mark (16 MB more after 10^4 rows)."""
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


class Tail:
    """The complete lines of a file that grows, as ``tail -F`` follows it.

    ``poll()`` reads what arrived and returns a notice (the file was truncated,
    rewritten or replaced: ``data`` starts again) or None; ``data`` holds the
    complete lines read so far, ``partial`` the last line until its newline.
    """

    def __init__(self, path: str):
        self.path = path
        self.fh = None
        self.started = 0  # times the file was read from its start
        self.reset()

    def reset(self) -> None:
        """Forget what was read (the file is read again from its start)."""
        self.pos, self.data, self.partial, self.head = 0, bytearray(), b"", b""
        self.started += 1

    def version(self) -> tuple[int, int]:
        """Changes when complete lines arrive or the file is read again from its start."""
        return self.started, len(self.data)

    def _open(self) -> bool:
        try:
            self.fh = open(self.path, "rb")
        except FileNotFoundError:
            return False
        except OSError as exc:
            raise ForecastInputError(f"{self.path}: {exc.strerror or exc}") from None
        self.reset()
        return True

    def poll(self) -> str | None:
        """Read what arrived; a notice if the file was started again."""
        notice = None
        if self.fh is None and not self._open():
            return None
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            st = None  # being replaced: keep reading the old one
        own = os.fstat(self.fh.fileno())
        if st is not None and (st.st_ino, st.st_dev) != (own.st_ino, own.st_dev):
            self.fh.close()
            self._open()
            notice = "replaced"
        elif own.st_size < self.pos:
            self.fh.seek(0)
            self.reset()
            notice = "truncated"
        elif self.head and os.pread(self.fh.fileno(), len(self.head), 0) != self.head:
            self.fh.seek(0)
            self.reset()
            notice = "rewritten from its start"
        chunk = self.fh.read()
        if chunk:
            self.pos += len(chunk)
            buf = self.partial + chunk
            k = buf.rfind(b"\n")
            if k >= 0:
                self.data += buf[:k + 1]
                self.partial = buf[k + 1:]
            else:
                self.partial = buf
            if len(self.head) < HEAD_BYTES:
                self.head = bytes(self.data[:HEAD_BYTES])
        return notice

    def close(self) -> None:
        """Close the file."""
        if self.fh is not None:
            self.fh.close()


def comments(data: bytes) -> tuple[str | None, bool]:
    """The last ``# tilt-now ANGLE`` of the lines ``data`` (its text), and whether a
    ``# avalanche`` line is among them."""
    tilt, avalanche = None, False
    for raw in bytes(data).splitlines():
        line = raw.strip()
        if not line.startswith(b"#"):
            continue
        words = line[1:].decode("utf-8", "replace").split()
        if words[:1] == ["tilt-now"] and len(words) >= 2:
            tilt = "".join(words[1:])
        elif words[:1] == ["avalanche"]:
            avalanche = True
    return tilt, avalanche


def rate_option(text) -> float:
    """``--tilt-rate`` in radians per second: ``0.1deg/s``, ``0.002rad/s`` or a bare number
    of degrees per second."""
    t = str(text).strip()
    body = t[:-2] if t.endswith("/s") else t
    return angle_option(body, "--tilt-rate")


def follow_command(args, argv=None) -> int:
    """``predict --follow``: the model loaded once, then ``follow``."""
    check_predict_options(args)
    return follow(args, load_model(args.model))


def status_line(pred, rows: int) -> str:
    """One line of an update: the rows, the tilt, the first method's forecast."""
    d = pred.to_dict()
    first = next(iter(d["methods"]))
    m = d["methods"][first]
    deg = math.degrees
    name = "80 % interval" if m["calibrated"] else "widened interval, uncalibrated"
    return (f"rows {rows}, tilt {deg(d['tilt_now']):.2f}°: {first} avalanche angle "
            f"{deg(m['alpha_c']):.2f}°, {name} {deg(m['interval'][0]):.2f}-"
            f"{deg(m['interval'][1]):.2f}°, P(within the next {deg(m['within']):g}°) "
            f"{probability_text(m['probability_within'], m['probability_bounds'])}"
            + ("" if d["in_domain"] else f"; OUT OF THE TRAINING DOMAIN: {d['domain_reason']}"))


def follow(args, model) -> int:
    """Follow ``args.catalogue`` and forecast each new state (module docstring)."""
    measurement = measurement_of(args)
    delta = within_option(args.within)
    rate = rate_option(args.tilt_rate) if args.tilt_rate is not None else None
    until = parse_angle(args.until, math.pi / 180.0) if args.until is not None else None
    stop = []
    tail = Tail(args.catalogue)

    def say(line, err=False):
        print(line, file=sys.stderr if err else sys.stdout, flush=True)

    anchor_text, anchor_time = args.tilt_now, time.monotonic()
    last_state, last_error, alarm, last_clock = None, None, False, 0.0
    parsed, read, avalanche = None, None, False
    with handled(lambda signum, frame: stop.append(signum)):
        try:
            while not stop:
                notice = tail.poll()
                if notice:
                    say(f"sliders.forecast: {args.catalogue} was {notice}: read again from its "
                        "start", err=True)
                    last_state = last_error = None
                if tail.version() != parsed:  # the lines are parsed when they change only
                    parsed = tail.version()
                    data = bytes(tail.data)
                    tilt_text, avalanche = comments(data)
                    if tilt_text is not None and tilt_text != anchor_text:
                        anchor_text, anchor_time = tilt_text, time.monotonic()
                    try:
                        read = read_source(data, args.catalogue)
                    except ForecastInputError as exc:
                        if "no events" not in str(exc) and "empty file" not in str(exc) \
                                and str(exc) != last_error:
                            say(f"sliders.forecast: {exc}", err=True)
                            last_error = str(exc)
                        read = None
                if read is not None:
                    cat, scale, unit = read
                    last = float(cat.alpha[-1])
                    base = (parse_angle(anchor_text, scale) if anchor_text is not None
                            else last)
                    now = time.monotonic()
                    tilt = base + (rate * (now - anchor_time) if rate else 0.0)
                    tilt = max(tilt, last)
                    clock_due = rate is not None and now - last_clock >= CLOCK_SECONDS
                    state = (len(cat), anchor_text, tilt if clock_due else None)
                    if state[:2] != (last_state or (None, None))[:2] or clock_due:
                        last_clock = now
                        last_state = state
                        try:
                            pred = model.predict_read(read, f"{tilt!r}rad", measurement, delta,
                                                      args.method)
                        except ForecastInputError as exc:
                            if str(exc) != last_error:
                                say(f"sliders.forecast: {exc}", err=True)
                                last_error = str(exc)
                        else:
                            last_error = None
                            alarm = report(args, pred, len(cat), alarm, say)
                            del pred
                            release_freed_memory()
                        if until is not None and tilt >= until:
                            say(f"the tilt reached {math.degrees(tilt):.2f}° (--until "
                                f"{args.until}): stopped", err=args.json)
                            return 0
                if avalanche:
                    say(f"avalanche recorded in {args.catalogue}: stopped", err=args.json)
                    return 0
                time.sleep(POLL_SECONDS)
        finally:
            tail.close()
    say(f"stopped ({signal.Signals(stop[0]).name})", err=True)
    return 0


def report(args, pred, rows: int, alarm: bool, say) -> bool:
    """Print one update (and an ALARM line when the threshold is crossed), write the picture;
    returns whether the alarm is on."""
    d = pred.to_dict()
    now = pred.alarm
    if args.json:
        say(json.dumps(d | {"rows": rows, "alarm": now}))
    else:
        say(status_line(pred, rows))
    if now != alarm:
        p, t = d["probability_within"], d["alarm_threshold"]
        say(f"ALARM: P(avalanche within the next {math.degrees(d['within']):g}°) = {p:.2f} "
            f"reached {t:g} at {math.degrees(d['tilt_now']):.2f}° (rows {rows})" if now else
            f"alarm off: P(within) = {p:.2f} below {t:g} at {math.degrees(d['tilt_now']):.2f}°",
            err=args.json)
    if args.plot:
        pred.plot(args.plot)
    return now
