"""Trust, second round (issue 22): the scenarios an attacker found, one test each.

Classes (docs/reliability.md counts them): 1. merge on the ensemble's footing;
2. a path is not a file (one notion of file identity); 3. computed, then lost
(checks before computing, leftover temporaries); 4. versions and kinds;
5. inputs (studies by meaning, bounds).  Tiny scenes (N = 10-12); most
scenarios run in this process, the ones that need a second writer or MPI as
subprocesses.
"""

from __future__ import annotations

import fcntl
import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

import sliders
from sliders.io import safeio, storage, study_file
from sliders.io.filelock import ClaimError, OutputClaim
from sliders.runs import ensemble, merge
from sliders.parts.checks import SceneError
from sliders.scene import available_memory, check_memory
from helpers import (PY, SCENE_OPTS, STUDY_TEXT, _env, _Run, assert_same_file, ensemble_args,
                     one_error_line, run)

TINY = ["--n-sliders", "10", "--seed", "3", "--mode", "explore"]
R_TINY = 6
# the same study written differently: keys reordered, 0 for 0.0, a default written out
STUDY_SAME = """
[axes]
xi = [0, 0.001]
[scene]
seed = 5
mu_d = 0.5
mode = "explore"
n_sliders = 10
[study]
realisations = 2
"""


def tilt_cli(*args, timeout=60):
    return subprocess.run([PY, "-m", "sliders", "tilt", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, env=_env())


def temporaries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith((".tmp", ".lock")))


def ensemble_main(capsys, *args) -> tuple[int, str]:
    code = ensemble.main([str(a) for a in args])
    return code, capsys.readouterr().err


def merge_main(capsys, *args) -> tuple[int, str]:
    code = merge.main([str(a) for a in args])
    return code, capsys.readouterr().err


