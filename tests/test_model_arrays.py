"""The model file of plain arrays: the shipped forecasts as they were, without scikit-learn.

``tests/data/forecasts_before_arrays.npz`` and ``.json`` hold what the shipped
forecaster and posterior gave when they were still read as scikit-learn's and
crepes's fitted objects (before their conversion to arrays): for the docs'
examples (the bench's three events, the cold-call benchmark's 150) and for
cuts of held-out rows of both training priors, each simulated by the kernel,
under four measurements; every forecaster's quantiles, fallbacks and levels,
the learned ones' raw regressor outputs and domain verdicts, the posterior's
quantiles and verdicts.  The converted files must give them again to 1e-12
(they give them bit for bit), also in a process where scikit-learn and crepes
cannot be imported.  Crafted files are refused in one line naming the file
and the array.
"""

from __future__ import annotations

import copy
import io
import json
import os
import pathlib
import subprocess
import sys
import warnings
import zipfile

import numpy as np
import pytest

from sliders.analysis.forecast.evaluators import NoveltyDetector, QuantileTrees, ResidualTable
from sliders.analysis.forecast.model_file import load_forecasters
from sliders.io.forecast_model import ModelFileError, default_model_path, default_posterior_path
from sliders.io.model_arrays import model_arrays_bytes, read_model_arrays

from helpers import forecasts_before_arrays, model_outputs, recorded_cases

DATA = pathlib.Path(__file__).parent / "data"
TOLERANCE = 1e-12


def assert_close(now, then, what):
    now, then = np.asarray(now), np.asarray(then)
    assert now.shape == then.shape, what
    if then.dtype.kind == "f":
        assert np.array_equal(np.isnan(now), np.isnan(then)), what
        gap = np.abs(np.where(np.isnan(then), 0.0, now - then))
        assert (gap <= TOLERANCE * np.maximum(1.0, np.abs(np.nan_to_num(then)))).all(), \
            (what, float(gap.max()))
    else:
        assert np.array_equal(now, then), what


def test_the_shipped_forecasts_are_todays_on_held_out_rows_and_the_docs_examples(shipped):
    ref = forecasts_before_arrays()
    cases, blind = recorded_cases(ref)
    assert len(cases) == 56 and sum(len(c) for c, _ in cases) > 1000
    post = load_forecasters(default_posterior_path())[0]["posterior"]
    now = model_outputs(shipped[0], post, cases, blind)
    recorded = {k for k in ref if not k.startswith("case.")}
    assert set(now) == recorded
    for k in sorted(recorded):
        assert_close(now[k], ref[k], k)
    # not a vacuous comparison: both domains' verdicts and the learned forecasters' widening
    assert ref["full.learned.inside"].any() and not ref["full.learned.inside"].all()
    assert ref["blind.learned_blind.fallback"].any()


#: a process where scikit-learn and crepes cannot be imported forecasts and infers the recorded
#: cases (the Python API and the commands), printing what it found as JSON
BLOCKED = r"""
import contextlib, io, json, math, sys
import numpy as np

class Blocked:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("sklearn", "crepes", "threadpoolctl"):
            raise ImportError(f"{name} is blocked")

sys.meta_path.insert(0, Blocked())
sys.path.insert(0, sys.argv[1])
from helpers import forecasts_before_arrays, model_outputs, recorded_cases
from sliders.forecasting.infer import load_posterior
from sliders.forecasting.predict import load_model
from sliders.runs.forecast.cli import main

ref = forecasts_before_arrays()
cases, blind = recorded_cases(ref)
fm, pm = load_model(), load_posterior()
now = model_outputs(fm.models, pm.posterior, cases, blind)
worst = max(float(np.nanmax(np.abs(np.asarray(now[k], float) - ref[k]), initial=0.0))
            for k in now)
e2e = {"forecast": [fm.forecast(c, m, math.radians(0.5), method="all").to_dict()
                    for c, m in cases[:8]],
       "infer": [pm.infer_catalogue(c, m, check=False).to_dict() for c, m in cases[:8]]}
codes = []
for args in (["predict", sys.argv[2], "--tilt-now", "27.5deg", "--method", "all", "--json"],
             ["infer", sys.argv[2], "--tilt-now", "27.5deg", "--no-check", "--json"]):
    with contextlib.redirect_stdout(io.StringIO()) as out:
        codes.append((main(args), json.loads(out.getvalue())["in_domain"]))
with open(sys.argv[2], "a") as fh:  # followed to its avalanche: the loop stops there
    fh.write("# avalanche 28deg\n")
with contextlib.redirect_stdout(io.StringIO()) as out:
    codes.append((main(["predict", sys.argv[2], "--follow", "--tilt-now", "27.5deg"]),
                  "run scored at the avalanche" in out.getvalue()))
print(json.dumps({"worst": worst, "e2e": e2e, "codes": codes,
                  "sklearn": sorted(m for m in sys.modules
                                    if m.split(".")[0] in ("sklearn", "crepes", "threadpoolctl"))}))
"""


