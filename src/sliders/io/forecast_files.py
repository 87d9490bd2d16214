"""The forecasting's files: a measured catalogue in CSV, an evaluation's outputs.

* ``read_catalogue_csv``: an experimenter's catalogue (docs/forecasting.md gives
  the format: ``angle [deg]`` or ``angle [rad]``, ``size``, optional
  ``displacement``, ``first``, ``last``); every refusal is one line naming the
  row and the column.  It streams the file within stated bounds
  (``MAX_CATALOGUE_BYTES``, ``MAX_EVENTS``, ``MAX_LINE_BYTES``).  With an angle
  error given, rows in time order whose angles go back by less than
  ``ANGLE_TOLERANCE_RESOLUTIONS`` of it are sorted by angle, as the training
  sorts its noisy catalogues.  ``read_catalogue_columns`` reads the Python
  API's mapping of columns with the same checks, cell by cell.
* ``claim_folder``, ``OutputSet``, ``complete_publication``: a run's output
  files claimed, compared with its inputs by identity, staged whole and
  published as one set (docs/reliability.md, "The forecast commands").

The fitted forecasters' model file is ``io.forecast_model``'s.
``python -m sliders.forecast`` (``sliders.runs.forecast``) uses them.
"""

from __future__ import annotations

import array
import contextlib
import csv
import itertools
import json
import math
import numbers
import os
import signal
import stat
import sys

import numpy as np

from .. import units
from .catalogue import Catalogue
from .safeio import (fsync_dir, leftover_temporaries, printable, publish_bytes,
                     resolve_target, temporary_beside)
from .filelock import ClaimError, OutputClaim


class ForecastInputError(ValueError):
    """Bad input to the command: one line, no traceback."""


# ---------------------------------------------------------------------------
# a run's outputs, published as one set
# ---------------------------------------------------------------------------
#: the claim of a folder of outputs: ``FOLDER/.forecast-outputs.lock``, inside the folder, so that
#: every path reaching the folder (a symlink, a bind mount) meets the one lock of that folder
CLAIM_NAME = ".forecast-outputs"
#: the record of a set being published: written (atomically) once every file of the set is staged
#: whole; its presence means "move these into place", finished by whoever claims the folder next
JOURNAL_NAME = ".forecast-publishing.json"
JOURNAL_FORMAT = "sliders-publication-1"
MAX_JOURNAL_BYTES = 2**20


def claim_folder(folder: str):
    """Claim the output folder ``folder`` (``io.filelock.OutputClaim`` on the lock inside it)."""
    try:
        return OutputClaim(os.path.join(resolve_target(folder).real, CLAIM_NAME)).acquire()
    except ClaimError as exc:
        raise ClaimError(f"output folder {folder!r}: {exc}") from None


def check_output_target(path: str, inputs: dict, option: str = "--out") -> str:
    """The file ``path`` names (symlinks written through), refused in one line naming ``option``
    if it is one of ``inputs`` (``{what: FileTarget}``, compared by device and inode: a
    symbolic or hard link to an input is that input), not a regular file (a folder, a device, a
    pipe), or in a folder that does not exist."""
    target = resolve_target(path)
    for what, given in inputs.items():
        if target.same_file(given):
            how = " through a symbolic link" if os.path.islink(path) else ""
            raise ForecastInputError(f"{option} {path} is {what} {given.given!r}{how}; an output "
                                     f"never replaces an input: choose another {option}")
    if os.path.lexists(target.real) and not os.path.isfile(target.real):
        raise ForecastInputError(f"{option} {path}: exists and is not a regular file (a folder, "
                                 f"a device or a pipe); remove it or choose another {option}")
    folder = os.path.dirname(target.real) or "."
    if not os.path.isdir(folder):
        raise ForecastInputError(f"{option} {path}: the folder {folder!r} does not exist")
    return target.real


