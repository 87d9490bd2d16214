"""Fault injection: nothing finished is lost, nothing hangs, nothing is silently wrong.

Every run is a subprocess in its own session, killed whole if it outlives its
timeout (helpers from test_ensemble).  Faults: kill -9 of a rank at random
moments, SIGTERM and SIGINT (ensemble, tilt, a Python loop of tilts), a full
disk (a small tmpfs mounted here), a read-only file system, concurrent
writers, flipped bytes and truncations.  After each ensemble fault the file
is readable, every finished row is bit-for-bit the row of an uninterrupted
run, and ``--resume`` completes exactly the rest.

The counts (trials, faults survived, rows lost) are in docs/reliability.md.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

import sliders
from sliders.io.storage import read_realisations
from sliders.analysis.summary import load_summary
from sliders.io import storage
from sliders.io.filelock import OutputClaim
from helpers import (BACKEND, PY, R, SCENE_OPTS, _env, _Run, assert_same_file, ensemble_args,
                     one_error_line, progress_lines, rank_pids, run)

pytestmark = pytest.mark.slow  # faults injected into running commands

KILL_TRIALS = 4  # kill -9 of a random rank at a random moment
# random byte flips per file kind: a damaged run file is probed in a child process (HDF5 may
# crash on damaged metadata), 0.5 s per copy, and its whole-file CRC-32 catches every flip of
# one byte, so the run file gets fewer random flips (to reach its metadata); every dataset of
# both kinds is also flipped on purpose
FLIPS = {"tilt": 20, "ensemble": 120}
TRUNCATIONS = 12  # truncation lengths per file kind
STOP_WITHIN = 2.0  # seconds from a signal to the end of the process


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted serial ensemble: the rows every trial is compared with."""
    out = tmp_path_factory.mktemp("rel") / "reference.h5"
    res = run(ensemble_args(out))
    assert res.returncode == 0, res.stderr
    return out


def tilt_cli(*args, env=None, timeout=60):
    return subprocess.run([PY, "-m", "sliders", "tilt", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, env=env or _env())


def leftovers(directory: Path) -> list[str]:
    """Temporary files or claims left in a directory."""
    return sorted(p.name for p in directory.iterdir()
                  if p.name.endswith((".tmp", ".lock")))


# ---------------------------------------------------------------------------
# a small tmpfs (we are root in CI); skipped only where mounting is impossible
# ---------------------------------------------------------------------------
@pytest.fixture
def tmpfs(tmp_path):
    mounted = []

    def mount(size: str, read_only: bool = False) -> Path:
        where = tmp_path / f"mnt{len(mounted)}"
        where.mkdir()
        opts = f"size={size}" + (",ro" if read_only else "")
        res = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(where)],
                             capture_output=True, text=True)
        if res.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here (not root?): {res.stderr.strip()}")
        mounted.append(where)
        return where

    yield mount
    for where in mounted:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)


# ---------------------------------------------------------------------------
# ownership: concurrent writers
# ---------------------------------------------------------------------------
@pytest.mark.two_cores  # its ensembles run on 2 ranks
def test_second_writer_refused_while_first_runs(reference, tmp_path):
    """Same path, --overwrite and --resume while a first ensemble writes: refused at once,
    one line naming the holder; the first run finishes intact."""
    out = tmp_path / "held.h5"
    first = _Run(ensemble_args(out), 2, _env(SLIDERS_ENSEMBLE_TEST_DELAY=1.2))
    first.wait_for(progress_lines(1))
    for extra in ([], ["--overwrite"], ["--resume"]):
        res = run(ensemble_args(out, extra=extra), n=2, timeout=60)
        line = one_error_line(res)
        assert "is being written by pid" in line and os.uname().nodename in line, line
        assert first.proc.poll() is None, "the first run ended before the test was done"
    res = first.finish()
    assert res.returncode == 0, res.stderr
    assert_same_file(reference, out)
    assert leftovers(tmp_path) == []


