"""``python -m sliders.forecast train``: training inputs that cannot overlap, outputs that never
replace an input.

A pile given twice to ``train`` is fitted twice, or held out and fitted: the posterior's
calibration and the forecasters' expected accuracy are then measured partly in-sample.  Every
``--data`` and ``--calibration-data`` file is compared with every other (the same file by device
and inode, the same draw by its prior and seed, the same piles by the rows' seeds and events'
CRC-32s), and every output of ``train`` with every input, before anything is fitted.  Two tiny
prior ensembles (24 rows of 6 or 8 sliders, seeds 3 and 4) serve every test; the commands run in
this process (``cli.main``) and are refused before any fit.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from sliders.io.forecast_files import ForecastInputError
from sliders.io.prior_file import FINGERPRINTS, read_prior_ensemble, same_draw, shared_piles
from sliders.io.safeio import resolve_target
from sliders.runs.forecast import cli
from sliders.runs.forecast.train import calibration_sets, check_disjoint

from conftest import session_folder

TINY = ('[prior]\nrealisations = 24\nseed = {seed}\nceiling_step = 0.5\nceiling_k = 1\n{scene}'
        '[parameters]\nmu_d = {{ uniform = [0.3, 0.6] }}\n'
        'mu_s_minus_mu_d = {{ loguniform = [0.02, 0.1] }}\nsigma_mu = 0.01\n'
        'xi = {{ loguniform = [1e-3, 1.0], zero = 0.3 }}\nn_sliders = {{ choice = [6, 8] }}\n')
#: the same prior with a default of its scene written out: another prior table, the same piles
EXPLICIT_SCENE = "[scene]\nspring_length = 10.0\n"
POSTERIOR = ["train", "--fit", "posterior", "--max-iter", "3", "--quiet"]


def _make_priors(d: Path) -> None:
    from sliders.runs import prior as prior_run

    for name, seed, scene in (("a", 3, ""), ("b", 4, ""), ("a_spelled", 3, EXPLICIT_SCENE)):
        (d / f"{name}.toml").write_text(TINY.format(seed=seed, scene=scene))
        assert prior_run.main([str(d / f"{name}.toml"), "--out", str(d / f"{name}.h5"),
                               "--quiet"]) == 0


@pytest.fixture(scope="module")
def priors(tmp_path_factory) -> Path:
    """A folder of the prior files a.h5 (seed 3), b.h5 (seed 4) and a_spelled.h5 (a's prior
    with a default of its scene written out, seed 3: a's piles), a copy, a symlink and a hard
    link of a.h5, and a copy of b.h5."""
    made = session_folder("trust-training-inputs", _make_priors)
    d = tmp_path_factory.mktemp("inputs")
    for name in ("a", "b", "a_spelled"):
        shutil.copyfile(made / f"{name}.h5", d / f"{name}.h5")
    shutil.copyfile(d / "a.h5", d / "a_copy.h5")
    shutil.copyfile(d / "b.h5", d / "b_copy.h5")
    os.symlink("a.h5", d / "a_link.h5")
    os.link(d / "a.h5", d / "a_hard.h5")
    return d


def refused(capsys, args, *words) -> str:
    """``python -m sliders.forecast ARGS`` gives exit 2 and one line holding ``words``."""
    capsys.readouterr()
    assert cli.main([str(a) for a in args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


# -- the prior files' draws and piles, without a file ---------------------------------------
def _attrs(seed, fingerprints, scene=None, done=None):
    prior = {"parameters": {"mu_d": {"uniform": [0.3, 0.6]}}, "prior": {"seed": seed}}
    if scene is not None:
        prior["scene"] = scene
    a = {"prior": json.dumps(prior), FINGERPRINTS: np.asarray(fingerprints, dtype=np.uint64)}
    if done is not None:
        a["done"] = np.asarray(done, dtype=bool)
    return a


def test_one_draw_is_the_same_prior_and_seed():
    assert same_draw(_attrs(3, []), _attrs(3, []))
    assert not same_draw(_attrs(3, []), _attrs(4, []))
    assert not same_draw(_attrs(3, []), _attrs(3, [], scene={"mode": "explore"}))
    assert not same_draw(_attrs(None, []), _attrs(None, []))  # no seed: the piles tell


def test_shared_piles_are_rows_of_one_fingerprint_done_in_both():
    rows = [[11, 5, 77, 9], [12, 6, 78, 10], [13, 7, 79, 11]]
    assert shared_piles(_attrs(3, rows), _attrs(4, [[21, 5, 77, 9], [22, 1, 2, 3]])) == 0
    assert shared_piles(_attrs(3, rows), _attrs(4, [rows[2], [22, 1, 2, 3], rows[0]])) == 2
    assert shared_piles(_attrs(3, rows, done=[False, True, True]),
                        _attrs(4, [rows[0], rows[1]])) == 1  # row 0 not done in the first
    assert shared_piles(_attrs(3, rows), {"prior": "{}"}) == 0  # nothing recorded


# -- the commands ----------------------------------------------------------------------------
@pytest.mark.slow
def test_a_prior_file_records_what_identifies_its_piles(priors):
    a, a2, b = (read_prior_ensemble(priors / f"{n}.h5") for n in ("a", "a_spelled", "b"))
    assert a.attrs[FINGERPRINTS].shape == (len(a), 4)
    assert np.array_equal(a.parameters["seed"].astype(np.uint64), a.attrs[FINGERPRINTS][:, 0])
    assert shared_piles(a.attrs, a2.attrs) == len(a) and not same_draw(a.attrs, a2.attrs)
    assert shared_piles(a.attrs, b.attrs) == 0


@pytest.mark.slow
@pytest.mark.parametrize("second", ["a.h5", "a_link.h5", "a_hard.h5"])
def test_the_same_data_file_twice_is_refused(priors, capsys, second):
    refused(capsys, POSTERIOR + ["--data", priors / "a.h5", priors / second, "--out",
                                 priors / "m.zip"], "the same file as --data", "must not overlap")
    assert not (priors / "m.zip").exists()


@pytest.mark.slow
def test_a_copy_of_a_data_file_is_the_same_draw(priors, capsys):
    refused(capsys, POSTERIOR + ["--data", priors / "a.h5", priors / "a_copy.h5", "--out",
                                 priors / "m.zip"], "a_copy.h5: the same draw", "seed 3")


@pytest.mark.slow
def test_data_files_of_the_same_piles_under_another_prior_table_are_refused(priors, capsys):
    refused(capsys, ["train", "--data", priors / "a.h5", priors / "a_spelled.h5", "--quiet",
                     "--max-iter", "3", "--out", priors / "m.zip"],
            "24 of its piles are piles of --data")


@pytest.mark.slow
def test_a_calibration_file_among_the_data_files_is_refused(priors, capsys):
    """The seed check read the first --data file only: b.h5, the second, passed as a draw of
    its own and its piles were fitted and calibrated on."""
    refused(capsys, POSTERIOR + ["--data", priors / "a.h5", priors / "b.h5",
                                 "--calibration-data", priors / "b.h5", "--out",
                                 priors / "m.zip"], "--calibration-data", "seed 4",
            f"already used by --data {priors / 'b.h5'}")
    refused(capsys, POSTERIOR + ["--data", priors / "a.h5", priors / "b.h5",
                                 "--calibration-data", priors / "b_copy.h5", "--out",
                                 priors / "m.zip"], "b_copy.h5", "seed 4")


@pytest.mark.slow
def test_distinct_draws_pass_and_calibrate(priors):
    sets = [(f"--data {p}", resolve_target(p), read_prior_ensemble(p))
            for p in (priors / "a.h5",)]
    check_disjoint(sets)  # one file: nothing to compare
    args = argparse.Namespace(calibration_data=[str(priors / "b.h5")], fit="posterior")
    cal, seeds = calibration_sets(args, sets[0][2], sets)
    assert seeds == [4] and len(cal) == 24
    both = sets + [("--data b", resolve_target(priors / "b.h5"),
                    read_prior_ensemble(priors / "b.h5"))]
    check_disjoint(both)
    with pytest.raises(ForecastInputError, match="the same draw"):
        check_disjoint(both + [("--data a_copy", resolve_target(priors / "a_copy.h5"),
                                read_prior_ensemble(priors / "a_copy.h5"))])


@pytest.mark.slow
@pytest.mark.parametrize("out", ["b.h5", "b_link.h5", "a_hard.h5"])
def test_the_model_never_replaces_an_input(priors, capsys, out):
    """``--out`` an input (the calibration file itself, a symlink to it, a hard link of the
    data): refused before anything is fitted, the input as it was."""
    if out == "b_link.h5" and not (priors / out).exists():
        os.symlink("b.h5", priors / out)
    before = {n: (priors / n).read_bytes() for n in ("a.h5", "b.h5")}
    refused(capsys, POSTERIOR + ["--data", priors / "a.h5", "--calibration-data",
                                 priors / "b.h5", "--out", priors / out],
            "never replaces an input")
    assert {n: (priors / n).read_bytes() for n in before} == before


@pytest.mark.slow
def test_the_prior_ensemble_train_runs_never_replaces_an_input(priors, capsys, tmp_path):
    """With --prior, ``OUT.prior.h5`` is an output too: a symlink there to the calibration
    file is refused before the prior runs (it would be resumed into that file)."""
    toml = tmp_path / "p.toml"
    toml.write_text(TINY.format(seed=5, scene=""))
    out = tmp_path / "m.zip"
    os.symlink(priors / "b.h5", str(out) + ".prior.h5")
    before = (priors / "b.h5").read_bytes()
    refused(capsys, POSTERIOR + ["--prior", toml, "--calibration-data", priors / "b.h5",
                                 "--out", out], "m.zip.prior.h5", "never replaces an input")
    assert (priors / "b.h5").read_bytes() == before
    refused(capsys, POSTERIOR + ["--prior", toml, "--out", toml], "never replaces an input")
