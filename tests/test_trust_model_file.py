"""A model file is data the package checks, never a program the libraries run.

Each attack writes a model file of plain arrays whose contents are wrong (a
tree whose child points past its nodes or back to itself, NaN leaves, a zip
member that inflates to hundreds of MB, malformed calibration tables,
provenance holding terminal control sequences) and runs ``predict --model`` in
a subprocess with a timeout, so that a crash or a hang is seen as one: every
outcome must be one line naming the file and exit status 2.  The fuzz test
corrupts the shipped model's arrays at random (seeded): every outcome is the
uncorrupted forecast or a one-line refusal, never a crash, a hang or a NaN.
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import resource
import shutil
import subprocess
import sys
import zipfile

import numpy as np
import pytest

import sliders.analysis.forecast.model_file as model_file
from sliders.analysis.forecast import arrays
from sliders.analysis.forecast.model_file import load_forecasters
from sliders.forecasting.predict import load_model
from sliders.io.forecast_files import ForecastInputError
from sliders.io.forecast_model import (DIGEST_SUFFIX, ModelFileError, default_model_path,
                                      default_posterior_path)
from sliders.io.model_arrays import read_model_arrays

from helpers import rate_law_catalogue, write_model

pytestmark = pytest.mark.slow  # corrupted model files forecast in processes

PREDICT = [sys.executable, "-m", "sliders.forecast", "predict"]
#: a crash shows as a negative status, a hang as this timeout
TIMEOUT = 90


def _limit_memory():
    """The subprocess's address space capped (2 GB): a reader without bounds fails fast."""
    resource.setrlimit(resource.RLIMIT_AS, (2 * 2**30, 2 * 2**30))


def run_predict(args, timeout=TIMEOUT):
    """``predict ARGS`` in a subprocess: (status, stdout, stderr); a hang fails the test."""
    try:
        res = subprocess.run(PREDICT + [str(a) for a in args], capture_output=True, text=True,
                             timeout=timeout, preexec_fn=_limit_memory)
    except subprocess.TimeoutExpired:
        pytest.fail(f"predict {' '.join(map(str, args))} hung for {timeout} s")
    return res.returncode, res.stdout, res.stderr


@pytest.fixture(scope="module")
def catalogue_csv(tmp_path_factory):
    cat = rate_law_catalogue(0.6, 80.0, 0.5)
    path = tmp_path_factory.mktemp("cat") / "cat.csv"
    path.write_text("angle [rad],size\n" + "".join(f"{a:.12g},1\n" for a in cat.alpha))
    return path


@pytest.fixture(scope="module")
def reference(reduced, catalogue_csv, tmp_path_factory):
    """The reduced model's file and its forecast of the catalogue (JSON)."""
    path = write_model(tmp_path_factory.mktemp("ref") / "ref.zip", *reduced)
    code, out, err = run_predict([catalogue_csv, "--model", path, "--json"])
    assert code == 0, err
    return path, json.loads(out)


def attacked(reduced, tmp_path, change, name="attack.zip", **kw):
    """A copy of the reduced model changed by ``change(forecasters, provenance)``, written."""
    models, prov = copy.deepcopy(reduced)
    change(models, prov)
    return write_model(tmp_path / name, models, prov, **kw)


def assert_refused(code, out, err, path, *words):
    """Exit 2, one line on stderr naming the file and saying what is wrong; nothing forecast."""
    lines = err.strip().splitlines()
    assert code == 2, (code, err[-2000:])
    assert len(lines) == 1, err
    assert str(path) in lines[0] and "internal error" not in lines[0], lines[0]
    for w in words:
        assert w in lines[0], lines[0]
    assert "avalanche angle" not in out


def first_tree(models):
    """The first quantile regressor's trees (``evaluators.QuantileTrees``)."""
    return models["learned_blind"].models_[0]


def test_reduced_model_forecasts_like_a_model(reference):
    _, d = reference
    assert np.isfinite(d["alpha_c"]) and d["interval"][0] <= d["alpha_c"] <= d["interval"][1]


def test_a_child_index_past_the_nodes_is_refused_not_a_segfault(reduced, catalogue_csv, tmp_path):
    def change(models, prov):
        trees = first_tree(models)
        trees.left[0] = trees.left.size + 100_000

    path = attacked(reduced, tmp_path, change)
    assert_refused(*run_predict([catalogue_csv, "--model", path]), path, "child index")


def test_a_root_that_is_its_own_child_is_refused_not_a_hang(reduced, catalogue_csv, tmp_path):
    def change(models, prov):
        first_tree(models).left[0] = 0

    path = attacked(reduced, tmp_path, change)
    assert_refused(*run_predict([catalogue_csv, "--model", path], timeout=60), path, "child index")


