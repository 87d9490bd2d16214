"""Bit-for-bit fingerprints of Fortran-kernel runs: the check that a rewrite changes no result.

A rewrite of the kernel meant to be exact (faster code, procedures split or merged) must
leave the events identical bit for bit.
This script runs a fixed set of scenes (N = 10/100/400, xi = 0 and 0.001, a
chain between walls, a strongly coupled relaxation, a capped event) and hashes
every event array, the recorded displacements, the final state and the run's
end (status, alpha_c, final event).

    python benchmarks/fingerprint.py --store    # before a change
    python benchmarks/fingerprint.py            # after: compare, exit 1 on a difference

The stored file is benchmarks/results/fingerprint.json.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

import sliders
from sliders import Scene

STORE = Path(__file__).parent / "results" / "fingerprint.json"

SCENES = {
    "n10_xi0": Scene(n_sliders=10, seed=0, record="displacements"),
    "n10_xi0.001": Scene(n_sliders=10, xi=0.001, seed=3, record="displacements"),
    "n100_xi0": Scene(n_sliders=100, seed=1, record="displacements"),
    "n100_xi0.001": Scene(n_sliders=100, xi=0.001, seed=2, record="displacements"),
    "n400_xi0": Scene(n_sliders=400, seed=0, record="displacements"),
    "n400_xi0.001": Scene(n_sliders=400, xi=0.001, seed=1, record="displacements"),
    "n400_xi0.001_summary": Scene(n_sliders=400, xi=0.001, seed=0, record="summary"),
    "walls_n30": Scene(n_sliders=30, ends="walls", seed=4, alpha_max=0.9,
                       record="displacements"),
    "relax_xi0.2": Scene(n_sliders=200, xi=0.2, seed=5, max_events=20,
                         record="displacements"),
    "capped_n100": Scene(n_sliders=100, seed=6, max_event_duration=20.0,
                         record="displacements"),
}


def fingerprint(result: sliders.Result) -> str:
    """sha256 over everything a run produced, as raw bytes."""
    digest = hashlib.sha256()
    digest.update(f"{result.status}|{result.message}|{result.alpha_c!r}".encode())
    digest.update(json.dumps(result.final_event, sort_keys=True).encode())
    digest.update(json.dumps(result.relaxation, sort_keys=True).encode())
    for name in sorted(result.events):
        digest.update(name.encode())
        digest.update(np.ascontiguousarray(result.events[name]).tobytes())
    if result.displacement is not None:
        for array in (result.displacement.ptr, result.displacement.index,
                      result.displacement.value):
            digest.update(np.ascontiguousarray(array).tobytes())
    for state in (result.initial, result.final):
        for array in (state.displacement, state.mu_s, state.n_stops):
            digest.update(np.ascontiguousarray(array).tobytes())
        digest.update(repr(state.drive).encode())
    return digest.hexdigest()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--store", action="store_true", help="write the fingerprints")
    parser.add_argument("--only", nargs="*", help="run only these scenes")
    args = parser.parse_args(argv)
    names = args.only or list(SCENES)
    unknown = sorted(set(names) - set(SCENES))
    if unknown:
        parser.error(f"unknown scene(s) {unknown}; known: {sorted(SCENES)}")
    stored = json.loads(STORE.read_text()) if STORE.exists() else {}
    if not args.store and not stored:
        parser.error(f"no stored fingerprints in {STORE}: run with --store first")
    current, differ = {}, []
    for name in names:
        start = time.process_time()
        result = sliders.tilt(SCENES[name])
        current[name] = fingerprint(result)
        same = stored.get(name) == current[name]
        if not args.store and not same:
            differ.append(name)
        print(f"{name:22s} {result.status:20s} {result.n_events:5d} events "
              f"{time.process_time() - start:6.2f} s  {current[name][:16]}"
              f"{'' if args.store else ('  same' if same else '  DIFFERENT')}")
    if args.store:
        STORE.parent.mkdir(parents=True, exist_ok=True)
        STORE.write_text(json.dumps({**stored, **current}, indent=1, sort_keys=True) + "\n")
        print(f"stored in {STORE}")
        return 0
    print("all identical" if not differ else f"DIFFERENT: {differ}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
