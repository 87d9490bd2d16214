"""``python -m sliders.forecast infer``: the posterior of the pile's material from its catalogue.

    python -m sliders.forecast infer CATALOGUE.csv [--tilt-now ANGLE] [--json] [--plot FILE.png]

The catalogue and its measurement flags are read as ``predict`` reads them
(``catalogue.read_source``, ``predict.prepared``, ``catalogue.measurement_of``).
The posterior file (default: the one shipped in the package,
``sliders/data/default_posterior.zip``, checked by its digest) is a model
file of one entry, ``"posterior"``, a fitted
``analysis.forecast.posterior.ParameterPosterior``, read as data through the
model file's checks (``io.forecast_model``).  For each parameter it gives the
median and the 80 and 95 % intervals, how much the catalogue narrowed the
prior (the contraction), whether the catalogue is like the training ones,
and the predictive check, two tests in one verdict (``combined_verdict``): the
prior predictive test, whether the model over its prior makes catalogues like
this one (the posterior's domain check, ``in_domain``, its thresholds set on
the fit's calibration split), and the posterior predictive test,
``CHECK_DRAWS`` piles simulated at posterior draws up to the tilt reached,
measured as the catalogue was, compared with it
(``analysis.forecast.posterior_check``).  The catalogue is reproduced when
both pass; ``reasons`` names each that failed.  ``--no-check`` skips the
simulations and the verdict (``in_domain`` stays).

One code path for the command and the Python API: ``PosteriorModel.infer``
returns an ``Inference`` whose ``to_dict()`` is what ``infer --json`` prints
and whose ``str()`` is the text output; ``sliders.forecast.load()`` gives an
``InferenceModel``, the forecast model with ``infer`` too.
"""

from __future__ import annotations

import copy
import io
import json
import math

import numpy as np

from ...io.catalogue import Catalogue
from ...io.forecast_files import ForecastInputError, angle_option, parse_angle, tilt_in_range
from ...io.forecast_model import default_posterior_path
from ...io.safeio import publish_bytes
from ...scene import check_memory
from ...analysis.forecast.features import Cuts
from ...analysis.forecast.measurement import Measurement, degrade
from ...analysis.forecast.posterior_check import (CHECK_ALPHA, SURVIVAL, check_statistics,
                                                  predictive_p_values, reproduced,
                                                  simulate_pile, survival_p_value)
from ..command import DEFAULT_BACKEND
from ..prior_spec import parse_prior
from .catalogue import (angles_and_sizes, measurement_as_json, measurement_from, measurement_of,
                        read_source)
from .common import CHECK_DRAWS, jsonable
from .predict import ForecastModel, check_plot_target, load_model, prepared, read_model_file

#: the most piles the predictive check may simulate
MAX_CHECK_DRAWS = 1000
#: the least p-value the check's text states as a number: each is a normal tail fitted to the
#: ``CHECK_DRAWS`` (24) simulated piles, whose spread is known to about 1/sqrt(2 (24 - 1)), 15 %;
#: at p = 0.001 (z = 3.3) that moves p by a factor of about 3, and below it the number says no
#: more than "beyond the Bonferroni level" (0.01 over 9 statistics, 0.0011)
P_VALUE_FLOOR = 0.001
#: the parameters' names in the text output
LABELS = {"mu_d": "mu_d", "mu_s_minus_mu_d": "mu_s - mu_d", "sigma_mu": "sigma_mu", "xi": "xi",
          "n_sliders": "N (sliders)"}


def infer(args, argv=None) -> int:
    """The posterior of a measured catalogue: the text (or ``--json``), the corner plot."""
    check_infer_options(args)
    # the catalogue read and checked before the posterior's seconds of loading
    measurement = measurement_of(args)
    cat, notes = prepared(read_source(args.catalogue, angle_resolution=measurement.angle_resolution),
                          args.tilt_now, measurement)
    model = load_posterior(args.posterior)
    result = model.infer_catalogue(cat, measurement, not args.no_check, args.check_draws,
                                   args.seed, notes)
    print(json.dumps(result.to_dict()) if args.json else str(result))
    if args.plot:
        result.plot(args.plot)
    return 0


