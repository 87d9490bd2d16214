"""The paper's statements judged on this package's runs (``python -m sliders.reproduction``,
``sliders.runs.reproduction``, runs the experiments and writes the report).

REPRODUCTION.md holds, for each numbered statement of the paper (docs/model.md,
"What the paper reports", and the avalanche bounds of "The avalanche"), what the paper reports,
what this package measures, on how many runs and with which uncertainty, and
a verdict (agrees / partly / disagrees) with an explanation where it does
not agree.  The model is never tuned: the analysis choices (fit ranges,
thresholds of the verdicts) are fixed below, before any number is seen.

Each statement is one function registered in ``CLAIMS`` with ``@claim``: the
experiment whose runs it reads, and the thresholds of its verdict beside it
as data; ``judge`` appends the statements of an experiment to the report.

The experiments (``runs.reproduction``; the paper's parameters l = 10, mu_d = 0.55, mu_s = 0.6,
sigma_mu = 0.01; realisation r has seed ``keyed_random.realisation_seed(base, r)``):

* **A**  ``--runs`` chains of N = 10, xi = 0 (first rearrangement, bursts, alpha_c);
* **B/C** ``--large-runs`` chains of N = 400 with xi = 0 and xi = 0.001, the
  same seeds (synchronisation, event sizes, alpha_c);
* **S**  ``--runs`` chains of N = 100, xi = 0, or an ensemble file
  (``--ensemble``): force statistics, P_i, stopped forces, A(alpha).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from . import model
from . import observables as ob
from .precursors import (DEPARTURE_SIGMAS, END_FRACTION, EXTREMITY_BIN, HALF_CHAIN, SYNC_BIN,
                         SYNC_FRACTION, avalanche_bounds, burst_periods, departure_angle,
                         extremity_profile, median_onset, stopped_modes, sync_profile)

# Fixed analysis choices (decided before looking at the data).
LINEAR_FIT_RANGE = (0.0, 0.25)  # where P_1 is fitted to find the end of its linear growth
P2_SLOPE_RANGE = (0.2, 0.4)  # the paper's range for dP_2/dalpha
SUM_FIT_RANGE = (0.1, 0.3)  # P_1 + P_2 linear trend, to locate the transition
CUMUL_FIT_RANGE = (0.1, 0.45)  # exponential fits of A and <dx>
# The tolerances of each verdict sit beside the function that judges it (``claim``).


@dataclass
class Statement:
    """One statement of the paper, what was measured, on what sample, and the verdict."""
    key: str
    paper: str
    measured: str
    sample: str
    verdict: str
    explanation: str = ""


@dataclass
class Report:
    """The statements judged, notes, timings and the data behind the figures."""
    statements: list[Statement] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    data: dict = field(default_factory=dict)


def _fmt(x, nd=3) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{nd}f}"


def _pm(mean, err, nd=3) -> str:
    return f"{_fmt(mean, nd)} ± {_fmt(err, nd)}"


# -----------------------------------------------------------------------------
# the report
# -----------------------------------------------------------------------------


def verdict_close(values, target, tol) -> str:
    """Paper value ``target`` given to +-``tol`` (its rounding) vs runs ``values``.

    agrees: the ensemble mean is within tol + 2 s.e. of the target; partly:
    some run lies within tol of it (the paper reports a single run), or the
    mean is within tol + 2 sd; disagrees otherwise.
    """
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return "disagrees"
    mean = float(v.mean())
    sd = float(v.std(ddof=1)) if v.size > 1 else 0.0
    d = abs(mean - target)
    if d <= tol + 2.0 * sd / math.sqrt(v.size):
        return "agrees"
    if np.any(np.abs(v - target) <= tol) or d <= tol + 2.0 * sd:
        return "partly"
    return "disagrees"


# -----------------------------------------------------------------------------
# the statements: one registered function each, its thresholds beside it
# -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Claim:
    """A statement of the paper as the report judges it.

    ``experiment`` names the runs it needs (``Evidence``: "small", "large",
    "statistics", or "all" for a statement on every run); ``judge`` measures
    and returns the ``Statement`` with its verdict; ``thresholds`` are the
    verdict's tolerances, fixed before any number is seen, passed to ``judge``
    as keyword arguments.
    """
    experiment: str
    judge: Callable[..., Statement]
    thresholds: dict = field(default_factory=dict)


# in the order of the report; a new statement is one more ``@claim`` function
CLAIMS: list[Claim] = []


def claim(experiment: str, **thresholds):
    """Register the decorated function as the judge of one statement (see ``Claim``)."""
    def register(judge_fn):
        CLAIMS.append(Claim(experiment, judge_fn, thresholds))
        return judge_fn
    return register


@dataclass
class Evidence:
    """The runs the statements are judged on, filled in as the experiments finish."""
    small: list = field(default_factory=list)  # scene A: N = 10, xi = 0
    uncoupled: list = field(default_factory=list)  # scene B: large N, xi = 0
    coupled: list = field(default_factory=list)  # scene C: large N, xi = 0.001 (same seeds)
    summary: object = None  # statistics (an EnsembleSummary)
    groups: dict = field(default_factory=dict)  # every group of runs, by label (the bounds)
    ensemble_ac: object = None  # alpha_c of an ensemble file, when the statistics come from one
    data: dict = field(default_factory=dict)  # the numbers behind the figures, by topic


def judge(rep: Report, evidence: Evidence, experiment: str) -> None:
    """Append to ``rep`` every registered statement judged on ``experiment``, in order."""
    for c in CLAIMS:
        if c.experiment == experiment:
            rep.statements.append(c.judge(evidence, **c.thresholds))
    rep.data.update(evidence.data)


def _percent(x: float) -> str:
    return f"{x * 100:g} %"


@claim("small", paper=0.1, percentiles=(10, 90))
def first_rearrangement(ev: Evidence, *, paper, percentiles) -> Statement:
    """1. The first rearrangement of N = 10 near ``paper``: within the runs' percentile range."""
    first = np.array([r.alpha[0] for r in ev.small if r.n_events])
    p10, p90 = np.percentile(first, percentiles)
    v = ("agrees" if p10 <= paper <= p90 else
         "partly" if first.min() <= paper <= first.max() else "disagrees")
    span = f"{percentiles[0]}–{percentiles[1]} %"
    return Statement(
        "1. First rearrangement (N = 10, xi = 0)", f"near alpha ≈ {paper:g} (one run)",
        f"mean {_fmt(first.mean())}, sd {_fmt(first.std(ddof=1))}, {span} range "
        f"[{_fmt(p10)}, {_fmt(p90)}], min {_fmt(first.min())}",
        f"{first.size} runs", v,
        "The first angle is set by the most loaded of 10 uniform forces, so it varies a lot "
        f"from run to run; the paper's single run is compared with the {span} range."
        + ("" if v == "agrees" else " The paper's value lies outside that range."))


