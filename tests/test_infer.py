"""``python -m sliders.forecast infer``: the posterior of a pile's material from its catalogue.

The shipped posterior is read once (module fixture); the piles are simulated
here: rows of the shipped posterior's own prior that its fit held out (their
indices are in its provenance), of at most ``SMALL_PILE`` sliders so that
they run in seconds, each cut at a random tilt before its avalanche.
"""

from __future__ import annotations

import copy
import json
import math
import shutil
import zipfile

import numpy as np
import pytest
from scipy.special import ndtr
from scipy.stats import kstest
from sklearn.base import clone

from sliders.analysis.forecast.features import Cuts
from sliders.analysis.forecast.measurement import PERFECT
from sliders.analysis.forecast.integrity import IntegrityError
from sliders.analysis.forecast.posterior import (POSTERIOR_PARAMETERS, RECALIBRATION_GROUPS,
                                                 REPORTED_LEVELS, ParameterPosterior,
                                                 recalibrated, recalibration_map)
from sliders.driver import run
from sliders.io.catalogue import Catalogue
from sliders.io.forecast_files import ForecastInputError
from sliders.io.forecast_model import default_posterior_path
from sliders.runs.forecast import cli
from sliders.forecasting.catalogue import catalogue_csv_text
from sliders.forecasting.infer import load_posterior
from sliders.runs.forecast.infer import CHECK_SIMULATION
from sliders.runs.prior_spec import parse_prior

SMALL_PILE = 50  # sliders: the held-out rows simulated here
N_PILES = 60


@pytest.fixture(scope="module")
def model():
    return load_posterior(simulation=CHECK_SIMULATION)


@pytest.fixture(scope="module")
def held_out(model):
    """(catalogues cut at random tilts, their true parameters) of held-out prior rows."""
    post = model.posterior
    prior = parse_prior(post.prior_spec())
    values = prior.values()
    rows = [r for r in model.provenance["held_out_rows"] if values["n_sliders"][r] <= SMALL_PILE]
    rng = np.random.default_rng(5)
    cats, truth, whole_set = [], {p: [] for p in post.parameters_}, []
    for r in rows[:N_PILES]:
        result = run(prior.scene(r), "fortran")
        whole = Catalogue.from_result(result)
        whole_set.append((whole, result.alpha_c))
        cats.append(whole.cut(rng.uniform(0.0, result.alpha_c)))
        for p in post.parameters_:
            truth[p].append(values[p][r])
    truth = {p: np.array(v, dtype=float) for p, v in truth.items()}
    HELD_OUT_PILES[:] = whole_set
    return cats, truth


#: the held-out piles' whole catalogues and avalanche angles (filled by ``held_out``)
HELD_OUT_PILES: list = []


def _csv(tmp_path, cat, name="pile.csv"):
    path = tmp_path / name
    path.write_text(catalogue_csv_text(cat))
    return str(path)


def test_json_has_every_parameter_with_nested_intervals(tmp_path, held_out, capsys):
    cats, _ = held_out
    cat = max(cats, key=len)
    code = cli.main(["infer", _csv(tmp_path, cat), "--json", "--no-check"])
    assert code == 0
    d = json.loads(capsys.readouterr().out)
    assert set(d) >= {"parameters", "contraction", "in_domain", "check"}
    assert d["check"] is None
    assert list(d["parameters"]) == list(POSTERIOR_PARAMETERS)
    for name, p in d["parameters"].items():
        lo95, hi95 = p["interval_95"]
        lo80, hi80 = p["interval_80"]
        assert lo95 <= lo80 <= p["median"] <= hi80 <= hi95, name
        assert -1.0 <= d["contraction"][name] <= 1.0
    assert 0.0 <= d["parameters"]["xi"]["p_zero"] <= 1.0
    probs = d["parameters"]["n_sliders"]["probabilities"]
    assert math.isclose(sum(probs.values()), 1.0, abs_tol=1e-9)
    mu = d["parameters"]["mu_d"]
    assert math.isclose(math.degrees(math.atan(mu["median"])), mu["atan_deg"]["median"])


def test_intervals_lie_within_the_prior_range(model, held_out):
    cats, _ = held_out
    post = model.posterior
    q = post.quantiles(Cuts.from_catalogues(cats[:20], PERFECT))
    span = post.prior_range()
    for row in q:
        for name, p in post.summary(row).items():
            lo, hi = span[name]
            for v in (p["interval_95"] or []):
                assert lo * (1 - 1e-9) <= v <= hi * (1 + 1e-9), (name, v, span[name])


