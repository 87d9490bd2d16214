"""The forecast of the avalanche angle of a measured catalogue (``python -m sliders.forecast
predict`` and ``sliders.forecast.load().predict``).

The catalogue (docs/forecasting.md, "Forecast your own pile") is read by
``catalogue.read_source``; without ``--model`` the forecaster shipped in the
package is used.  Every method asked gives its forecast, the domain check says
whether the pile is like the training ones, and a fallback says why.

The command and the Python API (``sliders.forecast``) are one code path:
``load_model`` reads a model file once, ``ForecastModel.predict`` forecasts a
catalogue and returns a ``Prediction``, whose ``to_dict()`` is what
``predict --json`` prints and whose ``lines()`` are the text output.
"""

from __future__ import annotations

import math

import numpy as np

from ..analysis.forecast.arrays import classes
from ..analysis.forecast.base import LEVELS, Forecaster
from ..analysis.forecast.evaluation import typical_accuracy, typical_accuracy_line
from ..analysis.forecast.features import Cuts, in_model_units
from ..analysis.forecast.registry import fallback_of
from ..io.forecast_files import ForecastInputError, angle_option
from ..io.forecast_model import default_model_path
from ..io.safeio import printable
from .alarm import Alarm, LatestPicture, RunScore
from .catalogue import (angles_and_sizes, camera_record, measurement_as_json,
                        measurement_from, prepared, read_source, record_kind)
from .files import read_model_file
from .report import Report, interval_name
from .common import (ALARM_DELTA_DEG, LEARNED_BY_RECORD, PREDICT_METHODS, clipped_probability,
                     jsonable, probability_text)
from .follower import Follower, check_source

#: why a method of the displacements gave no forecast of its own on a catalogue without them
NO_DISPLACEMENT = ("the catalogue has no displacement column: the conditioned climatology is "
                   "given instead")
#: the probability of the avalanche within the horizon at which the alarm sounds, unless the
#: forecaster holds its own (``alarm_threshold_``)
DEFAULT_ALARM_THRESHOLD = 0.5


def load_model(path=None, posterior=None, simulation=None, lazy=False) -> "ForecastModel":
    """The forecasters of the model file ``path`` (default: the one shipped in the package),
    read once, as data (``io.forecast_model``); ``posterior``, a posterior file (default: the
    shipped one), and ``simulation``, how its predictive check makes piles
    (``infer.PileSimulation``), are ``infer``'s, read at its first call.  Every forecaster is
    built, checked and its reference forecasts reproduced now; ``lazy`` (a one-shot forecast,
    as the commands make): the file's form now, each forecaster at its first use (a refusal
    then: ``io.forecast_model.ModelFileError``, one line naming the file)."""
    models, prov, path = read_model_file(
        path, default_model_path(), "the default forecaster is missing from this installation; "
        "reinstall sliders, or train one with python -m sliders.forecast train and pass --model "
        "FILE", lazy=lazy)
    # a class of the package's that is no forecaster, named before it is built (a name of no
    # class of the package's is refused when that forecaster is built)
    known = classes(posterior=False)
    names = {m: str(n.get("object")) if isinstance(n, dict) else "?"
             for m, n in models.tree.items()}
    wrong = next((k for k, name in names.items()
                  if name in known and not issubclass(known[name], Forecaster)), None)
    if wrong is not None:
        raise ForecastInputError(f"{path}: {wrong!r} holds a {printable(names[wrong])}, not "
                                 "the fitted forecasters a model file holds")
    if "learned_blind" not in models:
        raise ForecastInputError(f"{path}: no forecaster of angles and sizes (learned_blind) in it")
    return ForecastModel(path, models, prov, posterior, simulation)


def fallback_reason(method: str, forecast, complete: bool = True) -> str | None:
    """Why ``forecast`` is a fallback (None if it is the method's own); ``complete``: the
    catalogue has displacements and movers."""
    if not forecast.fallback:
        return None
    if not complete and method.endswith("_disp"):
        return NO_DISPLACEMENT
    return fallback_of(method)


