"""The live forecast of a growing catalogue: ``Follower``, the loop of ``ForecastModel.follow``
and of ``python -m sliders.forecast predict FILE --follow``.

Data go one way: the file (or standard input) -> a bounded line reader
(``Tail`` for a file, ``Stream`` for standard input, a FIFO or a device) ->
the catalogue reader (``read_catalogue_stream``) -> the forecast it is handed
(``ForecastModel.predict_read``) -> an ``Update``.  The loop is a solver's loop (Dedalus's ``proceed``/``step``)::

    follower = model.follow("pile.csv", tilt_rate="0.1deg/s")
    while follower.proceed:             # no stop yet: signal, until, '# avalanche'
        update = follower.step()        # one poll; an Update if the state is new
        follower.wait()
    follower.stopped                    # why it stopped, and the command's exit status

or ``for update in follower: ...``, which waits between polls and makes SIGINT and
SIGTERM stop the loop (their handler raises, so a call blocked in the kernel, an open
of a FIFO without a writer, a write to a full pipe, returns at once).

What the follower guarantees:

* **Bounded reads**, as the batch reader's: a regular file over
  ``MAX_CATALOGUE_BYTES`` (64 MB) is refused from its size, any source once it
  has given that much, and a line over ``MAX_LINE_BYTES`` (4096) as soon as it
  is that long, newline or not: one line naming the file and the row.  Reads
  are chunks of ``CHUNK_BYTES``; standard input, FIFOs and devices are read by
  ``os.read`` when ``select`` finds data, never blocking.
* **Complete lines only**: a half-written last line waits for its newline; a
  file truncated, rewritten from its start or replaced is read again from its
  start (one line says so).
* **Bad rows** (any row the catalogue reader refuses: its line names the file,
  the row and the column) are said once and skipped; the next good rows are
  forecast.  The row is found by where the reader stopped, not by its message.
  A bad header is said once; the file is then followed until it is rewritten.
* **Comments**: only the markers count. ``# tilt-now ANGLE`` (words after the
  angle are ignored; an unreadable angle is one line naming the row, and the
  marker is ignored), ``# avalanche`` or ``# avalanche ANGLE`` as the whole
  comment (the run stops; the angle scores it).  Other comments are ignored.
* **The clock**: the tilt reached is the latest anchor (``tilt_now`` at the
  start, a ``# tilt-now`` line when read, an event's angle when read) advanced
  by ``tilt_rate`` times the wall-clock time since it was read, never below the
  last event's angle (a ``# tilt-now`` below it is raised to it, said once) and
  never past 90° (the clock stops there, said once).
* **Stops** (``stopped``): ``# avalanche`` and ``until`` with status 0, SIGINT
  130, SIGTERM 143, the end of standard input or of a FIFO 0.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import datetime
import io
import json
import math
import os
import select
import signal
import stat
import sys
import threading
import time

from ..io.forecast_files import (MAX_CATALOGUE_BYTES, MAX_LINE_BYTES, ForecastInputError,
                                  angle_option, parse_angle, read_catalogue_stream,
                                  tilt_in_range)
from .alarm import alarm_skill_line

#: a file is polled this often, seconds (idle: a stat and an empty read each time)
POLL_SECONDS = 0.15
#: with a tilt rate and no new row, a forecast at most this often, seconds
CLOCK_SECONDS = 1.0
#: the head of the file compared at each poll: a file rewritten from its start is read again
HEAD_BYTES = 256
#: the most read at once (a poll reads until the end of what arrived, chunk by chunk)
CHUNK_BYTES = 2**20
#: the greatest tilt a forecast takes: the clock stops below 90°
LAST_TILT = math.nextafter(math.pi / 2, 0.0)
DEG = math.pi / 180.0


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


def rate_option(text) -> float:
    """``--tilt-rate`` in radians per second: ``0.1deg/s``, ``0.002rad/s`` or a bare number
    of degrees per second."""
    t = str(text).strip()
    body = t[:-2] if t.endswith("/s") else t
    return angle_option(body, "--tilt-rate")


def check_source(source) -> str:
    """The name of a catalogue to follow (``-``: standard input), refused in one line if it
    does not exist, is a folder, or is a regular file over ``MAX_CATALOGUE_BYTES``."""
    where = "-" if source == "-" else os.fspath(source)
    if where == "-":
        return where
    try:
        st = os.stat(where)
    except OSError as exc:
        raise ForecastInputError(f"{where}: {exc.strerror or exc}") from None
    if stat.S_ISDIR(st.st_mode):
        raise ForecastInputError(f"{where}: a folder, not a catalogue")
    _check_size(where, st)
    return where


def _check_size(where: str, st) -> None:
    if stat.S_ISREG(st.st_mode) and st.st_size > MAX_CATALOGUE_BYTES:
        raise ForecastInputError(f"{where}: {st.st_size / 2**20:.0f} MB; a catalogue may hold at "
                                 f"most {MAX_CATALOGUE_BYTES // 2**20} MB")


# ---------------------------------------------------------------------------
# the line readers: complete lines, within bounds
# ---------------------------------------------------------------------------
class LineBuffer:
    """Complete lines out of chunks of bytes, within the catalogue reader's bounds: at most
    ``MAX_CATALOGUE_BYTES`` in all and ``MAX_LINE_BYTES`` a line (a longer line is refused as
    soon as it is that long, whether its newline came or not)."""

    def __init__(self, where: str):
        self.where = where
        self.partial = b""
        self.total = 0
        self.count = 0  # complete lines so far

    def _refuse_line(self, k: int):
        raise ForecastInputError(f"{self.where}: row {k}: longer than {MAX_LINE_BYTES} bytes "
                                 "(not a catalogue of numbers)")

    def feed(self, chunk: bytes) -> list[bytes]:
        """The lines ``chunk`` completes (each with its newline)."""
        self.total += len(chunk)
        if self.total > MAX_CATALOGUE_BYTES:
            raise ForecastInputError(f"{self.where}: row {self.count + 1}: beyond "
                                     f"{MAX_CATALOGUE_BYTES // 2**20} MB, the most a catalogue "
                                     "may hold")
        parts = (self.partial + chunk).split(b"\n")
        self.partial = parts.pop()
        for j, part in enumerate(parts):
            if len(part) >= MAX_LINE_BYTES:
                self._refuse_line(self.count + j + 1)
        if len(self.partial) > MAX_LINE_BYTES:
            self._refuse_line(self.count + len(parts) + 1)
        self.count += len(parts)
        return [p + b"\n" for p in parts]

    def end(self) -> list[bytes]:
        """The last line, complete at the end of the input though it has no newline."""
        last, self.partial = self.partial, b""
        if last:
            self.count += 1
            return [last + b"\n"]
        return []


class Tail:
    """The complete lines of a regular file that grows, as ``tail -F`` follows it.

    ``poll()`` reads what arrived and returns ``(notice, lines)``: the new complete lines
    and a notice when the file was truncated, rewritten from its start or replaced (a new
    inode at the path): ``lines`` then start again from its first line.
    """

    ended = False

    def __init__(self, path: str):
        self.path = path
        self.fd = None
        self.started = 0  # times the file was read from its start
        self.reset()

    def reset(self) -> None:
        """Forget what was read (the file is read again from its start)."""
        self.pos, self.head, self.buffer = 0, b"", LineBuffer(self.path)
        self.started += 1

    def _open(self) -> None:
        fd = os.open(self.path, os.O_RDONLY)
        try:
            _check_size(self.path, os.fstat(fd))
        except BaseException:
            os.close(fd)
            raise
        self.close()
        self.fd = fd
        self.reset()

    def poll(self) -> tuple[str | None, list[bytes]]:
        """Read what arrived: ``(notice or None, new complete lines)``."""
        notice = None
        if self.fd is None:
            try:
                self._open()
            except FileNotFoundError:
                return None, []  # replaced, the new one not yet in place
            except OSError as exc:
                raise ForecastInputError(f"{self.path}: {exc.strerror or exc}") from None
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            st = None  # being replaced: keep reading the old one
        own = os.fstat(self.fd)
        if st is not None and (st.st_ino, st.st_dev) != (own.st_ino, own.st_dev):
            try:
                self._open()
            except FileNotFoundError:
                return None, []
            notice = "replaced"
        elif own.st_size < self.pos:
            self.reset()
            notice = "truncated"
        elif self.head and os.pread(self.fd, len(self.head), 0) != self.head:
            self.reset()
            notice = "rewritten from its start"
        lines = []
        while chunk := os.pread(self.fd, CHUNK_BYTES, self.pos):
            self.pos += len(chunk)
            if len(self.head) < HEAD_BYTES:
                self.head += chunk[:HEAD_BYTES - len(self.head)]
            lines += self.buffer.feed(chunk)
        return notice, lines

    def wait(self, seconds: float) -> None:
        """Wait for the next poll."""
        time.sleep(seconds)

    def close(self) -> None:
        """Close the file."""
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


class Stream:
    """The complete lines of standard input (``-``), a FIFO or a device, read without ever
    blocking: ``os.read`` when ``select`` finds data.  ``ended`` once the input ends."""

    def __init__(self, path: str):
        self.path = path
        self.fd = None
        self.ended = False
        self.buffer = LineBuffer(path)

    def _ready(self, seconds: float) -> bool:
        return bool(select.select([self.fd], [], [], seconds)[0])

    def poll(self) -> tuple[None, list[bytes]]:
        """Read what arrived: ``(None, new complete lines)``."""
        if self.fd is None:  # a FIFO's open waits for a writer (a stop signal interrupts it)
            try:
                self.fd = sys.stdin.fileno() if self.path == "-" else os.open(self.path,
                                                                              os.O_RDONLY)
            except OSError as exc:
                raise ForecastInputError(f"{self.path}: {exc.strerror or exc}") from None
        lines = []
        while not self.ended and self._ready(0.0):
            chunk = os.read(self.fd, CHUNK_BYTES)
            if not chunk:
                self.ended = True
                lines += self.buffer.end()
            else:
                lines += self.buffer.feed(chunk)
        return None, lines

    def wait(self, seconds: float) -> None:
        """Wait for the next poll: ``seconds``, or less if data arrive."""
        if self.fd is None or self.ended:
            time.sleep(seconds)
        else:
            self._ready(seconds)

    def close(self) -> None:
        """Close the input (standard input is left open)."""
        if self.fd is not None and self.path != "-":
            os.close(self.fd)
        self.fd = None


def line_reader(where: str):
    """``Stream`` for standard input, a FIFO or a device; ``Tail`` for a regular file."""
    if where == "-":
        return Stream(where)
    try:
        mode = os.stat(where).st_mode
    except OSError:
        return Tail(where)
    return Tail(where) if stat.S_ISREG(mode) else Stream(where)


# ---------------------------------------------------------------------------
# the lines' kinds: rows, and the two markers among the comments
# ---------------------------------------------------------------------------
def _text(line: bytes) -> str:
    return line.decode("utf-8", "replace").strip().lstrip("\ufeff")


def is_row(line: bytes) -> bool:
    """A line the catalogue reader reads (the header or an event): neither blank nor a ``#``
    comment."""
    t = _text(line)
    return bool(t) and not t.startswith("#")


def marker(line: bytes) -> tuple[str, str | None] | None:
    """``("tilt-now", ANGLE)`` of a ``# tilt-now ANGLE ...`` line (ANGLE the word after it,
    None if there is none), ``("avalanche", ANGLE or None)`` of a comment that is
    ``# avalanche`` or ``# avalanche ANGLE`` whole; None for any other line."""
    t = _text(line)
    if not t.startswith("#"):
        return None
    words = t[1:].split()
    if words[:1] == ["tilt-now"]:
        return "tilt-now", (words[1] if len(words) > 1 else None)
    if words == ["avalanche"]:
        return "avalanche", None
    if len(words) == 2 and words[0] == "avalanche":
        try:
            parse_angle(words[1], DEG)
        except ForecastInputError:
            return None
        return "avalanche", words[1]
    return None


