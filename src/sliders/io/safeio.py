"""Writing files so that nothing finished is ever lost, and I/O errors as one line.

* ``publish_bytes(path, data, overwrite)``: a whole file goes to a temporary
  file beside the target, is flushed to the disk (fsync), then renamed over
  it.  An existing file is never truncated before its replacement is
  complete; without ``overwrite`` the rename is a hard link, which fails
  atomically if another process created the target in the meantime (no
  check-then-create race).
* ``resolve_target(path)``: what a path names (``FileTarget``: the real path,
  symlinks resolved, and device + inode when the file exists).  Every claim,
  alias check, lock and publication goes through it.  Writing to a symlink
  writes *through* it: the file the link names is created or replaced
  (atomically), the link stays.  A lock file is never followed.
* ``check_output_name(path)``: a name every writer can use (UTF-8, short
  enough for its temporary name), checked before anything is computed.
* ``leftover_temporaries(path)`` / ``remove_leftovers(path)``: the temporary
  files of an earlier, killed write of ``path`` (named
  ``.NAME.XXXXXXXX.tmp``), which the next claim holder removes and reports.
* ``describe_os_error(exc, path)``: "PATH: REASON" for an ``OSError``,
  including the ones h5py raises for HDF5's own I/O failures (which carry the
  errno only in their text).
* ``crc32_of(array)`` and friends: the checksum every dataset of a sliders
  file carries (``DIGEST_ATTR``), verified on load.
"""

from __future__ import annotations

import errno
import json
import os
import re
import stat
import tempfile
import zlib
from typing import NamedTuple
import shutil

import numpy as np
from . import formats

# Every dataset written by sliders carries this attribute: CRC-32 of its dtype,
# shape and bytes (``crc32_of``).  The root group carries ATTRS_DIGEST over its
# other attributes.
DIGEST_ATTR = "crc32"
ATTRS_DIGEST = "attrs_crc32"


class IntegrityError(OSError):
    """A file's content does not match its checksums (flipped bytes, truncation)."""


# ---------------------------------------------------------------------------
# file identity
# ---------------------------------------------------------------------------
class FileTarget(NamedTuple):
    """What a path names: as given, the real path (every symlink resolved, a dangling
    last link included) and ``(st_dev, st_ino)`` of the file when it exists."""

    given: str
    real: str
    identity: tuple[int, int] | None

    def same_file(self, other: "FileTarget") -> bool:
        """True if both name one file: same device and inode, or (not yet existing) same real path."""
        if self.identity is not None and other.identity is not None:
            return self.identity == other.identity
        return self.real == other.real


def resolve_target(path) -> FileTarget:
    """The one notion of file identity (see the module doc)."""
    given = os.fspath(path)
    if isinstance(given, bytes):
        given = os.fsdecode(given)
    real = os.path.realpath(given) if given else given
    try:
        st = os.stat(real)
        identity = (st.st_dev, st.st_ino)
    except OSError:
        identity = None
    return FileTarget(given, real, identity)


TEMP_RANDOM = 8  # characters of mkstemp's random part
TEMP_SUFFIX = ".tmp"
TEMP_EXTRA = 1 + 1 + TEMP_RANDOM + len(TEMP_SUFFIX)  # "." NAME "." XXXXXXXX ".tmp"


def check_output_name(path) -> None:
    """Refuse (ValueError, one line) an output name no writer could publish: empty, not
    UTF-8 (HDF5 and the messages need text), or too long once ``.NAME.XXXXXXXX.tmp``
    makes the temporary name (the file system's NAME_MAX, 255 on most)."""
    p = os.fspath(path)
    if isinstance(p, bytes):
        p = os.fsdecode(p)
    if not p:
        raise ValueError("the output path is empty; give a file path to write")
    try:
        p.encode("utf-8")
    except UnicodeEncodeError:
        shown = os.fsencode(p).decode("utf-8", errors="backslashreplace")
        raise ValueError(f"output {shown!r}: the file name is not valid UTF-8 (HDF5 and the "
                         "messages need text); rename it") from None
    target = resolve_target(p).real
    folder = os.path.dirname(target) or "."
    try:
        name_max = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    name = os.path.basename(target)
    longest = name_max - TEMP_EXTRA
    if len(os.fsencode(name)) > longest:
        raise ValueError(f"output {name[:40]}...: its name has {len(os.fsencode(name))} bytes; "
                         f"at most {longest} can be written safely here (the temporary file "
                         f"beside it adds {TEMP_EXTRA} to the file system's limit of {name_max})")


def _leftover_pattern(target: str) -> re.Pattern:
    return re.compile(r"\." + re.escape(os.path.basename(target)) +
                      r"\.[a-z0-9_]{%d}" % TEMP_RANDOM + re.escape(TEMP_SUFFIX) + r"\Z")


def leftover_temporaries(path) -> list[str]:
    """Temporary files an earlier write of ``path`` left behind (killed before it published)."""
    target = resolve_target(path).real
    folder = os.path.dirname(target) or "."
    pattern = _leftover_pattern(target)
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    out = []
    for name in sorted(names):
        if pattern.match(name):
            full = os.path.join(folder, name)
            try:
                if stat.S_ISREG(os.lstat(full).st_mode):
                    out.append(full)
            except OSError:
                pass
    return out


