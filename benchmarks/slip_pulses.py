"""Cost of resolving the slow slip pulses: every realisation run to its true end.

Realisations of an ensemble scene (seed of realisation r as in
``sliders.ensemble``) run to their end with the long event cap
(``--long-cap``, default: the scene mode's ``max_event_duration``) and,
where an event lasted longer than the short cap, again with the short cap
(``--short-cap``, 1e5 tau, which stops the slowest slip pulses unfinished).
A run whose events all end within the short cap is the same run under both
caps (same events, same work), so the extra cost of the long cap is carried
by those "pulse" realisations alone.

Work is counted in slider-steps (deterministic: one slider advanced by one
time step) and in CPU seconds (this process; noisy on a shared machine).

* ``--realisations R --sample K``: K realisations drawn at random (``--seed``)
  plus ``--include`` (the pulse realisations known from a full scan).  The short
  cap's cost of the whole study is R x the mean of the random sample; the extra cost
  is the sum over the included pulse realisations (exact if the list of pulse
  realisations is complete, which only a full scan establishes).
* ``--sample 0`` (default) runs all R realisations: exact totals.

Rows are cached in ``--rows`` (JSON lines, one per realisation and cap) so a
long scan can be run in pieces.  Prints its table and writes
``benchmarks/results/slip_pulses_<scene>.{json,txt}``.

Usage: python benchmarks/slip_pulses.py --scene mpi_runs/scenes/study_n400_xi0.toml \
           --realisations 1000 [--sample 40 --include 3 29 ...] [--rows rows.jsonl]
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import random
import time
from pathlib import Path

import numpy as np

import sliders
from sliders import Scene
from sliders.keyed_random import realisation_seed

RESULTS = Path(__file__).parent / "results"
SHORT_CAP = 1e5  # tau: a cap that the slowest slip pulses outlast


def run_row(base: Scene, r: int, cap: float) -> dict:
    """One realisation to its end with event cap ``cap``: what it cost, how it ended."""
    scene = base.replace(seed=realisation_seed(base.seed, r), record="summary",
                         max_event_duration=cap)
    start = time.process_time()
    result = sliders.tilt(scene)
    cpu = time.process_time() - start
    durations = np.append(result.events["duration"], result.final_event.get("duration", 0.0))
    alphas = np.append(result.alpha, result.alpha_c if result.n_events else math.nan)
    k = int(np.argmax(durations))
    return {
        "r": r, "seed": scene.seed, "cap": cap, "status": result.status,
        "alpha_c": result.alpha_c, "n_events": int(result.n_events), "cpu": cpu,
        "slider_steps": int(result.total_slider_steps),
        "longest_event": float(durations[k]), "longest_event_alpha": float(alphas[k]),
        "last_alpha": float(result.alpha[-1]) if result.n_events else math.nan,
    }


def load_rows(path: Path | None) -> dict[tuple[int, float], dict]:
    rows = {}
    if path is not None and path.exists():
        for line in path.read_text().splitlines():
            row = json.loads(line)
            rows[(row["r"], row["cap"])] = row
    return rows


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="mpi_runs/scenes/study_n400_xi0.toml")
    parser.add_argument("--realisations", type=int, default=1000)
    parser.add_argument("--sample", type=int, default=0,
                        help="random realisations to run (0: all of them)")
    parser.add_argument("--seed", type=int, default=16, help="of the random sample")
    parser.add_argument("--include", type=int, nargs="*", default=[],
                        help="realisations known to hold an event longer than the short cap")
    parser.add_argument("--short-cap", type=float, default=SHORT_CAP)
    parser.add_argument("--long-cap", type=float, default=None,
                        help="default: the scene's max_event_duration")
    parser.add_argument("--rows", default=None, help="JSON-lines cache of finished runs")
    parser.add_argument("--study-realisations", type=int, default=None,
                        help="size of the whole study when --realisations runs only its first R "
                             "(seeds are hashed: the first R are a random sample)")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)

    base = Scene.from_toml(args.scene)
    long_cap = base.max_event_duration if args.long_cap is None else args.long_cap
    name = Path(args.scene).stem
    rows_path = Path(args.rows) if args.rows else None
    cache = load_rows(rows_path)

    R = args.realisations
    if args.sample:
        sample = sorted(random.Random(args.seed).sample(range(R), args.sample))
    else:
        sample = list(range(R))
    todo = sorted(set(sample) | set(args.include))

    def row(r, cap):
        if (r, cap) not in cache:
            cache[(r, cap)] = run_row(base, r, cap)
            if rows_path is not None:
                with rows_path.open("a") as fh:
                    fh.write(json.dumps(cache[(r, cap)]) + "\n")
        return cache[(r, cap)]

    long = {r: row(r, long_cap) for r in todo}
    # a run whose events all end within the short cap is the same run under both caps
    pulses = [r for r in todo if long[r]["longest_event"] > args.short_cap]
    short = {r: (row(r, args.short_cap) if r in pulses else long[r]) for r in todo}

    unresolved = [r for r in todo if long[r]["status"] != "avalanche"]
    capped_short = [r for r in todo if short[r]["status"] == "event_duration_cap"]
    missed = sorted(set(pulses) - set(args.include)) if args.sample else []
    scale = R / len(sample)
    totals = {}
    for unit in ("cpu", "slider_steps"):
        short_total = scale * sum(short[r][unit] for r in sample)
        extra = sum(long[r][unit] - short[r][unit] for r in pulses)
        totals[unit] = {"short_cap": short_total, "extra": extra,
                        "extra_fraction": extra / short_total}

    lines = []

    def say(text):
        print(text)
        lines.append(text)

    say(f"{name}: {len(todo)} of {R} realisations run ({'all' if not args.sample else f'random sample of {len(sample)} + {len(args.include)} included'}); "
          f"short cap {args.short_cap:g} tau, long cap {long_cap:g} tau")
    say(f"{'r':>5} {'seed':>11} {'tan a - mu_d':>13} {'longest event':>14} {'status short':>20} "
          f"{'alpha_c long':>12} {'CPU short':>9} {'CPU long':>8} {'steps short':>12} {'steps long':>12}")
    for r in pulses:
        o, n = short[r], long[r]
        say(f"{r:5d} {n['seed']:11d} {math.tan(n['longest_event_alpha']) - base.mu_d:13.2e} "
              f"{n['longest_event']:10.4g} tau {o['status']:>20} {n['alpha_c']:12.6f} "
              f"{o['cpu']:9.2f} {n['cpu']:8.2f} {o['slider_steps']:12.4g} {n['slider_steps']:12.4g}")
    for unit, t in totals.items():
        how = "sum over all" if not args.sample else f"{scale:g} x sum over the random sample"
        say(f"{unit:>12}: short cap {t['short_cap']:.4g} ({how}), extra {t['extra']:.4g} "
              f"(pulse realisations) = {100 * t['extra_fraction']:+.1f} %")
    if args.study_realisations:
        say(f"the first {R} of the {args.study_realisations} realisations of the study: a random "
            f"sample, so the extra fraction above is the estimate for the whole study")
    say(f"capped by the short cap: {len(capped_short)} {capped_short}; still unresolved with the long cap: "
          f"{len(unresolved)} {unresolved}")
    if missed:
        say(f"warning: pulse realisations of the random sample not in --include: {missed}")

    report = {
        "scene": args.scene, "realisations": R,
        "study_realisations": args.study_realisations or R, "sample": sample if args.sample else "all",
        "include": args.include, "short_cap": args.short_cap, "long_cap": long_cap,
        "pulses": [{"long_cap": long[r], "short_cap": short[r]} for r in pulses],
        "capped_short": capped_short, "unresolved": unresolved, "totals": totals,
        "missed_pulses": missed, "machine": platform.node(),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }
    out = Path(args.out) if args.out else RESULTS / f"slip_pulses_{name}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1) + "\n")
    out.with_suffix(".txt").write_text("\n".join(lines) + "\n")
    print(f"-> {out}, {out.with_suffix('.txt')}")
    return report


if __name__ == "__main__":
    main()
