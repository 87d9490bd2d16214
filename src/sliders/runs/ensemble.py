"""``python -m sliders.ensemble``: many realisations of one scene over MPI ranks, one HDF5 file.

    mpirun -n 2 python -m sliders.ensemble --scene S.toml --realisations 100 --out E.h5
    python -m sliders.ensemble --n-sliders 10 --realisations 4 --out E.h5   # serial

Realisation ``r`` is the scene with seed ``realisation_seed(scene.seed, r)``;
its row of the file (``storage`` module) depends on nothing else, so the file
is the same (bit for bit, apart from wall times and the creation date) with 1,
2 or 4 ranks.

Scheduling (dynamic): rank 0 hands out realisation indices on request and
computes realisations itself.  It answers requests between chunks of events
of its own run (the driver's progress callback), so no rank sits idle as a
dedicated master.  Every other rank keeps ``PREFETCH`` requests ahead of the
realisation it computes, so the answers are there when it finishes; near the
end rank 0 declines requests made ahead, so that no rank holds unstarted work
while another runs out.

Storage: ``storage.MpioFile`` (parallel h5py, every rank writes its own rows)
or ``storage.GatherFile`` (rows shipped to rank 0 with the "done" message);
``--storage auto`` picks mpio with several ranks when h5py has MPI.

Interruption: SIGTERM/SIGINT on any rank stops the whole run at the next safe
point (between chunks of events): runs in progress are dropped, rows already
written stay, the file is closed, rank 0 prints one line and every rank exits
with 128 + signal number.  ``--resume`` then computes the missing rows only.

Ensemble statistics are not stored: ``load_summary(path)`` derives them with
``observables.combine`` from the rows marked done.

Test hooks (environment variables, for the test suite only):
``SLIDERS_ENSEMBLE_STOP_AFTER=K``: rank 0 behaves as if it received SIGTERM
once K realisations have been completed in this session.
``SLIDERS_ENSEMBLE_TEST_DELAY=S``: every realisation starts with a sleep of S
seconds (so that a test can signal or kill a run that is still going).
``SLIDERS_ENSEMBLE_TEST_FAIL=r``: realisation r raises RuntimeError (an
unexpected failure on one rank mid-run).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from collections import Counter, deque
from typing import Any

import numpy as np

from .. import status as status_codes
from .merge import chunk_range, parse_chunk
from .parallel import MPIUnavailable, SerialComm, abort, get_comm, launcher_rank  # noqa: F401 - MPI optional
from ..analysis.summary import load_summary  # noqa: F401 - the readers, kept importable here
from ..io.storage import read_realisations  # noqa: F401
from ..scene import BACKENDS, Scene, SceneError

TAG_MSG, TAG_REPLY, TAG_CTRL = 71, 72, 73
NO_MORE, DECLINED = -1, -2  # replies to a request for an index
PREFETCH = 2  # indices a worker asks for ahead of the one it is computing
DEFAULT_BACKEND = "fortran"
STATUS_CODES = {name: code for code, name in status_codes.NAMES.items()}
UNKNOWN_STATUS = -2


class UsageError(Exception):
    """A bad command line or input: one line on rank 0, every rank exits non-zero."""

    def __init__(self, message: str, code: int = 1):
        super().__init__(message)
        self.code = code


class _HelpExit(Exception):
    def __init__(self, code: int):
        self.code = code


class Interrupted(Exception):
    """Raised at a safe point once the run has to stop (signal or abort from rank 0)."""


# ---------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    """argparse that raises instead of exiting and prints only on rank 0."""

    rank = 0

    def error(self, message):
        """Raise ``UsageError`` with argparse's one-line message (exit code 2)."""
        raise UsageError(f"{message} (see --help)", code=2)

    def exit(self, status=0, message=None):
        """Print ``message`` (help, version) and stop the command with ``status``."""
        if message:
            self._print_message(message, sys.stderr)
        raise _HelpExit(status)

    def _print_message(self, message, file=None):
        if self.rank == 0:
            super()._print_message(message, file)


def build_parser(rank: int = 0) -> argparse.ArgumentParser:
    """The command line of ``python -m sliders.ensemble`` (only ``rank`` 0 prints help and errors)."""
    from .cli import add_scene_arguments
    from ..io.storage import STORAGES

    p = _Parser(
        prog="python -m sliders.ensemble",
        description="Tilt R realisations of one scene (seed of realisation r = "
                    "realisation_seed(scene seed, r)), spread over MPI ranks with dynamic load "
                    "balancing, into one HDF5 file (one row per realisation).  Run under "
                    "`mpirun -n P` or plainly (serial).",
    )
    p.rank = rank
    add_scene_arguments(p)
    g = p.add_argument_group("ensemble")
    g.add_argument("--realisations", "-R", type=int, metavar="R",
                   help="number of realisations (required unless --resume, which takes the file's)")
    g.add_argument("--out", required=True, metavar="FILE.h5", help="output HDF5 file")
    g.add_argument("--backend", choices=BACKENDS, default=None,
                   help="tilt backend (default fortran; with --resume, the file's)")
    g.add_argument("--resume", action="store_true",
                   help="complete the missing realisations of an existing file: the scene, seed, "
                        "count and backend come from the file (options given must agree with it)")
    g.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    g.add_argument("--storage", choices=STORAGES, default="auto",
                   help="file writer: parallel h5py (mpio), rows gathered to rank 0 (gather), or "
                        "auto: mpio with several ranks when h5py has MPI (default)")
    g.add_argument("--progress-interval", type=float, default=5.0, metavar="S",
                   help="seconds between progress lines on stderr (0: after every realisation)")
    g.add_argument("--quiet", action="store_true", help="no progress lines")
    g.add_argument("--chunk", type=parse_chunk, metavar="I/K",
                   help="compute only chunk I (0..K-1) of K of the R realisations (rows "
                        "I*R//K to (I+1)*R//K - 1, same seeds as in the whole run), e.g. one task "
                        "of a job array; `python -m sliders.merge` joins the chunk files")
    return p


