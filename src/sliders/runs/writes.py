"""Every row written checked: room on the disk first, then the write, then HDF5's late failures.

``write_row`` is how the scheduler (``runs.scheduler``) writes a row: a row
that grows the file is written only with room for it and a margin
(``check_room_for``), and a failed write that h5py reports from a destructor
(``WriteFailures``) stops the run at that row with one line.
"""

from __future__ import annotations

import contextlib
import errno
import os
import sys

from ..io.safeio import disk_usage


class WriteFailures:
    """Failed writes that h5py reports only from a destructor.

    HDF5 writes some data late (its caches), and h5py reports a failure there
    (a full disk: errno 28) as an "exception ignored" in an object's
    destructor, which Python prints and forgets.  While ``watching()``, such
    exceptions are kept (the first one) instead of printed, and ``check()``,
    called after every written row, raises the first as an OSError: the run
    stops at the first failed write with one line.
    """

    first: BaseException | None = None

    @classmethod
    @contextlib.contextmanager
    def watching(cls):
        """Keep the exceptions raised in destructors (the first one) while inside."""
        cls.first = None
        old = sys.unraisablehook

        def keep(unraisable):
            if cls.first is None:
                cls.first = unraisable.exc_value

        sys.unraisablehook = keep
        try:
            yield cls
        finally:
            sys.unraisablehook = old

    @classmethod
    def check(cls) -> None:
        """Raise the first kept failure as an OSError (errno 28 for a full disk)."""
        exc = cls.first
        if exc is None:
            return
        if isinstance(exc, OSError) and exc.errno:
            raise exc
        text = " ".join(str(exc).split())
        code = errno.ENOSPC if "errno = 28" in text else errno.EIO
        raise OSError(code, f"{os.strerror(code)} ({text[:200]})")


WRITE_MARGIN = 1 << 20  # bytes kept free beyond a row's own: HDF5 allocates chunks and metadata


def payload_bytes(value) -> int:
    """The bytes of the arrays in a row (or a batch of rows: dicts, lists, tuples of arrays)."""
    if isinstance(value, dict):
        return sum(payload_bytes(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return sum(payload_bytes(v) for v in value)
    return int(getattr(value, "nbytes", 8))


def growth_bytes(handler, rows) -> int:
    """The bytes that writing ``rows`` (one row, or a worker's batch of ``(op, r, row)``) adds
    to the file beyond the rows the file allocated when it was created (a prior row's events)."""
    if isinstance(rows, list):
        return sum(growth_bytes(handler, op[2]) for op in rows if isinstance(op[2], dict))
    allocated = {c.name for c in handler.layout.columns}
    return payload_bytes({k: v for k, v in rows.items() if k not in allocated})


def check_room_for(path: str, nbytes: int) -> None:
    """Raise OSError(ENOSPC) before writing ``nbytes`` into ``path`` if its file system has
    not twice that plus ``WRITE_MARGIN`` free: HDF5 does not survive a write that fails for
    lack of room (the error surfaces in a destructor, then the library crashes on close)."""
    need = 2 * nbytes + WRITE_MARGIN
    try:
        free = disk_usage(path).free
    except OSError:
        return
    if free < need:
        raise OSError(errno.ENOSPC, f"{os.strerror(errno.ENOSPC)} ({free / 1e6:.3g} MB free, "
                                    f"the next write needs about {need / 1e6:.3g} MB with its margin)")


def write_row(handler, r: int, row: dict) -> None:
    """Write row ``r``, mark it done and flush; a failed write raises (``WriteFailures``), and
    a row that grows the file is written only with room for it (``check_room_for``)."""
    if handler.kind != "gather" or handler.comm.rank == 0:  # this rank writes the row itself
        grows = growth_bytes(handler, row)
        if grows:  # the file's own rows were allocated when it was created
            check_room_for(handler.path, grows)
    handler.write_row(r, row)
    WriteFailures.check()
    handler.mark_done(r)
    handler.flush()
    WriteFailures.check()