class ForecastModel:
    """The model of ``sliders.forecast.load()``: a model file's forecasters, loaded once;
    ``predict`` forecasts a catalogue, ``follow`` a growing one, ``infer`` gives the posterior
    of its pile's material (the posterior file read at the first ``infer``).

    Parameters
    ----------
    path : pathlib.Path or str
        The model file.
    models : dict
        ``{method: fitted Forecaster}``.
    provenance : dict
        The model's provenance (prior, rows, mode, versions, date).
    posterior_path : str or os.PathLike, optional
        The posterior file of ``infer`` (default: the shipped one).
    simulation : sliders.forecasting.infer.PileSimulation, optional
        How ``infer``'s predictive check makes piles (None: ``infer`` with ``check=False``).
    """

    def __init__(self, path, models: dict, provenance: dict, posterior_path=None,
                 simulation=None):
        self.path = path
        self.models = models
        self.provenance = provenance
        self.posterior_path = posterior_path
        self.simulation = simulation
        self._posterior = None

    def infer(self, catalogue, tilt_now=None, **options) -> "Inference":
        """The posterior of the material of the pile that made ``catalogue``
        (``infer.PosteriorModel.infer``, its options)."""
        from .infer import load_posterior  # its piles' simulation, read only by an inference

        if self._posterior is None:
            self._posterior = load_posterior(self.posterior_path, self.simulation)
        return self._posterior.infer(catalogue, tilt_now, **options)

    def __repr__(self) -> str:
        """One line: the file and its forecasters."""
        return f"<ForecastModel {self.path} ({', '.join(self.models)})>"

    def predict(self, catalogue, tilt_now=None, *, within=ALARM_DELTA_DEG, angle_resolution=0.0,
                min_size=1.0, missed_fraction=0.0, size_unit="sliders", sliders=None,
                displacement_unit="model", position_unit="sliders", pile_length=None,
                method="learned", size_label=None) -> "Prediction":
        """The forecast of ``catalogue`` at the tilt ``tilt_now``, measured as the keywords say.

        Parameters
        ----------
        catalogue : str, os.PathLike, mapping, DataFrame, bytes or Catalogue
            A CSV file's path, or its columns by the CSV header's names
            (``"angle [deg]"`` or ``"angle [rad]"``, ``"size"``, optionally
            ``"displacement"``, ``"first"``, ``"last"``); ``catalogue.read_source``.
        tilt_now : str or float, optional
            The tilt reached, ``"27.5deg"``, ``"0.48rad"``, or a bare number in the angle
            column's unit; default: the last event's angle.  Below the last event's angle by
            less than 3 angle resolutions it is taken as the last event's angle (a note says so).
        within : str or float
            The alarm's horizon, ``"1deg"``, ``"0.02rad"`` or a bare number of degrees.
        angle_resolution, min_size, missed_fraction, size_unit, sliders
            How the catalogue was measured, as ``predict``'s flags of those names
            (``angle_resolution``: an angle, a bare number in degrees; with it, rows in time
            order whose angles go back by less than 6 of it are sorted by angle; ``sliders``:
            any whole number, or a range ``"100-300"``).
        displacement_unit, position_unit, pile_length
            A camera's units, as ``--displacement-unit`` (``"model"`` or ``"arbitrary"``),
            ``--position-unit`` (``"sliders"``, ``"fraction"`` of the pile's length, or
            ``"mm"``) and ``--pile-length`` (mm); a catalogue with displacements in an
            arbitrary unit or positions not in sliders is forecast by the camera's forecaster.
        method : str
            ``"learned"``, a method of ``common.PREDICT_METHODS``, or ``"all"``.
        size_label : str, optional
            The sizes' unit as the picture's axis names it (``"mm²"``, ``"grains"``), as
            ``predict --size-label``; default: "sliders", or "CSV's unit" for arbitrary sizes.

        Returns
        -------
        Prediction
            ``to_dict()``: the ``predict --json`` object; ``lines()``: the text output.
        """
        if method not in PREDICT_METHODS:
            raise ForecastInputError(f"--method {method}: one of {', '.join(PREDICT_METHODS)}")
        measurement = measurement_from(angle_resolution, min_size, missed_fraction, size_unit,
                                       sliders, displacement_unit, position_unit, pile_length)
        read = read_source(catalogue, angle_resolution=measurement.angle_resolution,
                           position_unit=measurement.position_unit)
        return self.predict_read(read, tilt_now, measurement, within_option(within), method,
                                 size_label=size_label)

    def predict_read(self, read, tilt_now, measurement, within: float,
                     method: str = "learned", size_label=None) -> "Prediction":
        """``predict`` of a catalogue already read (``catalogue.read_source``'s triple), its
        measurement a ``Measurement``, the alarm's horizon ``within`` in radians."""
        cat, notes = prepared(read, tilt_now, measurement)
        pred = self.forecast(cat, measurement, within, method, notes)
        pred.size_label = size_label
        return pred

    def follow(self, source, *, tilt_now=None, tilt_rate=None, until=None,
               within=ALARM_DELTA_DEG, angle_resolution=0.0, min_size=1.0, missed_fraction=0.0,
               size_unit="sliders", sliders=None, displacement_unit="model",
               position_unit="sliders", pile_length=None, method="learned", alarm_threshold=None,
               alarm_release=None, on_alarm=None, plot=None, say=None, on_signal=None):
        """Follow the catalogue ``source`` while an acquisition appends to it: a
        ``follower.Follower``, whose iteration yields one ``Update`` per new state (the
        ``predict --follow`` command prints them) until ``# avalanche``, ``until``, SIGINT or
        SIGTERM (``stopped`` says which).

        Parameters
        ----------
        source : str or os.PathLike
            The CSV file (``"-"``: standard input); refused at once if it does not exist.
        tilt_now, tilt_rate, until : str or float, optional
            The tilt reached at the start, its rate (``"0.1deg/s"``) and the tilt at which to
            stop, as ``predict --follow``'s options.
        within, angle_resolution, min_size, missed_fraction, size_unit, sliders, method
        displacement_unit, position_unit, pile_length
            As ``predict``.
        alarm_threshold, alarm_release, on_alarm : optional
            The alarm's threshold, its release level and the command it runs, as
            ``--alarm-threshold``, ``--alarm-release`` and ``--on-alarm``.
        plot : str or os.PathLike, optional
            The picture, replaced at each update.
        say : callable, optional
            ``say(line)`` for the notices (a bad row, a file read again); default stderr.
        on_signal : callable, optional
            The stop handler the iteration calls at SIGINT or SIGTERM (``Follower``'s).
        """
        if method not in PREDICT_METHODS:
            raise ForecastInputError(f"--method {method}: one of {', '.join(PREDICT_METHODS)}")
        measurement = measurement_from(angle_resolution, min_size, missed_fraction, size_unit,
                                       sliders, displacement_unit, position_unit, pile_length)
        where = check_source(source)
        return Follower(self.predict_read, where, tilt_now=tilt_now, tilt_rate=tilt_rate, until=until,
                        within=within_option(within), measurement=measurement, method=method,
                        alarm=Alarm(alarm_threshold, alarm_release, hook=on_alarm,
                                    catalogue=where),
                        score=RunScore(), picture=None if plot is None else LatestPicture(plot),
                        say=say, on_signal=on_signal)

    def forecast(self, catalogue, measurement, within: float, method: str = "learned",
                 notes=()) -> "Prediction":
        """The ``Prediction`` of a ``Catalogue`` (its ``tilt_now`` is the tilt reached) measured
        as ``measurement``, the alarm's horizon ``within`` in radians."""
        kind = record_kind(catalogue, measurement)
        models, prov, path = self.models, self.provenance, self.path
        given = measurement  # as the user gave it, reported so
        if kind == "camera" and "learned" in models:
            # an exact record's lone slips fix the camera's unit: forecast in the model's units
            converted, unit, pairs = in_model_units(catalogue, measurement)
            if converted is not None:
                catalogue, kind = converted, "complete"
                measurement = measurement.in_model_units()
                notes = [*notes, f"the camera's unit read from {pairs} lone slips that agree "
                                 f"(1 unit = {unit:.4g} g τ²), its positions as slider indices: "
                                 "forecast in the model's units"]
        if LEARNED_BY_RECORD[kind] not in models:
            kind = "blind"  # a model file without it: angles and sizes, the size not read
        cat, complete = angles_and_sizes(catalogue)
        # the camera's forecaster reads its displacements and positions; every other method
        # reads them in the model's units only, so it is given the angles and sizes
        seen = camera_record(catalogue) if kind == "camera" else cat
        learned = models[LEARNED_BY_RECORD[kind]]
        try:
            inside, reasons = learned.domain(Cuts.from_catalogues([seen], measurement))
            chosen = {m: learned if m == "learned" else models[m] for m in
                      (PREDICT_METHODS[:-1] if method == "all" else (method,))
                      if m == "learned" or m in models}
            forecasts = [(m, f, f.predict(seen if m == "learned" else cat, measurement))
                         for m, f in chosen.items()]
        except AttributeError:  # a forecaster of another version lacks what this one reads
            raise ForecastInputError(f"{path}: written by sliders {prov.get('sliders', '?')}, "
                                     "whose forecasters this version cannot use; train it "
                                     "again") from None
        in_domain, reason = bool(inside[0]), reasons[0]
        top = float(learned.climatology_.alpha_c_[-1])
        if in_domain and any(fc.point > top for _, _, fc in forecasts):
            in_domain = False
            reason = ("a forecast lies above every training avalanche angle "
                      f"({math.degrees(top):.2f}°)")
        methods = {}
        for m, f, fc in forecasts:
            why = fallback_reason(m, fc, complete)
            if m == "learned" and fc.fallback:  # nothing fell back: the interval was widened
                why = widened_reason(learned, fc)
            bounds = probability_bounds(fc)
            raw = fc.probability_within(within)
            methods[m] = fc.as_dict(within) | {
                "label": f.label, "fallback_reason": why,
                "calibrated": bool(in_domain and why is None),
                # bounded as the text bounds it ("< 0.05" is 0.05 here), the distribution's own
                # value, extrapolated beyond the levels it resolves, beside it
                "probability_within": clipped_probability(raw, bounds),
                "probability_within_raw": raw,
                "probability_bounds": list(bounds),
                "typical_accuracy": typical_accuracy(f, fc) if in_domain else None,
                "typical_accuracy_line": typical_accuracy_line(f, fc) if in_domain else None}
        warnings = disjoint_intervals(methods)
        report = {"in_domain": in_domain, "domain_reason": reason, "events": len(cat),
                  "notes": list(notes), "warnings": warnings,
                  "alarm_threshold": alarm_threshold(forecasts[0][1]),
                  "alarm_skill": getattr(forecasts[0][1], "alarm_skill_", None),
                  "measurement": measurement_as_json(given),
                  "model": {"path": str(path), **prov}, "methods": methods}
        first = forecasts[0][0]
        top_level = {k: methods[first][k] for k in (*forecasts[0][2].as_dict(within),
                                                    "probability_within_raw")}
        # a single forecast's alarm (no hysteresis): P(within) at or above the threshold
        report["alarm"] = bool(top_level["probability_within_raw"] >= report["alarm_threshold"])
        return Prediction(jsonable(top_level | report), forecasts, cat, complete, given)