@claim("small", paper=0.5, rounding=0.05)
def small_avalanche_angle(ev: Evidence, *, paper, rounding) -> Statement:
    """2. alpha_c of N = 10 against the paper's one digit (``verdict_close``)."""
    ac = np.array([r.alpha_c for r in ev.small])
    ac_f = ac[np.isfinite(ac)]
    sd = float(ac_f.std(ddof=1)) if ac_f.size > 1 else math.nan
    return Statement(
        "2. Avalanche angle (N = 10, xi = 0)", f"alpha_c ≈ {paper:g}",
        f"{_pm(ac_f.mean(), sd / math.sqrt(ac_f.size))} (mean ± s.e.), sd {_fmt(sd)}",
        f"{ac_f.size} runs", verdict_close(ac_f, paper, rounding),
        f"The paper gives one digit ({paper:g} ± {rounding:g}, one run); agrees when the ensemble "
        "mean is within that, widened by 2 standard errors.")


def _iqr_text(bp: dict, which: str) -> str:
    iqr = bp[f"{which}_iqr"]
    return (f"{_fmt(iqr[0]) if iqr else 'n/a'}–"
            f"{_fmt(iqr[1]) if iqr else 'n/a'}")


@claim("small", early_within=0.25, late_within=0.5)
def burst_period(ev: Evidence, *, early_within, late_within) -> Statement:
    """3. Bursts repeat at the single-slider period early, at about Δμ late (relative tolerances)."""
    sc = ev.small[0].scene
    bp = burst_periods(ev.small, sc.delta_mu, sc.mu_s_mean)
    early_ok = abs(bp["early_median"] - bp["early_pred"]) <= early_within * bp["early_pred"]
    late_ok = abs(bp["late_median"] - sc.delta_mu) <= late_within * sc.delta_mu
    v = "agrees" if early_ok and late_ok else ("partly" if early_ok or late_ok else "disagrees")
    ev.data["bursts"] = bp
    return Statement(
        "3. Burst period (N = 10, xi = 0)",
        "bursts repeat at Δα ≈ 2Δμ (= 0.1) for single sliders, then ≈ Δμ (= 0.05) when "
        "several sliders move",
        f"early (single-slider events, α < 0.3): median {_fmt(bp['early_median'])} "
        f"(IQR {_iqr_text(bp, 'early')}; single-slider "
        f"prediction 2Δμ/(1+μ_s tan α) = {_fmt(bp['early_pred'])}); late (events of ≥ 3 "
        f"sliders, α > 0.35): median {_fmt(bp['late_median'])} (IQR {_iqr_text(bp, 'late')})",
        f"{len(ev.small)} runs; {bp['early_n']} early and {bp['late_n']} late intervals", v,
        f"Interval between two successive rearrangements of the same slider. Early: within "
        f"{_percent(early_within)} of the single-slider value; late: within "
        f"{_percent(late_within)} of Δμ."
        + ("" if v == "agrees" else
           (" The single-slider period is reproduced" if early_ok else
            " The single-slider period is not reproduced")
           + (", and so is the shorter period of grouped rearrangements." if late_ok else
              f", but sliders taking part in grouped rearrangements (≥ 3 sliders, α > 0.35) "
              f"rearrange again after a median {_fmt(bp['late_median'])}, well below Δμ = "
              f"{sc.delta_mu:g}: late in the tilt the active region of a 10-slider chain "
              "rearranges almost continuously; the paper's Δα ≈ Δμ is read off one run by eye.")))


