"""Command-line pieces shared by ``python -m sliders`` and ``python -m sliders.ensemble``."""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
import typing

from ..scene import DEFAULT_MODE, SPEED_MODES, Scene, SceneError, check_writable, toml_values

_SKIP = {"output"}


def add_scene_arguments(parser: argparse.ArgumentParser) -> None:
    """One option per Scene field (``--n-sliders``, ``--xi``, ...) plus ``--scene FILE.toml``."""
    group = parser.add_argument_group("scene (defaults: the paper's parameters)")
    group.add_argument("--scene", metavar="FILE.toml",
                       help="read the scene from a TOML file; options given here override it")
    hints = typing.get_type_hints(Scene)
    for f in dataclasses.fields(Scene):
        if f.name in _SKIP:
            continue
        kinds = typing.get_args(hints[f.name]) or (hints[f.name],)
        conv = int if int in kinds else float if float in kinds else str
        default = (f"from --mode (default {DEFAULT_MODE!r}: {SPEED_MODES[DEFAULT_MODE][f.name]!r})"
                   if f.default is None else f"default {f.default!r}")
        choices = tuple(SPEED_MODES) if f.name == "mode" else None
        group.add_argument("--" + f.name.replace("_", "-"), dest=f.name, type=_typed(conv, f.name),
                           default=None, metavar=None if choices else f.name.upper(),
                           choices=choices, help=default)


def _typed(conv, name):
    def parse(text: str):
        try:
            return conv(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} expects {conv.__name__}, got {text!r}") from None
    return parse


def given_scene_values(args: argparse.Namespace, scene_text: bytes | None = None) -> dict:
    """The scene values given on the command line: ``--scene`` file (``scene_text``: its bytes,
    read by MPI rank 0), then the options."""
    values: dict = {}
    if args.scene:
        values.update(toml_values(args.scene, scene_text))
        Scene.from_dict(values)  # the file alone must be a valid scene
    for f in dataclasses.fields(Scene):
        given = getattr(args, f.name, None)
        if f.name not in _SKIP and given is not None:
            values[f.name] = given
    return values


def scene_from_args(args: argparse.Namespace, scene_text: bytes | None = None) -> Scene:
    """The Scene given by ``--scene`` (``scene_text``: its bytes, read by MPI rank 0) and the
    per-field options (validated)."""
    return Scene.from_dict(given_scene_values(args, scene_text))


def disagreements(stored: Scene, given: dict) -> str:
    """The given scene values that differ from a stored scene ("" if they all agree).

    A value agrees if the stored scene with it applied is the same scene
    (``mode`` brings its settings as in ``Scene.replace``)."""
    merged = stored.replace(**given)
    a, b = stored.to_dict(), merged.to_dict()
    return "; ".join(f"{k}={a[k]!r} in the file, {b[k]!r} given" for k in a if a[k] != b[k])


def check_output(path: str, overwrite: bool, option: str = "--out") -> None:
    """Refuse, before anything is computed, an output that could not be published: an
    empty, non-UTF-8 or too long name (``safeio.check_output_name``), a folder that is
    missing or not writable, or an existing file without ``--overwrite``.  A symlink is
    written through (``safeio.resolve_target``): the checks apply to the file it names."""
    from ..io.safeio import check_output_name, is_special, resolve_target

    try:
        check_output_name(path)
    except ValueError as exc:
        raise SceneError(f"{option}: {exc}") from None
    target = resolve_target(path)
    if is_special(target.real):  # a fifo or device: written in place (or refused by the caller);
        return                   # never opened here, where a fifo would block
    check_writable(option, target.real)
    if os.path.exists(target.real) and not overwrite:
        raise SceneError(f"{option} {path!r} exists; pass --overwrite to replace it")


def ranks_on_this_node(comm) -> int:
    """How many ranks of ``comm`` run on this rank's node (collective: every rank calls it);
    their memory adds up against one MemAvailable."""
    if comm.size == 1:
        return 1
    import socket

    hosts = comm.allgather(socket.gethostname())
    return hosts.count(socket.gethostname())


class ProgressLine:
    """A single status line on stderr, refreshed at most every ``interval`` s."""

    def __init__(self, interval: float = 1.0, stream=None):
        self.interval = interval
        self.stream = stream or sys.stderr
        self.last = -1e9
        self.tty = self.stream.isatty()

    def show(self, text: str, force: bool = False) -> None:
        """Show ``text`` as the progress line, at most once per interval unless ``force``."""
        now = time.monotonic()
        if force or now - self.last >= self.interval:
            self.last = now
            end = "\r" if self.tty else "\n"
            self.stream.write(f"{text:<78s}{end}")
            self.stream.flush()

    def close(self) -> None:
        """End the progress line (a newline on a terminal)."""
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def fail(message: str, code: int = 2) -> typing.NoReturn:
    """Print a one-line error (no traceback) and exit non-zero."""
    sys.stderr.write(f"error: {message}\n")
    raise SystemExit(code)
