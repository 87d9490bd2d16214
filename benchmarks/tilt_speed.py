"""Speed of the two backends on the paper's N = 400 scenes.

For each scene (N = 400, xi = 0 and 0.001, dt = 1e-3):

* both backends run the same first ``--prefix-events`` rearrangements (the
  NumPy reference is far too slow to reach the avalanche), which gives the
  speed-up as a ratio measured in one run on identical work (the events are
  checked to be the same);
* the Fortran kernel then runs the whole scene to the avalanche: wall time,
  events, integration steps, slider-steps and slider-steps per second;
* then each scene runs to the avalanche in the coarser speed modes
  (``--modes``, default sketch, explore, statistics): wall time and alpha_c.

Prints a table and writes ``benchmarks/results/tilt_speed.json``.
Usage: python benchmarks/tilt_speed.py [--prefix-events 40] [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

import sliders
from sliders import Scene

RESULTS = Path(__file__).parent / "results"


def timed(scene, backend):
    start = time.perf_counter()
    result = sliders.tilt(scene, backend=backend)
    return result, time.perf_counter() - start


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-sliders", type=int, default=400)
    parser.add_argument("--prefix-events", type=int, default=40)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--modes", nargs="*", default=["sketch", "explore", "statistics"],
                        help="also run every scene to the avalanche in these speed modes")
    parser.add_argument("--out", default=str(RESULTS / "tilt_speed.json"))
    args = parser.parse_args(argv)

    rows = []
    for xi in (0.0, 0.001):
        for seed in args.seeds:
            scene = Scene(n_sliders=args.n_sliders, xi=xi, seed=seed, dt=1e-3)
            prefix = scene.replace(max_events=args.prefix_events)
            ref, t_numpy = timed(prefix, "numpy")
            fast, t_fortran_prefix = timed(prefix, "fortran")
            same = (ref.n_events == fast.n_events
                    and np.allclose(ref.alpha, fast.alpha, rtol=0, atol=1e-9)
                    and (ref.n_moved == fast.n_moved).all())
            full, t_full = timed(scene, "fortran")
            steps = int(full.n_steps.sum()) + int(full.final_event.get("n_steps", 0))
            work = full.total_slider_steps  # relaxation + events + the avalanche event
            rows.append({
                "xi": xi, "seed": seed,
                "prefix_events": prefix.max_events,
                "prefix_slider_steps": int(ref.slider_steps.sum()),
                "numpy_prefix_s": t_numpy, "fortran_prefix_s": t_fortran_prefix,
                "speedup": t_numpy / t_fortran_prefix, "prefix_events_identical": bool(same),
                "fortran_full_s": t_full, "status": full.status, "alpha_c": full.alpha_c,
                "events": full.n_events, "steps": steps, "slider_steps": work,
                "slider_steps_per_s": work / t_full,
            })
            r = rows[-1]
            print(f"xi={xi:<6g} seed={seed}  numpy/fortran on {r['prefix_events']} events: "
                  f"{r['numpy_prefix_s']:.2f} s / {r['fortran_prefix_s']:.4f} s = x{r['speedup']:.0f}"
                  f"{'' if same else ' (EVENTS DIFFER)'}  |  fortran to avalanche: {t_full:.3f} s, "
                  f"{r['events']} events, {steps:.3g} steps, {work:.3g} slider-steps, "
                  f"{r['slider_steps_per_s']:.3g} slider-steps/s, alpha_c={full.alpha_c:.4f}",
                  flush=True)

    mode_rows = []
    if args.modes:
        print(f"\nto the avalanche by speed mode (N={args.n_sliders}; wall s, alpha_c):")
    for mode in args.modes:
        line = []
        for xi in (0.0, 0.001):
            for seed in args.seeds:
                scene = Scene(n_sliders=args.n_sliders, xi=xi, seed=seed, mode=mode)
                run, t = timed(scene, "fortran")
                mode_rows.append({"mode": mode, "dt": scene.dt, "xi": xi, "seed": seed, "wall_s": t,
                                  "status": run.status, "alpha_c": run.alpha_c,
                                  "events": run.n_events, "slider_steps": run.total_slider_steps})
                line.append(f"xi={xi:g}/{seed}: {t:.2f} s ({run.alpha_c:.4f})")
        walls = [r["wall_s"] for r in mode_rows if r["mode"] == mode]
        print(f"  {mode:<10s} dt={Scene(mode=mode).dt:<6g} max {max(walls):.2f} s | " + ", ".join(line),
              flush=True)

    summary = {
        "machine": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "n_sliders": args.n_sliders,
        "dt": 1e-3,
        "rows": rows,
        "modes": mode_rows,
        "median_speedup": float(np.median([r["speedup"] for r in rows])),
        "max_full_s": float(max(r["fortran_full_s"] for r in rows)),
        "median_slider_steps_per_s": float(np.median([r["slider_steps_per_s"] for r in rows])),
    }
    print(f"\nmedian speed-up fortran/numpy: x{summary['median_speedup']:.0f}; "
          f"slowest N={args.n_sliders} scene to the avalanche: {summary['max_full_s']:.3f} s; "
          f"median {summary['median_slider_steps_per_s']:.3g} slider-steps/s")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(summary, indent=2))
    print(f"written {out}")
    return summary


if __name__ == "__main__":
    main()
