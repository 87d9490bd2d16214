"""Ensembles with record = "summary": only the per-realisation summary is computed and stored."""

from __future__ import annotations

import subprocess
import sys

import h5py
import numpy as np
import pytest
from sliders.io.storage import read_realisations
from sliders.analysis.summary import load_summary

pytestmark = pytest.mark.slow  # ensembles run as commands

ARGS = ["--n-sliders", "25", "--seed", "4", "--mode", "explore", "--realisations", "3", "--quiet"]


def run(out, *extra):
    res = subprocess.run([sys.executable, "-m", "sliders.ensemble", *ARGS, "--out", str(out), *extra],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    return read_realisations(out)


def test_summary_record_stores_the_summary_only(tmp_path):
    full = run(tmp_path / "full.h5")
    summary = run(tmp_path / "summary.h5", "--record", "summary")
    assert summary["statistics"] == {} and full["statistics"]  # nothing per angle or per bin
    for k in ("seed", "done", "status", "alpha_c", "n_events", "slider_steps"):
        assert np.array_equal(summary[k], full[k], equal_nan=True), k  # the same runs
    with h5py.File(tmp_path / "summary.h5") as f:
        assert len(f["realisations/statistics"]) == 0
        assert list(f["realisations/alpha_c"].dims[0].keys()) == ["realisation"]
    assert (tmp_path / "summary.h5").stat().st_size < (tmp_path / "full.h5").stat().st_size / 5  # grids and coordinates stay


def test_summary_file_has_no_statistics_to_load(tmp_path):
    run(tmp_path / "s.h5", "--record", "summary")
    res = subprocess.run([sys.executable, "-c", "from sliders.analysis.summary import load_summary; "
                          f"load_summary({str(tmp_path / 's.h5')!r})"],
                         capture_output=True, text=True)
    assert res.returncode != 0 and "record='summary'" in res.stderr