def one_line(code: int, err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code != 0, err
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    assert lines[0].startswith("error: "), lines[0]
    return lines[0]


def done_rows(path):
    return storage.read_realisations(path)["done"]


@pytest.fixture(scope="module")
def chunk_files(tmp_path_factory):
    """Two chunk files of one ensemble (R_TINY rows), and the whole run for comparison."""
    d = tmp_path_factory.mktemp("trust")
    for i in range(2):
        code = ensemble.main(TINY + ["-R", str(R_TINY), "--chunk", f"{i}/2", "--quiet",
                                     "--out", str(d / f"c{i}.h5")])
        assert code == 0
    code = ensemble.main(TINY + ["-R", str(R_TINY), "--quiet", "--out", str(d / "whole.h5")])
    assert code == 0
    return d


@pytest.fixture
def chunks(chunk_files, tmp_path):
    """Fresh copies of the chunk files in this test's folder."""
    for name in ("c0.h5", "c1.h5", "whole.h5"):
        (tmp_path / name).write_bytes((chunk_files / name).read_bytes())
    return tmp_path


def hold_claim(path: Path):
    """A foreign holder of the claim on ``path`` (another open file description)."""
    fd = os.open(str(path) + ".lock", os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    os.pwrite(fd, b"pid 424242 on elsewhere\n", 0)
    return fd


# ---------------------------------------------------------------------------
# 1. merge on the ensemble's footing
# ---------------------------------------------------------------------------
def test_merge_interrupted_keeps_the_old_output(chunks, capsys, monkeypatch):
    out = chunks / "out.h5"
    out.write_bytes((chunks / "c0.h5").read_bytes())  # an older file to be replaced
    before = out.read_bytes()
    calls = []

    def ctrl_c(self, r, row):
        calls.append(r)
        if len(calls) == 3:
            raise KeyboardInterrupt

    monkeypatch.setattr(storage.GatherFile, "write_row", ctrl_c)
    code, err = merge_main(capsys, out, chunks / "c0.h5", chunks / "c1.h5", "--overwrite")
    assert code == 130 and "Traceback" not in err and "unchanged" in err
    assert out.read_bytes() == before
    assert temporaries(chunks) == []


def test_merge_full_disk_keeps_the_old_output_and_names_it(chunks, capsys, monkeypatch):
    out = chunks / "out.h5"
    out.write_bytes(b"old")

    def full(self, r, row):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(storage.GatherFile, "write_row", full)
    code, err = merge_main(capsys, out, chunks / "c0.h5", chunks / "c1.h5", "--overwrite")
    line = one_line(code, err)
    assert "No space left on device" in line and str(out) in line
    assert out.read_bytes() == b"old" and temporaries(chunks) == []


def test_merge_onto_a_full_disk_keeps_the_old_output(chunks, capsys, tmp_path):
    """A real full disk (tmpfs): the old output stays, one line names the path."""
    disk = tmp_path / "disk"
    disk.mkdir()
    old = (chunks / "c0.h5").read_bytes()
    size = (len(old) // 4096 + 4) * 4096  # the old file fits, the merged one does not
    if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(disk)]).returncode:
        pytest.fail("cannot mount a tmpfs (the suite runs as root)")
    try:
        out = disk / "out.h5"
        out.write_bytes(old)
        code, err = merge_main(capsys, out, chunks / "c0.h5", chunks / "c1.h5", "--overwrite")
        line = one_line(code, err)
        assert "No space left on device" in line and str(out) in line
        assert out.read_bytes() == old and temporaries(disk) == []
    finally:
        subprocess.run(["umount", "-l", str(disk)])


def test_merge_refused_while_the_output_is_claimed(chunks, capsys):
    out = chunks / "whole.h5"
    fd = hold_claim(out)
    try:
        before = out.read_bytes()
        code, err = merge_main(capsys, out, chunks / "c0.h5", chunks / "c1.h5", "--overwrite")
        assert "pid 424242 on elsewhere" in one_line(code, err)
        assert out.read_bytes() == before
    finally:
        os.close(fd)


def test_resume_refused_while_merge_holds_the_output(chunks, capsys, monkeypatch):
    """The reverse: an ensemble --resume meets the merge's claim (the 12/12-but-7 case)."""
    out = chunks / "out.h5"
    original = storage.GatherFile.write_row
    out.write_bytes((chunks / "whole.h5").read_bytes())
    # the claim is re-entrant within a process: the resume runs in a child
    res = None

    def child_resume(self, r, row):
        nonlocal res
        if res is None:
            res = subprocess.run([PY, "-m", "sliders.ensemble", "--resume", "--out", str(out)],
                                 capture_output=True, text=True, timeout=60, env=_env())
        return original(self, r, row)

    monkeypatch.setattr(storage.GatherFile, "write_row", child_resume)
    code, err = merge_main(capsys, out, chunks / "c0.h5", chunks / "c1.h5", "--overwrite")
    assert code == 0, err
    assert res.returncode != 0 and "is being written by pid" in res.stderr, res.stderr
    assert done_rows(out).all()


def test_merge_output_that_is_an_input_through_a_symlinked_folder(chunks, capsys):
    (chunks / "here").symlink_to(".")
    before = (chunks / "c0.h5").read_bytes()
    code, err = merge_main(capsys, chunks / "here" / "c0.h5", chunks / "c0.h5", chunks / "c1.h5",
                           "--overwrite")
    assert "both an input and the output" in one_line(code, err)
    assert (chunks / "c0.h5").read_bytes() == before


def test_merge_output_that_is_an_input_by_hard_link(chunks, capsys):
    os.link(chunks / "c1.h5", chunks / "alias.h5")
    before = (chunks / "c1.h5").read_bytes()
    code, err = merge_main(capsys, chunks / "alias.h5", chunks / "c0.h5", chunks / "c1.h5",
                           "--overwrite")
    assert "both an input and the output" in one_line(code, err)
    assert (chunks / "c1.h5").read_bytes() == before


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_merge_refuses_an_output_that_is_not_a_regular_file(chunks, capsys, kind):
    out = chunks / "node"  # never a system node: a broken merge would replace it
    if kind == "fifo":
        os.mkfifo(out)
    else:
        os.mknod(out, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # a null device of our own
    code, err = merge_main(capsys, out, chunks / "c0.h5", chunks / "c1.h5", "--overwrite")
    assert "not a regular file" in one_line(code, err)
    mode = os.stat(out).st_mode
    assert stat.S_ISFIFO(mode) if kind == "fifo" else stat.S_ISCHR(mode)


def test_ensemble_onto_a_fifo_is_refused_without_blocking(tmp_path, capsys):
    os.mkfifo(tmp_path / "fifo")
    code, err = ensemble_main(capsys, *TINY, "-R", 2, "--out", tmp_path / "fifo")
    assert "not a regular file" in one_line(code, err)
    assert stat.S_ISFIFO(os.stat(tmp_path / "fifo").st_mode)


@pytest.mark.parametrize("where, needle", [
    ("missing/out.h5", "does not exist"),
    ("", "empty"),
    ("/sys/out.h5", "/sys"),
])
def test_merge_bad_output_is_one_line(chunks, capsys, where, needle):
    out = str(chunks / where) if where.startswith("missing") else where
    code, err = merge_main(capsys, out, chunks / "c0.h5", chunks / "c1.h5")
    line = one_line(code, err)
    assert needle in line and "MB free" not in line


def test_merge_read_only_folder_is_one_line(chunks, capsys, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m,ro", "tmpfs", str(ro)]).returncode:
        pytest.fail("cannot mount a read-only tmpfs (the suite runs as root)")
    try:
        code, err = merge_main(capsys, ro / "out.h5", chunks / "c0.h5", chunks / "c1.h5")
        line = one_line(code, err)
        assert "Read-only file system" in line and "MB free" not in line
    finally:
        subprocess.run(["umount", "-l", str(ro)])


def test_merge_removes_and_reports_a_killed_merges_temporary(chunks, capsys):
    out = chunks / "out.h5"
    leftover = chunks / ".out.h5.k1ll3d_x.tmp"
    leftover.write_bytes(b"\0" * 4096)
    code, err = merge_main(capsys, out, chunks / "c0.h5", chunks / "c1.h5")
    assert code == 0, err
    assert "removed 1 temporary file" in err and leftover.name in err
    assert temporaries(chunks) == []
    assert_same_file(chunks / "whole.h5", out)


# ---------------------------------------------------------------------------
# 2. a path is not a file
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("ranks", [None, pytest.param(2, marks=[pytest.mark.two_cores,
                                                                 pytest.mark.slow])])
@pytest.mark.slow  # seconds of work: the full suite
def test_second_resume_through_a_symlink_is_refused(tmp_path, ranks):
    out = tmp_path / "e.h5"
    (tmp_path / "link.h5").symlink_to(out.name)
    env = _env(SLIDERS_ENSEMBLE_TEST_DELAY=0.3, HDF5_USE_FILE_LOCKING="FALSE")
    first = _Run(ensemble_args(out, r=8), ranks, env)
    try:
        deadline = time.monotonic() + 30
        while not out.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        second = run(["--resume", "--out", tmp_path / "link.h5", "--progress-interval", "0"],
                     env=_env(HDF5_USE_FILE_LOCKING="FALSE"))
        assert "is being written by pid" in one_error_line(second)
    finally:
        res = first.finish(90)
    assert res.returncode == 0, res.stderr
    assert done_rows(out).all()


def test_lock_file_symlink_is_never_followed(tmp_path):
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me\n")
    (tmp_path / "out.h5.lock").symlink_to(victim)
    res = tilt_cli(*TINY, "--out", tmp_path / "out.h5", "--quiet")
    assert "symbolic link" in one_error_line(res)
    assert victim.read_text() == "keep me\n" and not (tmp_path / "out.h5").exists()


def test_lock_file_that_is_not_a_regular_file_is_refused(tmp_path):
    (tmp_path / "out.h5.lock").mkdir()
    with pytest.raises(ClaimError, match="not a regular file|Is a directory"):
        OutputClaim(tmp_path / "out.h5").acquire()


def test_tilt_out_symlink_to_a_new_file_writes_through(tmp_path):
    (tmp_path / "link.h5").symlink_to("target.h5")
    res = tilt_cli(*TINY, "--out", tmp_path / "link.h5", "--quiet")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "link.h5").is_symlink()
    assert sliders.Result.load(tmp_path / "target.h5").n_events > 0


def test_overwrite_and_save_write_through_a_symlink(tmp_path, tilt_file):
    target = tmp_path / "target.h5"
    target.write_bytes(b"old")
    (tmp_path / "link.h5").symlink_to(target)
    res = tilt_cli(*TINY, "--out", tmp_path / "link.h5", "--overwrite", "--quiet")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "link.h5").is_symlink() and target.read_bytes()[:6] != b"old"
    result = sliders.Result.load(tilt_file)
    result.save(tmp_path / "link.h5")
    assert (tmp_path / "link.h5").is_symlink()
    assert sliders.Result.load(target).n_events == result.n_events
    assert temporaries(tmp_path) == []


def test_ensemble_out_dangling_symlink_creates_its_target(tmp_path, capsys):
    (tmp_path / "link.h5").symlink_to("target.h5")
    code, err = ensemble_main(capsys, *TINY, "-R", 2, "--quiet", "--out", tmp_path / "link.h5")
    assert code == 0, err
    assert (tmp_path / "link.h5").is_symlink() and done_rows(tmp_path / "target.h5").all()


# ---------------------------------------------------------------------------
# 3. computed, then lost: checks before computing
# ---------------------------------------------------------------------------
def test_name_too_long_for_the_temporary_is_refused_before_the_run(tmp_path, capsys):
    out = tmp_path / ("n" * 239 + ".h5")  # 242 characters: legal, but not with the suffix
    res = tilt_cli(*TINY, "--out", out, "--quiet")
    assert "at most 241" in one_error_line(res)
    code, err = ensemble_main(capsys, *TINY, "-R", 2, "--out", out)
    assert "at most 241" in one_line(code, err)
    assert list(tmp_path.iterdir()) == []


def test_name_not_utf8_is_refused_before_the_run(tmp_path, capsys):
    out = os.fsdecode(os.fsencode(str(tmp_path)) + b"/bad\xff.h5")
    res = subprocess.run([PY.encode(), b"-m", b"sliders", b"tilt", b"--n-sliders", b"10",
                          b"--quiet", b"--out", os.fsencode(out)],
                         capture_output=True, timeout=60, env=_env())
    err = res.stderr.decode(errors="replace")
    assert res.returncode == 2 and "not valid UTF-8" in err and "Traceback" not in err, err
    code, err = ensemble_main(capsys, *TINY, "-R", 2, "--out", out)
    assert "not valid UTF-8" in one_line(code, err)
    assert os.listdir(tmp_path) == []  # no 0-row file that --resume could never complete


def test_study_point_too_large_is_refused_before_the_file(tmp_path, capsys):
    from sliders.runs import study

    spec = tmp_path / "s.toml"
    spec.write_text(STUDY_TEXT.replace("xi = [0.0, 0.001]", "n_sliders = [10, 1000000000]")
                    .replace("n_sliders = 10\n", ""))
    code = study.main([str(spec), "--out", str(tmp_path / "s.h5")])
    line = one_line(code, capsys.readouterr().err)
    assert "point 1" in line and "GB" in line
    assert not (tmp_path / "s.h5").exists() and temporaries(tmp_path) == []


def memory_hog(share: float) -> sliders.Scene:
    """A scene whose memory estimate is about ``share`` of MemAvailable."""
    available = available_memory()
    assert available, "no /proc/meminfo"
    base = sliders.Scene(n_sliders=1000, mode="explore")
    n = int(1000 * share * available / base.memory_estimate())
    return sliders.Scene(n_sliders=n, mode="explore")


@pytest.mark.slow  # runs under mpirun: the full suite's
@pytest.mark.two_cores  # it starts mpirun -n 2
def test_memory_is_summed_over_the_ranks_of_a_node(tmp_path):
    scene = memory_hog(0.6)
    check_memory(scene, 1)
    with pytest.raises(SceneError, match="2 ranks on this node"):
        check_memory(scene, 2)
    res = run(["--n-sliders", scene.n_sliders, "--mode", "explore", "-R", 4,
               "--out", tmp_path / "e.h5"], n=2)
    assert "2 ranks on this node" in one_error_line(res)
    assert not (tmp_path / "e.h5").exists()


def test_killed_save_leaves_a_temporary_the_next_save_removes(tmp_path, tilt_file):
    out = tmp_path / "r.h5"
    leftover = tmp_path / ".r.h5.abcd1234.tmp"
    leftover.write_bytes(b"\0" * 1000)
    res = tilt_cli(*TINY, "--out", out)
    assert res.returncode == 0 and "removed 1 temporary file" in res.stderr, res.stderr
    leftover.write_bytes(b"\0" * 1000)
    with pytest.warns(UserWarning, match="removed 1 temporary file"):
        sliders.Result.load(tilt_file).save(out)
    assert temporaries(tmp_path) == []


def test_killed_ensemble_creation_leaves_a_temporary_the_next_run_removes(tmp_path, capsys):
    leftover = tmp_path / ".e.h5.zz99yy88.tmp"
    leftover.write_bytes(b"\0" * 1000)
    (tmp_path / ".other.h5.zz99yy88.tmp").write_bytes(b"not ours")  # another file's: kept
    code, err = ensemble_main(capsys, *TINY, "-R", 2, "--out", tmp_path / "e.h5")
    assert code == 0 and "removed 1 temporary file" in err, err
    assert temporaries(tmp_path) == [".other.h5.zz99yy88.tmp"]


# ---------------------------------------------------------------------------
# 4. versions and kinds
# ---------------------------------------------------------------------------
def bump_version(path: Path, version: int = 99) -> None:
    """A file written by a future sliders: format_version changed, every checksum valid."""
    from sliders.io.run_file import WHOLE_FILE_MAGIC, seal_whole_file

    with h5py.File(path, "r+") as f:
        f.attrs["format_version"] = version
        safeio.seal_attrs(f)
    data = path.read_bytes()
    if data.startswith(WHOLE_FILE_MAGIC):
        path.write_bytes(seal_whole_file(data))


def test_newer_tilt_file_is_refused_naming_the_versions(tmp_path, tilt_file):
    path = tmp_path / "new.h5"
    path.write_bytes(tilt_file.read_bytes())
    bump_version(path)
    with pytest.raises(ValueError, match="format_version 99.*reads format_version 1"):
        sliders.Result.load(path)


def test_newer_ensemble_is_refused_by_readers_and_resume(chunks, capsys):
    path = chunks / "whole.h5"
    with h5py.File(path, "r+") as f:
        f["realisations"]["done"][-1] = 0  # one row left for a resume to write
    bump_version(path)
    before = path.read_bytes()
    for reader in (storage.read_header, storage.read_realisations, storage.damaged_rows):
        with pytest.raises(storage.StorageError, match="format_version 99.*newer"):
            reader(path)
    code, err = ensemble_main(capsys, "--resume", "--out", path)
    assert "format_version 99" in one_line(code, err)
    assert path.read_bytes() == before
    code, err = merge_main(capsys, chunks / "m.h5", path)
    assert "format_version 99" in one_line(code, err)


def test_newer_study_is_refused_by_readers_and_resume(tmp_path, capsys):
    from sliders.runs import study

    spec = tmp_path / "s.toml"
    spec.write_text(STUDY_TEXT)
    out = tmp_path / "s.h5"
    assert study.main([str(spec), "--out", str(out), "--quiet"]) == 0
    with h5py.File(out, "r+") as f:
        f["points"]["p001"]["realisations"]["done"][-1] = 0
    bump_version(out)
    before = out.read_bytes()
    capsys.readouterr()
    for reader in (study_file.read_study_header, study_file.read_study_spec):
        with pytest.raises(storage.StorageError, match="format_version 99"):
            reader(out)
    code = study.main([str(spec), "--out", str(out), "--resume"])
    assert "format_version 99" in one_line(code, capsys.readouterr().err)
    assert out.read_bytes() == before


def test_a_file_of_another_kind_is_named_not_damaged(tilt_file, chunks):
    with pytest.raises(storage.StorageError) as info:
        storage.read_realisations(tilt_file)
    assert "tilt file (one run" in str(info.value) and "damaged" not in str(info.value)
    with pytest.raises(ValueError) as info:
        sliders.Result.load(chunks / "c0.h5")
    assert "ensemble file" in str(info.value) and "damaged" not in str(info.value)


@pytest.mark.slow  # seconds of work: the full suite
def test_reading_an_ensemble_being_written_says_busy(tmp_path):
    out = tmp_path / "e.h5"
    env = _env(SLIDERS_ENSEMBLE_TEST_DELAY=0.4)
    env.pop("HDF5_USE_FILE_LOCKING", None)
    first = _Run(ensemble_args(out, r=6, extra=["--storage", "gather"]), None, env)
    try:
        deadline = time.monotonic() + 30
        while not out.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)
        probe = subprocess.run(
            [PY, "-c", "import sys; from sliders.io import storage\n"
             "try: storage.read_header(sys.argv[1])\n"
             "except storage.StorageError as e: print(e)", str(out)],
            capture_output=True, text=True, timeout=60, env=env)
        assert "is busy" in probe.stdout and "pid" in probe.stdout, probe.stdout + probe.stderr
    finally:
        res = first.finish(90)
    assert res.returncode == 0, res.stderr