@claim("large", paper=0.51, rounding=0.005)
def large_avalanche_angle(ev: Evidence, *, paper, rounding) -> Statement:
    """4. alpha_c of the coupled large chain against the paper's two digits (``verdict_close``)."""
    sc = ev.coupled[0].scene
    ac = np.array([r.alpha_c for r in ev.coupled])
    fin = ac[np.isfinite(ac)]
    sd = float(fin.std(ddof=1)) if fin.size > 1 else math.nan
    v = verdict_close(fin, paper, rounding)
    lo, hi = paper - rounding, paper + rounding
    return Statement(
        f"4. Avalanche angle (N = {sc.n_sliders}, xi = {sc.xi:g})", f"alpha_c ≈ {paper:g} (one run)",
        f"{_fmt(fin.mean(), 4)}" + (f" ± {_fmt(sd / math.sqrt(fin.size), 4)} (s.e.), sd "
                                     f"{_fmt(sd, 4)}" if fin.size > 1 else "")
        + f"; values {', '.join(_fmt(x, 4) for x in fin)}",
        f"{fin.size} runs that avalanched" + (f" (of {ac.size})" if fin.size < ac.size else ""), v,
        f"The paper gives two digits ({paper:g} ± {rounding:g}, one run); agrees when the ensemble "
        "mean is within that, widened by 2 standard errors; partly when at least one run is."
        + ("" if v == "agrees" else
           f" The mean here, {_fmt(fin.mean(), 4)}, lies {_fmt(lo - fin.mean(), 4)} below the "
           f"paper's rounding interval [{lo:g}, {hi:g}) while the run-to-run sd is "
           f"{_fmt(sd, 4)}; {int(np.sum(np.abs(fin - paper) <= rounding))} of {fin.size} runs fall "
           "inside it. Both α_c lie in the bounds [0.5028, 0.5404]; the difference may come from "
           "the preparation (which the paper leaves open, see docs/model.md) or from the paper's "
           "single run."))


@claim("large", onset=(0.38, 0.46), uncoupled_share=0.05)
def synchronisation(ev: Evidence, *, onset, uncoupled_share) -> Statement:
    """5. With coupling the regions synchronise from about 0.42 (median onset within ``onset``),
    without it (share of synchronised displacement at most ``uncoupled_share``) they do not."""
    res_b, res_c = ev.uncoupled, ev.coupled
    sc = res_c[0].scene
    sb, scc = sync_profile(res_b), sync_profile(res_c)
    onsets = np.array([sync_profile([r])["onset"] for r in res_c])
    median = float(np.median(onsets)) if np.all(np.isfinite(onsets)) else (
        float(np.nanmedian(onsets)) if np.any(np.isfinite(onsets)) else math.nan)
    if not np.any(np.isfinite(onsets)) or sb["overall_weighted"] > uncoupled_share:
        v = "disagrees"
    elif onset[0] <= median <= onset[1]:
        v = "agrees"
    else:
        v = "partly"
    bins = [(lo, w, f) for lo, w, f, t in zip(scc["edges"][:-1], scc["weighted"], scc["fraction"],
                                              scc["total"]) if t > 0 and lo >= 0.3]
    prof = ", ".join(f"{lo:.2f}: {w:.2f} ({f:.2f})" for lo, w, f in bins)
    ev.data["sync"] = {"b": sb, "c": scc}
    return Statement(
        f"5. Synchronisation with coupling (N = {sc.n_sliders})",
        "with xi = 0.001 the two active regions synchronise from α ≳ 0.42 (without coupling: "
        "unsynchronised regions)",
        f"share of the displacement in events where separate regions move together: "
        f"xi = 0.001: synchronised (share ≥ {SYNC_FRACTION:.0%} in every {SYNC_BIN}-wide bin "
        f"from there to the avalanche) from α = {', '.join(_fmt(o, 2) for o in onsets)} in the "
        f"{len(res_c)} runs (median {_fmt(median, 2)}); pooled over the runs, per bin from 0.3, "
        f"share (share of events): {prof}. xi = 0: share {_fmt(sb['overall_weighted'], 3)} "
        f"(no multi-region event at all)" if sb["overall"] == 0 else
        f"… xi = 0: share {_fmt(sb['overall_weighted'], 3)}",
        f"{len(res_c)} + {len(res_b)} runs (same seeds)", v,
        "Indicator: the sliders that move in one event form one or several separate groups of "
        "adjacent sliders. Without coupling a slider starts only when a neighbour moves, so "
        "every event is one group; two or more groups mean that distant regions rearranged "
        "together through the plate. The share is weighted by displacement because the many "
        "small one-slider events would otherwise hide the few large synchronised ones "
        "(the share of events is given in parentheses)."
        + ("" if v == "agrees" else
           f" The onset varies from run to run ({_fmt(np.nanmin(onsets), 2)}–"
           f"{_fmt(np.nanmax(onsets), 2)}); the paper's 0.42 comes from a single run, and "
           "the median here is earlier." if v == "partly" else ""))


@claim("large")
def larger_events(ev: Evidence) -> Statement:
    """6. The coupled chain's events move more sliders and more displacement (same seeds)."""
    res_b, res_c = ev.uncoupled, ev.coupled
    size_b = np.concatenate([r.n_moved for r in res_b])
    size_c = np.concatenate([r.n_moved for r in res_c])
    disp_b = np.concatenate([ob.event_total_displacement(r) for r in res_b])
    disp_c = np.concatenate([ob.event_total_displacement(r) for r in res_c])
    bigger = size_c.mean() > size_b.mean() and np.median(disp_c) > np.median(disp_b)
    return Statement(
        f"6. Coupling gives larger events (N = {res_c[0].scene.n_sliders})",
        "with coupling, rearrangements involve more sliders and larger displacements",
        f"mean event size {size_c.mean():.1f} (xi = 0.001) vs {size_b.mean():.1f} (xi = 0); "
        f"events {size_c.size} vs {size_b.size}; median total displacement per event "
        f"{np.median(disp_c):.3g} vs {np.median(disp_b):.3g}",
        f"{len(res_c)} + {len(res_b)} runs", "agrees" if bigger else "disagrees",
        "Event size: distinct sliders that moved; same seeds with and without coupling."
        + ("" if bigger else " The coupled chain does not give larger events here."))


