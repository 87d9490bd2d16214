"""A camera's catalogue: displacements in any unit and positions as fractions of the pile's
length read the same as the model's; the number of sliders told as a number or a range; the
edge of a noisy tilt.  Small synthetic sets (fast)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from sliders.analysis.forecast.features import Cuts, camera_features, displacement_scale
from sliders.analysis.forecast.base import EDGE_RESOLUTIONS, edge
from sliders.analysis.forecast.learned import Learned
from sliders.analysis.forecast.measurement import (Measurement, degrade, degrade_cuts,
                                                   tell_sliders)
from sliders.io.catalogue import Catalogue, CatalogueSet


def piles(n_rows: int, seed: int = 0) -> CatalogueSet:
    """Rows of accelerating catalogues with displacements growing towards the avalanche and
    movers' indices on piles of 20-200 sliders."""
    rng = np.random.default_rng(seed)
    cats, ac, ns = [], [], []
    for _ in range(n_rows):
        a_c, n = rng.uniform(0.3, 0.6), int(rng.choice([20, 50, 200]))
        i = np.arange(1, 1500)
        alpha = np.sort(a_c * (1.0 - np.exp(-(i + rng.uniform(0, 1, i.size)) / rng.uniform(30, 80))))
        alpha = alpha[alpha < a_c]
        k = alpha.size
        size = rng.integers(1, 5, k)
        first = rng.integers(0, n - 4, k)
        disp = size * 0.01 * (1.0 + 0.02 / (a_c - alpha + 0.002)) * rng.uniform(0.5, 1.5, k)
        cats.append(Catalogue(alpha, size, disp, first, first + size - 1))
        ac.append(a_c)
        ns.append(n)
    return CatalogueSet.from_catalogues(cats, {"mu_d": np.tan(np.array(ac)) - 0.003,
                                               "n_sliders": np.array(ns)}, ac,
                                        ["avalanche"] * n_rows)


def in_camera_units(cat: Catalogue, n: int, scale: float, length_mm: float | None = None):
    """``cat`` as a camera records it, and its measurement: displacements times ``scale``;
    positions as fractions of the pile's length, or in mm along a pile ``length_mm`` long."""
    first, last = (cat.first + 0.5) / n, (cat.last + 0.5) / n
    m = CAMERA
    if length_mm is not None:
        first, last = first * length_mm, last * length_mm
        m = replace(CAMERA, position_unit="mm", pile_length=length_mm)
    return Catalogue(cat.alpha, cat.size, cat.displacement * scale, first, last,
                     tilt_now=cat.tilt_now), m


CAMERA = Measurement(displacement_unit="arbitrary", position_unit="fraction")


def test_camera_features_do_not_depend_on_the_displacement_unit_or_the_position_unit():
    cset = piles(1, seed=4)
    cat = cset.catalogue(0).cut(0.9 * float(cset.alpha_c[0]))
    n = int(cset.parameters["n_sliders"][0])
    model = camera_features(cat, Measurement(n_sliders=n))
    for scale, length in ((1e-3, None), (1.0, 850.0), (1e3, 0.37)):
        other = camera_features(*in_camera_units(cat, n, scale, length))
        for key, v in model.items():
            assert other[key] == pytest.approx(v, rel=1e-12, nan_ok=True), key
    # the displacement's own scale is the median displacement per mover
    assert displacement_scale(cat) == pytest.approx(np.median(cat.displacement / cat.size))


@pytest.mark.slow
def test_a_camera_forecast_is_the_same_in_any_unit():
    train = piles(40, seed=1)
    f = Learned(inputs="camera", draws_per_row=6, max_iter=15, random_state=0).fit(train)
    assert f.name == "learned_camera"
    test = piles(4, seed=2)
    rows = np.arange(4)
    base = [test.catalogue(r).cut(0.95 * float(test.alpha_c[r])) for r in rows]
    n = np.asarray(test.parameters["n_sliders"])
    qs = []
    for scale, length in ((1e-3, None), (1.0, None), (1e3, 1200.0)):
        seen = [in_camera_units(c, int(k), scale, length) for c, k in zip(base, n)]
        cuts = Cuts([c for c, _ in seen], np.full(len(seen), -1), measurement=[m for _, m in seen])
        qs.append(f.quantiles(cuts)[0])
    assert np.isfinite(qs[0]).all()
    for q in qs[1:]:
        np.testing.assert_allclose(q, qs[0], rtol=0, atol=1e-9)