def remove_leftovers(path) -> list[tuple[str, int]]:
    """Remove the leftover temporaries of ``path`` (call only while holding its claim: no
    live writer then owns one); returns ``(name, bytes)`` of each removed."""
    removed = []
    for tmp in leftover_temporaries(path):
        try:
            size = os.lstat(tmp).st_size
            os.unlink(tmp)
        except OSError:
            continue
        removed.append((tmp, size))
    return removed


def leftovers_note(removed: list[tuple[str, int]]) -> str:
    """One line naming the removed leftovers ("" if none)."""
    if not removed:
        return ""
    total = sum(size for _, size in removed)
    names = ", ".join(os.path.basename(name) for name, _ in removed[:3])
    more = f" and {len(removed) - 3} more" if len(removed) > 3 else ""
    return (f"removed {len(removed)} temporary file(s) left by an interrupted write "
            f"({names}{more}; {total / 1e6:.3g} MB)")


# ---------------------------------------------------------------------------
# checksums
# ---------------------------------------------------------------------------
def crc32_of(array) -> int:
    """CRC-32 of an array's dtype, shape and bytes (C order)."""
    a = np.ascontiguousarray(array)
    return zlib.crc32(a.tobytes(), zlib.crc32(f"{a.dtype.str}{a.shape}".encode()))


def crc32_of_attrs(attrs: dict, names) -> int:
    """CRC-32 of the named attributes (names and values, in name order)."""
    items = {k: _attr_text(attrs[k]) for k in names}
    return zlib.crc32(json.dumps(items, sort_keys=True).encode())


def _attr_text(v) -> str:
    if isinstance(v, bytes):
        v = v.decode(errors="replace")
    if isinstance(v, np.ndarray):
        return f"{v.dtype.str}{v.shape}{v.tobytes().hex()}"
    if isinstance(v, (float, np.floating)):
        return float(v).hex()
    if isinstance(v, np.generic):
        v = v.item()
    return repr(v)


def seal_attrs(group) -> None:
    """Store the digest of a group's attributes present now (attributes added later by
    other tools, such as provenance, are not covered and do not invalidate it)."""
    attrs = dict(group.attrs)
    names = sorted(k for k in attrs if k != ATTRS_DIGEST)
    group.attrs[ATTRS_DIGEST] = json.dumps({"names": names, "crc32": crc32_of_attrs(attrs, names)})


def check_attrs(group, where: str) -> None:
    """Raise IntegrityError (naming ``where``) if the attributes of ``group`` fail their CRC-32."""
    attrs = dict(group.attrs)
    if ATTRS_DIGEST not in attrs:
        raise IntegrityError(f"{where}: the attributes of {group.name} carry no checksum "
                             "(written by an older sliders, or damaged)")
    try:
        sealed = json.loads(attrs[ATTRS_DIGEST])
        ok = int(sealed["crc32"]) == crc32_of_attrs(attrs, sealed["names"])
    except (ValueError, KeyError, TypeError):
        ok = False
    if not ok:
        raise IntegrityError(f"{where}: the attributes of {group.name} fail their checksum "
                             "(the file is damaged)")


def seal_dataset(ds, data) -> None:
    """Store the CRC-32 of ``data`` as an attribute of dataset ``ds`` (checked on load)."""
    ds.attrs[DIGEST_ATTR] = np.uint32(crc32_of(data))


def read_checked(ds, where: str) -> np.ndarray:
    """A dataset's values, verified against its checksum attribute."""
    values = ds[()]
    stored = ds.attrs.get(DIGEST_ATTR)
    if stored is None:
        raise IntegrityError(f"{where}: dataset {ds.name} carries no checksum "
                             "(written by an older sliders, or damaged)")
    if int(stored) != crc32_of(values):
        raise IntegrityError(f"{where}: dataset {ds.name} fails its checksum (the file is damaged)")
    return values


def check_header(h5file, fmt: str, where: str, wrong_kind=ValueError,
                 coordinates: bool = True, versions=(1,)) -> None:
    """The file is of kind ``fmt`` (else ``wrong_kind``, one line naming the kind it is),
    of a ``format_version`` in ``versions`` (a newer one is refused, naming it and the
    versions known), and its root attributes (and coordinate variables) pass their
    checksums.  Every reader (tilt, ensemble, study) opens a file through this, raising
    its own error."""
    found = h5file.attrs.get("format")
    if isinstance(found, bytes):
        found = found.decode(errors="replace")
    if found != fmt:
        raise wrong_kind(f"{where} {formats.kind_text(found)}, not a sliders "
                         f"{formats.KIND_NAMES.get(fmt, fmt)}")
    version = h5file.attrs.get("format_version")
    try:
        version = int(version)
    except (TypeError, ValueError):
        version = None
    if version not in versions:
        known = ", ".join(str(v) for v in versions)
        if version is not None and version > max(versions):
            raise wrong_kind(f"{where} has format_version {version}, written by a newer sliders; "
                             f"this one reads format_version {known}: upgrade sliders to read "
                             "or resume it")
        raise wrong_kind(f"{where} has format_version {version!r}; this sliders reads "
                         f"format_version {known} (the file is damaged or not from sliders)")
    check_attrs(h5file, where)
    if coordinates:
        check_coordinates(h5file, where)


