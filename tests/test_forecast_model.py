"""The forecasters as estimators, their model file (data, not code), predict's methods, the
measurement flags and the domain check."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys

import numpy as np
import pytest
from sklearn.base import clone

from sliders.analysis.forecast import Cuts, Measurement
from sliders.analysis.forecast.features import feature_matrix
from sliders.analysis.forecast.learned import Learned
from sliders.analysis.forecast.measurement import PERFECT, degrade
from sliders.analysis.forecast.fitting import fit_methods
from sliders.analysis.forecast.registry import FORECASTERS, make_forecasters
from sliders.io.catalogue import Catalogue
from sliders.io.prior_file import read_prior_ensemble
from sliders.analysis.forecast.model_file import load_forecasters, save_forecasters
from sliders.io.forecast_model import ModelFileError, default_model_path

from helpers import rate_law_catalogue, synthetic_set

pytestmark = pytest.mark.slow  # forecasters trained on prior files

PREDICT = [sys.executable, "-m", "sliders.forecast", "predict"]


class Ran:
    """What a command printed and its exit status (``sliders.runs.forecast.main`` in-process)."""

    def __init__(self, returncode, stdout, stderr):
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


@pytest.fixture
def predict(capsys, monkeypatch):
    """Run ``predict ARGS`` in this process (``cwd``: the folder it runs in)."""
    from sliders.runs.forecast.cli import main

    def run(args, cwd=None):
        if cwd is not None:
            monkeypatch.chdir(cwd)
        code = main(["predict", *args])
        out = capsys.readouterr()
        return Ran(code, out.out, out.err)

    return run


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    """Every method fitted on a small synthetic set, in a model file."""
    path = tmp_path_factory.mktemp("model") / "model.zip"
    models = fit_methods(synthetic_set(40, seed=1), max_iter=10, seed=0)
    save_forecasters(str(path), models, {"rows": 40, "prior": "synthetic rate laws"})
    return str(path)


def test_forecasters_follow_the_estimator_rules():
    train = synthetic_set(24, seed=3)
    for f in make_forecasters(max_iter=3, methods_only=True):
        twin = clone(f)
        assert twin.get_params() == f.get_params() and type(twin) is type(f)
        offsets = train.offsets.copy()
        alpha = train.columns["alpha"].copy()
        fitted = f.fit(train)
        assert fitted is f
        learned = [k for k in vars(f) if k.endswith("_")]
        assert learned, f"{f.name} learns nothing ending in _"
        assert not any(k.endswith("_") for k in vars(twin)), "clone carries fitted state"
        assert np.array_equal(train.offsets, offsets) and np.array_equal(train.columns["alpha"], alpha)
    assert len({e.method for e in FORECASTERS if e.method}) == sum(1 for e in FORECASTERS if e.method)


def test_a_crafted_pickle_is_refused_and_never_run(tmp_path):
    marker = tmp_path / "ran"

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    crafted = tmp_path / "crafted.zip"
    crafted.write_bytes(pickle.dumps(Evil()))
    catalogue = tmp_path / "c.csv"
    catalogue.write_text("angle [deg],size\n1,1\n2,1\n")
    out = subprocess.run(PREDICT + [str(catalogue), "--model", str(crafted)],
                         capture_output=True, text=True)
    assert out.returncode == 2 and not marker.exists()
    assert out.stderr.count("\n") == 1 and "refused" in out.stderr and str(crafted) in out.stderr


def test_a_model_file_naming_an_unlisted_type_is_refused(tmp_path, predict):
    """A model file whose header names a class that writes a file when built: refused by the
    closed table of the package's estimators, nothing imported or built."""
    from marker_class import archive_as_is

    marker = tmp_path / "ran"
    crafted = archive_as_is(tmp_path / "crafted.zip", {
        "format": "sliders-model-arrays-1", "arrays": {}, "provenance": {},
        "content": {"learned_blind": {"object": "marker_class.MarkerOnLoad",
                                      "state": {"path": str(marker)}}}})
    with pytest.raises(ModelFileError, match="marker_class.MarkerOnLoad.*no estimator"):
        load_forecasters(str(crafted))
    assert not marker.exists()
    catalogue = tmp_path / "c.csv"
    catalogue.write_text("angle [deg],size\n1,1\n2,1\n")
    out = predict([str(catalogue), "--model", str(crafted)])
    assert out.returncode == 2 and not marker.exists() and out.stderr.count("\n") == 1