def test_true_parameters_of_held_out_piles_are_covered_at_about_the_nominal_rate(model, held_out):
    cats, truth = held_out
    post = model.posterior
    q = post.quantiles(Cuts.from_catalogues(cats, PERFECT))
    inside = {p: [] for p in post.parameters_}
    for i, row in enumerate(q):
        s = post.summary(row)
        for p in ("mu_d", "mu_s_minus_mu_d", "sigma_mu"):
            lo, hi = s[p]["interval_80"]
            inside[p].append(lo <= truth[p][i] <= hi)
    rates = {p: float(np.mean(v)) for p, v in inside.items() if v}
    # 60 piles: the 80 % interval's binomial spread is +-0.05; the small piles are a slice
    assert all(0.6 <= r <= 0.97 for r in rates.values()), rates
    assert 0.7 <= np.mean(list(rates.values())) <= 0.92, rates


def test_the_rank_of_an_atom_spreads_over_its_probability(model, held_out):
    cats, truth = held_out
    post = model.posterior
    q = post.quantiles(Cuts.from_catalogues(cats[:10], PERFECT))
    n = post.parameters_.index("n_sliders")
    # every number of sliders of the prior in turn as the truth: its atoms tile [0, 1]
    lo, hi = np.array([post.pit_bounds(q, {p: np.full(10, v if p == "n_sliders" else
                                                      truth[p][0]) for p in post.parameters_})
                       for v in post.n_sliders_values_]).transpose(1, 0, 2, 3)[:, :, :, n]
    assert np.allclose(lo[0], 0.0) and np.allclose(hi[-1], 1.0)
    assert np.allclose(lo[1:], hi[:-1]) and (hi >= lo).all()
    # xi = 0 is one atom from 0; the randomized rank lies within the bounds it spreads over
    truth10 = {p: v[:10] for p, v in truth.items()}
    lo, hi = post.pit_bounds(q, truth10)
    u = post.probability_integral(Cuts.from_catalogues(cats[:10], PERFECT), truth10,
                                  np.random.default_rng(0))
    assert ((lo <= u) & (u <= hi)).all()
    zero = post.pit_bounds(q, truth10 | {"xi": np.zeros(10)})
    assert (zero[0][:, post.parameters_.index("xi")] == 0.0).all()


def test_the_text_names_every_parameter_and_the_skipped_check(model, held_out):
    cats, _ = held_out
    text = str(model.infer_catalogue(cats[0], PERFECT, check=False))
    for word in ("mu_d", "atan(mu_d)", "mu_s - mu_d", "sigma_mu", "P(xi = 0)", "N (sliders)",
                 "skipped"):
        assert word in text


def test_the_check_reproduces_a_held_out_pile(model, held_out):
    cats, _ = held_out
    cat = next(c for c in cats if len(c) >= 20)
    d = model.infer_catalogue(cat, PERFECT, check=True, check_draws=12, seed=1).to_dict()
    assert d["check"]["simulated"] == 12
    assert d["check"]["reproduced"] is True, d["check"]


def test_the_check_flags_a_pile_of_a_material_outside_the_prior(model):
    # mu_d = 1.4 is above the prior's 0.2-1.1: its pile stands to atan(1.4) = 54°, where
    # every pile of the prior has avalanched
    scene = parse_prior(model.posterior.prior_spec()).base_scene.replace(
        mu_d=1.4, mu_s_mean=1.45, sigma_mu=0.01, xi=0.0, n_sliders=50, seed=7)
    result = run(scene, "fortran")
    cat = Catalogue.from_result(result).cut(result.alpha_c - math.radians(0.5))
    inference = model.infer_catalogue(cat, PERFECT, check=True, seed=1)
    assert inference["check"]["reproduced"] is False
    assert "the model does not reproduce this catalogue" in str(inference)


