"""The scheduler of every run command: rows served over the ranks, stopped, reported.

Scheduling (dynamic): rank 0 hands out row indices on request and computes
rows itself.  It answers requests between chunks of events of its own run
(the driver's progress callback), so no rank sits idle as a dedicated
master.  Every other rank keeps ``PREFETCH`` requests ahead of the row it
computes, so the answers are there when it finishes; near the end rank 0
declines requests made ahead, so that no rank holds unstarted work while
another runs out.  ``Root`` is rank 0's side, ``worker`` the others'.

A row is ``ctx["compute_row"](r, progress)`` (``compute``): an ensemble's
realisation, a study's (point, realisation) pair, a prior ensemble's drawn
scene.  Rows are written as they come (``handler``: ``io.storage`` and kin).

Interruption: SIGTERM/SIGINT on any rank (``StopFlag``) stops the whole run
at the next safe point (between chunks of events): rows in progress are
dropped, rows already written stay, the file is closed, rank 0 prints one
line and every rank exits with 128 + signal number.  A failed write or any
other error on a rank stops the run at once with one line (exit 1).
"""

from __future__ import annotations

import math
import os
import signal
import sys
import time
from collections import Counter, deque
from typing import Any

from .. import status as status_codes
from .parallel import abort, error_line
from .signals import Interrupted, StopFlag
from .writes import WriteFailures, check_room_for, growth_bytes, write_row
from ..io.safeio import os_reason

TAG_MSG, TAG_REPLY, TAG_CTRL = 71, 72, 73
NO_MORE, DECLINED = -1, -2  # replies to a request for an index
PREFETCH = 2  # indices a worker asks for ahead of the one it is computing


def compute(ctx: dict, r: int, progress) -> dict[str, Any]:
    """Row ``r`` of the run: ``ctx["compute_row"](r, progress)``."""
    return ctx["compute_row"](r, progress)


