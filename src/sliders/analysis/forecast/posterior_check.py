"""The posterior predictive check: does the model, at the material the posterior gives, make
catalogues like the one measured?

``predictive_check`` simulates piles at posterior draws up to the catalogue's
tilt reached (``simulate_piles``), measures them as the catalogue was, and
compares summary statistics (``CHECK_STATISTICS``): each statistic's two-sided
p-value against the simulated ones, and how likely a simulated pile stands up
to the tilt the measured one reached (``survival_p_value``).  This posterior
predictive test passes (``reproduced``) when the survival p-value is at least
``CHECK_ALPHA`` and no statistic's p-value falls below ``CHECK_ALPHA`` divided
by their number (Bonferroni); the command's verdict also needs the prior
predictive test, the posterior's domain check (``combined_verdict``, whose ``reasons``
name each test that failed; ``p_value_text`` states a p-value as the text does).
A pile is run by the runner the caller hands (``run_pile(scene) -> Result``: the commands'
runs its preparation stoppable by a signal, ``sliders.runs.forecast.infer.simulate_pile``).
Neither scikit-learn nor the driver here: ``sliders.forecasting.infer`` imports this one at
its top, and ``predict`` imports that.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...io.catalogue import Catalogue
from ...parts.materials import scene_values
from ...scene import Scene
from .measurement import Measurement, degrade

#: the summary statistics compared; those counting sliders are left out for sizes in an
#: arbitrary unit
CHECK_STATISTICS = ("log_events", "onset", "centre", "log_mean_size", "log_max_size",
                    "share_one", "size_ratio_max", "log_slip", "log_lone_slip")
#: the statistics that count sliders
CHECK_IN_SLIDERS = ("log_mean_size", "log_max_size", "share_one")
#: the family-wise level under which a catalogue is "not reproduced"
CHECK_ALPHA = 0.01
#: the name of the survival p-value (``survival_p_value``) among the check's p-values
SURVIVAL = "stands_to_tilt"
#: the least spread of the simulated avalanche angles the survival p-value assumes (0.25°)
SURVIVAL_SPREAD = math.radians(0.25)
#: the least p-value the check's text states as a number: each is a normal tail fitted to the
#: ``CHECK_DRAWS`` (24) simulated piles, whose spread is known to about 1/sqrt(2 (24 - 1)), 15 %;
#: at p = 0.001 (z = 3.3) that moves p by a factor of about 3, and below it the number says no
#: more than "beyond the Bonferroni level" (0.01 over 9 statistics, 0.0011)
P_VALUE_FLOOR = 0.001


def check_statistics(cat: Catalogue, arbitrary_size: bool = False, complete: bool = True) -> dict:
    """The summary statistics of a catalogue the predictive check compares (``CHECK_STATISTICS``):
    the number of events (log), the first event's tilt and the events' mean tilt over the tilt
    reached, the mean and largest size (log), the share of lone slips, the largest size over
    the mean; with displacements (``complete``), the mean displacement of an event and of a
    lone slip (log, g tau^2: a lone slider moves by (mu_s,n - mu_d) cos(alpha)).  NaN where
    undefined (and for those counting sliders with ``arbitrary_size``)."""
    n = len(cat)
    t = max(float(cat.tilt_now), 1e-9)
    size = cat.size.astype(float)
    s = {"log_events": math.log1p(n),
         "onset": float(cat.alpha[0]) / t if n else 1.0,
         "centre": float(cat.alpha.mean()) / t if n else 1.0,
         "log_mean_size": math.log(size.mean()) if n else math.nan,
         "log_max_size": math.log(size.max()) if n else math.nan,
         "share_one": float(np.mean(size == 1)) if n else math.nan,
         "size_ratio_max": math.log(size.max() / size.mean()) if n else math.nan}
    disp = cat.displacement
    lone = (size == 1) & (disp > 0)
    s["log_slip"] = math.log(disp.mean()) if complete and n and disp.mean() > 0 else math.nan
    s["log_lone_slip"] = (math.log(disp[lone].mean()) if complete and not arbitrary_size
                          and lone.any() else math.nan)
    if arbitrary_size:
        for k in CHECK_IN_SLIDERS:
            s[k] = math.nan
    return s


def predictive_p_values(observed: dict, simulated: list[dict]) -> dict:
    """Each statistic's two-sided posterior predictive p-value: the observed value against the
    simulated ones' mean and spread (normal tails, the spread at least a tenth of the
    simulated range's scale and of the statistic's resolution), None where undefined."""
    out = {}
    for k in CHECK_STATISTICS:
        sims = np.array([s[k] for s in simulated], dtype=float)
        sims = sims[np.isfinite(sims)]
        obs = observed[k]
        if sims.size < 3 or not math.isfinite(obs):
            out[k] = None
            continue
        floor = 0.02 + 0.02 * abs(float(np.median(sims)))
        sd = max(float(np.std(sims, ddof=1)), floor)
        z = abs(obs - float(np.mean(sims))) / sd
        out[k] = math.erfc(z / math.sqrt(2.0))
    return out


def survival_p_value(avalanche_angles, tilt: float) -> float:
    """How likely a pile of the posterior stands up to the measured pile's tilt reached.

    ``avalanche_angles``: each simulated pile's avalanche angle, NaN if it stood up to
    ``tilt``.  With some standing: their share (the measured pile counted among them).  With
    none: at most that share, and less when ``tilt`` lies far above their avalanche angles,
    the normal tail of ``tilt`` above them (their spread at least ``SURVIVAL_SPREAD``).
    """
    a = np.asarray(avalanche_angles, dtype=float)
    standing = int(np.sum(~np.isfinite(a)))
    share = (standing + 1) / (a.size + 1)
    if standing or a.size < 3:
        return float(share)
    sd = max(float(np.std(a, ddof=1)), SURVIVAL_SPREAD)
    tail = 0.5 * math.erfc((tilt - float(np.mean(a))) / sd / math.sqrt(2.0))
    return float(min(share, tail))


def reproduced(p_values: dict, alpha: float = CHECK_ALPHA) -> bool:
    """Whether the catalogue is reproduced: a pile of the posterior may stand to its tilt
    (``stands_to_tilt`` at least ``alpha``: the physical test, on its own) and no statistic's
    p-value lies below ``alpha`` over their number (Bonferroni; the undefined ones left out)."""
    if (p_values.get(SURVIVAL) or 1.0) < alpha:
        return False
    p = [v for k, v in p_values.items() if v is not None and k != SURVIVAL]
    return not p or min(p) >= alpha / len(p)


def predictive_check(material: dict, base_scene: Scene, run_pile, cat: Catalogue,
                     measurement: Measurement, rng, complete: bool = True) -> dict:
    """The posterior predictive test: piles of the posterior draws ``material`` (one per draw),
    made from ``base_scene`` and run by ``run_pile(scene)``, simulated up to ``cat``'s tilt reached,
    measured as it was, against it (their displacements too if ``complete``): each statistic's
    p-value, whether it is reproduced."""
    draws = len(material["mu_d"])
    simulated, avalanche_angles = simulate_piles(base_scene, run_pile, material, cat.tilt_now,
                                                 measurement, rng)
    arbitrary = measurement.size_unit == "arbitrary"
    p = predictive_p_values(check_statistics(cat, arbitrary, complete),
                            [check_statistics(c, arbitrary, complete) for c in simulated])
    p[SURVIVAL] = survival_p_value(avalanche_angles, cat.tilt_now)
    return {"reproduced": reproduced(p), "p_values": p, "simulated": draws,
            "avalanched_before": int(np.sum(np.isfinite(avalanche_angles))),
            "significance_level": CHECK_ALPHA}


def simulate_piles(base_scene: Scene, run_pile, material: dict, tilt: float,
                   measurement: Measurement, rng):
    """The catalogues of piles of ``material`` (one per draw; ``base_scene`` with its
    parameters, run by ``run_pile(scene)``) tilted up to ``tilt``, measured as ``measurement`` says
    (sizes in sliders), and each one's avalanche angle (NaN: it stood)."""
    seeds = rng.integers(1, 2**31 - 1, len(material["mu_d"]))
    measured = Measurement(measurement.angle_resolution, 1.0 if measurement.size_unit ==
                           "arbitrary" else measurement.min_size, measurement.missed_fraction)
    cats, avalanched = [], []
    for j, seed in enumerate(seeds):
        changes = scene_values({name: v[j] for name, v in material.items()})
        result = run_pile(base_scene.replace(alpha_max=max(float(tilt), 1e-6), seed=int(seed),
                                             **changes))
        sim = Catalogue.from_result(result)
        sim = dataclasses.replace(sim, tilt_now=max(float(tilt), float(sim.tilt_now)))
        cats.append(degrade(sim, measured, rng))
        avalanched.append(result.alpha_c if result.status == "avalanche" else math.nan)
    return cats, np.array(avalanched, dtype=float)


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


def p_value_text(p: float) -> str:
    """A p-value of the check as the text gives it: ``= 0.023``, or ``< 0.001`` below
    ``P_VALUE_FLOOR``."""
    return f"< {P_VALUE_FLOOR:g}" if p < P_VALUE_FLOOR else f"= {p:.2g}"