def _extremities_explanation(ec: dict, two_regions: bool, upper_ok: bool, ends_share: float) -> str:
    """Why statement 14 is not "agrees", in numbers."""
    ends = ec["overall_up"] + ec["overall_down"]
    per_bin = ec["share_up"] + ec["share_down"]
    edges = ec["edges"]
    pop = np.flatnonzero((ec["total"] > 0) & (edges[:-1] >= 0.3))  # the bins listed above
    hi, lo = pop[np.argmax(per_bin[pop])], pop[np.argmin(per_bin[pop])]
    text = (" The two end regions carry most of the displacement" if two_regions else
            f" Over the whole tilt the two end quarters carry {ends:.2f} of the displacement, "
            f"below {ends_share:.2f}: per bin from 0.3 on the share ranges from {per_bin[lo]:.2f} (bin "
            f"{edges[lo]:.2f}) to {per_bin[hi]:.2f} (bin {edges[hi]:.2f}), and the largest "
            "rearrangements, just before the avalanche, carry most of it (see the extents above)")
    runs = ec["onset_up"].size
    n_up, n_down = int(np.isfinite(ec["onset_up"]).sum()), int(np.isfinite(ec["onset_down"]).sum())
    if upper_ok:
        return text + f"; the up-slope region spans half the chain from {median_onset(ec['onset_up']):.2f}."
    return (text + f". The region at the up-slope end spans half the chain until the avalanche in "
            f"{n_up} of {runs} runs (median onset {_fmt(median_onset(ec['onset_up']), 2)}), the "
            f"one at the down-slope end in {n_down} of {runs} (median onset "
            f"{_fmt(median_onset(ec['onset_down']), 2)}), against the paper's α ≈ 0.4 for the "
            "upper region.")


def _extremity_bins(ec: dict) -> str:
    """Per bin from 0.3: the pooled share of the two ends and the median extents of their regions."""
    rows = []
    with warnings.catch_warnings():  # bins where no run has events: NaN, said "n/a"
        warnings.simplefilter("ignore", RuntimeWarning)
        ext_up = np.nanmedian(ec["extent_up"], axis=0)
        ext_down = np.nanmedian(ec["extent_down"], axis=0)
    for j, lo in enumerate(ec["edges"][:-1]):
        if lo >= 0.3 and ec["total"][j] > 0:
            rows.append(f"{lo:.2f}: {ec['share_up'][j] + ec['share_down'][j]:.2f} "
                        f"({_fmt(ext_up[j], 2)}/{_fmt(ext_down[j], 2)})")
    return ", ".join(rows)


@claim("large", ends_share=2.0 / 3.0, each_end_share=1.0 / 6.0, upper_onset=(0.37, 0.43))
def extremities(ev: Evidence, *, ends_share, each_end_share, upper_onset) -> Statement:
    """14. Two active regions at the two ends; the upper one over half the chain from about 0.4.

    Two end regions: the end quarters carry at least ``ends_share`` of the
    displacement, each at least ``each_end_share`` (both ends, not one); the
    up-slope region's median onset within ``upper_onset`` ("from an angle of
    about 0.4", +-0.03 as statements 7 and 11).
    """
    res_b, res_c = ev.uncoupled, ev.coupled
    sc = res_c[0].scene
    ec, eb = extremity_profile(res_c), extremity_profile(res_b)
    ends = ec["overall_up"] + ec["overall_down"]
    two_regions = ends >= ends_share and min(ec["overall_up"], ec["overall_down"]) >= each_end_share
    med_up, med_down = median_onset(ec["onset_up"]), median_onset(ec["onset_down"])
    upper_ok = np.isfinite(med_up) and upper_onset[0] <= med_up <= upper_onset[1]
    any_half = bool(np.any(np.isfinite(ec["onset_up"])) or np.any(np.isfinite(ec["onset_down"])))
    if two_regions and upper_ok:
        v = "agrees"
    elif two_regions or upper_ok or any_half:
        v = "partly"
    else:
        v = "disagrees"
    onsets = lambda o: ", ".join(_fmt(x, 2) for x in o)  # noqa: E731
    q = f"{END_FRACTION:.0%}"
    ev.data["extremities"] = {"c": ec, "b": eb}
    return Statement(
        f"14. Two active regions at the extremities (N = {sc.n_sliders}, xi = {sc.xi:g})",
        "two main active regions involve the two extremities; from α ∼ 0.4 the upper region "
        "extends over more than half the size of the system",
        f"share of all displacement (events before the avalanche) in the end {q} of the "
        f"chain: up-slope {ec['overall_up']:.2f} + down-slope {ec['overall_down']:.2f} = "
        f"{ends:.2f} (an even spread gives {2 * END_FRACTION:.2f}; xi = 0: "
        f"{eb['overall_up'] + eb['overall_down']:.2f}). Region attached to an end spanning "
        f"≥ {HALF_CHAIN:.0%} of the chain in every {EXTREMITY_BIN}-wide bin from there to the "
        f"avalanche: up-slope end (slider 1) from α = {onsets(ec['onset_up'])} (median "
        f"{_fmt(med_up, 2)}), down-slope end (slider N) from α = {onsets(ec['onset_down'])} "
        f"(median {_fmt(med_down, 2)}). Per bin from 0.3, pooled share of the two ends "
        f"(median extent of the up-slope/down-slope region, fraction of N): {_extremity_bins(ec)}",
        f"{len(res_c)} + {len(res_b)} runs (same seeds)", v,
        f"Indicator, fixed before the runs: (i) the share of the total |displacement| carried "
        f"by the first and the last {q} of the sliders (two end regions: together "
        f"≥ {ends_share:.2f}, each ≥ {each_end_share:.2f}); (ii) the active region attached to "
        f"an end is the run of adjacent sliders, from the end slider on, that all moved in "
        f"the same {EXTREMITY_BIN}-wide angle bin; its onset is the first bin from which it "
        f"spans ≥ half of the chain in every bin with events until the avalanche (median over "
        f"the runs, required within {upper_onset[0]}–{upper_onset[1]}). \"Upper\" is read as "
        "up the slope (slider 1, smallest x); the paper does not say whether it means the top "
        "of the incline or the top of its hot map, so both ends are given."
        + ("" if v == "agrees" else
           _extremities_explanation(ec, two_regions, upper_ok, ends_share)))


