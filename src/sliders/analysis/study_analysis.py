"""Analysis of a study file (``python -m sliders.study``): one row of numbers per point.

Definitions are REPRODUCTION.md's (``sliders.reproduction``), applied at every point:

* α_c: mean, standard deviation and standard error over the avalanching runs, with the
  bounds atan μ_d and atan μ̄_s (docs/model.md, "The avalanche and why α_c is bounded");
* the observed transition angle: where P₁ + P₂ rises above its linear trend fitted on
  [0.1, 0.3] by more than 3 standard errors on two angles in a row
  (``precursors.departure_angle``), against the model's 2μ̄_s/(1 + e) and the angle where
  the master equations' P₃ deficit reaches 10 % (``model.transition_angle_from_p3``);
* burst periods (``precursors.burst_periods``, per realisation, then averaged): early =
  intervals between two single-slider events of one slider below α = 0.3, against
  2Δμ/(1 + μ_s tan α); late = between two events of ≥ 3 sliders above α = 0.35, against Δμ;
* the synchronisation share (``precursors.sync_profile``): share of the displacement in
  events whose moving sliders form ≥ 2 separate groups, per realisation.

Common random numbers: realisation r has the same seed at every point, so a difference
between two points is measured on pairs (``paired_difference``); its standard error is that
of the per-realisation differences, not the root sum of the two points' errors.
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from ..io.storage import STATISTICS
from ..io.study_file import read_point_rows, read_study_spec
from .study_spec import STUDY_PREFIX, Study, parse_study
from . import model
from .observables import StatisticsGrids, combine, default_grids
from .precursors import DEPARTURE_SIGMAS, departure_angle
from .reproduction import SUM_FIT_RANGE


def load_study_file(path) -> tuple[Study, list[dict[str, np.ndarray]]]:
    """The study (re-validated from the file) and every point's rows."""
    spec = read_study_spec(path)
    data = {"study": {"realisations": spec["realisations"]}, "scene": spec["scene"],
            "axes": spec["axes"]}
    if spec.get("zip"):
        data["study"]["zip"] = spec["zip"]
    study = parse_study(data, f"study in {os.fspath(path)!r}")
    return study, [read_point_rows(path, p) for p in range(len(study.points))]


def _mean_sem(x: np.ndarray) -> tuple[float, float, int]:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan, math.nan, 0
    sem = float(np.std(x, ddof=1) / math.sqrt(x.size)) if x.size > 1 else math.nan
    return float(np.mean(x)), sem, int(x.size)


def point_summary(study: Study, p: int, rows: dict[str, np.ndarray]) -> dict[str, Any]:
    """Every study quantity at point p (NaN where the data do not define it)."""
    scene = study.scenes[p]
    done = rows["done"]
    out: dict[str, Any] = dict(study.points[p])
    out.update({"point": p, "n_done": int(done.sum()), "n_sliders": scene.n_sliders,
                "xi": scene.xi, "mu_d": scene.mu_d, "mu_s_mean": scene.mu_s_mean,
                "delta_mu": scene.delta_mu})
    ac = rows["alpha_c"][done]
    fin = ac[np.isfinite(ac)]
    out["alpha_c_mean"], out["alpha_c_sem"], out["n_avalanche"] = _mean_sem(fin)
    out["alpha_c_std"] = float(np.std(fin, ddof=1)) if fin.size > 1 else math.nan
    out["alpha_c_min"] = float(fin.min()) if fin.size else math.nan
    out["alpha_c_max"] = float(fin.max()) if fin.size else math.nan
    out["bound_low"], out["bound_high"] = math.atan(scene.mu_d), math.atan(scene.mu_s_mean)
    stats = {k[len(STATISTICS):]: v[done] for k, v in rows.items() if k.startswith(STATISTICS)}
    out["mean_event_size"] = math.nan
    out["event_size_pdf"] = None
    out["alpha_t_observed"] = math.nan
    if done.sum() >= 2:
        grids = StatisticsGrids.from_arrays(default_grids(scene).to_arrays())
        summary = combine({k: v for k, v in stats.items() if not k.startswith(STUDY_PREFIX)},
                          grids, scene.n_sliders)
        ok = summary.n_valid >= max(2, 0.5 * summary.n_realisations)
        if summary.p_mean.shape[1] >= 2:
            s12 = np.where(ok, summary.p_mean[:, 0] + summary.p_mean[:, 1], np.nan)
            e12 = np.hypot(summary.p_sem[:, 0], summary.p_sem[:, 1])
            out["alpha_t_observed"], _ = departure_angle(summary.alpha, s12, e12,
                                                         SUM_FIT_RANGE, +1)
        sizes = np.arange(1, scene.n_sliders + 1)
        counts = summary.event_size_counts
        if counts.sum() > 0:
            out["mean_event_size"] = float((sizes * counts).sum() / counts.sum())
            out["event_size_pdf"] = summary.event_size_pdf
    out["alpha_t_stirling"] = model.transition_angle_stirling(scene.mu_s_mean)
    out["alpha_t_p3"] = model.transition_angle_from_p3(scene.mu_s_mean, scene.mu_d)
    for key in ("early_period", "early_pred", "late_period", "sync_share", "sync_event_share"):
        out[key], out[key + "_sem"], out[key + "_n"] = _mean_sem(stats[STUDY_PREFIX + key])
    out["late_pred"] = scene.delta_mu
    return out


