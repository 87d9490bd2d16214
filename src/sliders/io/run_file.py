"""The single-run file (``Result.save`` / ``Result.load``): layout, writer, reader.

One file holds one ``Result`` (of any loading; the format keeps its name ``sliders.tilt``)::

    (user block)           the first 512 bytes, which HDF5 skips: "sliders.tilt
                           whole-file crc32 XXXXXXXX" over the rest of the file
    /                      attrs: format = "sliders.tilt", format_version,
                           software_version, scene (JSON of Scene.to_dict()),
                           backend, status, message, alpha_c, wall_time,
                           relaxation (JSON), final_event (JSON), attrs_crc32
    /events/<name>         (K,) per-event arrays: drive (the loading's variable: the tilt
                           alpha in rad, or the driver position D), alpha (the incline's
                           angle: the drive under the tilt, the fixed incline under the
                           pushed end), n_moved, ...; format 1 held the drive in alpha
    /displacement/ptr, index, value   the moved sliders per event (CSR);
                           absent when the scene records only a summary
    /initial/<field>, /final/<field>  (N,) ChainState arrays; attr alpha

Integrity (``safeio``): every dataset carries a CRC-32, the root and the
state groups a CRC-32 of their attributes, and the user block a CRC-32 of the
whole rest of the file.  The reader checks the whole-file CRC before HDF5
parses anything, so that damaged HDF5 metadata cannot crash the process.
The names, units and dimension scales (``conventions``) are added after the
seals, which cover the data and the attributes the reader reads.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import warnings
import zlib

import numpy as np

from . import formats, safeio
from .._version import __version__
from ..chain import ChainState
from ..scene import Scene
from .conventions import describe_tilt_file
from .filelock import OutputClaim

FORMAT = formats.TILT
FORMAT_VERSION = 2
KNOWN_VERSIONS = (1, 2)  # format_version values this reader understands (a newer one is refused)
STATE_FIELDS = ("elastic_force0", "spring_extension0", "cantilever_stretch0",
                "lattice_position0", "mu_s", "displacement", "n_stops")
WHOLE_FILE_BLOCK = 512  # bytes before the HDF5 superblock, which HDF5 leaves to the user
WHOLE_FILE_MAGIC = b"sliders.tilt whole-file crc32 "


# ---------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------
def run_file_bytes(result) -> bytes:
    """The HDF5 file of a ``Result``, as bytes (sealed, described)."""
    import h5py

    def dataset(group, name, data):
        data = np.asarray(data)
        safeio.seal_dataset(group.create_dataset(name, data=data), data)

    buffer = io.BytesIO()
    with h5py.File(buffer, "w", userblock_size=WHOLE_FILE_BLOCK) as f:
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["software_version"] = __version__
        f.attrs["scene"] = json.dumps(result.scene.to_dict())
        f.attrs["backend"] = result.backend
        f.attrs["status"] = result.status
        f.attrs["message"] = result.message
        f.attrs["alpha_c"] = result.alpha_c
        f.attrs["wall_time"] = result.wall_time
        f.attrs["relaxation"] = json.dumps(result.relaxation)
        f.attrs["final_event"] = json.dumps(result.final_event)
        ev = f.create_group("events")
        drive = result.events["drive"]
        dataset(ev, "drive", drive)
        dataset(ev, "alpha", result.scene.loading.incline_at(drive))
        for name, values in result.events.items():
            if name != "drive":
                dataset(ev, name, values)
        if result.displacement is not None:
            g = f.create_group("displacement")
            dataset(g, "ptr", result.displacement.ptr)
            dataset(g, "index", result.displacement.index.astype(np.int32))
            dataset(g, "value", result.displacement.value)
        for label, state in (("initial", result.initial), ("final", result.final)):
            g = f.create_group(label)
            for name in STATE_FIELDS:
                dataset(g, name, getattr(state, name))
            g.attrs["alpha"] = state.drive  # the format's name of the drive
            safeio.seal_attrs(g)
        safeio.seal_attrs(f)
        # named dimensions, units, provenance: added after the seals, which
        # cover the data and the attributes that the reader reads
        describe_tilt_file(f, result)
    return seal_whole_file(buffer.getvalue())


def write_run_file(path, result, overwrite: bool = True) -> None:
    """Write a ``Result`` to ``path`` atomically (``safeio.publish_bytes``), holding the
    claim on it (``filelock.OutputClaim``: refused while another run writes it; re-entrant
    for ``tilt --out``, which holds it already); a symlink is written through."""
    safeio.check_output_name(path)
    data = run_file_bytes(result)
    with OutputClaim(path) as claim:
        if claim.leftovers:
            warnings.warn(safeio.leftovers_note(claim.leftovers), stacklevel=3)
        safeio.publish_bytes(path, data, overwrite)


# ---------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------
def read_run_file(path):
    """The fields of the ``Result`` saved in ``path`` (a dict of its constructor's
    arguments, the displacements as ``(ptr, index, value)``); every checksum is verified.

    ``Result.load`` builds the result from them: this module knows the
    layout, not the result class (no import of ``sliders.result``).

    A damaged or truncated file raises ``safeio.IntegrityError`` (an OSError)
    with one line naming the file and, for a flipped byte, the dataset; a
    file of another kind raises ValueError.
    """
    problem = whole_file_problem(path)
    if problem:
        raise safeio.IntegrityError(problem)
    return read_datasets_checked(path)


def read_datasets_checked(path):
    """``read_run_file`` without the whole-file check (per dataset and attribute set only)."""
    import h5py

    where = repr(os.fspath(path))
    try:
        f = h5py.File(path, "r")
    except FileNotFoundError as exc:
        raise FileNotFoundError(exc.errno, f"{where} does not exist") from None
    except OSError as exc:
        raise safeio.IntegrityError(f"{where} is not a readable HDF5 file ({exc})") from None
    try:
        with f:
            safeio.check_header(f, FORMAT, where, ValueError, versions=KNOWN_VERSIONS)
            scene = Scene.from_stored(json.loads(f.attrs["scene"]))
            events = {name: safeio.read_checked(ds, where) for name, ds in f["events"].items()}
            if int(f.attrs["format_version"]) >= 2:  # the drive in its own column; alpha,
                events.pop("alpha")  # the incline's angle, follows from it
            else:  # format 1 held the drive under the tilt's name
                events["drive"] = events.pop("alpha")
            disp = None
            if "displacement" in f:
                g = f["displacement"]
                disp = (safeio.read_checked(g["ptr"], where),
                        safeio.read_checked(g["index"], where).astype(np.int64),
                        safeio.read_checked(g["value"], where))
            states = {}
            for label in ("initial", "final"):
                g = f[label]
                safeio.check_attrs(g, where)
                states[label] = ChainState(**{k: safeio.read_checked(g[k], where) for k in g},
                                           drive=float(g.attrs["alpha"]))
            return dict(
                scene=scene, backend=str(f.attrs["backend"]), status=str(f.attrs["status"]),
                message=str(f.attrs["message"]), alpha_c=float(f.attrs["alpha_c"]),
                events=events, displacement=disp, initial=states["initial"],
                final=states["final"], relaxation=json.loads(f.attrs["relaxation"]),
                wall_time=float(f.attrs["wall_time"]),
                final_event=json.loads(f.attrs.get("final_event", "{}")),
            )
    except (safeio.IntegrityError, ValueError) as exc:
        if isinstance(exc, ValueError) and not str(exc).startswith(where):
            raise safeio.IntegrityError(f"{where} is damaged ({' '.join(str(exc).split())})") \
                from None
        raise
    except OSError as exc:
        raise safeio.IntegrityError(f"{where} is damaged ({safeio.describe_os_error(exc, path)})") \
            from None
    except Exception as exc:  # noqa: BLE001 - whatever HDF5 makes of a damaged file
        raise safeio.IntegrityError(f"{where} is damaged ({type(exc).__name__}: "
                                    f"{' '.join(str(exc).split())})") from None


# ---------------------------------------------------------------------------
# whole-file checksum in the HDF5 user block
# ---------------------------------------------------------------------------
def seal_whole_file(data: bytes) -> bytes:
    """Write the CRC-32 of everything after the user block into the user block."""
    out = bytearray(data)
    tag = WHOLE_FILE_MAGIC + b"%08x\n" % zlib.crc32(memoryview(out)[WHOLE_FILE_BLOCK:])
    out[:len(tag)] = tag
    return bytes(out)


def whole_file_problem(path) -> str | None:
    """One line if the file fails its whole-file checksum (then naming the damaged
    dataset when a sandboxed per-dataset check can), else None.  Files without
    the user-block checksum are left to the per-dataset checks."""
    where = repr(os.fspath(path))
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError:
        return None  # the HDF5 open reports it, in its own words
    if not data.startswith(WHOLE_FILE_MAGIC):
        return None
    stored = data[len(WHOLE_FILE_MAGIC):len(WHOLE_FILE_MAGIC) + 8]
    if len(data) > WHOLE_FILE_BLOCK and stored == b"%08x" % zlib.crc32(data[WHOLE_FILE_BLOCK:]):
        return None
    # Damaged: say where if HDF5 can tell, in a child process (damaged metadata
    # can crash HDF5 1.10 itself).
    probe = ("import sys\nfrom sliders.io.run_file import read_datasets_checked\ntry:\n"
             "    read_datasets_checked(sys.argv[1])\nexcept Exception as exc:\n"
             "    print(' '.join(str(exc).split()))\n")
    try:
        res = subprocess.run([sys.executable, "-c", probe, os.fspath(path)], capture_output=True,
                             text=True, timeout=120)
        named = res.stdout.strip() if res.returncode == 0 else ""
    except (OSError, subprocess.SubprocessError):
        named = ""
    if "checksum" in named or "damaged" in named:
        return named
    return f"{where} is damaged: it fails its whole-file checksum (in the HDF5 metadata)"
