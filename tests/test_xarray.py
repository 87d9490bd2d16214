"""Every file the package writes opens in xarray (h5netcdf) with named dimensions and coordinates."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tomllib
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest

import sliders
from sliders.runs import ensemble

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
    assert events.alpha.attrs["units"] == "rad" and "tilt" in events.alpha.attrs["long_name"]
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
    assert re.match(r"\d{4}-\d\d-\d\dT", a["history"]) and "pytest" in a["history"]
    assert a["hdf5_version"] == h5py.version.hdf5_version and a["numpy_version"] == np.__version__
    assert a["python_version"] == sys.version.split()[0] and a["h5py_version"] == h5py.__version__
    scene = sliders.Scene.from_dict(tomllib.loads(a["scene_toml"])["scene"])
    assert scene == result.scene  # the TOML gives the scene back
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True,
                          text=True)
    if head.returncode == 0 and Path(sliders.__file__).is_relative_to(ROOT):
        assert a["git_commit"].startswith(head.stdout.strip())


@pytest.mark.parametrize("n_ranks", [1, 2])  # 2: parallel HDF5 (mpio), described by rank 0
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
    summary, grids, scene, info = ensemble.load_summary(path)
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
    summary, grids, _, _ = ensemble.load_summary(path)
    g = int(np.argmin(np.abs(grids.alpha - 0.3)))
    assert np.allclose(namespace["pdf"].values, summary.force_pdf[g], rtol=1e-12, atol=0)
    assert namespace["pdf"].dims == ("force_bin",)
