"""A posterior file (``train --fit posterior``, read by ``infer``) and a forecaster's
expected-accuracy table are data the package checks on load, like the rest of a model file.

Each attack writes a copy of the shipped posterior (or of the reduced shipped forecasters,
``reduced`` in conftest.py) with one table changed, with no check on writing
(``helpers.write_model``): a mu_d range below 0, numbers of sliders that are not whole, a
sigma_mu of 10^400, a stored prior that is not JSON, 3 million sliders on a machine without the
memory for such a pile, an expected accuracy of coverage 7.5, error -3, NaN or a missing column.
Every one must be one line naming the file and the table, exit 2.  The predictive check's piles
stop at once on Ctrl-C or SIGTERM, also while their chains are prepared.
"""

from __future__ import annotations

import copy
import math
import re
import types
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from sliders.io.forecast_files import ForecastInputError
from sliders.analysis.forecast.evaluation import ACCURACY_FIELDS
from sliders.analysis.forecast.integrity import IntegrityError, check_fields
from sliders.runs.forecast import cli
from sliders.forecasting.infer import load_posterior
from sliders.runs.forecast.infer import CHECK_SIMULATION, simulate_pile
from sliders.scene import Scene

from helpers import write_model

#: a catalogue of a pile of the shipped posterior's prior, cut before its avalanche
CATALOGUE = "angle [deg],size\n10,1\n12,1\n15,2\n18,1\n20,3\n21,1\n22,4\n"
#: the held-out accuracy of a forecaster as ``train`` stores it (two lead bins)
TABLE = {"lead_edges_deg": [0.0, 2.0], "median_abs_deg": [0.4, 1.5], "coverage": [0.8, 0.78],
         "n": [40.0, 300.0], "overall": {"median_abs_deg": 1.2, "coverage": 0.79, "n": 340.0,
                                         "rows": 60.0}}


