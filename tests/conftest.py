"""Shared fixtures: both backends, a cache so that a scene runs once per session, the one SLURM
cluster of a test session, and the machine's cores shared between pytest-xdist workers.

Cores.  Under ``pytest -n N`` every test holds one core slot while it runs (setup, call and
teardown, so module fixtures count too); a test marked ``two_cores`` (it starts ``mpirun``, a
SLURM job or a second busy process) holds them all, so it never runs beside another test and
the machine is never oversubscribed; one marked ``ranks_share_one_core`` (a serial command under
``mpirun -n 2``, whose second rank sleeps) keeps its one core.  A waiting ``two_cores`` test
holds a turnstile that keeps new tests from starting, so it is not starved.  The ``two_cores``
tests form one xdist group, run back to back on one worker, which keeps both cores from one to
the next: the other worker gives up its core once for all of them, not once per test.  A test
that starts ranks without the mark fails, naming the mark (pages of commands are marked from
their blocks).  Without xdist nothing is locked.

``slurm`` starts munged, slurmctld and slurmd for one node on localhost
(``scripts/slurm_local.sh start``, in a private directory with its own munge
socket and ports) the first time a test asks for it, and stops them at the
end of the session by the pids in their pid files.  tests/test_slurm.py and
the SLURM blocks of mpi_runs/README.md (tests/test_docs_commands.py) share
it.  It skips only when SLURM cannot be started, saying why.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import pickle
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# One thread per library pool in every test process: a test holds one core (CoreSlots), and
# OpenMP threads of scikit-learn's trees that outnumber the free cores only wait for each other
# (on the busy two-core machine one fit of the learned forecaster took 128 s with them, 2.6 s
# without).  Set before NumPy, SciPy or scikit-learn load their thread pools.
for _pool in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_pool, "1")

import pytest  # noqa: E402

import sliders  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SLURM_LOCAL = ROOT / "scripts" / "slurm_local.sh"
SLURM_DAEMONS = ("munged", "slurmctld", "slurmd")

BACKENDS = ("fortran", "numpy")


def pytest_configure(config):
    # A suite started in the background by a script (``cmd &``, nohup) inherits SIGINT ignored,
    # and so would every process a test starts: Python then installs no KeyboardInterrupt
    # handler, and the tests of Ctrl-C would see a run that cannot be interrupted.  The
    # tests' processes get SIGINT as a terminal gives it (a handled signal is reset to the
    # default at exec).
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    config.addinivalue_line("markers", "two_cores: the test keeps both cores busy (mpirun -n 2, "
                                       "SLURM, a second process); under xdist it runs alone")
    config.addinivalue_line("markers", "ranks_share_one_core: the test's ranks use one core "
                                       "between them (a serial command under mpirun: rank 1 "
                                       "sleeps until rank 0's status); it holds one core")
    config.addinivalue_line("markers", "slow: left out of the fast loop (pytest -m 'not slow')")
    # pytest-xdist's own, named here too for a run without it (-p no:xdist)
    config.addinivalue_line("markers", "xdist_group(name): under --dist loadgroup, the tests of "
                                       "one group run on one worker")


# words of a command line that start ranks or jobs: a test running one needs both cores
LAUNCHERS = {"mpirun", "mpiexec", "sbatch", "srun", "salloc"}


def starts_ranks(args) -> bool:
    """Whether a subprocess's command line launches MPI ranks or a SLURM job (also inside a
    ``bash -c`` script, as one of the job scripts of mpi_runs/, or as a command given
    ``--np K``, K > 1, which starts its own ranks: ``sliders.forecast train``)."""
    argv = [args] if isinstance(args, (str, bytes, os.PathLike)) else list(args)
    words = re.split(r"[\s;&|()'\"=]+", " ".join(os.fsdecode(a) for a in argv))
    return any(Path(w).name in LAUNCHERS or ("mpi_runs/" in w and w.endswith(".sh"))
               or (w == "--np" and nxt.isdigit() and int(nxt) > 1)
               for w, nxt in zip(words, words[1:] + [""]))


class CoreSlots:
    """One xdist worker's share of the cores: shared while a test runs, all of them from the
    moment it starts ranks or a job (or from its start, if marked ``two_cores``) to its end.

    A change of hold drops the old one first, then waits at the turnstile, so two workers that
    both upgrade never wait on each other, and a worker waiting for all cores keeps new tests
    from taking one (no starvation)."""

    def __init__(self, directory: Path):
        directory.mkdir(exist_ok=True)
        self.turnstile = open(directory / "turnstile", "a")
        self.cores = open(directory / "cores", "a")
        self.held = None
        self.waited = {fcntl.LOCK_SH: 0.0, fcntl.LOCK_EX: 0.0}  # seconds, this test
        self.ranks_share_one_core = False  # this test's ranks need no second core

    def hold(self, mode: int) -> None:
        if self.held == mode or self.held == fcntl.LOCK_EX:
            return
        if self.held is not None:
            fcntl.flock(self.cores, fcntl.LOCK_UN)
        started = time.monotonic()
        fcntl.flock(self.turnstile, fcntl.LOCK_EX)
        try:
            fcntl.flock(self.cores, mode)
            self.held = mode
        finally:
            fcntl.flock(self.turnstile, fcntl.LOCK_UN)
            self.waited[mode] += time.monotonic() - started

    def release(self) -> None:
        fcntl.flock(self.cores, fcntl.LOCK_UN)
        self.held = None


def pytest_sessionstart(session):
    worker = getattr(session.config, "workerinput", None)
    if worker is None:  # not under xdist: nothing to share
        return
    slots = CoreSlots(Path(tempfile.gettempdir(), f"sliders-test-cores-{worker['testrunuid']}"))
    session.config.stash[CORE_SLOTS] = slots
    execute = subprocess.Popen._execute_child

    def execute_holding_cores(self, args, *rest, **kw):
        if slots.held is not None and not slots.ranks_share_one_core and starts_ranks(args):
            if slots.held != fcntl.LOCK_EX:  # it would share a core with another test's work
                raise RuntimeError("this test starts ranks or a job: mark it "
                                   "@pytest.mark.two_cores (or ranks_share_one_core if its "
                                   "second rank sleeps); see tests/conftest.py")
        return execute(self, args, *rest, **kw)

    subprocess.Popen._execute_child = execute_holding_cores


CORE_SLOTS = pytest.StashKey[CoreSlots]()


# the shell blocks of a Markdown page that tests/test_docs_commands.py runs: those not after a
# ``<!-- skip: next "why" -->`` line (and blank lines)
SHELL_BLOCK = re.compile(r"^(<!-- skip: next[^\n]*-->\s*)?```(?:bash|console)[^\n]*\n(.*?)^```",
                         re.M | re.S)


def run_blocks(text: str) -> list[str]:
    """The shell blocks of a page that its commands' test runs (the skipped ones left out)."""
    return [block for skip, block in SHELL_BLOCK.findall(text) if not skip]


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Every test that starts ranks or a job, and every test of the SLURM cluster, goes to one
    worker (the group ``two_cores``), which starts the session's one cluster and keeps both
    cores from one such test to the next.  Within the group, the tests that need one core come
    first, so that the others follow one another."""
    for item in items:
        runs_page = getattr(item, "originalname", "") == "test_page_commands_run_as_written"
        blocks = run_blocks(Path(item.callspec.params["page"]).read_text()) if runs_page else []
        if any(starts_ranks(block) for block in blocks):
            item.add_marker(pytest.mark.two_cores)
        if (item.get_closest_marker("two_cores") or "slurm" in item.fixturenames
                or any("sbatch" in block for block in blocks)):
            item.add_marker(pytest.mark.xdist_group("two_cores"))
    if getattr(config.option, "loadgroup", False):  # in one process, modules stay whole
        items.sort(key=lambda item: item.get_closest_marker("two_cores") is not None)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_finish(session):
    """``--dist loadgroup`` sends the tests of one ``xdist_group`` to one worker, which knows
    them by the suffix ``@group`` of their node ids.  pytest-xdist 3.8 writes that suffix into
    an attribute pytest 9's items no longer read (their ids are structured), so the groups would
    be lost and every test dealt out alone; it is written here into the id itself."""
    if not getattr(session.config.option, "loadgroup", False):
        return
    from _pytest.nodeid import NodeId

    for item in session.items:
        groups = sorted({str(m.args[0] if m.args else m.kwargs.get("name", "default"))
                         for m in item.iter_markers("xdist_group")})
        if groups and "@" not in item.nodeid:
            item._id = NodeId.parse(f"{item.nodeid}@{'_'.join(groups)}")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    slots = item.config.stash.get(CORE_SLOTS, None)
    if slots is None:
        yield
        return
    slots.waited = {fcntl.LOCK_SH: 0.0, fcntl.LOCK_EX: 0.0}
    slots.ranks_share_one_core = item.get_closest_marker("ranks_share_one_core") is not None
    started, cpu = time.time(), cpu_seconds()
    slots.hold(fcntl.LOCK_EX if item.get_closest_marker("two_cores") else fcntl.LOCK_SH)
    try:
        yield
    finally:
        both = slots.held == fcntl.LOCK_EX
        if not (both and nextitem is not None and nextitem.get_closest_marker("two_cores")):
            slots.release()  # else kept for the next test, which holds both cores too
        timeline = os.environ.get("SLIDERS_TEST_TIMELINE")
        if timeline:  # benchmarks/suite_cost.py: where the suite's wall time goes
            record = {"test": item.nodeid, "worker": item.config.workerinput["workerid"],
                      "start": started, "end": time.time(), "cpu": cpu_seconds() - cpu,
                      "both_cores": both, "waited_one": slots.waited[fcntl.LOCK_SH],
                      "waited_both": slots.waited[fcntl.LOCK_EX]}
            with open(timeline, "a") as f:
                f.write(json.dumps(record) + "\n")


def cpu_seconds(*who: int) -> float:
    """CPU time (user + system) of ``who`` (``resource.RUSAGE_SELF``, ``RUSAGE_CHILDREN``: the
    subprocesses waited for); both by default."""
    usages = [resource.getrusage(w) for w in who or (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    return sum(u.ru_utime + u.ru_stime for u in usages)


# where run() keeps its results: a folder of the test session that its xdist workers share
SCENE_CACHE: Path | None = None


@pytest.fixture(scope="session", autouse=True)
def scene_cache(request, tmp_path_factory) -> Path:
    """The session's folder of tilted scenes, one for all xdist workers (their base
    temporary folders are subfolders of the session's)."""
    global SCENE_CACHE
    base = tmp_path_factory.getbasetemp()
    if hasattr(request.config, "workerinput"):
        base = base.parent
    SCENE_CACHE = base / "scenes"
    SCENE_CACHE.mkdir(exist_ok=True)
    return SCENE_CACHE