def test_two_new_writers_race(tmp_path):
    """Two ensembles of different seeds started together on one new path: exactly one
    writes it, the other is refused; the file holds the rows of one seed only."""
    for trial in range(3):
        out = tmp_path / f"race{trial}.h5"
        jobs = [_Run(["--n-sliders", 10, "--seed", seed, "-R", 4, "--out", out, "--backend",
                      BACKEND, "--quiet"], None, _env()) for seed in (1, 2)]
        results = [j.finish() for j in jobs]
        codes = sorted(r.returncode for r in results)
        assert codes[0] == 0 and codes[1] != 0, [r.stderr for r in results]
        loser = next(r for r in results if r.returncode != 0)
        assert "being written by" in loser.stderr or "exists" in loser.stderr, loser.stderr
        winner_seed = 1 if results[0].returncode == 0 else 2
        head = storage.read_header(out)
        assert head["attrs"]["base_seed"] == winner_seed
        assert head["done"].all()


def test_tilt_refused_while_claimed(tmp_path):
    out = tmp_path / "t.h5"
    with OutputClaim(out):
        for extra in ([], ["--overwrite"]):
            res = tilt_cli("--n-sliders", 10, "--out", out, *extra)
            line = one_error_line(res)
            assert f"being written by pid {os.getpid()} on {os.uname().nodename}" in line
    assert not out.exists()
    res = tilt_cli("--n-sliders", 10, "--out", out, "--quiet")
    assert res.returncode == 0, res.stderr
    assert leftovers(tmp_path) == []


def test_without_file_locks_overwrite_is_refused(tmp_path, monkeypatch, capsys):
    """A file system whose flock fails with ENOLCK: said, and --overwrite refused."""
    def no_locks(fd, op):
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(fcntl, "flock", no_locks)
    out = tmp_path / "t.h5"
    out.write_bytes(b"precious")
    claim = OutputClaim(out).acquire()
    assert not claim.locking
    claim.release()
    from sliders.__main__ import main

    with pytest.raises(SystemExit) as exc:
        main(["tilt", "--n-sliders", "10", "--out", str(out), "--overwrite", "--quiet"])
    assert exc.value.code != 0
    assert "does not support file locks" in capsys.readouterr().err
    assert out.read_bytes() == b"precious"


# ---------------------------------------------------------------------------
# kill -9, SIGTERM, SIGINT of an ensemble: file readable, rows intact, --resume exact
# ---------------------------------------------------------------------------
def check_then_resume(reference, out, n=2):
    """The file reads, its done rows equal the reference's, --resume completes the rest
    (returns its stderr)."""
    if out.exists():  # (killed before the file was published: nothing was finished)
        rows = read_realisations(out)
        assert_same_file(reference, out, rows=np.flatnonzero(rows["done"]))
    res = run(ensemble_args(out, extra=["--resume"]), n=n)
    assert res.returncode == 0, res.stderr
    assert_same_file(reference, out)
    return res.stderr


@pytest.mark.parametrize("trial", range(KILL_TRIALS))
@pytest.mark.two_cores  # its ensembles run on 2 ranks
def test_kill9_at_random_moment(reference, tmp_path, trial):
    rng = random.Random(1000 + trial)
    out = tmp_path / f"kill{trial}.h5"
    storage_kind = ("mpio", "gather")[trial % 2]
    job = _Run(ensemble_args(out, extra=["--storage", storage_kind]), 2,
               _env(SLIDERS_ENSEMBLE_TEST_DELAY=0.15))
    job.wait_for(lambda lines: any("starting" in ln for ln in lines))
    time.sleep(rng.uniform(0.0, 1.2))
    pids = rank_pids(job.proc.pid)
    if pids:
        os.kill(rng.choice(pids), signal.SIGKILL)
    res = job.finish()
    assert "Traceback" not in res.stderr
    lock = Path(str(out) + ".lock")
    stale = lock.exists() and lock.read_text().strip()  # rank 0 died holding it
    log = check_then_resume(reference, out)
    if stale:
        assert f"was held by {stale}, which is no longer running" in log
    assert not lock.exists()  # taken over, then released


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
@pytest.mark.two_cores  # its ensembles run on 2 ranks
def test_ensemble_signal_stops_every_rank_quickly(reference, tmp_path, sig):
    out = tmp_path / f"sig{int(sig)}.h5"
    job = _Run(ensemble_args(out), 2, _env(SLIDERS_ENSEMBLE_TEST_DELAY=0.3))
    job.wait_for(progress_lines(1))
    pids = rank_pids(job.proc.pid)
    t0 = time.monotonic()
    for pid in pids:
        os.kill(pid, sig)
    res = job.finish()
    elapsed = time.monotonic() - t0
    assert res.returncode == 128 + sig, res.stderr
    assert elapsed < STOP_WITHIN + 1.0, f"stopped after {elapsed:.2f} s"  # + mpirun teardown
    assert "Traceback" not in res.stderr
    done = read_realisations(out)["done"].sum()
    assert 1 <= done < R
    assert f"resuming {R - done} of {R}" in check_then_resume(reference, out)


