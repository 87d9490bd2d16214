"""Ctrl-C while a command is still importing its modules: one line and status 130 for
``python -m sliders...``; a program that imports the package keeps its KeyboardInterrupt.

The Ctrl-C is made deterministic: a finder on ``sys.meta_path`` (installed by a
``sitecustomize`` on ``PYTHONPATH``) raises KeyboardInterrupt when the named module is
imported, as a Ctrl-C landing in that import would."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

HOOK = textwrap.dedent("""
    import os, sys

    class CtrlC:
        def find_spec(self, name, path=None, target=None):
            if name == os.environ["CTRL_C_IN"]:
                raise KeyboardInterrupt
            return None

    sys.meta_path.insert(0, CtrlC())
""")


def started(tmp_path, module: str, *argv: str) -> subprocess.CompletedProcess:
    (tmp_path / "sitecustomize.py").write_text(HOOK)
    env = dict(os.environ, CTRL_C_IN=module,
               PYTHONPATH=os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, *argv], capture_output=True, text=True, env=env,
                          timeout=120)


@pytest.mark.parametrize("command, module, who", [
    ("sliders.forecast", "sliders.runs.forecast.cli", "sliders.forecast"),  # its parser's
    ("sliders.forecast", "sliders.forecasting.common", "sliders.forecast"),  # its defaults
    ("sliders.ensemble", "sliders.runs.ensemble", "ensemble"),
    ("sliders", "sliders.scene", "sliders"),
])
def test_ctrl_c_while_a_command_starts_is_one_line(tmp_path, command, module, who):
    res = started(tmp_path, module, "-m", command, "--help")
    assert res.returncode == 130, res.stderr
    assert res.stderr.splitlines() == [f"{who}: interrupted (SIGINT) while starting; "
                                       "nothing written"], res.stderr
    assert res.stdout == ""


def test_a_program_importing_the_package_keeps_its_ctrl_c(tmp_path):
    res = started(tmp_path, "sliders.driver", "-c", "import sliders; sliders.Scene; sliders.run")
    assert res.returncode != 0 and "KeyboardInterrupt" in res.stderr
    assert "while starting" not in res.stderr
