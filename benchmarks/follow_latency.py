"""A live forecast at lab pace: ``predict --follow`` on a catalogue that a writer appends to.

    .venv/bin/python benchmarks/follow_latency.py            # about 2 minutes

A writer process appends one event row every ``--pace`` seconds, each in two
writes with a pause between them (a half line on disk, as a slow acquisition
leaves it), while ``python -m sliders.forecast predict FILE --follow --json``
forecasts each new state and the other core is kept busy by a spinning
process.  Measured, from the follower's JSON Lines as they arrive:

* the latency from a row's last byte written (and flushed) to the first
  forecast that holds it: median and 95th percentile (aim: 1 s and 2 s);
* forecasts made from a half-written row: an update whose complete rows
  outnumber the rows whose newline was on disk when it arrived (aim: none of
  ``--rows`` split writes);
* the follower's CPU while the file is idle, in % of one core over
  ``--idle`` seconds (aim: below 2 %);
* its resident memory before and after ``--big`` more rows (written in
  bursts; aim: less than 10 MB of growth).

Prints one JSON line and writes it to benchmarks/results/follow_latency.json.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from forecast_cold_call import accelerating_events, publish  # benchmarks/, beside this one

HERE = os.path.dirname(os.path.abspath(__file__))
SPIN = "while True:\n    pass\n"


def catalogue_rows(n: int, seed: int = 11) -> list[str]:
    """``n`` event rows (``angle [deg],size``) accelerating towards an avalanche near 31°."""
    alpha, size = accelerating_events(n, seed)
    return [f"{a:.6f},{s}\n" for a, s in zip(alpha, size)]


def proc_cpu_seconds(pid: int) -> float:
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def proc_rss_mb(pid: int) -> float:
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


class Updates(threading.Thread):
    """The follower's JSON lines, each with the monotonic time it arrived."""

    def __init__(self, stream):
        super().__init__(daemon=True)
        self.stream, self.lines = stream, []
        self.changed = threading.Condition()

    def run(self):
        for line in self.stream:
            arrived = time.monotonic()
            with self.changed:
                self.lines.append((arrived, json.loads(line)))
                self.changed.notify_all()

    def wait_for(self, rows: int, timeout: float) -> float:
        """The arrival time of the first update holding at least ``rows`` rows."""
        deadline = time.monotonic() + timeout
        with self.changed:
            while True:
                hit = next((t for t, u in self.lines if u["rows"] >= rows), None)
                if hit is not None:
                    return hit
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"no update with {rows} rows in {timeout} s")
                self.changed.wait(left)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", type=int, default=100, help="rows written at lab pace, in halves")
    ap.add_argument("--pace", type=float, default=0.5, help="seconds between rows")
    ap.add_argument("--half-pause", type=float, default=0.1,
                    help="seconds between a row's two writes")
    ap.add_argument("--first", type=int, default=50, help="rows in the file at the start")
    ap.add_argument("--idle", type=float, default=10.0, help="seconds of idle CPU measured")
    ap.add_argument("--big", type=int, default=10_000, help="rows added for the memory figure")
    ap.add_argument("--no-busy", action="store_true", help="leave the other core idle")
    ap.add_argument("--out", default=os.path.join(HERE, "results", "follow_latency.json"))
    args = ap.parse_args(argv)
    rows = catalogue_rows(args.first + args.rows + args.big)
    spinner = None if args.no_busy else subprocess.Popen([sys.executable, "-c", SPIN])
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "live.csv")
        with open(path, "w") as fh:
            fh.write("angle [deg],size\n" + "".join(rows[:args.first]))
        follower = subprocess.Popen([sys.executable, "-m", "sliders.forecast", "predict", path,
                                     "--follow", "--json"],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        updates = Updates(follower.stdout)
        updates.start()
        try:
            started = time.monotonic()
            updates.wait_for(args.first, timeout=120)
            load_s = time.monotonic() - started
            flushed = []  # (monotonic time the row's newline was on disk, rows then complete)
            completed = []  # monotonic time just before each row's newline was written
            with open(path, "a") as fh:
                for k, row in enumerate(rows[args.first:args.first + args.rows]):
                    half = len(row) // 2
                    fh.write(row[:half])
                    fh.flush()
                    time.sleep(args.half_pause)
                    completing = time.monotonic()  # before the newline can be on disk
                    fh.write(row[half:])
                    fh.flush()
                    flushed.append((time.monotonic(), args.first + k + 1))
                    completed.append(completing)
                    time.sleep(max(0.0, args.pace - args.half_pause))
            total = args.first + args.rows
            updates.wait_for(total, timeout=60)
            latency = [updates.wait_for(n, timeout=60) - t for t, n in flushed]
            with updates.changed:
                seen = list(updates.lines)
            whole = [args.first] + [n for _, n in flushed]
            times = [-1.0] + completed
            from_partial = sum(1 for t, u in seen
                               if u["rows"] > whole[np.searchsorted(times, t, side="right") - 1]
                               or u["events"] != u["rows"])
            time.sleep(2.0)  # the last update's picture and output are out
            cpu0, t0 = proc_cpu_seconds(follower.pid), time.monotonic()
            time.sleep(args.idle)
            idle_pct = 100 * (proc_cpu_seconds(follower.pid) - cpu0) / (time.monotonic() - t0)
            rss_before = proc_rss_mb(follower.pid)
            burst = 100
            with open(path, "a") as fh:
                for i in range(total, total + args.big, burst):
                    fh.write("".join(rows[i:i + burst]))
                    fh.flush()
                    time.sleep(0.02)
            updates.wait_for(total + args.big, timeout=300)
            time.sleep(1.0)
            rss_after = proc_rss_mb(follower.pid)
            n_updates = len(updates.lines)
        finally:
            follower.terminate()
            try:
                code = follower.wait(timeout=30)
            except subprocess.TimeoutExpired:
                follower.kill()
                code = follower.wait()
            if spinner is not None:
                spinner.kill()
                spinner.wait()
    lat = sorted(latency)
    out = {"benchmark": "follow_latency", "rows_split": args.rows, "pace_s": args.pace,
           "half_pause_s": args.half_pause, "other_core_busy": not args.no_busy,
           "model_load_s": round(load_s, 3),
           "latency_s": {"median": round(statistics.median(lat), 3),
                         "p95": round(float(np.percentile(lat, 95)), 3),
                         "max": round(lat[-1], 3)},
           "aim_latency_s": {"median": 1.0, "p95": 2.0},
           "forecasts_from_a_partial_row": from_partial,
           "idle_cpu_percent_of_a_core": round(idle_pct, 2), "aim_idle_cpu_percent": 2.0,
           "rss_mb": {"before": round(rss_before, 1), "after": round(rss_after, 1),
                      "rows_added": args.big, "growth": round(rss_after - rss_before, 1)},
           "aim_rss_growth_mb": 10.0, "updates": n_updates, "exit_status_on_sigterm": code,
           "load_average": os.getloadavg()[0], "cpus": os.cpu_count(),
           "python": sys.version.split()[0],
           "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    publish(out, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