@pytest.mark.two_cores  # its ensembles run on 2 ranks
def test_resume_alone_takes_everything_from_the_file(reference, tmp_path):
    out = tmp_path / "alone.h5"
    res = run(ensemble_args(out), n=2, env=_env(SLIDERS_ENSEMBLE_STOP_AFTER=3))
    assert res.returncode == 128 + signal.SIGTERM, res.stderr
    res = run(["--resume", "--out", out, "--progress-interval", 0], n=2)  # no scene options
    assert res.returncode == 0, res.stderr
    assert_same_file(reference, out)
    # options that agree are accepted; one that disagrees is refused, naming it
    res = run(["--resume", "--out", out, "--n-sliders", 10, "--seed", 7], n=2)
    assert res.returncode == 0, res.stderr
    res = run(["--resume", "--out", out, "--xi", 0.5], n=2, timeout=60)
    line = one_error_line(res)
    assert "xi=0.0 in the file, 0.5 given" in line


# ---------------------------------------------------------------------------
# full disk, read-only file system and other I/O errors: one line, nothing lost
# ---------------------------------------------------------------------------
@pytest.mark.two_cores  # its ensembles run on 2 ranks
def test_full_disk_ensemble_keeps_finished_rows(reference, tmpfs):
    disk = tmpfs("3m")
    out = disk / "e.h5"
    res = run(ensemble_args(out), n=2, env=_env(SLIDERS_ENSEMBLE_STOP_AFTER=3))
    assert res.returncode == 128 + signal.SIGTERM, res.stderr
    done_before = read_realisations(out)["done"].copy()
    with open(disk / "filler", "wb", buffering=0) as fh:  # fill the disk to the last block
        with pytest.raises(OSError) as full:
            while True:
                fh.write(b"\0" * 4096)
        assert full.value.errno == errno.ENOSPC
    # a new file does not fit: refused up front, one line, nothing left behind
    res = run(ensemble_args(disk / "new.h5"), n=2, timeout=60)
    line = one_error_line(res)
    assert "new.h5" in line and "No space left on device" in line
    assert not (disk / "new.h5").exists() and leftovers(disk) == []
    # the rows are allocated with the file: --resume completes it on the full disk
    res = run(ensemble_args(out, extra=["--resume"]), n=2)
    assert res.returncode == 0, res.stderr
    rows = read_realisations(out)
    assert rows["done"].all() and done_before.sum() >= 3
    assert_same_file(reference, out)


def test_full_disk_tilt_keeps_the_old_file(tmpfs):
    disk = tmpfs("200k")
    out = disk / "t.h5"
    res = tilt_cli("--n-sliders", 10, "--mode", "explore", "--out", out, "--quiet")
    assert res.returncode == 0, res.stderr
    before = out.read_bytes()
    # N = 400 with displacements is larger than what is left: the write fails
    res = tilt_cli("--n-sliders", 400, "--mode", "explore", "--out", out, "--overwrite", "--quiet")
    line = one_error_line(res)
    assert str(out) in line and "No space left on device" in line
    assert out.read_bytes() == before  # never truncated
    assert sliders.Result.load(out).scene.n_sliders == 10
    assert leftovers(disk) == []


@pytest.mark.parametrize("case", ["dev_full", "read_only", "permission", "missing_folder",
                                  "directory"])
