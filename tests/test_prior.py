"""Prior ensembles (``python -m sliders.prior``): the design, the runner, the file, the reader.

Small priors (a dozen rows of N = 20-40 sliders, explore mode) keep every run
to a second or two; the design's distribution is tested on 4000 draws without
simulating anything.
"""

from __future__ import annotations

import math
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from scipy import stats

import sliders
from sliders.io.catalogue import EVENT_COLUMNS, Catalogue
from sliders.io.prior_file import read_prior_ensemble, read_prior_row
from sliders.runs import prior as prior_run
from sliders.runs import prior_spec
from helpers import SMALL_PRIOR, _env, assert_same_sets

pytestmark = pytest.mark.slow  # prior ensembles under mpirun

MPIRUN = shutil.which("mpirun") or shutil.which("mpiexec")
PY = sys.executable
TIMEOUT = 180


def _command(args, n=None):
    base = [PY, "-m", "sliders.prior"]
    if n is not None:
        assert MPIRUN, "mpirun not found (install Debian mpich: scripts/setup.sh)"
        base = [MPIRUN, "-n", str(n)] + base
    return base + [str(a) for a in args]


def run(args, n=None, env=None):
    return subprocess.run(_command(args, n), capture_output=True, text=True, env=env or _env(),
                          timeout=TIMEOUT)


@pytest.fixture(scope="module")
def small(small_prior):
    """``helpers.SMALL_PRIOR`` of 12 rows (the session's)."""
    return small_prior[0]


@pytest.fixture(scope="module")
def reference(small_prior):
    """The small prior run once, serially (read only by the tests)."""
    return small_prior[1]


# ---------------------------------------------------------------------------
# the design
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("design", prior_spec.DESIGNS)
def test_drawn_parameters_follow_the_prior(tmp_path, design):
    """Kolmogorov-Smirnov on 4000 draws of each marginal (no simulation), and the choices' shares."""
    path = tmp_path / "p.toml"
    path.write_text(SMALL_PRIOR.format(R=4000, design=design))
    prior = prior_spec.load_prior(path)
    v = prior.values()
    assert stats.kstest(v["mu_d"], stats.uniform(0.3, 0.5).cdf).pvalue > 1e-3
    assert stats.kstest(v["mu_s_minus_mu_d"], stats.loguniform(0.02, 0.12).cdf).pvalue > 1e-3
    assert stats.kstest(v["sigma_mu"], stats.uniform(0.005, 0.025).cdf).pvalue > 1e-3
    xi = v["xi"]
    assert abs(np.mean(xi == 0) - 0.5) < 0.04
    assert stats.kstest(xi[xi > 0], stats.loguniform(1e-4, 1e-2).cdf).pvalue > 1e-3
    shares = np.array([np.mean(v["n_sliders"] == n) for n in (20, 30, 40)])
    assert np.all(np.abs(shares - 1 / 3) < 0.04)
    assert np.allclose(v["mu_s_mean"], v["mu_d"] + v["mu_s_minus_mu_d"])
    # the KS test can tell: a wrong law is refused
    assert stats.kstest(v["mu_d"], stats.uniform(0.3, 0.45).cdf).pvalue < 1e-3
    # sobol and random: a sequence, so the first rows of a longer design are the same rows
    # (a Latin hypercube is stratified over all R rows at once)
    if design != "latin":
        assert np.array_equal(prior.unit_design(16), prior.unit_design(4000)[:16])


def test_weighted_choices_are_drawn_in_their_shares(tmp_path):
    """``choice = [..], weights = [..]``: each choice in its share of 4000 Sobol draws."""
    path = tmp_path / "p.toml"
    path.write_text(SMALL_PRIOR.format(R=4000, design="sobol").replace(
        "choice = [20, 30, 40] }", "choice = [20, 30, 40], weights = [6, 3, 1] }"))
    n = prior_spec.load_prior(path).values()["n_sliders"]
    shares = np.array([np.mean(n == k) for k in (20, 30, 40)])
    assert np.all(np.abs(shares - [0.6, 0.3, 0.1]) < 0.02), shares


