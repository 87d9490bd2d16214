"""Speed of two checkouts of sliders on the same scenes, interleaved (A/B).

A change that must not cost speed (a new seam, a new loading) is measured
against the code before it in one run: each checkout's own Python (its
``.venv``) runs the N = 400 scenes to the avalanche, alternately A, B, A, B,
so that the machine's load hits both alike.  Reported: CPU seconds per scene
(best of ``--repeat``), ns per slider-step, and the ratio B/A; the events of
both must be the same (same count and alpha_c), else the comparison is void.

Usage:
    python benchmarks/ab_speed.py --a /path/to/old/checkout [--b .] [--repeat 3]

Writes benchmarks/results/ab_speed.json.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

RESULTS = Path(__file__).parent / "results"
SCENES = [(0.0, 0), (0.0, 1), (0.001, 0), (0.001, 1)]  # (xi, seed), N = 400, dt = 1e-3

# One timed run in the checkout's own interpreter: CPU time of the kernel run.
CHILD = """
import json, sys, time
import sliders
xi, seed = float(sys.argv[1]), int(sys.argv[2])
scene = sliders.Scene(n_sliders=400, xi=xi, seed=seed, record="summary")
sliders.tilt(scene.replace(max_events=5))   # import and build outside the timing
start = time.process_time()
result = sliders.tilt(scene)
cpu = time.process_time() - start
print(json.dumps({"cpu_s": cpu, "status": result.status, "alpha_c": result.alpha_c,
                  "n_events": result.n_events,
                  "slider_steps": int(result.total_slider_steps)}))
"""


def python_of(checkout: Path) -> Path:
    """The interpreter of a checkout set up by scripts/setup.sh."""
    python = checkout / ".venv" / "bin" / "python"
    if not python.exists():
        sys.exit(f"ab_speed: {python} not found (run bash scripts/setup.sh in {checkout})")
    return python


def run_once(python: Path, xi: float, seed: int) -> dict:
    out = subprocess.run([str(python), "-c", CHILD, str(xi), str(seed)], check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--a", type=Path, required=True, help="checkout A (before)")
    parser.add_argument("--b", type=Path, default=Path(__file__).resolve().parents[1],
                        help="checkout B (after; default: this one)")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    pythons = {"a": python_of(args.a.resolve()), "b": python_of(args.b.resolve())}
    rows = []
    print(f"{'scene':>16} {'A cpu s':>8} {'B cpu s':>8} {'A ns/ss':>8} {'B ns/ss':>8} {'B/A':>6}")
    for xi, seed in SCENES:
        best: dict[str, dict] = {}
        for _ in range(args.repeat):
            for side, python in pythons.items():  # interleaved: A, B, A, B, ...
                run = run_once(python, xi, seed)
                if side not in best or run["cpu_s"] < best[side]["cpu_s"]:
                    best[side] = run
        a, b = best["a"], best["b"]
        same = (a["n_events"], a["alpha_c"], a["slider_steps"]) == \
            (b["n_events"], b["alpha_c"], b["slider_steps"])
        row = {"xi": xi, "seed": seed, "a": a, "b": b, "same_events": same,
               "ratio_b_over_a": b["cpu_s"] / a["cpu_s"]}
        rows.append(row)
        ns = [1e9 * r["cpu_s"] / r["slider_steps"] for r in (a, b)]
        print(f"{f'xi={xi:g} seed={seed}':>16} {a['cpu_s']:8.3f} {b['cpu_s']:8.3f} "
              f"{ns[0]:8.3f} {ns[1]:8.3f} {row['ratio_b_over_a']:6.3f}"
              + ("" if same else "  EVENTS DIFFER: comparison void"))
    report = {"command": "python benchmarks/ab_speed.py " + " ".join(argv or sys.argv[1:]),
              "a": str(args.a.resolve()), "b": str(args.b.resolve()),
              "repeat": args.repeat, "rows": rows}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "ab_speed.json").write_text(json.dumps(report, indent=1))
    print(f"-> {RESULTS / 'ab_speed.json'}")
    return report


if __name__ == "__main__":
    main()
