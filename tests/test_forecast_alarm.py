"""The live forecast's alarm (hysteresis, the hook), the run's score, the picture drawn aside."""

from __future__ import annotations

import json
import math
import shlex
import sys
import threading
import time

import pytest

from sliders.io.forecast_files import ForecastInputError
from sliders.forecasting.alarm import (HOOK_ENVIRONMENT, Alarm, LatestPicture, RunScore,
                                         check_hook, default_release)

rad = math.radians


def prediction(p, tilt=28.0, alpha=29.0, interval=(28.5, 30.0), bounds=(0.05, 0.95),
               threshold=0.5, calibrated=True, fallback=False) -> dict:
    """A forecast's ``to_dict()`` as the alarm reads it (degrees given, radians kept)."""
    return {"probability_within": p, "tilt_now": rad(tilt), "within": rad(1.0),
            "alpha_c": rad(alpha), "interval": [rad(interval[0]), rad(interval[1])],
            "alarm_threshold": threshold,
            "methods": {"learned": {"probability_bounds": list(bounds),
                                    "calibrated": calibrated, "fallback": fallback}}}


class Lines(list):
    def __call__(self, line):
        self.append(line)


# ---- hysteresis ---------------------------------------------------------------------


def test_an_alarm_whose_p_hovers_at_the_threshold_sounds_once():
    hovering = [0.3, 0.48, 0.52, 0.47, 0.53, 0.45, 0.55, 0.46, 0.51, 0.42]
    said = Lines()
    alarm = Alarm(0.5, say=said)
    states = [alarm.update(prediction(p), rows=10 + k) for k, p in enumerate(hovering)]
    assert [s["raised"] for s in states].count(True) == 1
    assert not any(s["released"] for s in states)
    assert states[2] == {"alarm": True, "raised": True, "released": False}
    assert all(s["alarm"] for s in states[2:])
    assert len(said) == 1 and said[0].startswith("ALARM at 28.00° (rows 12)")
    # below the release level (0.5 - 0.1) it falls, once
    off = alarm.update(prediction(0.39), rows=30)
    assert off == {"alarm": False, "raised": False, "released": True}
    assert len(said) == 2 and said[1].startswith("alarm off at 28.00° (rows 30)")
    assert "below the release level 0.4" in said[1]
    # without the gap the same P would flicker: the hysteresis is what stops it
    flicker = Lines()
    bare = Alarm(0.5, release=0.4999, say=flicker)
    for p in hovering:
        bare.update(prediction(p), rows=1)
    assert sum(line.startswith("ALARM") for line in flicker) == 4


def test_the_release_level_default_and_bounds():
    assert default_release(0.5) == pytest.approx(0.4)
    assert default_release(0.9) == pytest.approx(0.8)
    assert default_release(0.1) == pytest.approx(0.05)  # a low threshold keeps a level
    for t in (0.01, 0.15, 0.5, 0.99):
        assert 0.0 < default_release(t) < t
    for bad in (0.0, 1.0, 1.5, -0.2, "x", 0.99, 0.05, 0.96):
        with pytest.raises(ForecastInputError, match="--alarm-threshold"):
            Alarm(bad)
    for bad in (0.5, 0.7, -0.1):
        with pytest.raises(ForecastInputError, match="--alarm-release"):
            Alarm(0.5, release=bad)


def test_without_a_threshold_the_forecasters_own_is_used():
    said = Lines()
    alarm = Alarm(None, say=said)
    assert not alarm.update(prediction(0.35, threshold=0.3 + 0.1), rows=1)["alarm"]
    assert alarm.update(prediction(0.41, threshold=0.4), rows=2)["raised"]
    assert "threshold 0.4" in said[0]
    assert not alarm.update(prediction(0.31, threshold=0.4), rows=3)["released"]
    assert alarm.update(prediction(0.29, threshold=0.4), rows=4)["released"]