class OutputSet:
    """The files of one run, published together or not at all.

    ``add`` stages each file whole beside its target (``.NAME.XXXXXXXX.tmp``,
    flushed to the disk); ``publish`` records the staged set in the folder's
    journal (one atomic write: the commit point), then renames every file into
    place.  A run stopped before the journal leaves the previous set as it was
    (its temporaries are removed by ``discard``, or by the next claim holder);
    one killed after it is completed by ``complete_publication`` when the folder
    is next claimed.  Signals wait while the set is committed.
    """

    def __init__(self, folder: str, inputs: dict):
        self.folder = folder
        self.inputs = inputs
        self.staged: list[tuple[str, str]] = []

    def add(self, path: str, data: bytes) -> None:
        """Stage the whole file ``path`` (refused if it is an input)."""
        target = check_output_target(path, self.inputs)
        try:
            tmp = temporary_beside(target)
            self.staged.append((tmp, target))
            with open(tmp, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        except OSError as exc:  # named by the file the run was writing
            raise OSError(exc.errno, exc.strerror or str(exc), path) from None

    def publish(self) -> None:
        """Commit the staged set and move it into place."""
        record = json.dumps({"format": JOURNAL_FORMAT, "moves": self.staged}).encode()
        with _signals_held():
            publish_bytes(os.path.join(self.folder, JOURNAL_NAME), record, overwrite=True)
            self.staged = []
            complete_publication(self.folder)

    def discard(self) -> None:
        """Remove the staged files (nothing of them published)."""
        for tmp, _ in self.staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        self.staged = []

    def __enter__(self) -> "OutputSet":
        return self

    def __exit__(self, *exc) -> None:
        self.discard()


@contextlib.contextmanager
def _signals_held():
    """SIGINT and SIGTERM held back (delivered on leaving) while a set is committed."""
    held = {signal.SIGINT, signal.SIGTERM}
    old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def complete_publication(folder: str) -> int:
    """Finish the publication a killed run committed in ``folder`` (call holding its claim);
    returns the number of files moved into place (0: nothing was pending)."""
    path = os.path.join(folder, JOURNAL_NAME)
    try:
        with open(path, "rb") as fh:
            record = json.loads(fh.read(MAX_JOURNAL_BYTES))
        moves = record["moves"] if record.get("format") == JOURNAL_FORMAT else None
        moves = [(str(tmp), str(target)) for tmp, target in moves]
    except FileNotFoundError:
        return 0
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        raise ForecastInputError(f"{path}: not a publication record of sliders; remove it") from None
    moved = 0
    for tmp, target in moves:
        if tmp in leftover_temporaries(target):  # only the staged files of that target, if left
            os.replace(tmp, target)
            moved += 1
    for flushed in {os.path.dirname(target): target for _, target in moves}.values():
        fsync_dir(flushed)  # the renames survive a power loss
    os.unlink(path)
    fsync_dir(path)
    return moved


# ---------------------------------------------------------------------------
# a measured catalogue
# ---------------------------------------------------------------------------


def _column_name(raw: str) -> tuple[str, str | None]:
    raw = raw.strip()
    if "[" in raw and raw.endswith("]"):
        name, unit = raw[:-1].split("[", 1)
        return name.strip().lower(), unit.strip().lower()
    return raw.lower(), None


#: the reader's bounds: a catalogue beyond them is refused while it is read, before it can
#: fill the memory (1e6 events take 40 MB here; a laboratory catalogue holds thousands)
MAX_CATALOGUE_BYTES = 64 * 2**20
MAX_EVENTS = 1_000_000
MAX_LINE_BYTES = 4096
MAX_FIELD_CHARS = 64
#: slider positions: whole numbers up to 2^53, which a float64 holds exactly; sizes: positive
#: numbers (sliders, or an area, a volume, a pixel sum: whether they must be whole is the
#: measurement's to say, ``analysis.forecast.measurement.check_catalogue``)
MAX_WHOLE = 2**53
COLUMNS = ("angle", "size", "displacement", "first", "last")
WHOLE_COLUMNS = {"first": 0, "last": 0}  # column -> its least value


@contextlib.contextmanager
def _open_catalogue(path: str):
    """The catalogue's bytes (``-``: standard input); a regular file over the size limit is
    refused from its size, before a byte is read."""
    if path == "-":
        yield sys.stdin.buffer
        return
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise ForecastInputError(f"{path}: {exc.strerror or exc}") from None
    with fh:
        size = os.fstat(fh.fileno()).st_size
        if stat.S_ISREG(os.fstat(fh.fileno()).st_mode) and size > MAX_CATALOGUE_BYTES:
            raise ForecastInputError(f"{path}: {size / 2**20:.0f} MB; a catalogue may hold at most "
                                     f"{MAX_CATALOGUE_BYTES // 2**20} MB ({MAX_EVENTS} events)")
        yield fh


def _numbered_lines(fh, path: str):
    """``(line number, text)`` of every line that is neither blank nor a ``#`` comment, read
    one bounded line at a time (a byte-order mark before the header is dropped)."""
    total = 0
    for k in itertools.count(1):
        try:
            raw = fh.readline(MAX_LINE_BYTES + 1)
        except OSError as exc:
            raise ForecastInputError(f"{path}: {exc.strerror or exc}") from None
        if not raw:
            return
        total += len(raw)
        if len(raw) > MAX_LINE_BYTES:
            raise ForecastInputError(f"{path}: row {k}: longer than {MAX_LINE_BYTES} bytes "
                                     "(not a catalogue of numbers)")
        if total > MAX_CATALOGUE_BYTES:
            raise ForecastInputError(f"{path}: row {k}: beyond {MAX_CATALOGUE_BYTES // 2**20} MB, "
                                     "the most a catalogue may hold")
        try:
            text = raw.decode("utf-8-sig" if k == 1 else "utf-8").rstrip("\r\n")
        except UnicodeDecodeError:
            raise ForecastInputError(f"{path}: row {k}: not UTF-8 text") from None
        if text.strip() and not text.lstrip().startswith("#"):
            yield k, text


def _fields(text: str, k: int, path: str) -> list[str]:
    if '"' not in text and "\0" not in text:
        return text.split(",")
    try:
        return next(csv.reader([text]))
    except csv.Error as exc:
        raise ForecastInputError(f"{path}: row {k}: {exc}") from None


def _header(lines, path: str) -> tuple[list[str], float, str]:
    """The column of every field (``""``: not read), the angle unit's scale, and its name."""
    try:
        k, text = next(lines)
    except StopIteration:
        raise ForecastInputError(f"{path}: empty file (a header and one event per row expected)") \
            from None
    raw = _fields(text, k, path)
    header = [_column_name(h) for h in raw]
    names = [h[0] for h in header]
    shown = printable(", ".join(raw))  # file text, on a terminal: control characters escaped
    for n in COLUMNS:
        where = [j + 1 for j, m in enumerate(names) if m == n]
        if len(where) > 1:
            raise ForecastInputError(f"{path}: row {k}: column {n!r} appears {len(where)} times "
                                     f"(fields {', '.join(map(str, where))}); keep one")
    if "angle" not in names:
        raise ForecastInputError(f"{path}: missing column 'angle [deg]' or 'angle [rad]' "
                                 f"(header: {shown})")
    if "size" not in names:
        raise ForecastInputError(f"{path}: missing column 'size' (header: {shown})")
    if ("first" in names) != ("last" in names):
        given, missing = ("first", "last") if "first" in names else ("last", "first")
        raise ForecastInputError(f"{path}: column {given!r} without {missing!r}: the first and "
                                 f"last movers of an event go together (header: {shown})")
    unit = header[names.index("angle")][1]
    if unit is None:
        raise ForecastInputError(f"{path}: column 'angle' needs its unit: 'angle [deg]' or 'angle [rad]'")
    if unit not in units.ANGLE_UNITS:
        raise ForecastInputError(f"{path}: column 'angle': unit {unit!r} not understood (deg or rad)")
    return [n if n in COLUMNS else "" for n in names], units.ANGLE_UNITS[unit], unit


def _value(v: str, k: int, n: str, path: str, position_unit: str = "sliders") -> float:
    """One field of column ``n`` on row ``k`` as a number, checked (``_checked``)."""
    s = v.strip()
    if len(s) > MAX_FIELD_CHARS:
        raise ForecastInputError(f"{path}: row {k}, column {n!r}: a field of {len(s)} characters "
                                 f"(a number has at most {MAX_FIELD_CHARS})")
    try:
        x = float(s)
    except ValueError:
        raise ForecastInputError(f"{path}: row {k}, column {n!r}: {s!r} is not a number") from None
    return _checked(x, s, k, n, path, position_unit)


def _checked(x: float, s: str, k: int, n: str, path: str, position_unit: str = "sliders") -> float:
    """The number ``x`` (shown as ``s``) of column ``n`` on row ``k``, if that column may hold it
    (``position_unit``: the movers' positions as slider indices, "fraction" of the pile's
    length, or "mm" along it)."""
    if not math.isfinite(x):
        raise ForecastInputError(f"{path}: row {k}, column {n!r}: {s!r} is not finite")
    if n in WHOLE_COLUMNS and position_unit != "sliders":
        top = 1.0 if position_unit == "fraction" else MAX_WHOLE
        if not 0.0 <= x <= top:
            raise ForecastInputError(f"{path}: row {k}, column {n!r}: {s!r} is not a position "
                                     f"from 0 to {top:g} ({position_unit})")
    elif n in WHOLE_COLUMNS and not (WHOLE_COLUMNS[n] <= x <= MAX_WHOLE and x == int(x)):
        raise ForecastInputError(f"{path}: row {k}, column {n!r}: {s!r} must be a whole number "
                                 f"from {WHOLE_COLUMNS[n]} to 2**53")
    if n == "size" and not 0 < x <= MAX_WHOLE:
        raise ForecastInputError(f"{path}: row {k}, column 'size': {s!r} must be a positive "
                                 "number (at most 2**53)")
    if n == "displacement" and x < 0:
        raise ForecastInputError(f"{path}: row {k}, column 'displacement': {s!r} is negative")
    return x


#: a row's angle may lie below the greatest angle of the rows before it by less than this many
#: angle resolutions (the measurement's standard deviation of an angle's error): the rows are
#: then sorted by angle, each keeping its size, displacement and movers, as the training's
#: noisy catalogues are (``analysis.forecast.measurement.degrade``).  The difference of two
#: angles with independent errors of standard deviation s spreads as s*sqrt(2): 6 s is 4.2 of
#: those spreads, a chance of 1e-5 a pair.  Measured against the greatest angle before (the
#: error of the highest of the nearby rows), noise of s on the angles of 200 rows over 200 s
#: of tilt (29 % of consecutive rows going backwards) is refused at most 2 times in 1000, on
#: 1000 rows over 200 s about 13 times in 1000; 5 s refuses 2 % and 29 %, 4 s 18 % and 98 %.
ANGLE_TOLERANCE_RESOLUTIONS = 6.0


class CatalogueRead(tuple):
    """``(catalogue, radians per unit of its angles, that unit's name)`` as read; ``reordered``:
    the rows that lay below an earlier row's angle, within the angle error, and were sorted."""

    reordered = 0

    def __new__(cls, catalogue: Catalogue, scale: float, unit: str, reordered: int = 0):
        out = super().__new__(cls, (catalogue, scale, unit))
        out.reordered = reordered
        return out


class _EventRows:
    """The events read so far, column by column (float64 arrays, at most ``MAX_EVENTS``), each
    row checked as it comes: the first mover not after the last, the angle in [0, 90°) and not
    below the rows before it by ``ANGLE_TOLERANCE_RESOLUTIONS`` angle resolutions or more."""

    def __init__(self, names, scale: float, where: str, angle_resolution: float = 0.0,
                 position_unit: str = "sliders"):
        self.cols = {n: array.array("d") for n in names if n}
        self.position_unit = position_unit
        self.scale, self.where = scale, where
        self.tolerance = ANGLE_TOLERANCE_RESOLUTIONS * angle_resolution  # radians
        self.top, self.top_row, self.reordered = -math.inf, 0, 0

    def room(self, k: int) -> None:
        """Refuse row ``k`` if the catalogue already holds ``MAX_EVENTS`` events."""
        if len(self.cols["angle"]) == MAX_EVENTS:
            raise ForecastInputError(f"{self.where}: row {k}: more than {MAX_EVENTS} events, the "
                                     "most a catalogue may hold")

    def add(self, k: int, values: dict, shown_angle: str) -> None:
        """Row ``k``: ``values`` (column -> checked number); ``shown_angle`` its angle's text."""
        where, cols = self.where, self.cols
        for n, x in values.items():
            cols[n].append(x)
        if "first" in cols and cols["first"][-1] > cols["last"][-1]:
            raise ForecastInputError(f"{where}: row {k}, columns 'first' and 'last': the first "
                                     f"mover ({cols['first'][-1]:g}) lies after the last "
                                     f"({cols['last'][-1]:g})")
        a = cols["angle"][-1] * self.scale
        if not 0 <= a < math.pi / 2:
            raise ForecastInputError(f"{where}: row {k}, column 'angle': {shown_angle!r} is "
                                     "outside [0, 90°)")
        if a < self.top:
            self.behind(k, a, shown_angle)
        else:
            self.top, self.top_row = a, k

    def behind(self, k: int, a: float, shown: str) -> None:
        """Row ``k``'s angle ``a`` lies below an earlier row's: taken within the angle error
        (the rows are sorted at the end), else refused."""
        gap = self.top - a
        if self.tolerance == 0:
            raise ForecastInputError(
                f"{self.where}: row {k}, column 'angle': {shown!r} is below the previous row's "
                "(angles must increase; angles with an error may go back by less than "
                f"{ANGLE_TOLERANCE_RESOLUTIONS:g} resolutions: give --angle-resolution)")
        if gap >= self.tolerance:
            raise ForecastInputError(
                f"{self.where}: row {k}, column 'angle': {shown!r} lies {math.degrees(gap):.3g}° "
                f"below row {self.top_row}'s angle, {ANGLE_TOLERANCE_RESOLUTIONS:g} angle "
                f"resolutions ({math.degrees(self.tolerance):.3g}°) or more: angles must "
                "increase, within their error")
        self.reordered += 1

    def read(self, unit: str) -> CatalogueRead:
        """The catalogue of the rows (sorted by angle if some went back), as ``CatalogueRead``."""
        cols = self.cols
        if not cols["angle"]:
            raise ForecastInputError(f"{self.where}: no events (only a header)")
        k = len(cols["angle"])
        arrays = {n: np.frombuffer(v, dtype=np.float64) for n, v in cols.items()}
        if self.reordered:  # as degrade orders a noisy catalogue: stable, rows kept whole
            order = np.argsort(arrays["angle"], kind="stable")
            arrays = {n: v[order] for n, v in arrays.items()}

        def column(n, fill, dtype):
            return arrays[n].astype(dtype) if n in arrays else np.full(k, fill, dtype)

        place = np.int64 if self.position_unit == "sliders" else np.float64
        cat = Catalogue(arrays["angle"] * self.scale, column("size", 1, np.float64),
                        column("displacement", np.nan, np.float64), column("first", -1, place),
                        column("last", -1, place))
        return CatalogueRead(cat, self.scale, unit, self.reordered)


def _events(lines, names: list[str], scale: float, path: str,
            angle_resolution: float = 0.0, position_unit: str = "sliders") -> _EventRows:
    """The events of the CSV's rows (``_EventRows``)."""
    rows = _EventRows(names, scale, path, angle_resolution, position_unit)
    at = names.index("angle")
    for k, text in lines:
        rec = _fields(text, k, path)
        if len(rec) != len(names):
            raise ForecastInputError(f"{path}: row {k}: {len(rec)} fields, the header has {len(names)}")
        rows.room(k)
        rows.add(k, {n: _value(v, k, n, path, position_unit) for n, v in zip(names, rec) if n},
                 rec[at].strip())
    return rows


def read_catalogue_csv(path: str, tilt_now_text: str | None = None) -> Catalogue:
    """A measured catalogue from CSV (module docstring); ``ForecastInputError`` names the row and column.

    The file is read as a stream, one bounded line at a time: at most
    ``MAX_CATALOGUE_BYTES`` (64 MB), ``MAX_EVENTS`` events and
    ``MAX_LINE_BYTES`` per line.  A UTF-8 byte-order mark (a spreadsheet's
    "CSV UTF-8") is read as such.

    Parameters
    ----------
    path : str
        The CSV file (header + one event per row; ``-`` reads standard input).
    tilt_now_text : str, optional
        The tilt reached, with its unit (``"27.5deg"``, ``"0.48rad"``); a bare
        number takes the angle column's unit.
    """
    cat, scale, unit = read_catalogue_file(path)
    tilt_now = None
    if tilt_now_text is not None:
        tilt_now = tilt_in_range(parse_angle(tilt_now_text, scale), f"--tilt-now {tilt_now_text}")
        if tilt_now < cat.alpha[-1]:
            raise ForecastInputError(f"--tilt-now {tilt_now_text}: below the last event's angle "
                                     f"({cat.alpha[-1] / scale:g} {unit})")
        cat.tilt_now = tilt_now
    return cat


def read_catalogue_file(path: str, angle_resolution: float = 0.0,
                        position_unit: str = "sliders") -> CatalogueRead:
    """The catalogue of the CSV file ``path`` (``-``: standard input), the radians per unit of its
    angle column and that unit's name (``read_catalogue_stream``), within the reader's bounds."""
    with _open_catalogue(path) as fh:
        return read_catalogue_stream(fh, path, angle_resolution, position_unit)


def read_catalogue_stream(fh, where: str, angle_resolution: float = 0.0,
                          position_unit: str = "sliders") -> CatalogueRead:
    """The catalogue of the CSV bytes of ``fh`` (a binary file, read to its end), the radians per
    unit of its angle column and that unit's name; its ``tilt_now`` is its greatest angle.
    ``angle_resolution`` (radians): the angles' error, within which a row may lie below the
    rows before it (``ANGLE_TOLERANCE_RESOLUTIONS``; the rows are then sorted by angle).
    ``position_unit``: the movers' positions (``first``, ``last``) as slider indices (whole
    numbers), "fraction" of the pile's length (0 to 1), or "mm" along it (from 0), read as
    floats.  Refusals as ``read_catalogue_csv``'s, naming ``where``."""
    lines = _numbered_lines(fh, where)
    names, scale, unit = _header(lines, where)
    return _events(lines, names, scale, where, angle_resolution, position_unit).read(unit)


def read_catalogue_columns(columns, where: str = "catalogue", angle_resolution: float = 0.0,
                           position_unit: str = "sliders") -> CatalogueRead:
    """The catalogue of a mapping (or DataFrame) of columns keyed by the CSV header's names, each
    cell checked as the CSV reader checks its fields, rows numbered as the CSV's would be (the
    header is row 1).  A cell is a number (a Python or NumPy integer or float) or the text of
    one; anything else (None, a bool, a text holding a comma or a line break) is refused in one
    line naming its row and column, and so is a catalogue of more than ``MAX_EVENTS`` rows,
    before a cell is read."""
    keys = list(columns.keys())
    names = [str(key) for key in keys]
    for name in names:
        if any(c in name for c in ',"\r\n') or not name.isprintable():
            raise ForecastInputError(f"{where}: column name '{printable(name)}' holds a comma, a "
                                     "quote or a control character")
    values = []
    for name, key in zip(names, keys):
        column = columns[key]
        try:
            length = 1 if isinstance(column, str) else len(column)
        except TypeError:  # one value
            length = 1
        if length > MAX_EVENTS:  # refused before a cell is copied
            raise ForecastInputError(f"{where}: column {name!r} of {length} rows, more than "
                                     f"{MAX_EVENTS} events, the most a catalogue may hold")
        values.append(np.asarray(column, dtype=object))
    if any(v.ndim > 1 for v in values):
        raise ForecastInputError(f"{where}: a column of {max(v.ndim for v in values)} "
                                 "dimensions; each column is one value per event")
    values = [np.atleast_1d(v) for v in values]
    if len({len(v) for v in values}) > 1:
        raise ForecastInputError(f"{where}: its columns differ in length ("
                                 + ", ".join(f"{n}: {len(v)}" for n, v in zip(names, values)) + ")")
    n_rows = len(values[0]) if values else 0
    header, scale, unit = _header(iter([(1, ",".join(names))]), where)
    used = [(n, v.tolist()) for n, v in zip(header, values) if n]
    rows = _EventRows(header, scale, where, angle_resolution, position_unit)
    for i in range(n_rows):
        k = i + 2
        cells = {n: _cell(v[i], k, n, where, position_unit) for n, v in used}
        rows.add(k, {n: x for n, (x, _) in cells.items()}, cells["angle"][1])
    return rows.read(unit)


def _cell(v, k: int, n: str, where: str, position_unit: str = "sliders") -> tuple[float, str]:
    """One cell of a mapping's column ``n`` on row ``k``: the checked number and its text."""
    if isinstance(v, str):
        if any(c in v for c in ",\r\n") or not v.isprintable():
            raise ForecastInputError(f"{where}: row {k}, column {n!r}: '{printable(v)}' holds a "
                                     "comma, a line break or a control character (a cell is "
                                     "one number)")
        return _value(v, k, n, where, position_unit), v.strip()
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
        what = "None (an empty cell)" if v is None else f"a {type(v).__name__} ({printable(repr(v))[:40]})"
        raise ForecastInputError(f"{where}: row {k}, column {n!r}: {what} is not a number")
    try:
        x = float(v)
    except (OverflowError, ValueError, TypeError):
        raise ForecastInputError(f"{where}: row {k}, column {n!r}: {printable(repr(v))[:40]} is "
                                 "not a finite number") from None
    shown = str(int(v)) if isinstance(v, numbers.Integral) else repr(x)
    return _checked(x, shown, k, n, where, position_unit), shown


def tilt_in_range(angle: float, what: str) -> float:
    """``angle`` (radians) if it lies in [0, 90°), else a one-line refusal naming ``what``."""
    if not 0.0 <= angle < math.pi / 2:
        raise ForecastInputError(f"{what}: {math.degrees(angle):g}° is outside [0, 90°) "
                                 "(a tilt of the incline)")
    return angle


def angle_option(value, option: str, default_scale: float = math.pi / 180.0) -> float:
    """The angle (radians) of an angle option's value: ``"0.3deg"``, ``"0.005rad"``, or a bare
    number in ``default_scale`` radians a unit (degrees unless said); one line naming the option
    if it is not a finite angle of at least 0."""
    text = value if isinstance(value, str) else repr(value)
    try:
        x = parse_angle(text, default_scale) if isinstance(value, str) else float(value) * default_scale
    except (ForecastInputError, TypeError, ValueError):
        raise ForecastInputError(f"{option} {text}: not an angle (e.g. 0.3deg, 0.005rad, or a "
                                 "bare number of degrees)") from None
    if not (math.isfinite(x) and x >= 0):
        raise ForecastInputError(f"{option} {text}: an angle of at least 0 is expected")
    return x


def parse_angle(text: str, default_scale: float) -> float:
    """``"27.5deg"``, ``"0.48 rad"`` or a bare number (in ``default_scale``) -> radians
    (``sliders.units.parse_angle``, refusing with ``ForecastInputError``)."""
    return units.parse_angle(text, default_scale, ForecastInputError)