def _valid(summary) -> np.ndarray:
    """Angles where at least half of the realisations (and two) still contribute."""
    return summary.n_valid >= max(2, 0.5 * summary.n_realisations)


def _sample(summary) -> str:
    return f"{summary.n_realisations} runs of N = {summary.n_sliders}"


def _crude_slope(summary) -> float:
    """The crude model's dP_1/dα = dP_2/dα = 1/(4 μ_s Δμ)."""
    return 1.0 / (4.0 * summary.grids.mu_s_mean * summary.grids.delta_mu)


def _p_bin(summary, i: int) -> tuple[np.ndarray, np.ndarray]:
    """P_(i+1) against the angle where enough runs contribute (NaN elsewhere), its s.e."""
    return np.where(_valid(summary), summary.p_mean[:, i], np.nan), summary.p_sem[:, i]


def _fits(ev: Evidence) -> dict:
    return ev.data.setdefault("fits", {})


@claim("statistics", paper=0.38, agrees_within=0.03, partly_within=0.08)
def p1_linear_growth(ev: Evidence, *, paper, agrees_within, partly_within) -> Statement:
    """7. P_1 grows linearly up to ``paper``: where it leaves its line (``departure_angle``)."""
    summary = ev.summary
    crude_slope = _crude_slope(summary)
    end, f1 = departure_angle(summary.alpha, *_p_bin(summary, 0), LINEAR_FIT_RANGE, -1)
    v = ("agrees" if np.isfinite(end) and abs(end - paper) <= agrees_within else
         "partly" if np.isfinite(end) and abs(end - paper) <= partly_within else "disagrees")
    _fits(ev).update(p1=f1, p1_end=end)
    return Statement(
        f"7. P_1 grows linearly up to α ≈ {paper:g} (N = {summary.n_sliders}, xi = 0)",
        "linear growth of P_1, slope of the crude model 1/(4 μ_s Δμ) = "
        f"{crude_slope:.2f}, up to α ≈ {paper:g}",
        f"slope on [{LINEAR_FIT_RANGE[0]}, {LINEAR_FIT_RANGE[1]}]: {_pm(f1['slope'], f1['slope_err'], 2)} "
        f"(crude model {crude_slope:.2f}); P_1 falls below the line (> {DEPARTURE_SIGMAS:g} s.e., two "
        f"angles in a row) from α = {_fmt(end, 2)}",
        _sample(summary), v,
        "End of the linear growth: first angle after the fit range where the measured P_1 lies "
        f"more than {DEPARTURE_SIGMAS:g} standard errors (point and extrapolated line) below the "
        "line fitted on the fit range."
        + ("" if v == "agrees" else f" Here P_1 leaves its line at {_fmt(end, 2)}, not {paper:g}."))


@claim("statistics", agrees_errors=2.0, agrees_within=0.15, partly_within=0.4)
def p2_slope(ev: Evidence, *, agrees_errors, agrees_within, partly_within) -> Statement:
    """8. dP_2/dα on P2_SLOPE_RANGE against the crude model (tolerances relative to it)."""
    summary = ev.summary
    a = summary.alpha
    crude_slope = _crude_slope(summary)
    p2, s2 = _p_bin(summary, 1)
    sel = (a >= P2_SLOPE_RANGE[0]) & (a <= P2_SLOPE_RANGE[1])
    f2 = ob.linear_fit(a[sel], p2[sel], s2[sel])
    dev = abs(f2["slope"] - crude_slope)
    v = ("agrees" if dev <= max(agrees_errors * f2["slope_err"], agrees_within * crude_slope) else
         "partly" if dev <= partly_within * crude_slope else "disagrees")
    _fits(ev)["p2"] = f2
    return Statement(
        "8. dP_2/dα ≈ 1/(4 μ_s Δμ) on 0.2 ≲ α ≲ 0.4",
        f"slope {crude_slope:.2f}, the same as dP_1/dα",
        f"weighted fit on [{P2_SLOPE_RANGE[0]}, {P2_SLOPE_RANGE[1]}]: "
        f"{_pm(f2['slope'], f2['slope_err'], 2)} (reduced χ² {_fmt(f2.get('chi2_red', math.nan), 1)})",
        _sample(summary), v,
        f"Agrees: within {agrees_errors:g} s.e. or {_percent(agrees_within)}; partly: within "
        f"{_percent(partly_within)}."
        + ("" if v == "agrees" else f" Measured/predicted = {f2['slope'] / crude_slope:.2f}."))


