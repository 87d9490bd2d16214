"""A live forecast at lab pace, with and without its picture: ``predict --follow`` on a growing file.

    .venv/bin/python benchmarks/follow_latency.py            # about 5 minutes

The pile is the one docs/forecasting.md simulates (four piles of 200 sliders,
its ``piles.toml``), its first row written by ``python -m sliders.forecast
catalogue`` up to just before its avalanche and kept to its angles and sizes,
as a camera's catalogue is.  The file starts with all but its last ``--rows``
events; a writer appends those one every ``--pace`` seconds, each in two writes
with a pause between them (a half line on disk, as a slow acquisition leaves
it), then a ``# avalanche ANGLE`` line, while ``python -m sliders.forecast
predict FILE --follow --json`` forecasts each new state and the other core is
kept busy by a spinning process.  Two passes, the same rows: without
``--plot``, then with ``--plot live.png``.  Measured in each, from the
follower's JSON Lines as they arrive:

* the latency from a row's last byte written (and flushed) to the first
  forecast that holds it: median and 95th percentile (aim with the picture:
  a median within ``AIM_PLOT_RATIO`` of the one without);
* the rows that got no update of their own (the next update already held a
  later row: the follower was still busy when it arrived);
* forecasts made from a half-written row (aim: none);
* with ``--plot``: the pictures written (the PNG replaced, seen by its inode)
  and how long after the last update the last picture was on disk;
* the follower's exit status at the ``# avalanche`` line, and the run's summary
  (its last JSON line; without ``--plot`` it scores the ``--big`` rows too).

Without ``--plot`` also: the follower's CPU while the file is idle (``--idle``
seconds; aim below 2 % of a core) and its resident memory before and after
``--big`` more rows written in bursts (aim: less than 10 MB of growth).  Last,
in this process, the alarm's hysteresis: how much P(within) moves from one row
to the next over the pile's last events, and the alarms raised at thresholds
0.1-0.5 with and without the release level's gap.  Prints one JSON line and
writes it to benchmarks/results/follow_latency.json.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from forecast_cold_call import publish  # benchmarks/, beside this one

HERE = os.path.dirname(os.path.abspath(__file__))
SPIN = "while True:\n    pass\n"
#: the aim: the median latency with --plot within this factor of the one without
AIM_PLOT_RATIO = 1.3
#: the page whose piles are followed ("What the output means": four piles of 200 sliders)
PAGE = os.path.join(os.path.dirname(HERE), "docs", "forecasting.md")


def page_prior() -> str:
    """The prior file docs/forecasting.md writes (its ``cat > piles.toml`` block)."""
    text = open(PAGE, encoding="utf-8").read()
    return re.search(r"cat > piles\.toml <<'TOML'\n(.*?)\nTOML\n", text, re.S).group(1) + "\n"


def pile_rows(tmp: str, row: int = 0) -> tuple[list[str], float]:
    """The event rows (``angle [deg],size``) of the docs' pile ``row``, up to just before its
    avalanche, and its avalanche angle (degrees)."""
    toml, h5, csv = (os.path.join(tmp, name) for name in ("piles.toml", "piles.h5", "row.csv"))
    with open(toml, "w") as fh:
        fh.write(page_prior())
    subprocess.run([sys.executable, "-m", "sliders.prior", toml, "--out", h5, "--quiet"],
                   check=True)
    said = subprocess.run([sys.executable, "-m", "sliders.forecast", "catalogue", "--data", h5,
                           "--row", str(row), "--lead", "0.01deg", "--out", csv], check=True,
                          capture_output=True, text=True).stdout
    avalanche = float(re.search(r"alpha_c ([0-9.]+)°", said).group(1))
    rows = []
    with open(csv) as fh:
        for line in fh:
            if line[:1].isdigit():
                angle, size = line.split(",")[:2]
                rows.append(f"{np.degrees(float(angle)):.4f},{size}\n")
    return rows, avalanche


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

    def updates(self) -> list[tuple[float, dict]]:
        """The forecasts (not the summary) so far."""
        with self.changed:
            return [(t, u) for t, u in self.lines if "rows" in u]

    def wait_for(self, rows: int, timeout: float) -> float:
        """The arrival time of the first update holding at least ``rows`` rows."""
        deadline = time.monotonic() + timeout
        with self.changed:
            while True:
                hit = next((t for t, u in self.lines if u.get("rows", -1) >= rows), None)
                if hit is not None:
                    return hit
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"no update with {rows} rows in {timeout} s")
                self.changed.wait(left)


class Lines(threading.Thread):
    """A stream's lines (the follower's stderr), kept so that its pipe never fills."""

    def __init__(self, stream):
        super().__init__(daemon=True)
        self.stream, self.lines = stream, []

    def run(self):
        for line in self.stream:
            self.lines.append(line.rstrip("\n"))


class PictureWatch(threading.Thread):
    """The times a PNG was replaced (a new inode at its path), polled every 20 ms."""

    def __init__(self, path):
        super().__init__(daemon=True)
        self.path, self.times, self.stop = path, [], threading.Event()

    def run(self):
        seen = None
        while not self.stop.is_set():
            try:
                st = os.stat(self.path)
                key = (st.st_ino, st.st_mtime_ns)
            except FileNotFoundError:
                key = None
            if key is not None and key != seen:
                seen = key
                self.times.append(time.monotonic())
            time.sleep(0.02)


def rounded(values) -> dict:
    v = sorted(values)
    return {"median": round(statistics.median(v), 3),
            "p95": round(float(np.percentile(v, 95)), 3), "max": round(v[-1], 3)}


def follow_pass(args, rows: list[str], avalanche: float, tmp: str, plot: bool) -> dict:
    """One follow of the same rows, with or without ``--plot``; its figures."""
    first, n = len(rows) - args.rows, args.rows
    path = os.path.join(tmp, f"live{'-plot' if plot else ''}.csv")
    png = os.path.join(tmp, "live.png")
    with open(path, "w") as fh:
        fh.write("angle [deg],size\n" + "".join(rows[:first]))
    command = [sys.executable, "-m", "sliders.forecast", "predict", path, "--follow", "--json"]
    watch = None
    if plot:
        command += ["--plot", png]
        watch = PictureWatch(png)
        watch.start()
    follower = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True)
    updates, errors = Updates(follower.stdout), Lines(follower.stderr)
    updates.start()
    errors.start()
    out = {}
    try:
        started = time.monotonic()
        updates.wait_for(first, timeout=180)
        out["model_load_s"] = round(time.monotonic() - started, 3)
        flushed = []  # (monotonic time the row's newline was on disk, rows then complete)
        completed = []  # monotonic time just before each row's newline was written
        with open(path, "a") as fh:
            for k, row in enumerate(rows[first:]):
                half = len(row) // 2
                fh.write(row[:half])
                fh.flush()
                time.sleep(args.half_pause)
                completing = time.monotonic()  # before the newline can be on disk
                fh.write(row[half:])
                fh.flush()
                flushed.append((time.monotonic(), first + k + 1))
                completed.append(completing)
                time.sleep(max(0.0, args.pace - args.half_pause))
        total = first + n
        last_update = updates.wait_for(total, timeout=120)
        latency = [updates.wait_for(k, timeout=60) - t for t, k in flushed]
        seen = updates.updates()
        own = {u["rows"] for _, u in seen}
        whole = [first] + [k for _, k in flushed]
        times = [-1.0] + completed
        out.update(
            rows_split=n, first_rows=first,
            latency_s=rounded(latency),
            rows_without_an_update_of_their_own=sum(1 for _, k in flushed if k not in own),
            forecasts_from_a_partial_row=sum(
                1 for t, u in seen
                if u["rows"] > whole[np.searchsorted(times, t, side="right") - 1]))
        if plot:
            deadline = time.monotonic() + 60
            while not (watch.times and watch.times[-1] >= last_update) \
                    and time.monotonic() < deadline:
                time.sleep(0.05)
            lag = watch.times[-1] - last_update if watch.times else None
            out["pictures"] = {"written": len(watch.times),
                               "last_picture_after_last_update_s":
                                   None if lag is None else round(lag, 3)}
        else:
            time.sleep(2.0)  # the last update's output is out
            cpu0, t0 = proc_cpu_seconds(follower.pid), time.monotonic()
            time.sleep(args.idle)
            out["idle_cpu_percent_of_a_core"] = round(
                100 * (proc_cpu_seconds(follower.pid) - cpu0) / (time.monotonic() - t0), 2)
            if args.big:
                out["rss_mb"] = memory_growth(args, follower, updates, path, rows, total)
                total += args.big
        out["updates"] = len(updates.updates())
        with open(path, "a") as fh:
            fh.write(f"# avalanche {avalanche:.3f}deg\n")
        try:
            out["exit_status_at_avalanche"] = follower.wait(timeout=60)
        except subprocess.TimeoutExpired:
            out["exit_status_at_avalanche"] = None
        updates.join(timeout=5)
        last = updates.lines[-1][1] if updates.lines else {}
        out["summary"] = last.get("summary")
        out["alarm_lines"] = sum(1 for line in errors.lines if line.startswith("ALARM"))
    finally:
        if follower.poll() is None:
            follower.terminate()
            try:
                follower.wait(timeout=30)
            except subprocess.TimeoutExpired:
                follower.kill()
                follower.wait()
        if watch is not None:
            watch.stop.set()
    return out


def memory_growth(args, follower, updates, path, rows, total) -> dict:
    """The follower's resident memory before and after ``args.big`` more rows (the pile's
    last angle and size repeated a hair apart), written in bursts of 100."""
    angle, size = rows[-1].strip().split(",")
    more = [f"{float(angle) + 1e-4 * (k + 1):.4f},{size}\n" for k in range(args.big)]
    before = proc_rss_mb(follower.pid)
    with open(path, "a") as fh:
        for i in range(0, args.big, 100):
            fh.write("".join(more[i:i + 100]))
            fh.flush()
            time.sleep(0.02)
    updates.wait_for(total + args.big, timeout=600)
    time.sleep(1.0)
    after = proc_rss_mb(follower.pid)
    return {"before": round(before, 1), "after": round(after, 1), "rows_added": args.big,
            "growth": round(after - before, 1)}


def alarm_flicker(rows: list[str], start: int = 150,
                  thresholds=(0.1, 0.2, 0.3, 0.4, 0.5)) -> dict:
    """P(within the next 1°) of the pile cut after each of its events from ``start`` on
    (forecast in this process, as the follower does): how much it moves from one row to the
    next, and the alarms raised at each threshold without a gap and with the default release
    level (``alarm.Alarm``)."""
    import sliders.forecast as sf
    from sliders.forecasting.alarm import Alarm, default_release, probability_within

    angle = np.array([float(r.split(",")[0]) for r in rows])
    size = np.array([float(r.split(",")[1]) for r in rows])
    model = sf.load()
    preds = [model.predict({"angle [deg]": angle[:k], "size": size[:k]}).to_dict()
             for k in range(start, len(rows) + 1)]
    p = np.array([probability_within(d) for d in preds])
    step = np.abs(np.diff(p))
    raised = {}
    for t in thresholds:
        counts = []
        for release in (t - 1e-9, default_release(t)):
            alarm = Alarm(t, release=release, say=lambda line: None)
            for k, d in enumerate(preds):
                alarm.update(d, start + k)
            counts.append(alarm.raised_count)
        raised[f"{t:g}"] = {"bare": counts[0], "with_release": counts[1],
                            "release": round(default_release(t), 3)}
    return {"forecasts": len(preds), "from_event": start,
            "p_step": {"median": round(float(np.median(step)), 4),
                       "p90": round(float(np.percentile(step, 90)), 4),
                       "max": round(float(step.max()), 4)},
            "alarms_raised": raised}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", type=int, default=100, help="rows written at lab pace, in halves")
    ap.add_argument("--pace", type=float, default=0.5, help="seconds between rows")
    ap.add_argument("--half-pause", type=float, default=0.1,
                    help="seconds between a row's two writes")
    ap.add_argument("--idle", type=float, default=10.0, help="seconds of idle CPU measured")
    ap.add_argument("--big", type=int, default=10_000,
                    help="rows added for the memory figure (0: none)")
    ap.add_argument("--no-busy", action="store_true", help="leave the other core idle")
    ap.add_argument("--out", default=os.path.join(HERE, "results", "follow_latency.json"))
    args = ap.parse_args(argv)
    spinner = None
    with tempfile.TemporaryDirectory() as tmp:
        rows, avalanche = pile_rows(tmp)
        if args.rows >= len(rows):
            ap.error(f"--rows {args.rows}: the pile has {len(rows)} events")
        try:
            spinner = None if args.no_busy else subprocess.Popen([sys.executable, "-c", SPIN])
            plain = follow_pass(args, rows, avalanche, tmp, plot=False)
            with_plot = follow_pass(args, rows, avalanche, tmp, plot=True)
            flicker = alarm_flicker(rows)
        finally:
            if spinner is not None:
                spinner.kill()
                spinner.wait()
    ratio = with_plot["latency_s"]["median"] / plain["latency_s"]["median"]
    out = {"benchmark": "follow_latency",
           "catalogue": f"docs/forecasting.md's pile of 200 sliders, row 0: {len(rows)} events "
                        f"up to its avalanche at {avalanche:.3f}°, angles and sizes",
           "pace_s": args.pace, "half_pause_s": args.half_pause,
           "other_core_busy": not args.no_busy,
           "without_plot": plain, "with_plot": with_plot,
           "median_latency_ratio_plot": round(ratio, 2), "aim_median_latency_ratio": AIM_PLOT_RATIO,
           "aim_idle_cpu_percent": 2.0, "aim_rss_growth_mb": 10.0, "alarm_flicker": flicker,
           "load_average": os.getloadavg()[0], "cpus": os.cpu_count(),
           "python": sys.version.split()[0],
           "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    publish(out, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