class _Trace(io.BytesIO):
    """The bytes the catalogue reader reads, and where the line it read last starts: the
    reader checks each row as it reads it, so a refusal stops at the refused line."""

    line_start = 0

    def readline(self, size=-1):
        """A line, its start remembered."""
        self.line_start = self.tell()
        return super().readline(size)


class Anchor:
    """What the clock advances from: an angle (radians, None until read in the catalogue's
    unit), when it was read, and where it came from (a row, or the option)."""

    def __init__(self, text, angle, when: float, row: int | None, event: bool = False):
        self.text, self.angle, self.when, self.row, self.event = text, angle, when, row, event
        self.raised_said = False

    def origin(self, where: str) -> str:
        """The row or the option it was read from."""
        return (f"{where}: row {self.row}: # tilt-now {self.text}" if self.row is not None
                else f"--tilt-now {self.text}")


class Stop:
    """Why a follow stopped: ``reason`` (``avalanche``, ``until``, ``end of input``,
    ``SIGINT``, ``SIGTERM``), the line that says it, and the command's exit status."""

    def __init__(self, reason: str, line: str, status: int):
        self.reason, self.line, self.status = reason, line, status

    def __repr__(self) -> str:
        """One line: the reason and the status."""
        return f"<Stop {self.reason}, status {self.status}>"


