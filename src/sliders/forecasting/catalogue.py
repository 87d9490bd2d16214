"""A measured catalogue read with its measurement, and a catalogue written as the CSV that is
read (``python -m sliders.forecast catalogue`` writes a simulated row so), and a catalogue at
the tilt reached (``prepared``).

``predict`` reads a CSV file with a header, one event per row, columns
``angle [deg]`` or ``angle [rad]`` (increasing, within the angle error: a noisy
catalogue in time order is sorted), ``size`` (sliders or grains
moved, >= 1), optionally ``displacement``, ``first`` and ``last`` (0-based
positions of the first and last mover); bad input gets one line naming the row
and the column (``io.forecast_files.read_catalogue_csv``).  How it was measured
(angle error, smallest size, missed events, size unit, pile) are flags, read
here as a ``Measurement``.

``catalogue_csv_text`` writes a catalogue as that CSV.
"""

from __future__ import annotations

import io
import math
import numbers
import os

import numpy as np

from ..analysis.forecast.measurement import Measurement
from ..io.catalogue import Catalogue
from ..io.forecast_files import (ANGLE_TOLERANCE_RESOLUTIONS, CatalogueRead, ForecastInputError,
                                 angle_option, parse_angle, read_catalogue_columns,
                                 read_catalogue_file, read_catalogue_stream, tilt_in_range)

#: a tilt reached below the last event's angle by less than this many angle resolutions is the
#: angles' error, not a mistake: the last event's angle is taken instead
TILT_TOLERANCE_RESOLUTIONS = 3.0


def read_source(source, where: str = "catalogue", angle_resolution: float = 0.0,
                position_unit: str = "sliders"):
    """The events of ``source``, the radians per unit of its angles and that unit's name
    (``io.forecast_files.CatalogueRead``: with ``reordered``, the rows sorted).

    ``source``: a CSV file's path (``-``: standard input); the CSV's bytes (``where`` names
    them in a refusal); a mapping or a pandas-like DataFrame whose keys are the CSV header's
    names (``"angle [deg]"`` or ``"angle [rad]"``, ``"size"``, ...), each a column of values,
    every cell checked as the CSV reader checks a field (``read_catalogue_columns``); or a
    ``Catalogue`` (radians).  Every refusal is one line naming the row and the column.
    ``angle_resolution`` (radians): the angles' error; rows in time order whose angles go back
    by less than ``ANGLE_TOLERANCE_RESOLUTIONS`` of it are sorted by angle, as the training's
    noisy catalogues are.  ``position_unit``: the movers' positions as slider indices,
    fractions of the pile's length, or mm along it (``Measurement.position_unit``).
    """
    if isinstance(source, Catalogue):
        return CatalogueRead(source, 1.0, "rad")
    if isinstance(source, (bytes, bytearray)):
        return read_catalogue_stream(io.BytesIO(bytes(source)), where, angle_resolution,
                                     position_unit)
    if isinstance(source, (str, os.PathLike)):
        return read_catalogue_file(os.fspath(source), angle_resolution, position_unit)
    if hasattr(source, "keys") and hasattr(source, "__getitem__"):
        return read_catalogue_columns(source, where, angle_resolution, position_unit)
    raise ForecastInputError(f"catalogue: a {type(source).__name__}; give a CSV file's path, or "
                             "a mapping or DataFrame of the CSV's columns")


def angles_and_sizes(cat: Catalogue) -> tuple[Catalogue, bool]:
    """``cat`` and whether it is complete (displacements and movers); an incomplete one is kept
    to its angles and sizes (no displacement, no movers)."""
    return (cat, True) if cat.complete else (cat.angles_and_sizes(), False)


