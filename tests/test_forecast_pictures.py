"""Pictures a lab reads at a glance: the bench picture of a sparse, a normal and an
out-of-domain catalogue (whole-number event counts, the user's size unit, the live status
line, the legend off the data, a density that shows), the corner plot (the check's verdict,
axes fitted to a narrow posterior, a posterior piled at the prior's edge), and the gallery's
resolution.  Figure objects only: no model file is read but in the one test marked slow."""

from __future__ import annotations

import datetime
import math
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.text import Text

from sliders.analysis.forecast.base import LEVELS, Forecast
from sliders.figures.bench import bench_figure
from sliders.figures.posterior import corner_figure
from sliders.io.catalogue import Catalogue

GALLERY = Path(__file__).resolve().parents[1] / "docs" / "figures"
#: the shipped posterior's prior range (mu_d's: atan 11.3-47.7 deg)
PRIOR = {"mu_d": (0.2, 1.1), "mu_s_minus_mu_d": (0.01, 0.2), "sigma_mu": (0.002, 0.05),
         "xi": (1e-4, 1.0), "n_sliders": (8.0, 800.0)}


def catalogue(alpha_deg, size, tilt_deg=None) -> Catalogue:
    n = len(alpha_deg)
    zeros = np.zeros(n)
    return Catalogue(np.radians(alpha_deg), np.asarray(size), zeros, zeros.astype(int) - 1,
                     zeros.astype(int) - 1,
                     tilt_now=None if tilt_deg is None else math.radians(tilt_deg))


def forecast(quantiles_deg, tilt_deg) -> Forecast:
    return Forecast(np.radians(quantiles_deg), math.radians(tilt_deg), "learned_blind")


def picture(cat, fc, draw=False, **kw):
    """The bench picture of ``cat`` and ``fc`` (laid out and drawn if ``draw``)."""
    fig = bench_figure(cat, fc, label="learned (angles + sizes)", calibrated=kw.pop("calibrated", True),
                       in_domain=kw.pop("in_domain", True), domain_reason=kw.pop("reason", None),
                       probability="= 0.12", within=math.radians(1.0), **kw)
    if draw:
        FigureCanvasAgg(fig).draw()
    return fig


def texts(fig) -> str:
    return "\n".join(t.get_text() for t in fig.findobj(Text))


SPARSE = (catalogue([1.21, 2.03, 2.87], [1, 1, 3], 27.5),
          forecast(np.linspace(30.0, 62.0, LEVELS.size), 27.5))


def normal():
    rng = np.random.default_rng(7)
    alpha = np.round(31.0 - 31.0 * np.exp(-3.0 * np.sort(rng.random(150))), 4)
    size = np.maximum(1, np.round(rng.pareto(1.5, 150) + 1)).astype(int)
    return catalogue(alpha, size, 29.5), forecast(np.linspace(35.0, 46.0, LEVELS.size), 29.5)


def test_the_event_count_has_whole_number_ticks():
    for n in (1, 2, 3, 5):
        fig = picture(catalogue(np.linspace(5.0, 20.0, n), np.ones(n, int), 21.0),
                      forecast(np.linspace(25.0, 40.0, LEVELS.size), 21.0))
        top = fig.axes[0]
        lo, hi = top.get_ylim()
        ticks = [t for t in top.yaxis.get_majorticklocs() if lo <= t <= hi]
        assert len(ticks) >= 2 and all(float(t).is_integer() for t in ticks), (n, ticks)


@pytest.mark.slow  # seconds of work: the full suite
def test_the_size_axis_names_the_users_unit_and_its_labels_do_not_overlap():
    cat, fc = normal()
    mm2 = catalogue(np.degrees(cat.alpha), np.round(0.37 * cat.size, 1) + 0.1, 29.5)
    fig = picture(mm2, fc, size_unit="arbitrary", size_label="mm²")
    middle = fig.axes[1]
    assert "mm²" in middle.get_ylabel() and "size unit" not in middle.get_ylabel()
    assert "CSV's unit" in picture(mm2, fc, size_unit="arbitrary").axes[1].get_ylabel()
    assert "sliders" in picture(cat, fc).axes[1].get_ylabel()
    # one size, sizes within a decade (the sparse catalogue's 1-3) and over two: at least two
    # labels, none on another
    one = catalogue([5.0], [2], 10.0)
    for c in (one, SPARSE[0], mm2):
        ax = picture(c, fc if c is mm2 else SPARSE[1], draw=True).axes[1]
        boxes = [t.get_window_extent() for t in ax.get_yticklabels()
                 if t.get_visible() and t.get_text()]
        boxes += [t.get_window_extent() for t in ax.yaxis.get_minorticklabels()
                  if t.get_visible() and t.get_text()]
        assert len(boxes) >= 2
        for i, a in enumerate(boxes):
            for b in boxes[i + 1:]:
                assert not a.overlaps(b), (a, b)


