"""Stop a loop of short tilts by a signal at random moments, and count how it stopped.

A Python script loops over 1000 tilts of 200 sliders (about 0.2 s each), with SIGTERM
turned into KeyboardInterrupt as a script that wants it to stop like Ctrl-C does. Each trial
starts it, waits a random time, sends the signal and sorts the outcome:

* ``interrupted``: ``sliders.Interrupted`` with its completed events, within 2 s;
* ``bare``: another traceback (a ``KeyboardInterrupt`` that left ``tilt`` without them);
* ``slow``: stopped, but after 2 s;
* ``running``: still running 10 s after the signal (the interrupt was forgotten).

Usage: ``python scripts/interrupt_trials.py [--trials 150] [--signal TERM|INT] [--out F]``.
Prints one line per outcome class and writes them as JSON to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

LOOP = """import signal
signal.signal(signal.SIGTERM, signal.default_int_handler)
import sliders
scenes = [sliders.Scene(n_sliders=200, seed=seed, mode="explore") for seed in range(1000)]
print("started", flush=True)
for scene in scenes:
    sliders.tilt(scene)
print("loop ended", flush=True)
"""
STOP_WITHIN = 2.0  # s, as the reliability tests ask
GIVE_UP = 10.0  # s after the signal: the interrupt was forgotten


def trial(script: Path, sig: int, delay: float) -> tuple[str, str]:
    """(outcome, the last line of standard error) of one stopped loop."""
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        proc.stdout.readline()
        time.sleep(delay)
        sent = time.monotonic()
        proc.send_signal(sig)
        try:
            _, err = proc.communicate(timeout=GIVE_UP)
        except subprocess.TimeoutExpired:
            return "running", ""
        took = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    last = (err.strip().splitlines() or [""])[-1]
    if "Interrupted" not in last or "completed events" not in last:
        return "bare", last
    return ("interrupted" if took < STOP_WITHIN else "slow"), last


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=150)
    parser.add_argument("--signal", choices=("TERM", "INT"), default="TERM")
    parser.add_argument("--seed", type=int, default=1, help="of the random delays")
    parser.add_argument("--out", type=Path, default=Path("interrupt_trials.json"))
    args = parser.parse_args(argv)
    sig = signal.Signals[f"SIG{args.signal}"]
    rng = random.Random(args.seed)
    counts = {"interrupted": 0, "bare": 0, "slow": 0, "running": 0}
    examples: dict[str, str] = {}
    with tempfile.TemporaryDirectory() as folder:
        script = Path(folder) / "loop.py"
        script.write_text(LOOP)
        for k in range(args.trials):
            outcome, last = trial(script, sig, rng.uniform(0.3, 1.5))
            counts[outcome] += 1
            examples.setdefault(outcome, last)
            print(f"\r{k + 1}/{args.trials} trials", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    for outcome, n in counts.items():
        print(f"{outcome:12s} {n:4d} of {args.trials}   {examples.get(outcome, '')[:80]}")
    args.out.write_text(json.dumps({"signal": sig.name, "trials": args.trials,
                                    "counts": counts, "examples": examples}, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0 if counts["interrupted"] == args.trials else 1


if __name__ == "__main__":
    sys.exit(main())
