"""Every figure function runs on tiny scenes (Fortran kernel; the NumPy reference agrees
event by event, tests/test_backends.py) and writes PNG + PDF at print size; the command line reports bad input in one line; the animation writes a GIF."""

from __future__ import annotations

import pytest

import os
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")

import h5py  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from PIL import Image  # noqa: E402

import sliders  # noqa: E402
from sliders.figures import animation  # noqa: E402
from sliders import figures as F  # noqa: E402
from sliders.analysis import observables as ob  # noqa: E402
from sliders.figures import schematics  # noqa: E402

pytestmark = pytest.mark.slow  # the paper's figures drawn from ensembles

MIN_BYTES = 5_000
MAX_WIDTH_IN = 3.5  # one column of the paper (3.4 in) and a little rounding
MIN_DPI = 300


def check_written(out_dir, name):
    """PNG and PDF exist; the PNG is one column wide at print resolution."""
    png = os.path.join(out_dir, f"{name}.png")
    pdf = os.path.join(out_dir, f"{name}.pdf")
    assert os.path.getsize(png) > MIN_BYTES, png
    assert os.path.getsize(pdf) > MIN_BYTES, pdf
    with open(png, "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    with open(pdf, "rb") as fh:
        assert fh.read(5) == b"%PDF-"
    check_print_size(png)


def check_print_size(png):
    with Image.open(png) as im:
        dpi_x, dpi_y = im.info["dpi"]
        width_px = im.size[0]
    assert round(dpi_x) >= MIN_DPI and round(dpi_y) >= MIN_DPI, (png, im.info["dpi"])
    assert width_px / dpi_x <= MAX_WIDTH_IN, (png, width_px / dpi_x)


@pytest.fixture(scope="module")
def runs():
    """Three free chains of 6 sliders, to the avalanche."""
    return [sliders.tilt(sliders.Scene(n_sliders=6, seed=s), backend="fortran") for s in (1, 2, 3)]


@pytest.fixture(scope="module")
def summary(runs):
    return ob.summary_from_results(runs)


def test_fig_scene(runs, tmp_path):
    fig = F.fig_scene(runs[0], name="scene_test", label="A", out_dir=tmp_path)
    check_written(tmp_path, "scene_test")
    assert len(fig.axes) == 4  # two panels and their colour bars
    plt.close(fig)


def test_fig_scene_coupled(tmp_path):
    res = sliders.tilt(sliders.Scene(n_sliders=5, xi=0.001, seed=4), backend="fortran")
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


def test_ensemble_file_summary_of_the_done_rows(runs, tmp_path):
    """Statistics read back from an ensemble file (the package's writer) give the same summary;
    a row not marked done is ignored."""
    from sliders import status
    from sliders.io import storage
    from sliders.runs.parallel import SerialComm

    scene = runs[0].scene
    grids = ob.default_grids(scene)
    rows = ob.stack_rows(ob.realisation_statistics(r, grids) for r in runs)
    layout = storage.make_layout(4, np.arange(4), grids.to_arrays(),
                                 ob.statistics_layout(grids, scene.n_sliders),
                                 storage.file_attributes(scene.to_dict(), scene.seed, 4, "fortran"))
    path = tmp_path / "e.h5"
    f = storage.GatherFile.create(path, layout, SerialComm())
    for r, res in enumerate(runs + [runs[0]]):  # a fourth row, written but not done
        f.write_row(r, {"status": status.AVALANCHE, "alpha_c": res.alpha_c,
                        "n_events": res.n_events, "slider_steps": 0, "wall_time": 0.0,
                        **{storage.STATISTICS + k: v[r % 3] for k, v in rows.items()}})
        if r < 3:
            f.mark_done(r)
    f.close()
    summary, g2, scene_dict = F.load_ensemble_summary(path)
    direct = ob.combine(rows, grids, 6)
    assert summary.n_realisations == 3 and scene_dict["n_sliders"] == 6
    np.testing.assert_allclose(summary.p_mean, direct.p_mean, equal_nan=True)
    np.testing.assert_array_equal(g2.force_edges, grids.force_edges)


def test_main_single_slider_short_name(tmp_path):
    """--only takes the short name; the file carries the paper's figure number."""
    assert F.main(["--backend", "numpy", "--only", "single_slider", "--out", str(tmp_path)]) == 0
    check_written(tmp_path, "fig05_single_slider")


def test_schematics_from_the_model(tmp_path):
    fig = schematics.fig_sketch(out_dir=tmp_path)
    check_written(tmp_path, "fig01_sketch")
    plt.close(fig)
    # the plate anchors follow the barycentre: their mean is the sliders' mean position
    _, x, anchors, l_star = schematics.sketch_chain()
    assert anchors.mean() == pytest.approx(x.mean())
    np.testing.assert_allclose(np.diff(anchors), l_star)
    fig = schematics.fig_histogram_model(alpha=0.3, out_dir=tmp_path)
    check_written(tmp_path, "fig08_histogram_model")
    plt.close(fig)
    upper, lower, heights, nu, low = schematics.histogram_model_bins(0.3)
    assert nu == sliders.analysis.model.n_bins(0.3, 0.6, 0.55) and heights.shape == (nu,)
    np.testing.assert_allclose(upper - lower, 0.1)
    assert lower[-1] <= low < upper[-1]  # the last bin holds the lower bound sin(a) - mu_s
    assert np.sum(heights) * 0.1 == pytest.approx(1.0)  # probabilities 2 dmu P_i sum to 1


def test_list_names_every_paper_figure(capsys):
    assert F.main(["--list"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 10
    for number, line in enumerate(out, start=1):
        assert f"Fig. {number} " in line
    assert any(line.startswith("fig09_P_i") and "fig:distrib2" in line for line in out)


def test_names_resolve():
    assert F.resolve_names(["bin_heights", "distrib1", "fig1"], ensemble=False) == [
        "fig01_sketch", "fig06_force_pdf", "fig09_P_i"]
    # an ensemble file: the statistics without re-simulating scenes A, B, C
    with_file = F.resolve_names(None, ensemble=True)
    assert "fig09_P_i" in with_file and not set(F.SCENE_LETTERS) & set(with_file)
    assert F.resolve_names(["scene_C"], ensemble=True) == ["fig04_scene_C"]


def one_error_line(capsys, code):
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "Traceback" not in err[0]
    return err[0]


def test_unknown_name_lists_valid_ones(capsys, tmp_path):
    line = one_error_line(capsys, F.main(["--only", "bogus", "--out", str(tmp_path)]))
    assert "bogus" in line and "fig01_sketch" in line and "fig10_cumulated" in line


def test_bad_ensemble_files_one_line(capsys, tmp_path, runs):
    missing = tmp_path / "missing.h5"
    assert "does not exist" in one_error_line(capsys, F.main(["--ensemble", str(missing)]))
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5\n")
    assert "not an HDF5 file" in one_error_line(capsys, F.main(["--ensemble", str(text)]))
    single = tmp_path / "run.h5"
    runs[0].save(single)
    line = one_error_line(capsys, F.main(["--ensemble", str(single)]))
    assert "Result.load" in line and "single run" in line
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = 1
    assert "not a sliders ensemble" in one_error_line(capsys, F.main(["--ensemble", str(other)]))
    assert not list(tmp_path.glob("*.png"))


def test_bad_scene_file_one_line(capsys, tmp_path):
    line = one_error_line(capsys, F.main(["--animate", "--scene", str(tmp_path / "no.toml"),
                                          "--out", str(tmp_path)]))
    assert "does not exist" in line


def test_ensemble_file_draws_statistics_only(tmp_path):
    """A real ensemble file (serial python -m sliders.ensemble) gives the statistics figures."""
    path = tmp_path / "e.h5"
    cmd = [sys.executable, "-m", "sliders.ensemble", "--n-sliders", "6", "--seed", "3", "-R", "3",
           "--out", str(path), "--backend", "fortran"]
    subprocess.run(cmd, check=True, timeout=120, capture_output=True)
    out = tmp_path / "figs"
    assert F.main(["--ensemble", str(path), "--out", str(out), "--only", "P_i",
                   "stopped_ratio"]) == 0
    check_written(out, "fig09_P_i")
    check_written(out, "fig07_stopped_ratio")
    assert sorted(p.name for p in out.glob("*.png")) == ["fig07_stopped_ratio.png",
                                                         "fig09_P_i.png"]


def test_animation_writes_frames(tmp_path):
    scene = sliders.Scene(n_sliders=5, seed=2, record="displacements")
    path = animation.animate_tilt(scene, out_dir=tmp_path, backend="fortran", frames=8)
    with Image.open(path) as im:
        assert im.format == "GIF"
        assert im.n_frames >= 3  # identical consecutive frames are merged by Pillow
        assert im.size[0] <= 3.5 * animation.GIF_DPI + 1


def test_animation_flashes_the_sliders_that_moved():
    res = sliders.tilt(sliders.Scene(n_sliders=5, seed=2), backend="fortran")
    angles = np.linspace(0.0, res.alpha_c * (1 - 1e-9), 30)
    moved = animation.moved_between(res, angles)
    assert moved.shape == (30, 5)
    # every event lands in exactly one frame: the moved sliders of all frames are
    # those of all events
    every = np.zeros(5, dtype=bool)
    for k in range(res.n_events):
        every[res.displacement.event(k)[0]] = True
    np.testing.assert_array_equal(moved.any(axis=0), every)
    assert not moved[0].any() or res.alpha[0] == 0.0