def test_the_status_line_shows_alarm_threshold_time_rows_and_file():
    cat, fc = normal()
    status = {"alarm": True, "alarm_threshold": 0.35,
              "time": datetime.datetime(2026, 11, 28, 3, 40, 12), "rows": 150,
              "file": "/data/lab/pile_b.csv"}
    fig = picture(cat, fc, status=status)
    shown = texts(fig)
    for part in ("ALARM", "0.35", "2026-11-28 03:40:12", "150 rows", "/data/lab/pile_b.csv"):
        assert part in shown, part
    banner = [t for t in fig.findobj(Text) if t.get_gid() == "status"]
    assert banner and banner[0].axes.get_facecolor()[:3] == pytest.approx((0.769, 0.0, 0.0),
                                                                          abs=0.01)
    quiet = picture(cat, fc, status={"alarm": False, "time": "2026-11-28T03:41:00",
                                     "rows": 1})
    shown = texts(quiet)
    assert "no alarm" in shown and "ALARM" not in shown and "1 row" in shown
    assert "03:41:00" in shown
    assert not [t for t in picture(cat, fc).findobj(Text) if t.get_gid() == "status"]


def _points(ax):
    """Display coordinates of every point drawn from data in ``ax``: the lines in data
    coordinates (the event count's steps, the sizes' markers, the quantiles' ticks) and the
    collections (the sizes' stems), not the vertical lines and spans across the panel."""
    out = [ax.transData.transform(line.get_xydata()) for line in ax.get_lines()
           if line.get_transform() is ax.transData]
    out += [ax.transData.transform(path.vertices) for coll in ax.collections
            for path in coll.get_paths()]
    return np.vstack([p for p in out if p.size] or [np.empty((0, 2))])


@pytest.mark.parametrize("case", ["sparse", "normal", "out of the domain"])
def test_the_legend_is_off_the_data(case):
    cat, fc = SPARSE if case == "sparse" else normal()
    kw = {}
    if case == "out of the domain":
        cat = catalogue(50 + 0.28 * np.degrees(cat.alpha), cat.size, 58.8)
        fc = forecast(np.r_[np.linspace(58.84, 59.05, 9), np.linspace(75.0, 90.0, 10)], 58.8)
        kw = {"in_domain": False, "reason": "the tilt reached is above the training's",
              "calibrated": False}
    fig = picture(cat, fc, draw=True, **kw)
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend()] + list(fig.legends)
    assert legends
    data = np.vstack([_points(ax) for ax in fig.axes[:3]])
    for legend in legends:
        box = legend.get_window_extent()
        inside = ((data[:, 0] > box.x0) & (data[:, 0] < box.x1) & (data[:, 1] > box.y0)
                  & (data[:, 1] < box.y1))
        assert not inside.any(), data[inside][:5]


def test_out_of_the_domain_the_density_shows():
    # 40 % of the probability within 0.2° of the tilt, the rest over 16°
    q = np.r_[np.linspace(58.84, 59.05, 9), np.linspace(75.0, 90.0, 10)]
    fig = picture(catalogue([50.0, 55.0, 58.0], [1, 2, 1], 58.8), forecast(q, 58.8),
                  in_domain=False, reason="far", calibrated=False)
    bottom = fig.axes[2]
    width = np.diff(bottom.get_xlim())[0]
    stairs = [p for p in bottom.patches if type(p).__name__ == "StepPatch"]
    assert stairs
    edges = stairs[0].get_data().edges
    assert np.min(np.diff(edges)) >= 0.01 * width  # no bin too thin to see
    # every quantile ticked on the axis
    ticks = [line for line in bottom.get_lines() if line.get_marker() == "|"]
    assert ticks and np.allclose(np.sort(ticks[0].get_xdata()), np.degrees(
        forecast(q, 58.8).quantiles))


def draws(mu_d_deg=30.0, mu_d_sd=0.03, n=1000, seed=1, names=("mu_d", "mu_s_minus_mu_d")):
    """Posterior draws of ``names`` (the others' flat over the prior); two parameters by
    default, the corner plot of all five costs a second and a half."""
    rng = np.random.default_rng(seed)
    every = {"mu_d": np.tan(np.radians(rng.normal(mu_d_deg, mu_d_sd, n))),
            "mu_s_minus_mu_d": np.exp(rng.uniform(np.log(0.01), np.log(0.2), n)),
            "sigma_mu": np.exp(rng.uniform(np.log(0.002), np.log(0.05), n)),
            "xi": np.where(rng.random(n) < 0.3, 0.0, np.exp(rng.uniform(np.log(1e-4), 0, n))),
            "n_sliders": rng.choice([50.0, 71.0, 100.0, 141.0], n)}
    return {k: every[k] for k in names}


