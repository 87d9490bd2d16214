"""``sliders.forecast`` as a Python API: ``load()``, ``predict()``, and what it prints, honestly.

One model is loaded for the module (the shipped one); the command line is run once, to check
that it prints what the API returns.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys

import numpy as np
import pytest

from sliders.analysis.forecast.base import LEVELS
from sliders.analysis.forecast.evaluation import accuracy_table
from sliders.io.forecast_files import ForecastInputError
from sliders.runs.forecast.cli import build_parser
from sliders.forecasting.predict import disjoint_intervals, probability_text
from helpers import SMALL_CATALOGUE, accelerating

# one xdist worker loads the shipped forecasters (the module's fixture) for all these tests
pytestmark = pytest.mark.xdist_group("forecast-api")


@pytest.fixture(scope="module")
def model(shipped_model):
    """The shipped model (the session's)."""
    return shipped_model


@pytest.fixture
def small(tmp_path):
    p = tmp_path / "small.csv"
    p.write_text(SMALL_CATALOGUE)
    return p


@pytest.fixture
def ramp(tmp_path):
    alpha, size = accelerating()
    p = tmp_path / "ramp.csv"
    p.write_text("angle [deg],size\n" + "".join(f"{a},{s}\n" for a, s in zip(alpha, size)))
    return p


@pytest.mark.slow  # the command as a process; in this process: test_forecast_cli
def test_the_command_prints_what_the_api_returns(model, ramp):
    out = subprocess.run([sys.executable, "-m", "sliders.forecast", "predict", str(ramp),
                          "--tilt-now", "29.5deg", "--json", "--within", "0.5deg",
                          "--angle-resolution", "0.05"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    api = model.predict(str(ramp), tilt_now="29.5deg", within=0.5, angle_resolution="0.05deg")
    assert json.loads(out.stdout) == json.loads(json.dumps(api.to_dict()))


def test_a_mapping_and_a_path_give_one_forecast(model, ramp):
    alpha, size = accelerating()
    by_path = model.predict(ramp, tilt_now="29.5deg").to_dict()
    by_map = model.predict({"angle [deg]": alpha, "size": size}, tilt_now="29.5deg").to_dict()
    rad = model.predict({"angle [rad]": np.radians(alpha), "size": size},
                        tilt_now=math.radians(29.5)).to_dict()
    assert by_map == by_path
    assert rad["alpha_c"] == pytest.approx(by_path["alpha_c"], abs=1e-9)
    assert rad["probability_within"] == pytest.approx(by_path["probability_within"], abs=1e-9)
    with pytest.raises(ForecastInputError, match="row 3, column 'size'"):
        model.predict({"angle [deg]": [1.0, 2.0], "size": [1, "x"]})
    with pytest.raises(ForecastInputError, match="differ in length"):
        model.predict({"angle [deg]": [1.0, 2.0], "size": [1]})


def test_out_of_the_domain_no_line_claims_an_80_percent_interval(model, small):
    pred = model.predict(small, tilt_now="27.5deg", method="all")
    text = str(pred)
    assert not pred["in_domain"] and "OUT OF THE TRAINING DOMAIN" in text
    assert "80 % interval" not in text
    assert "learned (learned, angles + sizes only): avalanche angle" in text
    assert "widened interval, uncalibrated" in text
    assert not any(m["calibrated"] for m in pred["methods"].values())


def test_no_probability_beyond_what_the_forecast_resolves(model, ramp):
    pred = model.predict(ramp, method="all")
    text = pred.lines()
    for method, m in pred["methods"].items():
        line = next(ln for ln in text if ln.startswith(f"{method} ("))
        shown = re.search(r"P\(within the next 1°\) (.*)$", line).group(1)
        assert shown not in ("= 0.00", "= 1.00"), line
        lo, hi = m["probability_bounds"]
        p = m["probability_within"]
        if p < lo:
            assert shown.startswith("< ") and p < float(shown[2:]), line
    assert probability_text(0.0, (0.05, 0.95)) == "< 0.05"
    assert probability_text(1.0, (0.013, 0.987)) == "> 0.98"
    assert probability_text(0.004, (0.013, 0.987)) == "< 0.02"
    assert probability_text(0.5, (0.05, 0.95)) == "= 0.50"


def test_methods_that_disagree_are_warned_and_fallbacks_claim_no_80_percent(model, ramp):
    pred = model.predict(ramp, method="all")
    text = pred.lines()
    assert any(ln.startswith("WARNING: the methods disagree") for ln in text), text
    for method, m in pred["methods"].items():
        if m["fallback"]:
            line = next(ln for ln in text if ln.startswith(f"{method} ("))
            assert "80 % interval" not in line and "uncalibrated" in line
    overlapping = {"a": {"interval": [0.1, 0.3], "fallback": False},
                   "b": {"interval": [0.25, 0.4], "fallback": False},
                   "c": {"interval": [0.9, 1.0], "fallback": True}}
    assert disjoint_intervals(overlapping) == []
    overlapping["b"]["interval"] = [0.31, 0.4]
    assert "a's interval" in disjoint_intervals(overlapping)[0]


def test_the_expected_accuracy_is_stated_when_the_model_holds_it(model, tmp_path):
    alpha, size = accelerating(300, seed=3)
    cat = {"angle [deg]": alpha, "size": size}
    f = model.models["learned_blind"]
    before = getattr(f, "expected_accuracy_", None)
    pred = model.predict(cat, method="learned")
    if before is None:
        assert not any("expected accuracy" in ln for ln in pred.lines())
    # the table training stores: held-out cuts 1° to 12° before their avalanche
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.4, 0.6, 400)
    tilt = truth - np.radians(rng.uniform(1, 12, 400))
    q = truth[:, None] + np.radians(np.linspace(-2, 2, LEVELS.size))[None, :] + 0.01
    table = accuracy_table(q, tilt, truth, 400)
    f.expected_accuracy_ = table
    try:
        pred = model.predict(cat, method="learned")
    finally:
        if before is None:
            del f.expected_accuracy_
        else:
            f.expected_accuracy_ = before
    assert pred["in_domain"], pred["domain_reason"]
    lines = [ln for ln in pred.lines() if "expected accuracy" in ln]
    assert len(lines) == 1 and "typical error at this stage" in lines[0], pred.lines()
    assert pred["methods"]["learned"]["typical_accuracy"]["coverage"] in table["coverage"]


def test_a_tilt_just_below_the_last_event_is_taken_within_three_resolutions(model, small):
    pred = model.predict(small, tilt_now="2.85deg", angle_resolution="0.1deg")
    assert pred["tilt_now"] == pytest.approx(math.radians(2.87))
    assert any("below the last event's angle" in n for n in pred["notes"])
    assert any("below the last event's angle" in ln for ln in pred.lines())
    with pytest.raises(ForecastInputError, match="below the last event's angle"):
        model.predict(small, tilt_now="2.5deg", angle_resolution="0.1deg")
    with pytest.raises(ForecastInputError, match="below the last event's angle"):
        model.predict(small, tilt_now="2.85deg")


def test_every_angle_option_takes_deg_rad_or_a_bare_number(model, small):
    a = model.predict(small, tilt_now="3deg", within="1deg", angle_resolution="0.1deg").to_dict()
    b = model.predict(small, tilt_now=f"{math.radians(3)!r}rad", within=f"{math.radians(1)!r}rad",
                      angle_resolution=f"{math.radians(0.1)!r}rad").to_dict()
    c = model.predict(small, tilt_now=3.0, within=1.0, angle_resolution=0.1).to_dict()
    for d in (b, c):
        assert d["alpha_c"] == pytest.approx(a["alpha_c"], abs=1e-9)
        assert d["within"] == pytest.approx(a["within"], abs=1e-12)
        assert d["measurement"]["angle_resolution_deg"] == pytest.approx(0.1)
    with pytest.raises(ForecastInputError, match="--within 0deg"):
        model.predict(small, within="0deg")
    with pytest.raises(ForecastInputError, match="--angle-resolution x"):
        model.predict(small, angle_resolution="x")


def test_the_text_repeats_the_measurement_and_help_says_min_size_unit(model, small):
    pred = model.predict(small, angle_resolution="0.2deg", min_size=0.5, missed_fraction=0.3,
                         size_unit="arbitrary")
    line = next(ln for ln in pred.lines() if ln.startswith("measurement assumed"))
    for words in ("angle resolution 0.2°", "min size 0.5 (the size column's unit)",
                  "missed fraction 0.3", "size unit arbitrary"):
        assert words in line
    helps = build_parser()._subparsers._group_actions[0].choices["predict"].format_help()
    assert "arbitrary" in helps and "median size" in " ".join(helps.split())
    assert "bare number in the catalogue's angle unit" in " ".join(helps.split())


def test_predict_help_imports_neither_numpy_nor_scikit_learn():
    out = subprocess.run([sys.executable, "-X", "importtime", "-m", "sliders.forecast", "predict",
                          "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and "--follow" in out.stdout and "--plot" in out.stdout
    imported = [ln.split("|")[-1].strip() for ln in out.stderr.splitlines() if "|" in ln]
    assert "sliders.forecasting.common" in imported  # the parser's defaults, read
    assert not [m for m in imported if m.split(".")[0] in ("sklearn", "matplotlib", "numpy")]