def check_run_options(args, comm, have_mpi: bool) -> str:
    """The options an ensemble and a study share (--resume/--overwrite,
    --progress-interval, --storage), checked; returns the storage to use."""
    from ..io.storage import StorageError, choose_storage

    if args.resume and args.overwrite:
        raise UsageError("--resume and --overwrite exclude each other", code=2)
    if args.progress_interval < 0:
        raise UsageError(f"--progress-interval={args.progress_interval} must be >= 0")
    try:
        return choose_storage(args.storage, comm.size, have_mpi)
    except StorageError as exc:
        raise UsageError(str(exc)) from None


def _plan(args, comm, have_mpi: bool, node_ranks: int = 1) -> dict[str, Any]:
    """Validate everything that can be checked locally (every rank, same answer);
    ``node_ranks``: ranks on this node, whose memory adds up."""
    from .cli import scene_from_args

    scene = scene_from_args(args)
    if args.realisations is not None and args.realisations < 1:
        raise UsageError(f"--realisations={args.realisations} must be at least 1")
    if args.realisations is None and not args.resume:
        raise UsageError("--realisations R is required (unless --resume)", code=2)
    if args.chunk is not None and args.realisations is None:
        raise UsageError("--chunk I/K needs --realisations R (the whole ensemble's)", code=2)
    storage = check_run_options(args, comm, have_mpi)
    from ..driver import make_engine

    backend = args.backend or DEFAULT_BACKEND
    try:
        make_engine(scene, backend)
    except (ImportError, AttributeError) as exc:  # not built, or built from older sources
        raise UsageError(f"backend {backend!r} is not available ({exc}); "
                         "build it (scripts/setup.sh) or use --backend numpy") from None
    from ..scene import check_memory, check_tilt_statistics

    check_tilt_statistics(scene)
    check_memory(scene, node_ranks)
    return {"scene": scene, "storage": storage}


def _claim_output(args, program: str = "ensemble"):
    """Rank 0, before anything is created or read: the claim on --out (held to the end);
    ``program`` ("ensemble", "study") names the command in its messages."""
    from .cli import check_output
    from ..io.filelock import OutputClaim
    from ..io.safeio import is_special

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
        from ..io.safeio import leftovers_note

        sys.stderr.write(f"{program}: note: {leftovers_note(claim.leftovers)}\n")
    return claim