@pytest.mark.slow  # a corner plot drawn: 0.4-1.7 s
def test_the_corner_plot_fits_the_atan_mu_d_axis_to_a_narrow_posterior():
    fig = corner_figure(draws(30.0, 0.03, names=("mu_d", "xi")), PRIOR)
    low, high = fig.axes[0].get_xlim()
    assert low < 30.0 < high and high - low < 1.0  # not the prior's 11-48°
    # a posterior's draws keep a few per cent spread over the prior: the axis stays narrow,
    # and its title counts the draws off it
    d = draws(30.0, 0.03)
    d["mu_d"][:30] = np.random.default_rng(5).uniform(0.2, 1.1, 30)
    marginal = corner_figure(d, PRIOR).axes[0]
    low, high = marginal.get_xlim()
    assert high - low < 1.0 and "3 % of the draws off this axis" in marginal.get_title()
    # a broad posterior keeps the prior's range
    low, high = corner_figure(draws(30.0, 8.0), PRIOR).axes[0].get_xlim()
    assert low < math.degrees(math.atan(0.2)) and high > math.degrees(math.atan(1.1))


@pytest.mark.slow  # a corner plot drawn: 0.4-1.7 s
def test_the_corner_plot_says_a_posterior_piled_at_the_priors_edge():
    edge = math.degrees(math.atan(1.1))
    d = draws()
    d["mu_d"] = np.tan(np.radians(np.minimum(edge - np.abs(np.random.default_rng(3).normal(
        0.0, 0.8, d["mu_d"].size)), edge)))
    fig = corner_figure(d, PRIOR)
    marginal = fig.axes[0]
    assert "prior's upper edge" in marginal.get_title()
    low, high = marginal.get_xlim()
    assert high > edge and [x for line in marginal.get_lines()
                            for x in line.get_xdata() if x == pytest.approx(edge)]
    assert "edge" not in corner_figure(draws(30.0, 0.5), PRIOR).axes[0].get_title()


@pytest.mark.slow  # a corner plot drawn: 0.4-1.7 s
@pytest.mark.parametrize("check, said", [
    ({"reproduced": True, "p_values": {"centre": 0.2}}, "REPRODUCED"),
    ({"reproduced": False, "reasons": [{"test": "posterior_predictive", "detail": "x"}]},
     "NOT REPRODUCED"),
    ({"reproduced": None, "verdict": "undecided"}, "UNDECIDED"),
    ("skipped", "skipped")])
def test_the_corner_plot_carries_the_checks_verdict(check, said):
    shown = texts(corner_figure(draws(), PRIOR, check=check))
    assert said in shown
    if said == "REPRODUCED":
        assert "NOT REPRODUCED" not in shown


@pytest.mark.slow  # a corner plot drawn: 0.4-1.7 s
def test_infers_corner_plot_carries_its_own_verdict():
    from sliders.forecasting.infer import Inference

    report = {"parameters": {}, "check": {"reproduced": False, "reasons": [
        {"test": "prior_predictive", "detail": "far"}]}}
    assert "NOT REPRODUCED" in texts(Inference(report, draws(), PRIOR).figure())
    assert "skipped" in texts(Inference(report | {"check": None}, draws(), PRIOR).figure())


def png_dpi(path: Path):
    """The PNG's resolution (dots per inch along x and y) from its pHYs chunk, None without."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    at = 8
    while at < len(data):
        length, kind = struct.unpack(">I4s", data[at:at + 8])
        body = data[at + 8:at + 8 + length]
        assert zlib.crc32(kind + body) == struct.unpack(">I", data[at + 8 + length:
                                                                   at + 12 + length])[0]
        if kind == b"pHYs":
            x, y, unit = struct.unpack(">IIB", body)
            assert unit == 1, f"{path.name}: pHYs not in pixels per metre"
            return x * 0.0254, y * 0.0254
        if kind == b"IDAT":
            return None  # pHYs comes before the image data or not at all
        at += 12 + length
    return None


def test_every_gallery_png_is_300_dpi():
    pngs = sorted(GALLERY.glob("*.png"))
    assert len(pngs) >= 30
    for p in pngs:
        dpi = png_dpi(p)
        assert dpi is not None and dpi == pytest.approx((300, 300), abs=0.5), (p.name, dpi)


def test_predict_takes_a_size_label():
    from sliders.runs.forecast.cli import build_parser

    args = build_parser().parse_args(["predict", "pile.csv", "--size-label", "mm²"])
    assert args.size_label == "mm²"
    assert build_parser().parse_args(["predict", "pile.csv"]).size_label is None


@pytest.mark.slow
def test_the_api_carries_the_size_label_to_the_picture(shipped_model):
    cat, _ = normal()
    pred = shipped_model.predict({"angle [deg]": np.degrees(cat.alpha), "size": 0.5 * cat.size},
                                 size_unit="arbitrary", min_size=0.5, size_label="mm²")
    assert "mm²" in pred.figure().axes[1].get_ylabel()
    assert "mm²" in pred.figure(status={"rows": 150}).axes[1].get_ylabel()
