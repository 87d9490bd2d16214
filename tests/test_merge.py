"""Job-array chunks (``--chunk I/K``) merged by ``python -m sliders.merge`` == one run, bit for bit."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import h5py
import numpy as np
import pytest

from sliders.runs import merge
from sliders.io.storage import read_realisations
from sliders.analysis.summary import load_summary
from helpers import assert_same_file, one_error_line

pytestmark = pytest.mark.slow  # ensembles run and merged as commands

R = 7  # not a multiple of the chunk counts: chunks of unequal sizes
SCENE_ARGS = ["--n-sliders", "12", "--seed", "11", "--mode", "explore", "--quiet"]


def run_ensemble(out, *extra):
    return subprocess.run([sys.executable, "-m", "sliders.ensemble", *SCENE_ARGS,
                           "--realisations", str(R), "--out", str(out), *extra],
                          capture_output=True, text=True, timeout=300)


def run_merge(*args):
    return subprocess.run([sys.executable, "-m", "sliders.merge", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def one_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("merge") / "one.h5"
    res = run_ensemble(out)
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(scope="module")
def chunks(tmp_path_factory):
    d = tmp_path_factory.mktemp("chunks")
    paths = []
    for i in range(3):
        p = d / f"chunk_{i}.h5"
        res = run_ensemble(p, "--chunk", f"{i}/3")
        assert res.returncode == 0, res.stderr
        paths.append(p)
    return paths


def test_chunk_ranges_tile_the_ensemble():
    for n in (1, 7, 100):
        for k in range(1, min(n, 9) + 1):
            ranges = [merge.chunk_range((i, k), n) for i in range(k)]
            assert [f for f, _ in ranges] == list(np.cumsum([0] + [c for _, c in ranges[:-1]]))
            assert sum(c for _, c in ranges) == n and min(c for _, c in ranges) >= 1


def test_chunk_files_hold_their_realisations(chunks, one_run):
    full = read_realisations(one_run)
    for i, p in enumerate(chunks):
        first, count = merge.chunk_range((i, 3), R)
        rows = read_realisations(p)
        assert rows["done"].all() and rows["seed"].size == count
        assert np.array_equal(rows["seed"], full["seed"][first:first + count])
        assert np.array_equal(rows["alpha_c"], full["alpha_c"][first:first + count])
        with h5py.File(p) as f:  # the realisation coordinate carries the global numbers
            assert list(f["realisation"][()]) == list(range(first, first + count))


def test_merged_chunks_equal_one_run(chunks, one_run, tmp_path):
    out = tmp_path / "merged.h5"
    res = run_merge(out, *reversed(chunks))  # any order
    assert res.returncode == 0, res.stderr
    assert f"{R}/{R} realisations done" in res.stderr
    assert_same_file(one_run, out)  # every dataset bit for bit (wall times aside), same attributes
    with h5py.File(out) as f:  # CF history: each chunk's command, then the merge
        history = f.attrs["history"].splitlines()
    assert [ln.count("--chunk") for ln in history] == [1, 1, 1, 0] and "sliders.merge" in history[-1]
    summary, _, _, info = load_summary(out)
    assert info["n_done"] == R and np.isfinite(summary.force_pdf).any()


def test_merge_refuses_what_is_not_one_ensemble(chunks, tmp_path):
    assert "realisations 2..3 are in no input file" in one_error_line(
        run_merge(tmp_path / "gap.h5", chunks[0], chunks[2]))
    assert "overlaps" in one_error_line(run_merge(tmp_path / "dup.h5", chunks[0], chunks[0], *chunks[1:]))
    other = tmp_path / "other.h5"
    assert subprocess.run([sys.executable, "-m", "sliders.ensemble", "--n-sliders", "12", "--seed",
                           "12", "--mode", "explore", "--quiet", "--realisations", str(R),
                           "--chunk", "1/3", "--out", str(other)], capture_output=True).returncode == 0
    assert "differ in scene" in one_error_line(run_merge(tmp_path / "mix.h5", chunks[0], other, chunks[2]))
    assert "exists" in one_error_line(run_merge(chunks[1], chunks[0]))
    assert "does not exist" in one_error_line(run_merge(tmp_path / "m.h5", tmp_path / "none.h5"))
    assert "required" in one_error_line(run_merge())


@pytest.mark.parametrize("chunk, message", [("3/3", "0 <= I < K"), ("1-3", "is not I/K"),
                                            ("0/8", "use K <= R")])
def test_bad_chunk_is_one_line(tmp_path, chunk, message):
    assert message in one_error_line(run_ensemble(tmp_path / "x.h5", "--chunk", chunk))


def test_a_merge_stopped_by_sigterm_exits_143_and_leaves_nothing(chunks, tmp_path, monkeypatch,
                                                                   capsys):
    """SIGTERM while the rows are copied stops the merge as every command stops: 128 + 15,
    no output and no temporary file beside it."""
    read_rows = merge.read_rows

    def read_then_stopped(path):
        os.kill(os.getpid(), signal.SIGTERM)  # a batch system's stop, mid-merge
        return read_rows(path)

    monkeypatch.setattr(merge, "read_rows", read_then_stopped)
    out = tmp_path / "merged.h5"
    assert merge.main([str(out), *map(str, chunks)]) == 128 + signal.SIGTERM
    assert "interrupted" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