def test_the_alarm_line_prints_p_as_the_update_line_does():
    said = Lines()
    Alarm(0.5, say=said).update(prediction(0.999, bounds=(0.05, 0.95)), rows=7)
    assert "P(avalanche within the next 1°) > 0.95" in said[0]
    assert "1.00" not in said[0] and "= 0.99" not in said[0]
    assert "avalanche angle 29.00° (80 % interval 28.50-30.00°)" in said[0]
    said.clear()
    Alarm(0.5, say=said).update(prediction(0.62, calibrated=False, fallback=True), rows=7)
    assert "P(avalanche within the next 1°) = 0.62" in said[0]
    assert "widened interval, uncalibrated" in said[0]


def test_the_alarm_line_names_the_interval_as_every_output_does():
    """An interval uncalibrated but not widened (the pile outside the training domain, the
    learned forecaster's own interval) is "interval, uncalibrated" in the ALARM line as in the
    update line and the picture (``report.interval_name``), not "widened"."""
    from sliders.forecasting.report import interval_name

    said = Lines()
    Alarm(0.5, say=said).update(prediction(0.62, calibrated=False), rows=7)
    assert "avalanche angle 29.00° (interval, uncalibrated 28.50-30.00°)" in said[0]
    assert interval_name({"calibrated": False, "fallback": False}, "learned") in said[0]


# ---- the hook -----------------------------------------------------------------------


HOOK = """import json, os, sys
with open(sys.argv[1], "a") as fh:
    fh.write(json.dumps({k: v for k, v in os.environ.items() if k.startswith("SLIDERS_")}
                        | {"argv": sys.argv[2:]}) + "\\n")
sys.exit(int(os.environ.get("HOOK_STATUS", "0")))
"""


@pytest.fixture
def hook(tmp_path):
    """``(command text, file of the runs)``: a tiny hook in a folder with a space in its name,
    writing its environment and arguments as one JSON line per run."""
    folder = tmp_path / "the hooks"
    folder.mkdir()
    script, runs = folder / "hook.py", folder / "runs.jsonl"
    script.write_text(HOOK)
    text = f"{shlex.quote(sys.executable)} {shlex.quote(str(script))} {shlex.quote(str(runs))} " \
           "'two words' plain"
    return text, runs


def test_the_hook_runs_once_per_alarm_with_the_forecast_in_its_environment(hook):
    text, runs = hook
    said = Lines()
    alarm = Alarm(0.5, hook=text, say=said, catalogue="pile.csv")
    for rows, p in enumerate([0.2, 0.6, 0.7, 0.45, 0.8, 0.3, 0.2, 0.55, 0.9], start=40):
        alarm.update(prediction(p, tilt=27.0 + rows / 100), rows=rows)
    assert alarm.wait_hooks(timeout=30)
    got = [json.loads(line) for line in runs.read_text().splitlines()]
    assert len(got) == 2 == alarm.raised_count  # raised at rows 41 and 47
    first = got[0] if got[0]["SLIDERS_ROWS"] == "41" else got[1]
    assert first["argv"] == ["two words", "plain"]  # split as a shell splits words
    assert set(HOOK_ENVIRONMENT) <= set(first)
    assert float(first["SLIDERS_ALARM_P"]) == pytest.approx(0.6)
    assert first["SLIDERS_ALARM_P_TEXT"] == "= 0.60"
    assert float(first["SLIDERS_ALARM_ANGLE_DEG"]) == pytest.approx(29.0)
    assert float(first["SLIDERS_ALARM_LOW_DEG"]) == pytest.approx(28.5)
    assert float(first["SLIDERS_ALARM_HIGH_DEG"]) == pytest.approx(30.0)
    assert float(first["SLIDERS_TILT_DEG"]) == pytest.approx(27.41)
    assert first["SLIDERS_ALARM_THRESHOLD"] == "0.5"
    assert first["SLIDERS_CATALOGUE"] == "pile.csv"
    assert sorted(r["SLIDERS_ROWS"] for r in got) == ["41", "47"]
    assert not any("--on-alarm" in line for line in said)


