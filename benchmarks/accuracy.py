"""Speed against accuracy of the tilt integrator: error against cost for dt and refine_tol.

Three measurements, all with the Fortran backend (NumPy at two settings on the
small scenes, to show that both backends converge to the same reference):

A. **Trajectories** (deterministic scenes).  For every (dt, refine_tol) of the
   sweep, the run is compared with a reference:
   * ``single_walls``: N = 1 between walls, sigma_mu = 0, up to alpha = 1.2;
     the reference is the exact closed form (``model.single_slider_angles``,
     displacement (mu_s - mu_d) cos(alpha) per event);
   * ``N10``: N = 10, free, seed 1, to the avalanche;
   * ``N100_prefix``: N = 100, free, seed 0, its first 120 events (the event
     sequence is the same at every setting up to there);
   the chains' reference is a run at dt = 1e-5, refine_tol = 1e-12, itself
   checked against dt = 2e-5.  Errors: max error in the event angles (and
   alpha_c), in the per-event displacement and in the positions (displacement
   since preparation after each event), the energy-balance residual, and
   whether the event sequence (n_moved of every event) is identical.  The
   convergence order is fitted on log error against log dt.
B. **Single events from identical states** (chaotic scenes N = 100, xi = 0 and
   0.001): resting
   states are sampled along runs (including the state before the avalanche);
   from each, one rearrangement is run at every setting and at a reference
   (dt = 1e-5, refine_tol = 1e-12).  Reported: the fraction of events whose
   outcome differs (set of sliders that moved, or avalanche or not) and the
   displacement error of the others.  This is the local error that feeds the
   statistics, measurable even where trajectories are chaotic.
C. **Ensemble statistics** (N = 100, R realisations, seeds 0..R-1): alpha_c
   (mean, std), number of events, mean event size, P_1 and P_2 averaged over
   0.1 <= alpha <= 0.38 and P_i(alpha) on every model bin (observables), and
   the event-size distribution, for each setting against the reference setting
   (dt = 1e-4, refine_tol = 1e-12; dt = 2e-4 as its check).  Same seeds, so
   differences are paired; the systematic error (bias) is the mean paired
   difference, its uncertainty the standard error of the differences.  It is
   compared with the statistical noise of a 20-run and of a 1000-run ensemble,
   std / sqrt(20) and std / sqrt(1000).

Cost: CPU time per run (process time, robust on a shared machine; short runs
are repeated and the median kept), wall time, integration steps and
slider-steps (sum over steps of the moving sliders, the avalanche event
included: ``Result.total_slider_steps``).  CPU time is the cost to
compare.

Writes benchmarks/results/accuracy.json, accuracy.txt (the printed tables) and
accuracy_pareto.png.
Usage: python benchmarks/accuracy.py [--realisations 40] [--parts ABC] [--tag NAME] [--quick]
       (--quick: a smoke run of a few seconds, results not meaningful;
        --parts C --realisations 200 --tag R200: the statistics alone, more runs)
"""

from __future__ import annotations

import argparse
import io
import json
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

import sliders
from sliders import Scene, prepare, status
from sliders.analysis import model, observables
from sliders.driver import make_engine

RESULTS = Path(__file__).parent / "results"

DTS = (3e-2, 1e-2, 3e-3, 1e-3, 3e-4, 1e-4)
TOLS = (1e-6, 1e-8, 1e-10, 1e-12)
REF_DT, REF_TOL = 1e-5, 1e-12
NUMPY_SETTINGS = ((1e-2, 1e-10), (1e-3, 1e-10))

TRAJECTORY_SCENES = {
    "single_walls": Scene(n_sliders=1, ends="walls", sigma_mu=0.0, seed=3, alpha_max=1.2,
                          record="displacements"),
    "N10": Scene(n_sliders=10, seed=1, record="displacements"),
    "N100_prefix": Scene(n_sliders=100, seed=0, max_events=120, record="displacements"),
}

STAT_REF = (1e-4, 1e-12)
STAT_CHECK = (2e-4, 1e-12)
STAT_SETTINGS = ((3e-2, 1e-10), (1e-2, 1e-10), (1e-2, 1e-6), (3e-3, 1e-10), (1e-3, 1e-10),
                 (1e-3, 1e-6), (3e-4, 1e-10), STAT_CHECK)

EVENT_REF = (1e-5, 1e-12)
EVENT_SETTINGS = ((3e-2, 1e-10), (1e-2, 1e-10), (3e-3, 1e-10), (1e-3, 1e-10), (1e-3, 1e-6),
                  (3e-4, 1e-10), (1e-4, 1e-12))

OUT = io.StringIO()


def say(*args) -> None:
    text = " ".join(str(a) for a in args)
    print(text, flush=True)
    OUT.write(text + "\n")


def label(dt: float, tol: float) -> str:
    return f"dt={dt:g},tol={tol:g}"


# ----------------------------------------------------------------------------- timing

