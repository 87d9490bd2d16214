"""Fitted objects as data: a zip of one JSON tree and a few packed NumPy arrays.

A fitted forecaster is a tree of Python objects (scikit-learn's estimators, crepes'
calibration, the package's forecasters) around some ten thousand arrays.  ``dumps``
writes that tree the way ``pickle`` would describe it (each object as the call
that makes it and the state handed to its ``__setstate__``), but as data: the
tree is JSON (``tree.json``), every array is a slice of one of a few packed arrays,
one per dtype (``arrays/<k>.npy``, NumPy's format, never an object array), and
every class or function the tree names must be on the reader's allow-list.
``loads`` audits every name of the tree against that list before it builds
anything, then builds the objects from views of the packed arrays: the shipped
forecaster (2,975 trees) is built in about a fifth of a second, and nothing in the file
can name code that is not on the list.

A JSON node is one of: a JSON scalar or list (itself); ``{"tuple": [...]}``;
``{"dict": [[key, value], ...]}``; ``{"array": [k, offset, shape]}`` (elements
``offset`` on of packed array ``k``); ``{"scalar": [dtype, value]}`` (a NumPy
scalar); ``{"dtype": descr}``; ``{"name": "module.qualname"}`` (an allow-listed
class or function); ``{"object": [call, args, state], "id": n}`` (``call(*args)``,
then its state set, as ``pickle`` does); ``{"ref": n}`` (an object met before).
"""

from __future__ import annotations

import importlib
import io
import json
import math
import zipfile

import numpy as np

TREE_MEMBER = "tree.json"
ARRAYS_FOLDER = "arrays/"
#: how ``pickle`` makes an object of a class without calling its ``__init__``
NEWOBJ = "copyreg.__newobj__"
#: the types of the functions a tree may name (by name, as classes are)
FUNCTION_TYPES = ("function", "builtin_function_or_method", "cython_function_or_method")


class ArchiveError(ValueError):
    """An archive that cannot be read, or an object that cannot be written, as data."""


def qualified_name(thing) -> str:
    """``module.qualname`` of a class or function: how the archive names it."""
    return f"{thing.__module__}.{thing.__qualname__}"