class Update:
    """One new state of the followed catalogue and its forecast.

    ``line()`` is the update's line, ``lines()`` it and the alarm's lines that it raised,
    ``to_dict()`` the ``predict --json`` object with ``rows`` (the complete rows read) and
    ``alarm`` (raised or not after it).
    """

    def __init__(self, prediction, rows: int, alarm: dict, alarm_lines: list[str]):
        self.prediction = prediction
        self.rows = rows
        self.alarm = alarm
        self.alarm_lines = alarm_lines

    def __repr__(self) -> str:
        """One line: the rows and the forecast."""
        return f"<Update rows {self.rows}: {self.prediction!r}>"

    def __getitem__(self, key):
        """A value of ``to_dict()``."""
        return self.to_dict()[key]

    def line(self) -> str:
        """The update's line: the rows, the tilt, the first method's forecast as ``predict``
        words it."""
        d, pred = self.prediction.to_dict(), self.prediction
        return (f"rows {self.rows}, tilt {math.degrees(d['tilt_now']):.2f}°: "
                + pred.method_line(*pred.forecasts[0])
                + ("" if d["in_domain"] else f"; OUT OF THE TRAINING DOMAIN: {d['domain_reason']}"))

    def lines(self) -> list[str]:
        """The update's line and the alarm's lines it raised (the command's text output)."""
        return [self.line(), *self.alarm_lines]

    def to_dict(self) -> dict:
        """The forecast as JSON values with ``rows`` and ``alarm`` (a line of ``--json``)."""
        return self.prediction.to_dict() | {"rows": self.rows, "alarm": bool(self.alarm["alarm"])}

    def json_line(self) -> str:
        """``to_dict()`` as one line of JSON."""
        return json.dumps(self.to_dict())