def test_a_cameras_training_catalogues_are_in_its_units():
    cset = piles(6, seed=3)
    rng = np.random.default_rng(0)
    cuts = Cuts.from_set(cset, np.arange(6), 0.9 * np.asarray(cset.alpha_c))
    cam = degrade_cuts(cuts, rng, camera=True)
    for c, m, k in zip(cam.catalogues, cam.measurements(), cuts.n_sliders):
        assert m.displacement_unit == "arbitrary" and m.position_unit == "fraction"
        known = c.first >= 0
        assert ((c.first[known] > 0) & (c.last[known] < 1)).all()
        assert np.allclose(np.round(c.first[known] * k - 0.5), c.first[known] * k - 0.5)
    scales = [displacement_scale(c) / displacement_scale(o) for c, o in
              zip(cam.catalogues, cuts.catalogues)]
    assert max(scales) / min(scales) > 3  # one unit per catalogue
    # without the piles' numbers of sliders a camera's positions are unknown
    unknown = degrade_cuts(replace(cuts, n_sliders=None), rng, camera=True)
    assert all((c.first == -1).all() for c in unknown.catalogues)
    assert sum(len(c) for c in unknown.catalogues) > 0


def test_the_number_of_sliders_told_holds_the_truth_as_a_number_or_a_range():
    rng = np.random.default_rng(1)
    n = rng.choice([8, 50, 800], 400)
    told = tell_sliders([Measurement()] * 400, n, rng, {"p_told": 0.5, "p_exact": 0.4,
                                                         "range_factor": 4.0})
    low = np.array([m.n_sliders or 0 for m in told])
    high = np.array([m.n_sliders_high or m.n_sliders or 0 for m in told])
    some = low > 0
    assert 0.4 < some.mean() < 0.6  # told to half of them
    assert ((low[some] <= n[some]) & (n[some] <= high[some])).all()
    ranges = some & (high > low)
    assert 0.4 < ranges[some].mean() < 0.8 and (high[ranges] / low[ranges] <= 16.5).all()
    x = Measurement(n_sliders=100, n_sliders_high=300).as_features(Catalogue([], [], [], [], []))
    assert x[-2:] == pytest.approx([math.log(100), math.log(300)])
    with pytest.raises(ValueError, match="range"):
        Measurement(n_sliders=300, n_sliders_high=100)
    with pytest.raises(ValueError, match="pile's length"):
        Measurement(position_unit="mm")
    with pytest.raises(ValueError, match="position unit mm"):
        Measurement(pile_length=300.0)


def test_a_noisy_tilts_avalanche_may_lie_below_its_last_angle():
    cat = piles(1, seed=5).catalogue(0).cut(0.5)
    rng = np.random.default_rng(2)
    noisy = Measurement(angle_resolution=math.radians(0.3))
    seen = degrade(cat, noisy, rng)
    assert seen.tilt_now >= seen.alpha[-1] and seen.tilt_now >= cat.tilt_now
    cuts = Cuts.from_catalogues([seen, cat], noisy)
    assert edge(cuts) == pytest.approx(np.array([seen.tilt_now, cat.tilt_now])
                                       - EDGE_RESOLUTIONS * math.radians(0.3))
    assert edge(Cuts.from_catalogues([cat]))[0] == cat.tilt_now
    # a forecast keeps quantiles down to its floor, not to the noisy tilt reached
    from sliders.analysis.forecast.base import LEVELS, Forecast

    q = 0.5 + 0.02 * (LEVELS - 0.2)
    kept = Forecast(q, 0.5, "learned_blind", floor=0.49)
    assert kept.interval[0] < 0.5 and not kept.clipped
    assert Forecast(q, 0.5, "learned_blind").interval[0] == 0.5
    assert Forecast(q, 0.5, "learned_blind", floor=0.4985).clipped


