"""Forecasts that cannot be false: a catalogue is checked as physics, a measurement outside the
training measurement is out of the domain, every forecast is finite and within [tilt, 90°], and
every bad option is one line.  ``predict`` runs in this process on a reduced copy of the shipped
model (``test_trust_model_file.reduced``), written once.
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

from sliders.analysis.forecast import Measurement
from sliders.analysis.forecast.base import Forecast, ForecastError
from sliders.io.catalogue import Catalogue

from helpers import rate_law_catalogue, write_model

# one xdist worker writes the reduced model file (the module's fixture) for all these tests
pytestmark = pytest.mark.xdist_group("trust-catalogue")


@pytest.fixture(scope="module")
def model(reduced, tmp_path_factory):  # noqa: F811
    return str(write_model(tmp_path_factory.mktemp("model") / "model.zip", *reduced))


@pytest.fixture
def predict(capsys, model):
    """``predict CSV ARGS --model MODEL`` in this process: (status, stdout, stderr)."""
    from sliders.runs.forecast.cli import main

    def run(path, *args):
        code = main(["predict", str(path), "--model", model, *map(str, args)])
        out = capsys.readouterr()
        return code, out.out, out.err

    return run


def csv(tmp_path, header, rows, name="cat.csv"):
    path = tmp_path / name
    path.write_text(header + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    return path


def one_line_refusal(code, out, err, *words):
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, (code, err)
    assert "internal error" not in err
    for w in words:
        assert w in lines[0], lines[0]


@pytest.fixture(scope="module")
def rate_rows():
    cat = rate_law_catalogue(0.6, 80.0, 0.5)
    return [f"{a:.12g}" for a in cat.alpha]


def test_first_without_last_is_refused(tmp_path, predict, rate_rows):
    path = csv(tmp_path, "angle [rad],size,first", [(a, 1, 3) for a in rate_rows])
    one_line_refusal(*predict(path), "'first' without 'last'")


def test_first_after_last_is_refused(tmp_path, predict, rate_rows):
    path = csv(tmp_path, "angle [rad],size,displacement,first,last",
               [(a, 1, 0.01, 7, 3) for a in rate_rows])
    one_line_refusal(*predict(path), "row 2", "after the last")


def test_more_sliders_than_the_movers_span_is_refused(tmp_path, predict, rate_rows):
    path = csv(tmp_path, "angle [rad],size,displacement,first,last",
               [(a, 9, 0.01, 3, 5) for a in rate_rows])
    one_line_refusal(*predict(path), "9 sliders moved between slider 3 and slider 5")


def test_sizes_in_an_arbitrary_unit_are_any_positive_number(tmp_path, predict, rate_rows):
    path = csv(tmp_path, "angle [rad],size", [(a, 13.9 + i % 7) for i, a in enumerate(rate_rows)])
    code, out, err = predict(path, "--size-unit", "arbitrary", "--min-size", "0.5", "--json")
    assert code == 0, err
    assert np.isfinite(json.loads(out)["alpha_c"])
    one_line_refusal(*predict(path), "13.9 is not a whole number of sliders")
    bad = csv(tmp_path, "angle [rad],size", [(a, -2.5) for a in rate_rows], "neg.csv")
    one_line_refusal(*predict(bad, "--size-unit", "arbitrary"), "positive number")


@pytest.mark.parametrize("flags, reason", [
    (("--angle-resolution", "30"), "angle error of 30°"),
    (("--missed-fraction", "0.7"), "share of 0.7 of the events missed"),
])
def test_a_measurement_outside_the_training_is_out_of_the_domain(tmp_path, predict, rate_rows,
                                                                  flags, reason):
    path = csv(tmp_path, "angle [rad],size", [(a, 1) for a in rate_rows])
    code, out, err = predict(path, *flags, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["in_domain"] is False and reason in d["domain_reason"], d["domain_reason"]
    assert d["fallback"] is True  # the interval widened, and said so
    inside = json.loads(predict(path, "--json")[1])
    assert d["interval"][1] - d["interval"][0] > inside["interval"][1] - inside["interval"][0]


def test_a_detection_threshold_above_the_training_is_out_of_the_domain(tmp_path, predict,
                                                                       rate_rows):
    path = csv(tmp_path, "angle [rad],size", [(a, 1000 + i % 50) for i, a in enumerate(rate_rows)])
    code, out, err = predict(path, "--min-size", "1000", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["in_domain"] is False and "smallest size detected of 1000" in d["domain_reason"]
    small = csv(tmp_path, "angle [rad],size", [(a, 1) for a in rate_rows], "small.csv")
    one_line_refusal(*predict(small, "--min-size", "1000"), "below the smallest size detected")


def test_every_event_at_one_angle_falls_back_with_its_reason_and_no_warning(tmp_path, predict):
    path = csv(tmp_path, "angle [deg],size", [("20.0", 1)] * 40)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code, out, err = predict(path, "--method", "ffm_ml_events", "--tilt-now", "20.5deg",
                                 "--json")
    assert code == 0, err
    assert "Warning" not in err and "nan" not in out.lower()
    d = json.loads(out)
    m = d["methods"]["ffm_ml_events"]
    assert np.isfinite(m["alpha_c"]) and m["fallback"] is True and m["fallback_reason"]


@pytest.mark.parametrize("tilt_deg", [60.0, 80.0, 89.0])
def test_past_the_training_angles_every_forecast_lies_between_the_tilt_and_90(
        tmp_path, predict, rate_rows, tilt_deg):
    path = csv(tmp_path, "angle [rad],size", [(a, 1) for a in rate_rows])
    code, out, err = predict(path, "--tilt-now", f"{tilt_deg}deg", "--method", "all", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["in_domain"] is False
    for name, m in d["methods"].items():
        lo, hi = m["interval"]
        assert math.radians(tilt_deg) <= lo <= m["alpha_c"] <= hi <= math.pi / 2, (name, m)


def test_a_forecast_object_is_clipped_and_marked():
    q = np.linspace(0.5, 1.7, 19)
    f = Forecast(q, 0.6, "test")
    assert f.clipped and f.quantiles.min() == 0.6 and f.quantiles.max() == math.pi / 2
    assert not Forecast(np.linspace(0.7, 0.9, 19), 0.6, "test").clipped
    with pytest.raises(ForecastError):
        Forecast(np.full(19, np.nan), 0.6, "test")


def test_the_python_api_refuses_a_catalogue_that_contradicts_its_measurement(reduced):  # noqa: F811
    f = reduced[0]["learned_blind"]
    k = np.arange(30)
    cat = Catalogue(0.01 * (k + 1), np.full(30, 9), np.full(30, 0.01), k, k + 2, tilt_now=0.4)
    with pytest.raises(ForecastError, match="9 sliders moved between"):
        f.predict(cat)
    f.predict(cat, Measurement(size_unit="arbitrary", min_size=1.0))


@pytest.mark.parametrize("option", [
    ("--within", "nan"), ("--within", "0"), ("--within", "1e400"),
    ("--angle-resolution", "-1"), ("--angle-resolution", "nan"), ("--angle-resolution", "inf"),
    ("--min-size", "0"), ("--min-size", "inf"), ("--min-size", "nan"),
    ("--missed-fraction", "1"), ("--missed-fraction", "-0.1"), ("--missed-fraction", "nan"),
    ("--sliders", "0"), ("--sliders", "1.5"), ("--tilt-now", "100deg"), ("--tilt-now", "nan"),
    ("--tilt-now", "-1deg"), ("--method", "nope"), ("--size-unit", "furlongs"), ("--model", ""),
    ("--model", "/nonexistent/m.zip"),
])
def test_every_bad_option_is_one_line(tmp_path, predict, rate_rows, option):
    path = csv(tmp_path, "angle [rad],size", [(a, 1) for a in rate_rows])
    code, out, err = predict(path, *option)
    one_line_refusal(code, out, err)
    assert out == ""


def test_a_header_with_control_sequences_is_escaped_in_the_refusal(tmp_path, predict, rate_rows):
    path = csv(tmp_path, "angle [rad],\x1b[2J\x1b[31msize", [(a, 1) for a in rate_rows])
    code, out, err = predict(path)
    one_line_refusal(code, out, err, "missing column 'size'", "\\x1b[2J")
    assert "\x1b" not in err