@pytest.mark.slow
def test_predict_follow_and_infer_give_todays_forecasts_with_scikit_learn_unimportable(tmp_path):
    csv = tmp_path / "pile.csv"
    csv.write_text("# the bench example of docs/forecasting.md\nangle [deg],size\n"
                   "1.21,1\n2.03,1\n2.87,3\n")
    res = subprocess.run([sys.executable, "-c", BLOCKED, str(pathlib.Path(__file__).parent),
                          str(csv)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    got = json.loads(res.stdout.splitlines()[-1])
    assert got["sklearn"] == [] and got["worst"] <= TOLERANCE
    assert [c for c, _ in got["codes"]] == [0, 0, 0] and got["codes"][2][1]
    then = json.loads((DATA / "forecasts_before_arrays.json").read_text())
    for kind, drop in (("forecast", "model"), ("infer", "posterior")):
        for now, old in zip(got["e2e"][kind], then[kind], strict=True):
            now.pop(drop)
            assert json.dumps(now, sort_keys=True) == json.dumps(old, sort_keys=True), kind


def test_a_scikit_learn_import_fails_in_the_blocked_process():
    """The blocker of the test above does block: importing scikit-learn behind it fails."""
    code = BLOCKED.split("sys.meta_path.insert(0, Blocked())")[0] + \
        "sys.meta_path.insert(0, Blocked())\nimport sklearn.ensemble\n"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode != 0 and "sklearn is blocked" in res.stderr


# ---------------------------------------------------------------------------
# the evaluators against scikit-learn's and crepes's fitted objects
# ---------------------------------------------------------------------------

def test_the_evaluators_answer_as_the_fitted_objects_bit_for_bit():
    from crepes import ConformalPredictiveSystem
    from sklearn.ensemble import HistGradientBoostingRegressor
    from sklearn.impute import SimpleImputer
    from sklearn.neighbors import LocalOutlierFactor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    rng = np.random.default_rng(3)
    x = rng.normal(size=(600, 4))
    x[rng.random(x.shape) < 0.1] = np.nan
    y = np.nan_to_num(x[:, 0]) * 2 + rng.normal(size=600)
    model = HistGradientBoostingRegressor(loss="quantile", quantile=0.3, max_iter=30,
                                          early_stopping=False).fit(x, y)
    probe = rng.normal(size=(300, 4)) * 2
    probe[rng.random(probe.shape) < 0.2] = np.nan
    probe[:5, 1] = np.inf
    assert np.array_equal(QuantileTrees.of(model).predict(probe), model.predict(probe))

    bins = rng.integers(0, 4, 600)
    cps = ConformalPredictiveSystem().fit(rng.normal(size=600), bins=bins)
    at = rng.integers(0, 5, 50)  # bin 4 holds no residual: crepes gives 0
    pct = np.r_[0.1, 1.0, 50.0, 99.0]
    with pytest.warns(UserWarning, match="too small"):  # 0.1 %: below every bin's first
        then = cps.predict(np.zeros(50), bins=at, lower_percentiles=pct)
    now = ResidualTable.of(cps).predict(np.zeros(50), bins=at, lower_percentiles=pct)
    assert np.array_equal(now, then) and np.isneginf(now[:, 0]).any() and (now[at == 4] == 0).all()

    pipe = make_pipeline(SimpleImputer(strategy="median", keep_empty_features=True),
                         StandardScaler(), LocalOutlierFactor(n_neighbors=20, novelty=True))
    pipe.fit(x)
    det = NoveltyDetector.of(pipe)
    probe = probe[np.isfinite(probe).all(axis=1) | np.isnan(probe).any(axis=1)]
    probe = np.where(np.isinf(probe), 0.0, probe)
    assert np.array_equal(det.score_samples(probe), pipe.score_samples(probe))
    assert np.array_equal(det.predict(probe), pipe.predict(probe))


def test_a_tree_walk_that_never_ends_stops():
    rng = np.random.default_rng(0)
    from sklearn.ensemble import HistGradientBoostingRegressor

    model = HistGradientBoostingRegressor(loss="quantile", quantile=0.5, max_iter=2).fit(
        rng.normal(size=(200, 2)), rng.normal(size=200))
    trees = QuantileTrees.of(model)
    trees.left[0] = 0  # the root its own child: refused by the check, and never walked forever
    with pytest.raises(ValueError, match="does not end"):
        trees.predict(np.zeros((3, 2)))


# ---------------------------------------------------------------------------
# crafted files
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def shipped_parts():
    return read_model_arrays(default_model_path())


@pytest.fixture(scope="module")
def blind_parts(shipped_parts):
    """The shipped file's learned_blind alone, with the reference catalogues and its reference
    forecasts: a sixth of the arrays, quick to write again."""
    header, arrays = shipped_parts
    kept = ("learned_blind.", "reference.learned_blind.", "reference.catalogue.")
    return ({**header, "content": {"learned_blind": header["content"]["learned_blind"]}},
            {n: a for n, a in arrays.items() if n.startswith(kept)})


def crafted(tmp_path, parts, change, name="crafted.zip"):
    """The shipped forecaster's header and arrays changed by ``change(header, arrays)``,
    written as a model file (the file's form itself sound)."""
    header, arrays = copy.deepcopy(parts)
    change(header, arrays)
    path = tmp_path / name
    path.write_bytes(model_arrays_bytes({k: v for k, v in header.items() if k != "arrays"},
                                        arrays))
    return path


def refused(path, *words):
    with pytest.raises(ModelFileError) as info:
        load_forecasters(path)
    line = str(info.value)
    assert "\n" not in line and line.startswith(str(path)), line
    for w in words:
        assert w in line, line
    return line


TREE = "learned_blind.models_.3"
CAL = "learned_blind.calibration_"
DETECTOR = "learned_blind.domain_.detectors_.0"


def _rename(node, old, new):
    """Every array name in a header's ``node`` that starts with ``old``, made to start with
    ``new`` (a part moved to another place of its estimator)."""
    for k, v in (node.items() if isinstance(node, dict) else enumerate(node)):
        if isinstance(v, str) and v.startswith(old):
            node[k] = new + v[len(old):]
        elif isinstance(v, (dict, list)):
            _rename(v, old, new)


def split_of(arrays):
    """The index of the first split node of the tree ``TREE``'s first tree."""
    return int(np.flatnonzero(~arrays[f"{TREE}.leaf"])[0])


def test_the_shipped_parts_load_as_written(tmp_path, shipped_parts):
    path = crafted(tmp_path, shipped_parts, lambda h, a: None)
    models, prov = load_forecasters(path)
    assert set(models) == set(shipped_parts[0]["content"]) and prov["rows"] >= 500


@pytest.mark.parametrize("attack, words", [
    ("child past the nodes", (TREE, "child index")),
    ("cycle", (TREE, "child index")),
    ("two parents", (TREE, "one tree")),
    ("nan threshold", (TREE, "NaN threshold")),
    ("feature past the inputs", (TREE, "feature outside")),
    ("wrong dtype", (TREE, "left has dtype float64")),
    ("missing array", (f"{TREE}.value", "missing")),
    ("reference no longer matches", ("reference forecast", "learned_blind", "not reproduced")),
    ("levels not increasing", ("learned_blind", "percentiles")),
    ("unread array", ("stray", "read by no part")),
    ("unread array of a tree", (f"{TREE}.stray", "read by no part")),
    ("reference catalogue moved", ("reference catalogues", "not those")),
    ("reference catalogue dropped", ("reference catalogues", "not those")),
    ("reference catalogues' count dropped", ("no reference catalogues",)),
    ("a number of two values", (f"{TREE}.baseline", "not (1,)")),
    ("trees not from node 0", (TREE, "tree starts are not")),
    ("a tree of no node", (TREE, "tree starts are not")),
    ("residuals not from 0", (f"{CAL}", "do not start at 0")),
    ("residuals unsorted", (f"{CAL}", "not sorted")),
    ("detector of no feature", (f"{DETECTOR}", "training points of shape")),
    ("a part of another class", ("learned_blind.climatology_", "not a Climatology")),
    ("a climatology of three avalanches", ("learned_blind.climatology_.alpha_c_",
                                           "holds 3 values, fewer than")),
    ("columns not the design's", ("learned_blind", "feature columns or names")),
    ("a regressor of another level", ("learned_blind", "the regressor of level 0.5")),
    ("tilt edges of a kind of record short", ("learned_blind", "not nested in 8 kinds")),
    ("nested edges short", ("learned_blind", "nested edges do not match")),
    ("counts of more bins than cells", ("learned_blind", "counts of another number of bins")),
    ("percentiles not the calibration's", ("learned_blind", "percentiles read are not")),
    ("an alarm's skill without its threshold", ("learned_blind", "not both held")),
    ("a reference forecast of no estimator", ("reference forecast 'ghost.quantiles'",
                                             "of no estimator")),
    ("a climatology of two dimensions", ("learned_blind.climatology_.alpha_c_",
                                         "has 2 dimensions, not 1")),
])
def test_a_crafted_file_is_refused_in_one_line_naming_the_array(tmp_path, blind_parts, attack,
                                                                  words):
    def change(header, a):
        s = split_of(a)
        if attack == "child past the nodes":
            a[f"{TREE}.left"][s] = 10**6
        elif attack == "cycle":
            a[f"{TREE}.right"][a[f"{TREE}.left"][s]] = s  # a child's child its parent
            a[f"{TREE}.leaf"][a[f"{TREE}.left"][s]] = False
        elif attack == "two parents":
            a[f"{TREE}.right"][s] = a[f"{TREE}.left"][s]
        elif attack == "nan threshold":
            a[f"{TREE}.threshold"][s] = np.nan
        elif attack == "feature past the inputs":
            a[f"{TREE}.feature"][s] = 10_000
        elif attack == "wrong dtype":
            a[f"{TREE}.left"] = a[f"{TREE}.left"].astype(np.float64)
        elif attack == "missing array":
            del a[f"{TREE}.value"]
        elif attack == "reference no longer matches":
            a[f"{TREE}.baseline"] = a[f"{TREE}.baseline"] + 1e-3  # a valid model, another one
        elif attack == "levels not increasing":
            a["learned_blind.percentiles_"] = a["learned_blind.percentiles_"][::-1].copy()
        elif attack == "reference catalogue moved":  # the forecasts recorded of other events
            a["reference.catalogue.alpha"][3] += 1e-9
        elif attack == "reference catalogue dropped":
            del a["reference.catalogue.size"]
        elif attack == "reference catalogues' count dropped":
            del a["reference.catalogue.tilt_now"]
        elif attack == "a number of two values":  # the first read, the second hidden
            a[f"{TREE}.baseline"] = np.repeat(a[f"{TREE}.baseline"], 2)
        elif attack == "trees not from node 0":
            a[f"{TREE}.tree_start"][0] = 1  # node 0 in no tree
        elif attack == "a tree of no node":
            a[f"{TREE}.tree_start"][1] = a[f"{TREE}.tree_start"][0]
        elif attack == "residuals not from 0":  # the first, one no bin reads
            a[f"{CAL}.start"] = a[f"{CAL}.start"] + 1
            a[f"{CAL}.residuals"] = np.r_[0.0, a[f"{CAL}.residuals"]]
        elif attack == "residuals unsorted":
            r, (i, j) = a[f"{CAL}.residuals"], a[f"{CAL}.start"][:2]
            r[i:j] = r[i:j][::-1].copy()
        elif attack == "detector of no feature":
            for k in ("points", "medians", "mean", "scale"):
                a[f"{DETECTOR}.{k}"] = a[f"{DETECTOR}.{k}"][..., :0].copy()
        elif attack == "a part of another class":  # a domain check where a climatology is read
            state = header["content"]["learned_blind"]["state"]
            state["climatology_"] = state.pop("domain_")
            for k in [k for k in a if k.startswith("learned_blind.climatology_.")]:
                del a[k]
            for k in [k for k in a if k.startswith("learned_blind.domain_.")]:
                a[k.replace("domain_", "climatology_", 1)] = a.pop(k)
            _rename(state["climatology_"], "learned_blind.domain_.", "learned_blind.climatology_.")
        elif attack == "a climatology of three avalanches":
            a["learned_blind.climatology_.alpha_c_"] = a["learned_blind.climatology_.alpha_c_"][:3]
        elif attack == "columns not the design's":
            a["learned_blind.columns_"][0] = ~a["learned_blind.columns_"][0]
        elif attack == "a regressor of another level":
            a["learned_blind.models_.3.quantile"] = np.array([0.55])
        elif attack == "tilt edges of a kind of record short":
            a["learned_blind.calibration_edges_"] = a["learned_blind.calibration_edges_"][:-1]
        elif attack == "nested edges short":
            a["learned_blind.calibration_event_edges_"] = \
                a["learned_blind.calibration_event_edges_"][:-1]
        elif attack == "counts of more bins than cells":
            a["learned_blind.calibration_counts_"] = np.r_[a["learned_blind.calibration_counts_"],
                                                           np.zeros(1000, dtype=np.int64)]
        elif attack == "percentiles not the calibration's":
            a["learned_blind.percentiles_"] = a["learned_blind.percentiles_"] + 0.25
        elif attack == "an alarm's skill without its threshold":
            header["content"]["learned_blind"]["state"]["alarm_threshold_"] = None
        elif attack == "a reference forecast of no estimator":
            a["reference.ghost.quantiles"] = a["reference.learned_blind.quantiles"]
        elif attack == "a climatology of two dimensions":
            alpha = a["learned_blind.climatology_.alpha_c_"]
            a["learned_blind.climatology_.alpha_c_"] = alpha[:, None]
        elif attack == "unread array of a tree":
            a[f"{TREE}.stray"] = np.zeros(3)
        else:
            a["stray"] = np.zeros(3)

    refused(crafted(tmp_path, blind_parts, change), *words)


def test_a_file_of_more_members_than_the_bound_is_refused_before_one_is_read(tmp_path,
                                                                            monkeypatch):
    """The bound on members (a zip's directory may list millions), here lowered to 3."""
    monkeypatch.setattr("sliders.io.model_arrays.MAX_MEMBERS", 3)
    path = tmp_path / "many.zip"
    with zipfile.ZipFile(path, "w") as zf:
        for i in range(4):
            zf.writestr(f"a{i}.npy", b"")
    refused(path, "4 members; a model file holds at most 3")


@pytest.mark.slow  # 300 MB through deflate
def test_members_of_one_name_or_inflating_past_the_bound_together_are_refused(tmp_path):
    """Two members named alike (which of them a reader takes is the zip library's choice),
    five members of 60 MB of zeros, each within its bound and together past the file's, and
    one member past its own."""
    twice, wide = tmp_path / "twice.zip", tmp_path / "wide.zip"
    with warnings.catch_warnings(), zipfile.ZipFile(twice, "w") as zf:
        warnings.simplefilter("ignore")  # zipfile warns of the name it writes twice
        zf.writestr("header.json", "{}")
        zf.writestr("header.json", "{}")
    refused(twice, "two members of one name")
    with zipfile.ZipFile(wide, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for i in range(5):
            zf.writestr(f"a{i}.npy", bytes(60 * 2**20))
    assert wide.stat().st_size < 2**20
    refused(wide, "members inflate to more than 256 MB")
    with zipfile.ZipFile(wide, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("a.npy", bytes(65 * 2**20))
    refused(wide, "member 'a.npy' inflates to 65 MB; a member holds at most 64 MB")


def test_a_file_that_grows_while_it_is_read_is_refused(tmp_path, monkeypatch):
    """Its status said 1 kB; 65 MB came: refused once read, not parsed."""
    path = tmp_path / "growing.zip"
    with open(path, "wb") as fh:
        fh.truncate(65 * 2**20)
    real = os.fstat
    monkeypatch.setattr("sliders.io.forecast_model.os.fstat",
                        lambda fd: os.stat_result((*real(fd)[:6], 1024, *real(fd)[7:])))
    refused(path, "more than 64 MB")


def test_every_class_a_model_file_holds_declares_its_parts():
    """A class a model file may name (``arrays.classes``), and each evaluator, declares its
    fitted parts for ``integrity.check_fields``: none is built unchecked."""
    from sliders.analysis.forecast.arrays import EVALUATORS, classes

    for cls in (*classes().values(), *EVALUATORS.values()):
        assert isinstance(cls.FIELDS, dict) and cls.FIELDS, cls.__name__


def test_a_model_file_is_read_before_a_member_is_trusted(tmp_path, shipped_parts):
    """A member the header does not list, a header declaring another shape, a truncated
    file, another kind of file: one line each."""
    good = crafted(tmp_path, shipped_parts, lambda h, a: None, "good.zip")
    blob = good.read_bytes()
    cut = tmp_path / "truncated.zip"
    cut.write_bytes(blob[: len(blob) // 2])
    refused(cut, "not a sliders model file")
    png = tmp_path / "figure.zip"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    refused(png, "not a sliders model file")
    extra, shape = tmp_path / "extra.zip", tmp_path / "shape.zip"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(extra, "w") as a, \
            zipfile.ZipFile(shape, "w") as b:
        for info in src.infolist():
            data = src.read(info)
            a.writestr(info.filename, data)
            if info.filename == "header.json":
                h = json.loads(data)
                h["arrays"][f"{TREE}.left"]["shape"] = [3]
                data = json.dumps(h).encode()
            b.writestr(info.filename, data)
        a.writestr("run_me.py", b"print('ran')")
    refused(extra, "run_me.py", "no array")
    refused(shape, f"{TREE}.left", "the header declares")


def test_a_file_that_would_run_code_on_load_is_refused_and_never_runs(tmp_path):
    """A header naming a class outside the package's estimators, an array that is a pickle of
    an object whose unpickling writes a marker, a plain pickle: refused, the marker never
    written."""
    import pickle

    sys.path.insert(0, str(pathlib.Path(__file__).parent))
    from marker_class import MarkerOnLoad, marker_file

    marker = tmp_path / "ran"
    refused(marker_file(tmp_path / "m.zip", marker), "'x'", "dtype")
    plain = tmp_path / "m.pkl"
    plain.write_bytes(pickle.dumps({"learned_blind": MarkerOnLoad(str(marker))}))
    refused(plain, "a pickle is never loaded")
    header = json.loads(zipfile.ZipFile(marker_file(tmp_path / "n.zip", marker))
                        .read("header.json"))
    del header["arrays"]["x"]
    header["content"]["learned_blind"]["state"] = {}
    named = tmp_path / "named.zip"
    with zipfile.ZipFile(named, "w") as z:
        z.writestr("header.json", json.dumps(header))
    refused(named, "marker_class.MarkerOnLoad", "no estimator of this package")
    assert not marker.exists()


def test_an_npy_header_of_another_form_is_refused(tmp_path, shipped_parts):
    """A member whose .npy header is Fortran-ordered (or of another version): refused, as the
    format writes one form only."""
    good = crafted(tmp_path, shipped_parts, lambda h, a: None, "good.zip")
    bad = tmp_path / "fortran.zip"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(bad, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "learned_blind.columns_.npy":
                buf = io.BytesIO()
                np.lib.format.write_array(buf, np.asfortranarray(np.load(io.BytesIO(data))))
                data = buf.getvalue().replace(b"'fortran_order': False", b"'fortran_order': True")
            dst.writestr(info.filename, data)
    refused(bad, "learned_blind.columns_", "not a NumPy array of this format")


def test_a_header_of_more_than_16_mb_is_refused_before_it_is_parsed(tmp_path):
    """20 MB of JSON deflated to a few kB: refused from its declared size."""
    path = tmp_path / "wide.zip"
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("header.json", "[" + "0," * 10_000_000 + "0]")
    assert path.stat().st_size < 2**20
    refused(path, "header inflates to 19 MB")


@pytest.mark.parametrize("header, words", [
    ("[" * 5000 + "]" * 5000, "not JSON"),
    ("{{{", "not JSON"),
    ({"format": "sliders-model-arrays-1", "arrays": [], "content": {}}, "lists no arrays"),
    ({"format": "sliders-model-arrays-1", "arrays": {"a": {"dtype": "|O", "shape": [2]}},
      "content": {}}, "no dtype"),
    ({"format": "sliders-model-arrays-1", "arrays": {"../a": {"dtype": "<f8", "shape": [2]}},
      "content": {}}, "not a name of an array"),
    ({"format": "sliders-model-arrays-1", "arrays": {}, "content": {}}, "no provenance"),
    ({"format": "sliders-model-arrays-1", "arrays": {"a": {"dtype": "<f8", "shape": [2]}},
      "content": {}}, "array 'a' is missing"),
    ({"format": "sliders-model-arrays-1", "arrays": {}, "provenance": {},
      "content": {"learned blind": {}}}, "no table of estimators"),
    ({"format": "sliders-model-arrays-1", "arrays": {}, "provenance": {}, "content": []},
     "no table of estimators"),
    ({"format": "sliders-model-arrays-1", "arrays": {}, "provenance": {},
      "content": {"learned_blind": {"object": "Learned", "state": {"__class__": 1}}}},
     "neither a parameter nor a fitted part"),
    ({"format": "sliders-model-arrays-1", "arrays": {}, "provenance": {},
      "content": {"learned_blind": {"object": "Learned", "state": {"models_": {"array": "x"}}}}},
     "array 'x' is missing"),
    ({"format": "sliders-model-arrays-1", "arrays": {}, "provenance": {},
      "content": {"learned_blind": {"object": "builtins.eval", "state": {}}}},
     "no estimator of this package"),
    ({"format": "sliders-model-arrays-1", "arrays": {}, "provenance": {},
      "content": {"learned_blind": {"object": "Learned", "state": {"inputs": {}}}}},
     "learned_blind.inputs: not a part of a model"),
    ({"format": "sliders-model-arrays-1", "arrays": {}, "provenance": {},
      "content": {"learned_blind": {"object": "Learned", "state": []}}},
     "learned_blind: a state that is not a table"),
    ({"schema": "another format's"}, "not a sliders model file of format"),
])
def test_a_malformed_header_is_one_line_naming_the_file(tmp_path, header, words):
    path = tmp_path / "bad.zip"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("header.json", header if isinstance(header, str) else json.dumps(header))
    refused(path, words)
