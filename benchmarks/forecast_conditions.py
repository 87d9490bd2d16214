"""The shipped forecasters under the conditions a lab brings: a camera's units, the pile's size,
a noisy tilt near its end, and the accuracy each forecast announces.

    .venv/bin/python benchmarks/forecast_conditions.py --model src/sliders/data/default_forecaster.zip \\
        --out benchmarks/results

On the held-out rows of the model's training prior (named in its provenance, as
``forecast_skill.py`` reads them):

* **a camera's catalogue**, as ``predict`` forecasts it (``CameraForecast``: in the
  model's units when its lone slips fix the camera's unit, else ``learned_camera``),
  recorded three ways (``CAMERA_RECORDS``): the camera's units only (a displacement
  unit drawn over four decades, positions as fractions of the pile's length), with
  a 10 % relative displacement error too, and as the camera forecaster's training
  cuts are (``measurement.degrade_cuts(camera=True)``: also angle errors, missed
  events and detection thresholds drawn from the training ranges), no number of
  sliders told: the median |error| over the conditioned climatology's 3° and 1°
  before the avalanche, and the 80 % coverage over random cuts and at each lead;
* **the pile's size**: for a catalogue of angles and sizes, not told its pile's
  size (``learned_blind``), told it exactly or as a range (``learned_sized``), the
  coverage per size class (N < 50, 50-199, ≥ 200) over random cuts and at each
  lead, and the median signed error 3° before;
* **the edge of a noisy tilt**: catalogues with 0.15° of angle error cut within
  0.25° of their avalanche (the tilt reached at least their last, noisy, angle),
  angles and sizes only: the coverage;
* **the accuracy announced** ("typical error at this stage"): per size class,
  the median |error| over the median of the errors announced, over random cuts.

Writes forecast_conditions.json and forecast_conditions.md to ``--out``.
"""

from __future__ import annotations

import argparse
import math
import os
from dataclasses import replace

import numpy as np

from forecast_skill import LEADS_DEG, blind, skill, write_report
from sliders.analysis.forecast import Measurement
from sliders.analysis.forecast.base import LOWER, MEDIAN, UPPER, Forecast
from sliders.analysis.forecast.evaluation import cuts_at_leads, typical_accuracy
from sliders.analysis.forecast.features import cuts_in_model_units, training_cuts
from sliders.analysis.forecast.measurement import (SLIDERS_TOLD, degrade, degrade_cuts, draw_camera,
                                                   tell_sliders)
from sliders.analysis.forecast.model_file import load_forecasters
from sliders.io.catalogue import CatalogueSet
from sliders.runs.forecast.catalogue import load_set

#: size classes of the pile: label -> mask over numbers of sliders
SIZE_CLASSES = {"N < 50": lambda n: n < 50, "N 50-199": lambda n: (n >= 50) & (n < 200),
                "N ≥ 200": lambda n: n >= 200}
#: the noisy tilt's angle error (degrees) and how close to the avalanche its cuts lie
EDGE_NOISE_DEG, EDGE_LEAD_DEG = 0.15, 0.25


def untold(cuts):
    """The cuts with no number of sliders told."""
    return replace(cuts, measurement=[replace(m, n_sliders=None, n_sliders_high=None)
                                      for m in cuts.measurements()], cache={})


def told(cuts, how: str, seed: int):
    """The cuts told their pile's number of sliders (``TOLD``): exactly, or as a range around it
    whose ends lie up to ``SLIDERS_TOLD["range_factor"]`` away; untold as they are otherwise."""
    cuts = untold(cuts)
    if how == "not told":
        return cuts
    rule = {**SLIDERS_TOLD, "p_told": 1.0, "p_exact": 1.0 if how == "told exactly" else 0.0}
    meas = tell_sliders(cuts.measurements(), cuts.n_sliders, np.random.default_rng(seed), rule)
    return replace(cuts, measurement=meas, cache={})


#: how the pile's number of sliders is told to the angles-and-sizes forecaster (``told``)
TOLD = ("not told", "told exactly", "told a range")


