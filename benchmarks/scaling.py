"""Time, work and memory of the Fortran backend against the number of sliders N.

Fortran backend, record="summary", dt = 1e-3, xi = 0 and 0.001; every run in
a fresh child process (so that its peak resident memory is its own), one seed
per N (three for N <= 1000, whose runs are short and noisy).

Two end points:

* ``alpha_stop``: tilt up to alpha_max = 0.3 (the precursor regime, events of
  a few sliders), N = 1e2 .. 1e5 (``--n-max 1000000``: 1e6, 90 s) for xi = 0
  and 1e2 .. 1e4 for xi = 0.001
  (xi > 0 shifts every elastic force in every event, O(N) per event, and
  its relaxation at alpha = 0 sets the whole chain moving);
* ``avalanche``: to the avalanche, N = 100, 300, 1000, 3000, with
  max_event_duration = 1e5 tau (the default of every speed mode; the events
  just before the avalanche of long chains last ~3 N tau).  The longest event
  over N shows why the work grows as N^2: near the avalanche the events are
  slip fronts crossing the chain at the sound speed (one slider per tau).
* ``explore_avalanche``: N = 1e4 (``--explore-n``) with the paper's disorder,
  xi = 0 and 0.001, to the avalanche in the ``explore`` mode (dt = 1e-2).
  ``--parts explore_avalanche`` runs this part alone.

Measured per run: CPU time (process time of the child), wall time, events,
integration steps and slider-steps (sum over steps of the moving sliders,
relaxation and the avalanche event included), the largest event, the peak of Python-side allocations
(tracemalloc) and the peak resident set size (getrusage ru_maxrss, minus the
child's resident size before the run).  Fits: growth exponents of CPU time,
slider-steps and events against N (log-log least squares), and a
decomposition  cpu = a * slider_steps + b * events * N  that separates the
per-integration-step cost (a, ns per slider-step) from the per-event O(N)
work between events (b, ns per slider per event).

Writes benchmarks/results/scaling.json, scaling.txt and scaling.png.
Usage: python benchmarks/scaling.py [--n-max 100000] [--alpha-stop 0.3] [--quick]
"""

from __future__ import annotations

import argparse
import io
import json
import math
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).parent / "results"
EXPLORE_DT = 1e-2  # scene.py's explore mode
OUT = io.StringIO()


def say(*args) -> None:
    text = " ".join(str(a) for a in args)
    print(text, flush=True)
    OUT.write(text + "\n")


# ----------------------------------------------------------------------------- child

def child(n: int, xi: float, seed: int, alpha_max: float, cap: float, dt: float) -> dict:
    import resource
    import tracemalloc

    import sliders
    from sliders import Scene
    from sliders.parts.loading import ALPHA_MAX_LIMIT

    scene = Scene(n_sliders=n, xi=xi, seed=seed, dt=dt, record="summary",
                  alpha_max=min(alpha_max, ALPHA_MAX_LIMIT), max_event_duration=cap)
    sliders.tilt(Scene(n_sliders=2, record="summary"))  # load the extension before measuring
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    tracemalloc.start()
    c0, w0 = time.process_time(), time.perf_counter()
    result = sliders.tilt(scene, backend="fortran")
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    _, py_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    relax = result.relaxation
    return {
        "n": n, "xi": xi, "seed": seed, "dt": dt, "alpha_max": alpha_max, "max_event_duration": cap,
        "status": result.status, "alpha_c": result.alpha_c, "alpha_end": result.final.drive,
        "cpu_s": cpu, "wall_s": wall, "events": result.n_events,
        "steps": int(result.n_steps.sum()) + int(result.final_event.get("n_steps", 0)),
        "slider_steps": result.total_slider_steps,
        "relax_slider_steps": int(relax.get("slider_steps", 0)),
        "final_event_slider_steps": int(result.final_event.get("slider_steps", 0)),
        "final_event_tau": float(result.final_event.get("duration", 0.0)),
        "largest_event": int(result.n_moved.max()) if result.n_events else 0,
        "longest_event_tau": float(result.duration.max()) if result.n_events else 0.0,
        "python_peak_bytes": int(py_peak),
        "rss_before_kb": int(rss0), "rss_peak_kb": int(rss1), "rss_growth_kb": int(rss1 - rss0),
    }


