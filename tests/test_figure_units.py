"""Every axis of every figure names its unit.

The rule: a visible axis label (x, y, colour bar) ends in its unit in square
brackets: ``[rad]`` for angles, ``[$mg$]`` for forces (units of m g),
``[$g\\tau^2$]`` for displacements, ``[$1/mg$]`` for densities over a force,
``[1]`` for a dimensionless number or an index, or a countable (``[sliders]``).
The test walks the registries (``PAPER_FIGURES`` and the figures drawn beside
them in figures/paper.py, ``STUDY_FIGURES`` of figures/study.py, and the
animation's frame), draws each on small data and reads every label.
"""

from __future__ import annotations

import re
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

import sliders  # noqa: E402
from sliders.analysis import observables as ob  # noqa: E402
from sliders.figures import animation, paper, study as study_figures  # noqa: E402
from sliders.figures.pushed_end import NAME as PUSHED_END  # noqa: E402
from sliders.figures.style import STYLE  # noqa: E402

UNIT = re.compile(r"\[[^\[\]]+\]$")
SMALL_STUDY = """[study]
realisations = 2
[scene]
n_sliders = 12
mode = "explore"
[axes]
xi = [0.0, 1e-3]
"""


def labels_without_unit(fig) -> list[str]:
    """Every visible, non-empty axis label of ``fig`` that does not end in ``[unit]``."""
    missing = []
    for ax in fig.axes:
        if not (ax.get_visible() and ax.axison):
            continue
        for axis in (ax.xaxis, ax.yaxis):
            text = axis.get_label_text().strip()
            if text and axis.get_visible() and not UNIT.search(text):
                missing.append(text)
    return missing


def test_the_rule_reads_labels():
    fig, ax = plt.subplots()
    ax.set_xlabel(r"$\alpha$ [rad]")
    ax.set_ylabel(r"$\tilde F_t$")
    assert labels_without_unit(fig) == [r"$\tilde F_t$"]
    ax.set_ylabel(r"$\tilde F_t$ [$mg$]")
    assert labels_without_unit(fig) == []
    plt.close(fig)


@pytest.fixture(scope="module")
def small_runs():
    return [sliders.tilt(sliders.Scene(n_sliders=6, seed=s), backend="fortran") for s in (1, 2, 3)]


def paper_figure(name, runs):
    """Figure ``name`` of the paper's registry (or drawn beside it), on small data."""
    if name in paper.MODEL_FIGURES:
        if name == PUSHED_END:
            run = paper.pushed_end_run(sliders.Scene(n_sliders=12, seed=2, loading="pushed_end",
                                                     mode="explore"))
            return paper.fig_pushed_end(run, out_dir=None)
        return paper.MODEL_FIGURES[name]("fortran")
    if name in paper.STATISTICS_FIGURES:
        return paper.STATISTICS_FIGURES[name](ob.summary_from_results(runs), runs, "")
    if name in paper.SCENE_LETTERS:
        big = sliders.tilt(sliders.Scene(n_sliders=30, seed=1), backend="fortran")
        return paper.fig_scene(big if name != "fig02_scene_A" else runs[0], out_dir=None)
    raise AssertionError(f"{name}: a figure of the registry that this test cannot draw")


@pytest.mark.parametrize("name", paper.FIGURE_NAMES + (PUSHED_END,))
def test_paper_figure_axes_have_units(name, small_runs):
    fig = paper_figure(name, small_runs)
    assert not labels_without_unit(fig), f"{name}: labels without a unit"
    plt.close(fig)


def test_study_figure_axes_have_units(tmp_path):
    spec = tmp_path / "study.toml"
    spec.write_text(SMALL_STUDY)
    out = tmp_path / "study.h5"
    res = subprocess.run([sys.executable, "-m", "sliders.study", str(spec), "--out", str(out),
                          "--quiet"], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    plot = study_figures.StudyPlot(out)
    with plt.rc_context(STYLE):
        for name, draw in study_figures.STUDY_FIGURES.items():
            fig = draw(plot)
            assert not labels_without_unit(fig), f"study figure {name}: labels without a unit"
            plt.close(fig)


@pytest.mark.slow  # seconds of work: the full suite
def test_animation_axes_have_units(tmp_path, monkeypatch):
    kept = []
    monkeypatch.setattr(animation.plt, "close", kept.append)  # keep the frame's figure
    animation.animate_tilt(sliders.Scene(n_sliders=5, seed=1), out_dir=tmp_path, frames=3)
    assert kept and not labels_without_unit(kept[0])
