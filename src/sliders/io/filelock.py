"""Ownership of an output file: one writer at a time, and a dead writer never blocks.

``OutputClaim(path)`` is a context manager held by a run for as long as it
writes ``path`` (``tilt --out``, an ensemble, anything writing later).  It
takes an exclusive ``flock`` on the sidecar file ``<path>.lock``, which holds
"pid PID on HOST" of the holder:

* a second writer of the same path (new run, ``--overwrite`` or ``--resume``)
  fails at once with ``ClaimError`` naming the holder;
* the kernel drops a flock when its process dies (kill -9, crash, power loss
  on a local disk), so a dead holder's claim is stale by construction: the
  next run takes it (``previous_holder`` then names the dead one);
* on a file system without working locks (ENOLCK, EOPNOTSUPP: some NFS and
  FUSE mounts) ``locking`` is False: callers say so and refuse to replace an
  existing file, since a concurrent writer could not be seen.

The claim is on the file the path names (``safeio.resolve_target``: symlinks
resolved), so that two runs reaching one file through different paths meet
at one lock.  A file has one identity (device and inode) but may have several
names (hard links), each with its own sidecar; so an existing output is also
locked itself, by an open-file-description lock (``F_OFD_SETLK``) of one byte
far past any data (``IDENTITY_OFFSET``): a second claim of the same file
under another name fails like one under the same name, whether or not HDF5
locks its files (``HDF5_USE_FILE_LOCKING=FALSE``).  Such locks and HDF5's
``flock`` are independent on Linux; a created file joins the claim
(``bind``) as soon as it exists.  The sidecar is opened without following a symlink
(``O_NOFOLLOW``) and must be a regular file: a planted ``OUT.lock`` link
never makes a run truncate the file it points to.  Within one process a
claim is re-entrant (``tilt --out`` holds it while ``Result.save``, which
claims too, writes).  Whoever takes a claim removes the temporary files an
earlier, killed writer of the same path left (``leftovers``: reported by the
caller).

The sidecar is removed on release.  A process that opened it just before
that removal would lock an unlinked file, so ``acquire`` checks that the
locked file is still the one at ``<path>.lock`` and retries otherwise.
"""

from __future__ import annotations

import errno
import fcntl
import os
import socket
import stat
import struct
from .safeio import is_special, remove_leftovers, resolve_target

LOCK_SUFFIX = ".lock"
NO_LOCKING = (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL)
IDENTITY_OFFSET = 1 << 62  # the byte locked for the file's identity: past any data
_LOCKED = (errno.EAGAIN, errno.EACCES)  # F_OFD_SETLK: held by another open file


class ClaimError(OSError):
    """The output is held by another run, or its claim cannot be taken; one line."""


def holder_text() -> str:
    """This process as a claim names it: ``pid P on HOST``."""
    return f"pid {os.getpid()} on {socket.gethostname()}"


_HELD: dict[str, "OutputClaim"] = {}  # real path -> the claim this process holds on it