def test_nan_leaves_are_refused(reduced, catalogue_csv, tmp_path):
    def change(models, prov):
        for m in models["learned_blind"].models_:
            m.value[m.leaf] = np.nan

    path = attacked(reduced, tmp_path, change)
    assert_refused(*run_predict([catalogue_csv, "--model", path]), path, "leaf value")


def test_a_member_that_inflates_to_hundreds_of_mb_is_refused_before_inflating(
        reduced, catalogue_csv, tmp_path):
    """320 MB of zeros in a file of 2 MB: refused from the member's declared size."""
    def change(models, prov):
        models["conditioned"].alpha_c_ = np.zeros(40_000_000)

    path = attacked(reduced, tmp_path, change)
    assert path.stat().st_size < 4 * 2**20
    assert_refused(*run_predict([catalogue_csv, "--model", path]), path, "inflates")


def test_a_device_is_refused_before_a_byte_is_read(catalogue_csv):
    assert_refused(*run_predict([catalogue_csv, "--model", "/dev/zero"]), "/dev/zero",
                   "not a regular file")


def test_a_model_file_above_the_size_bound_is_refused(catalogue_csv, tmp_path):
    path = tmp_path / "big.zip"
    with open(path, "wb") as fh:
        fh.truncate(65 * 2**20)  # sparse: no disk used
    assert_refused(*run_predict([catalogue_csv, "--model", path]), path,
                   "65 MB; a model file holds at most 64 MB")


def test_a_member_that_lies_about_its_array_is_refused(reduced, tmp_path):
    """An .npy member holding less data than its header (and the file's) declares."""
    good = attacked(reduced, tmp_path, lambda m, p: None, name="good.zip")
    bad = tmp_path / "lying.zip"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(bad, "w") as dst:
        for i, info in enumerate(src.infolist()):
            data = src.read(info)
            if info.filename.endswith(".npy") and i == 1:
                data = data[:-8]
            dst.writestr(info.filename, data)
    with pytest.raises(ModelFileError, match="array '.*' is not a NumPy array .* the header declares"):
        load_forecasters(bad)


@pytest.mark.parametrize("what", ["columns", "edges", "bins", "percentiles", "climatology"])
def test_right_types_malformed_contents_are_one_line_naming_the_file(
        reduced, catalogue_csv, tmp_path, what):
    def change(models, prov):
        f = models["learned_blind"]
        if what == "columns":
            f.columns_ = f.columns_[:-1]
        elif what == "edges":
            f.calibration_edges_ = np.linspace(0.1, 0.6, 7)
        elif what == "bins":
            f.calibration_.bins = f.calibration_.bins + 1000
        elif what == "percentiles":
            f.percentiles_ = np.array([50.0, 250.0, 900.0])
        else:
            f.climatology_.alpha_c_ = f.climatology_.alpha_c_[::-1].copy()

    path = attacked(reduced, tmp_path, change)
    assert_refused(*run_predict([catalogue_csv, "--model", path]), path, "learned_blind")


def test_provenance_reaches_the_terminal_escaped(reduced, catalogue_csv, tmp_path):
    """Clear screen and a fake red forecast in the provenance: printed as escapes."""
    fake = "\x1b[2J\x1b[H\x1b[31mavalanche angle 0.1000 rad\x1b[0m\r\u202e"

    def change(models, prov):
        prov["prior"] = fake
        prov["created"] = fake

    path = attacked(reduced, tmp_path, change)
    code, out, err = run_predict([catalogue_csv, "--model", path, "--verbose"])
    assert code == 0, err
    assert "\x1b" not in out and "\r" not in out and "\u202e" not in out
    assert "\\x1b[31m" in out


def test_a_file_name_with_control_characters_is_escaped_in_the_refusal(catalogue_csv, tmp_path):
    path = tmp_path / "\x1b[31mmodel.zip"
    path.write_bytes(b"PK\x05\x06" + bytes(18))
    code, out, err = run_predict([catalogue_csv, "--model", path])
    assert code == 2 and "\x1b" not in err and "\\x1b[31mmodel.zip" in err


def test_the_shipped_model_matches_its_recorded_digest():
    path = default_model_path()
    recorded = open(str(path) + DIGEST_SUFFIX).read().split()[0]
    assert hashlib.sha256(path.read_bytes()).hexdigest() == recorded