@pytest.mark.parametrize("program", ["tilt", pytest.param("ensemble", marks=pytest.mark.two_cores)])
def test_io_error_is_one_line(tmp_path, tmpfs, case, program):
    if case == "read_only":
        target = tmpfs("1m", read_only=True) / "o.h5"
        reason = "Read-only file system"
    else:
        target, reason = {
            "dev_full": ("/dev/full", "No space left on device"),
            "permission": ("/sys/o.h5", "Permission denied"),
            "missing_folder": (tmp_path / "no" / "such" / "o.h5", "does not exist"),
            "directory": (tmp_path, "directory"),
        }[case]
    if program == "tilt":
        res = tilt_cli("--n-sliders", 10, "--mode", "explore", "--out", target, "--overwrite",
                       "--quiet")
    else:
        res = run(SCENE_OPTS + ["-R", 2, "--out", target, "--overwrite", "--backend", BACKEND],
                  n=2, timeout=60)
    if program == "ensemble" and case == "dev_full":  # written in place: a file is needed
        reason = "not a regular file"
    line = one_error_line(res)
    assert str(target) in line and reason in line, line
    assert os.path.exists("/dev/full") and not os.path.isfile("/dev/full")  # never replaced


# ---------------------------------------------------------------------------
# Ctrl-C and SIGTERM of tilt: stop within 2 s, never swallowed, finished events kept
# ---------------------------------------------------------------------------
LOOP = """
import sys, sliders
# the scenes first: a signal must land in tilt, not in the script's own Python
scenes = [sliders.Scene(n_sliders=200, seed=seed, mode="explore") for seed in range(1000)]
print("started", flush=True)
for scene in scenes:
    sliders.tilt(scene)
print("loop ended", flush=True)
"""


def _stop_after_start(cmd, sig, ready: str, delay: float = 0.5):
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=_env(), start_new_session=True)
    try:
        stream = proc.stdout if ready == "started" else proc.stderr
        line = stream.readline()
        assert ready in line, line + proc.stderr.read()
        time.sleep(delay)
        t0 = time.monotonic()
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
        return proc.returncode, time.monotonic() - t0, out, err
    finally:
        if proc.poll() is None:
            proc.kill()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_a_loop_of_tilts(tmp_path, sig):
    script = tmp_path / "loop.py"
    script.write_text(LOOP)
    if sig == signal.SIGTERM:  # as a script that wants SIGTERM to stop it like Ctrl-C does
        script.write_text("import signal\nsignal.signal(signal.SIGTERM, signal.default_int_handler)\n"
                          + LOOP)
    code, elapsed, out, err = _stop_after_start([PY, str(script)], sig, "started", delay=1.0)
    assert code != 0, (out, err)
    assert "loop ended" not in out
    assert "Interrupted" in err and "completed events" in err, err
    assert elapsed < STOP_WITHIN, f"stopped after {elapsed:.2f} s"


def test_signals_at_random_moments_each_stop_a_loop_of_tilts(tmp_path):
    """The trial script of the reliability page, three trials: each loop stops with
    Interrupted and its completed events within 2 s."""
    out = tmp_path / "trials.json"
    script = Path(__file__).resolve().parents[1] / "scripts" / "interrupt_trials.py"
    res = subprocess.run([PY, str(script), "--trials", "3",
                          "--out", str(out)], capture_output=True, text=True, timeout=120,
                         env=_env())
    assert res.returncode == 0, res.stdout + res.stderr
    assert json.loads(out.read_text())["counts"]["interrupted"] == 3


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_tilt_cli_while_the_history_is_prepared(tmp_path, sig):
    """A history preparation of 2000 sliders takes seconds with no event to save: the
    signal stops it within 2 s, one line, 128 + signal, and no file is written."""
    out = tmp_path / "history.h5"
    cmd = [PY, "-m", "sliders", "tilt", "--n-sliders", "2000", "--initial-forces", "history",
           "--out", str(out)]
    code, elapsed, _, err = _stop_after_start(cmd, sig, "preparing the chain's history")
    assert code == 128 + sig, err
    assert err.strip().splitlines() == [
        f"interrupted ({sig.name}) while the chain's history was prepared; nothing written"]
    assert elapsed < STOP_WITHIN, f"stopped after {elapsed:.2f} s"
    assert not out.exists() and leftovers(tmp_path) == []


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_tilt_cli_and_saves_finished_events(tmp_path, sig):
    out = tmp_path / "long.h5"
    cmd = [PY, "-m", "sliders", "tilt", "--n-sliders", "3000", "--out", str(out)]
    code, elapsed, _, err = _stop_after_start(cmd, sig, "tilt N=3000", delay=0.5)
    assert code == 128 + sig, err
    assert elapsed < STOP_WITHIN, f"stopped after {elapsed:.2f} s"
    assert "Traceback" not in err
    result = sliders.Result.load(out)
    assert result.status == "interrupted" and result.n_events > 0
    assert np.all(np.diff(result.alpha) >= 0)
    assert leftovers(tmp_path) == []