def run_child(n, xi, seed, alpha_max, cap, dt, timeout) -> dict | None:
    cmd = [sys.executable, __file__, "--child", json.dumps([n, xi, seed, alpha_max, cap, dt])]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=True)
    except subprocess.TimeoutExpired:
        say(f"  N={n} xi={xi} seed={seed}: over the {timeout} s limit, skipped")
        return None
    except subprocess.CalledProcessError as exc:
        say(f"  N={n} xi={xi} seed={seed}: child failed: {exc.stderr[-500:]}")
        return None
    return json.loads(done.stdout.strip().splitlines()[-1])


# ----------------------------------------------------------------------------- fits

def power_fit(n, y) -> dict:
    n, y = np.asarray(n, float), np.asarray(y, float)
    ok = (y > 0) & np.isfinite(y)
    if ok.sum() < 2:
        return {"exponent": math.nan}
    slope, icpt = np.polyfit(np.log(n[ok]), np.log(y[ok]), 1)
    return {"exponent": float(slope), "prefactor": float(math.exp(icpt)),
            "range": [float(n[ok].min()), float(n[ok].max())]}


def cost_decomposition(rows) -> dict:
    """Least squares cpu = c + a * slider_steps + b * events * N (relative residuals weighted)."""
    cpu = np.array([r["cpu_s"] for r in rows])
    x = np.column_stack([[r["slider_steps"] for r in rows], [r["events"] * r["n"] for r in rows],
                         np.ones(len(rows))]).astype(float)
    w = 1.0 / cpu  # fit relative errors: every N counts
    coef, *_ = np.linalg.lstsq(x * w[:, None], cpu * w, rcond=None)
    pred = x @ coef
    return {"ns_per_slider_step": float(coef[0] * 1e9), "ns_per_slider_per_event": float(coef[1] * 1e9),
            "fixed_s": float(coef[2]),
            "max_relative_residual": float(np.max(np.abs(pred / cpu - 1.0)))}


def aggregate(rows) -> list[dict]:
    """Mean over seeds per (xi, N)."""
    out = []
    for key in sorted({(r["xi"], r["n"]) for r in rows}):
        sel = [r for r in rows if (r["xi"], r["n"]) == key]
        m = {k: float(np.mean([r[k] for r in sel])) for k in
             ("cpu_s", "wall_s", "events", "steps", "slider_steps", "relax_slider_steps", "largest_event",
              "longest_event_tau", "python_peak_bytes", "rss_growth_kb", "rss_peak_kb")}
        m.update(xi=key[0], n=key[1], seeds=len(sel), statuses=sorted({r["status"] for r in sel}))
        m["ns_per_slider_step"] = 1e9 * m["cpu_s"] / max(m["slider_steps"], 1)
        m["us_per_event"] = 1e6 * m["cpu_s"] / max(m["events"], 1)
        m["events_per_n"] = m["events"] / key[1]
        m["longest_tau_per_n"] = m["longest_event_tau"] / key[1]
        out.append(m)
    return out


def table(agg) -> None:
    say(f"{'xi':>6s} {'N':>7s} {'seeds':>5s} {'cpu_s':>8s} {'wall_s':>8s} {'events':>8s} {'ev/N':>6s} "
        f"{'sl-steps':>11s} {'ns/sl-st':>8s} {'us/event':>9s} {'largest':>7s} {'py_MB':>7s} {'rss+MB':>7s} status")
    for m in agg:
        say(f"{m['xi']:6g} {m['n']:7d} {m['seeds']:5d} {m['cpu_s']:8.3f} {m['wall_s']:8.3f} {m['events']:8.0f} "
            f"{m['events_per_n']:6.2f} {m['slider_steps']:11.3g} {m['ns_per_slider_step']:8.1f} "
            f"{m['us_per_event']:9.1f} {m['largest_event']:7.0f} {m['python_peak_bytes'] / 1e6:7.2f} "
            f"{m['rss_growth_kb'] / 1e3:7.1f} {','.join(m['statuses'])}")