def timed_tilt(scene: Scene, backend: str = "fortran", min_cpu: float = 0.3, max_repeats: int = 15):
    """Run a scene; repeat short runs until min_cpu seconds; median CPU and wall per run."""
    cpus, walls = [], []
    while True:
        c0, w0 = time.process_time(), time.perf_counter()
        result = sliders.tilt(scene, backend=backend)
        cpus.append(time.process_time() - c0)
        walls.append(time.perf_counter() - w0)
        if sum(cpus) >= min_cpu or len(cpus) >= max_repeats:
            break
    return result, {
        "cpu_s": float(np.median(cpus)), "wall_s": float(np.median(walls)), "repeats": len(cpus),
        "steps": int(result.n_steps.sum()) + int(result.final_event.get("n_steps", 0)),
        "slider_steps": result.total_slider_steps,
        "n_events": result.n_events, "status": result.status,
    }


# ----------------------------------------------------------------------------- A. trajectories

def first_difference(a: np.ndarray, b: np.ndarray) -> int:
    n = min(a.size, b.size)
    d = np.flatnonzero(np.asarray(a[:n]) != np.asarray(b[:n]))
    return int(d[0]) if d.size else n


def energy_errors(result) -> dict:
    res = np.abs(result.energy_residual)
    scale = result.work_gravity + result.dissipation
    return {
        "energy_residual_max": float(res.max()) if res.size else 0.0,
        "energy_residual_rel_max": float((res / np.where(scale > 0, scale, 1.0)).max()) if res.size else 0.0,
    }


def compare_to_reference(result, ref) -> dict:
    """Errors of a chain run against a reference run (on the common event prefix)."""
    k = first_difference(result.n_moved, ref.n_moved)
    same = (k == result.n_events == ref.n_events and result.status == ref.status)
    out = {"identical_sequence": bool(same), "common_prefix": k,
           "n_events": result.n_events, "ref_n_events": ref.n_events, "status": result.status}
    if k == 0:
        out.update(err_alpha=math.nan, err_dx_event=math.nan, err_x=math.nan)
        return out | energy_errors(result)
    err_alpha = float(np.max(np.abs(result.alpha[:k] - ref.alpha[:k])))
    if same and result.status == "avalanche":
        out["err_alpha_c"] = abs(result.alpha_c - ref.alpha_c)
        err_alpha = max(err_alpha, out["err_alpha_c"])
    step, step_ref = result.displacement.dense()[:k], ref.displacement.dense()[:k]
    x, x_ref = result.displacement_after()[:k], ref.displacement_after()[:k]
    out.update(
        err_alpha=err_alpha,
        err_dx_event=float(np.max(np.abs(step - step_ref))),
        err_x=float(np.max(np.abs(x - x_ref))),
        dx_scale=float(np.max(np.abs(step_ref))),
    )
    return out | energy_errors(result)


def compare_single_slider(result) -> dict:
    """Errors of an N = 1 walls run against the exact closed form (Sec. IV-A)."""
    sc = result.scene
    exact = model.single_slider_angles(float(result.prepared_force()[0]), sc.mu_s_mean, sc.mu_d,
                                       sc.alpha_max)
    k = min(result.n_events, exact.size)
    dx_exact = model.single_slider_displacement(exact[:k], sc.mu_s_mean, sc.mu_d)
    dx = result.displacement.dense()[:k, 0]
    out = {
        "identical_sequence": bool(result.n_events == exact.size),
        "common_prefix": k, "n_events": result.n_events, "ref_n_events": int(exact.size),
        "status": result.status,
        "err_alpha": float(np.max(np.abs(result.alpha[:k] - exact[:k]))),
        "err_dx_event": float(np.max(np.abs(dx - dx_exact))),
        "err_x": float(np.max(np.abs(np.cumsum(dx) - np.cumsum(dx_exact)))),
        "dx_scale": float(np.max(np.abs(dx_exact))),
    }
    return out | energy_errors(result)


def fit_order(dts, errs, floor) -> dict:
    """Slope of log(err) against log(dt) over the points well above the floor."""
    dts, errs = np.asarray(dts, float), np.asarray(errs, float)
    ok = np.isfinite(errs) & (errs > 10.0 * max(floor, 1e-15))
    out = {"points": int(ok.sum())}
    if ok.sum() >= 2:
        slope, _ = np.polyfit(np.log(dts[ok]), np.log(errs[ok]), 1)
        out["order"] = float(slope)
        d = dts[ok]
        e = errs[ok]
        out["local_orders"] = [float(np.log(e[i] / e[i + 1]) / np.log(d[i] / d[i + 1]))
                               for i in range(len(d) - 1)]
    else:
        out["order"] = math.nan
    return out


