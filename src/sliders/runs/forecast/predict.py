"""``python -m sliders.forecast predict``: forecast the avalanche angle of a measured catalogue.

The options are checked here, the catalogue read and forecast by the forecasting layer
(``sliders.forecasting.predict``: ``load_model``, ``ForecastModel.forecast``), and the
``Prediction``'s text or JSON printed; ``--follow`` runs ``follow.follow_command``.
"""

from __future__ import annotations

import json
import math

from ...forecasting.alarm import check_hook, check_release, single_alarm, threshold_option
from ...forecasting.catalogue import measurement_from, prepared, read_source
from ...forecasting.predict import load_model, within_option
from ...io.forecast_files import (ForecastInputError, angle_option, check_output_target,
                                  parse_angle, tilt_in_range)
from ...io.forecast_model import default_model_path
from ...io.safeio import check_output_name, resolve_target
from .cli import measurement_options


def predict(args, argv=None) -> int:
    """Forecast a measured catalogue: every method asked, the domain, the model's provenance
    (``--follow`` runs ``follow.follow_command`` instead)."""
    check_predict_options(args)
    # the catalogue read and checked before the model's seconds of loading
    measurement = measurement_from(**measurement_options(args))
    cat, notes = prepared(read_source(args.catalogue, angle_resolution=measurement.angle_resolution,
                                      position_unit=measurement.position_unit),
                          args.tilt_now, measurement)
    model = load_model(args.model, lazy=True)
    pred = model.forecast(cat, measurement, within_option(args.within), args.method, notes)
    pred.size_label = getattr(args, "size_label", None)
    report, lines = pred.to_dict(), pred.lines(verbose=args.verbose)
    if getattr(args, "alarm_threshold", None) is not None:
        report, line = single_alarm(report, args.alarm_threshold)
        lines.append(line)
    print(json.dumps(report) if args.json else "\n".join(lines))
    if getattr(args, "plot", None):
        pred.plot(args.plot)
    return 0


def check_predict_options(args) -> None:
    """The options of ``predict`` in range (one line naming the option), before the file is read."""
    if args.tilt_now is not None:
        if not isinstance(args.tilt_now, str) or not args.tilt_now.strip():
            # argparse turns "--tilt-now=--" into an empty list
            raise ForecastInputError("--tilt-now: give the tilt reached, e.g. 27.5deg or 0.48rad")
        tilt_in_range(parse_angle(args.tilt_now, math.pi / 180.0), f"--tilt-now {args.tilt_now}")
    within_option(args.within)
    angle_option(args.angle_resolution, "--angle-resolution")
    check_plot_target(getattr(args, "plot", None), {
        "the catalogue": args.catalogue,
        "the model file": args.model if args.model is not None else default_model_path()})
    for option in ("until",):
        if getattr(args, option, None) is not None:
            tilt_in_range(parse_angle(getattr(args, option), math.pi / 180.0),
                          f"--{option} {getattr(args, option)}")
    check_alarm_options(args)


def check_plot_target(plot, inputs: dict) -> None:
    """``--plot``'s file, before anything is read or computed: a name a file can have, a
    regular file or none yet, in a folder that exists, and none of ``inputs`` (``{what: path}``;
    ``-``, standard input, is no file), whatever link leads to it (one line naming the option)."""
    if plot is None:
        return
    try:
        check_output_name(plot)
    except ValueError as exc:
        raise ForecastInputError(f"--plot: {exc}") from None
    check_output_target(plot, {what: resolve_target(path) for what, path in inputs.items()
                               if path is not None and str(path) != "-"}, "--plot")


def check_alarm_options(args) -> None:
    """``--alarm-threshold``, ``--alarm-release`` and ``--on-alarm`` in range, the hook's
    program found (one line naming the option), before the catalogue and the model are read;
    the release level and the hook need ``--follow`` (a single forecast has no hysteresis)."""
    threshold = getattr(args, "alarm_threshold", None)
    release = getattr(args, "alarm_release", None)
    hook = getattr(args, "on_alarm", None)
    if threshold is not None:
        threshold = threshold_option(threshold)
    if not getattr(args, "follow", False):
        for option, value in (("--alarm-release", release), ("--on-alarm", hook)):
            if value is not None:
                raise ForecastInputError(f"{option} {value}: with --follow only (a single "
                                         "forecast has no alarm to release or act on; "
                                         "--alarm-threshold says whether it sounds)")
    if release is not None:
        check_release(release, threshold if threshold is not None else 1.0)
    if hook is not None:
        check_hook(hook)