def check_infer_options(args) -> None:
    """The options of ``infer`` in range (one line naming the option), before a file is read."""
    if args.tilt_now is not None:
        if not isinstance(args.tilt_now, str) or not args.tilt_now.strip():
            raise ForecastInputError("--tilt-now: give the tilt reached, e.g. 27.5deg or 0.48rad")
        tilt_in_range(parse_angle(args.tilt_now, math.pi / 180.0), f"--tilt-now {args.tilt_now}")
    angle_option(args.angle_resolution, "--angle-resolution")
    if not 3 <= args.check_draws <= MAX_CHECK_DRAWS:
        raise ForecastInputError(f"--check-draws {args.check_draws}: must lie in "
                                 f"[3, {MAX_CHECK_DRAWS}]")
    if not 0 <= args.seed < 2**32:
        raise ForecastInputError(f"--seed {args.seed}: must lie in [0, 2^32)")
    check_plot_target(args.plot, {
        "the catalogue": args.catalogue,
        "the posterior file": (args.posterior if args.posterior is not None
                               else default_posterior_path())})


def load_posterior(path=None) -> "PosteriorModel":
    """The posterior of the file ``path`` (default: the shipped one), read once, as data."""
    models, prov, path = read_model_file(
        path, default_posterior_path(), "the default posterior is missing from this "
        "installation; reinstall sliders, or fit one with python -m sliders.forecast train "
        "--fit posterior and pass --posterior FILE")
    posterior = models.get("posterior")
    if type(posterior).__name__ != "ParameterPosterior":
        raise ForecastInputError(f"{path}: not a posterior file (written by train --fit "
                                 "posterior): it holds " + ", ".join(map(str, models)))
    model = PosteriorModel(path, posterior, prov)
    model.prior_scene(checked=True)
    return model


