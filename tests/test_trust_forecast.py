"""Trust of ``python -m sliders.forecast evaluate / predict``: the attacks on the forecast
commands, one test each (docs/reliability.md counts them by class).

Classes: 1. one-line refusals (bad files, bad options, Ctrl-C); 2. outputs (the claim,
inputs compared with outputs by identity, one set published whole or not at all, leftover
temporaries); 3. the catalogue reader (bounded input, malformed columns); 4. the model file.
One small prior ensemble (12 rows, N = 20-40) and one previous evaluation of it serve every
test; evaluations are tiny (3 boosting iterations, one lead, no alarm beyond 3 rows).
"""

from __future__ import annotations

import json
import os
import pickle
import resource
import shutil
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import h5py
import numpy as np
import pytest

from sliders.io import safeio
from sliders.io.model_arrays import MODEL_ARRAYS_FORMAT as MODEL_FORMAT
from sliders.runs import ensemble, study
from sliders.io.forecast_files import ForecastInputError, read_catalogue_csv
from sliders.runs.forecast import cli as forecast_cli
from sliders.runs.forecast import evaluate as rf_evaluate

from conftest import session_folder
from marker_class import archive_as_is

pytestmark = pytest.mark.slow  # attacks on the forecast commands, each a process

PY = sys.executable
MPIRUN = shutil.which("mpirun") or shutil.which("mpiexec")
TIMEOUT = 300
FAST = ["--max-iter", "3", "--boot", "5", "--alarm-rows", "3", "--leads-deg", "1", "--tilts",
        "0.2", "--only", "learned,learned_blind"]
STUDY = """
[study]
realisations = 1
[scene]
n_sliders = 10
mode = "explore"
[axes]
xi = [0.0, 0.001]
"""
MODEL, TABLE, METRICS, FIGURES = (rf_evaluate.MODEL_NAME, rf_evaluate.TABLE_NAME,
                                  rf_evaluate.METRICS_NAME, rf_evaluate.FIGURE_NAMES)
CATALOGUE = "angle [deg],size\n" + "".join(f"{a:.2f},1\n" for a in np.linspace(1, 12, 30))


def _env(**extra):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    env.update({k: str(v) for k, v in extra.items()})
    return env


def cli(*args, n=None, timeout=TIMEOUT, **kw):
    """``python -m sliders.forecast ARGS`` in a subprocess (under ``mpirun -n n`` if given)."""
    base = [PY, "-m", "sliders.forecast"]
    if n is not None:
        assert MPIRUN, "mpirun not found (install Debian mpich: scripts/setup.sh)"
        base = [MPIRUN, "-n", str(n)] + base
    return subprocess.run(base + [str(a) for a in args], capture_output=True, text=True,
                          timeout=timeout, env=_env(), **kw)


def forecast_main(capsys, *args) -> tuple[int, str]:
    code = forecast_cli.main([str(a) for a in args])
    return code, capsys.readouterr().err


def one_line(code: int, err: str, status: int = 2) -> str:
    """The refusal: exit ``status``, one line on stderr, no traceback."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    assert code == status, (code, err)
    assert lines[0].startswith("sliders.forecast: error: "), lines[0]
    return lines[0]


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file of ``folder`` (hidden ones too) with its bytes."""
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def leftovers(folder: Path) -> list[str]:
    """Hidden files: temporaries, claims, records of a publication (none once a run ends)."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


@pytest.fixture(scope="module")
def prior(small_prior) -> Path:
    """A 12-row prior ensemble (``python -m sliders.prior``), made once for every worker."""
    return small_prior[1]


@pytest.fixture(scope="module")
def previous(prior) -> Path:
    """A complete evaluation of ``prior`` (seed 0): the set a rerun must never damage (made
    once for every worker; the tests change copies of it, ``out``)."""
    def evaluate(d: Path) -> None:
        assert forecast_cli.main(["evaluate", "--data", str(prior), "--out", str(d / "out"),
                                  "--quiet", *FAST]) == 0
    return session_folder("trust-forecast-previous", evaluate) / "out"


@pytest.fixture
def out(previous, tmp_path) -> Path:
    """A fresh copy of the previous evaluation's folder."""
    shutil.copytree(previous, tmp_path / "out")
    return tmp_path / "out"