def _pooled_stopped(summary, modes: list[dict]) -> tuple[float, float, int]:
    """Mode (bins of 0.02), median and count of F_t/F_t* pooled over the angle bins ``modes``."""
    if not modes:
        return math.nan, math.nan, 0
    n = sum(m["n"] for m in modes)
    g = summary.grids
    rows = [j for j, c in enumerate(g.stop_alpha_centers)
            if any(abs(c - 0.5 * (m["lo"] + m["hi"])) < 1e-9 for m in modes)]
    w = summary.stopped_counts[rows][:, None] * summary.stopped_ratio_pdf[rows]
    p = np.nansum(w, axis=0)
    pr = p.reshape(-1, 2).sum(axis=1)
    rmid = 0.5 * (g.ratio_edges[::2][1:] + g.ratio_edges[::2][:-1])
    cdf = np.cumsum(p) / p.sum()
    return float(rmid[np.argmax(pr)]), float(g.ratio_edges[1:][np.searchsorted(cdf, 0.5)]), n


def _stopped_explanation(v: str, e_ok: bool, l_ok: bool, bound_ok: bool, above: float,
                         bound: float) -> str:
    """Why statement 9 is not "agrees"."""
    if v == "agrees":
        return ""
    if not (e_ok and l_ok and not bound_ok):
        return " See the per-bin values."
    return (f" The peaks are where the paper puts them, but {above:.0%} of the stopped "
            f"sliders end above {bound:.2f}: F_t = μ_d cos α is not an upper limit "
            "here. A possible mechanism (not checked): a slider stops with F_t < μ_d cos α (it "
            "decelerates), but its force is measured at the end of the event, and neighbours "
            "still moving after its stop can load it further, up to its static threshold "
            "μ_s cos α (ratio 1.2).")


@claim("statistics", early_alpha=0.2, late_alpha=0.4, early_within=0.03, late_within=0.05,
       bound_margin=0.02, above_bound=0.05)
def stopped_force_ratio(ev: Evidence, *, early_alpha, late_alpha, early_within, late_within,
                        bound_margin, above_bound) -> Statement:
    """9. F_t/F_t* of the stopped sliders peaks at 1 below ``early_alpha``, at μ_d/(2μ_d − μ_s)
    from ``late_alpha``, and at most ``above_bound`` of the stops lie ``bound_margin`` above that."""
    summary = ev.summary
    g = summary.grids
    modes = stopped_modes(summary)
    em, emed, en = _pooled_stopped(summary, [m for m in modes if m["hi"] <= early_alpha + 1e-9])
    lm, lmed, ln = _pooled_stopped(summary, [m for m in modes if m["lo"] >= late_alpha - 1e-9])
    high = g.mu_d / (2 * g.mu_d - g.mu_s_mean)
    bound = high + bound_margin
    e_ok = np.isfinite(em) and abs(em - 1.0) <= early_within
    l_ok = np.isfinite(lm) and abs(lm - high) <= late_within
    # is mu_d/(2 mu_d - mu_s) an upper limit?  the share of all stops above it (and the margin)
    allc = summary.stopped_counts[:, None] * summary.stopped_ratio_pdf * np.diff(g.ratio_edges)
    above = float(np.nansum(allc[:, g.ratio_centers > bound]) / max(np.nansum(allc), 1))
    bound_ok = above <= above_bound
    v = ("agrees" if e_ok and l_ok and bound_ok else
         "partly" if e_ok or l_ok else "disagrees")
    per_bin = "; ".join(f"[{m['lo']:.2f},{m['hi']:.2f}): mode {m['mode']:.3f}, median "
                        f"{m['median']:.3f} (n={m['n']})" for m in modes)
    _fits(ev)["stopped_modes"] = modes
    return Statement(
        "9. Stopped-force ratio F_t/F_t*",
        f"peaks at 1 for small α, at ≈ 1.1 (= μ_d/(2μ_d − μ_s) = {high:.3f}, F_t = μ_d cos α) "
        "for large α, which bounds all distributions",
        f"α < {early_alpha}: mode {_fmt(em)} (median {_fmt(emed)}, {en} stops); "
        f"α ≥ {late_alpha}: mode {_fmt(lm)} (median {_fmt(lmed)}, {ln} stops); "
        f"{above:.1%} of all stops lie above {bound:.2f}. Per bin: {per_bin}",
        _sample(summary), v,
        f"Mode of the PDF in bins of 0.01, pooled over the angle bins below {early_alpha:g} and "
        f"above {late_alpha:g}. Agrees: early mode within {early_within:g} of 1, late mode within "
        f"{late_within:g} of {high:.3f}, and at most {_percent(above_bound)} of the stops above "
        f"{bound:.2f} (the paper calls {high:.2f} an upper limit of all the distributions)."
        + _stopped_explanation(v, e_ok, l_ok, bound_ok, above, bound))


