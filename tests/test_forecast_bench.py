"""The bench picture (``predict --plot``): what it draws, in degrees, and that it is whole."""

from __future__ import annotations

import math

import numpy as np
import pytest


from helpers import SMALL_CATALOGUE, accelerating


@pytest.fixture(scope="module")
def model(shipped_model):
    """The shipped model (the session's)."""
    return shipped_model


def test_the_picture_shows_catalogue_forecast_tilt_and_verdict(model, tmp_path):
    alpha, size = accelerating()
    pred = model.predict({"angle [deg]": alpha, "size": size}, tilt_now="29.5deg")
    fig = pred.figure()
    top, middle, bottom = fig.axes
    assert "°" in bottom.get_xlabel() and "events" in top.get_ylabel()
    assert "sliders" in middle.get_ylabel() and "1/°" in bottom.get_ylabel()
    # the cumulative events reach the number of events, at the tilt reached (degrees)
    steps = top.lines[0]
    assert steps.get_ydata()[-1] == len(alpha)
    assert steps.get_xdata()[-1] == pytest.approx(29.5)
    title = fig._suptitle.get_text()
    d = pred.to_dict()
    assert f"{math.degrees(d['alpha_c']):.2f}°" in title and "P(within the next 1°)" in title
    assert "80 % interval" in title and "in the training domain" in top.get_title(loc="left")
    legend = " ".join(t.get_text() for t in bottom.get_legend().get_texts())
    lo, hi = np.degrees(d["interval"])
    assert f"{lo:.2f}-{hi:.2f}°" in legend
    out = tmp_path / "out.png"
    pred.plot(out)
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data.endswith(b"IEND\xaeB`\x82")
    assert [p.name for p in tmp_path.iterdir()] == ["out.png"]


def test_out_of_the_domain_the_picture_says_so(model, tmp_path):
    p = tmp_path / "small.csv"
    p.write_text(SMALL_CATALOGUE)
    fig = model.predict(p, tilt_now="27.5deg").figure()
    assert "OUT OF THE TRAINING DOMAIN" in fig.axes[0].get_title(loc="left")
    assert "widened interval, uncalibrated" in fig._suptitle.get_text()
    assert "80 % interval" not in fig._suptitle.get_text()