def camera(cuts, seed: int):
    """The cuts as a camera records them (the camera forecaster's training draw), untold."""
    return untold(degrade_cuts(cuts, np.random.default_rng(seed), camera=True))


def coverage_at(f, cuts, lead=None, mask=None) -> dict:
    """80 % coverage, median |error| and median signed error (degrees) of ``f`` on ``cuts``
    (at each lead of ``lead`` if given), within ``mask`` of the cuts."""
    q, _ = f.quantiles(cuts)
    truth = cuts.alpha_c
    keep = np.ones(len(cuts), bool) if mask is None else mask

    def one(m):
        inside = (q[m, LOWER] <= truth[m]) & (truth[m] <= q[m, UPPER])
        err = q[m, MEDIAN] - truth[m]
        return {"coverage": float(inside.mean()) if m.any() else math.nan,
                "median_abs_deg": float(np.degrees(np.median(np.abs(err)))) if m.any() else math.nan,
                "median_signed_deg": float(np.degrees(np.median(err))) if m.any() else math.nan,
                "n": int(m.sum())}

    if lead is None:
        return one(keep)
    return {f"{d:g}": one(keep & np.isclose(lead, math.radians(d))) for d in LEADS_DEG}


class CameraForecast:
    """What ``predict`` does with a camera's catalogue: in the model's units by ``learned`` when
    its lone slips fix its unit (``features.cuts_in_model_units``), else by ``learned_camera``."""

    def __init__(self, models: dict):
        self.complete, self.camera = models["learned"], models["learned_camera"]

    def quantiles(self, cuts):
        q, fb = self.camera.quantiles(cuts)
        converted, which = cuts_in_model_units(cuts)
        if which.any():
            q[which], fb[which] = self.complete.quantiles(converted)
        self.read_in_model_units = float(which.mean())
        return q, fb


#: records of a camera: its units only (an exact record), with a 10 % relative displacement
#: error, and the camera forecaster's training draw (angle noise, thresholds, missed events)
CAMERA_RECORDS = ("units only", "10 % displacement error", "training draw")


def camera_cuts(cuts, record: str, seed: int):
    """``cuts`` as a camera of ``record`` (``CAMERA_RECORDS``) records them, no N told."""
    if record == "training draw":
        return camera(cuts, seed)
    rng = np.random.default_rng(seed)
    m = Measurement(displacement_unit="arbitrary", position_unit="fraction")
    noise = 0.1 if record.startswith("10") else 0.0
    cats = [degrade(c, m, rng, 1.0, (s, noise), int(n)) for c, (s, _), n
            in zip(cuts.catalogues, draw_camera(len(cuts), rng), cuts.n_sliders)]
    return replace(cuts, catalogues=cats, measurement=[m] * len(cuts), cache={})


def camera_report(models, test, train_ac, seed) -> dict:
    """A camera's catalogue as ``predict`` forecasts it (``CameraForecast``), for each record of
    ``CAMERA_RECORDS``: skill 3° and 1° before, the share read in the model's units, coverage
    over random cuts and at each lead."""
    f = CameraForecast(models)
    out = {}
    for record in CAMERA_RECORDS:
        rep = {}
        for d in (3.0, 1.0):
            cuts, _ = cuts_at_leads(test, np.arange(len(test)), [math.radians(d)])
            rep[f"skill_{d:g}deg"] = skill(f, camera_cuts(cuts, record, seed), train_ac)
            rep[f"skill_{d:g}deg"]["read_in_model_units"] = f.read_in_model_units
        rnd = training_cuts(test, 10, np.random.default_rng(seed))
        rep["random_cuts"] = coverage_at(f, camera_cuts(rnd, record, seed))
        cuts, which = cuts_at_leads(test, np.arange(len(test)), np.radians(LEADS_DEG))
        rep["per_lead"] = coverage_at(f, camera_cuts(cuts, record, seed),
                                      np.radians(LEADS_DEG)[which])
        out[record] = rep
    return out


