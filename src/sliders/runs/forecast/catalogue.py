"""``python -m sliders.forecast catalogue``: a simulated row written as the CSV ``predict``
reads, cut at a tilt or a lead before its avalanche (the documentation's examples are made so);
the prior files' rows read for the commands (``load_set``: ``evaluate``, ``train``,
``catalogue``).

    python -m sliders.forecast catalogue --data prior.h5 --row 7 --lead 3deg --out row7.csv
"""

from __future__ import annotations

import math
import os

from ...forecasting.catalogue import catalogue_csv_text
from ...io.catalogue import CatalogueSet
from ...io.forecast_files import ForecastInputError, parse_angle
from ...io.prior_file import read_prior_ensemble
from ...io.safeio import describe_os_error, publish_bytes
from ...io.storage import StorageError


def load_set(path: str, what: str = "--data") -> CatalogueSet:
    """A prior ensemble file (``sliders.io.prior_file``) as a ``CatalogueSet``; one line naming
    ``what`` if it is not one (another kind, damaged, truncated, of a newer format)."""
    try:
        return read_prior_ensemble(path)
    except (StorageError, ValueError) as exc:
        raise ForecastInputError(f"{what}: {' '.join(str(exc).split())}") from None
    except OSError as exc:
        raise ForecastInputError(f"{what}: {describe_os_error(exc, path)}") from None


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