def record_kind(cat: Catalogue, measurement) -> str:
    """``"complete"``, ``"camera"``, ``"blind"`` or ``"sized"`` (``common.LEARNED_BY_RECORD``): a
    catalogue with every displacement is a camera's when its displacements or positions are
    not in the model's units, or when its movers are not all given; one of angles and sizes
    is "sized" when the pile's number of sliders is told.  A catalogue whose displacements are
    all 0 (``Catalogue.angles_and_sizes``) has none: every event moves some slider."""
    if len(cat) == 0 or np.isnan(cat.displacement).any() or not (cat.displacement > 0).any():
        return "blind" if measurement.n_sliders is None else "sized"
    whole = bool((cat.first >= 0).all())
    return "complete" if whole and not measurement.camera else "camera"


def camera_record(cat: Catalogue) -> Catalogue:
    """A camera's catalogue as its forecaster reads it: every displacement, the movers where
    given (else -1)."""
    known = (cat.first >= 0) & (cat.last >= 0)
    return Catalogue(cat.alpha, cat.size, cat.displacement, np.where(known, cat.first, -1),
                     np.where(known, cat.last, -1), cat.tilt_now)


def measurement_from(angle_resolution, min_size=1.0, missed_fraction=0.0, size_unit="sliders",
                     sliders=None, displacement_unit="model", position_unit="sliders",
                     pile_length=None) -> Measurement:
    """The ``Measurement`` of the ``predict`` flags' values (one line naming a bad flag);
    ``angle_resolution``: ``"0.3deg"``, ``"0.005rad"`` or a bare number of degrees;
    ``sliders``: a whole number (any integer, NumPy's too, or a float such as 100.0), or a
    range, ``"100-300"`` or a pair; ``displacement_unit``, ``position_unit`` and
    ``pile_length`` (mm): a camera's units."""
    res = angle_option(angle_resolution, "--angle-resolution")
    low, high = sliders_range(sliders)
    if pile_length is not None:
        try:
            pile_length = float(pile_length)
        except (TypeError, ValueError):
            raise ForecastInputError(f"--pile-length {pile_length}: the pile's length in mm, a "
                                     "positive number") from None
    try:
        return Measurement(res, float(min_size), float(missed_fraction), size_unit, low, high,
                           displacement_unit, position_unit, pile_length)
    except (TypeError, ValueError) as exc:
        raise ForecastInputError(f"measurement flags: {exc}") from None


def sliders_range(sliders) -> tuple[int | None, int | None]:
    """``--sliders`` (``sliders=``) as (least, largest or None): a whole number, or a range
    ``"100-300"`` (a pair of whole numbers); one line naming it otherwise."""
    if isinstance(sliders, str) and "-" in sliders.strip()[1:]:
        text = sliders.strip()
        cut = text.index("-", 1)
        low, high = sliders_option(text[:cut].strip()), sliders_option(text[cut + 1:].strip())
    elif isinstance(sliders, (tuple, list)) and len(sliders) == 2:
        low, high = sliders_option(sliders[0]), sliders_option(sliders[1])
    else:
        return sliders_option(sliders), None
    if high < low:
        raise ForecastInputError(f"--sliders {sliders}: a range is written least-largest "
                                 "(100-300)")
    return low, (high if high > low else None)


def sliders_option(sliders) -> int | None:
    """A number of sliders of ``--sliders`` (``sliders=``) as an int, or one line naming it."""
    if sliders is None:
        return None
    if isinstance(sliders, str):
        text = sliders.strip()
        sliders = int(text) if text.isdigit() else float(text) if _number(text) else text
    whole = None
    if isinstance(sliders, (bool, np.bool_)):
        pass
    elif isinstance(sliders, numbers.Integral):
        whole = int(sliders)
    elif isinstance(sliders, numbers.Real) and math.isfinite(sliders) and sliders == int(sliders):
        whole = int(sliders)
    if whole is None or whole < 1:
        raise ForecastInputError(f"--sliders {sliders}: the number of sliders of the pile must "
                                 "be a whole number of at least 1")
    return whole