# ---------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------
class _Writer:
    """One archive being written: the JSON tree, the arrays packed by dtype, the objects met."""

    def __init__(self, allowed):
        self.allowed = allowed
        self.groups: dict[str, list[np.ndarray]] = {}  # dtype's descr -> its arrays, in order
        self.sizes: dict[str, int] = {}  # dtype's descr -> elements packed so far
        self.memo: dict[int, int] = {}
        self.alive: list = []  # every object met, so that no id is reused while writing

    def name(self, thing) -> dict:
        """The node of a class or function on the allow-list."""
        name = qualified_name(thing)
        if name not in self.allowed:
            raise ArchiveError(f"{name} is not on the allow-list of the archive's names")
        return {"name": name}

    def array(self, a: np.ndarray) -> dict:
        """The node of an array of numbers: appended to the packed array of its dtype."""
        if a.dtype.hasobject:
            raise ArchiveError(f"an array of dtype {a.dtype} holds objects, not numbers")
        key = json.dumps(np.lib.format.dtype_to_descr(a.dtype))
        if key not in self.groups:
            self.groups[key], self.sizes[key] = [], 0
        offset = self.sizes[key]
        self.groups[key].append(np.ascontiguousarray(a).reshape(-1))
        self.sizes[key] += a.size
        return {"array": [list(self.groups).index(key), offset, list(a.shape)]}

    def node(self, value):
        """The JSON node of any value the archive can hold (the module docstring's list)."""
        if value is None or isinstance(value, (bool, str)):
            return value
        if type(value) in (int, float):
            return value
        if type(value) is list:
            return [self.node(v) for v in value]
        if type(value) is tuple:
            return {"tuple": [self.node(v) for v in value]}
        if type(value) is dict:
            return {"dict": [[self.node(k), self.node(v)] for k, v in value.items()]}
        if type(value) is np.ndarray:
            return self.memoised(value, self.array)
        if isinstance(value, np.generic):
            if value.dtype.hasobject:
                raise ArchiveError("a NumPy scalar of dtype object")
            return {"scalar": [np.lib.format.dtype_to_descr(value.dtype), value.item()]}
        if isinstance(value, np.dtype):
            return {"dtype": np.lib.format.dtype_to_descr(value)}
        if isinstance(value, type) or type(value).__name__ in FUNCTION_TYPES:
            return self.name(value)
        return self.memoised(value, self.reduced)

    def memoised(self, value, write) -> dict:
        """``write(value)`` the first time ``value`` is met, a reference to it after."""
        key = id(value)
        if key in self.memo:
            return {"ref": self.memo[key]}
        self.alive.append(value)
        self.memo[key] = n = len(self.memo)
        out = write(value)
        out["id"] = n
        return out

    def reduced(self, obj) -> dict:
        """The node of an object of an allow-listed class: the call that makes it and its
        state, as ``pickle`` describes it (``__reduce_ex__(2)``)."""
        kind = type(obj)
        if qualified_name(kind) not in self.allowed:
            raise ArchiveError(f"{qualified_name(kind)} is not on the allow-list of the "
                               "archive's names")
        rv = obj.__reduce_ex__(2)
        if isinstance(rv, str) or len(rv) > 3 and any(x is not None for x in rv[3:]):
            raise ArchiveError(f"a {qualified_name(kind)} is not made by a call and a state")
        call, args = rv[0], rv[1]
        state = rv[2] if len(rv) > 2 else None
        self.alive.append(rv)
        return {"object": [self.name(call)["name"], self.node(tuple(args))["tuple"],
                           self.node(state)]}

    def bytes(self, root, compresslevel: int) -> bytes:
        """The zip of ``root``'s tree and the packed arrays."""
        tree = json.dumps(self.node(root), separators=(",", ":"), allow_nan=True)
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED,
                             compresslevel=compresslevel) as zf:
            zf.writestr(_member(TREE_MEMBER), tree, compresslevel=compresslevel)
            for k, parts in enumerate(self.groups.values()):
                member = io.BytesIO()
                np.lib.format.write_array(member, np.concatenate(parts), allow_pickle=False)
                zf.writestr(_member(f"{ARRAYS_FOLDER}{k}.npy"), member.getvalue(),
                            compresslevel=compresslevel)
        return buf.getvalue()


def _member(name: str) -> zipfile.ZipInfo:
    """A member of fixed date and mode: the same objects give the same bytes (and digest)."""
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = 0o644 << 16
    return info


def dumps(root, allowed, compresslevel: int = 9) -> bytes:
    """The archive's bytes of ``root``; ``ArchiveError`` on an object it cannot write as data
    (a class or function not ``in allowed``, an object array, a custom reduction)."""
    return _Writer(allowed).bytes(root, compresslevel)


# ---------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------
def _named(found: set):
    """A JSON object hook that adds every class or function a node names to ``found``."""
    def hook(node: dict) -> dict:
        if "name" in node:
            found.add(node["name"])
        elif "object" in node:
            call = node["object"]
            found.add(call[0] if isinstance(call, list) and call else None)
        return node
    return hook


def resolve(name: str):
    """The class or function ``module.qualname``."""
    if not isinstance(name, str):
        raise ArchiveError(f"a name that is not a string: {name!r}")
    parts = name.split(".")
    for cut in range(len(parts) - 1, 0, -1):
        module, rest = ".".join(parts[:cut]), parts[cut:]
        try:
            thing = importlib.import_module(module)
        except ImportError:
            continue
        for attr in rest:
            thing = getattr(thing, attr)
        return thing
    raise ArchiveError(f"{name}: no such module")


