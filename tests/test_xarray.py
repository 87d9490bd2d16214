"""Every file the package writes opens in xarray (h5netcdf) with named dimensions and coordinates."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import tomllib
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest

import sliders
from sliders.analysis.summary import load_summary

pytestmark = pytest.mark.slow  # ensembles and studies run as commands, then opened

xr = pytest.importorskip("xarray", reason="xarray not installed (pip install '.[test]')")
pytest.importorskip("h5netcdf", reason="h5netcdf not installed (pip install '.[test]')")

ROOT = Path(__file__).resolve().parents[1]
SCENE_ARGS = ["--n-sliders", "40", "--seed", "3", "--mode", "explore"]
R = 4


def open_group(path, group=None):
    """open_dataset without phony_dims: a dataset without named dimensions would warn/raise."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # h5netcdf warns when it has to invent phony dimensions
        return xr.open_dataset(path, engine="h5netcdf", group=group)


def all_dims(path, groups):
    dims = {}
    for g in groups:
        with open_group(path, g) as ds:
            dims[g] = dict(ds.sizes)
    return dims


@pytest.fixture(scope="module")
def tilt_file(tmp_path_factory):
    result = sliders.tilt(sliders.Scene(n_sliders=40, seed=3, mode="explore"))
    path = tmp_path_factory.mktemp("xr") / "tilt.h5"
    result.save(path)
    return result, path


def ensemble_file(directory, n_ranks):
    out = Path(directory) / f"ens{n_ranks}.h5"
    cmd = [sys.executable, "-m", "sliders.ensemble", *SCENE_ARGS, "--realisations", str(R),
           "--out", str(out), "--quiet"]
    if n_ranks > 1:
        cmd = ["mpirun", "-n", str(n_ranks)] + cmd
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    return out


def test_tilt_file(tilt_file):
    result, path = tilt_file
    k, n = result.n_events, result.scene.n_sliders
    dims = all_dims(path, ["/", "events", "displacement", "initial", "final"])
    assert dims["events"] == {"event": k}
    assert dims["initial"] == dims["final"] == {"slider": n}
    assert dims["displacement"] == {"event_boundary": k + 1,
                                    "entry": result.displacement.index.size}
    tree = xr.open_datatree(path, engine="h5netcdf")
    events = tree["events"].to_dataset()
    assert list(events.event.values) == list(range(k))  # coordinate inherited from the root
    assert events.alpha.attrs["units"] == "rad" and "incline" in events.alpha.attrs["long_name"]
    assert events.drive.attrs["units"] == "rad" and "tilt" in events.drive.attrs["long_name"]
    assert np.array_equal(events.drive.values, result.drive)
    assert events.duration.attrs["units"] == "tau"
    # one reduction against the package's own numbers
    assert float(events.n_moved.sum()) == result.events["n_moved"].sum()
    final = tree["final"].to_dataset()
    assert np.array_equal(final.displacement.values, result.final.displacement)
    assert final.displacement.dims == ("slider",)


def test_tilt_file_provenance(tilt_file):
    result, path = tilt_file
    with open_group(path) as ds:
        a = ds.attrs
    assert a["source"].startswith(f"sliders {sliders.__version__}")
    assert f"N = {result.scene.n_sliders}" in a["title"]
    # the history names the process that wrote the file: this test's (pytest, or an xdist worker)
    # (its arguments as the interpreter got them: "-m pytest ..." or an xdist worker's "-c ...")
    command = shlex.join(sys.orig_argv[1:])
    assert re.match(r"\d{4}-\d\d-\d\dT", a["history"]) and a["history"].endswith(command)
    assert a["hdf5_version"] == h5py.version.hdf5_version and a["numpy_version"] == np.__version__
    assert a["python_version"] == sys.version.split()[0] and a["h5py_version"] == h5py.__version__
    scene = sliders.Scene.from_dict(tomllib.loads(a["scene_toml"])["scene"])
    assert scene == result.scene  # the TOML gives the scene back
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True,
                          text=True)
    if head.returncode == 0 and Path(sliders.__file__).is_relative_to(ROOT):
        assert a["git_commit"].startswith(head.stdout.strip())