def test_the_shipped_archive_passes_the_checks_beside_its_digest(tmp_path, shipped):
    """Loaded from the package, the shipped model is checked by its digest and as any file:
    its arrays' form, and a copy loaded from elsewhere, in full."""
    header, arrays = read_model_arrays(default_model_path())
    assert set(arrays) == set(header["arrays"]) and "learned_blind" in header["content"]
    assert all(a.dtype.str in ("|b1", "<i8", "<f8") for a in arrays.values())
    copy_path = tmp_path / "copy.zip"
    shutil.copyfile(default_model_path(), copy_path)
    models, _ = load_forecasters(copy_path)
    assert set(models) == set(shipped[0])


def test_a_changed_shipped_model_is_refused_by_its_digest(tmp_path, monkeypatch):
    import sliders.io.forecast_model as fm

    copy_path = tmp_path / fm.DEFAULT_MODEL_NAME
    shutil.copyfile(default_model_path(), copy_path)
    shutil.copyfile(str(default_model_path()) + DIGEST_SUFFIX, str(copy_path) + DIGEST_SUFFIX)
    with open(copy_path, "r+b") as fh:  # one byte of the zip's comment area: still a zip
        fh.seek(0, 2)
        fh.write(b"\0")
    monkeypatch.setattr(model_file, "default_model_path", lambda: copy_path)
    with pytest.raises(ModelFileError, match="SHA-256"):
        model_file.load_forecasters(copy_path)


# ---------------------------------------------------------------------------
# the fuzz: random corruptions of the shipped model's arrays
# ---------------------------------------------------------------------------
FUZZ_CASES = 30


def _arrays(f):
    """(name, holder, attribute) of the arrays of a learned forecaster that a forecast reads."""
    out = []
    for i, m in enumerate(f.models_):
        for field in ("left", "right", "feature", "value", "threshold", "leaf", "missing_left",
                      "tree_start"):
            out.append((f"regressor {i} {field}", m, field))
    det = next(d for d in f.domain_.detectors_ if d is not None)
    out += [("climatology", f.climatology_, "alpha_c_"), ("remaining", f, "remaining_quantiles_"),
            ("edges", f, "calibration_edges_"), ("percentiles", f, "percentiles_"),
            ("residuals", f.calibration_, "residuals"), ("calibration bins", f.calibration_, "bins"),
            ("lof points", det, "points"), ("lof densities", det, "density"),
            ("lof distances", det, "k_distance"), ("scaler", det, "scale")]
    return out


def corrupt(models, seed: int) -> str:
    """One seeded corruption of the learned forecaster's arrays; its description."""
    rng = np.random.default_rng(seed)
    f = models["learned_blind"]
    name, holder, key = _arrays(f)[rng.integers(len(_arrays(f)))]
    a = np.array(getattr(holder, key))
    k = tuple(rng.integers(0, s) for s in a.shape)
    kind = rng.choice(["nan", "inf", "huge", "negative", "past_end", "self", "truncate"])
    flat = a.reshape(-1)
    idx = int(np.ravel_multi_index(k, a.shape)) if a.ndim else 0
    if kind == "truncate":
        a = a[:-1]
    elif a.dtype.kind == "b":
        flat[idx] = not flat[idx]
    elif a.dtype.kind == "f":
        flat[idx] = {"nan": np.nan, "inf": np.inf, "huge": 1e300, "negative": -1e300,
                     "past_end": np.nan, "self": -np.inf}[kind]
    else:
        info = np.iinfo(a.dtype)
        flat[idx] = {"nan": info.max, "inf": info.max, "huge": info.max, "self": idx,
                     "negative": info.min, "past_end": a.size + 7}[kind]
    setattr(holder, key, a)
    return f"{kind} in {name}"


#: one process forecasts every corrupted file the check let through, as ``predict --json``
#: does, and prints one JSON line a file: a crash or a hang stops its lines at that file
FORECAST_EACH = """
import contextlib, io, json, sys
from sliders.runs.forecast.cli import main
catalogue, files = sys.argv[1], sys.argv[2:]
for path in files:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(["predict", catalogue, "--model", path, "--json"])
        except SystemExit as exc:
            code = exc.code
    print(json.dumps({"file": path, "code": code, "out": out.getvalue(), "err": err.getvalue()}),
          flush=True)
"""