def test_interrupt_in_python_raises_with_the_partial_result():
    scene = sliders.Scene(n_sliders=20, seed=1, mode="explore")
    calls = []

    def ctrl_c(progress):
        calls.append(progress.n_events)
        raise KeyboardInterrupt

    with pytest.raises(sliders.Interrupted) as exc:
        sliders.tilt(scene, backend="numpy", progress=ctrl_c)
    assert isinstance(exc.value, KeyboardInterrupt)
    partial = exc.value.partial
    assert partial.status == "interrupted" and partial.n_events == calls[0] > 0
    full = sliders.tilt(scene, backend="numpy")
    assert np.array_equal(partial.alpha, full.alpha[:partial.n_events])
    kept = sliders.tilt(scene, backend="numpy", progress=ctrl_c, keep_partial=True)
    assert kept.status == "interrupted" and kept.n_events == partial.n_events


def test_interrupt_in_the_python_of_a_history_preparation_draws_no_chain_again(monkeypatch):
    """Ctrl-C in the Python of a history preparation (a tilt of its own, seconds to minutes
    for large chains): the run stops with PreparationInterrupted rather than preparing the
    whole history again to describe a run that never started."""
    from sliders import preparation

    calls = []

    def ctrl_c(*args):
        calls.append(args)
        raise KeyboardInterrupt

    monkeypatch.setattr(preparation, "rebased", ctrl_c)
    with pytest.raises(sliders.PreparationInterrupted):
        sliders.tilt(sliders.Scene(n_sliders=10, seed=3, mode="explore",
                                   initial_forces="history"))
    assert len(calls) == 1  # the history was not prepared again


def test_interrupt_in_python_as_the_run_ends_keeps_the_whole_run():
    """Ctrl-C in the progress report of the chunk that ended the run: the run is
    kept whole (avalanche, its angle, every event) and the interrupt still raised."""
    scene = sliders.Scene(n_sliders=20, seed=3, mode="explore")
    full = sliders.tilt(scene)

    def ctrl_c_at_the_end(progress):
        if progress.n_events == full.n_events:
            raise KeyboardInterrupt

    with pytest.raises(sliders.Interrupted) as exc:
        sliders.tilt(scene, progress=ctrl_c_at_the_end)
    partial = exc.value.partial
    assert partial.status == full.status == "avalanche" and partial.alpha_c == full.alpha_c
    np.testing.assert_array_equal(partial.alpha, full.alpha)


# ---------------------------------------------------------------------------
# damaged files: flipped bytes and truncations, loaded in a subprocess (a crash fails)
# ---------------------------------------------------------------------------
LOADER = """
import sys
import numpy as np
import sliders
from sliders.io.storage import read_realisations
from sliders.analysis.summary import load_summary

kind, reference = sys.argv[1], sys.argv[2]

def content(path):
    if kind == "tilt":
        r = sliders.Result.load(path)
        arrays = dict(r.events)
        arrays.update({"ptr": r.displacement.ptr, "index": r.displacement.index,
                       "value": r.displacement.value})
        for label, st in (("initial", r.initial), ("final", r.final)):
            arrays.update({f"{label}/{k}": np.asarray(v) for k, v in vars(st).items()})
        arrays["attrs"] = np.array([repr((r.scene, r.status, r.alpha_c, r.message, r.backend,
                                          r.relaxation, r.final_event, r.wall_time))])
        return arrays
    rows = read_realisations(path)
    summary, grids, scene, info = load_summary(path)
    arrays = {k: v for k, v in rows.items() if k != "statistics"}
    arrays.update({"s/" + k: v for k, v in rows["statistics"].items()})
    info.pop("created", None)
    arrays["attrs"] = np.array([repr((scene, sorted(info.items(), key=str)))])
    return arrays

def same(a, b):
    return a.keys() == b.keys() and all(
        np.asarray(a[k]).tobytes() == np.asarray(b[k]).tobytes() for k in a)

good = content(reference)
for path in sys.argv[3:]:
    try:
        got = content(path)
    except Exception as exc:
        msg = str(exc)
        print(("ERROR " if "\\n" not in msg else "MULTILINE ") + type(exc).__name__ + " " + msg,
              flush=True)
        continue
    print("SAME" if same(got, good) else "DIFFERENT", flush=True)
"""