# 2: parallel HDF5 (mpio), described by rank 0
@pytest.mark.parametrize("n_ranks", [1, pytest.param(2, marks=pytest.mark.two_cores)])
def test_ensemble_file(tmp_path, n_ranks):
    path = ensemble_file(tmp_path, n_ranks)
    dims = all_dims(path, ["/", "grids", "realisations", "realisations/statistics"])
    with h5py.File(path, "r") as f:  # one CRC-32 per row and column (storage.ROW_DIGEST)
        n_columns = len(json.loads(f["realisations/row_crc32"].attrs["columns"]))
    assert dims["realisations"] == {"realisation": R, "checksummed_column": n_columns}
    stats = dims["realisations/statistics"]
    assert stats["realisation"] == R and stats["force_bin"] == 120 and stats["alpha"] == 55
    tree = xr.open_datatree(path, engine="h5netcdf")
    ds = tree["realisations/statistics"].to_dataset()
    assert ds.force_counts.dims == ("realisation", "alpha", "force_bin")
    assert ds.stopped_ratio_counts.dims == ("realisation", "stop_alpha_bin", "ratio_bin")
    assert ds.force_bin.attrs["units"] == "m g"
    summary, grids, scene, info = load_summary(path)
    assert np.array_equal(ds.alpha.values, grids.alpha)
    assert np.allclose(ds.force_bin.values, 0.5 * (grids.force_edges[1:] + grids.force_edges[:-1]))
    # one reduction: A(alpha) averaged over the realisations at rest, as load_summary gives it
    rows = tree["realisations"].to_dataset()
    assert list(rows.realisation.values) == list(range(R)) and rows.alpha_c.dims == ("realisation",)
    a_mean = ds.cumulated_displacement.where(ds.valid_alpha).mean("realisation")
    assert np.allclose(a_mean.values, summary.cumulated_mean, equal_nan=True)
    assert "sliders.ensemble" in tree.attrs["history"] and "[scene]" in tree.attrs["scene_toml"]


def readme_xarray_example() -> str:
    """The example of the documentation's xarray how-to (it was the README's)."""
    text = (ROOT / "docs" / "howto" / "xarray.md").read_text()
    return re.search(r"```python\n(.*?)```", text, flags=re.S).group(1)


def test_readme_example_gives_the_package_force_pdf(tmp_path, monkeypatch):
    """The docs' few lines (mean force PDF at alpha = 0.3) == load_summary's force_pdf there."""
    path = ensemble_file(tmp_path, 1)
    monkeypatch.chdir(tmp_path)
    Path("n100.h5").symlink_to(path)
    namespace: dict = {}
    exec(readme_xarray_example(), namespace)  # noqa: S102 - the README's own code
    summary, grids, _, _ = load_summary(path)
    g = int(np.argmin(np.abs(grids.alpha - 0.3)))
    assert np.allclose(namespace["pdf"].values, summary.force_pdf[g], rtol=1e-12, atol=0)
    assert namespace["pdf"].dims == ("force_bin",)


# ---------------------------------------------------------------------------
# every kind of file: the whole tree opens with named dimensions, no warning
# ---------------------------------------------------------------------------
STUDY_TOML = """
[study]
realisations = 2
zip = [["mu_d", "sigma_mu"]]
[scene]
n_sliders = 12
mode = "explore"
[axes]
xi = [0.0, 0.001]
mu_d = [0.5, 0.55]
sigma_mu = [0.01, 0.02]
"""
PRIOR_TOML = """
[prior]
realisations = 4
seed = 2
ceiling_step = 0.05
ceiling_k = 3
[parameters]
mu_d = { uniform = [0.4, 0.6] }
mu_s_minus_mu_d = { loguniform = [0.02, 0.12] }
n_sliders = { choice = [12, 16] }
initial_forces = { choice = ["uniform", "zero"] }
"""


def command(module, *args, n_ranks=1):
    cmd = [sys.executable, "-m", module, *map(str, args), "--quiet"]
    if n_ranks > 1:
        cmd = ["mpirun", "-n", str(n_ranks)] + cmd
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr


