"""The forecasters' registry is the one list: the command line reads its methods without
scikit-learn, predict's fallback lines and the figures' forecasters come from its entries."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from sliders.analysis.forecast.base import LEVELS
from sliders.analysis.forecast.registry import FORECASTERS, METHODS, Entry, by_name, fallback_of


def test_a_method_without_its_fallback_is_refused():
    with pytest.raises(ValueError, match="fallback"):
        Entry("baselines.Now", method="now")
    assert all(fallback_of(m) for m in METHODS)
    assert fallback_of("learned_blind") == fallback_of("learned") != fallback_of("model_based")


def test_every_entry_makes_its_class_with_its_options():
    made = [e.make(7, 3) for e in FORECASTERS]
    assert len({f.name for f in made}) == len(FORECASTERS)  # by_name loses no entry
    assert list(by_name().values()) == list(FORECASTERS)
    boosted = [f for e, f in zip(FORECASTERS, made) if e.boosted]
    assert boosted and all(f.max_iter == 7 and f.random_state == 3 for f in boosted)


def test_the_parser_reads_the_methods_without_scikit_learn():
    code = ("import sys; from sliders.runs.forecast import cli; cli.build_parser(); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'sklearn'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.slow  # seconds of work: the full suite
def test_the_convergence_figure_draws_every_example_entry(tmp_path):
    from matplotlib.figure import Figure

    from sliders.figures import forecast as figures

    names = [n for n, e in by_name().items() if e.example]
    tilts = np.linspace(0.05, 0.4, 5)
    q = np.tile(np.linspace(0.45, 0.55, len(LEVELS)), (tilts.size, 1))
    example = {"tilts": tilts, "alpha_c": 0.5, "row": 0, "events": tilts[:3],
               "forecasts": {n: q for n in names}, "labels": {n: f"label {n}" for n in names}}
    drawn = []
    real = Figure.legend

    def legend(self, handles, labels, **kw):
        drawn.extend(labels)
        return real(self, handles, labels, **kw)

    Figure.legend = legend
    try:
        figures.figure_convergence(example, tmp_path)
    finally:
        Figure.legend = real
    assert [lab for lab in drawn if lab.startswith("label ")] == [f"label {n}" for n in names]
    assert "label ffm_ml_disp_p" in drawn