def session_cached(what: str, compute, *args):
    """``compute(*args)`` once per test session, for every xdist worker: the first to ask
    computes it and stores it (``session_folder``); the others wait and read it.  Each call
    returns its own copy, which a test may change freely.  Keyed by ``what`` and the
    arguments' repr (frozen scenes and strings)."""
    if SCENE_CACHE is None:  # imported outside a test session
        return compute(*args)

    def store(folder: Path) -> None:
        (folder / "value.pickle").write_bytes(pickle.dumps(compute(*args)))

    return pickle.loads((session_folder((what, args), store) / "value.pickle").read_bytes())


def session_folder(what, make) -> Path:
    """A folder that ``make(folder)`` fills once per test session, for every xdist worker: the
    first to ask fills it (under a lock, then renames it into place); the others wait and get
    it.  The tests only read it (copy what they change).  Keyed by ``what``'s repr."""
    base = SCENE_CACHE if SCENE_CACHE is not None else Path(tempfile.mkdtemp())
    key = hashlib.sha256(repr((what, sliders.__version__)).encode()).hexdigest()[:24]
    folder = base / key
    with open(base / f"{key}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not folder.exists():
            partial = base / f"{key}.{os.getpid()}.part"
            shutil.rmtree(partial, ignore_errors=True)
            partial.mkdir()
            make(partial)
            partial.rename(folder)
    return folder


def run(scene: sliders.Scene, backend: str) -> sliders.Result:
    """Tilt a scene once per test session (``session_cached``).  Tests that patch the engines
    or the transcendentals call ``sliders.tilt`` themselves."""
    result = session_cached("tilt", sliders.tilt, scene, backend)
    assert result.scene == scene and result.backend == backend
    return result


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


# ---------------------------------------------------------------------------
# fixtures several test modules use (their plain helpers: tests/helpers.py)
# ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tilt_file(tmp_path_factory):
    """A saved run of 20 sliders (a module's own ``tilt_file`` fixture takes precedence)."""
    path = tmp_path_factory.mktemp("tiltfile") / "t.h5"
    sliders.tilt(sliders.Scene(n_sliders=20, seed=1, mode="explore")).save(path)
    return path


@pytest.fixture(scope="session")
def shipped():
    """The shipped model's forecasters and provenance (``load_forecasters``), loaded once a
    session: read only."""
    from sliders.analysis.forecast.model_file import load_forecasters
    from sliders.io.forecast_model import default_model_path

    return load_forecasters(default_model_path())


@pytest.fixture(scope="session")
def shipped_model():
    """The shipped model and posterior as ``sliders.forecast.load()`` gives them, loaded once a
    session: read only."""
    import sliders.forecast as sf

    return sf.load()


def _run_small_prior(folder: Path) -> None:
    from helpers import SMALL_PRIOR, TIMEOUT, _env

    (folder / "p.toml").write_text(SMALL_PRIOR.format(R=12, design="sobol"))
    done = subprocess.run([sys.executable, "-m", "sliders.prior", str(folder / "p.toml"),
                           "--out", str(folder / "p.h5"), "--quiet"], capture_output=True,
                          text=True, timeout=TIMEOUT, env=_env())
    assert done.returncode == 0, done.stderr


@pytest.fixture(scope="session")
def small_prior() -> tuple[Path, Path]:
    """``helpers.SMALL_PRIOR`` of 12 Sobol rows (``p.toml``) and its ensemble run serially by
    ``python -m sliders.prior`` (``p.h5``), made once a session for every worker: read only
    (copy what you change)."""
    folder = session_folder("small-prior", _run_small_prior)
    return folder / "p.toml", folder / "p.h5"


@pytest.fixture(scope="module")
def reduced(shipped):
    """The shipped model's conditioned, ffm_ml_events and learned_blind forecasters, each
    boosted regressor cut to its first ``ITERATIONS`` trees: fast to write and read."""
    import copy

    from helpers import ITERATIONS

    models, prov = shipped
    blind = copy.deepcopy(models["learned_blind"])
    blind.models_ = [m.first(ITERATIONS) for m in blind.models_]
    return {"conditioned": models["conditioned"], "ffm_ml_events": models["ffm_ml_events"],
            "learned_blind": blind}, {"rows": prov["rows"], "prior": "the shipped prior"}