@pytest.fixture
def catalogue(tmp_path) -> Path:
    (tmp_path / "cat.csv").write_text(CATALOGUE)
    return tmp_path / "cat.csv"


# ---------------------------------------------------------------------------
# 1. one-line refusals
# ---------------------------------------------------------------------------
def ensemble_file(folder: Path) -> Path:
    path = folder / "e.h5"
    assert ensemble.main(["--n-sliders", "10", "--mode", "explore", "-R", "2", "--quiet",
                          "--out", str(path)]) == 0
    return path


def study_file(folder: Path) -> Path:
    (folder / "s.toml").write_text(STUDY)
    assert study.main([str(folder / "s.toml"), "--out", str(folder / "s.h5"), "--quiet"]) == 0
    return folder / "s.h5"


def truncated_prior(folder: Path, prior: Path) -> Path:
    path = folder / "truncated.h5"
    path.write_bytes(prior.read_bytes()[: prior.stat().st_size // 2])
    return path


def newer_prior(folder: Path, prior: Path) -> Path:
    path = folder / "newer.h5"
    shutil.copy(prior, path)
    with h5py.File(path, "r+") as f:
        f.attrs["format_version"] = 99
        safeio.seal_attrs(f)
    return path


@pytest.mark.parametrize("make, words", [
    (lambda d, p: ensemble_file(d), "ensemble"), (lambda d, p: study_file(d), "study"),
    (truncated_prior, "truncated.h5"), (newer_prior, "format_version 99")])
def test_evaluate_on_a_file_that_is_no_prior_ensemble_is_one_line(tmp_path, prior, capsys, make,
                                                                   words):
    data = make(tmp_path, prior)
    capsys.readouterr()
    code, err = forecast_main(capsys, "evaluate", "--data", data, "--out", tmp_path / "o", *FAST)
    line = one_line(code, err)
    assert "--data" in line and words in line
    assert not (tmp_path / "o" / TABLE).exists()


@pytest.mark.parametrize("options, words", [
    (["--fractions", "0.98", "0.01", "0.01"], "validation part"),  # too few rows to split
    (["--fractions", "0.5", "0.5", "0.5"], "--fractions"),
    (["--fractions", "nan", "0.5", "0.5"], "--fractions"),
    (["--fractions", "-0.2", "0.7", "0.5"], "--fractions"),
    (["--only", "bogus"], "'bogus'"),
    (["--tilts", "-1"], "--tilts -1"),
    (["--tilts", "2"], "--tilts 2"),
    (["--leads-deg", "nan"], "--leads-deg"),
    (["--max-iter", "0"], "--max-iter 0"),
    (["--boot", "0"], "--boot 0"),
    (["--seed", "-1"], "--seed -1"),
    (["--robust", "test=x.h5"], "'test'"),
    (["--frobnicate"], "unrecognized arguments"),
])
def test_bad_evaluate_options_are_one_line(tmp_path, prior, capsys, options, words):
    base = ["evaluate", "--data", prior, "--out", tmp_path / "o", *FAST]
    code, err = forecast_main(capsys, *base, *options)
    assert words in one_line(code, err)
    assert not (tmp_path / "o" / TABLE).exists()


def test_out_that_is_a_file_is_refused_before_any_fitting(tmp_path, prior, capsys, monkeypatch):
    def no_fitting(*args, **kw):
        raise AssertionError("fitting started")

    monkeypatch.setattr(rf_evaluate, "make_forecasters", no_fitting)
    monkeypatch.setattr(rf_evaluate, "dev_catalogue_set", no_fitting)
    (tmp_path / "file").write_text("mine")
    for source in (["--data", prior], ["--dev", "40"]):
        code, err = forecast_main(capsys, "evaluate", *source, "--out", tmp_path / "file")
        assert "is not a folder" in one_line(code, err)
    assert (tmp_path / "file").read_text() == "mine"


@pytest.mark.parametrize("options, words", [
    (["--within", "nan"], "--within nan"), (["--within", "-5"], "--within -5"),
    (["--tilt-now=--"], "--tilt-now"), (["--tilt-now", "1000deg"], "outside [0, 90°)"),
    (["--tilt-now", "90deg"], "outside [0, 90°)"), (["--tilt-now", "100rad"], "outside [0, 90°)"),
    (["--tilt-now=-1deg"], "outside [0, 90°)"),
])
def test_bad_predict_options_are_one_line(previous, catalogue, capsys, options, words):
    code, err = forecast_main(capsys, "predict", catalogue, "--model",
                              previous / MODEL, *options)
    assert words in one_line(code, err)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_evaluate_stopped_by_a_signal_is_one_line_and_leaves_the_previous_set(out, prior, signum):
    before = snapshot(out)
    proc = subprocess.Popen([PY, "-m", "sliders.forecast", "evaluate", "--data", str(prior),
                             "--out", str(out), *FAST, "--max-iter", "2000"],
                            stderr=subprocess.PIPE, text=True, env=_env())
    for line in proc.stderr:  # stopped while the forecasters are fitted
        if "fitted conditioned" in line:
            break
    proc.send_signal(signum)
    err = proc.stderr.read()
    code = proc.wait(timeout=TIMEOUT)
    assert code == 128 + signum and "Traceback" not in err, err
    assert [ln for ln in err.splitlines() if "error" in ln] == [err.strip()]
    assert "interrupted" in err
    assert snapshot(out) == before and leftovers(out) == []


@pytest.mark.ranks_share_one_core  # a serial command: rank 1 sleeps until rank 0's status
def test_predict_under_mpirun_is_one_answer_and_one_refusal(previous, catalogue):
    good = cli("predict", catalogue, "--model", previous / MODEL, "--json", n=2)
    assert good.returncode == 0, good.stderr
    assert len(good.stdout.strip().splitlines()) == 1
    bad = cli("predict", catalogue, "--model", previous / MODEL, "--within", "nan", n=2)
    assert bad.returncode == 2 and "--within" in one_line(bad.returncode, bad.stderr)


@pytest.mark.ranks_share_one_core  # a serial command: rank 1 sleeps until rank 0's status
def test_evaluate_under_mpirun_refuses_in_one_line(tmp_path, prior):
    res = cli("evaluate", "--data", prior, "--out", tmp_path / "o", "--tilts", "-1", n=2)
    assert "--tilts" in one_line(res.returncode, res.stderr)


# ---------------------------------------------------------------------------
# 2. outputs: claim, identity, one set
# ---------------------------------------------------------------------------
def test_model_file_that_is_a_symlink_to_the_data_is_refused(tmp_path, prior, capsys):
    data = tmp_path / "data.h5"
    shutil.copy(prior, data)
    before = data.read_bytes()
    (tmp_path / "o").mkdir()
    (tmp_path / "o" / MODEL).symlink_to(data)
    code, err = forecast_main(capsys, "evaluate", "--data", data, "--out", tmp_path / "o", *FAST)
    line = one_line(code, err)
    assert MODEL in line and "--data" in line
    assert data.read_bytes() == before and leftovers(tmp_path / "o") == []


@pytest.mark.parametrize("how", ["symlink", "hard link", "other path"])
def test_robust_set_that_is_the_data_file_is_refused(tmp_path, prior, capsys, how):
    data = tmp_path / "data.h5"
    shutil.copy(prior, data)
    twin = {"symlink": tmp_path / "twin.h5", "hard link": tmp_path / "twin.h5",
            "other path": tmp_path / "." / "sub" / ".." / "data.h5"}[how]
    (tmp_path / "sub").mkdir()
    if how == "symlink":
        twin.symlink_to(data)
    elif how == "hard link":
        os.link(data, twin)
    code, err = forecast_main(capsys, "evaluate", "--data", data, "--robust", f"zero={twin}",
                              "--out", tmp_path / "o", *FAST)
    assert "the same file" in one_line(code, err)


def test_second_evaluate_of_one_folder_is_refused_through_a_symlink(out, prior, tmp_path):
    (tmp_path / "alias").symlink_to(out)
    first = subprocess.Popen([PY, "-m", "sliders.forecast", "evaluate", "--data", str(prior),
                              "--out", str(out), *FAST, "--max-iter", "2000"],
                             stderr=subprocess.PIPE, text=True, env=_env())
    try:
        for line in first.stderr:
            if "fitted conditioned" in line:
                break
        second = cli("evaluate", "--data", prior, "--out", tmp_path / "alias", *FAST, "--quiet")
        line = one_line(second.returncode, second.stderr)
        assert f"pid {first.pid}" in line
    finally:
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=TIMEOUT)


def test_killed_evaluates_temporaries_are_removed_by_the_next_run(out, prior, capsys):
    stale = out / f".{TABLE}.k1ll3d9x.tmp"
    stale.write_text("half a table")
    code, err = forecast_main(capsys, "evaluate", "--data", prior, "--out", out, *FAST,
                              "--no-figures")
    assert code == 0, err
    assert "removed 1 temporary file" in err and leftovers(out) == []


def test_failed_figures_leave_the_previous_set_whole(out, prior, capsys, monkeypatch):
    """No room left while the figures are drawn (the last files of the set)."""
    import sliders.figures.forecast as figures

    def full_disk(results, example, out_dir):
        raise OSError(28, os.strerror(28), str(Path(out_dir) / "forecast_error.png"))

    monkeypatch.setattr(figures, "draw_all", full_disk)
    assert_full_disk_leaves_the_previous_set(out, prior, capsys)


def assert_full_disk_leaves_the_previous_set(out, prior, capsys):
    """A rerun (seed 1) that runs out of room: one line naming the reason, no trace of it."""
    before = snapshot(out)
    code, err = forecast_main(capsys, "evaluate", "--data", prior, "--out", out, *FAST,
                              "--seed", "1", "--quiet")
    assert "No space left on device" in one_line(code, err, status=1)
    assert snapshot(out) == before and leftovers(out) == []


def test_full_disk_while_publishing_leaves_the_previous_set_whole(out, prior, capsys, monkeypatch):
    """The third file flushed to the disk fails: nothing of the new set may be seen."""
    real_fsync, calls = os.fsync, []

    def fsync(fd):
        calls.append(fd)
        if len(calls) == 3:
            raise OSError(28, os.strerror(28))
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    assert_full_disk_leaves_the_previous_set(out, prior, capsys)


KILLER = """
import os, signal, sys
import {module} as target
real, calls = target.{name}, []
def killed(*args, **kw):
    calls.append(args)
    if len(calls) <= {spare}:
        return real(*args, **kw)
    {action}
    os.kill(os.getpid(), signal.SIGKILL)
target.{name} = killed
from sliders.runs.forecast.cli import main
sys.exit(main(sys.argv[1:]))
"""


def killed_run(prior, out, module, name, spare, action, *extra):
    """An evaluation killed (SIGKILL) at its call ``spare + 1`` of ``module.name``, after ``action``."""
    code = KILLER.format(module=module, name=name, spare=spare, action=action)
    res = subprocess.run([PY, "-c", code, "evaluate", "--data", str(prior), "--out", str(out),
                          *FAST, "--quiet", *extra], capture_output=True, text=True,
                         timeout=TIMEOUT, env=_env())
    assert res.returncode == -signal.SIGKILL, res.stderr


def test_kill9_while_a_figure_is_written_leaves_the_previous_figures(out, prior):
    """savefig killed once it has opened its file: the published figures keep their bytes."""
    before = snapshot(out)
    killed_run(prior, out, "matplotlib.figure", "Figure.savefig", 0, "open(args[1], 'wb').close()",
               "--seed", "1")
    after = snapshot(out)
    for name in FIGURES:
        assert after[name] == before[name] and len(after[name]) > 1000


def test_kill9_while_publishing_is_completed_by_the_next_claim(out, prior, tmp_path, capsys):
    """Killed after the set's record and its first rename: the next holder of the folder (here
    an evaluation refused after its claim) finishes the publication, so the metrics, the model
    and the figures are all the killed run's (seed 1), none the previous run's (seed 0)."""
    before = snapshot(out)
    killed_run(prior, out, "os", "replace", 2, "pass", "--seed", "1")
    (tmp_path / "not_a_prior.h5").write_text("text")
    code, err = forecast_main(capsys, "evaluate", "--data", tmp_path / "not_a_prior.h5",
                              "--out", out)
    assert code == 2 and "finished publishing" in err, err
    metrics = json.loads((out / METRICS).read_text())
    assert "--seed 1" in metrics["provenance"]["command"]
    after = snapshot(out)
    assert all(after[name] != before[name] for name in [MODEL, *FIGURES])
    assert leftovers(out) == []


# ---------------------------------------------------------------------------
# 3. the catalogue reader
# ---------------------------------------------------------------------------
def limited(max_bytes: int):
    """preexec_fn: the child may map at most ``max_bytes`` (an unbounded reader fails fast)."""
    return lambda: resource.setrlimit(resource.RLIMIT_AS, (max_bytes, max_bytes))


@pytest.mark.parametrize("source", ["/dev/zero", "sparse 100 MB"])
def test_endless_or_huge_catalogue_is_refused_quickly_in_bounded_memory(previous, tmp_path, source):
    path = source
    if source.startswith("sparse"):
        path = tmp_path / "huge.csv"
        with open(path, "wb") as fh:
            fh.write(b"angle [deg],size\n")
            fh.truncate(100 * 2**20)
    t = time.monotonic()
    res = cli("predict", path, "--model", previous / MODEL, timeout=60,
              preexec_fn=limited(1500 * 2**20))
    assert time.monotonic() - t < 30
    line = one_line(res.returncode, res.stderr)
    assert str(path) in line and ("MB" in line or "bytes" in line)


def test_too_many_events_are_refused_naming_the_row(tmp_path):
    path = tmp_path / "many.csv"
    n = 10**6 + 1  # the most a catalogue may hold, and one more
    with open(path, "w") as fh:
        fh.write("angle [rad],size\n")
        fh.writelines(f"{1e-6 * i:.7f},1\n" for i in range(n))
    with pytest.raises(ForecastInputError, match=f"row {n + 1}: more than"):
        read_catalogue_csv(str(path))


@pytest.mark.parametrize("text, words", [
    (b"angle [deg],size,size\n1,1,1\n", "column 'size' appears 2 times"),
    (b"angle [deg],size,angle [rad]\n1,1,0.1\n", "column 'angle' appears 2 times"),
    (b"angle [deg],size\n1,1" + b"0" * 300 + b"\n", "row 2, column 'size'"),
    (b"angle [deg],size\n1,1e300\n", "row 2, column 'size': '1e300' must be a positive number"),
    (b"angle [deg],size,first,last\n1,1,1e19,1\n", "row 2, column 'first'"),
    (b"angle [deg],size,first\n1,1,1\n", "column 'first' without 'last'"),
    (b"angle [deg],size\n1," + b"1" * 200000 + b"\n", "row 2: longer than"),
    (b"angle [deg],size\n95,1\n", "row 2, column 'angle': '95' is outside"),
    (b"angle [deg],size\n1,1\n\xff\n", "row 3: not UTF-8"),
])
def test_malformed_catalogue_is_one_line_naming_row_or_column(tmp_path, text, words):
    path = tmp_path / "bad.csv"
    path.write_bytes(text)
    with pytest.raises(ForecastInputError) as info:
        read_catalogue_csv(str(path))
    assert words in str(info.value) and "\n" not in str(info.value)


def test_spreadsheet_csv_with_a_byte_order_mark_is_read(tmp_path, previous, capsys):
    path = tmp_path / "excel.csv"
    path.write_bytes(b"\xef\xbb\xbf" + CATALOGUE.replace("\n", "\r\n").encode())
    cat = read_catalogue_csv(str(path))
    assert len(cat) == 30 and np.isclose(cat.alpha[-1], np.radians(12.0))
    code, err = forecast_main(capsys, "predict", path, "--model", previous / MODEL)
    assert code == 0, err


# ---------------------------------------------------------------------------
# 4. the model file
# ---------------------------------------------------------------------------
def pickle_model_file(path: Path, blob: bytes) -> Path:
    """A pickle behind a JSON header with its CRC-32: a model file of the pickle kind."""
    head = json.dumps({"format": "sliders-forecaster-1", "crc32": zlib.crc32(blob)}).encode()
    path.write_bytes(len(head).to_bytes(8, "little") + head + blob)
    return path


class Vanished:
    """A forecaster class a later sliders no longer has."""


def test_pickle_model_file_is_refused_unread(tmp_path, catalogue, capsys):
    marker = tmp_path / "ran"

    class Runs:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    path = pickle_model_file(tmp_path / "m.pkl", pickle.dumps({"learned_blind": Runs()}))
    code, err = forecast_main(capsys, "predict", catalogue, "--model", path)
    assert "a pickle is never loaded" in one_line(code, err) and not marker.exists()


def test_model_naming_a_class_this_version_lacks_is_one_line(tmp_path, catalogue, capsys):
    path = archive_as_is(tmp_path / "m.zip", {
        "format": MODEL_FORMAT, "provenance": {}, "arrays": {},
        "content": {"learned_blind": {"object": Vanished.__name__, "state": {}}}})
    code, err = forecast_main(capsys, "predict", catalogue, "--model", path)
    assert "'Vanished'" in one_line(code, err) and "refused" in err


def test_model_of_a_forecaster_lacking_what_this_version_reads_is_one_line(
        tmp_path, previous, catalogue, capsys):
    """A forecaster of a known class whose fitted state differs (another version's)."""
    from sliders.analysis.forecast.model_file import load_forecasters

    from helpers import write_model

    models, prov = load_forecasters(previous / MODEL)
    del models["learned_blind"].domain_
    path = write_model(tmp_path / "m.zip", models, prov | {"sliders": "0.0.1"})
    code, err = forecast_main(capsys, "predict", catalogue, "--model", path)
    assert "sliders 0.0.1" in one_line(code, err) and "train it again" in err


@pytest.mark.parametrize("contents, words", [
    ([1, 2, 3], "not a sliders model file of format"),
    ({"format": MODEL_FORMAT, "provenance": {}, "arrays": {},
      "content": {"learned_blind": "not a forecaster"}}, "'learned_blind' holds no estimator"),
    ({"format": MODEL_FORMAT, "provenance": {}, "arrays": {}, "content": {}},
     "no forecaster of angles and sizes"),
])
def test_model_holding_the_wrong_contents_is_one_line(tmp_path, catalogue, capsys, contents,
                                                      words):
    path = archive_as_is(tmp_path / "m.zip", contents)
    code, err = forecast_main(capsys, "predict", catalogue, "--model", path)
    assert words in one_line(code, err)
