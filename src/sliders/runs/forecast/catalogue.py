"""The catalogues of the forecast commands: a measured one read with its measurement
(``predict``), and a simulated row written as one (``python -m sliders.forecast catalogue``).

``predict`` reads a CSV file with a header, one event per row, columns
``angle [deg]`` or ``angle [rad]`` (increasing), ``size`` (sliders or grains
moved, >= 1), optionally ``displacement``, ``first`` and ``last`` (0-based
positions of the first and last mover); bad input gets one line naming the row
and the column (``io.forecast_files.read_catalogue_csv``).  How it was measured
(angle error, smallest size, missed events, size unit, pile) are flags, read
here as a ``Measurement``.

``catalogue`` writes one simulated row as the CSV ``predict`` reads, cut at a
tilt or a lead before its avalanche: the documentation's examples are made so.

    python -m sliders.forecast catalogue --data prior.h5 --row 7 --lead 3deg --out row7.csv
"""

from __future__ import annotations

import math
import os

import numpy as np

from ...analysis.forecast.measurement import Measurement
from ...io.catalogue import Catalogue
from ...io.forecast_files import ForecastInputError, parse_angle, read_catalogue_csv
from ...io.safeio import publish_bytes
from .common import load_set


def read_measured(path: str, tilt_now: str | None) -> tuple[Catalogue, bool]:
    """The measured catalogue of ``path`` cut at ``tilt_now`` (text, as given), and whether it is
    complete (displacements and movers); an incomplete one holds angles and sizes only."""
    cat = read_catalogue_csv(path, tilt_now_text=tilt_now)
    complete = not np.isnan(cat.displacement).any() and bool((cat.first >= 0).all())
    if not complete:  # angles and sizes only: no displacement, no movers
        cat = Catalogue(cat.alpha, cat.size, np.zeros(len(cat)), np.full(len(cat), -1),
                        np.full(len(cat), -1), cat.tilt_now)
    return cat, complete


def measurement_of(args):
    """The ``Measurement`` the flags of ``predict`` describe (one line naming a bad flag)."""
    try:
        return Measurement(math.radians(args.angle_resolution), args.min_size,
                           args.missed_fraction, args.size_unit, args.sliders)
    except ValueError as exc:
        raise ForecastInputError(f"measurement flags: {exc}") from None


def measurement_as_json(measurement) -> dict:
    """The measurement as JSON values (the angle error in degrees, as given)."""
    return {"angle_resolution_deg": math.degrees(measurement.angle_resolution),
            "min_size": measurement.min_size, "missed_fraction": measurement.missed_fraction,
            "size_unit": measurement.size_unit, "n_sliders": measurement.n_sliders}


def catalogue_csv_text(cat) -> str:
    """A catalogue as the CSV ``predict`` reads (angles in radians, every column)."""
    lines = ["angle [rad],size,displacement,first,last"]
    for a, s, d, f, la in zip(cat.alpha, cat.size, cat.displacement, cat.first, cat.last):
        lines.append(f"{a:.10g},{int(s)},{d:.10g},{int(f)},{int(la)}")
    return "\n".join(lines) + "\n"


def catalogue(args, argv=None) -> int:
    """Write row ``--row`` of ``--data`` as a catalogue CSV cut at ``--at`` or ``--lead``."""
    data = load_set(args.data)
    if not 0 <= args.row < len(data):
        raise ForecastInputError(f"--row {args.row}: {args.data} has rows 0..{len(data) - 1}")
    a_c = float(data.alpha_c[args.row])
    if args.lead is not None:
        if not math.isfinite(a_c):
            raise ForecastInputError(f"--lead: row {args.row} did not reach the avalanche")
        tilt = a_c - parse_angle(args.lead, math.pi / 180.0)
    else:
        tilt = parse_angle(args.at, math.pi / 180.0)
    if not 0.0 < tilt < (a_c if math.isfinite(a_c) else math.pi / 2):
        raise ForecastInputError(f"--lead/--at: the cut at {math.degrees(tilt):.3f}° is not "
                                 f"between 0 and the row's end ({math.degrees(a_c):.3f}°)")
    cut = data.catalogue(args.row).cut(tilt)
    text = f"# row {args.row} of {os.path.basename(args.data)} cut at {tilt:.10g} rad; " \
           f"alpha_c = {a_c:.10g} rad\n" + catalogue_csv_text(cut)
    publish_bytes(args.out, text.encode(), overwrite=True)
    print(f"{args.out}: {len(cut)} events up to {math.degrees(tilt):.3f}° (alpha_c "
          f"{math.degrees(a_c):.3f}°); predict with --tilt-now {tilt:.10g}rad")
    return 0
