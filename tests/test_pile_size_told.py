"""The pile's number of sliders told (``--sliders``, ``sliders=``) conditions the forecast.

A forecaster of angles and sizes of its own (``learned_sized``) is trained on cuts each told
their pile's size (exactly or as a range), and calibrated apart for each kind of record
(``learned.record_category``): the size class told, and exact or noisy angles.  Its
coverage per size class is measured in benchmarks/forecast_conditions.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import domain_check_of_piles_50_to_800, rate_law_catalogue
from sliders.analysis.forecast import Measurement
from sliders.analysis.forecast.features import Cuts
from sliders.analysis.forecast.fitting import fit_sharing_cuts
from sliders.analysis.forecast.learned import (RECORD_CATEGORIES, TOLD_CLASSES, Learned,
                                               record_category)
from sliders.io.catalogue import Catalogue
from sliders.runs.forecast.catalogue import load_set


def test_each_kind_of_record_has_its_own_category():
    """Untold, told below 50, 50-199 and from 200 (a range by its geometric middle), each with
    exact or noisy angles: eight distinct categories, as documented."""
    cat = rate_law_catalogue(0.6, 80.0, 0.5)
    noisy = math.radians(0.15)
    kinds = [Measurement(), Measurement(n_sliders=16), Measurement(n_sliders=50),
             Measurement(n_sliders=100, n_sliders_high=300), Measurement(n_sliders=400),
             Measurement(angle_resolution=noisy),
             Measurement(angle_resolution=noisy, n_sliders=20, n_sliders_high=40),
             Measurement(angle_resolution=noisy, n_sliders=199),
             Measurement(angle_resolution=noisy, n_sliders=150, n_sliders_high=600)]
    got = [int(record_category(Cuts.from_catalogues([cat], m))[0]) for m in kinds]
    assert got == [0, 1, 2, 2, 3, 4, 5, 6, 7]
    assert RECORD_CATEGORIES == 2 * (TOLD_CLASSES.size + 2) == len(set(got))


def test_the_shipped_forecast_moves_with_the_size_told(shipped_model):
    """One catalogue of angles and sizes told it comes from 16, 100 or 600 sliders: the
    forecaster trained told the size gives three different forecasts, each different from the
    untold one (the forecaster of angles and sizes alone), as is the forecast told a range."""
    cat = rate_law_catalogue(0.6, 80.0, 0.5)
    n = len(cat)  # a record of angles and sizes only: no displacement, no movers
    cat = Catalogue(cat.alpha, cat.size, np.full(n, np.nan), np.full(n, -1), np.full(n, -1),
                    cat.tilt_now)
    untold = shipped_model.predict(cat).to_dict()
    told = {n: shipped_model.predict(cat, sliders=n).to_dict() for n in (16, 100, 600)}
    assert untold["forecaster"] == "learned_blind"
    assert all(f["forecaster"] == "learned_sized" for f in told.values()), told
    medians = {n: f["alpha_c"] for n, f in told.items()}
    assert len({round(m, 9) for m in medians.values()}) == 3, medians
    assert all(abs(m - untold["alpha_c"]) > 1e-6 for m in medians.values()), (medians, untold)
    spread = shipped_model.predict(cat, sliders="50-200").to_dict()
    assert spread["forecaster"] == "learned_sized" and abs(spread["alpha_c"] - untold["alpha_c"]) > 1e-6


def test_the_sized_forecaster_calibrates_each_size_class_apart(shipped):
    """The forecaster told the size: one catalogue told 16, 100 or 400 sliders, with exact or
    noisy angles, falls in calibration bins no other kind shares."""
    models, _ = shipped
    f = models["learned_sized"]
    assert f.told_share == 1.0 and f.calibration_edges_.shape[0] == RECORD_CATEGORIES
    cat = rate_law_catalogue(0.6, 80.0, 0.5)
    noisy = math.radians(0.15)
    kinds = [Measurement(n_sliders=16), Measurement(n_sliders=100), Measurement(n_sliders=400),
             Measurement(n_sliders=16, angle_resolution=noisy),
             Measurement(n_sliders=400, angle_resolution=noisy)]
    bins = [int(f._calibration_bin(Cuts.from_catalogues([cat], m), np.zeros(1))[0]) for m in kinds]
    assert len(set(bins)) == len(kinds), bins


@pytest.mark.slow
def test_a_size_told_as_a_range_is_outside_only_when_no_size_of_it_is_a_training_piles():
    """The training piles hold 50-800 sliders: told 16-60 or 700-1000 a pile is in the domain
    (some size of the range is a training pile's); told 10-40 or 900-2000, it is out, and the
    reason names the range."""
    check, _, _, cat = domain_check_of_piles_50_to_800()
    for (lo, hi), expected in (((16, 60), True), ((700, 1000), True), ((10, 40), False),
                               ((900, 2000), False)):
        inside, why = check.check(Cuts.from_catalogues(
            [cat], Measurement(n_sliders=lo, n_sliders_high=hi)))
        assert bool(inside[0]) is expected, (lo, hi, why)
        assert (f"a pile of {lo}-{hi} sliders, outside the training piles' 50-800" in why[0]) \
            is (not expected)


@pytest.mark.slow
def test_each_kind_of_training_cut_is_drawn_for_the_forecasters_that_read_it(small_prior):
    """Forecasters fitted together share their training cuts only with those that read the
    same kind: angles and sizes untold, the same told their pile's size, a camera's record.
    The forecaster told the size reads it as a feature; the one not told does not."""
    train = load_set(str(small_prior[1]))
    shared: dict = {}
    blind, sized, camera = (fit_sharing_cuts(Learned(inputs=i, told_share=t, max_iter=3), train,
                                             None, shared, 0)
                            for i, t in (("angles_sizes", 0.0), ("angles_sizes", 1.0),
                                         ("camera", 0.0)))
    assert len(shared) == 3
    cuts = {k[1:]: v["cuts"] for k, v in shared.items()}
    assert all(m.n_sliders is None for m in cuts[(False, 0.0)].measurements())
    assert all(m.n_sliders is not None for m in cuts[(False, 1.0)].measurements())
    assert all(m.displacement_unit == "arbitrary" for m in cuts[(True, 0.0)].measurements())
    assert "log_sliders_low" in sized.feature_names_
    assert "log_sliders_low" not in blind.feature_names_ + camera.feature_names_


def test_a_catalogue_kept_to_its_angles_and_sizes_is_read_by_them(shipped_model):
    """``Catalogue.angles_and_sizes()`` (displacements 0, movers unknown) given to the API is
    forecast as a record of angles and sizes, as the same record read from a CSV of two
    columns, not as a camera's; told its size, by the forecaster told it."""
    cat = rate_law_catalogue(0.6, 80.0, 0.5).angles_and_sizes()
    n = len(cat)
    read = Catalogue(cat.alpha, cat.size, np.full(n, np.nan), np.full(n, -1), np.full(n, -1),
                     cat.tilt_now)
    kept, as_read = shipped_model.predict(cat).to_dict(), shipped_model.predict(read).to_dict()
    assert kept["forecaster"] == as_read["forecaster"] == "learned_blind"
    assert kept["alpha_c"] == as_read["alpha_c"] and kept["interval"] == as_read["interval"]
    assert shipped_model.predict(cat, sliders=100).to_dict()["forecaster"] == "learned_sized"