def _plan_root(args, plan) -> dict[str, Any]:
    """Rank 0 (holding the claim on --out): output file checks, resume compatibility, the
    scene and backend (the file's with --resume), the layout."""
    from .cli import disagreements, given_scene_values
    from ..keyed_random import realisation_seed
    from ..analysis.observables import default_grids, statistics_layout
    from ..io.storage import (StorageError, check_room, damaged_rows, file_attributes, make_layout,
                              read_header, statistics_row_bytes)

    scene: Scene = plan["scene"]
    backend = args.backend or DEFAULT_BACKEND
    out = args.out
    resume = args.resume and os.path.exists(out)
    if os.path.exists(out) and not (args.overwrite or resume):
        raise UsageError(f"--out {out!r} exists; pass --resume to complete it or --overwrite "
                         "to replace it")
    R = args.realisations
    first = 0  # index of the file's first realisation (a chunk of a larger ensemble)
    if args.chunk is not None:
        first, R = chunk_range(args.chunk, R)
    if R is None and not resume:
        raise UsageError(f"--resume: {out!r} does not exist; give --realisations R to start it")
    done = None
    if resume:
        try:
            head = read_header(out)
        except StorageError as exc:
            raise UsageError(f"--resume: {exc}") from None
        attrs = head["attrs"]
        try:
            file_scene = Scene.from_dict(json.loads(attrs["scene"]))
        except (SceneError, ValueError, KeyError) as exc:
            raise UsageError(f"--resume: {out!r} holds an unreadable scene ({exc})") from None
        try:
            differ = disagreements(file_scene, given_scene_values(args))
        except SceneError as exc:
            raise UsageError(f"--resume: {exc}") from None
        if differ:
            raise UsageError(f"--resume: {out!r} holds a different scene ({differ}); give no "
                             "scene options with --resume, or ones that agree with the file")
        scene = file_scene
        if R is not None and R != attrs["realisations"]:
            raise UsageError(f"--resume: {out!r} has {attrs['realisations']} realisations, "
                             f"--realisations {R} requested")
        if args.backend is not None and attrs["backend"] != args.backend:
            raise UsageError(f"--resume: {out!r} was computed with --backend {attrs['backend']}, "
                             f"not {args.backend}; resume with the same backend")
        backend = attrs["backend"]
        R = int(attrs["realisations"])
        if args.chunk is not None and first != attrs.get("first_realisation", 0):
            raise UsageError(f"--resume: {out!r} starts at realisation "
                             f"{attrs.get('first_realisation', 0)}, chunk {args.chunk[0]}/"
                             f"{args.chunk[1]} at {first}")
        first = int(attrs.get("first_realisation", 0))
    # record = "summary": the per-realisation summary only (no displacements, no statistics)
    stats = {} if scene.record == "summary" else statistics_layout(default_grids(scene),
                                                                   scene.n_sliders)
    if not resume:  # before any per-row array: an absurd count is refused at once
        try:
            check_room(out, R, statistics_row_bytes(stats))
        except StorageError as exc:
            raise UsageError(f"--realisations {R}: {exc}") from None
    grids = default_grids(scene).to_arrays()
    if resume:
        for k, v in grids.items():
            if k not in head["grids"] or not np.array_equal(head["grids"][k], v):
                raise UsageError(f"--resume: the statistics grid {k!r} of {out!r} differs from "
                                 "this version's; start a new file")
        done = head["done"]
        try:
            damaged = damaged_rows(out)
        except StorageError as exc:
            raise UsageError(f"--resume: {exc}") from None
        if damaged:  # recomputed like the missing ones (keyed seeds: the same values)
            done[damaged] = False
            sys.stderr.write(f"ensemble: note: {len(damaged)} finished row(s) of {out} fail "
                             f"their checksums (rows {damaged[:10]}); recomputing them\n")
        file_attrs = attrs
    else:
        file_attrs = file_attributes(scene.to_dict(), scene.seed, R, backend)
        file_attrs["first_realisation"] = first
    seeds = np.array([realisation_seed(scene.seed, first + r) for r in range(R)], dtype=np.uint32)
    layout = make_layout(R, seeds, grids, stats, file_attrs)
    if resume:
        cols = head["columns"]
        for c in layout.columns:
            if c.name not in cols or tuple(cols[c.name][0]) != c.shape:
                raise UsageError(f"--resume: {out!r} has no dataset /realisations/{c.name} of shape "
                                 f"(R, *{c.shape}); it was written by another version of sliders")
        if not np.array_equal(head["seeds"], seeds):
            raise UsageError(f"--resume: the seeds of {out!r} differ from this version's")
    if done is None:
        done = np.zeros(R, dtype=bool)
    return {"layout": layout, "resume": resume, "done": done, "scene": scene, "backend": backend}


# ---------------------------------------------------------------------------
# one realisation
# ---------------------------------------------------------------------------
def compute_row(scene: Scene, r: int, backend: str, grids, progress=None,
                first: int = 0, extra_statistics=None) -> dict[str, Any]:
    """Row ``r`` of a file starting at realisation ``first``: realisation ``first + r`` of the
    scene (base columns + statistics/<key>).  ``extra_statistics(result)`` -> {key: value}
    adds statistics of the caller's own (a study's burst periods and synchronisation)."""
    from ..driver import realisation_scene
    from ..io.storage import STATISTICS
    from ..analysis.observables import realisation_statistics

    started = time.perf_counter()
    delay = os.environ.get("SLIDERS_ENSEMBLE_TEST_DELAY")
    if delay:
        time.sleep(float(delay))
        if progress is not None:
            progress(None)
    if os.environ.get("SLIDERS_ENSEMBLE_TEST_FAIL") == str(r):
        raise RuntimeError(f"test hook SLIDERS_ENSEMBLE_TEST_FAIL: realisation {r} fails")
    result = _tilt_interruptibly(realisation_scene(scene, first + r),
                                 backend, progress)
    stats = {} if scene.record == "summary" else realisation_statistics(result, grids)
    if extra_statistics is not None:
        stats.update(extra_statistics(result))
    row: dict[str, Any] = {
        "status": STATUS_CODES.get(result.status, UNKNOWN_STATUS),
        "alpha_c": float(result.alpha_c),
        "n_events": int(result.n_events),
        "slider_steps": int(result.total_slider_steps),  # the avalanche event included
    }
    row.update({STATISTICS + k: v for k, v in stats.items()})
    row["wall_time"] = time.perf_counter() - started
    return row


def _compute(ctx: dict, r: int, progress) -> dict[str, Any]:
    """Row ``r`` of the run: ``ctx["compute_row"](r, progress)`` when the caller schedules its
    own tasks (a study: row = one (point, realisation) pair), else realisation r of the scene."""
    task = ctx.get("compute_row")
    if task is not None:
        return task(r, progress)
    return compute_row(ctx["scene"], r, ctx["backend"], ctx["grids"], progress, ctx["first"])


