"""``python -m sliders.forecast predict``: forecast the avalanche angle of a measured catalogue.

The catalogue (docs/forecasting.md, "Your own catalogue") is read by
``catalogue.read_measured``; without ``--model`` the forecaster shipped in the
package is used.  Every method asked gives its forecast, the domain check says
whether the pile is like the training ones, and a fallback says why.
"""

from __future__ import annotations

import json
import math

from ...analysis.forecast import Cuts, Forecaster
from ...analysis.forecast.registry import fallback_of
from ...io.forecast_files import ForecastInputError, parse_angle, tilt_in_range
from ...io.forecast_model import ModelFileError, default_model_path, load_forecasters
from .catalogue import measurement_as_json, measurement_of, read_measured
from .common import PREDICT_METHODS, jsonable

#: why a method of the displacements gave no forecast of its own on a catalogue without them
NO_DISPLACEMENT = ("the catalogue has no displacement column: the conditioned climatology is "
                   "given instead")


def predict(args, argv=None) -> int:
    """Forecast a measured catalogue: every method asked, the domain, the model's provenance."""
    check_predict_options(args)
    measurement = measurement_of(args)
    cat, complete = read_measured(args.catalogue, args.tilt_now)
    path, models, prov = load_predict_model(args)
    learned = models["learned"] if complete and "learned" in models else models["learned_blind"]
    try:
        inside, reasons = learned.domain(Cuts.from_catalogues([cat], measurement))
        chosen = {m: learned if m == "learned" else models[m] for m in
                  (PREDICT_METHODS[:-1] if args.method == "all" else (args.method,))
                  if m == "learned" or m in models}
        forecasts = [(m, f, f.predict(cat, measurement)) for m, f in chosen.items()]
    except AttributeError:  # a forecaster of another version lacks what this one reads
        raise ForecastInputError(f"{path}: written by sliders {prov.get('sliders', '?')}, whose "
                                 "forecasters this version cannot use; train it again") from None
    in_domain, reason = bool(inside[0]), reasons[0]
    top = float(learned.climatology_.alpha_c_[-1])
    if in_domain and any(fc.point > top for _, _, fc in forecasts):
        in_domain = False
        reason = (f"a forecast lies above every training avalanche angle ({math.degrees(top):.2f}°)")
    within = math.radians(args.within)
    report = {"in_domain": in_domain, "domain_reason": reason, "events": len(cat),
              "measurement": measurement_as_json(measurement), "model": {"path": str(path), **prov},
              "methods": {m: fc.as_dict(within) | {"label": f.label,
                                                   "fallback_reason": fallback_reason(m, fc, complete)}
                          for m, f, fc in forecasts}}
    first = forecasts[0][2].as_dict(within)
    if args.json:
        print(json.dumps(jsonable(first | report)))
    else:
        print_forecasts(args, report, forecasts, path, prov, complete)
    return 0


def fallback_reason(method: str, forecast, complete: bool = True) -> str | None:
    """Why ``forecast`` is a fallback (None if it is the method's own); ``complete``: the
    catalogue has displacements and movers."""
    if not forecast.fallback:
        return None
    if not complete and method.endswith("_disp"):
        return NO_DISPLACEMENT
    return fallback_of(method)


def load_predict_model(args):
    """The model file of ``--model`` (default: the one shipped in the package), read as data."""
    path = default_model_path() if args.model is None else args.model
    if args.model is None and not path.is_file():
        raise ForecastInputError(f"{path}: the default forecaster is missing from this "
                                 "installation; reinstall sliders, or train one with python -m "
                                 "sliders.forecast train and pass --model FILE")
    try:
        models, prov = load_forecasters(path)
    except ModelFileError as exc:
        raise ForecastInputError(str(exc)) from None
    wrong = next((k for k, f in models.items() if not isinstance(f, Forecaster)), None)
    if wrong is not None:
        raise ForecastInputError(f"{path}: {wrong!r} holds a {type(models[wrong]).__name__}, not "
                                 "the fitted forecasters a model file holds")
    if "learned_blind" not in models:
        raise ForecastInputError(f"{path}: no forecaster of angles and sizes (learned_blind) in it")
    return path, models, prov


def print_forecasts(args, report: dict, forecasts, path, prov, complete: bool) -> None:
    """The text output: one block per method, the domain line, the provenance if ``--verbose``."""
    deg = math.degrees
    first = forecasts[0][2]
    print(f"events: {report['events']}, tilt reached: {first.tilt_now:.4f} rad "
          f"({deg(first.tilt_now):.2f}°)")
    if not report["in_domain"]:
        print(f"OUT OF THE TRAINING DOMAIN: {report['domain_reason']}; the learned interval is "
              "widened to hold the conditioned climatology's and the training's remaining "
              "angles too, and no forecast here is "
              "calibrated: retrain on a prior that holds this pile (python -m sliders.forecast train)")
    for method, f, fc in forecasts:
        lo, hi = fc.interval
        print(f"{method} ({f.label}): avalanche angle {fc.point:.4f} rad ({deg(fc.point):.2f}°), "
              f"80 % interval {lo:.4f}-{hi:.4f} rad ({deg(lo):.2f}-{deg(hi):.2f}°), "
              f"P(within the next {args.within:g}°) = {fc.probability_within(math.radians(args.within)):.2f}")
        why = fallback_reason(method, fc, complete)
        if why:
            print(f"  fallback: {why}")
    print(f"model: {path} ({prov.get('rows', '?')} training rows, "
          f"{prov.get('created', '?')})")
    if args.verbose:
        for k, v in prov.items():
            print(f"  {k}: {f'{len(v)} rows' if k == 'held_out_rows' else v}")


def check_predict_options(args) -> None:
    """The options of ``predict`` in range (one line naming the option), before the file is read."""
    if args.tilt_now is not None:
        if not isinstance(args.tilt_now, str) or not args.tilt_now.strip():
            # argparse turns "--tilt-now=--" into an empty list
            raise ForecastInputError("--tilt-now: give the tilt reached, e.g. 27.5deg or 0.48rad")
        tilt_in_range(parse_angle(args.tilt_now, math.pi / 180.0), f"--tilt-now {args.tilt_now}")
    if not 0.0 < args.within < 90.0:
        raise ForecastInputError(f"--within {args.within:g}: the alarm's horizon must lie in "
                                 "(0, 90) degrees")