def test_a_failing_hook_is_reported_in_one_line_and_the_follow_goes_on(hook, monkeypatch):
    text, runs = hook
    monkeypatch.setenv("HOOK_STATUS", "3")
    said = Lines()
    alarm = Alarm(0.5, hook=text, say=said)
    assert alarm.update(prediction(0.7), rows=5)["raised"]
    assert alarm.wait_hooks(timeout=30)
    failures = [line for line in said if line.startswith("--on-alarm")]
    assert len(failures) == 1 and "exited with status 3" in failures[0]
    assert "\n" not in failures[0]
    # the alarm goes on: released, raised again, the hook run again
    assert alarm.update(prediction(0.1), rows=6)["released"]
    assert alarm.update(prediction(0.9), rows=7)["raised"]
    assert alarm.wait_hooks(timeout=30)
    assert len(runs.read_text().splitlines()) == 2


def test_a_hook_that_cannot_start_is_refused_before_the_follow(tmp_path):
    with pytest.raises(ForecastInputError, match="no-such-program-sliders: no such program"):
        check_hook("no-such-program-sliders --loud")
    with pytest.raises(ForecastInputError, match="no such file, or not executable"):
        check_hook(f"{tmp_path}/absent.sh")
    with pytest.raises(ForecastInputError, match="--on-alarm"):
        check_hook("notify-send 'unclosed")
    with pytest.raises(ForecastInputError, match="give the command"):
        check_hook("  ")
    with pytest.raises(ForecastInputError, match="no such program"):
        Alarm(0.5, hook="no-such-program-sliders")
    assert check_hook(f"{shlex.quote(sys.executable)} -c 'print(1)'") == [sys.executable, "-c",
                                                                          "print(1)"]


# ---- the run's score ----------------------------------------------------------------


def update(tilt, alpha, lo, hi, rows, alarm, calibrated=True):
    return prediction(0.5, tilt=tilt, alpha=alpha, interval=(lo, hi),
                      calibrated=calibrated) | {"rows": rows, "alarm": alarm}


RUN = [update(25.0, 31.0, 27.0, 33.0, 100, False),   # holds 28.85
       update(26.0, 30.0, 28.9, 31.0, 120, False),   # misses
       update(27.0, 29.5, 28.0, 30.0, 140, True),    # holds; the first alarm
       update(27.5, 29.2, 28.0, 29.0, 150, False),   # holds
       update(28.0, 29.1, 28.5, 29.5, 160, True),    # holds; raised again
       update(28.5, 29.0, 28.9, 29.5, 170, True)]    # misses


def test_the_run_is_scored_against_the_avalanche_given():
    score = RunScore()
    for u in RUN:
        score.add(u)
    s = score.summary(rad(28.85))
    assert json.loads(json.dumps(s)) == s  # JSON values
    assert s["avalanche_angle"] == pytest.approx(rad(28.85))
    assert s["avalanche_angle_source"] == "given"
    assert s["updates"] == 6 and s["alarms_raised"] == 2
    assert s["first_alarm"]["rows"] == 140
    assert s["first_alarm"]["tilt_now"] == pytest.approx(rad(27.0))
    assert s["first_alarm"]["before"] == pytest.approx(rad(1.85))
    assert s["last_forecast"]["alpha_c"] == pytest.approx(rad(29.0))
    assert s["last_forecast"]["error"] == pytest.approx(rad(0.15))
    assert s["last_forecast"]["held"] is False and s["last_forecast"]["rows"] == 170
    assert s["interval_held"] == 4 and s["interval_held_share"] == pytest.approx(4 / 6)
    text = "\n".join(RunScore.lines(s))
    assert "28.85° (given on the '# avalanche' line): 6 updates" in text
    assert "first raised at 27.00° (rows 140), 1.85° before the avalanche; raised 2 times" in text
    assert "error +0.15°" in text and "outside its interval" in text
    assert "held the avalanche: 4 of 6 (0.67)" in text