# ---------------------------------------------------------------------------
# 5. inputs
# ---------------------------------------------------------------------------
def test_study_resume_compares_meaning_and_names_the_differing_key(tmp_path, capsys,
                                                                   monkeypatch):
    from sliders.runs import scheduler, study

    a, b, c = tmp_path / "a.toml", tmp_path / "b.toml", tmp_path / "c.toml"
    a.write_text(STUDY_TEXT)
    b.write_text(STUDY_SAME)
    c.write_text(STUDY_TEXT.replace("mu_d = 0.5", "mu_d = 0.45"))
    out = tmp_path / "s.h5"
    completed = scheduler.Root.completed

    def stop_after_one(root, code):  # as if SIGTERM came after the first row
        completed(root, code)
        root.stop("test: stop after one row", 15)

    with monkeypatch.context() as m:
        m.setattr(scheduler.Root, "completed", stop_after_one)
        study.main([str(a), "--out", str(out), "--quiet"])
    capsys.readouterr()
    code = study.main([str(c), "--out", str(out), "--resume", "--quiet"])
    line = one_line(code, capsys.readouterr().err)
    assert "scene differ: mu_d is 0.5 in the file, 0.45 in" in line
    assert study.main([str(b), "--out", str(out), "--resume", "--quiet"]) == 0
    assert all(d.all() for d in study_file.read_study_header(out)["done"])


def test_absurd_realisation_count_is_refused_at_once(tmp_path):
    t0 = time.monotonic()
    res = run(SCENE_OPTS + ["-R", "99999999999999999999", "--out", tmp_path / "e.h5"])
    assert "No space left on device" in one_error_line(res)
    assert time.monotonic() - t0 < 20
    assert list(tmp_path.iterdir()) == []


def test_scene_whose_lattice_overflows_is_refused(tmp_path):
    res = tilt_cli("--n-sliders", 10, "--spring-length", "1e308", "--out", tmp_path / "r.h5")
    assert "spring_length" in one_error_line(res) and "overflow" in res.stderr
    assert list(tmp_path.iterdir()) == []
