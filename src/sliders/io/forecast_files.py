"""The forecasting's files: a measured catalogue in CSV, and a fitted forecaster.

* ``read_catalogue_csv``: an experimenter's catalogue (docs/forecasting.md gives
  the format: ``angle [deg]`` or ``angle [rad]``, ``size``, optional
  ``displacement``, ``first``, ``last``); every refusal is one line naming the
  row and the column.
* ``save_model`` / ``load_model``: a fitted forecaster, pickled with its
  provenance and a CRC-32 (ours only: a pickle is code, never load an
  untrusted one).

``python -m sliders.forecast predict`` (``sliders.runs.forecast``) uses both.
"""

from __future__ import annotations

import csv
import io
import json
import math
import pathlib
import pickle
import sys
import zlib

import numpy as np

from .. import units
from .catalogue import Catalogue


class ForecastInputError(ValueError):
    """Bad input to the command: one line, no traceback."""


MODEL_FORMAT = "sliders-forecaster-1"


def save_model(path: str, forecaster, prov: dict) -> None:
    """Pickle a fitted forecaster with its provenance and a CRC-32 of the pickle (atomic write)."""
    from ..io.safeio import publish_bytes

    blob = pickle.dumps(forecaster, protocol=pickle.HIGHEST_PROTOCOL)
    head = json.dumps({"format": MODEL_FORMAT, "crc32": zlib.crc32(blob), **prov}).encode()
    publish_bytes(path, len(head).to_bytes(8, "little") + head + blob, overwrite=True)


def load_model(path: str):
    """A forecaster written by ``save_model`` (its checksum checked); returns (forecaster, header)."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise ForecastInputError(f"{path}: {exc.strerror or exc}") from None
    try:
        n = int.from_bytes(raw[:8], "little")
        head = json.loads(raw[8:8 + n])
        blob = raw[8 + n:]
    except (ValueError, UnicodeDecodeError):
        raise ForecastInputError(f"{path}: not a forecaster file of sliders") from None
    if head.get("format") != MODEL_FORMAT:
        raise ForecastInputError(f"{path}: not a forecaster file of sliders")
    if zlib.crc32(blob) != head.get("crc32"):
        raise ForecastInputError(f"{path}: checksum mismatch (damaged file)")
    return pickle.loads(blob), head


# ---------------------------------------------------------------------------
# a measured catalogue
# ---------------------------------------------------------------------------
ANGLE_UNITS = units.ANGLE_UNITS  # the one table of angle units, kept importable here


def _column_name(raw: str) -> tuple[str, str | None]:
    raw = raw.strip()
    if "[" in raw and raw.endswith("]"):
        name, unit = raw[:-1].split("[", 1)
        return name.strip().lower(), unit.strip().lower()
    return raw.lower(), None


def read_catalogue_csv(path: str, tilt_now_deg: float | None = None,
                       tilt_now_text: str | None = None) -> Catalogue:
    """A measured catalogue from CSV (module docstring); ``ForecastInputError`` names the row and column.

    Parameters
    ----------
    path : str
        The CSV file (header + one event per row; ``-`` reads standard input).
    tilt_now_text : str, optional
        The tilt reached, with its unit (``"27.5deg"``, ``"0.48rad"``); a bare
        number takes the angle column's unit.
    """
    try:
        text = sys.stdin.read() if path == "-" else pathlib.Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ForecastInputError(f"{path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ForecastInputError(f"{path}: not a text file (UTF-8)") from None
    numbered = [(k, ln) for k, ln in enumerate(text.splitlines(), start=1)
                if ln.strip() and not ln.lstrip().startswith("#")]
    if not numbered:
        raise ForecastInputError(f"{path}: empty file (a header and one event per row expected)")
    line_of = [k for k, _ in numbered]  # "row" in messages: the line of the file
    reader = list(csv.reader(io.StringIO("\n".join(ln for _, ln in numbered))))
    header = [_column_name(h) for h in reader[0]]
    names = [h[0] for h in header]
    if "angle" not in names:
        raise ForecastInputError(f"{path}: missing column 'angle [deg]' or 'angle [rad]' "
                                 f"(header: {', '.join(reader[0])})")
    if "size" not in names:
        raise ForecastInputError(f"{path}: missing column 'size' (header: {', '.join(reader[0])})")
    unit = header[names.index("angle")][1]
    if unit is None:
        raise ForecastInputError(f"{path}: column 'angle' needs its unit: 'angle [deg]' or 'angle [rad]'")
    if unit not in ANGLE_UNITS:
        raise ForecastInputError(f"{path}: column 'angle': unit {unit!r} not understood (deg or rad)")
    scale = ANGLE_UNITS[unit]
    if len(reader) < 2:
        raise ForecastInputError(f"{path}: no events (only a header)")
    cols = {n: [] for n in ("angle", "size", "displacement", "first", "last")}
    for j, rec in enumerate(reader[1:], start=1):
        i = line_of[j]
        if len(rec) != len(names):
            raise ForecastInputError(f"{path}: row {i}: {len(rec)} fields, the header has {len(names)}")
        for n, v in zip(names, rec):
            if n not in cols:
                continue
            try:
                x = float(v)
            except ValueError:
                raise ForecastInputError(f"{path}: row {i}, column {n!r}: {v.strip()!r} is not a number") \
                    from None
            if not math.isfinite(x):
                raise ForecastInputError(f"{path}: row {i}, column {n!r}: {v.strip()!r} is not finite")
            if n == "size" and (x < 1 or x != int(x)):
                raise ForecastInputError(f"{path}: row {i}, column 'size': {v.strip()!r} must be a whole "
                                         "number >= 1")
            if n == "displacement" and x < 0:
                raise ForecastInputError(f"{path}: row {i}, column 'displacement': {v.strip()!r} is negative")
            if n == "angle" and cols["angle"] and x * scale < cols["angle"][-1]:
                raise ForecastInputError(f"{path}: row {i}, column 'angle': {v.strip()!r} is below the "
                                         "previous row's (angles must increase)")
            cols[n].append(x * scale if n == "angle" else x)
    k = len(cols["angle"])
    alpha = np.array(cols["angle"])
    if alpha[0] < 0 or alpha[-1] >= math.pi / 2:
        raise ForecastInputError(f"{path}: column 'angle': tilts must lie in [0, 90°)")
    disp = np.array(cols["displacement"]) if cols["displacement"] else np.full(k, np.nan)
    first = np.array(cols["first"], dtype=np.int64) if cols["first"] else np.full(k, -1)
    last = np.array(cols["last"], dtype=np.int64) if cols["last"] else np.full(k, -1)
    tilt_now = None
    if tilt_now_text is not None:
        tilt_now = parse_angle(tilt_now_text, scale)
        if tilt_now < alpha[-1]:
            raise ForecastInputError(f"--tilt-now {tilt_now_text}: below the last event's angle "
                                     f"({alpha[-1] / scale:g} {unit})")
    return Catalogue(alpha, np.array(cols["size"], dtype=np.int64), disp, first, last, tilt_now=tilt_now)


def parse_angle(text: str, default_scale: float) -> float:
    """``"27.5deg"``, ``"0.48 rad"`` or a bare number (in ``default_scale``) -> radians
    (``sliders.units.parse_angle``, refusing with ``ForecastInputError``)."""
    return units.parse_angle(text, default_scale, ForecastInputError)