def sized(models: dict, how: str):
    """The forecaster ``predict`` gives a catalogue of angles and sizes told its size as ``how``
    (``TOLD``): ``learned_sized`` when told (if the model holds it), else ``learned_blind``."""
    return models.get("learned_sized", models["learned_blind"]) if how != "not told" \
        else models["learned_blind"]


def size_report(models, test, seed) -> dict:
    """Coverage per size class, angles and sizes only, for each way of telling the size
    (``TOLD``, each by the forecaster ``predict`` gives it: ``sized``): over random cuts, at
    each lead, and the median signed error there."""
    n = np.asarray(test.parameters["n_sliders"])
    rnd = blind(training_cuts(test, 10, np.random.default_rng(seed)))
    at, which = cuts_at_leads(test, np.arange(len(test)), np.radians(LEADS_DEG))
    at = blind(at)
    lead = np.radians(LEADS_DEG)[which]
    out = {}
    for how in TOLD:
        out[how] = {}
        r, a, f = told(rnd, how, seed), told(at, how, seed), sized(models, how)
        for label, of in SIZE_CLASSES.items():
            out[how][label] = {"random_cuts": coverage_at(f, r, mask=of(n[r.row])),
                               "per_lead": coverage_at(f, a, lead, mask=of(n[a.row]))}
    return out


def edge_report(f, test, seed) -> dict:
    """Coverage of noisy catalogues (angles and sizes) cut within ``EDGE_LEAD_DEG`` of their
    avalanche, the angle error told."""
    rng = np.random.default_rng(seed)
    rows = np.flatnonzero(np.isfinite(test.alpha_c))
    leads = rng.uniform(0.0, math.radians(EDGE_LEAD_DEG), (rows.size, 4))
    from sliders.analysis.forecast.features import Cuts

    cuts = Cuts.from_set(test, np.repeat(rows, 4), np.repeat(test.alpha_c[rows], 4) - leads.ravel())
    noisy = degrade_cuts(blind(cuts), rng, Measurement(angle_resolution=math.radians(EDGE_NOISE_DEG)))
    q, _ = f.quantiles(noisy)
    above = np.array([len(c) and c.alpha[-1] > t for c, t in zip(noisy.catalogues, noisy.alpha_c)])
    inside = (q[:, LOWER] <= noisy.alpha_c) & (noisy.alpha_c <= q[:, UPPER])
    return {"coverage": float(inside.mean()), "n": int(len(noisy)),
            "last_angle_above_avalanche": float(above.mean()),
            "coverage_last_angle_above": float(inside[above].mean()) if above.any() else math.nan}


def announced_report(f, test, seed, view=blind, how: str = "not told") -> dict:
    """Per size class: the median |error| over the median error announced (random cuts), the
    size told as ``how`` (``TOLD``)."""
    n = np.asarray(test.parameters["n_sliders"])
    cuts = told(view(training_cuts(test, 6, np.random.default_rng(seed))), how, seed)
    q, fb = f.quantiles(cuts)
    announced = np.full(len(cuts), np.nan)
    for i in range(len(cuts)):
        fc = Forecast(q[i], float(cuts.tilt_now[i]), bool(fb[i]))
        t = typical_accuracy(f, fc)
        announced[i] = np.nan if t is None else t["median_abs_deg"]
    err = np.degrees(np.abs(q[:, MEDIAN] - cuts.alpha_c))
    out = {}
    for label, of in {"all": lambda k: np.ones(k.shape, bool), **SIZE_CLASSES}.items():
        m = of(n[cuts.row]) & np.isfinite(announced)
        out[label] = {"median_abs_deg": float(np.median(err[m])),
                      "announced_deg": float(np.median(announced[m])),
                      "ratio": float(np.median(err[m]) / np.median(announced[m])), "n": int(m.sum())}
    return out


