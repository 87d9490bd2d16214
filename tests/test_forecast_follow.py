"""``predict --follow``: a writer replays a catalogue at lab pace, with half-written lines, a
truncation and a replacement; every forecast printed is batch ``predict``'s on the same rows and
tilt, none comes from a partial line, and the picture is never half-written."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import sliders.forecast as sf
from sliders.runs.forecast.follow import Tail, comments, rate_option

from test_forecast_api import accelerating

WRITER = textwrap.dedent('''
    import os, sys, time
    path, n = sys.argv[1], int(sys.argv[2])
    rows = open(path + ".rows").read().splitlines(keepends=True)
    header = "angle [deg],size\\n"

    def wait(step):                                   # the test has seen the last step's forecast
        while not os.path.exists(path + ".go" + step):
            time.sleep(0.05)

    def append(lines, half=False):
        with open(path, "a") as f:
            for k, line in enumerate(lines):
                if half and k == len(lines) // 2:      # half a line, its newline later
                    f.write(line[:4]); f.flush(); time.sleep(0.5); f.write(line[4:])
                else:
                    f.write(line)
                f.flush()
                time.sleep(0.03)                      # lab pace: a row every few frames

    append(rows[n:n + 20], half=True)
    append(["# tilt-now %.4fdeg\\n" % (float(rows[n + 19].split(",")[0]) + 0.2)])
    wait("1")
    with open(path, "w") as f:                        # truncated: the acquisition restarts
        f.write(header); f.writelines(rows[:n + 10])
    wait("2")
    with open(path + ".new", "w") as f:               # replaced by a new file, half a row last
        f.write(header); f.writelines(rows[:n + 30]); f.write(rows[n + 30][:5])
    os.replace(path + ".new", path)
    wait("3")
    time.sleep(0.5)
    append([rows[n + 30][5:]] + rows[n + 31:n + 40])
    wait("4")
    append(["# avalanche\\n"])
''')


def test_tail_holds_a_partial_line_and_rereads_a_truncated_file(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("angle [deg],size\n1,1\n2,")
    t = Tail(str(p))
    assert t.poll() is None and bytes(t.data) == b"angle [deg],size\n1,1\n"
    with open(p, "a") as f:
        f.write("1\n# tilt-now 2.5deg\n")
    t.poll()
    assert bytes(t.data).endswith(b"2,1\n# tilt-now 2.5deg\n")
    assert comments(t.data) == ("2.5deg", False)
    p.write_text("angle [deg],size\n")
    assert t.poll() == "truncated" and bytes(t.data) == b"angle [deg],size\n"
    assert rate_option("0.1deg/s") == pytest.approx(math.radians(0.1))


@pytest.fixture(scope="module")
def model():
    return sf.load()


@pytest.mark.slow  # three seconds of polls beside the model's load
def test_an_idle_follower_parses_nothing_and_forecasts_once(tmp_path, model, monkeypatch):
    """Polls of a file that does not change cost a stat and an empty read: its lines are parsed
    once, forecast once, and parsed again only when a complete line arrives (a half line
    does not count)."""
    import threading

    from sliders.runs.forecast import follow as live
    from sliders.runs.forecast.cli import build_parser

    alpha, size = accelerating(60, seed=3)
    path = tmp_path / "pile.csv"
    path.write_text("angle [deg],size\n" + "".join(f"{a},{s}\n" for a, s in zip(alpha, size)))
    parsed, forecasts = [], []
    read_source = live.read_source
    monkeypatch.setattr(live, "read_source", lambda *a: parsed.append(1) or read_source(*a))
    monkeypatch.setattr(live, "report", lambda args, pred, rows, alarm, say:
                        forecasts.append(rows) or alarm)
    args = build_parser().parse_args(["predict", str(path), "--follow", "--json"])
    seen = {}

    def writer():                                     # the follower runs in the main thread
        time.sleep(12 * live.POLL_SECONDS)             # a dozen idle polls
        seen["idle"] = (len(parsed), list(forecasts))
        with open(path, "a") as f:
            f.write("31.5,")                          # half a row: held, nothing parsed
            f.flush()
            time.sleep(6 * live.POLL_SECONDS)
            seen["half"] = len(parsed)
            f.write("2\n# avalanche\n")

    thread = threading.Thread(target=writer)
    thread.start()
    try:
        assert live.follow(args, model) == 0
    finally:
        thread.join(timeout=30)
    assert seen == {"idle": (1, [60]), "half": 1}
    assert len(parsed) == 2 and forecasts == [60, 61]


@pytest.mark.slow  # a replay at lab pace through two processes; batch's rows: test_forecast_cli
def test_follow_forecasts_what_batch_forecasts(tmp_path, model):
    alpha, size = accelerating(180, seed=5)
    rows = [f"{a},{s}\n" for a, s in zip(alpha, size)]
    path = tmp_path / "live.csv"
    (tmp_path / "live.csv.rows").write_text("".join(rows))
    n = 100
    path.write_text("angle [deg],size\n" + "".join(rows[:n]))
    png = tmp_path / "live.png"
    follower = subprocess.Popen(
        [sys.executable, "-m", "sliders.forecast", "predict", str(path), "--follow", "--json",
         "--plot", str(png), "--until", "89deg"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    updates, writer = [], None
    try:
        first = follower.stdout.readline()          # the model is loaded: the replay starts
        assert first, follower.stderr.read()
        updates.append(json.loads(first))
        writer = subprocess.Popen([sys.executable, "-c", WRITER, str(path), str(n)])
        pngs = []
        # in order: the truncation's n + 10 rows also pass by while the first rows arrive
        steps = [("1", lambda u: u["rows"] == n + 20
                  and u["tilt_now"] > math.radians(alpha[n + 19])),
                 ("2", lambda u: u["rows"] == n + 10), ("3", lambda u: u["rows"] == n + 30),
                 ("4", lambda u: u["rows"] == n + 40)]
        while (line := follower.stdout.readline()):
            updates.append(json.loads(line))
            if steps and steps[0][1](updates[-1]):
                (tmp_path / f"live.csv.go{steps[0][0]}").touch()
                del steps[0]
            if png.exists():
                pngs.append(png.read_bytes())
        code = follower.wait(timeout=60)
        err = follower.stderr.read()
    finally:
        for proc in (follower, writer):
            if proc is not None and proc.poll() is None:
                proc.kill()
    assert code == 0, err
    assert writer.wait(timeout=30) == 0
    assert "truncated" in err and "replaced" in err and "avalanche" in err, err
    counts = [u["rows"] for u in updates]
    assert counts[0] == n and max(counts) == n + 40 and n + 10 in counts, counts
    # rows only ever come whole: no forecast from the half-written row n + 30
    for u in updates:
        batch = model.predict({"angle [deg]": alpha[:u["rows"]], "size": size[:u["rows"]]},
                              tilt_now=f"{u['tilt_now']!r}rad").to_dict()
        assert u["events"] == u["rows"]
        for key in ("alpha_c", "probability_within", "tilt_now"):
            assert u[key] == pytest.approx(batch[key], abs=1e-9), key
        assert u["interval"] == pytest.approx(batch["interval"], abs=1e-9)
        assert {k: v for k, v in u.items() if k not in ("rows", "alarm", "model")} \
            .keys() == {k for k in batch if k != "model"}
    tilts = [u["tilt_now"] for u in updates]
    assert any(t > math.radians(alpha[n + 19]) + 1e-6 for t in tilts)  # the tilt-now line read
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert all(b[:8] == b"\x89PNG\r\n\x1a\n" and b.endswith(b"IEND\xaeB`\x82") for b in pngs)
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]


@pytest.mark.slow  # a process stopped by a signal; batch's bad-row line: test_forecast_cli
def test_follow_stops_on_sigterm_with_status_0(tmp_path):
    path = tmp_path / "c.csv"
    path.write_text("angle [deg],size\n1,1\n2,1\n")
    proc = subprocess.Popen([sys.executable, "-m", "sliders.forecast", "predict", str(path),
                             "--follow", "--tilt-rate", "0.5deg/s"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stdout.readline()
        assert first.startswith("rows 2, tilt "), proc.stderr.read()
        with open(path, "a") as f:                  # a bad row: one line naming it, as in batch
            f.write("3,x\n")
        bad = proc.stderr.readline()
        assert "row 4, column 'size': 'x' is not a number" in bad, bad
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0
        assert "stopped (SIGTERM)" in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()


def test_an_alarm_line_when_the_probability_crosses_the_threshold(model):
    from types import SimpleNamespace

    from sliders.runs.forecast.follow import report

    alpha, size = accelerating(150, seed=7)
    pred = model.predict({"angle [deg]": alpha, "size": size}, method="ffm_ls_events")
    p = pred["probability_within"]
    said = []
    args = SimpleNamespace(json=False, plot=None)
    pred._report["alarm_threshold"] = p / 2           # crossed upwards: ALARM
    assert report(args, pred, 150, False, lambda line, err=False: said.append(line)) is True
    assert said[-1].startswith("ALARM: P(avalanche within the next 1°)")
    said.clear()                                      # still above: no new line
    assert report(args, pred, 150, True, lambda line, err=False: said.append(line)) is True
    assert len(said) == 1 and said[0].startswith("rows 150")
    pred._report["alarm_threshold"] = min(1.0, p * 2 + 0.01)   # fallen below: said once
    assert report(args, pred, 150, True, lambda line, err=False: said.append(line)) is False
    assert said[-1].startswith("alarm off")
