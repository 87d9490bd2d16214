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
every array a ``.npy`` of version 1.0 in C order (its header parsed by NumPy,
``read_array_header_1_0``: a literal, never a pickle) of exactly the dtype,
shape and bytes the header declares.  Any refusal is one line naming the
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
    where = printable(path)
    blob = read_model_bytes(path) if blob is None else blob

    def refuse(what: str):
        raise ModelFileError(f"{where}: {what}")

    try:
        archive = zipfile.ZipFile(io.BytesIO(blob))
        infos = archive.infolist()
    except (zipfile.BadZipFile, ValueError, OSError, EOFError):
        refuse("refused: not a sliders model file (a zip of arrays; a pickle is never loaded)")
    big = max(infos, key=lambda i: i.file_size, default=zipfile.ZipInfo())
    by_name = {i.filename: i for i in infos}
    head = by_name.get(HEADER, zipfile.ZipInfo())
    for bad, what in (
            (len(infos) > MAX_MEMBERS, f"{len(infos)} members; a model file holds at most "
                                       f"{MAX_MEMBERS}"),
            (big.file_size > MAX_MEMBER_BYTES, f"member {printable(big.filename)[:80]!r} inflates "
             f"to {big.file_size / 2**20:.0f} MB; a member holds at most "
             f"{MAX_MEMBER_BYTES // 2**20} MB"),
            (sum(i.file_size for i in infos) > MAX_INFLATED_BYTES,
             f"its members inflate to more than {MAX_INFLATED_BYTES // 2**20} MB"),
            (len(by_name) != len(infos), "two members of one name"),
            (HEADER not in by_name, f"refused: not a sliders model file of format "
                                    f"{MODEL_ARRAYS_FORMAT} (no {HEADER}): train it again"),
            (head.file_size > MAX_TREE_BYTES, f"its header inflates to "
             f"{head.file_size / 2**20:.0f} MB; at most {MAX_TREE_BYTES // 2**20} MB")):
        if bad:
            refuse(what)
    text = _member(archive, head, where)
    try:
        header = json.loads(text)
    except (ValueError, RecursionError):
        refuse(f"{HEADER} is not JSON")
    found = header.get("format") if isinstance(header, dict) else None
    if found != MODEL_ARRAYS_FORMAT:
        refuse(f"a model file of format {printable(str(found))[:60]}; this version reads "
               f"{MODEL_ARRAYS_FORMAT}: train it again" if isinstance(found, str)
               else f"not a sliders model file of format {MODEL_ARRAYS_FORMAT}")
    schema = header.get("arrays")
    if not isinstance(schema, dict):
        refuse(f"{HEADER} lists no arrays")
    extra = sorted(set(by_name) - {HEADER} - {f"{n}.npy" for n in schema})
    if extra:
        refuse(f"member {printable(extra[0])[:80]!r} is no array of the header's")
    arrays = {}
    for name, spec in schema.items():
        what = f"array {printable(name)[:80]!r}"
        if not (isinstance(name, str) and NAME.fullmatch(name)):
            refuse(f"{what}: not a name of an array")
        if not (isinstance(spec, dict) and spec.get("dtype") in DTYPES
                and isinstance(spec.get("shape"), list) and len(spec["shape"]) <= 3
                and all(type(d) is int and 0 <= d <= 2**31 for d in spec["shape"])):
            refuse(f"{what}: declared of no dtype of {', '.join(DTYPES)} or of no shape")
        if f"{name}.npy" not in by_name:
            refuse(f"{what} is missing")
        raw = io.BytesIO(_member(archive, by_name[f"{name}.npy"], where))
        dtype, shape = np.dtype(spec["dtype"]), tuple(spec["shape"])
        try:  # NumPy's own parser of a header of at most 10 kB: a literal, never a pickle
            found = np.lib.format.read_magic(raw) == (1, 0) and \
                np.lib.format.read_array_header_1_0(raw)
        except (ValueError, TypeError, SyntaxError, RecursionError, MemoryError, EOFError):
            found = False
        if not found or found[1]:
            refuse(f"{what} is not a NumPy array of this format's (version 1.0, C order, "
                   "booleans or 64-bit numbers)")
        if found[2] != dtype or found[0] != shape:
            refuse(f"{what} holds {found[2].str} {found[0]}, not the {dtype} {shape} the header "
                   "declares")
        body = raw.read()
        if len(body) != dtype.itemsize * math.prod(shape):
            refuse(f"{what}: its member holds {len(body)} bytes of data, not the "
                   f"{dtype.itemsize * math.prod(shape)} of its shape")
        arrays[name] = np.frombuffer(body, dtype=dtype).reshape(shape).copy()
    return header, arrays


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