@pytest.mark.parametrize("xi", [0.0, 0.003])
def test_lone_slips_give_mu_d_and_the_cameras_unit_from_the_tilt_itself(xi):
    from sliders.analysis.forecast.features import (UNIT_PAIRS, coupled_lone_slips,
                                                    in_model_units, scale_free_lone_slips)
    from sliders.driver import run
    from sliders.scene import Scene

    scene = Scene(n_sliders=100, seed=3, mu_d=0.6, mu_s_mean=0.66, sigma_mu=0.01, xi=xi,
                  mode="explore", record="displacements")
    result = run(scene, "fortran")
    cat = Catalogue.from_result(result).cut(result.alpha_c - math.radians(1.0))
    mu_d, _, agree = coupled_lone_slips(cat)
    assert agree >= 4 and mu_d == pytest.approx(0.6, abs=1e-6)
    for scale in (1e-3, 250.0):
        seen = degrade(cat, CAMERA, np.random.default_rng(0), camera=(scale, 0.0), n_sliders=100)
        mu, unit, n, misfit = scale_free_lone_slips(seen, CAMERA)
        assert n == agree and mu == pytest.approx(mu_d, rel=1e-9) and misfit < 1e-6
        if xi == 0.0:  # the unit itself: model units per camera unit
            assert unit == pytest.approx(1.0 / scale, rel=1e-6)
        # read back in the model's units: the movers' indices and displacements in g tau^2
        back, unit, pairs = in_model_units(seen, CAMERA)
        assert pairs >= UNIT_PAIRS and unit == pytest.approx(1.0 / scale, rel=1e-3)
        assert (back.first == cat.first).all() and (back.last == cat.last).all()
        np.testing.assert_allclose(back.displacement, cat.displacement, rtol=1e-3)
    noisy = degrade(cat, CAMERA, np.random.default_rng(0), camera=(2.0, 0.05), n_sliders=100)
    assert in_model_units(noisy, CAMERA)[0] is None  # a noisy record's unit is not read


@pytest.fixture(scope="module")
def pile_near_its_end():
    """A simulated pile of 100 sliders cut 1° before its avalanche (its catalogue complete)."""
    from sliders.driver import run
    from sliders.scene import Scene

    result = run(Scene(n_sliders=100, seed=11, mu_d=0.55, mu_s_mean=0.6, sigma_mu=0.01,
                       mode="explore", record="displacements"), "fortran")
    return Catalogue.from_result(result).cut(result.alpha_c - math.radians(1.0)), result.alpha_c


@pytest.mark.parametrize("noise", [0.0, 0.1])
def test_the_api_forecasts_a_camera_catalogue_alike_in_any_unit(pile_near_its_end, noise,
                                                                 shipped_model):
    model = shipped_model
    cat, alpha_c = pile_near_its_end
    rng = np.random.default_rng(3)
    disp = cat.displacement * np.exp(rng.normal(0.0, noise, len(cat)))
    out = []
    for scale, length in ((1e-3, None), (1.0, 1000.0), (1e3, 37.5)):
        pos = {k: (getattr(cat, k) + 0.5) / 100 * (length or 1.0) for k in ("first", "last")}
        cols = {"angle [rad]": cat.alpha, "size": cat.size, "displacement": disp * scale, **pos}
        units = {"position_unit": "mm", "pile_length": length} if length else \
            {"position_unit": "fraction"}
        d = model.predict(cols, displacement_unit="arbitrary", **units).to_dict()
        out.append(d)
        assert isinstance(d["alarm"], bool) and d["alarm"] == (
            d["probability_within_raw"] >= d["alarm_threshold"])
    for d in out[1:]:
        assert d["alpha_c"] == pytest.approx(out[0]["alpha_c"], abs=1e-9)
        assert d["interval"] == pytest.approx(out[0]["interval"], abs=1e-9)
    read = any("camera's unit read from" in n for n in out[0]["notes"])
    # an exact record's unit is read from its lone slips; a noisy one's goes to learned_camera
    assert read == (noise == 0.0)
    assert out[0]["forecaster"] == ("learned" if noise == 0.0 else "learned_camera")
