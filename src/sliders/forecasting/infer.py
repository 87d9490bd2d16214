"""The posterior of the pile's material from its catalogue (``python -m sliders.forecast infer``
and ``sliders.forecast.load().infer``).

The catalogue and its measurement are read as ``predict`` reads them
(``catalogue.read_source``, ``catalogue.prepared``, ``catalogue.measurement_from``).
The posterior file (default: the one shipped in the package,
``sliders/data/default_posterior.zip``, checked by its digest) is a model
file of one entry, ``"posterior"``, a fitted
``analysis.forecast.posterior.ParameterPosterior``, read as data through the
model file's checks (``io.forecast_model``).  For each parameter it gives the
median and the 80 and 95 % intervals, how much the catalogue narrowed the
prior (the contraction), whether the catalogue is like the training ones,
and the predictive check, two tests in one verdict (``posterior_check.combined_verdict``): the
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
and whose ``str()`` is the text output; the model of ``sliders.forecast.load()``
(``predict.ForecastModel``) calls it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np

from ..io.catalogue import Catalogue
from ..io.forecast_files import ForecastInputError
from ..io.forecast_model import default_posterior_path
from ..parts.materials import MATERIALS
from ..scene import check_memory
from ..analysis.forecast.features import Cuts
from ..analysis.forecast.measurement import Measurement
from ..analysis.forecast.posterior_check import (combined_verdict, p_value_text,
                                                 predictive_check, smallest_p_value)
from .catalogue import (angles_and_sizes, measurement_as_json, measurement_from, prepared,
                        read_source)
from .common import CHECK_DRAWS, jsonable
from .files import read_model_file
from .report import Report

#: the most piles the predictive check may simulate
MAX_CHECK_DRAWS = 1000
#: the parameters' names in the text output
LABELS = {m.name: m.label for m in MATERIALS}


@dataclasses.dataclass(frozen=True)
class PileSimulation:
    """How the predictive check makes its piles: ``base_scene(spec)``, the base scene of the
    prior a posterior stores (the ``prior`` command's specification), and ``run_pile(scene)``,
    a pile's run (a ``Result``).  The commands hold both
    (``sliders.runs.forecast.infer.CHECK_SIMULATION``)."""

    base_scene: Callable[[dict], object]
    run_pile: Callable[[object], object]


def load_posterior(path=None, simulation: PileSimulation | None = None) -> "PosteriorModel":
    """The posterior of the file ``path`` (default: the shipped one), read once, as data;
    ``simulation``: how its predictive check makes piles (None: ``infer`` without the check)."""
    models, prov, path = read_model_file(
        path, default_posterior_path(), "the default posterior is missing from this "
        "installation; reinstall sliders, or fit one with python -m sliders.forecast train "
        "--fit posterior and pass --posterior FILE")
    posterior = models.get("posterior")
    if type(posterior).__name__ != "ParameterPosterior":
        raise ForecastInputError(f"{path}: not a posterior file (written by train --fit "
                                 "posterior): it holds " + ", ".join(map(str, models)))
    model = PosteriorModel(path, posterior, prov, simulation)
    if simulation is not None:
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
    simulation : PileSimulation, optional
        How the predictive check makes its piles (None: ``infer`` only with ``check=False``).
    """

    def __init__(self, path, posterior, provenance: dict, simulation=None):
        self.path = path
        self.posterior = posterior
        self.provenance = provenance
        self.simulation = simulation

    def __repr__(self) -> str:
        """One line: the file and the parameters."""
        return f"<PosteriorModel {self.path} ({', '.join(self.posterior.parameters_)})>"

    def infer(self, catalogue, tilt_now=None, *, angle_resolution=0.0, min_size=1.0,
              missed_fraction=0.0, size_unit="sliders", sliders=None, displacement_unit="model",
              position_unit="sliders", pile_length=None, check=True,
              check_draws=CHECK_DRAWS, seed=0) -> "Inference":
        """The posterior of the material of the pile that made ``catalogue``.

        Parameters
        ----------
        catalogue : str, os.PathLike, mapping, DataFrame, bytes or Catalogue
            As ``ForecastModel.predict`` reads it (``catalogue.read_source``).
        tilt_now : str or float, optional
            The tilt reached (as ``predict``'s); default: the last event's angle.
        angle_resolution, min_size, missed_fraction, size_unit, sliders
        displacement_unit, position_unit, pile_length
            How the catalogue was measured, as ``predict``'s flags of those names.  A
            camera's catalogue (displacements or positions not in the model's units) is
            read by its angles and sizes: the posterior reads displacements in g tau^2 only.
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
                                       sliders, displacement_unit, position_unit, pile_length)
        cat, notes = prepared(read_source(catalogue, angle_resolution=measurement.angle_resolution,
                                          position_unit=measurement.position_unit),
                              tilt_now, measurement)
        return self.infer_catalogue(cat, measurement, check, check_draws, seed, notes)

    def infer_catalogue(self, cat: Catalogue, measurement: Measurement, check: bool = True,
                        check_draws: int = CHECK_DRAWS, seed: int = 0, notes=()) -> "Inference":
        """``infer`` of a ``Catalogue`` at its tilt reached, measured as ``measurement``."""
        post = self.posterior
        if measurement.camera:
            notes = [*notes, "a camera's displacements and positions are not read: the "
                             "posterior reads them in the model's units only (g τ², slider "
                             "indices), so it reads this catalogue's angles and sizes"]
            cat = cat.angles_and_sizes()
            measurement = measurement.in_model_units()
        cat, complete = angles_and_sizes(cat)
        cuts = Cuts.from_catalogues([cat], measurement)
        try:
            given = post.given(cuts)
            inside, reasons = post.domain(cuts)
        except AttributeError:  # a posterior of another version lacks what this one reads
            raise ForecastInputError(f"{self.path}: written by sliders "
                                     f"{self.provenance.get('sliders', '?')}, whose posterior "
                                     "this version cannot use; fit it again") from None
        rng = np.random.default_rng([seed, 11])
        verdict = None
        if check:
            verdict = self.predictive_check(given.sample(check_draws, rng), cat, measurement,
                                            rng, complete)
            verdict = combined_verdict(verdict, bool(inside[0]), reasons[0])
        report = {"parameters": given.summary(), "contraction": given.contraction(),
                  "in_domain": bool(inside[0]), "domain_reason": reasons[0],
                  "events": len(cat), "tilt_now": float(cat.tilt_now),
                  "complete": complete, "notes": list(notes),
                  "prior_range": post.prior_range(),
                  "measurement": measurement_as_json(measurement),
                  "check": verdict,
                  "posterior": {"path": str(self.path), **self.provenance}}
        return Inference(jsonable(report), given.sample(4000, rng), post.prior_range())

    def predictive_check(self, material: dict, cat: Catalogue, measurement: Measurement,
                         rng, complete: bool = True) -> dict:
        """The posterior predictive test of ``cat``: piles simulated at the posterior draws
        ``material`` (``posterior_check.predictive_check``) on the prior's base scene."""
        return predictive_check(material, self.prior_scene(), self.simulation.run_pile, cat,
                                measurement, rng, complete)

    def prior_scene(self, checked: bool = False):
        """The base scene of the prior the posterior was fitted on; ``checked``: the stored
        prior refused in one line naming the file unless it reads as a prior and a pile of its
        most sliders fits in the memory available (``scene.check_memory``, as an ensemble's)."""
        if self.simulation is None:
            raise ForecastInputError(f"{self.path}: the predictive check makes piles of the "
                                     "posterior's prior: load the model with "
                                     "sliders.forecast.load(), or pass check=False")
        if not checked:
            return self.simulation.base_scene(self.posterior.prior_spec())
        post = self.posterior
        try:
            scene = self.prior_scene()
            if "n_sliders" in post.parameters_:
                check_memory(scene.replace(n_sliders=int(post.n_sliders_values_[-1])))
        except (ValueError, TypeError, AttributeError, KeyError) as exc:
            raise ForecastInputError(f"{self.path}: the stored prior: "
                                     f"{' '.join(str(exc).split())}; refused") from None
        return scene


class Inference(Report):
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
        super().__init__(report)
        self.draws = draws
        self.prior_range = prior_range

    def __repr__(self) -> str:
        """One line: mu_d's median and the events."""
        mu = self._report["parameters"].get("mu_d", {}).get("median")
        return f"<Inference mu_d {mu:.3f} from {self._report['events']} events>" if mu else \
            f"<Inference from {self._report['events']} events>"

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

    def figure(self):
        """The corner plot (``figures.posterior.corner_figure``): a matplotlib Figure, the
        predictive check's verdict on it."""
        from ..figures.posterior import corner_figure

        return corner_figure(self.draws, self.prior_range, self._report["parameters"],
                             check=self._report["check"] or "skipped")


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