def fits(agg) -> dict:
    out = {}
    for xi in sorted({m["xi"] for m in agg}):
        sel = [m for m in agg if m["xi"] == xi]
        n = [m["n"] for m in sel]
        out[f"{xi:g}"] = {
            "cpu_s": power_fit(n, [m["cpu_s"] for m in sel]),
            "slider_steps": power_fit(n, [m["slider_steps"] for m in sel]),
            "events": power_fit(n, [m["events"] for m in sel]),
            "ns_per_slider_step": power_fit(n, [m["ns_per_slider_step"] for m in sel]),
            "python_peak_bytes": power_fit(n, [m["python_peak_bytes"] for m in sel]),
            "decomposition": cost_decomposition(sel) if len(sel) >= 4 else None,
        }
        f = out[f"{xi:g}"]
        say(f"xi={xi:g}: exponents vs N: cpu {f['cpu_s']['exponent']:.2f}, slider-steps "
            f"{f['slider_steps']['exponent']:.2f}, events {f['events']['exponent']:.2f}, ns/slider-step "
            f"{f['ns_per_slider_step']['exponent']:.2f}, python memory {f['python_peak_bytes']['exponent']:.2f}")
        if f["decomposition"]:
            d = f["decomposition"]
            say(f"   cpu = {d['ns_per_slider_step']:.1f} ns x slider-steps + {d['ns_per_slider_per_event']:.2f} ns "
                f"x events x N + {d['fixed_s'] * 1e3:.1f} ms  (max relative residual {d['max_relative_residual']:.2f})")
    return out


# ----------------------------------------------------------------------------- figure