def current_holder(path) -> str | None:
    """The run named by the claim file of ``path`` ("pid P on HOST"), else None (read only,
    never locked: for messages about a file known to be busy)."""
    lock_path = resolve_target(path).real + LOCK_SUFFIX
    try:
        fd = os.open(lock_path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        return _read(fd) or None if stat.S_ISREG(os.fstat(fd).st_mode) else None
    finally:
        os.close(fd)


class OutputClaim:
    """Exclusive claim on an output path (see the module doc)."""

    def __init__(self, path):
        self.path = os.fspath(path)
        self.target = resolve_target(self.path)
        self.lock_path = self.target.real + LOCK_SUFFIX
        self.fd: int | None = None
        self.locking = True
        self.previous_holder: str | None = None  # a dead run's stale claim, taken over
        self.leftovers: list[tuple[str, int]] = []  # (name, bytes) of temporaries removed
        self._nested = False
        self._identity_fd: int | None = None  # the output itself, locked (see the module doc)

    def acquire(self) -> "OutputClaim":
        """Take the claim (an exclusive lock of ``<path>.lock``) or raise naming its holder; returns self."""
        if is_special(self.target.real):  # a device (/dev/full) or fifo: no file of ours to protect
            return self
        if self.target.real in _HELD:  # this process holds it already (tilt --out, then save)
            self._nested = True
            return self
        for _ in range(100):  # retried only when the sidecar was replaced under us
            try:
                fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW,
                             0o644)
            except OSError as exc:
                why = ("it is a symbolic link; sliders never writes through a lock file: "
                       "remove it" if exc.errno == errno.ELOOP else exc.strerror)
                raise ClaimError(f"cannot create the claim file {self.lock_path!r} for "
                                 f"{self.path!r}: {why}") from None
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                os.close(fd)
                raise ClaimError(f"the claim file {self.lock_path!r} for {self.path!r} is not a "
                                 "regular file; remove it")
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _read(fd) or "another process"
                os.close(fd)
                raise ClaimError(f"{self.path!r} is being written by {holder}; wait for it to "
                                 "finish, or stop it, or choose another output") from None
            except OSError as exc:
                if exc.errno not in NO_LOCKING:
                    os.close(fd)
                    raise ClaimError(f"cannot lock {self.lock_path!r}: {exc.strerror}") from None
                self.locking = False
            if self.locking and not _same_file(fd, self.lock_path):
                os.close(fd)  # released and removed meanwhile: take the new one
                continue
            self.previous_holder = _read(fd) or None
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, (holder_text() + "\n").encode(), 0)
            except OSError:  # a full disk: the lock holds all the same, unnamed
                pass
            self.fd = fd
            try:
                self.bind()
            except ClaimError:
                self.release()
                raise
            _HELD[self.target.real] = self
            if self.locking:  # no other writer alive: an earlier one's temporaries are garbage
                self.leftovers = remove_leftovers(self.target.real)
            return self
        raise ClaimError(f"cannot take the claim {self.lock_path!r}: it keeps being replaced")

    def bind(self) -> None:
        """Lock the output file itself (its device and inode) for the claim, if it exists:
        a created or replaced file joins the claim; ClaimError if another claim holds it."""
        self._unbind()
        fd = _identity_lock(self.target.real)
        if fd == -1:
            raise ClaimError(f"{self.path!r} is being written by another run, which reaches "
                             "the same file under another name (a hard link); wait for it to "
                             "finish, or stop it, or choose another output")
        self._identity_fd = fd

    def _unbind(self) -> None:
        if self._identity_fd is not None:
            os.close(self._identity_fd)  # drops the lock
            self._identity_fd = None

    def release(self) -> None:
        """Give the claim up (unlock and close; the lock file is removed)."""
        if self._nested:
            self._nested = False
            return
        self._unbind()
        if self.fd is None:
            return
        if _HELD.get(self.target.real) is self:
            del _HELD[self.target.real]
        try:
            if _same_file(self.fd, self.lock_path):
                os.unlink(self.lock_path)  # while still locked: nobody holds a stale copy
        except OSError:
            pass
        os.close(self.fd)  # drops the lock
        self.fd = None

    def __enter__(self) -> "OutputClaim":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def claim_of(path) -> "OutputClaim | None":
    """The claim this process holds on the file ``path`` names, else None."""
    return _HELD.get(resolve_target(path).real)


def _identity_lock(path: str) -> int | None:
    """An open descriptor of the regular file ``path`` holding the identity lock; None when
    there is nothing to lock (no such file, not writable, no such locks here); -1 when
    another open file holds it."""
    if not hasattr(fcntl, "F_OFD_SETLK"):
        return None
    try:
        fd = os.open(path, os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
    except OSError:  # missing (created later: bind), read-only, or a link planted meanwhile
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            return None
        # struct flock: l_type, l_whence, l_start, l_len, l_pid (0 for OFD locks)
        fcntl.fcntl(fd, fcntl.F_OFD_SETLK,
                    struct.pack("hhqqi4x", fcntl.F_WRLCK, os.SEEK_SET, IDENTITY_OFFSET, 1, 0))
    except OSError as exc:
        os.close(fd)
        return -1 if exc.errno in _LOCKED else None
    return fd


def _read(fd: int) -> str:
    try:
        return os.pread(fd, 256, 0).decode(errors="replace").strip()
    except OSError:
        return ""


def _same_file(fd: int, path: str) -> bool:
    try:
        a, b = os.fstat(fd), os.lstat(path)
    except OSError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)