def trajectories(args) -> dict:
    say("\n=== A. Trajectories: error against cost (Fortran unless stated) ===")
    report = {}
    ref_dt = 10 * REF_DT if args.quick else REF_DT  # a smoke run: a coarser reference
    for name, base in TRAJECTORY_SCENES.items():
        say(f"\n--- {name}: N={base.n_sliders} ends={base.ends} seed={base.seed} "
            f"max_events={base.max_events if base.max_events < 10**6 else '-'} alpha_max={base.alpha_max:.4g}")
        exact = name == "single_walls"
        ref, ref_cost = timed_tilt(base.replace(dt=ref_dt, refine_tol=REF_TOL), min_cpu=0.0)
        check, check_cost = timed_tilt(base.replace(dt=2 * ref_dt, refine_tol=REF_TOL), min_cpu=0.0)
        if exact:
            ref_err = compare_single_slider(ref)
            check_err = compare_single_slider(check)
            floor = ref_err["err_x"]
        else:
            check_err = compare_to_reference(check, ref)
            ref_err = {"identical_sequence": True} | energy_errors(ref)
            # order 2: error(ref) ~ difference(ref, 2 ref) / 3
            floor = check_err["err_x"] / 3.0
        say(f"reference dt={ref_dt:g} tol={REF_TOL:g}: {ref.n_events} events, status {ref.status}, "
            f"cpu {ref_cost['cpu_s']:.2f} s; check dt={2 * ref_dt:g}: err_alpha "
            f"{check_err['err_alpha']:.2e}, err_x {check_err['err_x']:.2e}, "
            f"identical sequence {check_err['identical_sequence']}"
            + (f"; reference vs closed form: err_alpha {ref_err['err_alpha']:.2e}, "
               f"err_x {ref_err['err_x']:.2e}" if exact else ""))
        rows = []
        header = (f"{'backend':7s} {'dt':>7s} {'tol':>7s} {'cpu_s':>8s} {'steps':>10s} "
                  f"{'sl-steps':>11s} {'ns/sl-st':>8s} {'err_alpha':>9s} {'err_dx':>9s} {'err_x':>9s} "
                  f"{'E_res_rel':>9s} {'same seq':>8s}")
        say(header)
        settings = [("fortran", dt, tol) for dt in DTS for tol in TOLS if tol <= dt]
        if name in ("single_walls", "N10") and not args.quick:
            settings += [("numpy", dt, tol) for dt, tol in NUMPY_SETTINGS]
        if args.quick:
            settings = [("fortran", dt, tol) for dt in (1e-2, 1e-3) for tol in (1e-6, 1e-10)]
        for backend, dt, tol in settings:
            res, cost = timed_tilt(base.replace(dt=dt, refine_tol=tol), backend=backend,
                                   min_cpu=0.3 if backend == "fortran" else 0.0)
            err = compare_single_slider(res) if exact else compare_to_reference(res, ref)
            row = {"backend": backend, "dt": dt, "refine_tol": tol} | cost | err
            row["ns_per_slider_step"] = 1e9 * cost["cpu_s"] / max(cost["slider_steps"], 1)
            rows.append(row)
            say(f"{backend:7s} {dt:7.0e} {tol:7.0e} {cost['cpu_s']:8.4f} {cost['steps']:10d} "
                f"{cost['slider_steps']:11d} {row['ns_per_slider_step']:8.1f} {err['err_alpha']:9.2e} "
                f"{err['err_dx_event']:9.2e} {err['err_x']:9.2e} {err['energy_residual_rel_max']:9.1e} "
                f"{str(err['identical_sequence']):>8s}")
        orders = {}
        for tol in TOLS:
            sel = [r for r in rows if r["backend"] == "fortran" and r["refine_tol"] == tol
                   and r["identical_sequence"]]
            if len(sel) >= 2:
                orders[f"{tol:g}"] = {
                    key: fit_order([r["dt"] for r in sel], [r[key] for r in sel], floor if key == "err_x" else 0.0)
                    for key in ("err_alpha", "err_dx_event", "err_x")}
        for tol, o in orders.items():
            say(f"convergence order at tol={tol}: " + ", ".join(
                f"{k} {v['order']:.2f} (local {', '.join(f'{x:.1f}' for x in v.get('local_orders', []))})"
                for k, v in o.items()))
        report[name] = {
            "scene": base.to_dict(),
            "reference": {"dt": ref_dt, "refine_tol": REF_TOL, "exact_closed_form": exact,
                          "n_events": ref.n_events, "status": ref.status} | ref_cost | ref_err,
            "reference_check": {"dt": 2 * ref_dt, "refine_tol": REF_TOL} | check_cost | check_err,
            "rows": rows, "orders": orders,
        }
    return report


# ----------------------------------------------------------------------------- B. single events

def sample_states(scene: Scene, per_seed: int, seeds, max_duration: float = 1000.0) -> tuple[list, int]:
    """Resting states before events of runs at the scene's setting: evenly spread + the last.

    States whose event lasted longer than ``max_duration`` tau at the generating
    setting are skipped (their reference event at dt = 1e-5 would cost minutes),
    and so is the last state of a run that did not end in an avalanche.
    """
    states, skipped = [], 0
    for seed in seeds:
        sc = scene.replace(seed=seed)
        engine = make_engine(sc, "fortran")
        state = prepare(sc)
        engine.advance(state, max_events=sc.max_events, relax_only=True)
        trail = []
        while True:
            before = state.copy()
            chunk = engine.advance(state, max_events=1)
            long = chunk.n_events and chunk.events["duration"][0] > max_duration
            trail.append(None if long else before)
            if chunk.status != status.RUNNING:
                if chunk.status != status.AVALANCHE:
                    trail[-1] = None
                break
        pick = np.unique(np.linspace(0, len(trail) - 1, per_seed).round().astype(int))
        skipped += sum(trail[i] is None for i in pick)
        states += [(seed, int(i), len(trail), trail[i]) for i in pick if trail[i] is not None]
    return states, skipped


