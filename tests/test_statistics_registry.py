"""Per-realisation statistics are declared once (observables.STATISTICS):
one entry gives the layout, the row and the ensemble combination."""

from __future__ import annotations

import numpy as np

import sliders
from sliders import Scene
from sliders.analysis import observables as ob


def _runs():
    return [sliders.tilt(Scene(n_sliders=12, seed=s, record="displacements")) for s in (1, 2)]


def test_layout_and_rows_agree():
    runs = _runs()
    grids = ob.default_grids(runs[0].scene)
    layout = ob.statistics_layout(grids, 12)
    assert list(layout) == [st.name for st in ob.STATISTICS]
    row = ob.realisation_statistics(runs[0], grids)
    for name, (shape, dtype) in layout.items():
        assert np.shape(row[name]) == shape and np.asarray(row[name]).dtype == dtype, name


def test_adding_a_statistic_is_one_entry(monkeypatch):
    """A new entry (largest event size of the run, combined as its mean over
    the runs) reaches the layout, the rows and summary.extra."""
    largest = ob.Statistic(
        "largest_event", lambda g, n: (), np.int64,
        lambda run: np.int64(run.result.events["n_moved"].max()),
        lambda rows, ens: {"largest_event_mean": float(np.mean(rows["largest_event"]))},
    )
    monkeypatch.setattr(ob, "STATISTICS", ob.STATISTICS + (largest,))
    runs = _runs()
    grids = ob.default_grids(runs[0].scene)
    assert ob.statistics_layout(grids, 12)["largest_event"] == ((), np.int64)
    summary = ob.summary_from_results(runs, grids)
    expected = np.mean([r.events["n_moved"].max() for r in runs])
    assert summary.extra == {"largest_event_mean": expected}
    assert summary.alpha_c_values.tolist() == [r.alpha_c for r in runs]
