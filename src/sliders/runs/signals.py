"""SIGINT and SIGTERM in the commands: how a signal stops a run without leaving half a file.

* ``StopFlag``: the run commands' flag (``runs.command``, ``runs.scheduler``):
  the signal is remembered and acted on at the next safe point, or interrupts
  local work at once (``interruptible``; a row's tilt: ``rows.run_interruptibly``);
* ``Interrupted``: raised at a safe point once a run has to stop;
* ``Received``: the signals of ``python -m sliders tilt``: they stop the tilt
  (the events so far are kept), then wait while its file is written;
* ``Stopped``, ``stopped_by_sigterm``: SIGTERM raises as Ctrl-C does, with its
  number (``python -m sliders.forecast`` and ``python -m sliders.merge``: nothing
  half-written is published; the exit status is 128 + ``stop_signal``).
"""

from __future__ import annotations

import contextlib
import signal


#: the signals that stop a command
STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT)


@contextlib.contextmanager
def handled(handler, signals=STOP_SIGNALS):
    """Within: ``handler`` on ``signals``; the previous handlers restored on exit."""
    old = {s: signal.signal(s, handler) for s in signals}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


class Interrupted(Exception):
    """Raised at a safe point once the run has to stop (signal or abort from rank 0)."""


class StopFlag:
    """Signal flag (set by the handler, acted on at safe points).

    ``installed()`` puts the handler on SIGINT and SIGTERM for the whole
    command.  Inside ``interruptible()`` (a rank's local planning, a
    realisation being computed: inside ``tilt``, outside the progress
    callbacks, which talk MPI) no file or message is in flight, so the
    handler also raises KeyboardInterrupt there: the kernel stops within its
    interrupt latency, a blocked read of an input returns, and the
    unfinished work is dropped.  Elsewhere (inside a collective call) the
    signal is only remembered and acted on at the next safe point.
    """

    signum: int | None = None
    computing = False

    @classmethod
    def handler(cls, signum, frame):
        """Signal handler: remember the first signal; interrupt the work if it is interruptible."""
        if cls.signum is None:
            cls.signum = signum
        if cls.computing:
            cls.computing = False
            raise KeyboardInterrupt

    @classmethod
    @contextlib.contextmanager
    def installed(cls):
        """The handler on SIGINT and SIGTERM (no signal remembered yet); restored on exit."""
        cls.signum, cls.computing = None, False
        with handled(cls.handler):
            yield cls

    @classmethod
    @contextlib.contextmanager
    def interruptible(cls):
        """Within: a signal raises KeyboardInterrupt (local work only, no collective call)."""
        if cls.signum is not None:  # arrived just before
            raise KeyboardInterrupt
        before, cls.computing = cls.computing, True
        try:
            yield cls
        finally:
            cls.computing = before


class Received(list):
    """The signals one scene's run received, in order: while ``stopping()`` the first stops
    the tilt (KeyboardInterrupt; the finished events are kept), while ``waiting()`` (its file
    being written) they are only remembered."""

    def _stop(self, signum, frame):
        self.append(signum)
        raise KeyboardInterrupt

    def _remember(self, signum, frame):
        self.append(signum)

    def stopping(self):
        """Within: SIGINT or SIGTERM stops the work (the batch systems' SIGTERM as Ctrl-C)."""
        return handled(self._stop)

    def waiting(self):
        """Within: a signal waits until the block ends (a file is being completed)."""
        return handled(self._remember)

    def exit_status(self) -> int:
        """128 + the first signal (SIGINT if none came: the kernel caught Ctrl-C itself)."""
        return 128 + (self[0] if self else signal.SIGINT)


class Stopped(KeyboardInterrupt):
    """SIGTERM (or SIGINT) received: the command stops, nothing half-written is published."""

    #: the SIGTERM received within ``stopped_by_sigterm``: its exception may be caught and
    #: replaced on the way up (a tilt it stops raises ``sliders.Interrupted``)
    received: int | None = None

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def raise_stopped(signum, frame):
    """A handler: the signal ``signum`` raises ``Stopped`` (and is recorded), so that a call
    blocked in the kernel is interrupted rather than retried."""
    Stopped.received = signum
    raise Stopped(signum)


@contextlib.contextmanager
def stopped_by_sigterm():
    """Within: SIGTERM raises ``Stopped`` (Ctrl-C raises KeyboardInterrupt as always)."""
    Stopped.received = None
    with handled(raise_stopped, (signal.SIGTERM,)):
        yield


def stop_signal(exc: KeyboardInterrupt) -> int:
    """The signal behind a KeyboardInterrupt raised within ``stopped_by_sigterm``."""
    return getattr(exc, "signum", None) or Stopped.received or signal.SIGINT
