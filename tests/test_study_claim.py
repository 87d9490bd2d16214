"""The study names itself in the messages of its output claim (they are the ensemble's code).

A dead run's claim (``<out>.lock`` left with its holder's words, no lock held)
is taken over with a note that must say ``study:``, not ``ensemble:``.
"""

from __future__ import annotations

import pytest

import subprocess
import sys

pytestmark = pytest.mark.slow  # a parameter study run as a command

STUDY = """
[study]
realisations = 1
[scene]
n_sliders = 8
mode = "explore"
seed = 2
[axes]
xi = [0.0]
"""


def test_study_takes_over_a_stale_claim_and_says_study(tmp_path):
    spec = tmp_path / "s.toml"
    spec.write_text(STUDY)
    out = tmp_path / "s.h5"
    lock = tmp_path / "s.h5.lock"
    lock.write_text("pid 999999 on a-dead-host\n")  # what a killed holder leaves
    res = subprocess.run([sys.executable, "-m", "sliders.study", str(spec), "--out", str(out)],
                         capture_output=True, text=True, timeout=180)
    assert res.returncode == 0, res.stderr
    notes = [line for line in res.stderr.splitlines() if "stale claim" in line]
    assert len(notes) == 1, res.stderr
    assert notes[0].startswith("study: note: ") and "pid 999999 on a-dead-host" in notes[0]
    assert not lock.exists()  # taken over, then released