class PosteriorModel:
    """A posterior file, loaded once: ``infer`` gives the posterior of a catalogue's pile.

    Parameters
    ----------
    path : pathlib.Path or str
        The posterior file.
    posterior : sliders.analysis.forecast.posterior.ParameterPosterior
        The fitted posterior.
    provenance : dict
        The file's provenance (prior, rows, versions, date).
    """

    def __init__(self, path, posterior, provenance: dict):
        self.path = path
        self.posterior = posterior
        self.provenance = provenance

    def __repr__(self) -> str:
        """One line: the file and the parameters."""
        return f"<PosteriorModel {self.path} ({', '.join(self.posterior.parameters_)})>"

    def infer(self, catalogue, tilt_now=None, *, angle_resolution=0.0, min_size=1.0,
              missed_fraction=0.0, size_unit="sliders", sliders=None, check=True,
              check_draws=CHECK_DRAWS, seed=0) -> "Inference":
        """The posterior of the material of the pile that made ``catalogue``.

        Parameters
        ----------
        catalogue : str, os.PathLike, mapping, DataFrame, bytes or Catalogue
            As ``ForecastModel.predict`` reads it (``catalogue.read_source``).
        tilt_now : str or float, optional
            The tilt reached (as ``predict``'s); default: the last event's angle.
        angle_resolution, min_size, missed_fraction, size_unit, sliders
            How the catalogue was measured, as ``predict``'s flags of those names.
        check : bool
            Run the predictive check (``check_draws`` piles simulated at posterior draws).
        seed : int
            Key of the posterior draws and of the check's piles.

        Returns
        -------
        Inference
            ``to_dict()``: the ``infer --json`` object; ``str()``: the text output.
        """
        measurement = measurement_from(angle_resolution, min_size, missed_fraction, size_unit,
                                       sliders)
        cat, notes = prepared(read_source(catalogue, angle_resolution=measurement.angle_resolution),
                              tilt_now, measurement)
        return self.infer_catalogue(cat, measurement, check, check_draws, seed, notes)

    def infer_catalogue(self, cat: Catalogue, measurement: Measurement, check: bool = True,
                        check_draws: int = CHECK_DRAWS, seed: int = 0, notes=()) -> "Inference":
        """``infer`` of a ``Catalogue`` at its tilt reached, measured as ``measurement``."""
        post = self.posterior
        cat, complete = angles_and_sizes(cat)
        cuts = Cuts.from_catalogues([cat], measurement)
        try:
            q = post.quantiles(cuts)[0]
            inside, reasons = post.domain(cuts)
        except AttributeError:  # a posterior of another version lacks what this one reads
            raise ForecastInputError(f"{self.path}: written by sliders "
                                     f"{self.provenance.get('sliders', '?')}, whose posterior "
                                     "this version cannot use; fit it again") from None
        rng = np.random.default_rng([seed, 11])
        verdict = None
        if check:
            verdict = self.predictive_check(q, cat, measurement, check_draws, rng, complete)
            verdict = combined_verdict(verdict, bool(inside[0]), reasons[0])
        report = {"parameters": post.summary(q), "contraction": post.contraction(q),
                  "in_domain": bool(inside[0]), "domain_reason": reasons[0],
                  "events": len(cat), "tilt_now": float(cat.tilt_now),
                  "complete": complete, "notes": list(notes),
                  "prior_range": post.prior_range(),
                  "measurement": measurement_as_json(measurement),
                  "check": verdict,
                  "posterior": {"path": str(self.path), **self.provenance}}
        return Inference(jsonable(report), post.sample(q, 4000, rng), post.prior_range())

    def predictive_check(self, q_row, cat: Catalogue, measurement: Measurement, draws: int,
                         rng, complete: bool = True) -> dict:
        """``draws`` piles simulated at posterior draws up to the catalogue's tilt reached,
        measured as it was, against it (their displacements too if ``complete``): each
        statistic's p-value, whether it is reproduced."""
        material = self.posterior.sample(q_row, draws, rng)
        simulated, avalanche_angles = simulate_piles(self.prior_scene(), material, cat.tilt_now,
                                               measurement, rng)
        arbitrary = measurement.size_unit == "arbitrary"
        p = predictive_p_values(check_statistics(cat, arbitrary, complete),
                                [check_statistics(c, arbitrary, complete) for c in simulated])
        p[SURVIVAL] = survival_p_value(avalanche_angles, cat.tilt_now)
        return {"reproduced": reproduced(p), "p_values": p, "simulated": draws,
                "avalanched_before": int(np.sum(np.isfinite(avalanche_angles))),
                "significance_level": CHECK_ALPHA}

    def prior_scene(self, checked: bool = False):
        """The base scene of the prior the posterior was fitted on; ``checked``: the stored
        prior refused in one line naming the file unless it reads as a prior and a pile of its
        most sliders fits in the memory available (``scene.check_memory``, as an ensemble's)."""
        if not checked:
            return parse_prior(self.posterior.prior_spec(), "the posterior's prior").base_scene
        post = self.posterior
        try:
            scene = self.prior_scene()
            if "n_sliders" in post.parameters_:
                check_memory(scene.replace(n_sliders=int(post.n_sliders_values_[-1])))
        except (ValueError, TypeError, AttributeError, KeyError) as exc:
            raise ForecastInputError(f"{self.path}: the stored prior: "
                                     f"{' '.join(str(exc).split())}; refused") from None
        return scene


def combined_verdict(check: dict, in_domain: bool, domain_reason: str) -> dict:
    """The check's verdict on both tests: the prior predictive one (the model over its prior
    makes catalogues like this one: ``in_domain``) and the posterior predictive one (piles at
    posterior draws reproduce it: ``check["reproduced"]``).  The catalogue is reproduced when
    both pass; ``reasons`` names each test that failed (``test``) and why (``detail``), and
    ``tests`` each one's result."""
    reasons = []
    if not in_domain:
        reasons.append({"test": "prior_predictive",
                        "detail": "no pile of the prior makes a catalogue like it: "
                                  + domain_reason})
    if not check["reproduced"]:
        name, p = smallest_p_value(check)
        n = sum(v is not None for v in check["p_values"].values())
        reasons.append({"test": "posterior_predictive",
                        "detail": f"{check['simulated']} piles simulated at posterior draws "
                                  f"differ in {name} (p {p_value_text(p)}, below "
                                  f"{check['significance_level']:g} "
                                  f"over the {n} statistics)"})
    return {**check, "reproduced": not reasons, "reasons": reasons,
            "tests": {"prior_predictive": in_domain, "posterior_predictive": check["reproduced"]}}


