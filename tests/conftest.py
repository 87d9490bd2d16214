"""Shared fixtures: both backends, a cache so that a scene runs once per session, and the
one SLURM cluster of a test session.

``slurm`` starts munged, slurmctld and slurmd for one node on localhost
(``scripts/slurm_local.sh start``, in a private directory with its own munge
socket and ports) the first time a test asks for it, and stops them at the
end of the session by the pids in their pid files.  tests/test_slurm.py and
the SLURM blocks of mpi_runs/README.md (tests/test_docs_commands.py) share
it.  It skips only when SLURM cannot be started, saying why.
"""

from __future__ import annotations

import functools
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

import sliders

ROOT = Path(__file__).resolve().parents[1]
SLURM_LOCAL = ROOT / "scripts" / "slurm_local.sh"
SLURM_DAEMONS = ("munged", "slurmctld", "slurmd")

BACKENDS = ("fortran", "numpy")


@functools.lru_cache(maxsize=None)
def run(scene: sliders.Scene, backend: str) -> sliders.TiltResult:
    """Tilt a scene once per test session (Scene is frozen and hashable)."""
    return sliders.tilt(scene, backend=backend)


@pytest.fixture(params=BACKENDS)
def backend(request) -> str:
    return request.param


def _why_slurm_cannot_start() -> str | None:
    if os.geteuid() != 0:
        return "SLURM cannot be started: slurmd must run as root (run the suite as root)"
    missing = [b for b in SLURM_DAEMONS + ("sbatch", "squeue", "scontrol")
               if shutil.which(b, path=os.environ.get("PATH", "") + ":/usr/sbin:/sbin") is None]
    if missing:
        return (f"SLURM cannot be started: {' '.join(missing)} not installed "
                "(bash scripts/slurm_local.sh install, or bash scripts/setup.sh)")
    return None


def _stopped(pid: int) -> bool:
    """Gone, or a zombie waiting for a parent that does not reap it (no init in a container)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except (FileNotFoundError, IndexError):
        return True


class Cluster:
    """A running one-node SLURM: its directory, the environment of its clients, its daemons."""

    def __init__(self, directory: str):
        self.dir = directory
        self.env = dict(os.environ, SLURM_CONF=f"{directory}/slurm.conf",
                        PATH=os.environ.get("PATH", "") + ":/usr/sbin:/sbin")
        self.pids: dict[str, int] = {}

    def submit(self, script: Path, *options: str, **env: str) -> str:
        """sbatch SCRIPT from the repository root with ``env`` exported; returns the job id."""
        res = subprocess.run(["sbatch", "--parsable", *options, str(script)], cwd=ROOT,
                             env=dict(self.env, **env), capture_output=True, text=True, timeout=60)
        assert res.returncode == 0, res.stderr
        return res.stdout.strip().split(";")[0]

    def wait(self, job: str, timeout: float = 240.0) -> list[tuple[str, str]]:
        """(JobState, ExitCode) of every record of a finished job (one per array task)."""
        deadline = time.monotonic() + timeout
        while subprocess.run(["squeue", "-h", "-j", job], env=self.env, capture_output=True,
                             text=True).stdout.strip():
            if time.monotonic() > deadline:
                subprocess.run(["scancel", job], env=self.env)
                pytest.fail(f"job {job} still queued after {timeout} s")
            time.sleep(0.3)
        show = subprocess.run(["scontrol", "show", "job", job], env=self.env, capture_output=True,
                              text=True).stdout
        return re.findall(r"JobState=(\S+).*?ExitCode=(\S+)", show, flags=re.S)


@pytest.fixture(scope="session")
def slurm():
    """The session's one-node SLURM cluster (started on first use, stopped at the end)."""
    why = _why_slurm_cannot_start()
    if why:
        pytest.skip(why)
    # under /tmp, world-traversable: munged (user munge) and slurmctld (user slurm) work in it
    directory = tempfile.mkdtemp(prefix="sliders-slurm-", dir="/tmp")
    os.chmod(directory, 0o755)
    cluster = Cluster(directory)
    started = time.monotonic()
    res = subprocess.run(["bash", str(SLURM_LOCAL), "start", directory], capture_output=True,
                         text=True, timeout=120)
    for d in SLURM_DAEMONS:
        pid = Path(directory, f"{d}.pid")
        if pid.exists() and pid.read_text().strip():
            cluster.pids[d] = int(pid.read_text())
    try:
        if res.returncode != 0:
            lines = res.stderr.strip().splitlines() or ["no message"]
            pytest.skip(f"SLURM cannot be started: {lines[-1]}")
        sys.stderr.write(f"\nslurm: cluster up in {time.monotonic() - started:.1f} s ({directory})\n")
        yield cluster
    finally:
        subprocess.run(["bash", str(SLURM_LOCAL), "stop", directory], timeout=60)
        alive = {d: p for d, p in cluster.pids.items() if not _stopped(p)}
        shutil.rmtree(directory, ignore_errors=True)
        assert not alive, f"daemons still running after stop: {alive}"
