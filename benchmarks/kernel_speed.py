"""The kernel against the machine's limit, measured in one run.

1. Builds benchmarks/verlet_baseline.c (gcc -O3 -march=native, IEEE) into a
   temporary folder and runs it: the fused velocity-Verlet loop over 250
   contiguous sliders, ns per slider-step (best of --repeat).
2. Runs the paper's four N = 400 scenes (xi = 0 and 0.001, seeds 0 and 1) to
   the avalanche at dt = 1e-3 on the Fortran kernel,
   ``sliders.tilt(Scene(n_sliders=400, xi=..., seed=..., record="summary"))``:
   CPU time (time.process_time, best of --repeat) divided by
   result.total_slider_steps.
3. Prints the kernel's ns per slider-step and its ratio to the baseline, and
   writes them to benchmarks/results/kernel_speed.json (under --label, so a
   "before" and an "after" measurement can sit side by side).
4. The same work for the baseline: the kernel's steps do not move 250
   sliders.  Most move a few (the median step of these runs moves ~10, the
   mean is 20-50), and a loop's cost per step has a fixed part (loop set-up,
   the remainder of the 8-wide vector loop) that 250 sliders hide and 10 do
   not.  So the baseline is also timed at m = 1 ... 400 sliders (ns per step
   T(m), interpolated), and each event of the scene is charged its steps at
   its mean movers per step m_e = slider_steps / n_steps:
       matched baseline = sum_e n_steps_e T(m_e) / sum_e slider_steps_e,
   the machine's limit for the steps the kernel really took (the movers of
   an event vary about m_e; T is nearly linear in m, so the error is small).
   The ratio to it is printed beside the ratio to the 250-slider loop.

With --reference PYTHON (the interpreter of another installation of
sliders, e.g. a checkout of the code before a change) that build is
measured in the same run, scene by scene alternating with this one, against
the same baseline, and stored under --reference-label: a before/after
comparison that the machine's drift between two runs cannot fake.  Every
measurement runs in a fresh process (the same for both builds).

Usage: python benchmarks/kernel_speed.py [--label after] [--repeat 2]
           [--reference /path/to/other/python --reference-label before]
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).parent
RESULTS = HERE / "results"
BASELINE_SOURCE = HERE / "verlet_baseline.c"


# movers per step at which the baseline's cost per step is measured (the
# kernel's events have means from 1 to ~400 on N = 400)
BASELINE_MOVERS = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 400)


def build_baseline(folder: Path) -> Path:
    """benchmarks/verlet_baseline.c built with gcc -O3 -march=native into ``folder``."""
    compiler = shutil.which("gcc") or shutil.which("cc")
    if compiler is None:
        sys.exit("kernel_speed: no C compiler (gcc) found to build the baseline")
    exe = folder / "verlet_baseline"
    subprocess.run([compiler, "-O3", "-march=native", "-o", str(exe), str(BASELINE_SOURCE)],
                   check=True)
    return exe


def baseline_ns(exe: Path, repeat: int, n_sliders: int = 250,
                slider_steps: float = 1e8) -> float:
    """Best ns per slider-step of the C baseline over ``n_sliders`` contiguous sliders."""
    steps = max(1, int(slider_steps / n_sliders))
    best = float("inf")
    for _ in range(repeat):
        out = subprocess.run([str(exe), str(n_sliders), str(steps)], check=True,
                             capture_output=True, text=True).stdout
        best = min(best, float(out.split()[1]))
    return best


def baseline_per_step(exe: Path, repeat: int) -> dict:
    """The baseline's ns per step T(m) at the movers BASELINE_MOVERS."""
    return {m: m*baseline_ns(exe, repeat, m, 2e7) for m in BASELINE_MOVERS}


def matched_baseline_ns(per_step: dict, steps_by_movers: dict) -> float:
    """ns per slider-step of the baseline doing the kernel's steps (see 4. above)."""
    import numpy as np

    movers = np.array(sorted(per_step), dtype=float)
    cost = np.array([per_step[m] for m in sorted(per_step)])
    m = np.array([float(k) for k in steps_by_movers])
    steps = np.array(list(steps_by_movers.values()), dtype=float)
    return float((steps*np.interp(m, movers, cost)).sum()/(steps*m).sum())


# One scene to the avalanche, best CPU time of `repeat` runs, in the process
# of the interpreter given (so that another build can be measured alike).
SCENE_RUN = """
import json, sys, time
import sliders
from sliders import Scene
xi, seed, repeat = float(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
scene = Scene(n_sliders=400, xi=xi, seed=seed, record="summary")
best = float("inf")
for _ in range(repeat):
    start = time.process_time()
    result = sliders.tilt(scene)
    best = min(best, time.process_time() - start)
# steps by the mean movers per step of their event (relaxation and final event included)
steps_by_movers = {}
parts = [(result.events["n_steps"], result.events["slider_steps"])]
parts += [([d.get("n_steps", 0)], [d.get("slider_steps", 0)])
          for d in (result.relaxation, result.final_event)]
for n_steps, slider_steps in parts:
    for k, w in zip(n_steps, slider_steps):
        if k > 0:
            key = f"{w/k:.2f}"
            steps_by_movers[key] = steps_by_movers.get(key, 0) + int(k)
print(json.dumps({"status": result.status, "alpha_c": result.alpha_c,
                  "n_events": result.n_events, "slider_steps": result.total_slider_steps,
                  "n_steps": sum(steps_by_movers.values()), "cpu_s": best,
                  "steps_by_movers": steps_by_movers}))
"""


