"""What an adversary writes: a class whose building writes a marker file (what a crafted model
file would make a loader run), and model files written as-is, naming anything, checked by
nothing."""

import io
import json
import pathlib
import pickle
import zipfile

import numpy as np


class MarkerOnLoad:
    """Writes ``self.path`` whenever its state is set (as an unpickler would do)."""

    def __init__(self, path):
        self.path = path

    def __setstate__(self, state):
        pathlib.Path(state["path"]).write_text("ran")
        self.__dict__.update(state)


def archive_as_is(path, header, members=None):
    """A zip at ``path`` of ``header`` (any JSON, as header.json) and ``members`` (``{name:
    bytes}``), whatever they hold (no check on writing); returns ``path``."""
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("header.json", json.dumps(header))
        for name, blob in (members or {}).items():
            z.writestr(name, blob)
    return path


def pickled_npy(obj) -> bytes:
    """A .npy member of an object array holding ``obj``: its data a pickle."""
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.array([obj, None], dtype=object), allow_pickle=True)
    return buf.getvalue()


def marker_file(path, marker) -> pathlib.Path:
    """A model file whose header names ``MarkerOnLoad`` as an estimator and whose one array is
    a pickle of a ``MarkerOnLoad`` writing ``marker``: read as data, neither runs."""
    pickle.dumps(MarkerOnLoad(str(marker)))  # the class pickles (the member is a real pickle)
    header = {"format": "sliders-model-arrays-1", "provenance": {},
              "arrays": {"x": {"dtype": "|O", "shape": [2]}},
              "content": {"learned_blind": {"object": "marker_class.MarkerOnLoad",
                                            "state": {"path": {"array": "x"}}}}}
    return archive_as_is(path, header, {"x.npy": pickled_npy(MarkerOnLoad(str(marker)))})