def test_a_model_file_holding_something_else_is_one_line(tmp_path, predict):
    from marker_class import archive_as_is

    path = archive_as_is(tmp_path / "wrong.zip", {
        "format": "sliders-model-arrays-1", "arrays": {}, "provenance": {"rows": 1},
        "content": {"learned_blind": [1, 2, 3]}})
    with pytest.raises(ModelFileError, match="not written"):
        save_forecasters(str(tmp_path / "not.zip"), {"learned_blind": np.arange(3)}, {"rows": 1})
    catalogue = tmp_path / "c.csv"
    catalogue.write_text("angle [deg],size\n1,1\n2,1\n")
    out = predict([str(catalogue), "--model", str(path)])
    assert out.returncode == 2 and out.stderr.count("\n") == 1
    assert "holds no estimator" in out.stderr and "'learned_blind'" in out.stderr


def test_a_model_file_of_another_format_asks_to_be_trained_again(tmp_path):
    from marker_class import archive_as_is

    older = archive_as_is(tmp_path / "older.zip", {"format": "sliders-forecaster-2",
                                                   "forecasters": {}, "provenance": {}})
    with pytest.raises(ModelFileError, match="format sliders-forecaster-2.*train it again"):
        load_forecasters(str(older))


def test_the_default_model_is_never_taken_from_the_current_folder(tmp_path, predict):
    path = default_model_path()
    assert "site-packages" in str(path) or "src" in str(path)
    assert os.path.dirname(str(path)) != str(tmp_path)
    # a file of the default's name in the current folder is not read
    (tmp_path / "default_forecaster.zip").write_bytes(b"not a model")
    (tmp_path / "results" / "forecast").mkdir(parents=True)
    (tmp_path / "results" / "forecast" / "forecaster.zip").write_bytes(b"not a model")
    catalogue = tmp_path / "c.csv"
    catalogue.write_text("angle [deg],size\n1,1\n2,1\n3,2\n")
    out = predict([str(catalogue), "--json"], cwd=tmp_path)
    assert "not a model" not in out.stderr
    if path.is_file():
        assert out.returncode == 0, out.stderr
        assert json.loads(out.stdout)["model"]["path"] == str(path)


def test_the_shipped_model_loads_and_predicts():
    path = default_model_path()
    assert path.is_file(), f"{path}: the default forecaster is not shipped"
    assert path.stat().st_size < 8e6
    models, prov = load_forecasters(path)
    assert {"learned", "learned_blind", "ffm_ml_events", "model_based"} <= set(models)
    assert prov["rows"] >= 500 and "mu_d" in prov["prior"]
    cat = rate_law_catalogue(0.6, 80.0, 0.5)
    f = models["learned_blind"].predict(cat)
    assert f.point > 0.5 and f.interval[0] <= f.point <= f.interval[1]


def test_a_pile_of_known_size_outside_the_training_piles_is_flagged(tmp_path, predict):
    """``--sliders N``: the shipped model's piles hold 8-800 sliders; a pile of 4 is outside,
    said so in the text and the JSON, one of 12 is not, and a bad N is refused in one line."""
    cat = rate_law_catalogue(0.6, 80.0, 0.5)
    path = tmp_path / "pile.csv"
    path.write_text("angle [rad],size\n" + "".join(f"{a:.12g},1\n" for a in cat.alpha))
    small = predict([str(path), "--sliders", "4", "--json"])
    d = json.loads(small.stdout)
    assert small.returncode == 0 and d["in_domain"] is False and d["measurement"]["n_sliders"] == 4
    assert "a pile of 4 sliders, outside the training piles' 8-800" in d["domain_reason"]
    text = predict([str(path), "--sliders", "4"])
    assert "OUT OF THE TRAINING DOMAIN: a pile of 4 sliders" in text.stdout
    for n in ("12", "200"):
        told = json.loads(predict([str(path), "--sliders", n, "--json"]).stdout)
        assert "sliders, outside" not in told["domain_reason"]
    bad = predict([str(path), "--sliders", "0"])
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "sliders" in bad.stderr


