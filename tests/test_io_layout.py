"""All file I/O lives in ``sliders.io``: no other module of the package imports h5py.

The tilt-result, ensemble and study files are laid out, written and read in
``sliders/io/``; the rest of the package asks it.  The scan reads the source
(every import statement, also inside functions, and ``import_module``/
``__import__`` calls), so a new ``import h5py`` anywhere else fails here.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import sliders

PACKAGE = Path(sliders.__file__).resolve().parent
IO_PACKAGE = PACKAGE / "io"


def h5py_imports(source: str) -> list[int]:
    """Line numbers of every import of h5py (or of one of its submodules) in ``source``."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            names = [node.module or ""] if node.level == 0 else []
        elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
              and getattr(node.func, "attr", getattr(node.func, "id", None))
              in ("import_module", "__import__")):
            names = [str(node.args[0].value)]
        else:
            continue
        if any(n == "h5py" or n.startswith("h5py.") for n in names):
            lines.append(node.lineno)
    return lines


def test_the_scan_sees_every_form_of_import():
    source = ("import numpy as np\n"
              "import h5py\n"
              "def f():\n    from h5py import File\n"
              "def g():\n    import os, h5py.h5p as p\n"
              "h = importlib.import_module('h5py')\n"
              "from .h5py_notes import x\n"      # a relative module named alike: not h5py
              "import h5pyx\n")
    assert h5py_imports(source) == [2, 4, 6, 7]


def test_h5py_is_imported_only_inside_sliders_io():
    importing = {path.relative_to(PACKAGE).as_posix(): h5py_imports(path.read_text())
                 for path in sorted(PACKAGE.rglob("*.py"))}
    importing = {name: lines for name, lines in importing.items() if lines}
    outside = {name: lines for name, lines in importing.items() if not name.startswith("io/")}
    assert not outside, f"h5py imported outside sliders/io (module: lines): {outside}"
    # the file modules themselves are found by the scan (it is not looking at nothing)
    for module in ("io/storage.py", "io/run_file.py", "io/study_file.py"):
        assert module in importing, module


@pytest.mark.slow  # seconds of work: the full suite
def test_the_probe_tells_the_user_what_a_path_holds(tmp_path):
    from sliders.io import formats

    assert formats.probe_file(tmp_path / "none.h5").state == "missing"
    assert formats.probe_file(tmp_path).state == "directory"
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5\n")
    assert formats.probe_file(text).state == "not_hdf5"
    run = tmp_path / "run.h5"
    sliders.tilt(sliders.Scene(n_sliders=4, seed=1), backend="numpy").save(run)
    probe = formats.probe_file(run)
    assert (probe.state, probe.format, probe.ensemble_rows) == ("hdf5", formats.TILT, False)
    cut = tmp_path / "cut.h5"
    cut.write_bytes(run.read_bytes()[:700])  # the superblock's signature, not the rest
    probe = formats.probe_file(cut)
    assert probe.state == "bad_hdf5" and probe.reason


# ---------------------------------------------------------------------------
# the prior file: each quantity once, the same bytes on any number of ranks
# ---------------------------------------------------------------------------
DATA = Path(__file__).resolve().parent / "data"
PRIOR_TOML = """
[prior]
realisations = 8
seed = 5
ceiling_step = 0.05
ceiling_k = 4
[scene]
mode = "explore"
[parameters]
mu_d = { uniform = [0.3, 0.8] }
mu_s_minus_mu_d = { loguniform = [0.02, 0.12] }
sigma_mu = { uniform = [0.005, 0.03] }
xi = { loguniform = [1e-4, 1e-2], zero = 0.5 }
n_sliders = { choice = [20, 30] }
initial_forces = { choice = ["uniform", "zero"] }
"""


def run_prior(args, n_ranks=1):
    import shutil
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "sliders.prior", *map(str, args), "--quiet"]
    if n_ranks > 1:
        cmd = [shutil.which("mpirun") or "mpiexec", "-n", str(n_ranks)] + cmd
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


def stored_datasets(path) -> dict:
    """{dataset path: (dtype, shape, bytes)}; a dimension without values (no storage) as None."""
    import h5py

    out = {}

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset):
            stored = obj.id.get_storage_size() > 0 or obj.size == 0
            out[name] = (obj.dtype.str, obj.shape, obj[()].tobytes()) if stored else None
    with h5py.File(path, "r") as f:
        f.visititems(visit)
    return out