def study_table(path) -> tuple[Study, list[dict[str, Any]]]:
    """``point_summary`` of every point of a study file."""
    study, rows = load_study_file(path)
    return study, [point_summary(study, p, r) for p, r in enumerate(rows)]


def paired_difference(rows_a: dict, rows_b: dict, column: str) -> dict[str, float]:
    """b - a of a per-realisation value over the realisations done (and finite) at both.

    With common random numbers realisation r saw the same seed at both points: ``sem`` is
    the standard error of the paired differences; ``sem_unpaired`` what two independent
    ensembles of the same size would give (for comparison).
    """
    key = next((k for k in (column, STATISTICS + column, STATISTICS + STUDY_PREFIX + column)
                if k in rows_a), None)
    if key is None:
        raise KeyError(f"no per-realisation column {column!r} in the study")
    a, b = np.asarray(rows_a[key], float), np.asarray(rows_b[key], float)
    both = rows_a["done"] & rows_b["done"] & np.isfinite(a) & np.isfinite(b)
    d = b[both] - a[both]
    n = int(both.sum())
    if n < 2:
        return {"mean": math.nan, "sem": math.nan, "sem_unpaired": math.nan, "n": n}
    return {"mean": float(d.mean()), "sem": float(d.std(ddof=1) / math.sqrt(n)),
            "sem_unpaired": float(math.sqrt((a[both].var(ddof=1) + b[both].var(ddof=1)) / n)),
            "n": n}


def paired_differences(path, column: str, reference: int = 0) -> list[dict[str, float]]:
    """``paired_difference`` of every point against point ``reference``."""
    _, rows = load_study_file(path)
    return [paired_difference(rows[reference], r, column) for r in rows]


TABLE_COLUMNS = (  # (header, key, digits): the docs/studies.md tables
    ("runs", "n_done", 0), ("α_c mean", "alpha_c_mean", 4), ("sd", "alpha_c_std", 4),
    ("min", "alpha_c_min", 4), ("max", "alpha_c_max", 4),
    ("atan μ_d", "bound_low", 4), ("atan μ̄_s", "bound_high", 4),
    ("α_t obs.", "alpha_t_observed", 2), ("2μ̄_s/(1+e)", "alpha_t_stirling", 3),
    ("α_t P₃", "alpha_t_p3", 3), ("early Δα", "early_period", 4),
    ("2Δμ/(1+μ_s tan α)", "early_pred", 4), ("late Δα", "late_period", 4), ("Δμ", "late_pred", 3),
    ("sync share", "sync_share", 3), ("⟨s⟩", "mean_event_size", 2))


def markdown_table(path) -> str:
    """One Markdown row per point, plus the paired α_c differences to the first point."""
    study, table = study_table(path)
    _, rows = load_study_file(path)
    names = [n for d in study.dims for n in d]
    head = names + [h for h, _, _ in TABLE_COLUMNS] + ["Δα_c vs first (paired s.e.; unpaired)"]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for p, t in enumerate(table):
        d = paired_difference(rows[0], rows[p], "alpha_c")
        cells = [f"{t[n]:g}" for n in names]
        cells += ["n/a" if isinstance(t[k], float) and not math.isfinite(t[k]) else
                  f"{t[k]:.{nd}f}" for _, k, nd in TABLE_COLUMNS]
        cells.append(f"{d['mean']:+.4f} ± {d['sem']:.4f}; ± {d['sem_unpaired']:.4f}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    import sys

    for arg in sys.argv[1:]:
        print(f"\n{arg}\n\n{markdown_table(arg)}")