def format_duration(s: float) -> str:
    """Seconds for a progress line: ``"4.2 s"``, ``"3 min 05 s"``, ``"2 h 01 min"`` (``"?"`` if unknown)."""
    if not math.isfinite(s):
        return "?"
    if s < 120:
        return f"{s:.1f} s" if s < 10 else f"{s:.0f} s"
    s = int(round(s))
    if s < 7200:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {(s % 3600) // 60:02d} min"


class Root:
    """Rank 0: serve requests, compute, write (gather), report progress."""

    def __init__(self, comm, handler, pending, n_done_before, ctx):
        self.comm = comm
        self.handler = handler
        self.queue = deque(int(r) for r in pending)
        self.total = n_done_before + len(self.queue)
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
            grows = growth_bytes(self.handler, ops or [])
            if grows:
                check_room_for(self.handler.path, grows)
            self.handler.apply(ops)
            WriteFailures.check()
            self.completed(code)
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
        if StopFlag.signum is not None:
            sig = StopFlag.signum
            self.stop(f"{signal.Signals(sig).name} on rank 0", sig)

    # -- progress ----------------------------------------------------------
    def completed(self, code: int) -> None:
        """A row is written (its end status ``code``): count it, stop if asked, report."""
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
        label, unit = self.ctx["label"]
        sys.stderr.write(f"{label}: {done}/{self.total} {unit} done, "
                         f"{rate:.3g}/s, elapsed {format_duration(elapsed)}, ETA {format_duration(eta)}\n")
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
                row = compute(ctx, r, self.poll)
            except (Interrupted, KeyboardInterrupt):  # the signal stops the run below
                break
            finally:
                self.timing["compute"] += time.perf_counter() - t0
            write_row(self.handler, r, row)
            self.completed(row["status"])
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


def worker(comm, handler, ctx) -> dict[str, float]:
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
        if StopFlag.signum is not None or (ctrl and ctrl[0] == "abort"):
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
                row = compute(ctx, r, check)
            finally:
                timing["compute"] += time.perf_counter() - t0
            write_row(handler, r, row)
            sends.append(comm.isend(("done", r, handler.outbox(), row["status"]), dest=0,
                                    tag=TAG_MSG))
            r = next_index()
    except (Interrupted, KeyboardInterrupt):
        pass
    take(block=True)  # every request gets its answer before the end
    if StopFlag.signum is not None:
        sig = StopFlag.signum
        comm.send(("interrupted", f"{signal.Signals(sig).name} on rank {comm.rank}", sig),
                  dest=0, tag=TAG_MSG)
    MPI.Request.Waitall(sends)
    comm.send(("bye",), dest=0, tag=TAG_MSG)
    if not ctrl:
        ctrl.append(comm.recv(source=0, tag=TAG_CTRL))
    return timing


def serve_rows(comm, handler, pending, total: int, ctx: dict, out: str, write_view=None,
               rank_timings: bool = False) -> int:
    """Run the scheduler over ``pending`` rows, then close the file and report; the exit code.

    Rank 0 serves the rows (``Root``) and writes them, the other ranks compute
    (``worker``); SIGTERM and SIGINT stop after the rows in progress.  Then
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
        ``compute_row(r, progress)``, ``interval`` (s between progress lines),
        ``quiet``, ``label``: (first word of every line, name of the rows).
    out : str
        The file, for the messages.
    write_view : callable, optional
        Called on rank 0 after the rows are closed.
    rank_timings : bool
        Gather every rank's computing time and report how busy each rank was
        (and rank 0's cost of writing a row).

    Returns
    -------
    int
        0, 1 after an error on a rank, 128 + signal after a stop.
    """
    rank = comm.rank
    root = None
    with WriteFailures.watching():
        try:
            if rank == 0:
                root = Root(comm, handler, pending, total - len(pending), ctx)
                root.run()
                timing = root.timing
            else:
                timing = worker(comm, handler, ctx)
        except Exception as exc:  # noqa: BLE001 - a bug or a failed write: nothing may hang
            return _failed(comm, handler, exc, out)
        try:
            handler.close()
            WriteFailures.check()
        except Exception as exc:  # noqa: BLE001 - a failed final write: the same one line
            return _failed(comm, None, exc, out)
    timings = comm.gather(timing, root=0) if rank_timings and comm.size > 1 else [timing]
    final = None
    if rank == 0:
        if write_view is not None:
            _write_view(write_view, out, ctx["label"][0])
        final = {"stop": root.stop_reason, "signum": root.signum}
        _report(root, comm.size, out, timings if rank_timings else None)
    final = comm.bcast(final, root=0)
    if final["stop"]:
        return 128 + int(final["signum"] or signal.SIGTERM)
    return 0


def _write_view(write_view, out: str, kind: str) -> None:
    """Rank 0, rows closed: ``write_view()`` if the file system has room for a copy of the
    file (the view holds at most the rows again); else, or if it fails, one warning (the
    rows are safe, ``--resume`` adds the view)."""
    with WriteFailures.watching():
        try:
            check_room_for(out, os.path.getsize(out) // 2)
            write_view()
            WriteFailures.check()
        except (OSError, KeyError, ValueError, RuntimeError) as exc:
            sys.stderr.write(f"{kind}: warning: the xarray view of {out} was not written "
                             f"({' '.join(str(exc).split())}); rerun with --resume to add it\n")


def _failed(comm, handler, exc: BaseException, out: str) -> int:
    """One line for an error on this rank, every rank stopped; 1."""
    what = (f"cannot write {out!r}: {os_reason(exc)}" if isinstance(exc, OSError)
            else f"{type(exc).__name__}: {exc}")
    sys.stderr.write(error_line(f"rank {comm.rank}: {what}") + "\n")
    sys.stderr.flush()
    if comm.size > 1:
        abort(comm)
    if handler is not None:
        try:
            handler.close()
        except Exception:  # noqa: BLE001 - already failing; the line above is the one
            pass
    return 1


def _report(root: Root, ranks: int, out: str, timings: list | None) -> None:
    """Rank 0's closing line: interrupted, or what was done (and, with ``timings``, how busy
    each rank was and what a written row cost)."""
    kind, unit = root.ctx["label"]
    elapsed = time.monotonic() - root.started
    n_done = root.done_before + root.done_now
    if root.stop_reason:
        sys.stderr.write(f"{kind}: interrupted ({root.stop_reason}): {n_done}/{root.total} {unit} "
                         f"in {out}; rerun with --resume to complete them\n")
    elif not root.ctx["quiet"]:
        stats = ", ".join(f"{k} {v}" for k, v in sorted(root.statuses.items())) or "none run"
        rate = f"{root.done_now / elapsed:.3g}/s" if elapsed > 0 and root.done_now else "-"
        extra = ""
        if timings is not None:
            busy = ("/".join(f"{100 * t['compute'] / elapsed:.0f}%" for t in timings)
                    if elapsed > 0 else "-")
            extra = f"; ranks busy {busy}"
            rows = getattr(root.handler, "rows_written", 0)
            if rows:
                extra += (f"; rank 0 wrote {rows} rows at "
                          f"{1e3 * root.handler.write_seconds / rows:.2f} ms each (write + flush)")
        sys.stderr.write(f"{kind}: {n_done}/{root.total} {unit} done, {root.done_now} in this "
                         f"run in {elapsed:.2f} s ({rate}) on {ranks} rank"
                         f"{'s' if ranks > 1 else ''}; statuses: {stats}{extra} -> {out}\n")
    bad = {k: v for k, v in root.statuses.items()
           if k not in ("avalanche", "alpha_max", "max_events")}
    if bad and not root.stop_reason:
        sys.stderr.write(f"{kind}: warning: {sum(bad.values())} {unit} ended without an "
                         f"avalanche: {dict(bad)}\n")
    sys.stderr.flush()
