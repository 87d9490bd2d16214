"""The shape every run command shares (ensemble, study, prior ensemble), and its parts.

A run command is a ``RunCommand``: a parser, the input files rank 0 reads,
the checks every rank makes, the plan rank 0 makes while holding the claim on
``--out`` (a ``RunPlan``), and the run.  ``run_planned`` drives it over the
ranks in agreement rounds: between two collective steps every rank does local
work only, and every failure of that work (a bad option, a bad input, Ctrl-C,
a bug) is caught and carried into the next collective step, so that every rank
learns it and exits together:

1. every rank parses the command line; rank 0 reads the input files
   (``input_paths``), and every rank receives rank 0's bytes: no rank reads
   an input itself, so every rank parses the same text;
2. every rank checks what it can (``prepare``); rank 0 claims ``--out``
   (``claim_output``) and makes the plan (``plan``);
3. rank 0's plan is broadcast and the rows are computed (``run``, usually
   ``open_output`` then ``scheduler.serve_rows``).

A refusal is one line on rank 0's stderr (``error_line``), exit status 2 for
bad input, 1 for a failure, 128 + signal number after SIGINT or SIGTERM.

The pieces are public for every command that reads or writes files:
``UsageError``, ``CommandParser``, ``error_line``, ``claim_output``,
``check_new_or_resume``, ``read_input``.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .parallel import (MPIUnavailable, abort, error_line, get_comm, launcher_rank,
                       stopped_job_status)
from .signals import StopFlag
from .cli import check_output, ranks_on_this_node
from ..analysis.study_spec import StudyError
from ..io.filelock import OutputClaim, claim_of
from ..io.safeio import is_special, leftovers_note, os_reason
from ..io.storage import CollectiveFailure, STORAGES, StorageError, choose_storage
from ..parts.checks import SceneError
from ..scene import BACKENDS

DEFAULT_BACKEND = "fortran"
MAX_INPUT_BYTES = 1 << 20  # an input TOML larger than this is refused unread


class UsageError(Exception):
    """A bad command line or input: one line on rank 0, every rank exits non-zero."""

    def __init__(self, message: str, code: int = 1):
        super().__init__(message)
        self.code = code


class HelpShown(Exception):
    """``--help`` (or ``--version``) was answered: the command stops with ``code``."""

    def __init__(self, code: int):
        super().__init__(code)
        self.code = code


class CommandParser(argparse.ArgumentParser):
    """argparse that raises instead of exiting and prints only on rank ``rank``."""

    rank = 0

    def error(self, message):
        """Raise ``UsageError`` with argparse's one-line message (exit code 2)."""
        raise UsageError(f"{message} (see --help)", code=2)

    def exit(self, status=0, message=None):
        """Print ``message`` (help, version) and stop the command with ``status``."""
        if message:
            self._print_message(message, sys.stderr)
        raise HelpShown(status)

    def _print_message(self, message, file=None):
        if self.rank == 0:
            super()._print_message(message, file)


def input_command_parser(prog: str, description: str, rank: int, name: str, metavar: str,
                         what: str) -> CommandParser:
    """The parser of a command that runs one input file into one output file: the input
    (positional ``name``) and the output options (``add_output_options``)."""
    p = CommandParser(prog=prog, description=description)
    p.rank = rank
    p.add_argument(name, metavar=metavar, help=what)
    add_output_options(p)
    return p