@pytest.mark.parametrize("body, words", [
    ("n_sliders = { choice = [20, 30], weights = [1] }", "weights needs a list of 2 numbers"),
    ("n_sliders = { choice = [20, 30], weights = [1, 0] }", "must all be > 0"),
    ("mu_d = { uniform = [0.3, 0.8], weights = [1, 2] }", "goes with choice"),
    ("mu_q = { uniform = [0.3, 0.8] }", "unknown parameter 'mu_q'"),
    ("mu_d = { uniform = [0.8, 0.3] }", "empty range"),
    ("mu_d = { uniform = [0.5, 0.5] }", "empty range"),
    ("mu_d = { uniform = [0.3, 0.8] }\nmu_s_mean = { uniform = [0.6, 0.9] }",
     "allow mu_d >= mu_s_mean"),
    ("mu_d = 0.5\nmu_s_minus_mu_d = { uniform = [-0.01, 0.1] }", "gives mu_d >= mu_s_mean"),
    ("mu_d = { normal = [0.5, 0.1] }", "unknown distribution 'normal'"),
    ("sigma_mu = { loguniform = [0.0, 0.1] }", "needs 0 < low"),
])
def test_bad_priors_are_refused_in_one_line(tmp_path, capsys, body, words):
    path = tmp_path / "bad.toml"
    path.write_text("[prior]\nrealisations = 4\n[parameters]\n" + body + "\n")
    with pytest.raises(prior_spec.PriorError, match=words):
        prior_spec.load_prior(path)
    assert prior_run.main([str(path), "--out", str(tmp_path / "x.h5")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and words.split("'")[0] in lines[0]
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.parametrize("count, words, code", [
    (99999999999999999, "more than one file holds", 2),  # the plan alone would not fit in memory
    (9000000, "No space left on device", 1),             # fits in memory, no disk here holds it
])
def test_an_absurd_count_is_refused_at_once(tmp_path, capsys, count, words, code):
    """A count that no memory or disk could hold is refused in one line, in well under a second
    of work, before any row is drawn or any file made."""
    path = tmp_path / "huge.toml"
    path.write_text(f"[prior]\nrealisations = {count}\ndesign = 'random'\nceiling_k = 64\n"
                    "[parameters]\nmu_d = { uniform = [0.3, 0.5] }\n")  # rows of >= 30 kB: petabytes
    t0 = time.process_time()
    assert prior_run.main([str(path), "--out", str(tmp_path / "x.h5")]) == code
    assert time.process_time() - t0 < 5.0
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], lines
    assert os.listdir(tmp_path) == ["huge.toml"]


def test_a_bad_row_is_named_before_anything_runs(tmp_path, capsys):
    """Each scene is checked: a drawn xi that makes the given dt too long names the row."""
    path = tmp_path / "bad.toml"
    path.write_text("[prior]\nrealisations = 8\n[scene]\ndt = 0.05\n[parameters]\n"
                    "xi = { uniform = [0.0, 20.0] }\n")
    assert prior_run.main([str(path), "--out", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "row " in lines[0] and "dt=" in lines[0], err
    assert not (tmp_path / "x.h5").exists()


# ---------------------------------------------------------------------------
# the runner
# ---------------------------------------------------------------------------
@pytest.mark.two_cores  # it starts mpirun -n 2
def test_one_rank_equals_two_ranks(small, reference, tmp_path):
    """The same rows, events, parameters and ceiling, bit for bit, with 1 and 2 ranks."""
    out = tmp_path / "two.h5"
    done = run([small, "--out", out, "--quiet"], n=2)
    assert done.returncode == 0, done.stderr
    a, b = read_prior_ensemble(reference), read_prior_ensemble(out)
    assert len(a) == 12 and np.all(a.status == "avalanche")
    assert_same_sets(a, b)


def test_kill9_then_resume_equals_uninterrupted(small, reference, tmp_path):
    out = tmp_path / "killed.h5"
    proc = subprocess.Popen(_command([small, "--out", out, "--progress-interval", "0"]),
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env=_env(SLIDERS_ENSEMBLE_TEST_DELAY=0.3))
    try:
        for line in proc.stderr:
            if " 3/12 rows done" in line:
                break
        time.sleep(0.15)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    partial = read_prior_ensemble(out)
    assert 3 <= len(partial) < 12
    done = run([small, "--out", out, "--resume", "--quiet"])
    assert done.returncode == 0, done.stderr
    assert_same_sets(read_prior_ensemble(reference), read_prior_ensemble(out))


def test_a_row_is_the_tilt_of_its_scene(small, reference):
    """Row r's catalogue is ``sliders.tilt`` of its scene (same seed), its ceiling the chain's."""
    prior = prior_spec.load_prior(small)
    got = read_prior_ensemble(reference)
    for r in (0, 5):
        scene = prior.scene(r)
        assert scene.seed == int(got.parameters["seed"][r])
        result = sliders.tilt(scene)
        want = Catalogue.from_result(result)
        row = read_prior_row(reference, r)
        for c in EVENT_COLUMNS:
            assert np.array_equal(getattr(row, c), getattr(want, c)), c
        assert got.alpha_c[r] == result.alpha_c
        assert np.all(row.first >= 0) and np.all(row.last >= row.first)
        # the ceiling at one grid angle below alpha_c, from the uncut run's state there
        j = int(np.searchsorted(got.ceiling_alpha, result.alpha_c)) - 3
        g = got.ceiling_alpha[j]
        cut = sliders.tilt(scene.replace(alpha_max=float(g)))
        dist = cut.final.mu_s * math.cos(g) - np.abs(cut.force_at([g])[0])
        assert np.array_equal(got.ceiling_distance[r, j], np.sort(dist)[:8])
        assert np.all(np.isnan(got.ceiling_distance[r, j + 4:]))


def test_file_opens_in_xarray(reference):
    xr = pytest.importorskip("xarray")
    tree = xr.open_datatree(reference, engine="h5netcdf")
    rows, events = tree["realisations"].to_dataset(), tree["events"].to_dataset()
    assert rows.sizes["row"] == 12 and "event" in events.dims
    assert "mu_d" in rows.coords and rows["mu_d"].dims == ("row",)
    assert "alpha" in events.coords and events["size"].dims == ("event",)
    assert events["alpha"].attrs["units"] == "rad"
    assert rows["ceiling_distance"].attrs["units"] == "m g"
    assert rows["ceiling_distance"].dims == ("row", "ceiling_alpha", "nearest")
    assert "history" in tree.attrs and "prior" in tree.attrs
    got = read_prior_ensemble(reference)
    assert np.array_equal(events["alpha"].values, got.columns["alpha"])  # row order
    assert np.array_equal(rows["n_events"].values, np.diff(got.offsets))
    assert np.array_equal(rows["event_start"].values, got.offsets[:-1])


def test_damaged_events_are_found_and_recomputed(small, reference, tmp_path):
    """A flipped event value fails its row's checksum: the reader drops the row, --resume redoes it."""
    import h5py

    out = tmp_path / "damaged.h5"
    shutil.copy(reference, out)
    with h5py.File(out, "r+") as f:
        r = 4
        a = int(f["realisations/event_start"][r])
        f["events/alpha"][a + 1] += 1e-9
    got = read_prior_ensemble(out)
    assert len(got) == 11 and 4 not in got.attrs["rows"]
    with pytest.raises(Exception, match="row 4 .* fails its checksums"):
        read_prior_row(out, 4)
    done = run([small, "--out", out, "--resume", "--quiet"])
    assert done.returncode == 0, done.stderr
    assert_same_sets(read_prior_ensemble(reference), read_prior_ensemble(out))


def test_another_draw_is_the_same_prior_with_a_seed_of_its_own():
    import json

    from sliders.io.prior_file import another_draw, prior_seed

    def attrs(seed, mu_d=(0.2, 1.1), mode="explore"):
        return {"prior": json.dumps({"prior": {"seed": seed, "realisations": 10},
                                     "scene": {"mode": mode},
                                     "parameters": {"mu_d": {"uniform": list(mu_d)}}})}

    assert prior_seed(attrs(7)) == 7 and prior_seed({}) is None
    assert another_draw(attrs(1), attrs(2)) is None
    assert "seed 1" in another_draw(attrs(1), attrs(1))
    assert "seed 3" in another_draw(attrs(1), attrs(3), taken=[3])
    assert "not the same prior" in another_draw(attrs(1), attrs(2, mu_d=(0.2, 1.0)))
    assert "not the same prior" in another_draw(attrs(1), attrs(2, mode="history"))
    assert another_draw(attrs(1), {}) is not None
    seedless = json.loads(attrs(2)["prior"])
    del seedless["prior"]["seed"]
    assert "names no seed" in another_draw(attrs(1), {"prior": json.dumps(seedless)})