def test_method_all_on_an_exact_inverse_rate_catalogue(tmp_path, model_file, predict):
    """Rate exactly 1 / (0.6 - alpha): the maximum-likelihood inverse rate finds 0.6 within 0.03."""
    cat = rate_law_catalogue(0.6, 120.0, 0.55)
    path = tmp_path / "rate.csv"
    path.write_text("angle [rad],size\n" + "".join(f"{a:.12g},1\n" for a in cat.alpha))
    out = predict([str(path), "--model", model_file, "--method", "all", "--json", "--tilt-now",
                   "0.55rad"])
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    assert set(d["methods"]) >= {"learned", "ffm_ls_events", "ffm_ml_events", "model_based"}
    assert abs(d["methods"]["ffm_ml_events"]["alpha_c"] - 0.6) < 0.03
    assert not d["methods"]["ffm_ml_events"]["fallback"]
    # no displacement column: the displacement fits fall back, and say why
    assert d["methods"]["ffm_ml_disp"]["fallback"] and d["methods"]["ffm_ml_disp"]["fallback_reason"]
    text = predict([str(path), "--model", model_file, "--method", "all", "--tilt-now", "0.55rad"])
    assert text.returncode == 0 and "ffm_ml_events" in text.stdout and "fallback:" in text.stdout


def test_out_of_domain_catalogue_is_flagged_with_its_reason(tmp_path, model_file, predict):
    """The synthetic training avalanches lie in [0.3, 0.6] rad: a pile at 0.8 rad is outside."""
    late = rate_law_catalogue(0.95, 80.0, 0.8)
    path = tmp_path / "late.csv"
    path.write_text("angle [rad],size\n" + "".join(f"{a:.12g},1\n" for a in late.alpha))
    out = predict([str(path), "--model", model_file, "--json"])
    d = json.loads(out.stdout)
    assert d["in_domain"] is False and "above" in d["domain_reason"] and d["fallback"]
    text = predict([str(path), "--model", model_file])
    assert "OUT OF THE TRAINING DOMAIN" in text.stdout and "widened" in text.stdout
    models, _ = load_forecasters(model_file)
    row = synthetic_set(3, seed=9).catalogue(0).cut(0.25)
    inside, _ = models["learned_blind"].domain(Cuts.from_catalogues([row]))
    assert inside[0]


def test_degraded_catalogues_and_the_flags_reach_the_features(tmp_path, model_file, predict):
    rng = np.random.default_rng(0)
    cat = synthetic_set(1, seed=4).catalogue(0).cut(0.25)
    m = Measurement(np.radians(0.3), 2.0, 0.5, "sliders")
    low = degrade(cat, m, rng)
    assert len(low) < 0.6 * len(cat) and (low.size >= 2).all() and np.all(np.diff(low.alpha) >= 0)
    scaled = degrade(cat, Measurement(size_unit="arbitrary", min_size=3.0), rng, size_scale=3.0)
    x, names = feature_matrix(Cuts.from_catalogues([scaled], Measurement(size_unit="arbitrary",
                                                                         min_size=3.0)))
    row = dict(zip(names, x[0]))
    assert row["size_arbitrary"] == 1.0 and np.isnan(row["max_size"])
    assert row["size_ratio_max"] == pytest.approx(scaled.size.max() / scaled.size.mean())
    x2, _ = feature_matrix(Cuts.from_catalogues([cat], m))
    assert dict(zip(names, x2[0]))["angle_resolution"] == pytest.approx(np.radians(0.3))
    assert dict(zip(names, x2[0]))["missed_fraction"] == 0.5
    path = tmp_path / "c.csv"
    path.write_text("angle [rad],size\n" + "".join(f"{a:.12g},{s * 7}\n" for a, s in
                                                   zip(scaled.alpha, scaled.size)))
    out = predict([str(path), "--model", model_file, "--json", "--size-unit", "arbitrary",
                   "--min-size", "21", "--angle-resolution", "0.3", "--missed-fraction", "0.5"])
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    assert d["measurement"] == {"angle_resolution_deg": pytest.approx(0.3), "min_size": 21.0,
                                "missed_fraction": 0.5, "size_unit": "arbitrary", "n_sliders": None,
                                "n_sliders_high": None, "displacement_unit": "model",
                                "position_unit": "sliders", "pile_length_mm": None}
    bad = predict([str(path), "--model", model_file, "--missed-fraction", "1.5"])
    assert bad.returncode == 2 and "missed fraction" in bad.stderr and bad.stderr.count("\n") == 1