@claim("statistics", agrees_r2=0.97, partly_r2=0.9, clean_r2=0.8)
def exponential_growth(ev: Evidence, *, agrees_r2, partly_r2, clean_r2) -> Statement:
    """10. A(α) grows exponentially: R² of the log-linear fit on CUMUL_FIT_RANGE; the ⟨Δx⟩ fit
    is reported (called far from exponential below ``clean_r2``), not judged."""
    summary = ev.summary
    a = summary.alpha
    A = np.where(_valid(summary), summary.cumulated_mean, np.nan)
    fa = ob.exponential_fit(a, A, *CUMUL_FIT_RANGE)
    in_range = (a >= CUMUL_FIT_RANGE[0]) & (a <= CUMUL_FIT_RANGE[1])
    lin = ob.linear_fit(a[in_range], A[in_range])
    fb = {"rate": math.nan, "r2": math.nan, "rate_err": math.nan}
    if summary.event_mean_displacement is not None:
        fb = ob.exponential_fit(summary.alpha_mid, summary.event_mean_displacement, *CUMUL_FIT_RANGE)
    v = "agrees" if fa["r2"] >= agrees_r2 else ("partly" if fa["r2"] >= partly_r2 else "disagrees")
    _fits(ev).update(A=fa, dx=fb)
    return Statement(
        "10. Cumulated displacement A(α) grows exponentially",
        "A(α) grows exponentially, because the mean displacement per rearrangement ⟨Δx⟩ grows "
        "exponentially",
        f"fit of ln A on [{CUMUL_FIT_RANGE[0]}, {CUMUL_FIT_RANGE[1]}]: rate "
        f"{_pm(fa['rate'], fa['rate_err'], 1)}, R² = {_fmt(fa['r2'])} (a straight line in A: "
        f"R² = {_fmt(lin['r2'])}); A grows by ×{_fmt(np.exp(fa['rate'] * 0.35), 0)} over the range. "
        f"⟨Δx⟩ (mean over the sliders that moved, per event, averaged per 0.01 bin): rate "
        f"{_pm(fb['rate'], fb['rate_err'], 1)}, R² = {_fmt(fb['r2'])}",
        _sample(summary), v,
        f"Agrees: R² of the log-linear fit ≥ {agrees_r2:g}. The ⟨Δx⟩ part is reported, not judged: "
        "its definition in the paper is loose (per slider or per event)."
        + (" ⟨Δx⟩ is far from a clean exponential here (low R²): most of the growth of A "
           "comes from the number and size of events." if np.isfinite(fb["r2"]) and fb["r2"] < clean_r2
           else ""))


@claim("statistics", paper=0.4, within=0.03)
def transition_angle(ev: Evidence, *, paper, within) -> Statement:
    """11. The observed transition (P_1 + P_2 above its trend) near ``paper`` and after Stirling's α_t."""
    summary = ev.summary
    g = summary.grids
    s12 = np.where(_valid(summary), summary.p_mean[:, 0] + summary.p_mean[:, 1], np.nan)
    e12 = np.hypot(summary.p_sem[:, 0], summary.p_sem[:, 1])  # ignores their correlation
    at_obs, f12 = departure_angle(summary.alpha, s12, e12, SUM_FIT_RANGE, +1)
    at_s = model.transition_angle_stirling(g.mu_s_mean)
    at_e = model.transition_angle_exact(g.mu_s_mean, g.mu_d)
    at_p3 = model.transition_angle_from_p3(g.mu_s_mean, g.mu_d)
    v = ("agrees" if np.isfinite(at_obs) and abs(at_obs - paper) <= within and at_s < at_obs else
         "partly" if np.isfinite(at_obs) and at_s < at_obs else "disagrees")
    _fits(ev).update(p12=f12, alpha_t=at_obs)
    return Statement(
        "11. Transition angle α_t",
        f"model (Stirling) α_t = 2μ_s/(1+e) ≈ 0.32 underestimates the observed ≈ {paper:g} "
        "(sharp rise of P_1 + P_2)",
        f"observed: P_1 + P_2 rises above its linear trend (fitted on [{SUM_FIT_RANGE[0]}, "
        f"{SUM_FIT_RANGE[1]}], > {DEPARTURE_SIGMAS:g} s.e. on two angles in a row) from "
        f"α = {_fmt(at_obs, 2)}. Model: Stirling {at_s:.3f}, exact Eq. (not_neg) {at_e:.3f}, "
        f"deficit of P_3 = 10 % {at_p3:.3f}",
        _sample(summary), v,
        "Observed transition defined from the data as above; the model values are computed, "
        "not fitted.")


@claim("statistics", sigmas=3.0, partly_bins=2)
def flat_initial_forces(ev: Evidence, *, sigmas, partly_bins) -> Statement:
    """13. P_i(0) flat at 1/(2μ_s) (paper Sec. IV-B-1): no bin off by more than ``sigmas`` s.e.
    (partly: at most ``partly_bins`` of them)."""
    summary = ev.summary
    g = summary.grids
    p0, e0 = summary.p_mean[0], summary.p_sem[0]
    flat = 1.0 / (2.0 * g.mu_s_mean)
    z = (p0 - flat) / np.where(e0 > 0, e0, np.nan)
    worst = int(np.nanargmax(np.abs(z)))
    n_off = int(np.sum(np.abs(z) > sigmas))
    v = "agrees" if n_off == 0 else ("partly" if n_off <= partly_bins else "disagrees")
    return Statement(
        "13. Flat initial force distribution (α = 0)",
        f"flat on ]−μ_s, μ_s[: every P_i(0) = 1/(2μ_s) = {flat:.3f}",
        "P_i(0) for i = 1.." + f"{g.n_model_bins}: "
        + ", ".join(f"{x:.2f}" for x in p0)
        + f" (s.e. ≈ {np.nanmean(e0):.2f}); {n_off} of {g.n_model_bins} bins off by more than "
          f"{sigmas:g} s.e., worst bin {worst + 1} ({z[worst]:+.1f} s.e.)",
        _sample(summary), v,
        "Tests the preparation, not the paper's physics."
        + ("" if v == "agrees" else
           " The outer bins are depleted: the preparation (preparation.py) makes the drawn "
           "forces of a free chain sum to zero by moving each force towards one bound in "
           "proportion to its room, which compresses the whole distribution by a factor "
           "≈ 1 − |Σf|/(|Σf| + Σa) (a few % for N = 100, of order 1/√N) towards one end; "
           "the 0.1-wide end bins lose a large share of their sliders. This lowers P_1 at "
           "small α (statement 7 compares slopes, which it does not affect much)."))