def markdown(rep: dict) -> str:
    """The tables of docs/forecasting_results.md."""
    lines = ["| a camera's catalogue | lead | median abs err (deg) | / cond. clim. | 80 % coverage "
             "| read in the model's units | n |", "|---|---|---|---|---|---|---|"]
    for record, cam in rep["camera"].items():
        for d in ("3", "1"):
            s = cam[f"skill_{d}deg"]
            lines.append(f"| {record} | {d}° | {s['median_abs_deg']:.2f} | "
                         f"{s['vs_conditioned']:.2f} | {s['coverage']:.2f} | "
                         f"{s['read_in_model_units']:.2f} | {s['n']} |")
    leads = next(iter(rep["camera"].values()))["per_lead"]
    lines += ["", "| 80 % coverage | random cuts | " + " | ".join(f"{k}°" for k in leads) + " |",
              "|---|---|" + "---|" * len(leads)]
    for record, cam in rep["camera"].items():
        lines.append(f"| {record} | {cam['random_cuts']['coverage']:.2f} | "
                     + " | ".join(f"{v['coverage']:.2f}" for v in cam["per_lead"].values()) + " |")
    lines += ["", "| angles and sizes, size class | told | coverage, random cuts | lowest coverage "
                  "over leads 0.25-20° | median signed err 3° before (deg) |", "|---|---|---|---|---|"]
    for how, per in rep["sizes"].items():
        for label, v in per.items():
            low = min(x["coverage"] for x in v["per_lead"].values())
            lines.append(f"| {label} | {how} | {v['random_cuts']['coverage']:.2f} "
                         f"({v['random_cuts']['n']}) | {low:.2f} | "
                         f"{v['per_lead']['3']['median_signed_deg']:+.2f} |")
    e = rep["edge"]
    lines += ["", f"noisy tilt (angle error {EDGE_NOISE_DEG}°) cut within {EDGE_LEAD_DEG}° of the "
                  f"avalanche: coverage {e['coverage']:.2f} ({e['n']} cuts); last angle above the "
                  f"avalanche in {e['last_angle_above_avalanche']:.2f} of them, covered "
                  f"{e['coverage_last_angle_above']:.2f}"]
    for name, per in rep["announced"].items():
        lines += ["", f"{name}: the typical error announced against the error made (random cuts)",
                  "", "| size class | median abs err (deg) | median announced (deg) | ratio | n |",
                  "|---|---|---|---|---|"]
        for label, v in per.items():
            lines.append(f"| {label} | {v['median_abs_deg']:.2f} | {v['announced_deg']:.2f} | "
                         f"{v['ratio']:.2f} | {v['n']} |")
    return "\n".join(lines) + "\n"


def held_out(model: str):
    """The forecasters and provenance of ``model``, its training prior (found as named, beside
    the model, or in results/default_model) and its held-out rows that reached the avalanche."""
    models, prov = load_forecasters(model)
    beside = os.path.dirname(os.path.abspath(model))
    paths = [f if os.path.exists(f) else os.path.join(beside, os.path.basename(f))
             for f in prov["data_files"]]
    if not all(os.path.exists(f) for f in paths):
        paths = [os.path.join("results/default_model", os.path.basename(f)) for f in paths]
    data = CatalogueSet.joined([load_set(f) for f in paths])
    held = np.asarray(prov["held_out_rows"], dtype=int)
    return models, prov, data, held[np.isfinite(data.alpha_c[held])]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default="src/sliders/data/default_forecaster.zip")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    models, prov, data, held = held_out(args.model)
    test = data.subset(held)
    train_ac = models["learned_blind"].climatology_.alpha_c_
    rep = {"model": os.path.basename(args.model), "rows_tested": int(len(test)),
           "camera": camera_report(models, test, train_ac, args.seed),
           "sizes": size_report(models, test, args.seed),
           "edge": edge_report(models["learned_blind"], test, args.seed),
           "announced": {"learned, angles + sizes": announced_report(models["learned_blind"], test,
                                                                     args.seed),
                         "learned, angles + sizes, size told exactly": announced_report(
                             sized(models, "told exactly"), test, args.seed, how="told exactly"),
                         "learned, camera's units": announced_report(
                             models["learned_camera"], test, args.seed,
                             view=lambda c: camera(c, args.seed))}}
    print(write_report(rep, args.out, "forecast_conditions", markdown))


if __name__ == "__main__":
    main()