def one_event(scene: Scene, state):
    st = state.copy()
    engine = make_engine(scene, "fortran")
    c0 = time.process_time()
    chunk = engine.advance(st, max_events=1)
    cpu = time.process_time() - c0
    moved = np.flatnonzero(st.displacement != state.displacement)
    return {
        "status": chunk.status, "moved": moved, "dx": st.displacement - state.displacement,
        "cpu": cpu, "slider_steps": int(chunk.events["slider_steps"].sum()),
    }


def single_events(args) -> dict:
    say("\n=== B. One rearrangement from identical resting states (N=100, free) ===")
    out = {"reference": {"dt": EVENT_REF[0], "refine_tol": EVENT_REF[1]}, "scenes": []}
    for xi, n_seeds in ((0.0, args.event_seeds), (0.001, max(1, args.event_seeds // 2))):
        per_seed, seeds = (3, (0,)) if args.quick else (args.events_per_seed, range(n_seeds))
        gen = Scene(n_sliders=100, xi=xi, dt=1e-3, record="summary")
        states, skipped = sample_states(gen, per_seed, seeds)
        say(f"xi={xi:g}: {len(states)} resting states from seeds {list(seeds)} (generated at dt=1e-3; "
            f"{skipped} skipped: event longer than 1000 tau or run not ending in an avalanche), "
            f"reference dt={EVENT_REF[0]:g} tol={EVENT_REF[1]:g}")
        ref = [one_event(gen.replace(dt=EVENT_REF[0], refine_tol=EVENT_REF[1]), s[3]) for s in states]
        n_aval = sum(r["status"] == status.AVALANCHE for r in ref)
        say(f"reference: {n_aval} avalanche outcomes, sliders moved per event: mean "
            f"{np.mean([r['moved'].size for r in ref]):.1f}, max {max(r['moved'].size for r in ref)}; "
            f"cpu {sum(r['cpu'] for r in ref):.2f} s")
        say(f"{'dt':>7s} {'tol':>7s} {'cpu_s':>8s} {'sl-steps':>11s} {'differ':>7s} {'rel_dx_med':>10s} "
            f"{'rel_dx_max':>10s}")
        rows = []
        settings = EVENT_SETTINGS if not args.quick else ((1e-2, 1e-10), (1e-3, 1e-10))
        for dt, tol in settings:
            sc = gen.replace(dt=dt, refine_tol=tol)
            outs = [one_event(sc, s[3]) for s in states]
            differ, rel = [], []
            for o, r in zip(outs, ref):
                diff = (o["status"] != r["status"]) or not np.array_equal(o["moved"], r["moved"])
                differ.append(diff)
                if not diff and r["status"] == status.RUNNING:
                    rel.append(np.max(np.abs(o["dx"] - r["dx"])) / np.max(np.abs(r["dx"])))
            row = {
                "dt": dt, "refine_tol": tol, "n_states": len(states),
                "cpu_s": float(sum(o["cpu"] for o in outs)),
                "slider_steps": int(sum(o["slider_steps"] for o in outs)),
                "n_differ": int(np.sum(differ)),
                "fraction_differ": float(np.mean(differ)),
                "differ_states": [f"seed{s[0]}:event{s[1]}/{s[2]}" for s, d in zip(states, differ) if d],
                "rel_dx_median": float(np.median(rel)) if rel else math.nan,
                "rel_dx_max": float(np.max(rel)) if rel else math.nan,
            }
            rows.append(row)
            say(f"{dt:7.0e} {tol:7.0e} {row['cpu_s']:8.3f} {row['slider_steps']:11d} "
                f"{row['n_differ']:3d}/{len(states):<3d} {row['rel_dx_median']:10.2e} {row['rel_dx_max']:10.2e}"
                + (f"  differ: {', '.join(row['differ_states'])}" if row["n_differ"] else ""))
        out["scenes"].append({"scene": gen.to_dict(), "n_states": len(states), "skipped": skipped,
                              "states": [f"seed{s[0]}:event{s[1]}/{s[2]}" for s in states],
                              "reference_cpu_s": float(sum(r["cpu"] for r in ref)),
                              "reference_avalanches": int(n_aval), "rows": rows})
    return out


# ----------------------------------------------------------------------------- C. statistics

def run_scalars(result, grids) -> dict:
    """Per-realisation values compared between settings."""
    row = observables.realisation_statistics(result, grids)
    a = grids.alpha
    p = row["model_bin_counts"] / (result.scene.n_sliders * 2.0 * grids.delta_mu)
    window = (a >= 0.1) & (a <= 0.38) & row["valid_alpha"]
    return {
        "alpha_c": float(result.alpha_c),
        "n_events": float(result.n_events),
        "mean_event_size": float(np.mean(result.n_moved)) if result.n_events else math.nan,
        "P1_window": float(p[window, 0].mean()) if window.any() else math.nan,
        "P2_window": float(p[window, 1].mean()) if window.any() else math.nan,
        "_p": p, "_valid": row["valid_alpha"], "_sizes": np.asarray(result.n_moved),
        "_status": result.status,
    }


def paired(values, ref_values) -> dict:
    """Bias (mean paired difference), its standard error, and the ensemble noises."""
    v, r = np.asarray(values, float), np.asarray(ref_values, float)
    ok = np.isfinite(v) & np.isfinite(r)
    d = v[ok] - r[ok]
    n = int(ok.sum())
    std_ref = float(np.std(r[ok], ddof=1)) if n > 1 else math.nan
    bias = float(d.mean()) if n else math.nan
    sem = float(np.std(d, ddof=1) / math.sqrt(n)) if n > 1 else math.nan
    return {"n": n, "ref_mean": float(r[ok].mean()) if n else math.nan, "std_ref": std_ref,
            "bias": bias, "sem": sem, "noise20": std_ref / math.sqrt(20),
            "noise1000": std_ref / math.sqrt(1000),
            "verdict20": verdict(bias, sem, std_ref / math.sqrt(20)),
            "verdict1000": verdict(bias, sem, std_ref / math.sqrt(1000))}


def verdict(bias, sem, noise) -> str:
    """'below' if |bias| + 2 sem < noise; 'above' if |bias| - 2 sem > noise; else unresolved."""
    if not (math.isfinite(bias) and math.isfinite(sem)):
        return "n/a"
    if abs(bias) + 2 * sem < noise:
        return "below"
    if abs(bias) - 2 * sem > noise:
        return "ABOVE"
    return "unresolved" if abs(bias) >= 2 * sem else "unresolved(no bias seen)"


def std_comparison(values, ref_values, n_boot: int = 2000) -> dict:
    """Difference of the alpha_c spreads on the runs that avalanched at both settings.

    The uncertainty is a paired bootstrap over the realisations (the alpha_c
    distribution has a tail, so the Gaussian formula std/sqrt(2(R-1)) would
    understate it).
    """
    v, r = np.asarray(values, float), np.asarray(ref_values, float)
    ok = np.isfinite(v) & np.isfinite(r)
    v, r = v[ok], r[ok]
    sv, sr = float(np.std(v, ddof=1)), float(np.std(r, ddof=1))
    rng = np.random.default_rng(12345)
    idx = rng.integers(0, v.size, size=(n_boot, v.size))
    boot = np.std(v[idx], axis=1, ddof=1) - np.std(r[idx], axis=1, ddof=1)
    sem = float(np.std(boot, ddof=1))
    boot_ref = np.std(r[rng.integers(0, r.size, size=(n_boot, 20))], axis=1, ddof=1)  # a 20-run std
    noise20 = float(np.std(boot_ref, ddof=1))
    noise1000 = noise20 * math.sqrt(19 / 999)
    return {"n": int(v.size), "std": sv, "std_ref": sr, "bias": sv - sr, "sem": sem, "noise20": noise20,
            "noise1000": noise1000, "verdict20": verdict(sv - sr, sem, noise20),
            "verdict1000": verdict(sv - sr, sem, noise1000)}


def grid_comparison(rows, ref_rows) -> dict:
    """P_i(alpha) on every (angle, model bin) cell valid in >= 90 % of the paired runs."""
    p = np.stack([r["_p"] for r in rows])
    q = np.stack([r["_p"] for r in ref_rows])
    valid = np.stack([r["_valid"] for r in rows]) & np.stack([r["_valid"] for r in ref_rows])
    keep_angles = valid.mean(axis=0) >= 0.9
    d = (p - q)[:, keep_angles]
    v = valid[:, keep_angles]
    m = v[..., None] & np.ones(d.shape, bool)
    n = m.sum(axis=0)
    bias = np.where(m, d, 0).sum(axis=0) / np.maximum(n, 1)
    var_d = np.where(m, (d - bias) ** 2, 0).sum(axis=0) / np.maximum(n - 1, 1)
    qq = q[:, keep_angles]
    qmean = np.where(m, qq, 0).sum(axis=0) / np.maximum(n, 1)
    var_ref = np.where(m, (qq - qmean) ** 2, 0).sum(axis=0) / np.maximum(n - 1, 1)
    cells = var_ref > 0
    sem2 = var_d[cells] / n[cells]
    b2 = bias[cells] ** 2
    noise20_2 = var_ref[cells] / 20
    rms_bias = math.sqrt(max(0.0, float(np.mean(b2 - sem2))))
    return {
        "cells": int(cells.sum()),
        "chi2_per_cell": float(np.mean(b2 / np.where(sem2 > 0, sem2, np.inf))),
        "rms_bias": rms_bias,
        "rms_sem": float(math.sqrt(np.mean(sem2))),
        "rms_noise20": float(math.sqrt(np.mean(noise20_2))),
        "rms_noise1000": float(math.sqrt(np.mean(noise20_2) * 20 / 1000)),
        "bias_over_noise20": rms_bias / float(math.sqrt(np.mean(noise20_2))),
        "resolution_over_noise20": float(2 * math.sqrt(np.mean(sem2)) / math.sqrt(np.mean(noise20_2))),
    }


def ks_sizes(sizes, ref_sizes) -> dict:
    a, b = np.concatenate(sizes), np.concatenate(ref_sizes)
    grid = np.arange(1, max(a.max(), b.max()) + 1)
    ca = np.searchsorted(np.sort(a), grid, side="right") / a.size
    cb = np.searchsorted(np.sort(b), grid, side="right") / b.size
    dist = float(np.max(np.abs(ca - cb)))
    crit = 1.36 * math.sqrt((a.size + b.size) / (a.size * b.size))
    per_run = b.size / len(ref_sizes)
    crit20 = 1.36 * math.sqrt(2 / (20 * per_run))
    return {"ks_distance": dist, "ks_critical_5pc": crit, "ks_critical_20_vs_20": crit20,
            "events": int(a.size), "ref_events": int(b.size)}


def statistics(args) -> dict:
    r = 3 if args.quick else args.realisations
    base = Scene(n_sliders=args.stat_n, record="displacements")
    grids = observables.default_grids(base)
    say(f"\n=== C. Ensemble statistics: N={args.stat_n}, free, xi=0, R={r} realisations "
        f"(seeds 0..{r - 1}); reference dt={STAT_REF[0]:g} tol={STAT_REF[1]:g} ===")
    settings = [STAT_REF] + list(STAT_SETTINGS if not args.quick else ((1e-2, 1e-10),))
    per = {}
    for dt, tol in settings:
        rows, cpu, wall, work, statuses = [], 0.0, 0.0, 0, {}
        for seed in range(r):
            res, cost = timed_tilt(base.replace(seed=seed, dt=dt, refine_tol=tol), min_cpu=0.0)
            rows.append(run_scalars(res, grids))
            cpu += cost["cpu_s"]
            wall += cost["wall_s"]
            work += cost["slider_steps"]
            statuses[res.status] = statuses.get(res.status, 0) + 1
        per[(dt, tol)] = {"rows": rows, "cpu_s_per_run": cpu / r, "wall_s_per_run": wall / r,
                          "slider_steps_per_run": work / r, "statuses": statuses}
        say(f"  ran {label(dt, tol)}: {cpu / r:.3f} s cpu per run, statuses {statuses}")
    ref_rows = per[STAT_REF]["rows"]
    scalars = ("alpha_c", "n_events", "mean_event_size", "P1_window", "P2_window")
    out = {"scene": base.to_dict(), "realisations": r, "reference": {"dt": STAT_REF[0], "refine_tol": STAT_REF[1]},
           "rows": []}
    ref_info = {k: paired([x[k] for x in ref_rows], [x[k] for x in ref_rows]) for k in scalars}
    say("reference ensemble: " + ", ".join(
        f"{k} mean {ref_info[k]['ref_mean']:.4g} std {ref_info[k]['std_ref']:.3g}" for k in scalars))
    say(f"{'setting':24s} {'cpu/run':>8s} {'statistic':16s} {'bias':>10s} {'+-sem':>9s} "
        f"{'noise20':>9s} {'noise1000':>9s}  vs20 / vs1000")
    for (dt, tol), info in per.items():
        if (dt, tol) == STAT_REF:
            continue
        rows = info["rows"]
        entry = {"dt": dt, "refine_tol": tol, "cpu_s_per_run": info["cpu_s_per_run"],
                 "wall_s_per_run": info["wall_s_per_run"],
                 "slider_steps_per_run": info["slider_steps_per_run"], "statuses": info["statuses"],
                 "scalars": {k: paired([x[k] for x in rows], [x[k] for x in ref_rows]) for k in scalars}}
        entry["per_run"] = {k: [x[k] for x in rows] for k in scalars} | {"status": [x["_status"] for x in rows]}
        entry["alpha_c_std"] = std_comparison([x["alpha_c"] for x in rows], [x["alpha_c"] for x in ref_rows])
        entry["P_grid"] = grid_comparison(rows, ref_rows)
        entry["event_sizes"] = ks_sizes([x["_sizes"] for x in rows], [x["_sizes"] for x in ref_rows])
        first = True
        for k in scalars + ("alpha_c_std",):
            s = entry["alpha_c_std"] if k == "alpha_c_std" else entry["scalars"][k]
            say(f"{label(dt, tol) if first else '':24s} {info['cpu_s_per_run'] if first else math.nan:8.3f} "
                f"{k:16s} {s['bias']:10.2e} {s['sem']:9.2e} {s['noise20']:9.2e} {s['noise1000']:9.2e}  "
                f"{s['verdict20']} / {s['verdict1000']}")
            first = False
        g, e = entry["P_grid"], entry["event_sizes"]
        say(f"{'':24s} {'':8s} {'P_i(alpha) grid':16s} rms bias/noise20 {g['bias_over_noise20']:.2f} "
            f"(resolution {g['resolution_over_noise20']:.2f}), chi2/cell {g['chi2_per_cell']:.2f} on {g['cells']} cells")
        say(f"{'':24s} {'':8s} {'event sizes':16s} KS {e['ks_distance']:.3f} (5% critical "
            f"{e['ks_critical_5pc']:.3f}; between two 20-run ensembles {e['ks_critical_20_vs_20']:.3f})")
        out["rows"].append(entry)
    out["reference"]["per_run"] = ({k: [x[k] for x in ref_rows] for k in scalars}
                                   | {"status": [x["_status"] for x in ref_rows]})
    out["reference"].update(cpu_s_per_run=per[STAT_REF]["cpu_s_per_run"],
                            slider_steps_per_run=per[STAT_REF]["slider_steps_per_run"],
                            statuses=per[STAT_REF]["statuses"], scalars=ref_info)
    # fastest setting with no bias detected above the noise (no statistic "ABOVE",
    # P_i(alpha) rms bias below the noise); with R runs a bias is only resolved down
    # to ~2 sem, so the 1000-run statement is as strong as R allows (see the verdicts).
    def passes(entry, key):
        checks = [entry["scalars"][k][key] for k in scalars] + [entry["alpha_c_std"][key]]
        grid = entry["P_grid"]["bias_over_noise20"] * (1.0 if key == "verdict20" else math.sqrt(1000 / 20))
        return all(c != "ABOVE" for c in checks) and grid < 1.0
    for key in ("verdict20", "verdict1000"):
        ok = [e for e in out["rows"] if passes(e, key)]
        best = min(ok, key=lambda e: e["cpu_s_per_run"]) if ok else None
        name = key[7:]
        out[f"fastest_without_detected_bias_{name}"] = None if best is None else label(best["dt"], best["refine_tol"])
        say(f"fastest setting with no bias detected above the {name}-run noise: "
            f"{out[f'fastest_without_detected_bias_{name}']}; settings passing: "
            f"{', '.join(label(e['dt'], e['refine_tol']) for e in ok) or 'none'}")
    return out


# ----------------------------------------------------------------------------- figure

def pareto_front(points):
    """Indices of the non-dominated (cost, error) points, by increasing cost."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def pareto_figure(report, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if "trajectories" not in report:  # statistics only (--parts C)
        fig, ax = plt.subplots(1, 1, figsize=(7, 5.6))
        axes = [None, None, ax]
    else:
        fig, axes = plt.subplots(1, 3, figsize=(17, 5.6))
    colours = {"single_walls": "tab:blue", "N10": "tab:orange", "N100_prefix": "tab:green"}
    if "trajectories" in report:
        _trajectory_panels(report, axes[0], axes[1], colours)
    _statistics_panel(report, axes[2])
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _trajectory_panels(report, ax, ax2, colours) -> None:
    tol_marker = {1e-6: "v", 1e-8: "s", 1e-10: "o", 1e-12: "D"}
    for name, sc in report.get("trajectories", {}).items():
        c = colours[name]
        rows = [r for r in sc["rows"] if r["backend"] == "fortran" and r["identical_sequence"]
                and r["err_x"] > 0]
        for tol, m in tol_marker.items():
            sel = [r for r in rows if r["refine_tol"] == tol]
            ax.plot([r["cpu_s"] for r in sel], [r["err_x"] for r in sel], m, color=c, mfc="none",
                    ms=5, alpha=0.6, ls="none")
        pts = [(r["cpu_s"], r["err_x"]) for r in rows]
        front = [rows[i] for i in pareto_front(pts)]
        ax.plot([r["cpu_s"] for r in front], [r["err_x"] for r in front], "-", color=c, lw=1.5,
                label=f"{name} (N={sc['scene']['n_sliders']}): Pareto front")
        seen = set()
        for r in front:
            if r["dt"] in seen:
                continue
            seen.add(r["dt"])
            ax.annotate(f"{r['dt']:g}", (r["cpu_s"], r["err_x"]), fontsize=6.5,
                        xytext=(4, 3), textcoords="offset points", color=c)
        nps = [r for r in sc["rows"] if r["backend"] == "numpy"]
        if nps:
            ax.plot([r["cpu_s"] for r in nps], [max(r["err_x"], 1e-15) for r in nps], "*", color=c,
                    ms=10, label=f"{name}: NumPy backend")
    for tol, m in tol_marker.items():
        ax.plot([], [], m, color="grey", mfc="none", label=f"refine_tol={tol:g}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("CPU time per run (s)")
    ax.set_ylabel("max position error (g tau^2)")
    ax.set_title("A. trajectories: error against cost\n(front labelled with dt; marker: refine_tol)", fontsize=10)
    ax.legend(fontsize=6, loc="center right")
    ax.grid(True, which="major", alpha=0.3)

    ax = ax2
    for name, sc in report.get("trajectories", {}).items():
        c = colours[name]
        for tol, ls in ((1e-12, "-"), (1e-6, ":")):
            sel = [r for r in sc["rows"] if r["backend"] == "fortran" and r["refine_tol"] == tol
                   and r["identical_sequence"]]
            ax.plot([r["dt"] for r in sel], [r["err_x"] for r in sel], marker="o", ls=ls, color=c, ms=4,
                    label=f"{name}: positions, tol={tol:g}")
            if tol == 1e-12:
                ax.plot([r["dt"] for r in sel], [r["err_alpha"] for r in sel], marker="^", ls="--",
                        color=c, ms=4, label=f"{name}: event angles, tol={tol:g}")
    dts = np.array(DTS)
    ax.plot(dts, 3e-2 * (dts / dts[0]) ** 2, "k-", lw=0.8, alpha=0.5, label="slope 2")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time step dt (tau)")
    ax.set_ylabel("max error against the reference")
    ax.set_title("A. convergence with dt (solid: refine_tol=1e-12, dotted: 1e-6)", fontsize=10)
    ax.legend(fontsize=6)
    ax.grid(True, which="major", alpha=0.3)



def _statistics_panel(report, ax) -> None:
    st = report.get("statistics")
    if st:
        floor = 1e-3
        stats = (("alpha_c", "mean alpha_c", "tab:blue"), ("n_events", "events per run", "tab:orange"),
                 ("mean_event_size", "mean event size", "tab:green"),
                 ("P1_window", "P_1, 0.1<=alpha<=0.38", "tab:red"))
        for j, (key, name, c) in enumerate(stats):
            xs, lo, up = [], [], []
            for e in st["rows"]:
                s = e["scalars"][key]
                xs.append(e["cpu_s_per_run"] * (1 + 0.06 * (j - 1.5)))
                y = abs(s["bias"]) / s["std_ref"]
                lo.append(max(y, floor))
                up.append(max((abs(s["bias"]) + 2 * s["sem"]) / s["std_ref"] - max(y, floor), 0.0))
            ax.errorbar(xs, lo, yerr=[[0.0] * len(lo), up], fmt="o", color=c, capsize=2, ms=4,
                        label=f"{name}: |bias| / std, bar to +2 sem")
        for i, e in enumerate(sorted(st["rows"], key=lambda e: e["cpu_s_per_run"])):
            ax.annotate(f"{e['dt']:g}/{e['refine_tol']:g}", (e["cpu_s_per_run"], (2.3, 1.65, 1.2)[i % 3]),
                        fontsize=6, ha="center", va="top")
        ref_cpu = st["reference"]["cpu_s_per_run"]
        ax.axvline(ref_cpu, color="grey", ls=":", label="reference setting (cost)")
        ax.axhline(1 / math.sqrt(20), color="k", ls="--", label="noise of a 20-run ensemble")
        ax.axhline(1 / math.sqrt(1000), color="k", ls="-.", label="noise of a 1000-run ensemble")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_ylim(0.7 * floor, 2.4)
        ax.set_xlabel("CPU time per run (s)")
        ax.set_ylabel("systematic error / ensemble std  (floor 1e-3)")
        ax.set_title(f"C. ensemble statistics, N={st['scene']['n_sliders']}, "
                     f"R={st['realisations']} paired runs", fontsize=10)
        ax.legend(fontsize=6, loc="lower right")
        ax.grid(True, which="major", alpha=0.3)


# ----------------------------------------------------------------------------- main

def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realisations", type=int, default=40, help="R of part C (default 40)")
    parser.add_argument("--stat-n", type=int, default=100, help="N of parts C (default 100)")
    parser.add_argument("--event-seeds", type=int, default=6, help="seeds of part B")
    parser.add_argument("--events-per-seed", type=int, default=25, help="states per seed in part B")
    parser.add_argument("--parts", default="ABC", help="which parts to run (default ABC)")
    parser.add_argument("--quick", action="store_true", help="smoke run, seconds")
    parser.add_argument("--tag", default="", help="suffix of the output names (e.g. R200)")
    parser.add_argument("--out-dir", default=str(RESULTS))
    args = parser.parse_args(argv)
    out_dir = Path(args.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    report = {
        "machine": platform.processor() or platform.machine(), "python": platform.python_version(),
        "command": " ".join([Path(sys.argv[0]).name] + (argv if argv is not None else sys.argv[1:])),
        "cost_note": "cpu_s is process time per run (median of repeats for short runs); "
                     "slider_steps includes the avalanche event (total_slider_steps)",
    }
    if "A" in args.parts:
        report["trajectories"] = trajectories(args)
    if "B" in args.parts:
        report["single_events"] = single_events(args)
    if "C" in args.parts:
        report["statistics"] = statistics(args)
    report["total_wall_s"] = time.perf_counter() - started
    say(f"\ntotal {report['total_wall_s']:.0f} s")
    suffix = ("_quick" if args.quick else "") + (f"_{args.tag}" if args.tag else "")
    (out_dir / f"accuracy{suffix}.json").write_text(json.dumps(report, indent=1, default=_json_default))
    (out_dir / f"accuracy{suffix}.txt").write_text(OUT.getvalue())
    pareto_figure(report, out_dir / f"accuracy_pareto{suffix}.png")
    print(f"written {out_dir}/accuracy{suffix}.json, .txt, _pareto{suffix}.png")
    return report


def _json_default(x):
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return float(x)
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(type(x))


if __name__ == "__main__":
    main()