def every_kind_of_file(d: Path) -> dict[str, Path]:
    """One file of every kind the package writes, in ``d``."""
    files = {}
    for name, scene in (("tilt", sliders.Scene(n_sliders=20, seed=1, mode="explore")),
                        ("tilt_summary", sliders.Scene(n_sliders=20, seed=1, record="summary")),
                        ("pushed_end", sliders.Scene(n_sliders=20, seed=1, loading="pushed_end",
                                                     incline=0.2, mode="explore"))):
        files[name] = d / f"{name}.h5"
        sliders.tilt(scene).save(files[name])
    files["ensemble"], files["ensemble_mpio"] = ensemble_file(d, 1), ensemble_file(d, 2)
    chunks = [d / f"chunk{i}.h5" for i in range(2)]
    for i, chunk in enumerate(chunks):
        command("sliders.ensemble", *SCENE_ARGS, "--realisations", R, "--chunk", f"{i}/2",
                "--out", chunk)
    files["merged"] = d / "merged.h5"
    res = subprocess.run([sys.executable, "-m", "sliders.merge", files["merged"], *chunks],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    for kind, text in (("study", STUDY_TOML), ("prior", PRIOR_TOML)):
        (d / f"{kind}.toml").write_text(text)
        files[kind] = d / f"{kind}.h5"
        command(f"sliders.{kind}", d / f"{kind}.toml", "--out", files[kind])
    return files


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return every_kind_of_file(tmp_path_factory.mktemp("kinds"))


KINDS = ("tilt", "tilt_summary", "pushed_end", "ensemble", "ensemble_mpio", "merged", "study",
         "prior")


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.two_cores  # its fixture writes files on 2 ranks
def test_every_file_opens_as_a_tree_with_named_dimensions_and_no_warning(files, kind):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # phony dimensions, undecodable attributes, ...
        tree = xr.open_datatree(files[kind], engine="h5netcdf")
        nodes = {node.path: node.to_dataset() for node in tree.subtree}
    phony = {path: [d for d in ds.dims if str(d).startswith("phony_dim")]
             for path, ds in nodes.items()}
    assert not any(phony.values()), phony
    variables = {f"{path}/{v}": ds[v] for path, ds in nodes.items() for v in ds.variables}
    assert len(variables) > 5
    unitless = [name for name, v in variables.items() if v.ndim and "units" not in v.attrs]
    assert not unitless, unitless


@pytest.mark.two_cores  # its fixture writes files on 2 ranks
def test_tilt_events_have_the_drive_as_coordinate_and_the_recipe_gives_dense_displacements(
        files, tmp_path, monkeypatch):
    result = sliders.Result.load(files["tilt"])
    tree = xr.open_datatree(files["tilt"], engine="h5netcdf")
    events = tree["events"].to_dataset()
    assert "drive" in events.coords and events.coords["drive"].dims == ("event",)
    assert np.array_equal(events.n_moved.sel(event=events.drive < 0.3).values,
                          result.events["n_moved"][result.events["drive"] < 0.3])
    monkeypatch.chdir(tmp_path)
    Path("run.h5").symlink_to(files["tilt"])
    namespace = {"xr": xr, "np": np}
    exec(dense_recipe(), namespace)  # noqa: S102 - the how-to's own line
    dense = namespace["dense"]
    assert dense.shape == (result.n_events, result.scene.n_sliders)
    assert np.array_equal(dense, result.displacement.dense())
    k = int(np.argmax(result.events["n_moved"]))
    assert np.flatnonzero(dense[k]).size == result.events["n_moved"][k] > 1


@pytest.mark.two_cores  # its fixture writes files on 2 ranks
def test_the_drive_of_a_pushed_end_is_a_length(files):
    events = xr.open_datatree(files["pushed_end"], engine="h5netcdf")["events"].to_dataset()
    assert events.drive.attrs["units"] == "g tau^2" and "driver" in events.drive.attrs["long_name"]
    assert events.alpha.attrs["units"] == "rad" and np.all(events.alpha.values == events.alpha.values[0])
    tilted = xr.open_datatree(files["tilt"], engine="h5netcdf")["events"].to_dataset()
    assert tilted.drive.attrs["units"] == "rad" and tilted.alpha.attrs["units"] == "rad"


def dense_recipe() -> str:
    """The how-to's line that makes the dense (event, slider) displacements of a tilt file."""
    text = (ROOT / "docs" / "howto" / "xarray.md").read_text()
    return re.search(r"```python\n(# dense displacements.*?)```", text, flags=re.S).group(1)


@pytest.mark.two_cores  # its fixture writes files on 2 ranks
def test_prior_tree_is_the_catalogue_set(files):
    from sliders.io.prior_file import read_prior_ensemble

    got = read_prior_ensemble(files["prior"])
    tree = xr.open_datatree(files["prior"], engine="h5netcdf")
    rows, events = tree["realisations"].to_dataset(), tree["events"].to_dataset()
    assert np.array_equal(events.alpha.values, got.columns["alpha"])
    assert "mu_d" in rows.coords and np.array_equal(rows.mu_d.values, got.parameters["mu_d"])
    assert rows.ceiling_distance.dims == ("row", "ceiling_alpha", "nearest")
    r = 2  # one row's events through the offsets
    first, n = int(rows.event_start[r]), int(rows.n_events[r])
    assert np.array_equal(events.size.isel(event=slice(first, first + n)).values,
                          got.catalogue(r).size)


@pytest.mark.two_cores  # its fixture writes files on 2 ranks
def test_study_tree_has_the_axes_and_each_point_its_grids(files):
    tree = xr.open_datatree(files["study"], engine="h5netcdf")
    root = tree.to_dataset()
    assert root.alpha_c.dims == ("xi", "mu_d", "realisation")
    assert root.sigma_mu.dims == ("mu_d",) and list(root.sigma_mu.values) == [0.01, 0.02]
    assert root.alpha_c.attrs["units"] == "rad"
    point = tree["points/p001/realisations/statistics"].to_dataset()
    assert point.force_counts.dims == ("realisation", "alpha", "force_bin")
    assert point.force_bin.attrs["units"] == "m g"
    # the root view shows point p's rows at the p-th place of the axes, row-major
    rows = [tree[f"points/p{p:03d}/realisations"].to_dataset().alpha_c.values for p in range(4)]
    assert np.array_equal(root.alpha_c.values.reshape(4, -1), np.stack(rows), equal_nan=True)
    assert root.alpha_c.sel(xi=0.001, mu_d=0.5).values.tolist() == rows[2].tolist()
