"""The model file: a zip of plain NumPy arrays and one JSON header, never code.

::

    header.json     {"format": MODEL_ARRAYS_FORMAT, "content": ..., "provenance": ...,
                     "references": [...], "arrays": {name: {"dtype": ..., "shape": [...]}}}
    NAME.npy        one array per name of "arrays": booleans, 64-bit integers or floats

``content`` is the fitted estimators as a JSON tree naming their arrays
(``analysis.forecast.arrays``); ``references`` names the arrays of the
reference forecasts.  Reading (``read_model_arrays``) checks the form before
anything is used: a regular file of at most ``MAX_MODEL_BYTES``, read once; a
zip whose members are exactly the header and the arrays it lists, each bounded
before it is inflated (``MAX_MEMBER_BYTES``, ``MAX_INFLATED_BYTES``: no zip
bomb), each member's size and CRC-32 checked by ``zipfile`` as it is read;
every array a ``.npy`` of version 1.0 in C order of exactly the dtype, shape
and bytes the header declares (its own header compared with the one NumPy
writes for them, never parsed: no literal, never a pickle).  Any refusal is one line naming the
file and, where it is one, the array (``ModelFileError``).
"""

from __future__ import annotations

import io
import json
import math
import re
import zipfile

import numpy as np

from .forecast_model import (MAX_INFLATED_BYTES, MAX_MEMBER_BYTES, MAX_MEMBERS, MAX_TREE_BYTES,
                             ModelFileError, read_model_bytes)
from .safeio import printable, publish_bytes

MODEL_ARRAYS_FORMAT = "sliders-model-arrays-1"
HEADER = "header.json"
#: the dtypes an array may have: booleans, little-endian 64-bit integers and floats
DTYPES = ("|b1", "<i8", "<f8")
#: a name of an array: letters, digits, '_' and '.'
NAME = re.compile(r"[A-Za-z0-9_.]{1,200}")


def model_arrays_bytes(header: dict, arrays: dict) -> bytes:
    """The bytes of a model file of ``header`` (JSON: content, provenance, references) and
    ``arrays`` (``{name: array}``); the header's "format" and "arrays" are set here."""
    schema = {}
    members = {}
    for name, a in arrays.items():
        a = np.ascontiguousarray(a)
        if not NAME.fullmatch(name) or a.dtype.str not in DTYPES:
            raise ModelFileError(f"array {printable(name)!r} of {a.dtype}: not written (names of "
                                 f"letters, digits, '_' and '.'; dtypes {', '.join(DTYPES)})")
        schema[name] = {"dtype": a.dtype.str, "shape": list(a.shape)}
        buf = io.BytesIO()
        np.lib.format.write_array(buf, a, allow_pickle=False)
        members[f"{name}.npy"] = buf.getvalue()
    head = json.dumps({**header, "format": MODEL_ARRAYS_FORMAT, "arrays": schema},
                      sort_keys=True).encode()
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for name, blob in [(HEADER, head), *sorted(members.items())]:
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(info, blob)
    return out.getvalue()


def save_model_arrays(path, header: dict, arrays: dict) -> int:
    """Write a model file atomically; returns its size in bytes."""
    blob = model_arrays_bytes(header, arrays)
    publish_bytes(str(path), blob, overwrite=True)
    return len(blob)


def read_model_arrays(path, blob: bytes | None = None) -> tuple[dict, dict]:
    """``(header, {name: array})`` of a model file, its form checked (module docstring)."""
    archive = ModelArchive.open(path, blob)
    return archive.header, archive.read(archive.schema)


