"""Imports that hold the suite and the package together.

* No test module imports another test module: shared helpers live in
  ``tests/helpers.py``, shared fixtures in ``tests/conftest.py`` (importing a
  test module runs its module-level code, fixtures and handlers included).
* Every module of the package imports on its own, in a fresh package state
  (as sbi's ``circular_import_test.py``): an import circle that only some
  entry points reach shows as the error of a partially initialised module.
  ``tests/test_layers.py`` reads the same circles statically.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent

# One interpreter imports every module of PACKAGE in turn, each after the package's modules
# are dropped from sys.modules (the libraries they use stay loaded: a fresh package, cheaply).
IMPORT_EACH = """
import importlib, pkgutil, sys
package = sys.argv[1]
root = importlib.import_module(package)
names = sorted(m.name for m in pkgutil.walk_packages(root.__path__, package + ".")
               if not m.name.endswith("__main__"))
failed = []
for name in names:
    for k in [k for k in sys.modules if k == package or k.startswith(package + ".")]:
        del sys.modules[k]
    try:
        importlib.import_module(name)
    except Exception as exc:
        failed.append(f"{name}: {type(exc).__name__}: {exc}")
print(len(names))
print("\\n".join(failed), file=sys.stderr)
sys.exit(1 if failed else 0)
"""


def test_no_test_module_imports_another():
    """No ``import test_x`` or ``from test_x import ...`` anywhere under tests/, also inside
    functions."""
    found = []
    for path in sorted(TESTS.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                     else [])
            found += [f"{path.relative_to(TESTS)}:{node.lineno} imports {n}"
                      for n in names if n.split(".")[0].startswith("test_")]
    assert not found, "test modules import test modules (use helpers.py or conftest.py):\n" + \
        "\n".join(found)


def import_each(package: str, pycache: Path, path: Path | None = None) -> subprocess.CompletedProcess:
    """Every module of ``package`` (found on ``path`` if given) imported in turn, in one
    interpreter."""
    env = dict(os.environ, PYTHONPYCACHEPREFIX=str(pycache))  # compiled once, not per module
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    if path is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(path)] + [p for p in [env.get("PYTHONPATH")] if p])
    return subprocess.run([sys.executable, "-c", IMPORT_EACH, package], capture_output=True,
                          text=True, env=env, timeout=300)


@pytest.mark.slow  # an interpreter started
def test_the_check_finds_an_import_circle(tmp_path):
    """A package whose two modules import names from each other: each, imported first,
    fails on the other half-initialised, and the check names both."""
    pkg = tmp_path / "circle"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .b import B\nA = 1\n")
    (pkg / "b.py").write_text("from .a import A\nB = 2\n")
    res = import_each("circle", tmp_path / "pycache", tmp_path)
    assert res.returncode == 1 and res.stdout.split() == ["2"]
    assert "circle.a: ImportError" in res.stderr and "circle.b: ImportError" in res.stderr
    assert "circular import" in res.stderr


@pytest.mark.slow  # ~100 fresh imports of the package: 10-40 s on the shared machine
def test_every_module_of_the_package_imports_on_its_own(tmp_path):
    res = import_each("sliders", tmp_path / "pycache")  # the installed package
    assert res.returncode == 0, res.stderr
    assert int(res.stdout.split()[0]) > 50  # the package's modules were walked


# The forecasting layer's modules imported in a fresh interpreter, and what of the package they
# bring in: none of the commands (``sliders.runs``) nor the front door, however reached
# (an import statement, a name imported by importlib at run time).
FORECASTING_IMPORTS = """
import importlib, pkgutil, sys
import sliders.forecasting as layer
for m in pkgutil.iter_modules(layer.__path__, "sliders.forecasting."):
    importlib.import_module(m.name)
print("\\n".join(sorted(m for m in sys.modules if m.startswith(("sliders.runs", "sliders.forecast"))
                        and not m.startswith("sliders.forecasting"))))
"""


@pytest.mark.slow  # an interpreter started
def test_the_forecasting_layer_imports_none_of_the_commands():
    res = subprocess.run([sys.executable, "-c", FORECASTING_IMPORTS], capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == []
