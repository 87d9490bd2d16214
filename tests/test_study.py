"""``python -m sliders.study``: sweeps with common random numbers, on the ensemble scheduler.

Tiny scenes (N = 12, explore mode); every run is a subprocess, like tests/test_ensemble.py.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest

from helpers import _env

pytestmark = pytest.mark.slow  # parameter studies under mpirun

MPIRUN = shutil.which("mpirun") or shutil.which("mpiexec")
TIMEOUT = 180
IGNORED = {"wall_time", "row_crc32"}  # depend on the run (the checksums cover the wall time)

STUDY_2X2 = """
[study]
realisations = 3
[scene]
n_sliders = 12
mode = "explore"
seed = 5
[axes]
xi = [0.0, 0.001]
mu_d = [0.5, 0.55]
"""


def study(args, n=None, **env):
    cmd = [sys.executable, "-m", "sliders.study"] + [str(a) for a in args]
    if n is not None:
        assert MPIRUN, "mpirun not found (install Debian mpich: scripts/setup.sh)"
        cmd = [MPIRUN, "-n", str(n)] + cmd
    return subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT, env=_env(**env))


def rows(path) -> dict[str, np.ndarray]:
    out = {}
    with h5py.File(path, "r") as f:
        f["points"].visititems(lambda n, o: out.__setitem__(n, o[()])
                               if isinstance(o, h5py.Dataset) else None)
    return out


@pytest.fixture
def spec(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(STUDY_2X2)
    return p


@pytest.mark.parametrize("storage", ["auto", "gather"])  # auto: parallel HDF5 (mpio) here
@pytest.mark.two_cores  # it starts mpirun -n 2
def test_two_ranks_same_bits_as_serial_and_same_seeds_at_every_point(spec, tmp_path, storage):
    serial, par = tmp_path / "serial.h5", tmp_path / "par.h5"
    a = study([spec, "--out", serial, "--quiet"])
    b = study([spec, "--out", par, "--quiet", "--storage", storage], n=2)
    assert a.returncode == 0 and b.returncode == 0, a.stderr + b.stderr
    ra, rb = rows(serial), rows(par)
    assert set(ra) == set(rb)
    compared = [k for k in ra if k.rsplit("/", 1)[-1] not in IGNORED]
    assert len(compared) > 4 * 10
    for k in compared:
        assert np.array_equal(ra[k], rb[k], equal_nan=True), k
    seeds = [rb[f"p{p:03d}/realisations/seed"] for p in range(4)]
    assert all(np.array_equal(s, seeds[0]) for s in seeds) and len(set(seeds[0])) == 3
    assert all(rb[f"p{p:03d}/realisations/done"].all() for p in range(4))
    with h5py.File(par, "r") as f:
        assert "common random numbers" in f.attrs["common_random_numbers"]
        # the points differ: xi and mu_d of point 3 are the last values of both axes
        assert json.loads(f["points/p003"].attrs["point_values"]) == {"xi": 0.001, "mu_d": 0.55}


def test_resume_completes_only_the_missing_rows(spec, tmp_path):
    out = tmp_path / "r.h5"
    first = study([spec, "--out", out, "--progress-interval", "0"],
                  SLIDERS_ENSEMBLE_STOP_AFTER=5)
    assert first.returncode != 0 and "--resume" in first.stderr
    before = rows(out)
    done_before = {p: before[f"p{p:03d}/realisations/done"].astype(bool) for p in range(4)}
    n_before = sum(int(d.sum()) for d in done_before.values())
    assert 0 < n_before < 12
    second = study([spec, "--out", out, "--resume", "--progress-interval", "0"])
    assert second.returncode == 0, second.stderr
    assert f"starting {12 - n_before} of 12 rows" in second.stderr.replace("resuming", "starting")
    after = rows(out)
    for p, d in done_before.items():
        wall = f"p{p:03d}/realisations/wall_time"
        assert np.array_equal(after[wall][d], before[wall][d])  # finished rows untouched
        assert after[f"p{p:03d}/realisations/done"].all()
    reference = tmp_path / "ref.h5"
    assert study([spec, "--out", reference, "--quiet"]).returncode == 0
    ref = rows(reference)
    for k in ref:
        if k.rsplit("/", 1)[-1] not in IGNORED:
            assert np.array_equal(ref[k], after[k], equal_nan=True), k


@pytest.mark.parametrize("axes, expected", [
    ("n_slider = [10, 12]", "axis 'n_slider' is not a scene parameter (did you mean 'n_sliders'?)"),
    ("xi = []", "axis 'xi' is empty"),
    ("mu_d = [0.5, 0.7]", "axis 'mu_d' at point 1 (mu_d=0.7)"),
    ("xi = [0.0, 0.001]\nmu_d = [0.5, 0.7]", "axis 'mu_d' at point 1 (xi=0.0, mu_d=0.7)"),
    ("seed = [1, 2]", "axis 'seed' cannot vary"),
    ('loading = ["tilt", "pushed_end"]', "axis 'loading' at point 1 (loading='pushed_end'): "
                                         "loading='pushed_end': ensembles and studies gather"),
])
def test_bad_study_is_one_line_before_anything_runs(tmp_path, axes, expected):
    p = tmp_path / "bad.toml"
    p.write_text(f"[study]\nrealisations = 2\n[scene]\nn_sliders = 12\n[axes]\n{axes}\n")
    out = tmp_path / "bad.h5"
    res = study([p, "--out", out])
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and expected in lines[0], res.stderr
    assert not out.exists()


def test_resume_against_a_different_study_is_refused(spec, tmp_path):
    out = tmp_path / "d.h5"
    assert study([spec, "--out", out, "--quiet"]).returncode == 0
    other = tmp_path / "other.toml"
    other.write_text(STUDY_2X2.replace("mu_d = [0.5, 0.55]", "mu_d = [0.5, 0.52]"))
    mtime = out.stat().st_mtime_ns
    res = study([other, "--out", out, "--resume"])
    lines = res.stderr.strip().splitlines()
    assert res.returncode != 0 and len(lines) == 1
    assert "holds a different study (axes differ" in lines[0]
    assert out.stat().st_mtime_ns == mtime


def test_xarray_view_has_the_axes_as_dimensions(spec, tmp_path):
    xr = pytest.importorskip("xarray", reason="xarray is an optional reader (pip install xarray)")
    out = tmp_path / "x.h5"
    assert study([spec, "--out", out, "--quiet"]).returncode == 0
    ds = xr.open_dataset(out, engine="h5netcdf")
    assert ds["alpha_c"].dims == ("xi", "mu_d", "realisation")
    assert list(ds["mu_d"].values) == [0.5, 0.55]
    # the view holds the rows of the points' groups
    r = rows(out)
    assert ds["alpha_c"].sel(xi=0.001, mu_d=0.5).values.tolist() == \
        r["p002/realisations/alpha_c"].tolist()
    assert bool(ds["done"].all())


def test_most_expensive_points_are_queued_first(tmp_path):
    from types import SimpleNamespace

    from sliders.analysis.study_spec import parse_study
    from sliders.runs.study import plan_study

    st = parse_study({"study": {"realisations": 2}, "scene": {"mode": "explore"},
                      "axes": {"n_sliders": [10, 40, 20]}})
    args = SimpleNamespace(out=str(tmp_path / "o.h5"), backend=None, resume=False,
                           overwrite=False, study="s.toml")
    plan = plan_study(args, st)
    # rows t = point * R + realisation: N = 40 (point 1), then N = 20 (point 2), then N = 10
    assert plan.pending.tolist() == [2, 3, 4, 5, 0, 1]


def test_paired_difference_uses_the_pairs():
    from sliders.analysis.study_analysis import paired_difference

    common = np.array([0.50, 0.52, 0.48, 0.51])  # the realisations' shared disorder
    a = {"done": np.ones(4, bool), "alpha_c": common}
    b = {"done": np.array([True, True, True, False]), "alpha_c": common + 0.01 + [0, 1e-4, -1e-4, 9]}
    d = paired_difference(a, b, "alpha_c")
    assert d["n"] == 3 and d["mean"] == pytest.approx(0.01)
    assert d["sem"] == pytest.approx(1e-4 / np.sqrt(3))  # the spread of the differences only
    assert d["sem_unpaired"] > 50 * d["sem"]


def test_figures_and_table_of_a_study(spec, tmp_path):
    out = tmp_path / "f.h5"
    assert study([spec, "--out", out, "--quiet"]).returncode == 0
    from sliders.analysis.study_analysis import markdown_table, study_table

    st, table = study_table(out)
    assert [t["mu_d"] for t in table] == [0.5, 0.55, 0.5, 0.55]
    assert all(t["bound_low"] < t["alpha_c_mean"] < t["bound_high"] for t in table)
    assert len(markdown_table(out).splitlines()) == 2 + 4
    res = subprocess.run([sys.executable, "-m", "sliders.figures", "--study", out, "--out",
                          tmp_path / "figs"], capture_output=True, text=True, timeout=TIMEOUT)
    assert res.returncode == 0, res.stderr
    pngs = sorted(p.name for p in (tmp_path / "figs").glob("*.png"))
    assert pngs == sorted(f"study_f_{n}.png" for n in ("alpha_c", "event_sizes", "transition",
                                                       "bursts", "sync", "alpha_c_paired"))
    bad = subprocess.run([sys.executable, "-m", "sliders.figures", "--study", spec],
                         capture_output=True, text=True, timeout=TIMEOUT)
    assert bad.returncode == 2 and "not a readable HDF5 file" in bad.stderr


def test_zipped_axes_vary_together(tmp_path):
    from sliders.analysis.study_spec import StudyError, parse_study

    data = {"study": {"realisations": 1, "zip": [["mu_d", "sigma_mu"]]}, "scene": {"n_sliders": 12},
            "axes": {"mu_d": [0.5, 0.55], "sigma_mu": [0.01, 0.02], "xi": [0.0, 0.001]}}
    st = parse_study(data)
    assert st.dims == [["mu_d", "sigma_mu"], ["xi"]] and st.shape == (2, 2)
    assert [(p["mu_d"], p["sigma_mu"]) for p in st.points] == [(0.5, 0.01)] * 2 + [(0.55, 0.02)] * 2
    data["axes"]["sigma_mu"] = [0.01]
    with pytest.raises(StudyError, match="zipped axes need equal lengths"):
        parse_study(data)
    xr = pytest.importorskip("xarray", reason="xarray is an optional reader (pip install xarray)")
    spec = tmp_path / "z.toml"
    spec.write_text('[study]\nrealisations = 2\nzip = [["mu_d", "sigma_mu"]]\n[scene]\n'
                    'n_sliders = 12\nmode = "explore"\n[axes]\nmu_d = [0.5, 0.55]\n'
                    'sigma_mu = [0.01, 0.02]\n')
    out = tmp_path / "z.h5"
    res = study([spec, "--out", out, "--quiet"])
    assert res.returncode == 0, res.stderr
    ds = xr.open_dataset(out, engine="h5netcdf")
    assert ds["alpha_c"].dims == ("mu_d", "realisation")
    assert ds["sigma_mu"].dims == ("mu_d",) and list(ds["sigma_mu"].values) == [0.01, 0.02]