def test_without_an_angle_the_run_is_scored_at_the_last_tilt_and_says_so():
    score = RunScore()
    for u in RUN[:2]:
        score.add(u)
    s = score.summary()
    assert s["avalanche_angle"] == pytest.approx(rad(26.0))
    assert s["avalanche_angle_source"] == "last tilt reached"
    assert s["first_alarm"] is None and s["alarms_raised"] == 0
    assert s["interval_held"] == 0  # the tilt lies below both intervals
    text = "\n".join(RunScore.lines(s))
    assert "the last tilt reached" in text and "never raised" in text
    empty = RunScore().summary(rad(28.0))
    assert empty["updates"] == 0 and RunScore.lines(empty) == ["run: no forecast was made"]


# ---- the picture drawn aside ----------------------------------------------------------


class SlowDraw:
    """A draw that takes ``seconds`` and records what it drew (in ``log``, a file, when it runs
    in a forked child); the PNG is the name."""

    def __init__(self, seconds, log=None):
        self.seconds, self.log, self.drawn = seconds, log, []
        self.started = threading.Event()

    def __call__(self, prediction, status):
        self.started.set()
        if self.log is not None:
            with open(self.log, "a") as fh:
                fh.write(f"start {prediction}\n")
        time.sleep(self.seconds)
        self.drawn.append((prediction, status["rows"]))
        if self.log is not None:
            with open(self.log, "a") as fh:
                fh.write(f"drew {prediction} rows {status['rows']}\n")
        if prediction == "fault":
            raise ZeroDivisionError("a fault of the drawing")
        return prediction.encode()