def smallest_p_value(check: dict) -> tuple:
    """The statistic of the check's smallest p-value and that p-value."""
    return min(((k, v) for k, v in check["p_values"].items() if v is not None),
               key=lambda kv: kv[1], default=("none", 1.0))


def simulate_piles(base_scene, material: dict, tilt: float, measurement: Measurement, rng):
    """The catalogues of piles of ``material`` (one per draw) tilted up to ``tilt``, measured as
    ``measurement`` says (sizes in sliders), and each one's avalanche angle (NaN: it stood)."""
    seeds = rng.integers(1, 2**31 - 1, len(material["mu_d"]))
    measured = Measurement(measurement.angle_resolution, 1.0 if measurement.size_unit ==
                           "arbitrary" else measurement.min_size, measurement.missed_fraction)
    cats, avalanched = [], []
    for j, seed in enumerate(seeds):
        mu_d = float(material["mu_d"][j])
        changes = {"mu_d": mu_d, "alpha_max": max(float(tilt), 1e-6), "seed": int(seed)}
        if "mu_s_minus_mu_d" in material:
            changes["mu_s_mean"] = mu_d + float(material["mu_s_minus_mu_d"][j])
        for name in ("sigma_mu", "xi"):
            if name in material:
                changes[name] = float(material[name][j])
        if "n_sliders" in material:
            changes["n_sliders"] = int(material["n_sliders"][j])
        result = simulate_pile(base_scene.replace(**changes), DEFAULT_BACKEND)
        sim = Catalogue.from_result(result)
        sim = Catalogue(sim.alpha, sim.size, sim.displacement, sim.first, sim.last,
                        tilt_now=max(float(tilt), float(sim.tilt_now)))
        cats.append(degrade(sim, measured, rng))
        avalanched.append(result.alpha_c if result.status == "avalanche" else math.nan)
    return cats, np.array(avalanched, dtype=float)


class Inference:
    """The posterior of one catalogue: ``to_dict()`` (the ``infer --json`` object), ``str()``
    (the text output), ``plot(path)`` (the corner plot).

    Attributes
    ----------
    draws : dict
        Posterior draws of every parameter, in its own units (for the corner plot).
    prior_range : dict
        Each parameter's prior range, in its own units.
    """

    def __init__(self, report: dict, draws: dict, prior_range: dict):
        self._report = report
        self.draws = draws
        self.prior_range = prior_range

    def __getitem__(self, key):
        """A value of ``to_dict()``."""
        return self._report[key]

    def __repr__(self) -> str:
        """One line: mu_d's median and the events."""
        mu = self._report["parameters"].get("mu_d", {}).get("median")
        return f"<Inference mu_d {mu:.3f} from {self._report['events']} events>" if mu else \
            f"<Inference from {self._report['events']} events>"

    def to_dict(self) -> dict:
        """The posterior as JSON values: what ``infer --json`` prints."""
        return copy.deepcopy(self._report)

    def lines(self) -> list[str]:
        """The text output: the catalogue, the domain, one line per parameter, the check."""
        d = self._report
        out = [f"events: {d['events']}, tilt reached: {d['tilt_now']:.4f} rad "
               f"({math.degrees(d['tilt_now']):.2f}°), "
               + ("complete catalogue" if d["complete"] else "angles and sizes only"),
               *d["notes"]]
        if not d["in_domain"]:
            out.append(f"OUT OF THE TRAINING DOMAIN: {d['domain_reason']}; the posterior is "
                       "not calibrated here")
        out.append("parameter: median, 80 % interval, 95 % interval (contraction of the prior)")
        for name, p in d["parameters"].items():
            c = d["contraction"][name]
            out.append(f"  {LABELS.get(name, name)}: {parameter_text(name, p)} "
                       f"({contraction_text(c)})")
        out.append(check_text(d["check"]))
        out.append(f"posterior: {d['posterior']['path']} ({d['posterior'].get('rows', '?')} "
                   f"training rows, {d['posterior'].get('created', '?')})")
        return out

    def __str__(self) -> str:
        """The text output (``lines``)."""
        return "\n".join(self.lines())

    def figure(self):
        """The corner plot (``figures.posterior.corner_figure``): a matplotlib Figure, the
        predictive check's verdict on it."""
        from ...figures.posterior import corner_figure

        return corner_figure(self.draws, self.prior_range, self._report["parameters"],
                             check=self._report["check"] or "skipped")

    def plot(self, path) -> None:
        """Write the corner plot to ``path`` (PNG), whole or not at all."""
        buf = io.BytesIO()
        self.figure().savefig(buf, format="png", dpi=110)
        publish_bytes(str(path), buf.getvalue(), overwrite=True)


