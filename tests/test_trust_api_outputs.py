"""What ``predict``, ``infer`` and the Python API promise about their inputs and outputs: a
``--plot`` never replaces an input and is checked before anything is loaded or computed, the
catalogue is checked before the model is loaded, the API's cells are checked as the CSV's
fields, a noisy catalogue in time order is read as the training reads noisy angles, and the
edges of a forecast and of a posterior are said in words (and JSON values) that match them.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest

from sliders.analysis.forecast.measurement import Measurement, degrade
from sliders.io.catalogue import Catalogue
from sliders.io.forecast_files import (ANGLE_TOLERANCE_RESOLUTIONS, MAX_EVENTS,
                                       ForecastInputError)
from sliders.runs.forecast import infer as infer_module
from sliders.runs.forecast import predict as predict_module
from sliders.forecasting import predict as forecasting_predict
from sliders.forecasting.catalogue import measurement_from, read_source
from sliders.runs.forecast.cli import build_parser

pytestmark = pytest.mark.xdist_group("forecast-api")

PILE = "# a small pile\nangle [deg],size\n1.21,1\n2.03,1\n2.87,3\n"


class Loaded(Exception):
    """The model (or posterior) was loaded: what must not happen before the inputs are checked."""


@pytest.fixture
def no_loading(monkeypatch):
    """``predict`` and ``infer`` with their loaders replaced by a refusal to load."""
    def refuse(*a, **k):
        raise Loaded

    monkeypatch.setattr(predict_module, "load_model", refuse)
    monkeypatch.setattr(infer_module, "load_posterior", refuse)


def command(*argv):
    """``predict`` or ``infer`` of ``argv``, in this process (its function, its parsed options)."""
    args = build_parser().parse_args([str(a) for a in argv])
    return (predict_module.predict if args.command == "predict" else infer_module.infer)(args)


@pytest.fixture
def bench(tmp_path):
    """A folder with a catalogue, a copy, a symlink and a hard link to them, a folder, a FIFO."""
    (tmp_path / "pile.csv").write_text(PILE)
    (tmp_path / "pile2.csv").write_text(PILE)
    os.symlink("pile2.csv", tmp_path / "view.png")
    os.link(tmp_path / "pile.csv", tmp_path / "hard.png")
    (tmp_path / "folder").mkdir()
    os.mkfifo(tmp_path / "fifo.png")
    (tmp_path / "m.zip").write_bytes(b"not read")
    return tmp_path


@pytest.mark.parametrize("cmd", ["predict", "infer"])
@pytest.mark.parametrize("plot, words", [
    ("pile.csv", "is the catalogue"), ("view.png", "through a symbolic link"),
    ("hard.png", "is the catalogue"), ("folder", "not a regular file"),
    ("fifo.png", "not a regular file"), ("/dev/full", "not a regular file"),
    ("missing/x.png", "does not exist")])
def test_a_plot_that_is_an_input_or_no_file_is_refused_before_anything_is_loaded(
        bench, no_loading, monkeypatch, cmd, plot, words):
    monkeypatch.chdir(bench)
    catalogue = "pile2.csv" if plot == "view.png" else "pile.csv"
    with pytest.raises(ForecastInputError, match=re.escape(words)) as refused:
        command(cmd, catalogue, "--plot", plot)
    assert "--plot" in str(refused.value) and "\n" not in str(refused.value)
    assert (bench / "pile.csv").read_text() == PILE and (bench / "pile2.csv").read_text() == PILE


def test_a_plot_onto_the_model_or_the_posterior_file_is_refused(bench, no_loading, monkeypatch):
    monkeypatch.chdir(bench)
    with pytest.raises(ForecastInputError, match="is the model file 'm.zip'"):
        command("predict", "pile.csv", "--model", "m.zip", "--plot", "m.zip")
    with pytest.raises(ForecastInputError, match="is the posterior file 'm.zip'"):
        command("infer", "pile.csv", "--posterior", "m.zip", "--plot", "./m.zip")
    shipped = predict_module.default_model_path()
    with pytest.raises(ForecastInputError, match="is the model file"):
        command("predict", "pile.csv", "--plot", shipped)
    assert (bench / "m.zip").read_bytes() == b"not read"


@pytest.mark.parametrize("cmd", ["predict", "infer"])
def test_the_catalogue_is_checked_before_the_model_is_loaded(bench, no_loading, cmd):
    bad = bench / "bad.csv"
    bad.write_text("angle [deg],size\n1.0,1\n2.0,abc\n")
    with pytest.raises(ForecastInputError, match="row 3, column 'size'"):
        command(cmd, bad)
    with pytest.raises(ForecastInputError, match="--tilt-now 1.5deg: below the last event"):
        command(cmd, bench / "pile.csv", "--tilt-now", "1.5deg")
    with pytest.raises(Loaded):  # a good catalogue: then, and only then, the model
        command(cmd, bench / "pile.csv", "--plot", bench / "new.png")


@pytest.mark.slow  # the command as a process
def test_the_command_refuses_to_draw_over_its_catalogue(bench):
    started = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "sliders.forecast", "predict", "pile.csv",
                          "--plot", "pile.csv"], cwd=bench, capture_output=True, text=True)
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert "never replaces an input" in out.stderr and out.stdout == ""
    assert (bench / "pile.csv").read_text() == PILE
    assert time.monotonic() - started < 30


# ---- the API's cells ------------------------------------------------------------------------

def test_any_whole_number_of_sliders_is_taken_and_a_fraction_refused():
    for n in (100, np.int64(100), np.uint16(100), 100.0, np.float32(100.0), "100", " 100 "):
        m = measurement_from(0.0, sliders=n)
        assert m.n_sliders == 100 and type(m.n_sliders) is int and m.n_sliders_high is None
    for n in ("100-300", (100, 300), [np.int64(100), 300.0]):  # a range
        m = measurement_from(0.0, sliders=n)
        assert (m.n_sliders, m.n_sliders_high) == (100, 300)
    for n in (2.5, 0, -3, True, float("nan"), "abc", "2.5", "300-100", "100-", (1, 2, 3)):
        with pytest.raises(ForecastInputError, match="--sliders") as refused:
            measurement_from(0.0, sliders=n)
        assert "\n" not in str(refused.value) and "measurement flags: --" not in str(refused.value)


@pytest.mark.parametrize("columns, words", [
    ({"angle [deg]": [1.0, None], "size": [1, 1]}, "row 3, column 'angle': None"),
    ({"angle [deg]": [1.0, 2.0], "size": [None, 1]}, "row 2, column 'size': None"),
    ({"angle [deg]": ["#DIV/0!", 2.0], "size": [1, 1]}, "row 2, column 'angle': '#DIV/0!'"),
    ({"angle [deg]": [1.0, "# 2.0"], "size": [1, 1]}, "row 3, column 'angle'"),
    ({"angle [deg]": [1.0, 2.0], "size": [1, "1\n3"]}, "row 3, column 'size'"),
    ({"angle [deg]": [1.0, "2.0,5"], "size": [1, 1]}, "row 3, column 'angle'"),
    ({"angle [deg]": [1.0, 2.0], "size": [True, 1]}, "row 2, column 'size': a bool"),
    ({"angle [deg]": [1.0, 2.0], "size": [1, object()]}, "row 3, column 'size': a object"),
    ({"angle [deg]": [1.0, 2.0], "size": [1, 1], "first\nlast": [0, 1]}, "column name"),
])
def test_a_cell_is_one_number_or_a_one_line_refusal_naming_its_row_and_column(columns, words):
    with pytest.raises(ForecastInputError, match=re.escape(words)) as refused:
        read_source(columns)
    assert "\n" not in str(refused.value)


def test_a_mapping_of_too_many_rows_is_refused_before_a_cell_is_read():
    n = 3 * MAX_EVENTS
    angles = np.zeros(n)
    started = time.perf_counter()
    with pytest.raises(ForecastInputError, match=f"{n} rows, more than {MAX_EVENTS}"):
        read_source({"angle [deg]": angles, "size": angles})
    assert time.perf_counter() - started < 0.5


# ---- a noisy catalogue in time order --------------------------------------------------------

def noisy_in_time_order(n=200, resolution_deg=0.15, seed=4):
    """A catalogue's angles accelerating towards 31°, each with a Gaussian error of
    ``resolution_deg`` (the rows in time order: the true angles' order), and its sizes."""
    rng = np.random.default_rng(seed)
    true = np.sort(31.0 - 31.0 * np.exp(-3.0 * rng.random(n)))
    size = np.maximum(1, np.round(rng.pareto(1.5, n) + 1)).astype(int)
    return true, size


def test_a_noisy_catalogue_in_time_order_is_read_as_training_degrades_one():
    true, size = noisy_in_time_order()
    res = math.radians(0.15)
    cat = Catalogue(np.radians(true), size, np.zeros(true.size), np.full(true.size, -1),
                    np.full(true.size, -1), tilt_now=math.radians(31.0))
    trained = degrade(cat, Measurement(res), np.random.default_rng(9))
    # the same errors, the rows left in time order: what a laboratory records
    recorded = np.clip(cat.alpha + np.random.default_rng(9).normal(0.0, res, true.size), 0.0,
                       cat.tilt_now)
    assert np.mean(np.diff(recorded) < 0) > 0.2  # a fifth of the rows go back
    with pytest.raises(ForecastInputError, match=r"row \d+, column 'angle'.*--angle-resolution"):
        read_source({"angle [rad]": recorded, "size": size})
    read = read_source({"angle [rad]": recorded, "size": size}, angle_resolution=res)
    assert read.reordered == int(np.sum(recorded < np.maximum.accumulate(recorded)))
    np.testing.assert_array_equal(read[0].alpha, trained.alpha)
    np.testing.assert_array_equal(read[0].size, trained.size)
    csv = "angle [rad],size\n" + "".join(f"{float(a)!r},{s}\n" for a, s in zip(recorded, size))
    from_csv = read_source(csv.encode(), angle_resolution=res)[0]
    np.testing.assert_array_equal(from_csv.alpha, trained.alpha)


def test_an_angle_back_by_the_tolerance_or_more_is_refused_naming_its_row():
    k = ANGLE_TOLERANCE_RESOLUTIONS
    rows = {"angle [deg]": [10.0, 11.0, 11.0 - 0.1 * k + 0.01, 12.0], "size": [1, 2, 3, 4]}
    cat = read_source(rows, angle_resolution=math.radians(0.1))[0]
    assert cat.size.tolist() == [1, 3, 2, 4]  # sorted, each size kept with its angle
    rows["angle [deg]"][2] = 11.0 - 0.1 * k - 0.01
    with pytest.raises(ForecastInputError, match="row 4, column 'angle'.*below row 3's angle"):
        read_source(rows, angle_resolution=math.radians(0.1))
    with pytest.raises(ForecastInputError, match="row 4, column 'angle'"):
        read_source(rows, angle_resolution=math.radians(1.0) / 10)


# ---- the forecast's and the posterior's edges (the shipped model: slow, its loading) ---------

@pytest.fixture(scope="module")
def model(shipped_model):
    """The shipped model (the session's)."""
    return shipped_model


def accelerating(n=150, seed=7):
    rng = np.random.default_rng(seed)
    alpha = 31.0 - 31.0 * np.exp(-3.0 * np.sort(rng.random(n)))
    return np.round(alpha, 4), np.maximum(1, np.round(rng.pareto(1.5, n) + 1)).astype(int)


@pytest.mark.slow  # the shipped model's seconds of loading
def test_the_api_forecasts_a_noisy_catalogue_as_its_sorted_rows_and_says_so(model):
    true, size = noisy_in_time_order()
    recorded = np.round(true + np.random.default_rng(5).normal(0.0, 0.15, true.size), 2)
    pred = model.predict({"angle [deg]": recorded, "size": size}, angle_resolution="0.15deg",
                         sliders=np.int64(200))
    order = np.argsort(recorded, kind="stable")
    ordered = model.predict({"angle [deg]": recorded[order], "size": size[order]},
                            angle_resolution="0.15deg", sliders=200)
    assert pred["alpha_c"] == ordered["alpha_c"] and pred["interval"] == ordered["interval"]
    assert any("sorted by angle" in note for note in pred["notes"])
    assert pred["measurement"]["n_sliders"] == 200


@pytest.mark.slow  # the shipped model's seconds of loading
def test_json_probabilities_are_bounded_as_the_text_bounds_them(model):
    alpha, size = accelerating()
    pred = model.predict({"angle [deg]": alpha, "size": size}, tilt_now="29.5deg", method="all")
    lines, seen = pred.lines(), 0
    for method, m in pred.to_dict()["methods"].items():
        line = next(ln for ln in lines if ln.startswith(f"{method} ("))
        shown = re.search(r"P\(within the next 1°\) (.*)$", line).group(1)
        assert 0.0 < m["probability_within"] < 1.0
        if shown[0] in "<>":
            seen += 1
            assert m["probability_within"] == float(shown[2:]), (method, shown, m)
            assert (m["probability_within_raw"] < m["probability_within"]) == (shown[0] == "<")
        else:
            assert m["probability_within"] == m["probability_within_raw"]
    assert seen and pred.to_dict()["probability_within"] == \
        pred.to_dict()["methods"]["learned"]["probability_within"]


@pytest.mark.slow  # the shipped model's seconds of loading
def test_out_of_the_domain_the_text_says_what_was_done_and_whose_median_it_is(model):
    from sliders.analysis.forecast.base import MEDIAN

    alpha, size = accelerating()
    pred = model.predict({"angle [deg]": alpha, "size": size}, tilt_now="29.5deg",
                         angle_resolution="2deg", method="all")
    lines = pred.lines()
    at = next(i for i, ln in enumerate(lines) if ln.startswith("learned ("))
    said = lines[at + 1]
    assert not pred["in_domain"] and not said.lstrip().startswith("fallback")
    assert "the interval is widened" in said and "the median given is" in said
    point = pred["methods"]["learned"]["alpha_c"]
    learned = model.models["learned_blind"]
    remaining = pred["tilt_now"] + learned.remaining_quantiles_[MEDIAN]
    climatology = pred["methods"]["conditioned"]["alpha_c"]
    whose = ("the conditioned climatology's" if abs(point - climatology) < 1e-9 else
             "the training piles' median remaining angle" if abs(point - remaining) < 1e-9 else
             "the learned forecaster's own")
    assert whose in said and f"({math.degrees(point):.2f}°)" in said


def test_one_name_for_an_interval_wherever_it_is_printed():
    name = forecasting_predict.interval_name
    assert name({"calibrated": True, "fallback": False}, "learned") == "80 % interval"
    assert name({"calibrated": False, "fallback": True}, "learned") == \
        "widened interval, uncalibrated"
    assert name({"calibrated": False, "fallback": True}, "ffm_ls_disp") == \
        "climatology's 10-90 % range, uncalibrated"
    assert name({"calibrated": False, "fallback": False}, "learned") == "interval, uncalibrated"


def test_a_p_value_below_the_checks_resolution_and_a_negative_contraction_are_said_so():
    from sliders.analysis.forecast.posterior_check import combined_verdict
    from sliders.forecasting.infer import Inference, check_text, contraction_text

    check = {"reproduced": False, "p_values": {"onset": 0.0, "log_events": 0.3},
             "simulated": 24, "significance_level": 0.01}
    verdict = combined_verdict(check, True, "")
    assert "p < 0.001, below 0.01" in verdict["reasons"][0]["detail"]
    assert "p = 0 " not in check_text(verdict) and "p < 0.001" in check_text(verdict)
    passed = combined_verdict({**check, "reproduced": True,
                               "p_values": {"onset": 0.4}}, True, "")
    assert "smallest p-value = 0.4" in check_text(passed)
    assert contraction_text(-0.02) == "contraction none"
    assert contraction_text(0.456) == "contraction 0.46"
    report = {"events": 3, "tilt_now": 0.1, "complete": False, "notes": [], "in_domain": True,
              "parameters": {"sigma_mu": {"median": 0.05, "interval_80": [0.01, 0.1],
                                          "interval_95": [0.0, 0.2]}},
              "contraction": {"sigma_mu": -0.02}, "check": None, "posterior": {"path": "p"}}
    text = str(Inference(report, {}, {}))
    assert "(contraction none)" in text and "-0.02" not in text