def camera_units(m) -> str:
    """", displacements in ..., positions in ..." of a camera's measurement ("" otherwise)."""
    if not m.camera:
        return ""
    disp = "a camera's unit" if m.displacement_unit == "arbitrary" else "g τ²"
    if m.position_unit == "sliders":
        return f", displacements in {disp}"
    where = (f"mm along a {m.pile_length:g} mm pile" if m.position_unit == "mm" else
             "fractions of the pile's length")
    return f", displacements in {disp}, positions (if given) in {where}"


def within_option(within) -> float:
    """The alarm's horizon (radians) of ``--within``, in (0, 90°)."""
    delta = angle_option(within, "--within")
    if not 0.0 < delta < math.pi / 2:
        raise ForecastInputError(f"--within {within}: the alarm's horizon must lie in (0, 90) "
                                 "degrees")
    return delta


def widened_reason(learned, forecast) -> str:
    """What the learned forecaster gave out of its domain, in words that match it: the interval
    widened to hold the conditioned climatology's and the training piles' remaining angles, and
    the median the greatest of the three medians (``learned.Learned._quantiles``), named."""
    t = forecast.tilt_now

    def median(quantiles) -> float:  # read as a forecast at the tilt reached reads it
        return type(forecast)(quantiles, t, "").point

    medians = {"the conditioned climatology's":
               median(learned.climatology_.conditioned(np.array([t]))[0]),
               "the tilt reached plus the training piles' median remaining angle":
               median(t + learned.remaining_quantiles_)}
    point = forecast.point
    whose = next((name for name, m in medians.items() if abs(m - point) < 1e-9),
                 "the learned forecaster's own")
    return ("out of the training domain: the interval is widened to hold the conditioned "
            "climatology's and the training piles' remaining angles too, and the median given "
            f"is {whose} ({math.degrees(point):.2f}°), the greatest of the three medians")