def test_learned_features_are_invariant_to_the_size_unit():
    cat = synthetic_set(1, seed=5).catalogue(0).cut(0.3)
    arb = Measurement(size_unit="arbitrary")
    a, names = feature_matrix(Cuts.from_catalogues([cat], arb))
    big = Catalogue(cat.alpha, cat.size * 9, cat.displacement, cat.first, cat.last, cat.tilt_now)
    b, _ = feature_matrix(Cuts.from_catalogues([big], Measurement(size_unit="arbitrary", min_size=9)))
    assert np.allclose(a, b, equal_nan=True)


def test_coverage_per_lead_is_computed_and_written(tmp_path):
    from sliders.analysis.forecast.reliability import coverage_report

    data = synthetic_set(60, seed=6)
    f = Learned(inputs="angles_sizes", draws_per_row=5, max_iter=5).fit(data.subset(np.arange(40)))
    out = tmp_path / "coverage.json"
    rep = coverage_report(f, data, np.arange(40, 60), np.radians([0.5, 3.0]), str(out))
    written = json.loads(out.read_text())
    assert written == json.loads(json.dumps(rep))
    assert set(written["per_lead"]) == {"0.5", "3"}
    for v in written["per_lead"].values():
        assert 0.0 <= v["coverage"] <= 1.0 and v["n"] > 0
    assert 0.0 <= written["all_cuts"]["coverage"] <= 1.0
    assert written["per_tilt_bin"] and written["per_events_bin"]


TINY_PRIOR = ('[prior]\nrealisations = 24\nseed = {seed}\nceiling_step = 0.5\nceiling_k = 1\n'
              '[parameters]\nmu_d = {{ uniform = [0.3, 0.6] }}\n'
              'mu_s_minus_mu_d = {{ loguniform = [0.02, 0.1] }}\nsigma_mu = 0.01\n'
              'xi = {{ loguniform = [1e-3, 1.0], zero = 0.3 }}\nn_sliders = {{ choice = [12, 16] }}\n')


def test_a_posterior_calibrates_on_another_draw_of_its_prior_and_refuses_the_same(tmp_path,
                                                                                  capsys):
    from sliders.runs import prior as prior_run
    from sliders.runs.forecast.cli import main

    files = {}
    for seed in (3, 4):
        (tmp_path / f"p{seed}.toml").write_text(TINY_PRIOR.format(seed=seed))
        files[seed] = tmp_path / f"p{seed}.h5"
        assert prior_run.main([str(tmp_path / f"p{seed}.toml"), "--out", str(files[seed]),
                               "--quiet"]) == 0
    out = tmp_path / "post.zip"
    base = ["train", "--data", str(files[3]), "--fit", "posterior", "--max-iter", "3",
            "--out", str(out), "--quiet"]
    assert main(base + ["--calibration-data", str(files[4])]) == 0
    models, prov = load_forecasters(str(out))
    assert prov["calibration_files"] == ["p4.h5"] and prov["calibration_seeds"] == [4]
    held = int(models["posterior"].calibration_split(prov["rows"])[1].sum())
    assert models["posterior"].n_calibration_realisations_ == held + 24
    capsys.readouterr()
    for given, words in (([str(files[3])], "seed 3, which is already used"),
                         ([str(files[4]), str(files[4])], "seed 4, which is already used")):
        assert main(base + ["--calibration-data"] + given) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err, err
    assert main(base[:3] + ["--out", str(out), "--quiet", "--calibration-data",
                            str(files[4])]) == 2
    assert "only with --fit posterior" in capsys.readouterr().err