def figure(report, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    styles = {("alpha_stop", 0.0): ("tab:blue", "o", "-"), ("alpha_stop", 0.001): ("tab:orange", "s", "-"),
              ("avalanche", 0.0): ("tab:blue", "o", "--"), ("avalanche", 0.001): ("tab:orange", "s", "--")}
    for part, data in (("alpha_stop", report["alpha_stop"]), ("avalanche", report["avalanche"])):
        end = f"to alpha={report['alpha_stop_value']:g}" if part == "alpha_stop" else "to the avalanche"
        for xi in (0.0, 0.001):
            sel = [m for m in data["aggregate"] if m["xi"] == xi]
            if not sel:
                continue
            c, mk, ls = styles[(part, xi)]
            n = np.array([m["n"] for m in sel])
            lab = f"xi={xi:g}, {end}"
            mfc = c if part == "alpha_stop" else "none"
            ax = axes[0, 0]
            ax.plot(n, [m["cpu_s"] for m in sel], marker=mk, ls=ls, color=c, mfc=mfc, label=lab)
            ax = axes[0, 1]
            ax.plot(n, [m["slider_steps"] for m in sel], marker=mk, ls=ls, color=c, mfc=mfc,
                    label=f"slider-steps, {lab}")
            ax.plot(n, [m["events"] for m in sel], marker=mk, ls=":", color=c, mfc=mfc, alpha=0.6,
                    label=f"events, {lab}")
            ax = axes[1, 0]
            ax.plot(n, [m["ns_per_slider_step"] for m in sel], marker=mk, ls=ls, color=c, mfc=mfc,
                    label=f"CPU / slider-steps, {lab}")
            if part == "alpha_stop":
                ax.plot(n, [m["us_per_event"] * 1e3 / m["n"] for m in sel], marker=mk, ls=":", color=c,
                        alpha=0.6, label=f"CPU / (events x N), {lab}")
            ax = axes[1, 1]
            ax.plot(n, [m["python_peak_bytes"] for m in sel], marker=mk, ls=ls, color=c, mfc=mfc,
                    label=f"Python peak (tracemalloc), {lab}")
            ax.plot(n, [max(m["rss_growth_kb"], 1) * 1e3 for m in sel], marker=mk, ls=":", color=c, mfc=mfc,
                    alpha=0.6, label=f"RSS growth, {lab}")
    nn = np.array([1e2, 1e5])
    axes[0, 0].plot(nn, 1e-3 * (nn / 1e2) ** 1, "k-", lw=0.7, alpha=0.5, label="slope 1")
    axes[0, 0].plot(nn, 1e-3 * (nn / 1e2) ** 2, "k--", lw=0.7, alpha=0.5, label="slope 2")
    titles = ("CPU time per run", "work: slider-steps and events", "cost per unit of work",
              "memory")
    ylabels = ("CPU time (s)", "count", "ns", "bytes")
    for ax, t, yl in zip(axes.flat, titles, ylabels):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("number of sliders N")
        ax.set_ylabel(yl)
        ax.set_title(t, fontsize=10)
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=6.5)
    fig.suptitle(f"Fortran backend scaling, dt={report['dt']:g}, record='summary' "
                 f"(solid/filled: to alpha={report['alpha_stop_value']:g}; dashed/open: to the avalanche)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ----------------------------------------------------------------------------- main

def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--n-max", type=int, default=100_000, help="largest N for xi = 0 (default 1e5)")
    parser.add_argument("--n-max-coupled", type=int, default=10_000, help="largest N for xi = 0.001")
    parser.add_argument("--alpha-stop", type=float, default=0.3)
    parser.add_argument("--avalanche-n", type=int, nargs="*", default=[100, 300, 1000, 3000])
    parser.add_argument("--dt", type=float, default=1e-3)
    parser.add_argument("--explore-n", type=int, nargs="*", default=[10_000],
                        help="N of the explore-mode runs to the avalanche")
    parser.add_argument("--parts", nargs="+", default=["alpha_stop", "avalanche", "explore_avalanche"],
                        choices=["alpha_stop", "avalanche", "explore_avalanche"])
    parser.add_argument("--timeout", type=float, default=900.0, help="per run, seconds")
    parser.add_argument("--quick", action="store_true", help="smoke run (N <= 1000)")
    parser.add_argument("--out-dir", default=str(RESULTS))
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(*json.loads(args.child))))
        return {}
    if args.quick:
        args.n_max, args.n_max_coupled, args.avalanche_n = 1000, 300, [100]
    started = time.perf_counter()
    grid = [100, 300, 1000, 3000, 10_000, 30_000, 100_000, 300_000, 1_000_000]
    report = {"machine": platform.processor() or platform.machine(), "python": platform.python_version(),
              "command": " ".join(["scaling.py"] + (argv if argv is not None else sys.argv[1:])),
              "dt": args.dt, "alpha_stop_value": args.alpha_stop}
    titles = {"alpha_stop": f"tilt to alpha_max={args.alpha_stop}",
              "avalanche": "tilt to the avalanche (max_event_duration=1e5 tau)",
              "explore_avalanche": "tilt to the avalanche in the explore mode (dt = 1e-2)"}
    for part in args.parts:
        say(f"\n=== {part}: {titles[part]} ===")
        rows = []
        dt = EXPLORE_DT if part == "explore_avalanche" else args.dt
        for xi in (0.0, 0.001):
            if part == "alpha_stop":
                ns = [n for n in grid if n <= (args.n_max if xi == 0.0 else args.n_max_coupled)]
            else:
                ns = args.avalanche_n if part == "avalanche" else args.explore_n
            for n in ns:
                for seed in (range(3) if n <= 1000 else range(1)):
                    r = run_child(n, xi, seed, args.alpha_stop if part == "alpha_stop" else 10.0,
                                  5000.0 if part == "alpha_stop" else 1e5, dt, args.timeout)
                    if r is not None:
                        rows.append(r)
                        say(f"  xi={xi:g} N={n} seed={seed}: {r['status']}, {r['events']} events, "
                            f"cpu {r['cpu_s']:.3f} s, {r['slider_steps']:.3g} slider-steps")
        agg = aggregate(rows)
        say("")
        table(agg)
        if part != "alpha_stop":
            say("\nslip fronts: the longest event lasts ~c N tau, and one front crossing the chain "
                "costs >= N^2 / (4 dt) slider-steps")
            for m in agg:
                bound = m["n"] ** 2 / (4 * dt)
                say(f"  xi={m['xi']:g} N={m['n']}: longest event {m['longest_tau_per_n']:.2f} N tau; "
                    f"slider-steps {m['slider_steps'] / bound:.1f} x N^2/(4 dt)")
        report[part] = {"rows": rows, "aggregate": agg, "fits": fits(agg)}
    report["total_wall_s"] = time.perf_counter() - started
    out_dir = Path(args.out_dir)
    suffix = "_quick" if args.quick else ""
    if set(args.parts) != {"alpha_stop", "avalanche", "explore_avalanche"}:
        # a partial run adds its parts to the stored report
        stored_path = out_dir / f"scaling{suffix}.json"
        stored = json.loads(stored_path.read_text()) if stored_path.exists() else {}
        report = {**stored, **{k: v for k, v in report.items() if k in args.parts},
                  "partial_command": report["command"]}
        suffix += "_" + "_".join(args.parts)
    say(f"\ntotal {time.perf_counter() - started:.0f} s")
    out_dir.mkdir(parents=True, exist_ok=True)
    json_name = "scaling_quick.json" if args.quick else "scaling.json"
    (out_dir / json_name).write_text(json.dumps(report, indent=1))
    (out_dir / f"scaling{suffix}.txt").write_text(OUT.getvalue())
    if "alpha_stop" in report and "avalanche" in report:
        figure(report, out_dir / f"scaling{'_quick' if args.quick else ''}.png")
    print(f"written {out_dir}/{json_name} and scaling{suffix}.txt")
    return report


if __name__ == "__main__":
    main()