def test_bad_input_is_one_line_and_status_2(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("angle [deg],size\n2,1\n1,1\n")
    assert cli.main(["infer", str(bad), "--no-check"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "below the previous row" in err
    assert cli.main(["infer", str(bad), "--check-draws", "1"]) == 2
    assert "--check-draws 1" in capsys.readouterr().err


def test_a_corrupted_posterior_file_is_refused_in_one_line(tmp_path, held_out, capsys):
    cats, _ = held_out
    copy = tmp_path / "posterior.zip"
    shutil.copyfile(default_posterior_path(), copy)
    with zipfile.ZipFile(copy) as z:  # an array member of the copy, rewritten as other bytes
        member = next(i for i in z.infolist() if i.filename.endswith(".npy")
                      and i.file_size > 1000)
        members = {i.filename: z.read(i.filename) for i in z.infolist()}
    members[member.filename] = members[member.filename][:-8]
    with zipfile.ZipFile(copy, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    assert cli.main(["infer", _csv(tmp_path, cats[0]), "--posterior", str(copy)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(copy) in err


def test_a_forecaster_file_is_not_a_posterior(tmp_path):
    from sliders.io.forecast_model import default_model_path

    with pytest.raises(ForecastInputError, match="not a posterior file"):
        load_posterior(default_model_path(), CHECK_SIMULATION)


def test_the_estimator_follows_the_scikit_learn_rules():
    est = ParameterPosterior(max_iter=7, random_state=3)
    twin = clone(est)
    assert twin.get_params() == est.get_params()
    assert not any(k.endswith("_") for k in vars(twin))


@pytest.mark.slow
def test_the_corner_plot_is_a_png(tmp_path, model, held_out):
    cats, _ = held_out
    out = tmp_path / "posterior.png"
    model.infer_catalogue(cats[0], PERFECT, check=False).plot(out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_a_posterior_fitted_on_a_few_piles_round_trips_through_its_file(tmp_path, held_out,
                                                                         model):
    from sliders.analysis.forecast.model_file import save_forecasters
    from sliders.io.catalogue import CatalogueSet

    cats, truth = held_out
    whole = [c for c, _ in HELD_OUT_PILES]
    train = CatalogueSet.from_catalogues(
        whole, truth, [a for _, a in HELD_OUT_PILES], ["avalanche"] * len(whole),
        attrs={"prior": model.posterior.prior_}).subset(np.arange(len(whole)))
    post = ParameterPosterior(max_iter=5, draws_per_row=3, random_state=1).fit(train)
    path = tmp_path / "tiny.zip"
    save_forecasters(str(path), {"posterior": post}, {"command": "test"})
    d = load_posterior(path, CHECK_SIMULATION).infer_catalogue(cats[0], PERFECT,
                                                  check=False).to_dict()
    assert set(d["parameters"]) == set(post.parameters_)
    assert d["parameters"]["n_sliders"]["median"] in post.n_sliders_values_


@pytest.mark.slow
def test_the_python_api_infers_with_the_forecast_model(tmp_path, held_out, shipped_model):
    import sliders.forecast as sf

    cats, _ = held_out
    inference = shipped_model.infer(_csv(tmp_path, cats[0]), check=False)
    assert isinstance(inference, sf.Inference)
    assert inference.to_dict()["check"] is None and "mu_d" in str(inference)


def test_the_shipped_posterior_passes_the_archive_check_beside_its_digest():
    from sliders.io.model_arrays import read_model_arrays

    header, arrays = read_model_arrays(default_posterior_path())  # ModelFileError if not
    assert list(header["content"]) == ["posterior"] and set(arrays) == set(header["arrays"])


def test_the_verdict_fails_when_either_predictive_test_fails_and_says_which():
    from sliders.analysis.forecast.posterior_check import combined_verdict
    from sliders.forecasting.infer import check_text

    posterior_ok = {"reproduced": True, "p_values": {"onset": 0.4, "stands_to_tilt": 0.5},
                    "simulated": 24, "significance_level": 0.01}
    both_ok = combined_verdict(posterior_ok, True, "")
    assert both_ok["reproduced"] is True and both_ok["reasons"] == []
    assert both_ok["tests"] == {"prior_predictive": True, "posterior_predictive": True}
    outside = combined_verdict(posterior_ok, False, "the tilt reached is above 99.5 %")
    assert outside["reproduced"] is False
    assert [r["test"] for r in outside["reasons"]] == ["prior_predictive"]
    assert "the tilt reached" in outside["reasons"][0]["detail"]
    assert "prior predictive check failed" in check_text(outside)
    differs = combined_verdict({**posterior_ok, "reproduced": False,
                                "p_values": {"onset": 1e-5, "stands_to_tilt": 0.5}}, False, "x")
    assert [r["test"] for r in differs["reasons"]] == ["prior_predictive", "posterior_predictive"]
    assert "onset" in differs["reasons"][1]["detail"]
    assert differs["p_values"]["onset"] == 1e-5 and differs["simulated"] == 24


def test_the_json_verdict_names_the_failed_test_of_a_pile_prepared_outside_the_prior(model):
    # a material of the prior, prepared without internal forces: silent up to a tilt where
    # every pile of the prior has had events (the prior predictive test fails)
    scene = parse_prior(model.posterior.prior_spec()).base_scene.replace(
        mu_d=0.7, mu_s_mean=0.74, sigma_mu=0.03, xi=0.0, n_sliders=100, seed=3,
        initial_forces="zero")
    result = run(scene, "fortran")
    cat = Catalogue.from_result(result).cut(result.alpha_c - math.radians(1.0))
    inference = model.infer_catalogue(cat, PERFECT, check=True, check_draws=8)
    check = inference.to_dict()["check"]  # what infer --json prints
    assert check["reproduced"] is False and check["tests"]["prior_predictive"] is False
    assert "prior_predictive" in [r["test"] for r in check["reasons"]]
    assert {"p_values", "simulated", "significance_level", "avalanched_before"} <= set(check)
    assert "prior predictive check failed" in str(inference)


def test_mu_d_and_xi_come_together_from_the_lone_slips_of_a_coupled_pile(model):
    from sliders.analysis.forecast.features import coupled_lone_slips, densest_value, \
        single_slider_mu_d

    scene = parse_prior(model.posterior.prior_spec()).base_scene.replace(
        mu_d=0.6, mu_s_mean=0.64, sigma_mu=0.01, xi=0.05, n_sliders=30, seed=4)
    result = run(scene, "fortran")
    cat = Catalogue.from_result(result).cut(result.alpha_c - math.radians(1.0))
    mu_d, xi, agree = coupled_lone_slips(cat)
    assert agree >= 3
    assert mu_d == pytest.approx(0.6, abs=1e-6) and xi == pytest.approx(0.05, rel=1e-3)
    neglected, _ = densest_value(single_slider_mu_d(cat))  # the cantilevers neglected
    assert not abs(neglected - 0.6) < 1e-3


def test_the_domain_check_flags_the_share_of_calibration_cuts_it_is_set_to(model):
    from sliders.analysis.forecast.domain import DomainCheck

    post = model.posterior
    assert post.get_params()["domain_level"] == 0.005
    # the shipped posterior's domain check, set again on catalogues of the prior it knows
    prior = parse_prior(post.prior_spec())
    rng = np.random.default_rng(2)
    cats = []
    for r in range(8):
        whole = Catalogue.from_result(run(prior.scene(r).replace(n_sliders=20), "fortran"))
        cats += [whole.cut(a) for a in rng.uniform(0.0, whole.tilt_now, 40)]
    cuts = Cuts.from_catalogues(cats, PERFECT)
    check = copy.deepcopy(post.domain_)
    assert isinstance(check, DomainCheck)
    for level in (0.05, 0.2):
        check.calibrate(cuts, level)
        share = float(np.mean(check.novel(cuts)))
        assert level - 1 / len(cuts) <= share <= level + 1e-9, (level, share)


@pytest.mark.parametrize("report", ["inference_calibration.json",
                                    "inference_checks_200_piles.json"])
def test_the_benchmark_names_the_shipped_posterior_by_its_name_and_digest(report):
    import pathlib

    results = pathlib.Path(__file__).parents[1] / "benchmarks" / "results"
    d = json.loads((results / report).read_text())
    recorded = pathlib.Path(str(default_posterior_path()) + ".sha256").read_text().split()[0]
    assert d["posterior"] == {"name": default_posterior_path().name, "sha256": recorded}
    assert "/work" not in json.dumps(d)


def test_the_recalibration_makes_the_pits_of_a_too_wide_cdf_uniform():
    rng = np.random.default_rng(3)
    # truths N(0, 1) read on a CDF N(0, 2^2), too wide: their PITs crowd the middle
    fit_u, new_u = (ndtr(rng.standard_normal(n) / 2) for n in (4000, 2000))
    assert kstest(new_u, "uniform").pvalue < 1e-6
    r = recalibration_map(fit_u)
    assert type(r) is np.ndarray and r.dtype == np.float64 and r.shape == REPORTED_LEVELS.shape
    assert (np.diff(r) >= 0).all() and 0.0 <= r.min() and r.max() <= 1.0
    assert kstest(recalibrated(new_u, r), "uniform").pvalue > 0.01
    # composed again on the PITs of the CDF it makes, the map stays where it is
    assert np.allclose(recalibration_map(recalibrated(fit_u, r), r), r, atol=0.01)


def test_the_shipped_posterior_stores_a_monotone_recalibration_of_plain_numbers(model):
    post = model.posterior
    r = post.recalibration_
    assert type(r) is np.ndarray and r.dtype == np.float64
    assert r.shape == (len(RECALIBRATION_GROUPS), len(post.parameters_), REPORTED_LEVELS.size)
    assert (np.diff(r, axis=2) >= 0).all() and 0.0 <= r.min() and r.max() <= 1.0
    # mu_d from the lone slips, sharper than a CDF linear between seven levels, is recalibrated
    lone = RECALIBRATION_GROUPS.index("complete_lone_slips")
    assert not np.allclose(r[lone, post.parameters_.index("mu_d")], REPORTED_LEVELS)
    reversed_ = r.copy()
    reversed_[lone, 0, 10] = reversed_[lone, 0, 11] + 0.01
    try:
        post.recalibration_ = reversed_
        with pytest.raises(IntegrityError, match="recalibration"):
            post.check_fitted()
    finally:
        post.recalibration_ = r


def test_interp_rows_is_numpys_interp_row_by_row_to_the_last_bit():
    from sliders.analysis.forecast.posterior import interp_rows

    rng = np.random.default_rng(11)
    xp = np.sort(rng.normal(size=(50, 9)), axis=1)
    xp[:5, 3] = xp[:5, 2]  # ties, as a run of equal quantiles makes
    fp = np.sort(rng.uniform(size=(50, 9)), axis=1)
    x = rng.normal(scale=2.0, size=(50, 4))
    x[:, 0] = xp[:, 4]  # exactly on a knot, and outside both ends
    x[0, 1], x[1, 1] = -np.inf, np.inf
    for knots in (xp, xp[0]):
        want = np.array([np.interp(x[i], knots if knots.ndim == 1 else knots[i], fp[i])
                         for i in range(len(x))])
        assert np.array_equal(interp_rows(x, knots, fp), want)


@pytest.mark.slow  # seconds of work: the full suite
def test_a_calibration_set_only_calibrates(held_out, model):
    """Rows given as ``calibration`` join the held-out realisations: the regressors are those
    of the fit without them, and the calibration counts them."""
    from sliders.io.catalogue import CatalogueSet

    _, truth = held_out
    whole = [c for c, _ in HELD_OUT_PILES]
    data = CatalogueSet.from_catalogues(whole, truth, [a for _, a in HELD_OUT_PILES],
                                        ["avalanche"] * len(whole),
                                        attrs={"prior": model.posterior.prior_})
    train, extra = data.subset(np.arange(40)), data.subset(np.arange(40, len(whole)))
    kw = dict(max_iter=5, draws_per_row=3, random_state=2)
    alone = ParameterPosterior(**kw).fit(train)
    both = ParameterPosterior(**kw).fit(train, calibration=extra)
    held = int(alone.calibration_split(len(train))[1].sum())
    assert alone.n_calibration_realisations_ == held
    assert both.n_calibration_realisations_ == held + len(extra)
    x = np.random.default_rng(0).normal(size=(7, alone.n_features_in_))
    for a, b in zip(alone.models_, both.models_):
        assert all(np.array_equal(ma.predict(x), mb.predict(x)) for ma, mb in zip(a, b))
    assert not np.array_equal(alone.shifts_, both.shifts_)
    lacking = CatalogueSet.from_catalogues([whole[0]], {"mu_d": truth["mu_d"][:1]},
                                           extra.alpha_c[:1], ["avalanche"])
    with pytest.raises(IntegrityError, match="calibration realisations lack"):
        ParameterPosterior(**kw).fit(train, calibration=lacking)


def test_one_catalogues_posterior_is_a_small_object_of_the_estimators_answers(model, held_out):
    """``given(catalogue)``: its summary and contraction are the estimator's for the catalogue's
    quantiles, its inverse CDF undoes its CDF, and its draws follow its CDF."""
    cats, _ = held_out
    post = model.posterior
    given = post.given(cats[0], PERFECT)
    q = post.quantiles(Cuts.from_catalogues([cats[0]], PERFECT))[0]
    assert given.summary() == post.summary(q) and given.contraction() == post.contraction(q)
    levels = np.array([0.1, 0.5, 0.9])
    at = given.ppf(levels)
    assert at["mu_d"][1] == pytest.approx(given.summary()["mu_d"]["median"])
    assert np.allclose(given.cdf({"mu_d": at["mu_d"], "sigma_mu": at["sigma_mu"]})["mu_d"], levels)
    draws = given.sample(2000, np.random.default_rng(0))
    below = np.mean(draws["mu_d"] <= at["mu_d"][1])
    assert abs(below - 0.5) < 0.05 and set(draws) == set(given.parameters)
