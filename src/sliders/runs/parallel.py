"""MPI is optional: ``get_comm()`` gives COMM_WORLD with a working mpi4py, else a serial stand-in.

``pip install sliders`` runs everything serially (tilt, ensembles through the
gather writer, figures); ``pip install "sliders[mpi]"`` adds mpi4py.  An
mpi4py that is absent or cannot load its MPI library (the PyPI wheel on a
machine without libmpi: ``libmpi.so.12: cannot open shared object file``)
is handled in one of two ways, decided from the environment the launcher sets:

* a plain process: one warning line (only when mpi4py is installed but
  broken), then serial;
* under ``mpirun``/``srun`` (``PMI_RANK``, ``PMI_SIZE``, ``HYDRA_*``,
  ``OMPI_COMM_WORLD_SIZE``, ``PMIX_RANK``, or ``SLURM_STEP_NUM_TASKS`` > 1): every rank would otherwise run
  the whole job alone and write the same file, so ``MPIUnavailable`` is raised;
  the caller prints one line (rank 0 of the launcher) and exits non-zero on
  every rank.  No rank calls MPI, so none can wait for another: never a hang.
"""

from __future__ import annotations

import os
import signal
import sys
import time

# Variables that MPICH (Hydra, PMI), Open MPI and PMIx launchers set in every rank.
LAUNCHER_VARIABLES = ("PMI_RANK", "PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "OMPI_COMM_WORLD_RANK",
                      "PMIX_RANK")
LAUNCHER_PREFIXES = ("HYDRA_",)
RANK_VARIABLES = ("PMI_RANK", "OMPI_COMM_WORLD_RANK", "PMIX_RANK", "SLURM_PROCID")

INSTALL_HINT = ('install an MPI library and an mpi4py built against it (Debian: '
                '`bash scripts/setup.sh`, or `apt install mpich libmpich-dev` then '
                '`pip install --no-binary mpi4py "sliders[mpi]"`), or run without mpirun (serial)')


class MPIUnavailable(RuntimeError):
    """Launched by an MPI launcher, but mpi4py cannot give this process an MPI communicator."""


class SerialComm:
    """The few communicator calls the package uses, for one process without MPI."""

    rank = 0
    size = 1

    def bcast(self, obj, root=0):
        """``obj`` itself (one process)."""
        return obj

    def allgather(self, obj):
        """``[obj]`` (one process)."""
        return [obj]

    def gather(self, obj, root=0):
        """``[obj]`` (one process)."""
        return [obj]

    def Abort(self, code=1):  # noqa: N802 - MPI spelling
        """End the process at once with ``code``, as MPI_Abort would."""
        os._exit(code)


# Seconds a rank waits between writing its last words and MPI_Abort.  Hydra forwards a rank's
# stderr through its proxy and handles the abort on another socket of the same event loop: an
# abort read first kills the job before the proxy drains the pipe, and the one line that says
# why is lost (seen once in CI: "realisation 4 fails" never reached the terminal).
ABORT_GRACE = 0.5
#: how long the other ranks of a stopped job wait for rank 0's abort beyond that grace (a rank
#: that exits with the code before the abort leaves MPICH's mpiexec to return 0 at times: 1
#: run in 5 of a SIGTERM while rank 0 reads its input); they exit with it if none comes
ABORT_WAIT = 10.0


def error_line(message: str) -> str:
    """``message`` as the one line a refusal or a failure prints: ``error: ...``, no line breaks."""
    return "error: " + " ".join(str(message).split())


def abort(comm, line: str | None = None, code: int = 1):
    """Write ``line`` (if any) to stderr, let the launcher forward it, then end every rank."""
    if line is not None:
        sys.stderr.write(line + "\n")
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed or broken stream: nothing more to say
            pass
    if comm.size > 1:
        time.sleep(ABORT_GRACE)
    comm.Abort(code)


def under_mpi_launcher(environ=None) -> bool:
    """True when an MPI launcher started this process (one rank of several, or of one)."""
    env = os.environ if environ is None else environ
    srun_tasks = env.get("SLURM_STEP_NUM_TASKS", "")  # srun without an MPI plugin sets no PMI_*
    return (any(v in env for v in LAUNCHER_VARIABLES)
            or any(k.startswith(LAUNCHER_PREFIXES) for k in env)
            or (srun_tasks.isdigit() and int(srun_tasks) > 1))


def launcher_rank(environ=None) -> int:
    """This process's rank as the launcher announces it (0 when it does not)."""
    env = os.environ if environ is None else environ
    for v in RANK_VARIABLES:
        if env.get(v, "").isdigit():
            return int(env[v])
    return 0


def stopped_job_status(comm, code: int) -> int:
    """The exit status of every rank, made the job's own when a signal stopped it.

    A job stopped by SIGINT or SIGTERM (``code`` = 128 + the signal) on
    several ranks ends by ``MPI_Abort(code)`` from rank 0, after the one line
    is out: MPICH's ``mpiexec`` then returns ``code``.  Ranks that merely exit
    with it lose it when the terminal's Ctrl-C also reaches the launcher's
    proxy (``mpiexec`` returned 0 there).  MPICH's own "application called
    MPI_Abort" line is not printed: the command has said why it stopped.
    From here on every rank ignores SIGINT and SIGTERM: MPICH's proxy forwards the
    terminal's Ctrl-C to the ranks, which had it from the terminal too, and that copy
    may land after the command's handlers are gone (a KeyboardInterrupt traceback
    while the interpreter shuts down).  The other ranks wait for rank 0's abort
    (``ABORT_WAIT``) rather than exit first.  Serially (or for any other code) the code is
    returned as it is.
    """
    if code <= 128 or comm.size < 2:
        return code
    for stop in (signal.SIGINT, signal.SIGTERM):  # the job is stopping: copies change nothing
        signal.signal(stop, signal.SIG_IGN)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    if comm.rank == 0:
        time.sleep(ABORT_GRACE)  # the launcher forwards the line before the abort
        try:
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, 2)
        except OSError:
            pass
        comm.Abort(code)
    else:  # the other ranks wait for rank 0's abort: one that exits first may lose the code
        time.sleep(ABORT_GRACE + ABORT_WAIT)
    return code


def get_comm():
    """``(COMM_WORLD, True)`` with a working mpi4py, else ``(SerialComm(), False)``.

    Raises ``MPIUnavailable`` under an MPI launcher when mpi4py is missing or broken.
    """
    try:
        from mpi4py import MPI
    except ModuleNotFoundError as exc:
        if exc.name != "mpi4py":  # mpi4py is there but something it needs is not
            return _broken(exc)
        if under_mpi_launcher():
            raise MPIUnavailable(f"started by an MPI launcher, but mpi4py is not installed; "
                                 f"{INSTALL_HINT}") from None
        return SerialComm(), False
    except (ImportError, RuntimeError, OSError) as exc:  # e.g. libmpi.so.12 missing
        return _broken(exc)
    return MPI.COMM_WORLD, True


def _broken(exc: BaseException):
    reason = " ".join(str(exc).split()) or type(exc).__name__
    if under_mpi_launcher():
        raise MPIUnavailable(f"started by an MPI launcher, but mpi4py cannot load MPI ({reason}); "
                             f"{INSTALL_HINT}") from None
    sys.stderr.write(f"sliders: warning: mpi4py is installed but cannot load MPI ({reason}); "
                     "running serially\n")
    sys.stderr.flush()
    return SerialComm(), False