def probability_bounds(forecast) -> tuple[float, float]:
    """The least and the greatest probability the forecast's distribution resolves: its lowest
    and highest quantile levels (below and above them the tails are extrapolated, not
    calibrated)."""
    lv = LEVELS if forecast.levels is None else np.asarray(forecast.levels)
    return float(lv[0]), float(lv[-1])


def alarm_threshold(forecaster) -> float:
    """The probability at which ``forecaster``'s alarm sounds (its own, or the default)."""
    return float(getattr(forecaster, "alarm_threshold_", DEFAULT_ALARM_THRESHOLD))



def disjoint_intervals(methods: dict) -> list[str]:
    """A warning if the intervals of the methods that answered on their own do not overlap."""
    own = {m: d["interval"] for m, d in methods.items() if not d["fallback"]}
    if len(own) < 2:
        return []
    hi_low = max(own, key=lambda m: own[m][0])
    lo_high = min(own, key=lambda m: own[m][1])
    if own[hi_low][0] <= own[lo_high][1]:
        return []
    a, b = own[lo_high], own[hi_low]
    return [f"the methods disagree: {lo_high}'s interval ({math.degrees(a[0]):.2f}-"
            f"{math.degrees(a[1]):.2f}°) and {hi_low}'s ({math.degrees(b[0]):.2f}-"
            f"{math.degrees(b[1]):.2f}°) do not overlap; trust neither alone"]


