"""What the two commands cost: the set-up's steps and the test suite's slowest tests.

    .venv/bin/python benchmarks/suite_cost.py                 # this checkout, as it is set up
    .venv/bin/python benchmarks/suite_cost.py --fresh-clone   # a clone of HEAD with a new .venv
    .venv/bin/python benchmarks/suite_cost.py --fast          # the fast loop (-m "not slow") only

Runs ``bash scripts/setup.sh`` (in a fresh clone of HEAD with ``--fresh-clone``: a new virtual
environment and build, the machine's Debian packages, pip's cache and the h5py wheel cache as
they are; ``--cold-wheels`` also empties the wheel cache and pip's for that run), reads the seconds of each
step from its summary, then runs the suite there the way the README's test command does
(``pytest -n <cores>``, or the fast loop) with a JUnit report, and reads each test's seconds
(setup + call + teardown) from it, and where the cores' time went (``SLIDERS_TEST_TIMELINE``:
tests/conftest.py records each test's CPU and its waits for one core or for both).  Prints the
steps, the totals, the core use and the slowest tests, and
writes them to ``benchmarks/results/suite_cost.json`` (``--out`` to change).  Wall-clock seconds
on a possibly shared machine: compare figures of one run, and state the load beside them.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STEP = re.compile(r"^  (\S.*?)\s+(\d+)s$")


def timed(cmd, cwd, env):
    start = time.monotonic()
    res = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    return res, time.monotonic() - start


def setup_steps(stdout: str) -> list[dict]:
    """The summary lines of scripts/setup.sh: what each step did and its seconds."""
    return [{"step": m[1], "s": int(m[2])} for m in map(STEP.match, stdout.splitlines()) if m]


def slowest_tests(junit: Path, count: int) -> tuple[list[dict], int]:
    cases = [{"test": f"{c.get('classname')}::{c.get('name')}", "s": float(c.get("time", 0))}
             for c in ET.parse(junit).getroot().iter("testcase")]
    return sorted(cases, key=lambda c: -c["s"])[:count], len(cases)


def core_use(timeline: Path, suite_s: float, count: int) -> dict:
    """Where the cores' time went (tests/conftest.py writes one record per test under xdist):
    CPU of the tests, waiting for a core or for both, holding both."""
    tests = [json.loads(line) for line in timeline.read_text().splitlines()]
    waits = sorted(tests, key=lambda t: -t["waited_both"])[:count]
    return {"available_s": round(suite_s * (os.cpu_count() or 1), 1),
            "cpu_s": round(sum(t["cpu"] for t in tests), 1),
            "waiting_for_one_s": round(sum(t["waited_one"] for t in tests), 1),
            "waiting_for_both_s": round(sum(t["waited_both"] for t in tests), 1),
            "holding_both_s": round(sum(t["end"] - t["start"] - t["waited_both"] - t["waited_one"]
                                        for t in tests if t["both_cores"]), 1),
            "longest_waits_for_both": [{"test": t["test"], "waited_both": round(t["waited_both"], 1)}
                                       for t in waits if t["waited_both"] > 0]}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fresh-clone", action="store_true", help="set up a clone of HEAD from scratch")
    p.add_argument("--cold-wheels", action="store_true",
                   help="with --fresh-clone: empty h5py wheel and pip caches (h5py is built)")
    p.add_argument("--fast", action="store_true", help='the fast loop: -m "not slow"')
    p.add_argument("--slowest", type=int, default=25, help="how many of the slowest tests to list")
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "suite_cost.json")
    args = p.parse_args()

    env = {k: v for k, v in os.environ.items() if not k.startswith(("VIRTUAL_ENV", "PYTHON"))}
    scratch = Path(tempfile.mkdtemp(prefix="sliders-suite-cost-"))
    where = ROOT
    if args.fresh_clone:
        where = scratch / "sliders"
        subprocess.run(["git", "clone", "-q", str(ROOT), str(where)], check=True)
        if args.cold_wheels:  # pip's own cache would hand back the wheel it built last time
            env["SLIDERS_WHEEL_CACHE"] = str(scratch / "wheels")
            env["PIP_CACHE_DIR"] = str(scratch / "pip-cache")
    target = "fast" if args.fast else "test"
    load_before = os.getloadavg()
    try:
        setup, setup_s = timed(["bash", "scripts/setup.sh"], where, env)
        if setup.returncode != 0:
            sys.exit(f"suite_cost: set-up failed:\n{setup.stderr[-2000:]}")
        junit = scratch / "junit.xml"
        timeline = scratch / "timeline.jsonl"
        suite, suite_s = timed(["bash", "scripts/setup.sh", target, "-p", "no:cacheprovider",
                                f"--junitxml={junit}", "-o", "junit_duration_report=total"],
                               where, dict(env, SLIDERS_TEST_TIMELINE=str(timeline)))
        tail = suite.stdout.strip().splitlines()[-1:] or ["(no output)"]
        slow, n_tests = slowest_tests(junit, args.slowest) if junit.exists() else ([], 0)
        cores = core_use(timeline, suite_s, args.slowest) if timeline.exists() else {}
    finally:  # the clone, the cold wheel cache and the JUnit report
        shutil.rmtree(scratch, ignore_errors=True)
    report = {
        "checkout": "fresh clone of HEAD" if args.fresh_clone else str(ROOT),
        "wheel_cache": "empty" if args.cold_wheels else "as on this machine",
        "target": f"scripts/setup.sh {target}", "cores": os.cpu_count(),
        "load_average_before": load_before,
        "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "setup_s": round(setup_s, 1), "setup_steps": setup_steps(setup.stdout),
        "suite_s": round(suite_s, 1), "suite_exit": suite.returncode, "suite_summary": tail[0],
        "tests": n_tests, "slowest": slow, "cores_used": cores,
    }
    print(f"set-up {setup_s:.0f} s ({report['checkout']}, wheel cache {report['wheel_cache']})")
    for s in report["setup_steps"]:
        print(f"  {s['s']:5d} s  {s['step']}")
    print(f"suite  {suite_s:.0f} s, exit {suite.returncode}: {tail[0]}")
    print(f"total  {setup_s + suite_s:.0f} s")
    print(f"slowest {len(slow)} of {n_tests} tests (setup + call + teardown):")
    for c in slow:
        print(f"  {c['s']:7.1f} s  {c['test']}")
    if cores:
        print(f"core-seconds: {cores['available_s']:.0f} available, {cores['cpu_s']:.0f} of CPU in "
              f"the tests, {cores['waiting_for_one_s']:.0f} waiting for a core, "
              f"{cores['waiting_for_both_s']:.0f} waiting for both; "
              f"{cores['holding_both_s']:.0f} s of wall time with both cores held by one test")
        print("tests that waited longest for both cores:")
        for c in cores["longest_waits_for_both"]:
            print(f"  {c['waited_both']:7.1f} s  {c['test']}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1) + "\n")
    print(f"written: {args.out}")
    sys.exit(0 if suite.returncode == 0 else 1)


if __name__ == "__main__":
    main()