def measurement_as_json(measurement) -> dict:
    """The measurement as JSON values (the angle error in degrees, as given)."""
    m = measurement
    return {"angle_resolution_deg": math.degrees(m.angle_resolution), "min_size": m.min_size,
            "missed_fraction": m.missed_fraction, "size_unit": m.size_unit,
            "n_sliders": m.n_sliders, "n_sliders_high": m.n_sliders_high,
            "displacement_unit": m.displacement_unit, "position_unit": m.position_unit,
            "pile_length_mm": m.pile_length}


def _number(text: str) -> bool:
    """``text`` reads as a float."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def catalogue_csv_text(cat) -> str:
    """A catalogue as the CSV ``predict`` reads (angles in radians, every column)."""
    lines = ["angle [rad],size,displacement,first,last"]
    for a, s, d, f, la in zip(cat.alpha, cat.size, cat.displacement, cat.first, cat.last):
        lines.append(f"{a:.10g},{int(s)},{d:.10g},{int(f)},{int(la)}")
    return "\n".join(lines) + "\n"


def prepared(read, tilt_now, measurement) -> tuple[Catalogue, list[str]]:
    """The catalogue read (``catalogue.read_source``'s triple) at the tilt reached ``tilt_now``
    (``at_tilt``) and the notes on what was done to it: its rows sorted by angle where they
    went back within the angle error (``io.forecast_files.ANGLE_TOLERANCE_RESOLUTIONS``)."""
    cat, scale, unit = read
    notes = []
    if reordered := getattr(read, "reordered", 0):
        notes.append(f"{reordered} of {len(cat)} rows lay below an earlier row's angle, within "
                     f"{ANGLE_TOLERANCE_RESOLUTIONS:g} × the angle resolution "
                     f"({math.degrees(measurement.angle_resolution):g}°): the rows are sorted by "
                     "angle, each keeping its size, as the training's noisy catalogues are")
    top = 1.0 if measurement.position_unit == "fraction" else measurement.pile_length
    if top is not None and len(cat) and max(cat.last.max(), cat.first.max()) > top * (1 + 1e-9):
        far = float(max(cat.last.max(), cat.first.max()))
        raise ForecastInputError(
            f"catalogue: a mover at {far:g} {measurement.position_unit} lies beyond the pile's "
            f"length ({top:g} {measurement.position_unit}): positions are measured along the "
            "pile from its up-slope end")
    return at_tilt(cat, tilt_now, scale, unit, measurement.angle_resolution, notes), notes


def at_tilt(cat, tilt_now, scale: float, unit: str, resolution: float, notes: list):
    """``cat`` at the tilt reached ``tilt_now`` (text or a bare number in ``unit``, ``scale``
    radians each); a tilt below the last event's angle by less than
    ``TILT_TOLERANCE_RESOLUTIONS`` angle resolutions is raised to it (a note in ``notes``)."""
    if tilt_now is None:
        return cat
    text = tilt_now if isinstance(tilt_now, str) else repr(tilt_now)
    if isinstance(tilt_now, str):
        tilt = parse_angle(tilt_now, scale)
    else:
        tilt = float(tilt_now) * scale
    tilt = tilt_in_range(tilt, f"--tilt-now {text}")
    last = float(cat.alpha[-1]) if len(cat) else 0.0
    if tilt < last:
        gap = last - tilt
        if gap >= TILT_TOLERANCE_RESOLUTIONS * resolution:
            raise ForecastInputError(
                f"--tilt-now {text}: below the last event's angle ({last / scale:g} {unit}) by "
                f"{math.degrees(gap):.3g}°, more than {TILT_TOLERANCE_RESOLUTIONS:g} × the angle "
                f"resolution ({math.degrees(resolution):g}°)")
        notes.append(f"--tilt-now {text} lies {math.degrees(gap):.3g}° below the last event's "
                     f"angle, within {TILT_TOLERANCE_RESOLUTIONS:g} × the angle resolution: the "
                     f"tilt reached is taken as the last event's, {math.degrees(last):.3f}°")
        tilt = last
    return Catalogue(cat.alpha, cat.size, cat.displacement, cat.first, cat.last, tilt_now=tilt)