def add_output_options(p: argparse.ArgumentParser, progress_interval: float = 10.0) -> None:
    """The options of a run into one file: ``--out``, ``--backend``, ``--resume``,
    ``--overwrite``, ``--progress-interval``, ``--quiet``."""
    p.add_argument("--out", required=True, metavar="FILE.h5", help="output HDF5 file")
    p.add_argument("--backend", choices=BACKENDS, default=None,
                   help=f"tilt backend, one of {{{', '.join(BACKENDS)}}} (default "
                        f"{DEFAULT_BACKEND}; with --resume, the file's)")
    p.add_argument("--resume", action="store_true",
                   help="complete the missing rows of --out (the options given must agree with "
                        "the file)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    p.add_argument("--progress-interval", type=float, default=progress_interval, metavar="S",
                   help="seconds between progress lines on rank 0 (0: one per row; default "
                        f"{progress_interval:g} s)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def add_storage_option(p: argparse.ArgumentParser) -> None:
    """``--storage``: the file writer (parallel h5py, rows gathered to rank 0, or auto)."""
    p.add_argument("--storage", choices=STORAGES, default="auto",
                   help=f"file writer, one of {{{', '.join(STORAGES)}}}: parallel h5py (mpio), "
                        "rows gathered to rank 0 (gather), or auto: mpio with several ranks when "
                        "h5py has MPI (default auto)")


def check_run_options(args, comm, have_mpi: bool) -> str:
    """The options every run shares (--resume/--overwrite, --progress-interval,
    --storage), checked; returns the storage to use."""
    if args.resume and args.overwrite:
        raise UsageError("--resume and --overwrite exclude each other", code=2)
    if not args.progress_interval >= 0:
        raise UsageError(f"--progress-interval={args.progress_interval} must be >= 0", code=2)
    try:
        return choose_storage(args.storage, comm.size, have_mpi)
    except StorageError as exc:
        raise UsageError(str(exc)) from None


def check_new_or_resume(args) -> bool:
    """Rank 0, holding the claim: True to resume ``--out``, False to start it; an existing
    file without ``--resume`` or ``--overwrite`` is refused."""
    exists = os.path.exists(args.out)
    if exists and not (args.overwrite or args.resume):
        raise UsageError(f"--out {args.out!r} exists; pass --resume to complete it or "
                         "--overwrite to replace it")
    return bool(args.resume and exists)


def resume_header(args, read_header):
    """Rank 0, holding the claim: ``read_header(args.out)`` when ``--out`` is resumed (a file
    that cannot be resumed is a UsageError in one line), None when it is started."""
    if not check_new_or_resume(args):
        return None
    try:
        return read_header(args.out)
    except StorageError as exc:
        raise UsageError(f"--resume: {exc}") from None


def claim_output(args, program: str):
    """Rank 0, before anything is created or read: the claim on ``args.out`` (an
    ``io.filelock.OutputClaim``, held to the end); ``program`` names the command."""
    check_output(args.out, overwrite=True)  # a writable file path (existence checked later)
    if is_special(args.out):
        raise UsageError(f"--out {args.out!r} is not a regular file (a device or a fifo): the "
                         f"{program} file is written in place and resumed; give a file path")
    claim = OutputClaim(args.out).acquire()
    if not claim.locking:
        if args.overwrite:
            claim.release()
            raise UsageError(f"--out {args.out!r}: this file system does not support file locks, "
                             "so a concurrent writer could not be detected; --overwrite is "
                             "refused there (delete the file first, or write elsewhere)")
        sys.stderr.write(f"{program}: warning: no file locks on the file system of {args.out!r}; "
                         "a concurrent writer would not be detected\n")
    elif claim.previous_holder and not args.quiet:
        sys.stderr.write(f"{program}: note: {args.out} was held by {claim.previous_holder}, which "
                         "is no longer running; its stale claim is taken over\n")
    if claim.leftovers:
        sys.stderr.write(f"{program}: note: {leftovers_note(claim.leftovers)}\n")
    return claim


def read_input(path, what: str, limit: int = MAX_INPUT_BYTES) -> bytes:
    """The bytes of an input file (rank 0 reads, the others receive them); a missing,
    unreadable or oversized file raises ``UsageError`` naming it (exit 2).  A pipe is
    read like a file (at most ``limit`` + 1 bytes: a device that never ends is refused)."""
    where = f"{what} {os.fspath(path)!r}"
    try:
        with open(path, "rb") as fh:
            data = fh.read(limit + 1)
    except FileNotFoundError:
        raise UsageError(f"{where} does not exist", code=2) from None
    except IsADirectoryError:
        raise UsageError(f"{where} is a folder, not a file", code=2) from None
    except OSError as exc:
        raise UsageError(f"{where} cannot be read ({exc.strerror})", code=2) from None
    if len(data) > limit:
        raise UsageError(f"{where} is larger than {limit} bytes; an input file is a few lines",
                         code=2)
    return data


@dataclass
class RunPlan:
    """What rank 0 decided, holding the claim on the output, and every rank runs.

    Attributes
    ----------
    layout : the file's layout (``io.storage.Layout`` or a study's or prior's kin)
    backend : str
        The tilt backend (the file's with ``--resume``).
    resume : bool
        True to complete an existing file, False to create it.
    done : numpy.ndarray
        One flag per row of the file: already computed (and intact).
    pending : numpy.ndarray
        The rows to compute, in the order to serve them.
    scene : Scene, optional
        The ensemble's scene (the file's with ``--resume``).
    """

    layout: Any
    backend: str
    resume: bool
    done: np.ndarray
    pending: np.ndarray
    scene: Any = None

    @property
    def total(self) -> int:
        """Rows in the file."""
        return int(self.done.size)


@dataclass(frozen=True)
class RunCommand:
    """One run command, as ``run_planned`` drives it (see the module doc).

    Attributes
    ----------
    name : str
        The first word of its messages ("ensemble", "study", "prior").
    make_parser : callable
        ``rank`` -> the parser (help and errors printed by rank 0 only).
    prepare : callable
        ``(args, inputs, world)`` -> the command's own value: every rank's local
        checks; ``inputs`` maps the input file's path to rank 0's bytes.
    plan : callable
        ``(args, local)`` -> ``RunPlan``: rank 0, holding the claim on ``--out``.
    run : callable
        ``(comm, args, local, plan)`` -> exit code: every rank.
    input_option : (str, str), optional
        The destination of the option naming the input file, and what it is.
    """

    name: str
    make_parser: Callable
    prepare: Callable
    plan: Callable
    run: Callable
    input_option: tuple[str, str] | None = None

    def input_paths(self, args) -> dict[str, str]:
        """The input files rank 0 reads: {path: what it is, for messages}."""
        if self.input_option is None:
            return {}
        dest, what = self.input_option
        path = getattr(args, dest)
        return {path: what} if path else {}


@dataclass
class World:
    """The communicator and what every rank knows of it before planning."""

    comm: Any
    have_mpi: bool
    node_ranks: int  # ranks on this node, whose memory adds up


def world_or_none():
    """``(comm, have_mpi)``; None under a launcher without a working mpi4py, after one
    line from its rank 0 (every rank then exits non-zero: never a hang)."""
    try:
        return get_comm()
    except MPIUnavailable as exc:
        if launcher_rank() == 0:
            sys.stderr.write(error_line(str(exc)) + "\n")
        return None


def _failure(exc: BaseException) -> tuple[int, str]:
    """The (exit code, one line) of a failure of local work."""
    if isinstance(exc, HelpShown):
        return exc.code, ""
    if isinstance(exc, UsageError):
        return exc.code, str(exc)
    if isinstance(exc, KeyboardInterrupt):
        sig = StopFlag.signum or signal.SIGINT
        return 128 + sig, f"interrupted ({signal.Signals(sig).name}) while planning; nothing written"
    if isinstance(exc, (SceneError, StudyError)):  # a bad scene or study: bad input
        return 2, str(exc)
    if isinstance(exc, (ValueError, OSError)):
        return 1, str(exc)
    return 1, f"{type(exc).__name__}: {exc}"


def local_step(work, failed=None):
    """``(work(), None)`` or ``(failed, (exit code, line))``: every failure of ``work``, Ctrl-C
    included, caught so that the rank goes on to the next collective step."""
    try:
        with StopFlag.interruptible():
            return work(), None
    except BaseException as exc:  # noqa: BLE001 - every failure must reach every rank
        return failed, _failure(exc)


def agree(comm, err, claims: list) -> int | None:
    """Collective: None when no rank failed, else the first failure's exit code (rank 0
    prints its line; the claims are released).  A signal received since the last step
    counts as a failure of this rank."""

    if err is None and StopFlag.signum is not None:
        err = _failure(KeyboardInterrupt())
    errors = comm.allgather(err)
    first = next((e for e in errors if e is not None), None)
    if first is None:
        return None
    for claim in claims:
        claim.release()
    code, message = first
    if comm.rank == 0 and message:
        sys.stderr.write(error_line(message) + "\n")
        sys.stderr.flush()
    return code


def run_planned(command: RunCommand, argv: list[str] | None = None) -> int:
    """Run ``command`` over the ranks in agreement rounds (the module doc); the exit code.

    The output claims are released after the run: the next writer finds the
    file complete.  SIGINT and SIGTERM are handled by ``signals.StopFlag``
    from the start: a signal on any rank reaches every rank at the next step.
    """
    got = world_or_none()
    if got is None:
        return 1
    comm, have_mpi = got
    world = World(comm, have_mpi, ranks_on_this_node(comm))  # collective, before any failure
    return stopped_job_status(comm, _run_rounds(command, argv, comm, world))


def _run_rounds(command: RunCommand, argv, comm, world) -> int:
    """``run_planned``'s agreement rounds on ``comm``: the exit code of every rank."""
    claims: list = []
    with StopFlag.installed():
        # 1. the command line (every rank) and the inputs (rank 0's bytes, to every rank)
        def read():
            args = command.make_parser(comm.rank).parse_args(argv)
            paths = command.input_paths(args)
            data = ({p: read_input(p, what) for p, what in paths.items()} if comm.rank == 0
                    else None)
            return args, data

        (args, data), err = local_step(read, (None, None))
        shared = comm.allgather((err, data))
        err = err or next((e for e, _ in shared if e is not None), None)
        code = agree(comm, err, claims)
        if code is not None:
            return code
        inputs = shared[0][1]

        # 2. the checks (every rank), the claim and the plan (rank 0)
        def prepare():
            local = command.prepare(args, inputs, world)
            if comm.rank != 0:
                return local, None
            claims.append(claim_output(args, command.name))
            return local, command.plan(args, local)

        (local, plan), err = local_step(prepare, (None, None))
        code = agree(comm, err, claims)
        if code is not None:
            return code
        # 3. the run
        plan = comm.bcast(plan, root=0)
        try:
            return command.run(comm, args, local, plan)
        finally:
            for claim in claims:
                claim.release()  # after the file is closed: the next writer finds it complete


def open_output(comm, args, plan: RunPlan, handlers: dict, storage: str, describe=None):
    """Create (or open, to resume) ``args.out`` on every rank; the open handler, or None after
    one line (every rank then returns 1, or the run is aborted when a collective call failed).

    ``describe(path)`` (rank 0, between create and open) adds the file's xarray
    description; it returns True or the reason it failed.  A created file's
    identity joins rank 0's claim (``OutputClaim.bind``).
    """
    rank = comm.rank
    handler = err = None
    try:
        cls = handlers[storage]
        if not plan.resume:
            cls.create(args.out, plan.layout, comm, overwrite=args.overwrite).close()
        if rank == 0 and claim_of(args.out) is not None:
            claim_of(args.out).bind()
        if describe is not None:
            described = describe(args.out) if rank == 0 else None
            if comm.bcast(described, root=0) is not True:
                raise StorageError(f"cannot describe the file: {described}")
        handler = cls.open_for_resume(args.out, plan.layout, comm)
    except Exception as exc:  # noqa: BLE001 - reported on one rank, then every rank stops
        err = f"cannot {'open' if plan.resume else 'create'} {args.out!r}: {os_reason(exc)}"
        if isinstance(exc, CollectiveFailure):  # other ranks may be inside the failed call
            abort(comm, error_line(f"rank {rank}: {err}"))
    errors = comm.allgather(err)
    if not any(errors):
        return handler
    if rank == next(i for i, e in enumerate(errors) if e):  # one line, from one rank
        sys.stderr.write(error_line(errors[rank]) + "\n")
        sys.stderr.flush()
    if not all(errors):
        abort(comm)  # some ranks hold a half-open collective file
    return None