def check_coordinates(h5file, where: str) -> None:
    """Verify the coordinate variables (the root group's datasets, written by
    ``conventions.describe`` for xarray) against their checksums."""
    import h5py

    for ds in h5file.values():
        if isinstance(ds, h5py.Dataset):
            read_checked(ds, where)


# ---------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------
_ERRNO_IN_TEXT = re.compile(r"errno = (\d+)")
_REASONS_IN_TEXT = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EIO, errno.EFBIG)


def disk_usage(path):
    """``shutil.disk_usage`` (total, used, free bytes) of the file system that holds ``path``'s
    real file (symlinks followed: the disk a write reaches); OSError if it cannot be asked."""
    target = resolve_target(path).real
    return shutil.disk_usage(os.path.dirname(target) or ".")


def os_reason(exc: BaseException) -> str:
    """The operating system's reason for a failed I/O call, as words."""
    code = getattr(exc, "errno", None)
    if not code:
        m = _ERRNO_IN_TEXT.search(str(exc))
        code = int(m.group(1)) if m else None
    if code:
        return os.strerror(code)
    text = " ".join((getattr(exc, "strerror", None) or str(exc)).split())
    for known in _REASONS_IN_TEXT:  # MPI-IO errors carry the reason as words only
        if os.strerror(known) in text:
            return os.strerror(known)
    return text


def describe_os_error(exc: BaseException, path) -> str:
    """One line: the path and the operating system's reason."""
    return f"{os.fspath(path)!r}: {os_reason(exc)}"


# ---------------------------------------------------------------------------
# whole-file writes
# ---------------------------------------------------------------------------
def is_special(path) -> bool:
    """True if ``path`` exists and is not a regular file (a device such as /dev/full, a fifo)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return False
    return not stat.S_ISREG(mode) and not stat.S_ISDIR(mode)


def temporary_beside(path) -> str:
    """A new, empty temporary file beside the file ``path`` names (symlinks resolved: same
    file system, so that the rename is atomic), named ``.NAME.XXXXXXXX.tmp``."""
    target = resolve_target(path).real
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(target) + ".",
                               suffix=TEMP_SUFFIX, dir=os.path.dirname(target))
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # what open() would give, not mkstemp's 0600
    finally:
        os.close(fd)
    return tmp


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def publish(tmp: str, path, overwrite: bool) -> None:
    """Move a complete, flushed temporary file onto ``path``.

    ``overwrite``: atomic replace.  Otherwise a hard link, which fails with
    FileExistsError if ``path`` appeared meanwhile; the temporary file is then
    removed and the existing file left as it was.  A symlink is written through:
    the file it names is created or replaced, the link stays.
    """
    target = resolve_target(path).real
    try:
        if is_special(target):  # never replace a device node (root could: /dev/full)
            raise IsADirectoryError(errno.EINVAL, "not a regular file", target)
        if overwrite:
            os.replace(tmp, target)
            fsync_dir(target)
            return
        try:
            os.link(tmp, target)
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOSYS):
                raise
            # no hard links here (some FUSE and SMB mounts): exclusive create then rename
            fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            os.close(fd)
            os.replace(tmp, target)
        fsync_dir(target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def publish_bytes(path, data: bytes, overwrite: bool) -> None:
    """Write a whole file: temporary file beside it, fsync, rename (see module doc).

    A target that is a device or a fifo (``/dev/full``, ``/dev/stdout``) is
    written in place: it cannot be replaced, and it holds no file to lose.
    """
    target = resolve_target(path).real
    if is_special(target):
        with open(target, "wb") as fh:
            fh.write(data)
            fh.flush()
        return
    if not overwrite and os.path.exists(target):
        raise FileExistsError(errno.EEXIST, "File exists", target)
    tmp = temporary_beside(target)
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    except BaseException:
        os.unlink(tmp)
        raise
    publish(tmp, target, overwrite)


def fsync_path(path) -> None:
    """Flush a file's data to the disk (through a descriptor of its own: any one will do)."""
    fd = os.open(os.fspath(path), os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(path: str) -> None:
    """Flush the directory entry of a renamed file (the rename survives a power loss)."""
    try:
        fd = os.open(os.path.dirname(os.path.abspath(path)), os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems refuse fsync on directories; the data is synced
        pass
    finally:
        os.close(fd)


def printable(text) -> str:
    """``text`` with every character that is not printable escaped as Python writes it
    (``\\x1b``, ``\\n``, ``\\u202e``): text read from a file (a model's provenance, a file
    name) that reaches a terminal cannot clear the screen, move the cursor, colour a line or
    reverse the text.  The space stays a space."""
    return "".join(ch if ch == " " or ch.isprintable()
                   else ch.encode("unicode_escape").decode("ascii") for ch in str(text))