def parameter_text(name: str, p: dict) -> str:
    """One parameter's posterior in a line (mu_d also in degrees; xi: P(xi = 0) first; the
    number of sliders: its most probable values)."""
    if p.get("median") is None:
        return f"P(xi = 0) {p['p_zero']:.2f}"

    def fmt(v):
        return f"{v:.0f}" if name == "n_sliders" else f"{v:.4g}"

    lo8, hi8 = p["interval_80"]
    lo9, hi9 = p["interval_95"]
    text = f"{fmt(p['median'])}, {fmt(lo8)}-{fmt(hi8)}, {fmt(lo9)}-{fmt(hi9)}"
    if name == "mu_d":
        a = p["atan_deg"]
        text += (f"; atan(mu_d) {a['median']:.2f}°, {a['interval_80'][0]:.2f}-"
                 f"{a['interval_80'][1]:.2f}°, {a['interval_95'][0]:.2f}-{a['interval_95'][1]:.2f}°")
    if name == "xi" and "p_zero" in p:
        text = f"P(xi = 0) {p['p_zero']:.2f}; given xi > 0: {text}"
    if name == "n_sliders" and "probabilities" in p:
        top = sorted(p["probabilities"].items(), key=lambda kv: -kv[1])[:3]
        text += "; most probable " + ", ".join(f"{k} ({v:.2f})" for k, v in top)
    return text


def contraction_text(c) -> str:
    """A parameter's contraction in words: "fixed by the prior" (None), "none" (the posterior
    no narrower than the prior: below 0 is the draws' noise), else to two decimals."""
    if c is None:
        return "fixed by the prior"
    return "contraction none" if c <= 0 else f"contraction {c:.2f}"


def p_value_text(p: float) -> str:
    """A p-value of the check as the text gives it: ``= 0.023``, or ``< 0.001`` below
    ``P_VALUE_FLOOR``."""
    return f"< {P_VALUE_FLOOR:g}" if p < P_VALUE_FLOOR else f"= {p:.2g}"


def check_text(check) -> str:
    """The predictive check in a line."""
    if check is None:
        return "predictive check: skipped (--no-check)"
    name, p = smallest_p_value(check)
    if check["reproduced"]:
        return (f"predictive check: the prior's piles make catalogues like this one, and "
                f"{check['simulated']} piles simulated at posterior draws reproduce it "
                f"(smallest p-value {p_value_text(p)}, {name})")
    failed = "; ".join(f"{r['test'].replace('_', ' ')} check failed: {r['detail']}"
                       for r in check["reasons"])
    return (f"predictive check: the model does not reproduce this catalogue ({failed}); its "
            "parameters are not to be trusted")


class InferenceModel(ForecastModel):
    """The forecast model of ``sliders.forecast.load()`` with ``infer`` too: the posterior of
    the pile's material (the posterior file is read at the first ``infer``)."""

    posterior_path = None
    _posterior = None

    def infer(self, catalogue, tilt_now=None, **options) -> Inference:
        """``PosteriorModel.infer`` with the shipped posterior (or ``posterior_path``)."""
        if self._posterior is None:
            self._posterior = load_posterior(self.posterior_path)
        return self._posterior.infer(catalogue, tilt_now, **options)


def load_inference_model(path=None, posterior=None) -> InferenceModel:
    """``predict.load_model`` as an ``InferenceModel`` (``posterior``: a posterior file)."""
    model = load_model(path)
    out = InferenceModel(model.path, model.models, model.provenance)
    out.posterior_path = posterior
    return out