def test_fuzz_every_corruption_is_the_forecast_or_a_refusal(reduced, reference, catalogue_csv,
                                                            tmp_path):
    """Each of ``FUZZ_CASES`` seeded corruptions is refused by the check in one line, or (the
    corruption touched nothing a forecast reads) gives the uncorrupted forecast itself, read
    in a process of its own: never a crash, a hang or a NaN."""
    written, refused = {}, 0
    clean = str(reference[0])
    _, parts = read_model_arrays(clean)
    recorded = {k[len("reference."):]: a for k, a in parts.items()
                if k.startswith("reference.") and not k.startswith("reference.catalogue.")}
    for seed in range(FUZZ_CASES):
        models, prov = copy.deepcopy(reduced)
        what = corrupt(models, seed)
        path = write_model(tmp_path / f"fuzz{seed}.zip", models, prov, references=recorded)
        try:
            load_forecasters(path)
        except ModelFileError as exc:
            assert "\n" not in str(exc) and str(exc).startswith(str(path)), what
            refused += 1
            continue
        written[str(path)] = what
    assert refused, "no corruption was refused"
    assert written, "every corruption was refused by the check: none reached a forecast"
    try:
        res = subprocess.run([sys.executable, "-c", FORECAST_EACH, str(catalogue_csv), *written],
                             capture_output=True, text=True, timeout=TIMEOUT + 5 * len(written),
                             preexec_fn=_limit_memory)
    except subprocess.TimeoutExpired as exc:
        done = (exc.stdout or b"").decode().count("\n")
        pytest.fail(f"hung on {list(written.values())[done]}")
    lines = [json.loads(line) for line in res.stdout.splitlines()]
    print(f"{refused} refused by the check, {len(written)} read and forecast")
    assert len(lines) == len(written), (f"crashed ({res.returncode}) on "
                                        f"{list(written.values())[len(lines)]}: {res.stderr[-2000:]}")
    ref = reference[1]
    for line in lines:
        what = written[line["file"]]
        assert line["code"] in (0, 2), (what, line)
        if line["code"] == 2:
            assert len(line["err"].strip().splitlines()) == 1, (what, line["err"])
            continue
        d = json.loads(line["out"])
        assert d["alpha_c"] == ref["alpha_c"] and d["interval"] == ref["interval"], what


# ---------------------------------------------------------------------------
# exit status under mpirun
# ---------------------------------------------------------------------------


def test_a_forecast_reads_and_checks_only_the_forecasters_it_uses(reduced, tmp_path):
    """The shipped file holds ten forecasters; a forecast of angles and sizes needs one.  A
    file whose inverse-rate forecaster has a NaN in its climatology still forecasts a
    catalogue of angles and sizes (that forecaster never read), refuses in one line the moment
    that forecaster is asked for, and is refused whole by ``load_forecasters``."""
    models, prov = copy.deepcopy(reduced)
    models["ffm_ml_events"].climatology_.alpha_c_[3] = np.nan
    path = write_model(tmp_path / "partly.zip", models, prov, references=arrays.reference_outputs(
        reduced[0], arrays.reference_cuts()))
    with pytest.raises(ModelFileError, match="ffm_ml_events.climatology_.alpha_c_ holds NaN"):
        load_forecasters(path)
    with pytest.raises(ForecastInputError, match="holds NaN"):
        load_model(path)  # the Python API's default: every forecaster checked at load
    model = load_model(path, lazy=True)  # as the commands load it
    cat = rate_law_catalogue(0.6, 80.0, 0.5)
    d = model.predict({"angle [rad]": cat.alpha, "size": cat.size}).to_dict()
    assert np.isfinite(d["alpha_c"]) and set(model.models._trusted) == {"learned_blind"}
    with pytest.raises(ModelFileError) as info:
        model.predict({"angle [rad]": cat.alpha, "size": cat.size}, method="ffm_ml_events")
    line = str(info.value)
    assert "\n" not in line and line.startswith(str(path)) and "holds NaN" in line, line


def _drop_reference(name):
    """A change that leaves out the reference forecast ``name`` (or, ``+name``, adds one)."""
    def change(models, prov):
        refs = arrays.reference_outputs(models, arrays.reference_cuts())
        if name.startswith("+"):
            refs[name[1:]] = refs["conditioned.quantiles"]
        else:
            del refs[name]
        prov["references"] = refs
    return change


def _domain(**parts):
    def change(models, prov):
        domain = models["learned_blind"].domain_
        for k, v in parts.items():
            setattr(domain, k, v(domain) if callable(v) else v)
    return change


def _shrink_detector(domain):
    detectors = list(domain.detectors_)
    k = next(i for i, d in enumerate(detectors) if d is not None)
    d = copy.copy(detectors[k])
    d.points, d.medians, d.mean, d.scale = (d.points[:, :-1], d.medians[:-1], d.mean[:-1],
                                            d.scale[:-1])
    detectors[k] = d
    return detectors