def _load_copies(tmp_path, kind, reference, copies):
    script = tmp_path / "loader.py"
    script.write_text(LOADER)
    res = subprocess.run([PY, str(script), kind, str(reference), *map(str, copies)],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, f"the loader crashed (code {res.returncode}):\n{res.stderr[-2000:]}"
    lines = res.stdout.splitlines()
    assert len(lines) == len(copies), res.stdout
    return lines


def _damaged_copies(tmp_path, source, kind, offsets):
    data = source.read_bytes()
    copies = []
    for i, (offset, mask) in enumerate(offsets):
        damaged = bytearray(data)
        damaged[offset] ^= mask
        path = tmp_path / f"{kind}_flip{i}.h5"
        path.write_bytes(bytes(damaged))
        copies.append(path)
    return copies


def _data_offsets(path):
    """(dataset name, file offset of its first data byte) of every contiguous dataset."""
    out = []
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.append((o.name, o.id.get_offset()))
                     if isinstance(o, h5py.Dataset) and o.id.get_offset() is not None
                     and o.size else None)
    return out


@pytest.mark.parametrize("kind", ["tilt", "ensemble"])
def test_flipped_bytes_are_reported_or_harmless(tmp_path, tilt_file, reference, kind):
    """A flipped byte anywhere: the load reports it in one line, or (a byte HDF5 does not
    use) returns exactly the same values; never different values, never a crash."""
    source = tilt_file if kind == "tilt" else reference
    rng = random.Random(7)
    size = source.stat().st_size
    if kind == "ensemble":  # most of the file is rows: sample the first 64 kB more densely
        offsets = [rng.randrange(min(size, 65536)) for _ in range(FLIPS[kind] // 2)]
        offsets += [rng.randrange(size) for _ in range(FLIPS[kind] - len(offsets))]
    else:
        offsets = [rng.randrange(size) for _ in range(FLIPS[kind])]
    targeted = _data_offsets(source)
    if kind == "ensemble":  # inside done rows: every column of row 0
        targeted = [(n, o) for n, o in targeted if n.startswith("/realisations/")
                    and not n.endswith(("/done", "/row_crc32"))]
    flips = [(o, 1 << rng.randrange(8)) for o in offsets]
    flips += [(o, 0x10) for _, o in targeted]
    lines = _load_copies(tmp_path, kind, source, _damaged_copies(tmp_path, source, kind, flips))
    assert not [ln for ln in lines if ln.startswith(("DIFFERENT", "MULTILINE"))], lines
    for (name, _), line in zip(targeted, lines[len(offsets):]):
        assert line.startswith("ERROR") and name.rsplit("/", 1)[-1] in line, (name, line)
    reported = sum(ln.startswith("ERROR") for ln in lines)
    assert reported >= len(targeted)
    print(f"\n{kind}: {len(lines)} flipped bytes ({len(targeted)} inside datasets): {reported} "
          f"reported in one line, {len(lines) - reported} harmless (same values)")


@pytest.mark.parametrize("kind", ["tilt", "ensemble"])
def test_truncated_files_give_one_line(tmp_path, tilt_file, reference, kind):
    source = tilt_file if kind == "tilt" else reference
    data = source.read_bytes()
    copies = []
    for i, length in enumerate(np.linspace(0, len(data) - 1, TRUNCATIONS).astype(int)):
        path = tmp_path / f"{kind}_cut{i}.h5"
        path.write_bytes(data[:length])
        copies.append(path)
    lines = _load_copies(tmp_path, kind, source, copies)
    assert all(ln.startswith("ERROR") for ln in lines), lines


@pytest.mark.two_cores  # its ensembles run on 2 ranks
def test_damaged_ensemble_refuses_resume_in_one_line(tmp_path, reference):
    out = tmp_path / "damaged.h5"
    shutil.copy(reference, out)
    with h5py.File(out, "r") as f:
        offset = f["grids"][sorted(f["grids"])[0]].id.get_offset()
    with open(out, "r+b") as fh:
        fh.seek(offset)
        byte = fh.read(1)
        fh.seek(offset)
        fh.write(bytes([byte[0] ^ 0xFF]))
    res = run(ensemble_args(out, extra=["--resume"]), n=2, timeout=60)
    assert "fails its checksum" in one_error_line(res)


def test_write_then_read_keeps_checksums_valid(tmp_path, tilt_file):
    """No false alarm: a saved run and a finished ensemble load without a word."""
    r = sliders.Result.load(tilt_file)
    r.save(tmp_path / "again.h5")
    assert sliders.Result.load(tmp_path / "again.h5").n_events == r.n_events


def test_script_loop_without_handler_is_not_swallowed(tmp_path):
    """The exit status of an interrupted script is non-zero (SIGINT, KeyboardInterrupt)."""
    script = tmp_path / "one.py"
    script.write_text(textwrap.dedent("""
        import os, signal, sliders
        def ctrl_c(p):
            os.kill(os.getpid(), signal.SIGINT)
        sliders.tilt(sliders.Scene(n_sliders=30, seed=1, mode="explore"), backend="numpy",
                     progress=ctrl_c)
        print("not reached")
    """))
    res = subprocess.run([PY, str(script)], capture_output=True, text=True, timeout=60)
    assert res.returncode != 0 and "not reached" not in res.stdout
    assert "sliders.driver.Interrupted" in res.stderr


@pytest.mark.two_cores  # its ensembles run on 2 ranks
def test_resume_recomputes_a_damaged_row(tmp_path, reference):
    """A finished row whose bytes were flipped: reading names it; --resume recomputes it."""
    out = tmp_path / "row.h5"
    shutil.copy(reference, out)
    with h5py.File(out, "r") as f:
        ds = f["realisations/alpha_c"]
        offset = ds.id.get_offset() + 3 * ds.dtype.itemsize  # row 3
    with open(out, "r+b") as fh:
        fh.seek(offset + 2)
        byte = fh.read(1)
        fh.seek(offset + 2)
        fh.write(bytes([byte[0] ^ 0x01]))
    with pytest.raises(storage.StorageError, match=r"row 3 of dataset /realisations/alpha_c fails"):
        read_realisations(out)
    assert storage.damaged_rows(out) == [3]
    res = run(ensemble_args(out, extra=["--resume"]), n=2)
    assert res.returncode == 0, res.stderr
    assert "1 finished row(s)" in res.stderr and "resuming 1 of" in res.stderr
    assert_same_file(reference, out)


@pytest.mark.parametrize("where", ["prepare", "_finish"])
def test_interrupt_in_the_python_around_the_engine_is_an_interrupted(monkeypatch, where):
    """Ctrl-C landing while the chain is drawn or the result assembled (the
    milliseconds of Python around the engine: a loop of short runs hits them)
    still answers with Interrupted, and the partial result is a whole one."""
    from sliders import driver

    scene = sliders.Scene(n_sliders=20, seed=3, mode="explore")
    real = getattr(driver, where)
    calls = []

    def ctrl_c_once(*args, **kwargs):
        calls.append(where)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(driver, where, ctrl_c_once)
    with pytest.raises(sliders.Interrupted) as exc:
        sliders.tilt(scene)
    partial = exc.value.partial
    full = sliders.tilt(scene)
    np.testing.assert_array_equal(partial.initial.displacement, full.initial.displacement)
    if where == "prepare":  # stopped before any event
        assert partial.status == "interrupted" and partial.n_events == 0
    else:  # stopped as the run ended: the whole run
        assert partial.status == full.status and partial.n_events == full.n_events
    calls.clear()
    kept = sliders.tilt(scene, keep_partial=True)
    assert kept.n_events == partial.n_events