def wait_until(condition, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline
        time.sleep(0.01)


@pytest.mark.parametrize("fork", [False, True], ids=["thread", "forked child"])
def test_only_the_newest_prediction_is_drawn_never_more_than_one_behind(tmp_path, fork):
    log = tmp_path / "draws.log"
    draw = SlowDraw(0.3, log)
    path = tmp_path / "live.png"
    picture = LatestPicture(path, draw=draw, fork=fork)
    picture.show("update-0", {"rows": 0})
    wait_until(lambda: log.exists())
    behind = []
    for k in range(1, 8):  # seven updates while the first is drawn
        picture.show(f"update-{k}", {"rows": k})
        behind.append(picture.behind())
    assert max(behind) == 2  # one drawn, one waiting: the newest
    picture.close()
    assert log.read_text().splitlines() == ["start update-0", "drew update-0 rows 0",
                                            "start update-7", "drew update-7 rows 7"]
    assert path.read_bytes() == b"update-7"
    assert picture.drawn == 2 and picture.shown == 8
    assert sorted(p.name for p in tmp_path.iterdir()) == ["draws.log", "live.png"]


@pytest.mark.parametrize("fork", [False, True], ids=["thread", "forked child"])
def test_show_returns_at_once_while_a_picture_is_drawn(tmp_path, fork):
    picture = LatestPicture(tmp_path / "live.png", draw=SlowDraw(0.5), fork=fork)
    started = time.monotonic()
    for k in range(3):
        picture.show(f"u{k}", {"rows": k})
    assert time.monotonic() - started < 0.2
    assert picture.wait(timeout=10)
    picture.close()
    assert (tmp_path / "live.png").read_bytes() == b"u2"


@pytest.mark.parametrize("fork", [False, True], ids=["thread", "forked child"])
def test_a_picture_that_cannot_be_written_is_raised_once_naming_the_path(tmp_path, fork):
    path = tmp_path / "no such folder" / "live.png"
    picture = LatestPicture(path, draw=SlowDraw(0.0), fork=fork)
    picture.show("u0", {"rows": 1})
    picture.wait(timeout=10)
    with pytest.raises(ForecastInputError) as caught:
        picture.show("u1", {"rows": 2})
    line = str(caught.value)
    assert line.startswith(f"{path}: the picture could not be written") and "\n" not in line
    picture.close()  # reported once: not again
    again = LatestPicture(path, draw=SlowDraw(0.0), fork=fork)
    again.show("u0", {"rows": 1})
    with pytest.raises(ForecastInputError, match="could not be written"):
        again.close()


@pytest.mark.parametrize("fork", [False, True], ids=["thread", "forked child"])
def test_a_failed_picture_is_told_by_check_with_no_update_after_it(tmp_path, fork):
    """A follow whose input goes quiet after the update whose picture fails still learns
    of the failure: ``check`` raises it (once), as the next ``show`` would."""
    path = tmp_path / "live.png"
    path.mkdir()  # a folder where the picture goes
    picture = LatestPicture(path, draw=SlowDraw(0.0), fork=fork)
    picture.check()  # nothing failed yet
    picture.show("u0", {"rows": 1})
    picture.wait(timeout=10)
    with pytest.raises(ForecastInputError, match="could not be written"):
        picture.check()
    picture.check()  # told once
    picture.close()


def test_a_fault_of_the_drawing_child_is_raised_in_one_line(tmp_path):
    picture = LatestPicture(tmp_path / "live.png", draw=SlowDraw(0.0), fork=True)
    picture.show("fault", {"rows": 1})
    with pytest.raises(RuntimeError, match="ZeroDivisionError: a fault of the drawing"):
        picture.close()
    assert not (tmp_path / "live.png").exists()


# ---- the options --------------------------------------------------------------------


def test_the_alarm_options_are_refused_in_one_line_before_anything_is_read(tmp_path, capsys):
    from sliders.runs.forecast.cli import main

    absent = str(tmp_path / "absent.csv")  # never read: the options are refused first
    for options, says in [(["--alarm-threshold", "1.5"], "strictly between 0 and 1"),
                          (["--alarm-threshold", "0.99"], "would never sound"),
                          (["--alarm-threshold", "0.05"], "would always sound"),
                          (["--alarm-threshold", "high"], "a probability"),
                          (["--alarm-release", "0.3"], "with --follow only"),
                          (["--on-alarm", "true"], "with --follow only"),
                          (["--follow", "--alarm-threshold", "0.5", "--alarm-release", "0.5"],
                           "must lie in [0, the alarm threshold 0.5)"),
                          (["--follow", "--on-alarm", "no-such-program-sliders -v"],
                           "no such program")]:
        assert main(["predict", absent, *options]) == 2, options
        err = capsys.readouterr().err.strip()
        assert says in err and "\n" not in err and options[-1].split()[0] in err


def test_a_single_forecast_says_whether_its_alarm_sounds():
    from sliders.forecasting.alarm import single_alarm

    report = prediction(0.62, threshold=0.5)
    out, line = single_alarm(report, "0.6")
    assert out["alarm"] is True and out["alarm_threshold"] == 0.6 and "alarm" not in report
    assert line == "alarm: P(avalanche within the next 1°) = 0.62, at or above the threshold " \
                   "0.6: ALARM"
    out, line = single_alarm(report, 0.7)
    assert out["alarm"] is False and line.endswith("below the threshold 0.7: no alarm")
    # the distribution's own P decides where JSON's is clipped to what the forecast resolves
    clipped = prediction(0.05) | {"methods": {"learned": {"probability_bounds": [0.05, 0.95],
                                                          "probability_within_raw": 0.01}}}
    assert Alarm(0.1, release=0.02, say=Lines()).update(clipped, 1)["alarm"] is False
    alarm = Alarm(0.1, release=0.02, say=Lines())
    alarm.update(prediction(0.2), 1)
    assert alarm.update(clipped, 2)["released"]


def test_a_stop_signal_lets_the_drawing_child_finish_its_picture(tmp_path):
    import os
    import signal

    log = tmp_path / "draws.log"
    picture = LatestPicture(tmp_path / "live.png", draw=SlowDraw(0.4, log), fork=True)
    picture.show("u0", {"rows": 1})
    wait_until(lambda: log.exists() and picture.child is not None)
    os.kill(picture.child, signal.SIGINT)  # as the terminal's Ctrl-C reaches the whole group
    picture.close()
    assert (tmp_path / "live.png").read_bytes() == b"u0"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["draws.log", "live.png"]


@pytest.mark.slow
def test_the_live_picture_of_a_real_forecast_carries_its_status(tmp_path, shipped_model):
    import numpy as np

    from sliders.forecasting.alarm import png_bytes

    u = np.sort(np.random.default_rng(3).random(120))
    alpha, size = 31.0 - 31.0 * np.exp(-3.0 * u), np.ones(120, dtype=int)
    pred = shipped_model.predict({"angle [deg]": alpha, "size": size}, tilt_now="30deg")
    status = {"alarm": True, "alarm_threshold": 0.4, "rows": 120, "file": "pile.csv",
              "time": "2026-11-28T03:40:00"}
    bare, with_status = png_bytes(pred), png_bytes(pred, status)
    assert bare[:8] == with_status[:8] == b"\x89PNG\r\n\x1a\n" and bare != with_status
    picture = LatestPicture(tmp_path / "live.png", fork=True)
    picture.show(pred, status)
    picture.close()
    assert (tmp_path / "live.png").read_bytes() == with_status


#: a pile of prior_format1.h5 (row 0) to 0.05° before its avalanche at 19.937°: angle° and size
SMALL_PILE = ("0.1824:1 4.0529:2 4.7686:2 6.8907:2 6.9814:1 7.7756:1 9.1642:3 9.2035:1 10.7131:1 "
              "10.8201:1 12.6662:1 13.3822:1 13.4918:1 14.4720:2 14.9675:1 15.0398:2 15.0862:9 "
              "15.1412:4 17.0682:9 18.0061:3 18.6709:29 19.2287:1 19.5475:2 19.8138:2")


@pytest.mark.slow
def test_the_command_runs_the_hook_once_and_scores_the_run_at_the_avalanche(tmp_path, hook,
                                                                            shipped_model):
    import subprocess

    from sliders.forecasting.alarm import probability_within

    rows = [r.split(":") for r in SMALL_PILE.split()]
    path = tmp_path / "pile.csv"
    path.write_text("angle [deg],size\n" + "".join(f"{a},{s}\n" for a, s in rows)
                    + "# avalanche 19.937deg\n")
    p = probability_within(shipped_model.predict(path).to_dict())
    assert p > 0.08  # the threshold below it is one the option takes
    threshold = f"{max(0.06, min(0.95, p - 0.02)):.3f}"
    text, runs = hook
    done = subprocess.run([sys.executable, "-m", "sliders.forecast", "predict", str(path),
                           "--follow", "--json", "--alarm-threshold", threshold,
                           "--on-alarm", text], capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    *updates, last = lines
    assert updates and all(u["alarm"] is True for u in updates)
    summary = last["summary"]
    assert summary["avalanche_angle"] == pytest.approx(rad(19.937))
    assert summary["avalanche_angle_source"] == "given"
    assert summary["first_alarm"]["rows"] == 24 and summary["alarms_raised"] == 1
    alarm_lines = [line for line in done.stderr.splitlines() if line.startswith("ALARM")]
    assert len(alarm_lines) == 1 and f"threshold {float(threshold):g}" in alarm_lines[0]
    wait_until(lambda: runs.exists() and runs.read_text().endswith("\n"), timeout=30)
    got = [json.loads(line) for line in runs.read_text().splitlines()]
    assert len(got) == 1 and got[0]["SLIDERS_ROWS"] == "24"
    assert got[0]["SLIDERS_CATALOGUE"] == str(path) and got[0]["argv"] == ["two words", "plain"]