# ---------------------------------------------------------------------------
# the run: rank 0 (hands out indices, computes, reports) and the other ranks
# ---------------------------------------------------------------------------
class _Stop:
    """Signal flag (set by the handler, acted on at safe points).

    While a realisation is being computed (``computing``: inside ``tilt``,
    outside the progress callbacks, which talk MPI) no file or message is in
    flight, so the handler also raises KeyboardInterrupt there: the kernel
    stops within its interrupt latency instead of at the end of its chunk,
    and the unfinished realisation is dropped.
    """

    signum: int | None = None
    computing = False

    @classmethod
    def handler(cls, signum, frame):
        """Signal handler: remember the first signal; interrupt the kernel if it is computing."""
        if cls.signum is None:
            cls.signum = signum
        if cls.computing:
            cls.computing = False
            raise KeyboardInterrupt


def _tilt_interruptibly(scene: Scene, backend: str, progress, **options):
    """``tilt`` with ``_Stop.computing`` set except inside the progress callback
    (``options``: more of ``tilt``'s keywords, such as ``state``)."""
    from ..driver import tilt

    def callback(p):
        _Stop.computing = False
        try:
            if progress is not None:
                progress(p)
        finally:
            _Stop.computing = True

    _Stop.computing = True
    try:
        if _Stop.signum is not None:  # arrived just before
            raise Interrupted()
        return tilt(scene, backend=backend, progress=callback, **options)
    except KeyboardInterrupt:  # also when the kernel caught the signal itself: stop the run
        if _Stop.signum is None:
            _Stop.signum = signal.SIGINT
        raise
    finally:
        _Stop.computing = False