@pytest.fixture(scope="module")
def prior_files(tmp_path_factory):
    """A small prior run on 1 rank and on 2 ranks."""
    d = tmp_path_factory.mktemp("prior")
    toml = d / "prior.toml"
    toml.write_text(PRIOR_TOML)
    one, two = d / "one.h5", d / "two.h5"
    for out, n in ((one, 1), (two, 2)):
        done = run_prior([toml, "--out", out], n)
        assert done.returncode == 0, done.stderr
    return one, two


@pytest.mark.slow  # runs under mpirun: the full suite's
@pytest.mark.two_cores  # its fixture runs the prior on 2 ranks
def test_prior_file_is_the_same_on_one_and_two_ranks_and_stores_each_thing_once(prior_files):
    """Every dataset byte for byte, but the measured wall time of each row (and its CRC-32 in
    row_crc32); no two datasets hold the same values; the events are in row order."""
    import json

    import h5py

    from sliders.io.prior_file import read_prior_ensemble

    one, two = prior_files
    a, b = stored_datasets(one), stored_datasets(two)
    assert sorted(a) == sorted(b)
    with h5py.File(one, "r") as f:
        wall = json.loads(f["realisations/row_crc32"].attrs["columns"]).index("wall_time")
        digests = [h5py.File(p, "r")["realisations/row_crc32"][()] for p in (one, two)]
    timings = {"realisations/wall_time", "realisations/row_crc32"}
    assert {k for k in a if a[k] != b[k]} <= timings
    assert np.array_equal(np.delete(digests[0], wall, axis=1), np.delete(digests[1], wall, axis=1))
    stored = [v for v in a.values() if v is not None and np.prod(v[1]) > 1]
    assert len(stored) == len(set(stored)), "a quantity is stored twice"
    got = read_prior_ensemble(one)
    with h5py.File(one, "r") as f:
        assert np.array_equal(f["realisations/event_start"][()], got.offsets[:-1])
        assert f["events/alpha"].shape == (got.offsets[-1],)
        assert f.attrs["format_version"] == 2


@pytest.mark.slow  # seconds of work: the full suite
def test_a_prior_file_of_format_1_still_reads_and_is_not_resumed(tmp_path):
    """Format 1 (everything also flat at the root, events in completion order) reads the
    same catalogues as its own root view; --resume refuses it in one line naming the version."""
    import shutil

    import h5py

    from sliders.io.prior_file import read_prior_ensemble, read_prior_row

    old = DATA / "prior_format1.h5"
    got = read_prior_ensemble(old)
    assert len(got) == 3 and got.attrs["format_version"] == 1
    with h5py.File(old, "r") as f:  # format 1's flat view: the events in row order
        for c in ("alpha", "size", "displacement", "first", "last"):
            assert np.array_equal(got.columns[c], f[c][()]), c
        assert np.array_equal(got.parameters["mu_d"], f["mu_d"][()])
    assert len(read_prior_row(old, 1)) == got.offsets[2] - got.offsets[1]
    copy = tmp_path / "old.h5"
    shutil.copy(old, copy)
    shutil.copy(DATA / "prior_format1.toml", tmp_path / "prior.toml")
    with h5py.File(copy, "r+") as f:
        f["realisations/done"][-1] = 0  # a row left for a resume
    done = run_prior([tmp_path / "prior.toml", "--out", copy, "--resume"])
    lines = done.stderr.strip().splitlines()
    assert done.returncode != 0 and len(lines) == 1 and "format_version 1" in lines[0], lines


@pytest.mark.slow  # runs under mpirun: the full suite's
@pytest.mark.two_cores  # its fixture runs the prior on 2 ranks
def test_putting_a_prior_file_in_row_order_is_atomic_and_resumable(prior_files, tmp_path,
                                                                     monkeypatch):
    """Events a killed writer left past the last row are dropped when the file is put in row
    order; a kill before the rename leaves the file as it was, and the next run orders it."""
    import shutil

    import h5py

    from sliders.io import prior_file, safeio

    path = tmp_path / "p.h5"
    shutil.copy(prior_files[0], path)
    with h5py.File(path, "r+") as f:  # a row's events written, the row itself never
        prior_file.append_events(f, prior_file.file_events(
            {c: np.arange(3) for c in ("alpha", "size", "displacement", "first", "last")}))
    before = path.read_bytes()

    def killed(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(safeio, "publish", killed)
    with pytest.raises(KeyboardInterrupt):
        prior_file.write_view(path)
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["p.h5"]
    monkeypatch.undo()
    prior_file.write_view(path)
    a, b = stored_datasets(prior_files[0]), stored_datasets(path)
    assert {k for k in a if a[k] != b[k]} == set()