def _group_bounds(name: str, results) -> tuple[str, bool, int, int]:
    """One group's line of statement 12, whether all its runs avalanched within the bounds,
    its number of runs that avalanched and of the others."""
    other = sum(1 for r in results if r.status != "avalanche")
    b = avalanche_bounds(results)
    ok = b["in_own"] == b["n_avalanche"] == b["n"]
    return (f"{name}: {b['in_own']}/{b['n']} within [atan μ_d, atan(mean μ_s,n)], "
            f"{b['in_nominal']}/{b['n']} within [{b['lo']:.4f}, {b['hi']:.4f}], "
            f"range {_fmt(b['min'], 4)}–{_fmt(b['max'], 4)}"), ok, b["n"], other


@claim("all", mu_d=0.55, mu_s=0.6)
def avalanche_bounds_statement(ev: Evidence, *, mu_d, mu_s) -> Statement:
    """12. atan(mu_d) <= alpha_c <= atan(mean mu_s) on every group of runs; an ensemble file's
    alpha_c (no final state kept) against the paper's ``mu_d`` and ``mu_s``."""
    parts, all_ok, total, other = [], True, 0, 0
    for name, results in ev.groups.items():
        if results:
            line, ok, n, n_other = _group_bounds(name, results)
            parts.append(line)
            all_ok &= ok
            total += n
            other += n_other
    if ev.ensemble_ac is not None:
        ac = np.asarray(ev.ensemble_ac)
        lo, hi = math.atan(mu_d), math.atan(mu_s)
        fin = ac[np.isfinite(ac)]
        total += ac.size
        parts.append(f"ensemble: {int(np.sum((fin >= lo) & (fin <= hi)))}/{ac.size} within "
                     f"[{lo:.4f}, {hi:.4f}], range {_fmt(fin.min(), 4)}–{_fmt(fin.max(), 4)}")
        all_ok &= fin.size == ac.size and bool(np.all(fin >= lo))
    return Statement(
        "12. Bounds of the avalanche angle (docs/model.md)",
        "atan μ_d ≤ α_c ≤ atan(mean μ_s) (here [0.5028, 0.5404] with the mean μ_s of the scene)",
        "; ".join(parts), f"{total} runs that avalanched"
        + (f" ({other} other run(s) did not end in an avalanche, see the notes)" if other else ""),
        "agrees" if all_ok else "disagrees",
        "The upper bound holds with the mean of the coefficients the sliders hold at the "
        "avalanche (it fluctuates around μ_s by σ_μ/√N), so a run may exceed atan(0.6) "
        "slightly without violating it." if all_ok else
        "Some run violates the bounds: a bug or a run that did not end in an avalanche.")


def report_markdown(rep: Report, meta: dict) -> str:
    """The text of REPRODUCTION.md: the report, and ``meta`` (date, version, backend, python,
    wall, command) of the run that made it."""
    lines = ["# Reproduction of \"Avalanche precursors in a frictional model\"", "",
             f"Generated by `python -m sliders.reproduction` on {meta['date']} "
             f"(sliders {meta['version']}, backend `{meta['backend']}`, Python {meta['python']}, "
             f"{meta['wall']:.0f} s on one core). Command: `{meta['command']}`.", "",
             "Parameters as in the paper: l = 10, μ_d = 0.55, μ̄_s = 0.6, σ_μ = 0.01. "
             "Realisation r of an ensemble has seed `realisation_seed(base_seed, r)`. "
             "The analysis choices (fit ranges, tolerances of the verdicts) are fixed in "
             "`src/sliders/analysis/reproduction.py`; nothing in the model is tuned.", "",
             "| # | statement | paper | this package | sample | verdict |",
             "|---|---|---|---|---|---|"]
    for s in rep.statements:
        num, _, title = s.key.partition(". ")
        cell = lambda t: t.replace("|", "\\|").replace("\n", " ")  # noqa: E731
        lines.append(f"| {num} | {cell(title)} | {cell(s.paper)} | {cell(s.measured)} | "
                     f"{cell(s.sample)} | **{s.verdict}** |")
    lines += ["", "## Notes on each statement", ""]
    for s in rep.statements:
        lines += [f"**{s.key}** — {s.verdict}. {s.explanation}", ""]
    counts = {v: sum(1 for s in rep.statements if s.verdict == v)
              for v in ("agrees", "partly", "disagrees")}
    lines += ["## Summary", "",
              f"{counts['agrees']} agree, {counts['partly']} partly, {counts['disagrees']} disagree.", ""]
    if rep.notes:
        lines += ["## Other notes", ""] + [f"- {n}" for n in rep.notes] + [""]
    lines += ["## Timings", ""] + [f"- {k}: {v:.1f} s" for k, v in rep.timings.items()] + [""]
    return "\n".join(lines)