def refused_in_one_line(capsys, args, path, *words) -> str:
    capsys.readouterr()
    assert cli.main([str(a) for a in args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "internal error" not in err, err
    for w in (str(path), *words):
        assert w in err, err
    return err


# -- the expected-accuracy table, as data --------------------------------------------------
def _changed(change):
    t = copy.deepcopy(TABLE)
    change(t)
    return t


def check_accuracy_table(table) -> None:
    """``table`` checked as a model file's forecaster's (``evaluation.ACCURACY_FIELDS``)."""
    check_fields(types.SimpleNamespace(expected_accuracy_=table), "", ACCURACY_FIELDS)


@pytest.mark.parametrize("change, words", [
    (lambda t: t.__setitem__("coverage", [7.5, 0.8]), "coverage holds values above 1"),
    (lambda t: t.__setitem__("median_abs_deg", [-3.0, 1.0]), "median_abs_deg holds values below"),
    (lambda t: t.__setitem__("median_abs_deg", [math.inf, 1.0]), "NaN or infinite"),
    (lambda t: t.__setitem__("coverage", [math.nan, 0.8]), "NaN or infinite"),
    (lambda t: t.pop("coverage"), "not a dict of lead_edges_deg"),
    (lambda t: t["overall"].pop("median_abs_deg"), "overall is not a dict of"),
    (lambda t: t.__setitem__("n", [40.0]), "n has shape (1,), not (2,)"),
    (lambda t: t.__setitem__("lead_edges_deg", [2.0, 0.0]), "increasing"),
    (lambda t: t["overall"].__setitem__("coverage", 1.5), "overall.coverage = 1.5"),
    (lambda t: t.__setitem__("coverage", "0.8"), "coverage is a str, not an array"),
    (lambda t: t.__setitem__("coverage", ["0.8", "0.7"]), "coverage has dtype <U3"),
    (lambda t: t.__setitem__("by_width", {"width_edges_deg": [[1.0, 2.0]] * 2}), "by_width is not"),
])
def test_an_expected_accuracy_table_out_of_its_ranges_is_refused(change, words):
    check_accuracy_table(TABLE)  # the table as train writes it
    check_accuracy_table(None)  # a forecaster trained without held-out piles has none
    check_accuracy_table({})
    with pytest.raises(IntegrityError, match=re.escape(words)):
        check_accuracy_table(_changed(change))


@pytest.mark.slow
@pytest.mark.parametrize("change, words", [
    (lambda t: t.__setitem__("coverage", [7.5] * len(t["coverage"])), "coverage"),
    (lambda t: t.__setitem__("median_abs_deg", [-3.0] * len(t["coverage"])), "median_abs_deg"),
    (lambda t: t.__setitem__("median_abs_deg", [math.inf] * len(t["coverage"])), "infinite"),
    (lambda t: t.pop("coverage"), "expected_accuracy_ is not a dict"),
])
def test_predict_refuses_a_model_whose_expected_accuracy_is_out_of_range(reduced, tmp_path,
                                                                          capsys, change, words):
    """Was "typical error -3.0°; covered 7.50", "inf° ... covered nan", an internal error."""
    models, prov = copy.deepcopy(reduced)
    change(models["learned_blind"].expected_accuracy_)
    path = write_model(tmp_path / "model.zip", models, prov)
    (tmp_path / "c.csv").write_text(CATALOGUE)
    refused_in_one_line(capsys, ["predict", tmp_path / "c.csv", "--model", path], path,
                        "learned_blind.expected_accuracy_", words)


# -- the posterior's tables and its prior --------------------------------------------------
@pytest.fixture(scope="module")
def posterior():
    """The shipped posterior and its provenance, loaded once (as ``infer`` loads it)."""
    model = load_posterior()
    return model.posterior, dict(model.provenance)


def crafted(posterior, tmp_path, change, name="posterior.zip"):
    """A copy of the shipped posterior changed by ``change(posterior)``, written unchecked."""
    post, prov = posterior
    p = copy.copy(post)
    p.low_, p.high_ = post.low_.copy(), post.high_.copy()
    change(p)
    return write_model(tmp_path / name, {"posterior": p}, dict(prov))


def _numbers_of_sliders(values):
    def change(p):
        k = p.parameters_.index("n_sliders")
        p.n_sliders_values_ = np.array(values, dtype=float)
        p.low_[k], p.high_[k] = np.log10(values[0]), np.log10(values[-1])
    return change


def _range(name, low, high):
    def change(p):
        k = p.parameters_.index(name)
        p.low_[k], p.high_[k] = low, high
    return change


def _wider_regressor(p):
    """One regressor reading a feature more than the posterior makes."""
    tree = copy.copy(p.models_[0][0])
    tree.n_features_in_ += 1
    p.models_ = [list(row) for row in p.models_]
    p.models_[0][0] = tree


def _every_reader_wider(p):
    """The posterior and all its regressors reading a feature more than the design has."""
    p.n_features_in_ += 1
    p.models_ = [[copy.copy(tree) for tree in row] for row in p.models_]
    for row in p.models_:
        for tree in row:
            tree.n_features_in_ += 1


@pytest.mark.slow
@pytest.mark.parametrize("change, words", [
    (lambda p: None, None),  # the shipped posterior's tables, written again: accepted
    (_range("mu_d", -5.0, -4.0), "mu_d"),  # was "atan(mu_d) -75.96°", exit 0
    (_numbers_of_sliders([2.5, 3.5]), "numbers of sliders"),  # was "N: 4 ... most probable 3"
    (_numbers_of_sliders([1.0, 8.0]), "n_sliders"),  # one slider is no chain
    (_range("sigma_mu", -2.7, 400.0), "sigma_mu"),  # was an internal error
    (_range("n_sliders", 0.0, 2.0), "n_sliders"),  # not the range of its numbers of sliders
    (lambda p: setattr(p, "prior_", "{not json"), "prior is not JSON"),  # was an internal error
    (lambda p: setattr(p, "prior_", "[1, 2]"), "not a prior's tables"),
    (lambda p: setattr(p, "xi_zero_code_", p.xi_zero_code_ - 3.0), "xi's zero"),
    (lambda p: setattr(p, "mu_d_reference_", -0.5), "mu_d's reference"),
    (lambda p: setattr(p, "prior_", '{"parameters": {}, "scene": {"n_sliders": "many"}}'),
     "the stored prior"),
    (_range("mu_d", 0.5, 0.1), "a prior range is reversed"),
    (lambda p: setattr(p, "copula_", np.ones_like(p.copula_)), "copula is not a positive"),
    (_wider_regressor, "a regressor reads another number of features"),
    (_every_reader_wider, "n_features_in_"),  # consistent together, not with the design
])
def test_every_table_of_a_posterior_file_is_checked_on_load(posterior, tmp_path, capsys, change,
                                                            words):
    path = crafted(posterior, tmp_path, change)
    (tmp_path / "c.csv").write_text(CATALOGUE)
    args = ["infer", tmp_path / "c.csv", "--posterior", path, "--no-check"]
    if words is None:
        assert cli.main([str(a) for a in args]) == 0
        assert "atan(mu_d)" in capsys.readouterr().out
        return
    refused_in_one_line(capsys, args, path, words)


@pytest.mark.slow
def test_numbers_of_sliders_beyond_the_memory_are_refused_on_load(posterior, tmp_path,
                                                                   monkeypatch):
    """3 million sliders make piles of about 11 GB: refused as an ensemble of them is, against
    the memory available (here made 4 GB), before anything is simulated, also with
    --no-check; 800 sliders (the shipped prior's most) fit."""
    import sliders.scene

    monkeypatch.setattr(sliders.scene, "available_memory", lambda: 4 * 10**9)
    load_posterior(crafted(posterior, tmp_path, lambda p: None, "fits.zip"), CHECK_SIMULATION)
    path = crafted(posterior, tmp_path, _numbers_of_sliders([8, 3_000_000]))
    with pytest.raises(ForecastInputError) as info:
        load_posterior(path, CHECK_SIMULATION)
    assert str(path) in str(info.value) and "n_sliders=3000000" in str(info.value)
    assert "GB available" in str(info.value)


# -- the predictive check's piles stop at once ---------------------------------------------
def _interrupted_after(scene: Scene, delay: float = 0.5) -> float:
    """Seconds from a SIGINT sent ``delay`` s into ``simulate_pile(scene)`` to its
    KeyboardInterrupt (a run that ends otherwise fails)."""
    sent = []
    timer = threading.Timer(delay, lambda: (sent.append(time.monotonic()),
                                            os.kill(os.getpid(), signal.SIGINT)))
    finished = []
    timer.start()
    try:
        simulate_pile(scene, "fortran")
        finished.append(True)
        time.sleep(5)  # the signal still to come (the pile was too fast: the test fails)
    except KeyboardInterrupt:
        pass
    finally:
        timer.cancel()
    assert not finished, "the pile ended before the signal"
    return time.monotonic() - sent[0]


@pytest.mark.slow
def test_a_pile_of_a_million_sliders_stops_while_its_chain_is_prepared():
    """The run finished a preparation Ctrl-C interrupted before it stopped: 16.7 s here for a
    million sliders, half a minute and more for 3 million."""
    scene = Scene(n_sliders=1_000_000, mode="explore", mu_d=0.5, mu_s_mean=0.6, sigma_mu=0.01,
                  xi=0.01, alpha_max=0.6, seed=3)
    assert _interrupted_after(scene) < 2.0


@pytest.mark.slow
def test_a_history_preparation_stopped_is_an_interrupt_not_an_internal_error():
    """Its engine answers the signal by ending the history's tilt as interrupted: that was a
    RuntimeError ("the relaxation at alpha = 0 ended with status 'interrupted'"), status 1."""
    scene = Scene(n_sliders=20_000, mode="explore", mu_d=0.5, mu_s_mean=0.6, sigma_mu=0.01,
                  xi=0.01, alpha_max=0.6, seed=3, initial_forces="history")
    assert _interrupted_after(scene, 0.3) < 2.0


@pytest.mark.slow
def test_infer_answers_sigterm_within_seconds_while_its_check_prepares_piles(posterior,
                                                                            tmp_path):
    """``infer`` with the check on a posterior of a million sliders, SIGTERM after 8 s (the
    load takes about 3): 143, one line, within seconds (12.4 s here before)."""
    path = crafted(posterior, tmp_path, _numbers_of_sliders([1_000_000]))
    (tmp_path / "c.csv").write_text(CATALOGUE)
    proc = subprocess.Popen([sys.executable, "-m", "sliders.forecast", "infer",
                             str(tmp_path / "c.csv"), "--posterior", str(path), "--check-draws",
                             "3"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(8)
        sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
        took = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, err
    assert len(err.strip().splitlines()) == 1 and "SIGTERM" in err, err
    assert took < 5.0, took
