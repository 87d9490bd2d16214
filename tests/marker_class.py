"""What an adversary writes: a class whose building writes a marker file (what a crafted model
file would make a loader run), and model files written as-is, naming anything, checked by
nothing."""

import pathlib

from sliders.io import model_archive


class MarkerOnLoad:
    """Writes ``self.path`` whenever its state is set (as an unpickler would do)."""

    def __init__(self, path):
        self.path = path

    def __setstate__(self, state):
        pathlib.Path(state["path"]).write_text("ran")
        self.__dict__.update(state)


class Anything:
    """An allow-list holding every name."""

    def __contains__(self, name) -> bool:
        return True


def archive_as_is(path, contents):
    """``contents`` written at ``path`` in the model files' archive format, whatever classes
    it names and whatever they hold (no check on writing); returns ``path``."""
    pathlib.Path(path).write_bytes(model_archive.dumps(contents, Anything()))
    return path