class Prediction(Report):
    """A forecast of a catalogue by every method asked: ``to_dict()`` (the ``predict --json``
    object), ``lines()`` (the text output), ``plot(path)`` (the bench picture).

    Attributes
    ----------
    forecasts : list
        ``(method, forecaster, Forecast)`` of every method asked, the first at the top.
    catalogue : sliders.io.catalogue.Catalogue
        The catalogue forecast, at its tilt reached.
    complete : bool
        It had displacements and movers.
    measurement : sliders.analysis.forecast.measurement.Measurement
        How it was measured.
    """

    def __init__(self, report: dict, forecasts, catalogue, complete: bool, measurement):
        super().__init__(report)
        self.forecasts = forecasts
        self.catalogue = catalogue
        self.complete = complete
        self.measurement = measurement

    def __repr__(self) -> str:
        """One line: the first method's forecast."""
        d = self._report
        return (f"<Prediction {d['forecaster']}: {math.degrees(d['alpha_c']):.2f}° from "
                f"{math.degrees(d['tilt_now']):.2f}°, {d['events']} events>")

    @property
    def alarm(self) -> bool:
        """P(within) of the first method at or above its alarm threshold."""
        d = self._report
        return d.get("probability_within_raw", d["probability_within"]) >= d["alarm_threshold"]

    def measurement_line(self) -> str:
        """The measurement assumed, in one line."""
        m = self.measurement
        unit = "sliders" if m.size_unit == "sliders" else "the size column's unit"
        return (f"measurement assumed: angle resolution {math.degrees(m.angle_resolution):g}°, "
                f"min size {m.min_size:g} ({unit}), missed fraction {m.missed_fraction:g}, "
                f"size unit {m.size_unit}"
                + (f", {m.n_sliders}" + (f"-{m.n_sliders_high}" if m.n_sliders_high else "")
                   + " sliders" if m.n_sliders is not None else "") + camera_units(m))

    def method_line(self, method: str, forecaster, forecast) -> str:
        """One method's forecast: the point, the interval (called what it is), P(within)."""
        d = self._report["methods"][method]
        deg = math.degrees
        lo, hi = forecast.interval
        name = interval_name(d, method)
        within = deg(d["within"])
        p = probability_text(d["probability_within"], d["probability_bounds"])
        return (f"{method} ({forecaster.label}): avalanche angle {forecast.point:.4f} rad "
                f"({deg(forecast.point):.2f}°), {name} {lo:.4f}-{hi:.4f} rad "
                f"({deg(lo):.2f}-{deg(hi):.2f}°), P(within the next {within:g}°) {p}")

    def lines(self, verbose: bool = False) -> list[str]:
        """The text output: the tilt, the measurement assumed, the domain, one block per
        method, the warnings, the model (its whole provenance if ``verbose``)."""
        d = self._report
        first = self.forecasts[0][2]
        out = [f"events: {d['events']}, tilt reached: {first.tilt_now:.4f} rad "
               f"({math.degrees(first.tilt_now):.2f}°)", *d["notes"], self.measurement_line()]
        if not d["in_domain"]:
            out.append(f"OUT OF THE TRAINING DOMAIN: {d['domain_reason']}; the learned interval "
                       "is widened to hold the conditioned climatology's and the training's "
                       "remaining angles too, and no forecast here is calibrated: retrain on a "
                       "prior that holds this pile (python -m sliders.forecast train)")
        for method, f, fc in self.forecasts:
            out.append(self.method_line(method, f, fc))
            why = d["methods"][method]["fallback_reason"]
            if why:  # the learned forecaster out of its domain widens; it falls back on nothing
                out.append(f"  {why}" if method == "learned" else f"  fallback: {why}")
            elif acc := d["methods"][method]["typical_accuracy_line"]:
                out.append(f"  expected accuracy: {acc}")
        out += [f"WARNING: {w}" for w in d["warnings"]]
        prov = d["model"]
        out.append(f"model: {prov['path']} ({prov.get('rows', '?')} training rows, "
                   f"{prov.get('created', '?')})")
        if verbose:
            for k, v in prov.items():
                if k != "path":
                    out.append(f"  {k}: {f'{len(v)} rows' if k == 'held_out_rows' else v}")
        return out

    #: the sizes' unit as the picture's axis names it (``predict``'s ``size_label``)
    size_label = None

    def figure(self, status: dict | None = None):
        """The bench picture (``figures.bench.bench_figure``): a matplotlib Figure;
        ``status`` (the alarm and its threshold, the time, the rows, the file) a live
        picture's status line."""
        from ..figures.bench import bench_figure

        d = self._report
        method, f, fc = self.forecasts[0]
        m = d["methods"][method]
        return bench_figure(self.catalogue, fc, label=f"{method} ({f.label})",
                            calibrated=m["calibrated"], in_domain=d["in_domain"],
                            domain_reason=d["domain_reason"],
                            probability=probability_text(m["probability_within"],
                                                         m["probability_bounds"]),
                            within=d["within"], size_unit=self.measurement.size_unit,
                            size_label=self.size_label, status=status,
                            interval_name=interval_name(m, method))
