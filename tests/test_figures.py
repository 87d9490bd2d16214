"""Every figure function runs on tiny scenes (NumPy reference backend) and writes PNG + PDF."""

from __future__ import annotations

import json
import os

import matplotlib

matplotlib.use("Agg")

import h5py  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import sliders  # noqa: E402
from sliders import figures as F  # noqa: E402
from sliders import observables as ob  # noqa: E402

MIN_BYTES = 5_000


def check_written(out_dir, name):
    png = os.path.join(out_dir, f"{name}.png")
    pdf = os.path.join(out_dir, f"{name}.pdf")
    assert os.path.getsize(png) > MIN_BYTES, png
    assert os.path.getsize(pdf) > MIN_BYTES, pdf
    with open(png, "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    with open(pdf, "rb") as fh:
        assert fh.read(5) == b"%PDF-"


@pytest.fixture(scope="module")
def runs():
    """Three free chains of 6 sliders, to the avalanche."""
    return [sliders.tilt(sliders.Scene(n_sliders=6, seed=s), backend="numpy") for s in (1, 2, 3)]


@pytest.fixture(scope="module")
def summary(runs):
    return ob.summary_from_results(runs)


def test_fig_scene(runs, tmp_path):
    fig = F.fig_scene(runs[0], name="scene_test", label="A", out_dir=tmp_path)
    check_written(tmp_path, "scene_test")
    assert len(fig.axes) == 4  # two panels and their colour bars
    plt.close(fig)


def test_fig_scene_coupled(tmp_path):
    res = sliders.tilt(sliders.Scene(n_sliders=5, xi=0.001, seed=4), backend="numpy")
    plt.close(F.fig_scene(res, name="scene_c", out_dir=tmp_path))
    check_written(tmp_path, "scene_c")


def test_force_curves_jump_at_events(runs):
    r = runs[0]
    x, y = F.force_curves(r)
    assert np.all(np.diff(x) >= 0)
    after = ob.force_history(r)
    for k, a in enumerate(r.alpha):
        rows = np.flatnonzero(x == a)
        assert rows.size >= 2
        np.testing.assert_allclose(y[rows[-1]], after[k], atol=1e-12)


def test_fig_single_slider(tmp_path):
    fig = F.fig_single_slider(backend="numpy", out_dir=tmp_path, alpha_max=0.4)
    check_written(tmp_path, "single_slider")
    plt.close(fig)


def test_statistics_figures(summary, runs, tmp_path):
    for fn, name in ((F.fig_force_pdf, "force_pdf"), (F.fig_stopped_force_ratio, "stopped_ratio"),
                     (F.fig_bin_heights, "bin_heights")):
        plt.close(fn(summary, out_dir=tmp_path, name=name))
        check_written(tmp_path, name)
    fig = F.fig_cumulated_displacement(runs, out_dir=tmp_path, name="cumul_runs")
    check_written(tmp_path, "cumul_runs")
    assert np.isfinite(fig.fits["cumulated"]["rate"])
    plt.close(fig)
    plt.close(F.fig_cumulated_displacement(summary, out_dir=tmp_path, name="cumul_summary"))
    check_written(tmp_path, "cumul_summary")


def test_rebin_factor():
    assert F.rebin_factor(120, 19.4) == 3
    assert F.rebin_factor(120, 100.0) == 1
    assert F.rebin_factor(120, 0.01) == 120


def test_ensemble_file_agreed_layout(runs, tmp_path):
    """Statistics read back from an HDF5 file in the agreed layout give the same summary."""
    grids = ob.default_grids(runs[0].scene)
    rows = ob.stack_rows(ob.realisation_statistics(r, grids) for r in runs)
    path = tmp_path / "e.h5"
    with h5py.File(path, "w") as f:
        f.attrs["scene"] = json.dumps(runs[0].scene.to_dict())
        g = f.create_group("grids")
        for k, v in grids.to_arrays().items():
            g.create_dataset(k, data=v)
        s = f.create_group("realisations/statistics")
        for k, v in rows.items():  # a fourth, unfinished row must be ignored
            s.create_dataset(k, data=np.concatenate([v, np.zeros_like(v[:1])]))
        f.create_dataset("realisations/done", data=np.array([1, 1, 1, 0], dtype=np.uint8))
    summary, g2, scene = F.load_ensemble_summary(path, prefer_package=False)
    direct = ob.combine(rows, grids, 6)
    assert summary.n_realisations == 3 and scene["n_sliders"] == 6
    np.testing.assert_allclose(summary.p_mean, direct.p_mean, equal_nan=True)
    np.testing.assert_array_equal(g2.force_edges, grids.force_edges)


def test_main_single_slider(tmp_path):
    assert F.main(["--backend", "numpy", "--only", "single_slider", "--out", str(tmp_path)]) == 0
    check_written(tmp_path, "single_slider")
