"""All file I/O lives in ``sliders.io``: no other module of the package imports h5py.

The tilt-result, ensemble and study files are laid out, written and read in
``sliders/io/``; the rest of the package asks it.  The scan reads the source
(every import statement, also inside functions, and ``import_module``/
``__import__`` calls), so a new ``import h5py`` anywhere else fails here.
"""

from __future__ import annotations

import ast
from pathlib import Path

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
    for module in ("io/storage.py", "io/tilt_file.py", "io/study_file.py"):
        assert module in importing, module


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
