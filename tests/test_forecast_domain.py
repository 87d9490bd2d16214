"""The domain check: a scikit-learn-style estimator that reads a catalogue through its measurement."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.base import clone

from sliders.analysis.forecast import Cuts, Measurement, training_cuts
from sliders.analysis.forecast.domain import DOMAIN_FEATURES, DomainCheck, domain_features
from sliders.analysis.forecast.learned import Learned
from sliders.analysis.forecast.measurement import degrade_cuts
from sliders.io.catalogue import Catalogue

from helpers import domain_check_of_piles_50_to_800, synthetic_set


@pytest.fixture(scope="module")
def fitted():
    """A domain check fitted on degraded cuts of synthetic rows (thousands of events each)."""
    train = synthetic_set(60, seed=1)
    rng = np.random.default_rng(0)
    cuts = degrade_cuts(training_cuts(train, 20, rng), rng)
    return DomainCheck().fit(cuts, train.alpha_c), train


def sparse_pile(tilt=0.3, n=12):
    """A few lone slips spread over the tilt: the catalogue of a pile of a few sliders."""
    alpha = np.linspace(0.08, tilt - 0.01, n)
    return Catalogue(alpha, np.ones(n), np.zeros(n), -np.ones(n), -np.ones(n), tilt_now=tilt)


def test_a_few_events_told_complete_are_out_of_the_domain(fitted):
    """Training catalogues of some 20-60 events by 0.3 rad, up to 60 % of them missed: three or
    twelve lone slips said to be complete are none of them; a training-like cut is in."""
    check, _ = fitted
    few = [sparse_pile(n=3), sparse_pile(n=12)]
    inside, why = check.check(Cuts.from_catalogues(few, Measurement()))
    assert not inside.any() and all("measurement" in w for w in why)
    row = Cuts.from_catalogues([synthetic_set(3, seed=9).catalogue(k).cut(0.25) for k in range(3)])
    inside, why = check.check(row)
    assert inside.all() and why == ["", "", ""]


def test_rates_are_read_as_if_no_event_were_missed(fitted):
    """Half the events missed, and said so: the rates are those of the whole catalogue."""
    cat = synthetic_set(1, seed=4).catalogue(0).cut(0.25)
    half = Catalogue(cat.alpha[::2], cat.size[::2], cat.displacement[::2], cat.first[::2],
                     cat.last[::2], tilt_now=cat.tilt_now)
    told = domain_features(Cuts.from_catalogues([half], Measurement(missed_fraction=0.5)))
    whole = domain_features(Cuts.from_catalogues([cat]))
    rate = DOMAIN_FEATURES.index("log_rate")
    assert told[0, rate] == pytest.approx(whole[0, rate], abs=0.01)


def test_domain_check_is_a_scikit_learn_estimator(fitted):
    check, _ = fitted
    copy = clone(check)
    assert copy.get_params() == check.get_params() and not hasattr(copy, "detectors_")
    assert len(check.detectors_) == 3 and 0.3 < check.top_tilt_ <= 0.6
    with pytest.raises(ValueError, match="unknown domain features"):
        DomainCheck(features=("tilt", "mu_d")).fit(Cuts.from_catalogues([sparse_pile()]), [0.5])


@pytest.mark.slow  # seconds of work: the full suite
def test_learned_delegates_its_domain_to_the_check():
    f = Learned(inputs="angles_sizes", draws_per_row=20, max_iter=5).fit(synthetic_set(60, seed=2))
    assert isinstance(f.domain_, DomainCheck)
    inside, why = f.domain(Cuts.from_catalogues([sparse_pile(n=3)]))
    assert not inside[0] and "local outlier factor" in why[0]
    f.domain_ = f.domain_.detectors_[0]  # a model file of another version: a pipeline there
    with pytest.raises(AttributeError, match="another version"):
        f.domain(Cuts.from_catalogues([sparse_pile()]))


def test_a_pile_told_its_number_of_sliders_is_checked_against_the_training_piles():
    """The training piles hold 50-800 sliders: a catalogue like theirs, told it comes from 16
    sliders, is out of the domain and says why; told 100, it is in; told nothing, as before."""
    check, train, cuts, cat = domain_check_of_piles_50_to_800()
    assert list(check.n_sliders_range_) == [50.0, 800.0]
    for told, expected in ((16, False), (100, True), (None, True), (801, False)):
        inside, why = check.check(Cuts.from_catalogues([cat], Measurement(n_sliders=told)))
        assert bool(inside[0]) is expected, (told, why)
        assert (f"a pile of {told} sliders, outside the training piles' 50-800" in why[0]) \
            is (not expected)
    assert DomainCheck().fit(cuts, train.alpha_c).n_sliders_range_ is None
    with pytest.raises(ValueError, match="number of sliders"):
        Measurement(n_sliders=0)
