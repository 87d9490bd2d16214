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
bomb); every array of the dtype and shape the header declares, read with
``allow_pickle=False``.  Any refusal is one line naming the file and, where it
is one, the array (``ModelFileError``).
"""

from __future__ import annotations

import io
import json
import math
import re
import zipfile
import zlib

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
#: the header of a .npy member as NumPy writes it for a C-ordered array of ``DTYPES``
NPY_HEADER = re.compile(rb"\x93NUMPY\x01\x00..\{'descr': '(?P<descr><f8|<i8|\|b1)', "
                        rb"'fortran_order': False, 'shape': \((?P<shape>(?:\d{1,10}, ?)*\d{0,10}),?\), \}"
                        rb" *\n", re.DOTALL)
NPY_HEADER_MAX = 4096


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
    if len(infos) > MAX_MEMBERS:
        refuse(f"{len(infos)} members; a model file holds at most {MAX_MEMBERS}")
    big = max(infos, key=lambda i: i.file_size, default=None)
    if big is not None and big.file_size > MAX_MEMBER_BYTES:
        refuse(f"member {printable(big.filename)[:80]!r} inflates to "
               f"{big.file_size / 2**20:.0f} MB; a member holds at most "
               f"{MAX_MEMBER_BYTES // 2**20} MB")
    if sum(i.file_size for i in infos) > MAX_INFLATED_BYTES:
        refuse(f"its members inflate to more than {MAX_INFLATED_BYTES // 2**20} MB")
    by_name = {i.filename: i for i in infos}
    if len(by_name) != len(infos):
        refuse("two members of one name")
    head = by_name.get(HEADER)
    if head is None:
        refuse(f"refused: not a sliders model file of format {MODEL_ARRAYS_FORMAT} (no "
               f"{HEADER}): train it again")
    if head.file_size > MAX_TREE_BYTES:
        refuse(f"its header inflates to {head.file_size / 2**20:.0f} MB; at most "
               f"{MAX_TREE_BYTES // 2**20} MB")
    text = _member(archive, head, where)
    try:
        header = json.loads(text)
    except (ValueError, RecursionError):
        refuse(f"{HEADER} is not JSON")
    if not isinstance(header, dict) or header.get("format") != MODEL_ARRAYS_FORMAT:
        found = header.get("format") if isinstance(header, dict) else None
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
        info = by_name.get(f"{name}.npy")
        if info is None:
            refuse(f"{what} is missing")
        dtype, shape = np.dtype(spec["dtype"]), tuple(spec["shape"])
        if info.file_size < dtype.itemsize * math.prod(shape):
            refuse(f"{what}: its member holds {info.file_size} bytes, not an array of shape "
                   f"{shape}")
        arrays[name] = _array(_member(archive, info, where), dtype, shape, what, where)
    return header, arrays


def _array(raw: bytes, dtype: np.dtype, shape: tuple, what: str, where) -> np.ndarray:
    """The array of a ``.npy`` member: its header exactly the one ``write_array`` writes for
    ``dtype`` and ``shape`` (version 1.0, C order), its data exactly the bytes they need.
    Parsed here (no ``ast.literal_eval``, no object dtype: nothing a pickle could hide in)."""
    m = NPY_HEADER.fullmatch(raw[:NPY_HEADER_MAX].split(b"\n", 1)[0] + b"\n") \
        if raw[:8] == b"\x93NUMPY\x01\x00" else None
    if m is None:
        raise ModelFileError(f"{where}: {what} is not a NumPy array of this format's (version "
                             "1.0, C order, booleans or 64-bit numbers)")
    dims = tuple(int(d) for d in m["shape"].split(b",") if d.strip())
    if m["descr"].decode() != dtype.str or dims != shape:
        raise ModelFileError(f"{where}: {what} holds {m['descr'].decode()} {dims}, not the "
                             f"{dtype} {shape} the header declares")
    body = raw[m.end():]
    if len(body) != dtype.itemsize * math.prod(shape):
        raise ModelFileError(f"{where}: {what}: its member holds {len(body)} bytes of data, not "
                             f"the {dtype.itemsize * math.prod(shape)} of its shape")
    return np.frombuffer(body, dtype=dtype).reshape(shape).copy()


def _member(archive: zipfile.ZipFile, info: zipfile.ZipInfo, where) -> bytes:
    """A member's bytes, at most those it declares (a damaged member: ``ModelFileError``)."""
    try:
        with archive.open(info) as fh:
            data = fh.read(info.file_size + 1)
        if len(data) != info.file_size or zlib.crc32(data) != info.CRC:
            raise zipfile.BadZipFile(f"member {printable(info.filename)[:80]!r} is not the "
                                     "bytes its size and CRC-32 declare")
        return data
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError) as exc:
        raise ModelFileError(f"{where}: damaged model file ({printable(str(exc))[:80]})") \
            from None
    except MemoryError:
        raise ModelFileError(f"{where}: damaged model file (out of memory while reading it)") \
            from None