def _fmt_time(s: float) -> str:
    if not math.isfinite(s):
        return "?"
    if s < 120:
        return f"{s:.1f} s" if s < 10 else f"{s:.0f} s"
    s = int(round(s))
    if s < 7200:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {(s % 3600) // 60:02d} min"


class _Root:
    """Rank 0: serve requests, compute, write (gather), report progress."""

    def __init__(self, comm, handler, pending, n_done_before, ctx):
        self.comm = comm
        self.handler = handler
        self.queue = deque(int(r) for r in pending)
        self.total = ctx["R"]
        self.done_before = n_done_before
        self.done_now = 0
        self.ctx = ctx
        self.alive = set(range(1, comm.size))
        self.ctrl_sent: set[int] = set()
        self.sends: list = []
        self.stop_reason: str | None = None
        self.signum: int | None = None
        self.statuses: Counter = Counter()
        self.started = time.monotonic()
        self.last_report = self.started
        self.timing = {"compute": 0.0, "idle": 0.0}
        self.n_needs = 0
        stop_after = os.environ.get("SLIDERS_ENSEMBLE_STOP_AFTER")
        self.stop_after = int(stop_after) if stop_after else None
        if comm.size > 1:
            from mpi4py import MPI

            self._status = MPI.Status()
            self._any = MPI.ANY_SOURCE

    # -- messages ----------------------------------------------------------
    def _reply(self, dest: int, ahead: bool) -> None:
        """Next index for ``dest``; -1: no more work; -2: a prefetch declined near the end.

        A request made ahead (the worker still has work in hand) is declined
        once few indices are left, so that no rank sits on unstarted work
        while another one runs out.
        """
        if self.stop_reason or not self.queue:
            idx = NO_MORE
        elif ahead and len(self.queue) <= self.comm.size:
            idx = DECLINED
        else:
            idx = self.queue.popleft()
        self.sends.append(self.comm.isend(idx, dest=dest, tag=TAG_REPLY))
        if len(self.sends) > 256:  # keep only the sends still in flight
            self.sends = [q for q in self.sends if not q.Test()]

    def _handle(self, src: int, msg: tuple) -> None:
        kind = msg[0]
        if kind == "need":
            self.n_needs += 1
            self._reply(src, ahead=msg[1])
        elif kind == "done":
            _, r, ops, code = msg
            self.handler.apply(ops)
            self._completed(code)
        elif kind == "interrupted":
            self.stop(msg[1], msg[2])
        elif kind == "bye":
            self.alive.discard(src)
            if src not in self.ctrl_sent:
                self.ctrl_sent.add(src)
                self.sends.append(self.comm.isend("final", dest=src, tag=TAG_CTRL))
        else:  # pragma: no cover - protocol bug
            raise RuntimeError(f"unknown message {kind!r} from rank {src}")

    def service(self) -> bool:
        """Handle every waiting message; True if there was one."""
        if self.comm.size == 1:
            return False
        got = False
        while self.comm.Iprobe(source=self._any, tag=TAG_MSG, status=self._status):
            src = self._status.Get_source()
            self._handle(src, self.comm.recv(source=src, tag=TAG_MSG))
            got = True
        return got

    def stop(self, reason: str, signum: int | None) -> None:
        """Stop handing out rows (first reason kept) and tell every live worker to stop after its row."""
        if self.stop_reason is None:
            self.stop_reason, self.signum = reason, signum
            for w in sorted(self.alive - self.ctrl_sent):
                self.ctrl_sent.add(w)
                self.sends.append(self.comm.isend("abort", dest=w, tag=TAG_CTRL))

    def _check_stop(self) -> None:
        if _Stop.signum is not None:
            sig = _Stop.signum
            self.stop(f"{signal.Signals(sig).name} on rank 0", sig)
        elif self.stop_after is not None and self.done_now >= self.stop_after:
            self.stop(f"test hook SLIDERS_ENSEMBLE_STOP_AFTER={self.stop_after}", signal.SIGTERM)

    # -- progress ----------------------------------------------------------
    def _completed(self, code: int) -> None:
        self.done_now += 1
        self.statuses[status_codes.NAMES.get(code, "unknown")] += 1
        self._check_stop()
        self.report(force=self.ctx["interval"] == 0)

    def report(self, force: bool = False) -> None:
        """Print one progress line (rows done, rate, estimated time left) at most every interval."""
        if self.ctx["quiet"]:
            return
        now = time.monotonic()
        interval = self.ctx["interval"]
        if not force and (interval == 0 or now - self.last_report < interval):
            return
        self.last_report = now
        elapsed = now - self.started
        done = self.done_before + self.done_now
        rate = self.done_now / elapsed if elapsed > 0 else math.nan
        left = self.total - done
        eta = left / rate if rate > 0 else math.inf
        label, unit = self.ctx.get("label", ("ensemble", "realisations"))  # a study: its rows
        sys.stderr.write(f"{label}: {done}/{self.total} {unit} done, "
                         f"{rate:.3g}/s, elapsed {_fmt_time(elapsed)}, ETA {_fmt_time(eta)}\n")
        sys.stderr.flush()

    def poll(self, _progress=None) -> None:
        """Progress callback of rank 0's own runs: serve, report, stop if asked."""
        self.service()
        self._check_stop()
        self.report()
        if self.stop_reason:
            raise Interrupted(self.stop_reason)

    # -- main loop ---------------------------------------------------------
    def run(self) -> None:
        """Serve rows to the workers until every row is done or the run is stopped; write as they come."""
        ctx = self.ctx
        # first request of every worker, so that all ranks start at once
        for _ in range(len(self.alive)):
            src = None
            while src is None:
                if self.comm.Iprobe(source=self._any, tag=TAG_MSG, status=self._status):
                    src = self._status.Get_source()
                else:
                    time.sleep(0.001)
            self._handle(src, self.comm.recv(source=src, tag=TAG_MSG))
        # ... and their first requests ahead (sent as soon as they have an index)
        deadline = time.monotonic() + 0.2
        while self.n_needs < len(self.alive) * (1 + PREFETCH) and time.monotonic() < deadline:
            if not self.service():
                time.sleep(0.001)
        while self.queue and not self.stop_reason:
            r = self.queue.popleft()
            t0 = time.perf_counter()
            try:
                row = _compute(ctx, r, self.poll)
            except (Interrupted, KeyboardInterrupt):  # the signal stops the run below
                break
            finally:
                self.timing["compute"] += time.perf_counter() - t0
            self.handler.write_row(r, row)
            self.handler.mark_done(r)
            self.handler.flush()
            self._completed(row["status"])
            self.service()
        t0 = time.perf_counter()
        while self.alive:  # serve the other ranks until they have all finished
            self._check_stop()
            if not self.service():
                self.report()
                time.sleep(0.002)
        self.timing["idle"] += time.perf_counter() - t0
        if self.sends:
            from mpi4py import MPI

            MPI.Request.Waitall(self.sends)


def _worker(comm, handler, ctx) -> dict[str, float]:
    """Ranks > 0: ask for indices, compute them, write (or ship) their rows.

    Besides the index being computed, up to ``PREFETCH`` requests are kept
    ahead, so that the answers (given by rank 0 between chunks of its own
    events) are there when needed.  Returns the time spent computing and
    waiting for indices.
    """
    from mpi4py import MPI

    ctrl: list[str] = []
    timing = {"compute": 0.0, "idle": 0.0}

    def check(_progress=None):
        if not ctrl and comm.Iprobe(source=0, tag=TAG_CTRL):
            ctrl.append(comm.recv(source=0, tag=TAG_CTRL))
        if _Stop.signum is not None or (ctrl and ctrl[0] == "abort"):
            raise Interrupted()

    held: deque[int] = deque()  # indices received, not started
    pending: deque = deque()  # requests sent, answers not read
    exhausted = False
    sends = []

    def ask(ahead: bool) -> None:
        comm.send(("need", ahead), dest=0, tag=TAG_MSG)
        pending.append(comm.irecv(source=0, tag=TAG_REPLY))

    def take(block: bool) -> None:
        """Read the answers that are there (all of them, in order, if ``block``)."""
        nonlocal exhausted
        while pending:
            if block:
                t0 = time.perf_counter()
                value = pending[0].wait()
                timing["idle"] += time.perf_counter() - t0
            else:
                done, value = pending[0].test()
                if not done:
                    return
            pending.popleft()
            if value >= 0:
                held.append(value)
            elif value == NO_MORE:
                exhausted = True

    def next_index() -> int | None:
        take(block=False)
        if not held and pending:
            take(block=True)
        if not held and not exhausted:
            ask(ahead=False)
            take(block=True)
        return held.popleft() if held else None

    r = next_index()
    try:
        while r is not None:
            check()
            while not exhausted and len(held) + len(pending) < PREFETCH:
                ask(ahead=True)
            t0 = time.perf_counter()
            try:
                row = _compute(ctx, r, check)
            finally:
                timing["compute"] += time.perf_counter() - t0
            handler.write_row(r, row)
            handler.mark_done(r)
            handler.flush()
            sends.append(comm.isend(("done", r, handler.outbox(), row["status"]), dest=0,
                                    tag=TAG_MSG))
            r = next_index()
    except (Interrupted, KeyboardInterrupt):
        pass
    take(block=True)  # every request gets its answer before the end
    if _Stop.signum is not None:
        sig = _Stop.signum
        comm.send(("interrupted", f"{signal.Signals(sig).name} on rank {comm.rank}", sig),
                  dest=0, tag=TAG_MSG)
    MPI.Request.Waitall(sends)
    comm.send(("bye",), dest=0, tag=TAG_MSG)
    if not ctrl:
        ctrl.append(comm.recv(source=0, tag=TAG_CTRL))
    return timing


# ---------------------------------------------------------------------------
# main
# ---------------------------------------------------------------------------
def _error_line(message: str) -> str:
    return "error: " + " ".join(str(message).split())


def main(argv: list[str] | None = None) -> int:
    """Run ``python -m sliders.ensemble`` with ``argv``; returns the exit code (0: every realisation done)."""

    def prepare(comm, have_mpi, node_ranks, claims):
        args = build_parser(comm.rank).parse_args(argv)
        plan = _plan(args, comm, have_mpi, node_ranks)
        root_plan = None
        if comm.rank == 0:
            claims.append(_claim_output(args))
            root_plan = _plan_root(args, plan)
        return args, plan, root_plan

    return run_planned(prepare, lambda comm, args, plan, root_plan: _run(args, comm, plan, root_plan))


def run_planned(prepare, run) -> int:
    """The shape of every run command (ensemble, study, prior ensemble); the exit code.

    Sets up the world (one line and exit 1 without a working MPI), counts the
    ranks of this node (collective, before any rank can fail), runs
    ``prepare(comm, have_mpi, node_ranks, claims)`` on every rank and agrees
    on whether it failed anywhere (``agree_on_plan``), broadcasts rank 0's
    plan, then runs ``run(comm, *values, root_plan)``.  The output claims are
    released after ``run``: the next writer finds the file complete.

    Parameters
    ----------
    prepare : callable
        Parses and checks the command (no collective step); rank 0 appends
        its output claim to ``claims``.  Returns a tuple whose last item is
        rank 0's plan (None on the other ranks).
    run : callable
        Computes the rows; returns the exit code.
    """
    from .cli import ranks_on_this_node

    world = world_or_none()
    if world is None:
        return 1
    comm, have_mpi = world
    node_ranks = ranks_on_this_node(comm)  # collective, before any rank can fail
    claims: list = []
    code, planned = agree_on_plan(comm, lambda: prepare(comm, have_mpi, node_ranks, claims),
                                  claims)
    if code is not None:
        return code
    *values, root_plan = planned
    root_plan = comm.bcast(root_plan, root=0)
    try:
        return run(comm, *values, root_plan)
    finally:
        for claim in claims:
            claim.release()  # after the file is closed: the next writer finds it complete


def add_output_options(p: argparse.ArgumentParser) -> None:
    """The options of a run into one file that studies and prior ensembles share:
    ``--out``, ``--backend``, ``--resume``, ``--overwrite``, ``--progress-interval``, ``--quiet``."""
    from ..scene import BACKENDS

    p.add_argument("--out", required=True, metavar="FILE.h5", help="output HDF5 file")
    p.add_argument("--backend", choices=BACKENDS, default=None, help="tilt backend (default fortran)")
    p.add_argument("--resume", action="store_true", help="complete the missing rows of --out")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    p.add_argument("--progress-interval", type=float, default=10.0, metavar="S",
                   help="seconds between progress lines on rank 0 (0: one per row)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def world_or_none():
    """``(comm, have_mpi)``; None under a launcher without a working mpi4py, after one
    line from its rank 0 (every rank then exits non-zero: never a hang)."""
    try:
        return get_comm()
    except MPIUnavailable as exc:
        if launcher_rank() == 0:
            sys.stderr.write(_error_line(str(exc)) + "\n")
        return None


def agree_on_plan(comm, prepare, claims: list):
    """Run ``prepare()`` on every rank and agree on whether it failed anywhere.

    ``prepare`` takes no collective step and appends any output claim it
    takes to ``claims``.  Returns ``(None, its value)`` when every rank
    succeeded, else ``(exit code, None)``: rank 0 has printed the one-line
    reason and the claims are released.
    """
    err: tuple[int, str] | None = None
    value = None
    try:
        value = prepare()
    except _HelpExit as exc:
        err = (exc.code, "")
    except UsageError as exc:
        err = (exc.code, str(exc))
    except (SceneError, ValueError, OSError) as exc:
        err = (1, str(exc))
    except Exception as exc:  # noqa: BLE001 - any failure here must reach every rank
        err = (1, f"{type(exc).__name__}: {exc}")
    except BaseException:  # Ctrl-C while planning: no stale claim left behind
        for claim in claims:
            claim.release()
        raise
    errors = comm.allgather(err)
    first = next((e for e in errors if e is not None), None)
    if first is None:
        return None, value
    for claim in claims:
        claim.release()
    code, message = first
    if comm.rank == 0 and message:
        sys.stderr.write(_error_line(message) + "\n")
    return code, None


def _run(args, comm, plan, root_plan) -> int:
    """Steps 2-4 of ``main``, every rank, rank 0 holding the claim on --out."""
    rank = comm.rank

    # 2. create or open the file (collective for mpio)
    from ..analysis.observables import StatisticsGrids
    from ..io.conventions import describe_ensemble_file
    from ..io.safeio import os_reason
    from ..io.storage import HANDLERS, CollectiveFailure, StorageError

    layout = root_plan["layout"]
    scene: Scene = root_plan["scene"]
    backend = root_plan["backend"]
    storage = plan["storage"]
    handler = None
    err = None
    try:
        cls = HANDLERS[storage]
        if not root_plan["resume"]:
            cls.create(args.out, layout, comm, overwrite=args.overwrite).close()
        # named dimensions, units, provenance (even if the run is cut short): dimension scales
        # are serial HDF5, so rank 0 adds them between the collective create and open
        described = describe_ensemble_file(args.out) if rank == 0 else None
        if comm.bcast(described, root=0) is not True:
            raise StorageError(f"cannot describe the file: {described}")
        handler = cls.open_for_resume(args.out, layout, comm)
    except Exception as exc:  # noqa: BLE001
        err = (f"cannot {'open' if root_plan['resume'] else 'create'} {args.out!r}: "
               f"{os_reason(exc)}")
        if isinstance(exc, CollectiveFailure):  # other ranks may be inside the failed call
            abort(comm, _error_line(f"rank {rank}: {err}"))
    errors = comm.allgather(err)
    if any(errors):
        if rank == next(i for i, e in enumerate(errors) if e):  # one line, from one rank
            sys.stderr.write(_error_line(errors[rank]) + "\n")
            sys.stderr.flush()
        if all(errors):
            return 1
        abort(comm)  # some ranks hold a half-open collective file

    done = root_plan["done"]
    pending = np.flatnonzero(~done)
    ctx = {
        "scene": scene, "backend": backend, "R": layout.n_realisations,
        "first": int(layout.attrs.get("first_realisation", 0)),
        "grids": StatisticsGrids.from_arrays(layout.grids),
        "interval": args.progress_interval, "quiet": args.quiet,
    }
    if rank == 0 and not args.quiet and pending.size == 0:
        sys.stderr.write(f"ensemble: all {layout.n_realisations} realisations of {args.out} are "
                         "done already; nothing to do\n")
    elif rank == 0 and not args.quiet:
        verb = "resuming" if root_plan["resume"] else "starting"
        sys.stderr.write(
            f"ensemble: {verb} {pending.size} of {layout.n_realisations} realisations of "
            f"N={scene.n_sliders} xi={scene.xi:g} (backend {backend}) on {comm.size} "
            f"rank{'s' if comm.size > 1 else ''}, storage {storage} -> {args.out}\n")
        sys.stderr.flush()

    # 3. run
    old = {s: signal.signal(s, _Stop.handler) for s in (signal.SIGTERM, signal.SIGINT)}
    root = None
    timing = None
    try:
        if rank == 0:
            root = _Root(comm, handler, pending, int(done.sum()), ctx)
            root.run()
            timing = root.timing
        else:
            timing = _worker(comm, handler, ctx)
    except Exception as exc:  # noqa: BLE001 - a bug or a failed write: nothing may hang
        what = (f"cannot write {args.out!r}: {os_reason(exc)}" if isinstance(exc, OSError)
                else f"{type(exc).__name__}: {exc}")
        sys.stderr.write(_error_line(f"rank {rank}: {what}") + "\n")
        if os.environ.get("SLIDERS_DEBUG"):
            import traceback

            traceback.print_exc()
        sys.stderr.flush()
        if comm.size > 1:
            abort(comm)
        try:
            handler.close()
        except Exception:  # noqa: BLE001 - already failing; the message above is the one
            pass
        return 1

    # 4. close (collective) and report
    try:
        handler.close()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    timings = comm.gather(timing, root=0) if comm.size > 1 else [timing]
    if rank == 0 and os.environ.get("SLIDERS_DEBUG"):
        sys.stderr.write(f"ensemble: timings per rank {timings}\n")
    final = None
    if rank == 0:
        final = {"stop": root.stop_reason, "signum": root.signum,
                 "done": root.done_before + root.done_now, "write_s": handler.write_seconds}
    final = comm.bcast(final, root=0)
    if rank == 0:
        elapsed = time.monotonic() - root.started
        n_now = root.done_now
        if final["stop"]:
            sys.stderr.write(
                f"ensemble: interrupted ({final['stop']}): {final['done']}/{layout.n_realisations} "
                f"realisations in {args.out}; rerun with --resume to complete them\n")
        elif not args.quiet:
            stats = ", ".join(f"{k} {v}" for k, v in sorted(root.statuses.items())) or "none run"
            rate = f"{n_now / elapsed:.3g}/s" if elapsed > 0 and n_now else "-"
            rows = handler.rows_written
            cost = (f"; rank 0 wrote {rows} rows at {1e3 * handler.write_seconds / rows:.2f} ms "
                    "each (write + flush)") if rows else ""
            busy = "/".join(f"{100 * t['compute'] / elapsed:.0f}%" for t in timings) \
                if elapsed > 0 else "-"
            sys.stderr.write(
                f"ensemble: {final['done']}/{layout.n_realisations} realisations done, {n_now} in "
                f"this run in {elapsed:.2f} s ({rate}); statuses: {stats}; ranks busy {busy}"
                f"{cost} -> {args.out}\n")
        bad = {k: v for k, v in root.statuses.items()
               if k not in ("avalanche", "alpha_max", "max_events")}
        if bad and not final["stop"]:
            sys.stderr.write(f"ensemble: warning: {sum(bad.values())} realisation(s) ended without "
                             f"an avalanche: {dict(bad)}\n")
        sys.stderr.flush()
    if final["stop"]:
        return 128 + int(final["signum"] or signal.SIGTERM)
    return 0


def serve_rows(comm, handler, pending, total: int, ctx: dict, kind: str, out: str,
               write_view=None) -> int:
    """Run the scheduler over ``pending`` rows of a study or a prior ensemble, then close and report.

    Rank 0 serves the rows (``_Root``) and writes them, the other ranks compute
    (``_worker``); SIGTERM and SIGINT stop after the rows in progress.  Then
    ``write_view()`` (rank 0; the rows are safe if it fails) rewrites the
    file's xarray view, and one line says what was done.

    Parameters
    ----------
    comm : mpi4py communicator or SerialComm
    handler : the open file handler (``io.storage.HANDLERS`` and kin)
    pending : numpy.ndarray
        Row indices still to compute, in the order to serve them.
    total : int
        Rows in the file.
    ctx : dict
        The scheduler's context (``compute_row``, ``interval``, ``quiet``, ``label``).
    kind : str
        "study" or "prior": the first word of every line.
    out : str
        The file, for the messages.
    write_view : callable, optional
        Called on rank 0 after the rows are closed.

    Returns
    -------
    int
        0, 1 after an error on a rank, 128 + signal after a stop.
    """
    rank = comm.rank
    old = {s: signal.signal(s, _Stop.handler) for s in (signal.SIGTERM, signal.SIGINT)}
    root = None
    try:
        if rank == 0:
            root = _Root(comm, handler, pending, total - pending.size, ctx)
            root.run()
        else:
            _worker(comm, handler, ctx)
    except Exception as exc:  # noqa: BLE001 - nothing may hang
        sys.stderr.write(_error_line(f"rank {rank}: {type(exc).__name__}: {exc}") + "\n")
        sys.stderr.flush()
        if comm.size > 1:
            abort(comm)
        handler.close()
        return 1
    try:
        handler.close()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    final = None
    if rank == 0:
        if write_view is not None:
            try:
                write_view()
            except (OSError, KeyError, ValueError, RuntimeError) as exc:  # the rows are safe
                sys.stderr.write(f"{kind}: warning: the xarray view of {out} was not written "
                                 f"({' '.join(str(exc).split())}); rerun with --resume to add it\n")
        final = {"stop": root.stop_reason, "signum": root.signum}
        elapsed = time.monotonic() - root.started
        n_done = root.done_before + root.done_now
        if root.stop_reason:
            sys.stderr.write(f"{kind}: interrupted ({root.stop_reason}): {n_done}/{total} rows in "
                             f"{out}; rerun with --resume to complete them\n")
        elif not ctx["quiet"]:
            stats = ", ".join(f"{k} {v}" for k, v in sorted(root.statuses.items())) or "none run"
            sys.stderr.write(f"{kind}: {n_done}/{total} rows done, {root.done_now} in this run in "
                             f"{elapsed:.1f} s on {comm.size} rank(s); statuses: {stats} -> "
                             f"{out}\n")
    final = comm.bcast(final, root=0)
    if final["stop"]:
        return 128 + int(final["signum"] or signal.SIGTERM)
    return 0


if __name__ == "__main__":
    sys.exit(main())