def raise_interrupt(signum, frame):
    """The follower's default stop handler: the signal ``signum`` raises KeyboardInterrupt
    carrying it (``signum``), so that a call blocked in the kernel returns at once."""
    exc = KeyboardInterrupt(signum)
    exc.signum = signum
    raise exc


def _say_on_stderr(line: str) -> None:
    print(f"sliders.forecast: {line}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------
# the loop
# ---------------------------------------------------------------------------
class Follower:
    """Follow a growing catalogue and forecast each new state (module docstring).

    Parameters
    ----------
    forecast : callable
        ``forecast(read, tilt, measurement, within, method)``: the ``Prediction`` of a catalogue
        read (``catalogue.read_source``'s triple) at the tilt reached ``tilt``
        (``ForecastModel.predict_read``); the follower hands it each state, and nothing flows
        back.
    source : str or os.PathLike
        The catalogue CSV (``-``: standard input); it must exist.
    tilt_now : str, optional
        The tilt reached at the start (``27.5deg``, ``0.48rad``, a bare number in the angle
        column's unit): the clock's first anchor.
    tilt_rate : str or float, optional
        The tilt's rate (``0.1deg/s``, ``0.002rad/s``, a bare number of degrees a second).
    until : str or float, optional
        Stop once the tilt reaches it (an angle; a bare number of degrees).
    within : float
        The alarm's horizon, radians.
    measurement : Measurement
        How the catalogue is measured.
    method : str
        The forecaster.
    alarm
        The alarm (``alarm.Alarm``): ``update(prediction, rows) -> {"alarm", "raised",
        "released"}`` at each update, ``levels(prediction)``; the lines it says while an update
        is made are that update's (``Update.alarm_lines``), the others notices.
    score
        The run's score (``alarm.RunScore``): ``add(update_dict)`` at each update,
        ``summary(avalanche_angle)`` at ``# avalanche``.
    picture : optional
        The picture (``alarm.LatestPicture``): ``show(prediction, status)`` at each update,
        ``close()`` at the end.
    say : callable, optional
        ``say(line)`` for the notices (a bad row, a file read again, a marker's angle);
        default: stderr.
    poll_seconds : float
        The wait between polls.
    on_signal : callable, optional
        ``on_signal(signum, frame)``, called by the iteration's handler of SIGINT and SIGTERM
        after the loop has recorded the signal; it raises (a KeyboardInterrupt).  Default:
        ``raise_interrupt``; the commands pass theirs (``runs.signals.raise_stopped``).
    """

    def __init__(self, forecast, source, *, tilt_now=None, tilt_rate=None, until=None,
                 within: float, measurement, method: str = "learned", alarm, score,
                 picture=None, say=None, poll_seconds: float = POLL_SECONDS, on_signal=None):
        self.forecast = forecast
        self.on_signal = on_signal or raise_interrupt
        self.signum: int | None = None  # the stop signal received while iterating
        self.where = check_source(source)
        self.say = say or _say_on_stderr
        self.rate = rate_option(tilt_rate) if tilt_rate is not None else None
        self.until_text = None if until is None else (until if isinstance(until, str)
                                                     else repr(until))
        self.until = None if until is None else tilt_in_range(
            angle_option(until, "--until"), f"--until {self.until_text}")
        if tilt_now is not None:
            angle_option(tilt_now, "--tilt-now")  # its form; its unit is the catalogue's
        self.tilt_now = None if tilt_now is None else (tilt_now if isinstance(tilt_now, str)
                                                       else repr(tilt_now))
        self.within, self.measurement, self.method = within, measurement, method
        self.alarm, self.score, self.picture = alarm, score, picture
        alarm.say = self._alarm_say  # an update's alarm lines are the update's
        self.poll_seconds = poll_seconds
        self.clock = time.monotonic  # the wall clock the tilt advances by (seconds)
        self.reader = line_reader(self.where)
        self.stopped: Stop | None = None
        self.summary: dict | None = None
        self.updates = 0
        self._captured: list[str] | None = None
        self._start = None
        self._clock_stopped = False
        self._last = None  # (reading, events, anchors) of the last forecast
        self._last_tilt, self._last_time = None, -math.inf
        self.anchor: Anchor | None = None
        self.anchors = 0  # anchors set so far
        self.reading = 0  # readings of the file from its start
        self._restart()

    # -- the stop conditions ---------------------------------------------------
    @property
    def proceed(self) -> bool:
        """No stop yet (a stop signal, ``until``, ``# avalanche``, the end of the input)."""
        return self.stopped is None

    def stop(self, reason: str, line: str, status: int = 0) -> None:
        """Stop the loop (the first stop counts)."""
        if self.stopped is None:
            self.stopped = Stop(reason, line, status)

    def stop_by_signal(self, exc: KeyboardInterrupt) -> None:
        """Stop for the signal behind ``exc`` (SIGINT: 130, SIGTERM: 143)."""
        signum = getattr(exc, "signum", None) or self.signum or signal.SIGINT
        name = signal.Signals(signum).name
        self.stop(name, f"stopped ({name})", 128 + signum)

    # -- the catalogue's state -------------------------------------------------
    def _restart(self) -> None:
        """The catalogue read from its start (at the start, or the file started again)."""
        self.kept = bytearray()  # every complete line; a bad row blanked (same bytes)
        self.header_at = None  # offset of the header line in ``kept``
        self.header_bad = False
        self.read = None  # (Catalogue, scale, unit) of ``kept``
        self.reported: set[str] = set()
        self.avalanche = None  # (row, angle text or None) once the marker is read
        self.reading += 1
        self.new_from = 0  # where the lines of the last poll start in ``kept``

    def _note(self, line: str) -> None:
        """Say ``line`` once per reading of the file."""
        if line not in self.reported:
            self.reported.add(line)
            self.say(line)

    def _alarm_say(self, line: str) -> None:
        if self._captured is not None and threading.current_thread() is threading.main_thread():
            self._captured.append(line)
        else:
            self.say(line)

    def _lines_from(self, start: int):
        """``(offset, line)`` of every line of ``kept`` from the offset ``start`` (a line's
        start) on."""
        k = start
        while k < len(self.kept):
            end = self.kept.index(b"\n", k) + 1
            yield k, bytes(self.kept[k:end])
            k = end

    def _is_event(self, offset: int, line: bytes) -> bool:
        return offset != self.header_at and is_row(line)

    def _set_anchor(self, anchor: Anchor) -> None:
        self.anchor = anchor
        self.anchors += 1

    def _take(self, lines: list[bytes], now: float) -> None:
        """Add complete lines (none after ``# avalanche``), read the catalogue, and move the
        anchor to the last event or ``# tilt-now`` among them."""
        start, row0 = len(self.kept), self.kept.count(b"\n") + 1
        self.new_from = start
        for j, line in enumerate(lines):
            m = marker(line)
            if m is not None and m[0] == "avalanche":
                self.avalanche = (row0 + j, m[1])
                lines = lines[:j]
                break
        for line in lines:
            if self.header_at is None and is_row(line):
                self.header_at = len(self.kept)
            self.kept += line
        if not self.header_bad and any(is_row(line) for line in lines):
            self._read_rows(start)
        # the lines again, as kept (a refused row blanked): the last event or marker read is
        # the anchor (an event's: the greatest angle so far, the angles' error sorted out)
        for j, (off, line) in enumerate(self._lines_from(start)):
            m = marker(line)
            if m is not None and m[0] == "tilt-now":
                anchor = Anchor(m[1], None, now, row0 + j)
                if self.read is None or self._resolve(anchor, self.read[1]):
                    self._set_anchor(anchor)
            elif self.read is not None and self._is_event(off, line):
                self._set_anchor(Anchor(None, float(self.read[0].alpha[-1]), now, row0 + j,
                                        event=True))

    def _read_rows(self, start: int) -> None:
        """Read ``kept`` with the catalogue reader; a refused row is said once and blanked
        (spaces: the rows after it keep their numbers), and the rest read again."""
        while True:
            trace = _Trace(bytes(self.kept))
            try:
                self.read = read_catalogue_stream(trace, self.where,
                                                  self.measurement.angle_resolution,
                                                  self.measurement.position_unit)
                return
            except ForecastInputError as exc:
                at = trace.line_start
                if at >= len(self.kept):  # refused at the end
                    if not self._skip_rows_from(start, exc):
                        return  # no event yet: nothing to say
                    continue
                self._note(str(exc))
                if at == self.header_at:
                    self.header_bad, self.read = True, None
                    return
                end = self.kept.index(b"\n", at)
                self.kept[at:end] = b" " * (end - at)

    def _skip_rows_from(self, start: int, exc) -> bool:
        """A refusal at the end of rows that hold events (a reader that checks the catalogue
        whole once read): said once, and the events added from ``start`` on skipped; False if
        there are none (the file holds no event yet)."""
        rows = [(off, line) for off, line in self._lines_from(start) if self._is_event(off, line)]
        if not rows:
            return False
        self._note(str(exc))
        for off, line in rows:
            self.kept[off:off + len(line) - 1] = b" " * (len(line) - 1)
        return True

    # -- the tilt --------------------------------------------------------------
    def _resolve(self, anchor: Anchor, scale: float) -> bool:
        """Read the anchor's angle in the catalogue's unit; an unreadable one is said once
        (naming its row or the option) and False."""
        if anchor.angle is not None:
            return True
        try:
            if anchor.text is None:
                raise ForecastInputError("no angle after it")
            anchor.angle = tilt_in_range(parse_angle(anchor.text, scale), "the angle")
            return True
        except ForecastInputError as exc:
            self._note(f"{anchor.origin(self.where)}: not a tilt reached ({exc}); ignored")
            return False

    def tilt(self, now: float) -> float | None:
        """The tilt reached at ``now`` (radians; None before the first event)."""
        if self.read is None:
            return None
        cat, scale, unit = self.read
        last = float(cat.alpha[-1])
        if self.anchor is not None and not self._resolve(self.anchor, scale):
            self._set_anchor(Anchor(None, last, now, None, event=True))
        a = self.anchor or Anchor(None, last, now, None, event=True)
        tilt = a.angle + (self.rate * (now - a.when) if self.rate else 0.0)
        if a.angle < last and not a.event and not a.raised_said:
            a.raised_said = True
            self.say(f"{a.origin(self.where)} ({math.degrees(a.angle):.3f}°) lies below the last "
                     f"event's angle ({math.degrees(last):.3f}°): the tilt reached is raised "
                     "to it")
        tilt = max(tilt, last)
        if tilt >= LAST_TILT:
            tilt = LAST_TILT
            if self.rate and not self._clock_stopped:
                self._clock_stopped = True
                self.say("the tilt reached 90°: the clock stops there")
        return tilt

    # -- one poll --------------------------------------------------------------
    def step(self) -> Update | None:
        """One poll: read what arrived, and forecast the state if it is new; the ``Update``,
        or None.  Sets ``stopped`` at ``# avalanche``, ``until`` or the end of the input."""
        if not self.proceed:
            return None
        if self.picture is not None:  # a picture that failed while the input was quiet
            self.picture.check()
        now = self.clock()
        notice, lines = self.reader.poll()
        if notice:
            self.say(f"{self.where} was {notice}: read again from its start")
            self._restart()
        if lines and self.avalanche is None:
            self._take(lines, now)
        if self._start is None:  # the tilt given is now's: after what the file held
            self._start = now
            if self.tilt_now is not None:
                self._set_anchor(Anchor(self.tilt_now, None, now, None))
        update = self._forecast(now)
        if self.avalanche is not None:
            self._stop_at_avalanche()
        elif self.reader.ended:
            self.stop("end of input", f"{self.where}: the input ended: stopped")
        return update

    def _forecast(self, now: float) -> Update | None:
        while True:
            tilt = self.tilt(now)
            if tilt is None:
                return None
            state = (self.reading, len(self.read[0]), self.anchors)
            if state == self._last and (tilt == self._last_tilt or not self.rate
                                        or now - self._last_time < CLOCK_SECONDS):
                return None  # nothing new (the clock: at most every CLOCK_SECONDS)
            self._last, self._last_tilt, self._last_time = state, tilt, now
            try:
                pred = self._predict(self.read, tilt)
                break
            except ForecastInputError as exc:  # a row the measurement cannot have made?
                if not self._skip_refused_row(exc):
                    self._note(str(exc))
                    return None
        events = len(self.read[0])
        # the first update says what the alarm can do for this kind of catalogue
        self._captured = [] if self.score.updates else [alarm_skill_line(
            pred.forecasts[0][1], pred.to_dict()["alarm_threshold"], self.alarm.threshold)]
        try:
            alarm = self.alarm.update(pred, events)
            update = Update(pred, events, alarm, self._captured)
        finally:
            self._captured = None
        self.score.add(update.to_dict())
        if self.picture is not None:
            self.picture.show(pred, {"alarm": update.alarm["alarm"], "rows": events,
                                     "alarm_threshold": self.alarm.levels(pred)[0],
                                     "file": self.where, "time": datetime.datetime.now()})
        self.updates += 1
        release_freed_memory()
        if self.until is not None and tilt >= self.until:
            self.stop("until", f"the tilt reached {math.degrees(tilt):.2f}° (--until "
                               f"{self.until_text}): stopped")
        return update

    def _predict(self, read, tilt: float):
        return self.forecast((read[0], 1.0, "rad"), tilt, self.measurement,
                                       self.within, self.method)

    def _skip_refused_row(self, exc) -> bool:
        """After the forecast refused the catalogue (a size the measurement cannot have
        recorded): the first row of the last poll with which it is refused is named (with the
        refusal) and skipped, and the rest read again; False if the catalogue is refused
        without any of them (nothing to skip)."""
        rows = [(off, line) for off, line in self._lines_from(self.new_from)
                if self._is_event(off, line)]

        def refusal(j: int):  # the refusal of the catalogue up to new row j (-1: none of them)
            end = rows[j][0] + len(rows[j][1]) if j >= 0 else self.new_from
            try:
                read = read_catalogue_stream(io.BytesIO(bytes(self.kept[:end])), self.where,
                                             self.measurement.angle_resolution,
                                             self.measurement.position_unit)
            except ForecastInputError:
                return None  # no event yet
            try:
                self._predict(read, float(read[0].alpha[-1]))
            except ForecastInputError as err:
                return err
            return None

        if not rows or refusal(-1) is not None:
            return False
        lo, hi, err = -1, len(rows) - 1, exc  # refusal(lo) is None, the whole state refused
        while hi - lo > 1:
            mid = (lo + hi) // 2
            found = refusal(mid)
            lo, hi, err = (lo, mid, found) if found is not None else (mid, hi, err)
        off, line = rows[hi]
        row = self.kept.count(b"\n", 0, off) + 1
        self._note(f"{self.where}: row {row}: {err}")
        self.kept[off:off + len(line) - 1] = b" " * (len(line) - 1)
        self.read = None
        self._read_rows(self.new_from)
        if self.anchor is not None and self.anchor.event and self.anchor.row == row:
            self._set_anchor(Anchor(None, float(self.read[0].alpha[-1]), self.anchor.when, None,
                                    event=True) if self.read is not None else None)
        self._last = None
        return True

    def _stop_at_avalanche(self) -> None:
        row, text = self.avalanche
        angle = None
        if text is not None:
            scale = self.read[1] if self.read is not None else DEG
            try:
                angle = tilt_in_range(parse_angle(text, scale), "the angle")
            except ForecastInputError as exc:
                self._note(f"{self.where}: row {row}: # avalanche {text}: {exc}; the run is "
                           "scored at the last tilt reached")
        self.summary = self.score.summary(angle)
        at = "" if angle is None else f" at {math.degrees(angle):.2f}°"
        self.stop("avalanche", f"avalanche recorded in {self.where}{at} (row {row}): stopped")

    def wait(self) -> None:
        """Wait for the next poll (less if a stream's data arrive)."""
        self.reader.wait(self.poll_seconds)

    def close(self) -> None:
        """Close the input; wait for the last picture (its failure raised)."""
        self.reader.close()
        if self.picture is not None:
            picture, self.picture = self.picture, None
            picture.close()

    def _signal(self, signum, frame):
        self.signum = signum
        self.on_signal(signum, frame)

    @contextlib.contextmanager
    def _signals_handled(self):
        """Within: SIGINT and SIGTERM recorded and raised (``_signal``); the previous handlers
        restored on exit."""
        old = {s: signal.signal(s, self._signal) for s in (signal.SIGTERM, signal.SIGINT)}
        try:
            yield
        finally:
            for s, h in old.items():
                signal.signal(s, h)

    def __iter__(self):
        """The updates, one per new state, until a stop; SIGINT and SIGTERM stop the loop
        (their handler raises while it runs: a call blocked in the kernel returns)."""
        main = threading.current_thread() is threading.main_thread()
        with self._signals_handled() if main else contextlib.nullcontext():
            finished = False
            try:
                while self.proceed:
                    try:
                        update = self.step()
                        if update is None and self.proceed:
                            self.wait()
                    except KeyboardInterrupt as exc:
                        self.stop_by_signal(exc)
                        break
                    if update is not None:
                        yield update
                finished = True
            finally:
                self.reader.close()
            if finished and self.stopped.status == 0:
                self.close()  # the last picture written (a signal leaves it behind)