class ModelArchive:
    """A model file whose form is checked when opened (``open``: the zip, the header, every
    array's declaration and member) and whose arrays are read when asked (``read``), each
    checked as it is read."""

    def refuse_if(self, *checks) -> None:
        """``ModelFileError`` naming the file and saying the first ``(bad, what)`` that is bad."""
        what = next((what for bad, what in checks if bad), None)
        if what is not None:
            raise ModelFileError(f"{self.where}: {what}")

    @classmethod
    def open(cls, path, blob: bytes | None = None) -> "ModelArchive":
        """The archive of the model file ``path`` (its bytes ``blob`` if read already)."""
        self = cls()
        self.where = printable(path)
        try:
            self.zip = zipfile.ZipFile(io.BytesIO(read_model_bytes(path) if blob is None else blob))
            infos = self.zip.infolist()
        except (zipfile.BadZipFile, ValueError, OSError, EOFError):
            infos = None
        self.refuse_if((infos is None, "refused: not a sliders model file (a zip of arrays; a "
                                       "pickle is never loaded)"))
        big = max(infos, key=lambda i: i.file_size, default=zipfile.ZipInfo())
        members = {i.filename: i for i in infos}
        head = members.get(HEADER, zipfile.ZipInfo())
        self.refuse_if(
            (len(infos) > MAX_MEMBERS, f"{len(infos)} members; a model file holds at most "
                                       f"{MAX_MEMBERS}"),
            (big.file_size > MAX_MEMBER_BYTES, f"member {printable(big.filename)[:80]!r} inflates "
             f"to {big.file_size / 2**20:.0f} MB; a member holds at most "
             f"{MAX_MEMBER_BYTES // 2**20} MB"),
            (sum(i.file_size for i in infos) > MAX_INFLATED_BYTES,
             f"its members inflate to more than {MAX_INFLATED_BYTES // 2**20} MB"),
            (len(members) != len(infos), "two members of one name"),
            (HEADER not in members, f"refused: not a sliders model file of format "
                                    f"{MODEL_ARRAYS_FORMAT} (no {HEADER}): train it again"),
            (head.file_size > MAX_TREE_BYTES, f"its header inflates to "
             f"{head.file_size / 2**20:.0f} MB; at most {MAX_TREE_BYTES // 2**20} MB"))
        text = _member(self.zip, head, self.where)
        try:
            self.header = json.loads(text)
        except (ValueError, RecursionError):
            self.header = None
        found = self.header.get("format") if isinstance(self.header, dict) else None
        self.refuse_if((self.header is None, f"{HEADER} is not JSON"), (
            found != MODEL_ARRAYS_FORMAT,
            f"a model file of format {printable(str(found))[:60]}; this version reads "
            f"{MODEL_ARRAYS_FORMAT}: train it again" if isinstance(found, str)
            else f"not a sliders model file of format {MODEL_ARRAYS_FORMAT}"))
        self.schema = self.header.get("arrays")
        self.refuse_if((not isinstance(self.schema, dict), f"{HEADER} lists no arrays"))
        extra = sorted(set(members) - {HEADER} - {f"{n}.npy" for n in self.schema})
        self.refuse_if((extra, f"member {printable(extra[0] if extra else '')[:80]!r} is no "
                               "array of the header's"))
        for name, spec in self.schema.items():
            what = f"array {printable(name)[:80]!r}"
            self.refuse_if(
                (not (isinstance(name, str) and NAME.fullmatch(name)),
                 f"{what}: not a name of an array"),
                (not (isinstance(spec, dict) and spec.get("dtype") in DTYPES
                      and isinstance(spec.get("shape"), list) and len(spec["shape"]) <= 3
                      and all(type(d) is int and 0 <= d <= 2**31 for d in spec["shape"])),
                 f"{what}: declared of no dtype of {', '.join(DTYPES)} or of no shape"),
                (f"{name}.npy" not in members, f"{what} is missing"))
        return self

    def read(self, names) -> dict:
        """``{name: array}`` of the arrays ``names`` declared by the header, each its member's
        ``.npy`` (version 1.0, C order) of exactly the dtype, shape and bytes declared: its
        header those bytes NumPy writes for them, compared, never parsed."""
        out = {}
        for name in names:
            dtype, shape = np.dtype(self.schema[name]["dtype"]), tuple(self.schema[name]["shape"])
            head = io.BytesIO()
            np.lib.format.write_array_header_1_0(head, {"descr": dtype.str, "shape": shape,
                                                        "fortran_order": False})
            head = head.getvalue()
            data = _member(self.zip, self.zip.getinfo(f"{name}.npy"), self.where)
            self.refuse_if((not data.startswith(head) or len(data) != len(head) + dtype.itemsize
                            * math.prod(shape), f"array {printable(name)[:80]!r} is not a NumPy "
                            f"array of this format's (version 1.0, C order) of the {dtype} "
                            f"{shape} the header declares"))
            out[name] = np.frombuffer(data, dtype, offset=len(head)).reshape(shape).copy()
        return out


def _member(archive: zipfile.ZipFile, info: zipfile.ZipInfo, where) -> bytes:
    """A member's bytes, their size and CRC-32 checked by ``zipfile`` as it reads them (a
    damaged member: ``ModelFileError``)."""
    try:
        return archive.read(info)
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError,
            MemoryError) as exc:
        raise ModelFileError(f"{where}: damaged model file "
                             f"({printable(str(exc) or 'out of memory while reading it')[:80]})") \
            from None