class _Reader:
    """One archive being read: its packed arrays, its resolved names, the objects built."""

    def __init__(self, arrays: list[np.ndarray], names: dict):
        self.arrays, self.names = arrays, names
        self.memo: dict[int, object] = {}

    def node(self, node):
        """The value of a JSON node (arrays are views of the packed arrays)."""
        if isinstance(node, list):
            return [self.node(v) for v in node]
        if not isinstance(node, dict):
            return node
        if "object" in node:
            return self.built(node)
        if "array" in node:
            k, offset, shape = node["array"]
            packed = self.arrays[k]
            size = math.prod(shape)
            if not (isinstance(offset, int) and 0 <= offset and offset + size <= packed.size
                    and all(isinstance(s, int) and s >= 0 for s in shape)):
                raise ArchiveError(f"an array past the end of packed array {k}")
            a = packed[offset:offset + size].reshape(shape)
            self.memo[node["id"]] = a
            return a
        if "tuple" in node:
            return tuple(self.node(v) for v in node["tuple"])
        if "dict" in node:
            return {self.node(k): self.node(v) for k, v in node["dict"]}
        if "ref" in node:
            return self.memo[node["ref"]]
        if "scalar" in node:
            descr, value = node["scalar"]
            return np.lib.format.descr_to_dtype(_tuples(descr)).type(value)
        if "dtype" in node:
            return np.lib.format.descr_to_dtype(_tuples(node["dtype"]))
        if "name" in node:
            return self.names[node["name"]]
        raise ArchiveError(f"an unknown node ({', '.join(map(str, node))})")

    def built(self, node):
        """An object: made by its call, remembered, then given its state."""
        call, args, state = node["object"]
        args = tuple(self.node(a) for a in args)
        if call == NEWOBJ:
            cls, args = args[0], args[1:]
            if not isinstance(cls, type):
                raise ArchiveError("an object of something that is not a class")
            obj = cls.__new__(cls, *args)
        else:
            obj = self.names[call](*args)
        self.memo[node["id"]] = obj
        state = self.node(state)
        if state is not None:
            setstate = getattr(obj, "__setstate__", None)
            if setstate is not None:
                setstate(state)
            else:
                if isinstance(state, tuple) and len(state) == 2:
                    state, slots = state
                    for k, v in (slots or {}).items():
                        setattr(obj, k, v)
                if state:
                    obj.__dict__.update(state)
        return obj


def _tuples(descr):
    """A JSON descr (lists) as NumPy's (a structured dtype's fields are tuples)."""
    if isinstance(descr, list):
        return [tuple(_tuples(x) for x in field) if isinstance(field, list) else field
                for field in descr]
    return descr


def read_tree(archive: zipfile.ZipFile) -> tuple[object, set]:
    """The JSON tree of an archive and every name it holds (no object built)."""
    found: set = set()
    try:
        return json.loads(archive.read(TREE_MEMBER), object_hook=_named(found)), found
    except KeyError:
        raise ArchiveError(f"no {TREE_MEMBER}: not an archive of fitted objects of this "
                           "format (train the model again)") from None
    except (ValueError, RecursionError) as exc:
        raise ArchiveError(f"{TREE_MEMBER} is not JSON ({type(exc).__name__})") from None


def loads(blob: bytes, allowed) -> object:
    """The object of an archive's bytes; ``UntrustedNames`` if the tree names anything off
    ``allowed`` (nothing is imported or built then), ``ArchiveError`` if it cannot be built
    from what it holds."""
    archive = zipfile.ZipFile(io.BytesIO(blob))
    tree, found = read_tree(archive)
    refused = sorted(map(str, found - set(allowed)))
    if refused:
        raise UntrustedNames(refused)
    names = {name: resolve(name) for name in found - {NEWOBJ}}
    arrays = []
    for k in range(sum(1 for n in archive.namelist() if n.startswith(ARRAYS_FOLDER))):
        with archive.open(f"{ARRAYS_FOLDER}{k}.npy") as fh:
            arrays.append(np.lib.format.read_array(fh, allow_pickle=False))
    return _Reader(arrays, names).node(tree)


class UntrustedNames(ArchiveError):
    """An archive naming classes or functions off the allow-list; ``names`` lists them."""

    def __init__(self, names):
        super().__init__(", ".join(names))
        self.names = names