def test_a_posterior_of_a_prior_that_fixes_parameters_infers_them_exactly(tmp_path, capsys):
    """sigma_mu and xi fixed by the prior (xi = 0: no positive value to code the atom below):
    the fit writes a file that reads, whose posterior of each is the prior's value."""
    from sliders.runs import prior as prior_run
    from sliders.runs.forecast.cli import main

    toml = tmp_path / "fixed.toml"
    toml.write_text(TINY_PRIOR.format(seed=3).replace("xi = { loguniform = [1e-3, 1.0], "
                                                      "zero = 0.3 }", "xi = 0.0"))
    assert prior_run.main([str(toml), "--out", str(tmp_path / "fixed.h5"), "--quiet"]) == 0
    out = tmp_path / "post.zip"
    assert main(["train", "--data", str(tmp_path / "fixed.h5"), "--fit", "posterior",
                 "--max-iter", "3", "--out", str(out), "--quiet"]) == 0
    post = load_forecasters(str(out))[0]["posterior"]
    cset = read_prior_ensemble(str(tmp_path / "fixed.h5"))
    cut = cset.catalogue(0).cut(float(cset.alpha_c[0]) - 0.02)
    summary = post.summary(post.quantiles(Cuts.from_catalogues([cut], PERFECT))[0])
    assert summary["xi"]["p_zero"] == 1.0
    assert summary["sigma_mu"]["interval_95"] == pytest.approx([0.01, 0.01], rel=1e-9)
    contraction = post.contraction(post.quantiles(Cuts.from_catalogues([cut], PERFECT))[0])
    assert contraction["sigma_mu"] is None and contraction["xi"] is None
    assert isinstance(contraction["mu_d"], float)
    csv = tmp_path / "row.csv"
    assert main(["catalogue", "--data", str(tmp_path / "fixed.h5"), "--row", "0", "--lead",
                 "1deg", "--out", str(csv)]) == 0
    capsys.readouterr()
    assert main(["infer", str(csv), "--posterior", str(out), "--no-check"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert any(line.strip().startswith("sigma_mu: 0.01,") and line.endswith("(fixed by the prior)")
               for line in lines), lines


def test_train_runs_a_prior_and_writes_a_model_file_of_its_provenance(tmp_path, capsys):
    from sliders.runs.forecast.cli import main

    prior = tmp_path / "tiny.toml"
    prior.write_text('[prior]\nrealisations = 24\nseed = 3\nceiling_step = 0.5\nceiling_k = 1\n'
                     '[parameters]\nmu_d = { uniform = [0.3, 0.6] }\n'
                     'mu_s_minus_mu_d = { loguniform = [0.02, 0.1] }\nsigma_mu = 0.01\nxi = 0.0\n'
                     'n_sliders = { choice = [12, 16] }\n')
    out = tmp_path / "tiny.zip"
    assert main(["train", "--prior", str(prior), "--out", str(out), "--max-iter", "3",
                 "--hold-out", "0.25", "--quiet"]) == 0
    models, prov = load_forecasters(str(out))
    assert set(models) >= {"learned", "learned_blind", "ffm_ml_events", "model_based"}
    assert 12 <= prov["rows"] and prov["rows"] + len(prov["held_out_rows"]) <= 24
    assert "n_sliders" in prov["prior"]
    assert prov["mode"] == "explore" and prov["crepes"] and prov["scikit-learn"]
    # the provenance names no path of the machine: the prior file outside the folder by its name
    assert prov["data_files"] == ["tiny.zip.prior.h5"]
    assert str(tmp_path) not in json.dumps(prov)
    # the held-out accuracy per bin of the forecast's lead, plain floats, in each learned one
    for method in ("learned", "learned_blind"):
        table = models[method].expected_accuracy_
        k = len(table["lead_edges_deg"])
        assert [len(table[c]) for c in ("median_abs_deg", "coverage", "n")] == [k, k, k]
        assert all(isinstance(v, float) and 0.0 <= v <= 1.0 for v in table["coverage"])
        assert sum(table["n"]) == table["overall"]["n"] > 0
    # the prior file is kept: run again, it is resumed (complete), the same rows fitted
    assert main(["train", "--prior", str(prior), "--out", str(out), "--max-iter", "3",
                 "--hold-out", "0.25", "--quiet"]) == 0
    again = load_forecasters(str(out))[1]
    assert again["rows"] == prov["rows"] and again["prior_digest"] == prov["prior_digest"]
    assert again["seconds_simulation"] < prov["seconds_simulation"] + 5
    csv = tmp_path / "row.csv"
    assert main(["catalogue", "--data", str(out) + ".prior.h5", "--row", "2", "--lead", "1deg",
                 "--out", str(csv)]) == 0
    assert csv.read_text().splitlines()[1] == "angle [rad],size,displacement,first,last"
    capsys.readouterr()
    assert main(["predict", str(csv), "--model", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["model"]["rows"] == prov["rows"]
