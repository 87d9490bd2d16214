"""Command-line pieces shared by ``python -m sliders`` and ``python -m sliders.ensemble``."""

from __future__ import annotations

import argparse
import os
import sys
import time
import typing
import socket

from ..parts.checks import SceneError
from ..scene import DEFAULT_MODE, SPEED_MODES, Scene, check_writable, scene_keys, toml_values
from .. import scene
from ..io.safeio import check_output_name, is_special, resolve_target
from ..units import format_angle, parse_angle


class OneLineParser(argparse.ArgumentParser):
    """argparse whose refusal of a command line is one line, ``PROG: error: MESSAGE (see
    PROG --help)``, and exit status 2 (argparse alone prints the whole usage first)."""

    def error(self, message):
        """Print the one-line refusal and exit with status 2."""
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


# What each scene option means and its unit (the model's units, ``Scene``: time tau,
# length g tau^2, force m g, angles in radians; "" for a count or a name).
SCENE_OPTIONS = {
    "n_sliders": ("N, the number of sliders", ""),
    "xi": ("stiffness of the springs to the upper plate", "units of k, the neighbours' spring"),
    "spring_length": ("natural length of the springs between neighbours", "g tau^2"),
    "mu_d": ("dynamic friction coefficient", ""),
    "mu_s_mean": ("mean static friction coefficient", ""),
    "sigma_mu": ("width of the Gaussian static coefficients", ""),
    "seed": ("key of every random draw, 0 to 2**32 - 1", ""),
    "ends": ("a free chain or one between immobile walls", ""),
    "initial_forces": ("the preparation of the forces", ""),
    "mode": ("named speed/accuracy setting giving dt, refine-tol, max-event-duration", ""),
    "dt": ("Velocity-Verlet time step", "tau"),
    "refine_tol": ("width to which a slider's start or stop is bracketed", "tau"),
    "max_event_duration": ("cap on the duration of one rearrangement", "tau"),
    "max_events": ("stop after this many rearrangements", ""),
    "alpha_max": ("stop tilting at this angle", "angle"),
    "force_tol": ("tolerance of the stability test of a resting slider", "m g"),
    "avalanche": ("avalanche criterion", ""),
    "loading": ("tilt the incline, or push the first slider at a fixed incline", ""),
    "incline": ("pushed_end only: the fixed incline", "angle"),
    "driver_stiffness": ("pushed_end only: stiffness K of the driver's spring", "units of k"),
    "drive_max": ("pushed_end only: the driver's limit", "g tau^2"),
    "record": ("what each event keeps", ""),
}
ANGLE_HELP = "an angle: 0.5rad, 30deg, or a bare number in rad"


def _choices(name: str):
    """The fixed set of values of a scene option, if it has one."""
    table = {"ends": scene.ENDS, "record": scene.RECORDS, "avalanche": scene.AVALANCHE_CRITERIA,
             "initial_forces": scene.INITIAL_FORCES, "loading": scene.LOADINGS,
             "mode": tuple(SPEED_MODES)}
    return tuple(table[name]) if name in table else None


def _scene_option_help(name: str, default, choices) -> str:
    """The help of one scene option: meaning, choices, unit, default (angles in rad and deg)."""
    meaning, unit = SCENE_OPTIONS.get(name, (name.replace("_", " "), ""))
    parts = [meaning + (f" [{unit}]" if unit and unit != "angle" else "")]
    if choices:
        parts.append("one of {" + ", ".join(choices) + "}")
    if unit == "angle":
        parts.append(ANGLE_HELP)
    if default is None:
        parts.append(f"default from --mode (default {DEFAULT_MODE}: "
                     f"{SPEED_MODES[DEFAULT_MODE][name]!r})")
    else:
        parts.append(f"default {format_angle(default) if unit == 'angle' else repr(default)}")
    return "; ".join(parts)


def add_scene_arguments(parser: argparse.ArgumentParser) -> None:
    """One option per flat scene key (``--n-sliders``, ``--xi``, ...) plus ``--scene FILE.toml``;
    angles are read by ``sliders.units.parse_angle`` (rad or deg)."""
    group = parser.add_argument_group("scene (defaults: the paper's parameters; units: time "
                                      "tau, length g tau^2, force m g)")
    group.add_argument("--scene", metavar="FILE.toml",
                       help="read the scene from a TOML file; options given here override it")
    for f in scene_keys():
        conv = _angle if SCENE_OPTIONS.get(f.name, ("", ""))[1] == "angle" else f.type
        choices = _choices(f.name)
        group.add_argument("--" + f.name.replace("_", "-"), dest=f.name, type=_typed(conv, f.name),
                           default=None, metavar=None if choices else f.name.upper(),
                           choices=choices, help=_scene_option_help(f.name, f.default, choices))


def _angle(text: str) -> float:
    return parse_angle(text)


def _typed(conv, name):
    def parse(text: str):
        try:
            return conv(text)
        except ValueError:
            what = "an angle (e.g. 0.5rad or 30deg)" if conv is _angle else conv.__name__
            raise argparse.ArgumentTypeError(f"{name} expects {what}, got {text!r}") from None
    return parse


def given_scene_values(args: argparse.Namespace, scene_text: bytes | None = None) -> dict:
    """The scene values given on the command line: ``--scene`` file (``scene_text``: its bytes,
    read by MPI rank 0), then the options."""
    values: dict = {}
    if args.scene:
        values.update(toml_values(args.scene, scene_text))
        Scene.from_dict(values)  # the file alone must be a valid scene
    for f in scene_keys():
        given = getattr(args, f.name, None)
        if given is not None:
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
