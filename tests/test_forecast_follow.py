"""``predict --follow`` and ``ForecastModel.follow``: the ``Follower`` polled step by step on a
file the test appends to (bad rows skipped, the markers read, the clock anchored), its bounds,
standard input; and, as processes, a writer replaying a catalogue at lab pace with half-written
lines, a truncation and a replacement, and the Python follow equal to the command's output."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from sliders.io.forecast_files import ForecastInputError
from sliders.forecasting import follower as live
from sliders.forecasting.follower import LineBuffer, Tail, marker, rate_option


def accelerating(n: int = 150, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """Angles (degrees) of ``n`` events accelerating towards 31° and their sizes."""
    rng = np.random.default_rng(seed)
    alpha = 31.0 - 31.0 * np.exp(-3.0 * np.sort(rng.random(n)))
    return np.round(alpha, 4), np.maximum(1, np.round(rng.pareto(1.5, n) + 1)).astype(int)


def csv_rows(alpha, size) -> str:
    return "".join(f"{a},{s}\n" for a, s in zip(alpha, size))


@pytest.fixture(scope="module")
def model(shipped_model):
    """The shipped model (the session's)."""
    return shipped_model


class Clock:
    """A wall clock the test moves."""

    def __init__(self):
        self.now = 1000.0

    def __call__(self):
        return self.now


@pytest.fixture
def pile(tmp_path):
    alpha, size = accelerating(40, seed=3)
    path = tmp_path / "pile.csv"
    path.write_text("angle [deg],size\n" + csv_rows(alpha, size))
    return path, alpha, size


def following(model, path, said, **kw):
    f = model.follow(path, say=said.append, **kw)
    f.clock = Clock()
    return f


def append(path, text):
    with open(path, "a") as fh:
        fh.write(text)


def test_a_bad_row_is_said_once_and_skipped_and_the_next_rows_are_forecast(model, pile):
    """Rows 2.5, 4.0 and 5.0 after 3.0: 2.5 is named (file, row, column) and skipped, 4.0 and
    5.0 are forecast; a later 'abc' row is named too, and the rows after it forecast."""
    path, alpha, size = pile
    path.write_text("angle [deg],size\n1.0,1\n2.0,1\n3.0,2\n")
    said = []
    f = following(model, path, said)
    assert f.step().rows == 3
    append(path, "2.5,1\n4.0,1\n5.0,3\n")
    u = f.step()
    assert u.rows == 5 and u["tilt_now"] == pytest.approx(math.radians(5.0))
    assert len(said) == 1 and "pile.csv: row 5, column 'angle': '2.5'" in said[0], said
    append(path, "abc,1\n")
    assert f.step() is None
    append(path, "6.0,1\n")
    assert f.step().rows == 6
    assert len(said) == 2 and "row 8, column 'angle': 'abc' is not a number" in said[1], said
    assert f.step() is None and len(said) == 2  # each said once
    # the forecast is batch predict's on the good rows
    batch = model.predict({"angle [deg]": [1, 2, 3, 4, 5, 6], "size": [1, 1, 2, 1, 3, 1]})
    assert f.score.updates[-1]["alpha_c"] == pytest.approx(batch["alpha_c"], abs=1e-12)


def test_a_row_the_measurement_refuses_is_skipped_too(model, pile):
    """A size of 0.5 sliders is read by the CSV reader but refused by the forecast (below the
    smallest size detected): its row is named and skipped, and the follow forecasts on."""
    path, alpha, size = pile
    said = []
    f = following(model, path, said)
    assert f.step().rows == 40
    append(path, f"{alpha[-1] + 0.1:.4f},0.5\n{alpha[-1] + 0.2:.4f},2\n")
    u = f.step()
    assert u.rows == 41 and u["tilt_now"] == pytest.approx(math.radians(alpha[-1] + 0.2))
    assert len(said) == 1 and "pile.csv: row 42: " in said[0] and "size 0.5" in said[0], said
    append(path, f"{alpha[-1] + 0.3:.4f},1\n")
    assert f.step().rows == 42 and len(said) == 1


def test_a_bad_header_is_said_once_and_a_rewritten_file_is_read(model, tmp_path):
    path = tmp_path / "pile.csv"
    path.write_text("angle,size\n1.0,1\n")
    said = []
    f = following(model, path, said)
    assert f.step() is None
    append(path, "2.0,1\n3.0,1\n")
    assert f.step() is None and len(said) == 1 and "'angle' needs its unit" in said[0]
    path.write_text("angle [deg],size\n1.0,1\n2.0,1\n")
    assert f.step().rows == 2 and "read again from its start" in said[-1]


def test_only_the_markers_count_among_the_comments(model, pile):
    """A header mentioning the avalanche is ignored; '# tilt-now 21deg (by hand)' is read;
    '# tilt-now nandeg' is one line naming its row, and the follow goes on; a tilt-now below
    the last event is raised to it, said once; '# avalanche 31.2deg' stops and scores."""
    path, alpha, size = pile
    path.write_text("# avalanche precursors, lab run 3\nangle [deg],size\n"
                    + csv_rows(alpha[:20], size[:20]))
    said = []
    f = following(model, path, said)
    assert f.step().rows == 20 and f.proceed
    top = alpha[19]
    append(path, f"# tilt-now {top + 1.5:.4f}deg (by hand)\n")
    u = f.step()
    assert u["tilt_now"] == pytest.approx(math.radians(top + 1.5)) and not said
    append(path, "# tilt-now nandeg\n")
    assert f.step() is None and f.proceed
    assert len(said) == 1 and "row 24: # tilt-now nandeg" in said[0], said
    append(path, "# tilt-now 1deg\n")
    u = f.step()
    assert u["tilt_now"] == pytest.approx(math.radians(top))
    assert len(said) == 2 and "row 25: # tilt-now 1deg" in said[1] and "raised" in said[1]
    append(path, csv_rows(alpha[20:22], size[20:22]) + "# avalanche in the camera's view\n")
    assert f.step().rows == 22 and f.proceed and len(said) == 2
    append(path, csv_rows(alpha[22:24], size[22:24]) + "# avalanche 31.2deg\n"
           + csv_rows(alpha[24:26], size[24:26]))
    assert f.step().rows == 24 and not f.proceed  # the rows after the marker are not read
    assert (f.stopped.reason, f.stopped.status) == ("avalanche", 0)
    assert f.summary["avalanche_angle"] == pytest.approx(math.radians(31.2))
    assert f.summary["updates"] == 5 and "31.20°" in f.stopped.line


def test_the_clock_starts_again_at_each_anchor(model, pile):
    """At 1°/s from --tilt-now, an event appended 6 s in, 0.5° above the start, is forecast
    from its own angle (reckoned from the start the clock was 5.5° ahead of it); 1.1 s on,
    from 1.1° above it; a '# tilt-now' line is the next anchor."""
    path, alpha, size = pile
    path.write_text("angle [deg],size\n" + csv_rows(alpha[:30], size[:30]))
    said = []
    start = alpha[29] + 0.1
    f = following(model, path, said, tilt_now=f"{start:.4f}deg", tilt_rate="1deg/s")
    assert f.step()["tilt_now"] == pytest.approx(math.radians(start), abs=1e-12)
    f.clock.now += 6.0
    append(path, f"{start + 0.5:.4f},2\n")
    assert f.step()["tilt_now"] == pytest.approx(math.radians(start + 0.5), abs=1e-12)
    f.clock.now += 0.5
    assert f.step() is None  # the clock's forecasts: at most one a second
    f.clock.now += 0.6
    assert f.step()["tilt_now"] == pytest.approx(math.radians(start + 1.6), abs=1e-9)
    append(path, f"# tilt-now {start + 1.0:.4f}deg\n")
    f.clock.now += 2.0
    assert f.step()["tilt_now"] == pytest.approx(math.radians(start + 1.0), abs=1e-12)
    assert not said


def test_the_clock_stops_at_90_degrees_with_one_line(model, pile):
    path, alpha, size = pile
    said = []
    f = following(model, path, said, tilt_now="85deg", tilt_rate="20deg/s")
    assert f.step()["tilt_now"] == pytest.approx(math.radians(85))
    for _ in range(5):
        f.clock.now += 1.5
        u = f.step()
        if u is not None:
            assert u["tilt_now"] < math.pi / 2
    assert said == ["the tilt reached 90°: the clock stops there"]
    assert f.score.updates[-1]["tilt_now"] == live.LAST_TILT


def test_until_stops_with_status_0(model, pile):
    path, alpha, size = pile
    f = following(model, path, [], until=f"{alpha[-1] + 0.5:.4f}", tilt_rate="1deg/s")
    assert f.step() is not None and f.proceed
    f.clock.now += 1.0
    assert f.step() is not None and (f.stopped.reason, f.stopped.status) == ("until", 0)


def test_an_alarm_line_gives_the_probability_as_the_update_line(model, tmp_path):
    alpha, size = accelerating(150, seed=7)
    path = tmp_path / "ramp.csv"
    path.write_text("angle [deg],size\n" + csv_rows(alpha, size))
    f = following(model, path, [], method="ffm_ls_events", tilt_now="30.95deg")
    u = f.step()
    p_text = u.line().rsplit(") ", 1)[1]
    assert u.alarm["raised"] and p_text.startswith(">"), u.lines()
    # the first update also says what the alarm can do for this kind of catalogue
    assert len(u.lines()) == 3 and u.lines()[1].startswith("alarm: at P(avalanche within")
    assert f"°) {p_text}," in u.lines()[2], u.lines()
    assert u.to_dict()["alarm"] is True
    f.clock.now += 0.5
    later = f.step()
    assert later is None or not any(x.startswith("alarm: at P(") for x in later.lines())


def test_the_reads_are_bounded(model, tmp_path):
    """A line over 4096 bytes is refused as soon as it is that long (no newline needed), a
    file over 64 MB from its size, a missing file and a folder at once: one line each."""
    buf = LineBuffer("x.csv")
    assert buf.feed(b"angle [deg],size\n1,") == [b"angle [deg],size\n"]
    with pytest.raises(ForecastInputError, match=r"x.csv: row 2: longer than 4096 bytes"):
        buf.feed(b"1" * 5000)
    big = tmp_path / "big.csv"
    with open(big, "wb") as fh:
        fh.truncate(400 * 2**20)                      # sparse: 400 MB of zeros, no newline
    with pytest.raises(ForecastInputError, match=r"big.csv: 400 MB"):
        model.follow(big)
    for name in ("no_such_pile.csv", "."):
        with pytest.raises(ForecastInputError, match=r"no_such_pile.csv: No such file|a folder"):
            model.follow(tmp_path / name)
    grown = tmp_path / "grown.csv"
    grown.write_text("angle [deg],size\n1,1\n")
    f = following(model, grown, [])
    assert f.step().rows == 1
    with open(grown, "ab") as fh:
        fh.write(b"2" * (3 * live.CHUNK_BYTES))
    with pytest.raises(ForecastInputError, match=r"grown.csv: row 3: longer than 4096"):
        f.step()


def test_standard_input_is_followed_without_blocking(model, monkeypatch):
    """``-`` reads standard input: polls return at once while nothing comes, the rows are
    forecast as they arrive, and the end of the input stops the follow (status 0)."""
    read_end, write_end = os.pipe()

    class Stdin:
        def fileno(self):
            return read_end

    monkeypatch.setattr(sys, "stdin", Stdin())
    f = following(model, "-", [])
    try:
        t = time.monotonic()
        assert f.step() is None and time.monotonic() - t < 0.5
        os.write(write_end, b"angle [deg],size\n1.0,1\n2.0,")
        assert f.step().rows == 1
        os.write(write_end, b"1\n3.0,2")                # the last row without its newline
        assert f.step().rows == 2
        os.close(write_end)
        write_end = None
        assert f.step().rows == 3 and (f.stopped.reason, f.stopped.status) == ("end of input", 0)
    finally:
        if write_end is not None:
            os.close(write_end)
        os.close(read_end)


def test_tail_holds_a_partial_line_and_rereads_a_truncated_file(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("angle [deg],size\n1,1\n2,")
    t = Tail(str(p))
    assert t.poll() == (None, [b"angle [deg],size\n", b"1,1\n"])
    with open(p, "a") as f:
        f.write("1\n# tilt-now 2.5deg\n")
    assert t.poll() == (None, [b"2,1\n", b"# tilt-now 2.5deg\n"])
    p.write_text("angle [deg],size\n")
    assert t.poll() == ("truncated", [b"angle [deg],size\n"])
    t.close()
    assert marker(b"# tilt-now 21deg (by hand)\n") == ("tilt-now", "21deg")
    assert marker(b"# avalanche precursors, lab run 3\n") is None
    assert marker(b"# avalanche 28.85deg\n") == ("avalanche", "28.85deg")
    assert marker(b"#avalanche\n") == ("avalanche", None)
    assert rate_option("0.1deg/s") == pytest.approx(math.radians(0.1))


@pytest.mark.slow  # three seconds of polls beside the model's load
def test_an_idle_follower_parses_nothing_and_forecasts_once(tmp_path, model, monkeypatch):
    """Polls of a file that does not change cost a stat and an empty read: its lines are parsed
    once, forecast once, and parsed again only when a complete line arrives (a half line
    does not count)."""
    import threading

    alpha, size = accelerating(60, seed=3)
    path = tmp_path / "pile.csv"
    path.write_text("angle [deg],size\n" + csv_rows(alpha, size))
    parsed = []
    reader = live.read_catalogue_stream
    monkeypatch.setattr(live, "read_catalogue_stream", lambda *a: parsed.append(1) or reader(*a))
    seen = {}

    def writer():                                     # the follower runs in the main thread
        time.sleep(12 * live.POLL_SECONDS)             # a dozen idle polls
        seen["idle"] = len(parsed)
        with open(path, "a") as f:
            f.write("31.5,")                          # half a row: held, nothing parsed
            f.flush()
            time.sleep(6 * live.POLL_SECONDS)
            seen["half"] = len(parsed)
            f.write("2\n# avalanche\n")

    thread = threading.Thread(target=writer)
    thread.start()
    try:
        forecasts = [u.rows for u in model.follow(path)]
    finally:
        thread.join(timeout=30)
    assert seen == {"idle": 1, "half": 1}
    assert len(parsed) == 2 and forecasts == [60, 61]


def run_follow(*args, **kw):
    return subprocess.run([sys.executable, "-m", "sliders.forecast", "predict", *args],
                          capture_output=True, text=True, timeout=120, **kw)


@pytest.mark.slow  # two commands beside the model's load
def test_the_python_follow_prints_what_the_command_prints(tmp_path, model):
    """The command is the Python follow printed: the same text lines, and the same JSON lines
    (the summary at '# avalanche' last), on a file with a bad row and the markers."""
    alpha, size = accelerating(150, seed=7)
    path = tmp_path / "pile.csv"
    path.write_text("# avalanche precursors, lab run 3\nangle [deg],size\n"
                    + csv_rows(alpha[:140], size[:140]) + "x,1\n# tilt-now 30.8deg (by hand)\n"
                    + csv_rows(alpha[140:], size[140:]) + "# avalanche 31.05deg\n")
    said = []
    f = model.follow(path, method="ffm_ls_events", alarm_threshold=0.5, say=said.append)
    updates = list(f)
    text = [line for u in updates for line in u.lines()] + sf_lines(f.summary)
    jsonl = [u.to_dict() for u in updates] + [{"summary": f.summary}]
    out = run_follow(str(path), "--follow", "--method", "ffm_ls_events",
                     "--alarm-threshold", "0.5")
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == text
    assert any(line.startswith("ALARM") for line in text) and len(updates) == 1
    assert "row 143, column 'angle': 'x' is not a number" in out.stderr
    assert out.stderr.strip().endswith(f.stopped.line)
    out = run_follow(str(path), "--follow", "--json", "--method", "ffm_ls_events",
                     "--alarm-threshold", "0.5")
    assert out.returncode == 0, out.stderr
    assert [json.loads(line) for line in out.stdout.splitlines()] == \
        json.loads(json.dumps(jsonl))


def sf_lines(summary):
    from sliders.forecasting.alarm import RunScore

    return RunScore.lines(summary)


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
            if "summary" in updates[-1]:
                break
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
    summary = updates.pop()["summary"]
    assert summary["updates"] == len(updates) and summary["avalanche_angle_source"]
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
            .keys() == {k for k in batch if k not in ("model", "alarm")}
    tilts = [u["tilt_now"] for u in updates]
    assert any(t > math.radians(alpha[n + 19]) + 1e-6 for t in tilts)  # the tilt-now line read
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert all(b[:8] == b"\x89PNG\r\n\x1a\n" and b.endswith(b"IEND\xaeB`\x82") for b in pngs)
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]