@pytest.mark.parametrize("change, words", [
    (_drop_reference("learned_blind.raw"), "reference forecast 'learned_blind.raw' is missing"),
    (_drop_reference("+conditioned.extra"),
     "reference forecast 'conditioned.extra' is of no estimator of the file"),
    (_domain(features=("tilt", "the pile's colour")), "learned_blind.domain_: unknown features"),
    (_domain(features=("tilt", "tilt")), "learned_blind.domain_: unknown features"),
    (_domain(detectors_=_shrink_detector), "detector reads other features than its class's"),
    (_domain(n_sliders_range_=np.array([300.0, 50.0])), "the range of sliders is reversed"),
], ids=["reference missing", "reference of no estimator", "unknown domain feature",
        "domain feature twice", "detector narrower than its class", "sliders range reversed"])
def test_a_file_whose_parts_disagree_is_refused_saying_which(reduced, tmp_path, change, words):
    """Parts each of the right form that do not fit together: the reference forecasts a file
    carries against those of its estimators, a domain check's features against its detectors.
    Each is one line naming the file and the disagreement, before a forecast is made."""
    models, prov = copy.deepcopy(reduced)
    change(models, prov)
    refs = prov.pop("references", None)
    path = write_model(tmp_path / "disagree.zip", models, prov, references=refs)
    with pytest.raises(ModelFileError) as info:
        load_forecasters(path)
    line = str(info.value)
    assert "\n" not in line and line.startswith(str(path)) and words in line, line


#: the parts of a shipped estimator that no forecast or inference reads (training's settings
#: and records): a file may hold anything there, and forecasts as before
READ_BY_NO_FORECAST = {
    "learned_blind": {"calibration_bins", "calibration_event_bins", "calibration_size_bins",
                      "calibration_remaining_bins", "domain_contamination", "draws_per_row",
                      "learning_rate", "max_bins", "max_iter", "max_leaf_nodes",
                      "min_samples_leaf", "n_calibration_cuts_", "n_training_cuts_",
                      "random_state", "domain_.contamination", "domain_.max_samples",
                      "domain_.n_neighbors", "domain_.random_state"},
    "model_based": {"draws_per_row", "random_state"},
    "posterior": {"angles_sizes_share", "calibration_share", "degrade", "domain_level",
                  "draws_per_row", "exact_share", "learning_rate", "max_bins", "max_iter",
                  "max_leaf_nodes", "min_samples_leaf", "n_calibration_cuts_",
                  "n_calibration_realisations_", "n_training_cuts_", "random_state",
                  "domain_.contamination", "domain_.max_samples", "domain_.n_neighbors",
                  "domain_.random_state"}}


def _state_parts(node, prefix=()):
    """The paths (keys within ``state``, nested estimators' too) of an estimator's parts."""
    for key, value in node["state"].items():
        yield (*prefix, key)
        if isinstance(value, dict) and "object" in value:
            yield from _state_parts(value, (*prefix, key))


@pytest.mark.parametrize("method", ["learned_blind", "conditioned", "ffm_ml_events",
                                    "model_based", "posterior"])
def test_every_part_a_forecast_reads_is_checked_by_its_name(method):
    """Each part of a shipped estimator in turn is replaced by a table it never holds: the file
    is refused in one line naming that part (``learned_blind.domain_.top_tilt_``), unless the
    part is one no forecast reads (``READ_BY_NO_FORECAST``), where the reference forecasts
    come out as before.  A fitted part a class forgot to declare shows here, as one accepted."""
    path = default_posterior_path() if method == "posterior" else default_model_path()
    archive = model_file.ModelArchive.open(path)
    accepted = set()
    for parts in _state_parts(archive.header["content"][method]):
        changed = copy.copy(archive)
        changed.header = copy.deepcopy(archive.header)
        node = changed.header["content"][method]
        for key in parts[:-1]:
            node = node["state"][key]
        node["state"][parts[-1]] = {"dict": {"corrupt": 1.0}}
        name = ".".join(parts)
        gone = f"{method}.{name}"  # its arrays gone with it: none left for no part to read
        changed.schema = {n: s for n, s in archive.schema.items()
                          if n != gone and not n.startswith(gone + ".")}
        try:
            model_file.ModelForecasters(changed)[method]
        except ModelFileError as exc:
            line = str(exc)
            owner = ".".join((method, *parts[:-1]))  # or its owner's consistency check
            assert "\n" not in line and line.startswith(str(path)) and (
                f"{method}.{name}" in line or f"{owner}: " in line), (name, line)
        else:
            accepted.add(name)
    assert accepted == READ_BY_NO_FORECAST.get(method, set())