def kernel_row(python: str, xi: float, seed: int, repeat: int) -> dict:
    """Best CPU time of one N = 400 scene to the avalanche, and its work."""
    out = subprocess.run([python, "-c", SCENE_RUN, str(xi), str(seed), str(repeat)],
                         check=True, capture_output=True, text=True).stdout
    row = {"xi": xi, "seed": seed, **json.loads(out.splitlines()[-1])}
    row["ns_per_slider_step"] = 1e9 * row["cpu_s"] / row["slider_steps"]
    return row


def print_rows(title: str, rows: list, base: float, per_step: dict) -> None:
    """The table of one build, ratios to both baselines filled in."""
    print(title)
    print(f"{'scene':26s} {'CPU s':>7s} {'slider-steps':>13s} {'movers/step':>11s} "
          f"{'ns/step':>8s} {'ratio 250':>9s} {'matched ns':>10s} {'ratio matched':>13s}")
    for row in rows:
        row["ratio_to_baseline"] = row["ns_per_slider_step"]/base
        row["mean_movers_per_step"] = row["slider_steps"]/row["n_steps"]
        row["matched_baseline_ns"] = matched_baseline_ns(per_step, row["steps_by_movers"])
        row["ratio_to_matched_baseline"] = row["ns_per_slider_step"]/row["matched_baseline_ns"]
        print(f"N = 400, xi = {row['xi']:<5g} seed {row['seed']}  {row['cpu_s']:7.3f} "
              f"{row['slider_steps']:13.3e} {row['mean_movers_per_step']:11.1f} "
              f"{row['ns_per_slider_step']:8.2f} {row['ratio_to_baseline']:9.2f} "
              f"{row['matched_baseline_ns']:10.2f} {row['ratio_to_matched_baseline']:13.2f}")


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--label", default="current", help="key of this measurement in the json")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--out", default=str(RESULTS / "kernel_speed.json"))
    parser.add_argument("--reference", metavar="PYTHON",
                        help="interpreter of another sliders build, measured in the same run")
    parser.add_argument("--reference-label", default="reference",
                        help="key of the reference build's measurement in the json")
    args = parser.parse_args(argv)
    if args.repeat < 1:
        parser.error("--repeat must be at least 1")
    if args.reference is not None and shutil.which(args.reference) is None:
        parser.error(f"--reference {args.reference!r} is not an executable")
    if args.reference is not None and args.reference_label == args.label:
        parser.error("--reference-label must differ from --label")

    builds = {args.label: sys.executable}
    if args.reference is not None:
        builds[args.reference_label] = args.reference
    with tempfile.TemporaryDirectory() as tmp:
        exe = build_baseline(Path(tmp))
        base = baseline_ns(exe, args.repeat)
        per_step = baseline_per_step(exe, args.repeat)
        rows = {label: [] for label in builds}
        for xi in (0.0, 0.001):
            for seed in (0, 1):
                for label, python in builds.items():     # alternating: the same machine state
                    rows[label].append(kernel_row(python, xi, seed, args.repeat))
        base = min(base, baseline_ns(exe, args.repeat))  # the machine drifts: the better one
        after = baseline_per_step(exe, args.repeat)
        per_step = {m: min(per_step[m], after[m]) for m in per_step}
    print(f"baseline (fused Verlet loop, 250 sliders, gcc -O3 -march=native): {base:.3f} ns "
          "per slider-step")
    print("baseline ns per step at m movers: "
          + ", ".join(f"{m}: {t:.1f}" for m, t in per_step.items()))
    when = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    stored = json.loads(out.read_text()) if out.exists() else {}
    for label, python in builds.items():
        print_rows(f"{label} ({python}):", rows[label], base, per_step)
        for row in rows[label]:   # hundreds of bins: used above, too long to keep
            del row["steps_by_movers"]
        stored[label] = {"baseline_ns_per_slider_step": base,
                         "baseline_ns_per_step_by_movers": per_step, "rows": rows[label],
                         "repeat": args.repeat, "machine": platform.node(), "when": when}
        if label != args.label:
            stored[label]["python"] = python
    if args.reference is not None:
        for new, ref in zip(rows[args.label], rows[args.reference_label]):
            print(f"xi = {new['xi']:<5g} seed {new['seed']}: CPU {args.label} / "
                  f"{args.reference_label} = {new['cpu_s']/ref['cpu_s']:.3f}")
    out.write_text(json.dumps(stored, indent=1) + "\n")
    print(f"written to {out} under {list(builds)}")
    return stored[args.label]


if __name__ == "__main__":
    main()
