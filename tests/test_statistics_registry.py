"""Registries where one entry is the whole of a new item: per-realisation statistics
(observables.STATISTICS: one entry gives the layout, the row and the ensemble combination)
and the statements of the reproduction report (reproduction.CLAIMS: one entry gives the
judge and the thresholds of its verdict)."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

import sliders
from sliders import Scene
from sliders.analysis import observables as ob
from sliders.analysis import reproduction as rp
from sliders.runs.reproduction import run_many, write_report


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
        units="1", meaning="sliders moved in the largest event")
    monkeypatch.setattr(ob, "STATISTICS", ob.STATISTICS + (largest,))
    assert ob.statistic_conventions()["largest_event"] == ((), "1", "sliders moved in the largest event")
    runs = _runs()
    grids = ob.default_grids(runs[0].scene)
    assert ob.statistics_layout(grids, 12)["largest_event"] == ((), np.int64)
    summary = ob.summary_from_results(runs, grids)
    expected = np.mean([r.events["n_moved"].max() for r in runs])
    assert summary.extra == {"largest_event_mean": expected}
    assert summary.alpha_c_values.tolist() == [r.alpha_c for r in runs]


def test_a_statistic_without_units_or_with_wrong_dims_is_refused():
    rows = dict(shape=lambda g, n: (g.alpha.size,), dtype=np.int64, compute=lambda run: 0)
    with pytest.raises(ValueError, match="units"):
        ob.Statistic("no_units", **rows, dims=("alpha",), meaning="something per angle")
    with pytest.raises(ValueError, match="dims"):
        ob.Statistic("no_dims", **rows, units="1", meaning="something per angle")
    ok = ob.Statistic("per_angle", **rows, dims=("alpha",), units="1", meaning="per angle")
    assert ok.units == "1"


def test_every_statistic_is_described_by_its_own_entry():
    """The xarray conventions of a statistic are its entry's (io holds no table of them)."""
    from sliders.io import conventions

    assert not hasattr(conventions, "ENSEMBLE_STATISTICS")
    conv = ob.statistic_conventions()
    assert [st.name for st in ob.STATISTICS] == list(conv)
    assert conv["cumulated_displacement"] == (("alpha",), conventions.LENGTH,
                                              "A(alpha): sum of all displacements up to alpha")


def _small_chains():
    """Scene A of the report (N = 10, xi = 0), three realisations."""
    return run_many(10, 0.0, 3, 0, "fortran")


def test_the_report_statements_in_order():
    keys = [c.judge.__doc__.split(".")[0] for c in rp.CLAIMS]
    assert keys == ["1", "2", "3", "4", "5", "6", "14", "7", "8", "9", "10", "11", "13", "12"]
    for c in rp.CLAIMS:
        assert c.experiment in ("small", "large", "statistics", "all")
        # every threshold is a keyword of its judge: the data and the function agree
        params = inspect.signature(c.judge).parameters
        assert set(c.thresholds) == {n for n, p in params.items() if p.kind == p.KEYWORD_ONLY}


def test_thresholds_are_data():
    """The avalanche angle of N = 10 (about atan 0.55 = 0.50) agrees with the paper's 0.5;
    the same judge with the paper's value moved to 0.3 disagrees."""
    ev = rp.Evidence(small=_small_chains())
    (entry,) = [c for c in rp.CLAIMS if c.judge is rp.small_avalanche_angle]
    assert entry.judge(ev, **entry.thresholds).verdict == "agrees"
    moved = dataclasses.replace(entry, thresholds={**entry.thresholds, "paper": 0.3})
    stmt = moved.judge(ev, **moved.thresholds)
    assert stmt.verdict == "disagrees" and "alpha_c ≈ 0.3" in stmt.paper


def test_adding_a_statement_is_one_entry(monkeypatch, tmp_path):
    """A new entry (every run of scene A ends in an avalanche) is judged with the other
    statements of its experiment, after them, and reaches the written report."""
    def all_avalanche(ev, *, share):
        ok = np.mean([r.status == "avalanche" for r in ev.small]) >= share
        return rp.Statement("15. Every chain avalanches (N = 10)", "the chain avalanches",
                            f"{len(ev.small)} runs", f"{len(ev.small)} runs",
                            "agrees" if ok else "disagrees")

    monkeypatch.setattr(rp, "CLAIMS", rp.CLAIMS + [rp.Claim("small", all_avalanche, {"share": 1.0})])
    rep = rp.Report()
    rp.judge(rep, rp.Evidence(small=_small_chains()), "small")
    assert [s.key.split(".")[0] for s in rep.statements] == ["1", "2", "3", "15"]
    assert rep.statements[-1].verdict == "agrees"
    meta = {"date": "d", "version": "v", "backend": "fortran", "python": "3", "wall": 1.0,
            "command": "c"}
    text = write_report(rep, tmp_path / "R.md", meta)
    assert "| 15 | Every chain avalanches (N = 10) |" in text
    assert (tmp_path / "R.md").read_text(encoding="utf-8") == text
