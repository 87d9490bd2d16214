"""Reading a model file runs nothing from the current folder.

Reading a model file imports the modules of the classes it names, and a module loaded by
then may answer a lookup by importing a module of that name (``Cython.Shadow`` does, loaded by
scipy wherever Cython is installed): a ``./exp2.py`` (a name of scipy.special) would run while
``predict`` read the shipped model.  Here a
stand-in for such a module is loaded by a ``sitecustomize`` (so the test does not depend on
Cython being installed), and the folder holds a module under every name it could be asked for.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # a forecast in a fresh process

ANSWERS_BY_IMPORTING = textwrap.dedent("""
    import importlib, sys, types

    shadow = types.ModuleType("shadow_like")
    shadow.__getattr__ = lambda name: importlib.import_module(name)  # as Cython.Shadow does
    sys.modules["shadow_like"] = shadow
""")
BAIT = ("exp2", "gamma", "erf", "sqrt", "loads", "dumps", "Pipeline", "Learned")


@pytest.mark.parametrize("how", ["module", "script"])
def test_predict_imports_nothing_from_the_current_folder(tmp_path, how):
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(ANSWERS_BY_IMPORTING)
    here = tmp_path / "pile"
    here.mkdir()
    ran = here / "ran.txt"
    for name in BAIT:
        (here / f"{name}.py").write_text(f"open({str(ran)!r}, 'a').write('{name}\\n')\n")
    angles = np.degrees(0.55 * (1.0 - np.exp(-np.arange(1, 120) / 40.0)))  # events accelerating
    (here / "pile.csv").write_text("angle [deg],size\n" + "".join(f"{a:.4f},2\n" for a in angles))
    if how == "module":
        argv = ["-m", "sliders.forecast", "predict", "pile.csv"]
    else:  # a script in that folder, through the Python API
        (here / "bench.py").write_text("import sliders.forecast as sf\n"
                                       "print(sf.load().predict('pile.csv'))\n")
        argv = ["bench.py"]
    env = dict(os.environ,
               PYTHONPATH=os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    res = subprocess.run([sys.executable, *argv], cwd=here, capture_output=True, text=True,
                         env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "avalanche angle" in res.stdout
    assert not ran.exists(), f"ran from the current folder: {ran.read_text().split()}"
