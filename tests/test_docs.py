"""The documentation is checked, not trusted.

* Every command and example of the README and of the pages under docs/ runs
  as written in tests/test_docs_commands.py (Sybil), printed outputs compared.
* The ``>>>`` examples in the package's docstrings give what they print.
* The Sphinx site builds with warnings as errors (-W); the build executes the
  tutorial notebook (myst-nb, through nbclient), so a cell that raises fails
  this test, and the rendered page must hold its figures.
* Every public name (``sliders.__all__``, and the public functions, classes
  and methods of every public module) has a docstring.
"""

from __future__ import annotations

import doctest
import importlib
import inspect
import os
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import pytest

import sliders

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def test_docstring_examples_are_current(tmp_path, monkeypatch):
    """The ``>>>`` examples in the package's docstrings give what they print."""
    monkeypatch.chdir(tmp_path)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE | doctest.ELLIPSIS)
    report: list[str] = []
    for modname in public_modules():
        for test in finder.find(importlib.import_module(modname)):
            runner.run(test, out=report.append)
    result = runner.summarize(verbose=False)
    assert result.attempted >= 2  # Scene and Result have examples
    assert result.failed == 0, "".join(report)


def public_modules() -> list[str]:
    """Every module of the package whose dotted name has no part starting with '_'."""
    names = ["sliders"]
    for info in pkgutil.walk_packages(sliders.__path__, "sliders."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return names


def public_objects():
    """(qualified name, object) of every public name to document."""
    for name in sliders.__all__:
        if not name.startswith("__"):
            yield f"sliders.{name}", getattr(sliders, name)
    for modname in public_modules():
        module = importlib.import_module(modname)
        yield modname, module
        for name, obj in vars(module).items():
            if name.startswith("_") or getattr(obj, "__module__", None) != modname:
                continue  # private, or imported from elsewhere (documented there)
            if inspect.isfunction(obj) or inspect.isclass(obj):
                yield f"{modname}.{name}", obj
            if inspect.isclass(obj):
                for attr, member in vars(obj).items():
                    if attr.startswith("_"):
                        continue
                    if isinstance(member, (staticmethod, classmethod)):
                        member = member.__func__
                    if inspect.isfunction(member) or isinstance(member, property):
                        yield f"{modname}.{name}.{attr}", member


def test_every_public_name_has_a_docstring():
    objects = list(public_objects())
    assert len(objects) > 200  # the walk found the package's modules
    missing = sorted(name for name, obj in objects if not (inspect.getdoc(obj) or "").strip())
    assert not missing, f"{len(missing)} public names without a docstring: {missing}"


@pytest.mark.slow  # the whole site, the tutorial executed
def test_docs_build_without_warnings_and_run_the_tutorial(tmp_path):
    """sphinx -W: a broken reference, a bad docstring or a failing tutorial cell fails here."""
    out = tmp_path / "html"
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}  # figures inline
    env["SLIDERS_DOCS_EXECUTE"] = "force"
    res = subprocess.run([sys.executable, "-m", "sphinx", "-E", "-W", "--keep-going", "-q", "-b",
                          "html", "-d", str(tmp_path / "doctrees"), str(DOCS), str(out)],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    tutorial = (out / "tutorial.html").read_text()
    assert "Traceback" not in tutorial
    assert tutorial.count("<img") >= 2  # the hot map and P_i against the master equation
    assert re.search(r"alpha_c = 0\.5\d{3} rad in \[0\.5028, 0\.5404\]", tutorial)
    for page in ("index", "model", "api", "howto/xarray", "reproduction", "performance"):
        assert (out / f"{page}.html").is_file(), page
    # the API reference was generated: a page per module, its classes and functions on it
    assert 'id="sliders.Scene"' in (out / "generated" / "sliders.html").read_text()
    assert 'id="sliders.io.catalogue.Catalogue"' in (
        out / "generated" / "sliders.io.catalogue.html").read_text()
