"""Every command's ``--help`` explains every option: a text for each, its choices listed, its unit named.

The parsers are walked (sub-commands included), not their printed help, so
that a new option is checked the day it is added.  An option "has a unit" when
its destination is one of ``UNITS`` (the physical quantities the commands
take); its help must name the unit, angles both rad and deg, since every angle
option reads either (``sliders.units.parse_angle``).
"""

from __future__ import annotations

import argparse
import importlib
import math

import pytest

from sliders.units import DEGREE, format_angle, parse_angle

# destination -> words its help must contain
UNITS = {
    "alpha_max": ("rad", "deg"), "incline": ("rad", "deg"), "tilt_now": ("rad", "deg"),
    "dt": ("[tau]",), "refine_tol": ("[tau]",), "max_event_duration": ("[tau]",),
    "spring_length": ("[g tau^2]",), "drive_max": ("[g tau^2]",), "force_tol": ("[m g]",),
    "xi": ("units of k",), "driver_stiffness": ("units of k",),
    "progress_interval": ("seconds",), "within": ("deg",), "leads_deg": ("deg",),
}
# command -> (module, function building its parser, arguments)
COMMANDS = {
    "ensemble": ("sliders.runs.ensemble", "build_parser"),
    "study": ("sliders.runs.study", "build_parser"),
    "prior": ("sliders.runs.prior", "build_parser"),
    "merge": ("sliders.runs.merge", "build_parser"),
    "tilt": ("sliders.__main__", "build_parser"),
    "reproduction": ("sliders.runs.reproduction", "build_parser"),
    "forecast": ("sliders.runs.forecast.cli", "build_parser"),
    "figures": ("sliders.figures.paper", "build_parser"),
}


def options(parser: argparse.ArgumentParser, prefix: str = ""):
    """(command path, action) of every option and positional, sub-commands included."""
    for action in parser._actions:  # argparse keeps no public list of its actions
        if isinstance(action, argparse._HelpAction):
            continue
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from options(sub, f"{prefix} {name}".strip())
            continue
        yield prefix, action


def problems(parser: argparse.ArgumentParser) -> list[str]:
    """Every option without help, with choices its help does not list, or a unit it does not name."""
    out = []
    for where, action in options(parser):
        name = "/".join(action.option_strings) or action.dest
        text = action.help or ""
        if not text.strip() or text == argparse.SUPPRESS:
            out.append(f"{where} {name}: no help text")
            continue
        missing = [str(c) for c in (action.choices or ()) if str(c) not in text]
        if missing:
            out.append(f"{where} {name}: choices {missing} not listed in its help")
        unit = [w for w in UNITS.get(action.dest, ()) if w not in text]
        if unit:
            out.append(f"{where} {name}: help does not name its unit ({unit})")
    return out


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_option_is_explained(command):
    module, builder = COMMANDS[command]
    parser = getattr(importlib.import_module(module), builder)()
    assert problems(parser) == []


def test_the_checker_finds_what_it_looks_for():
    p = argparse.ArgumentParser()
    p.add_argument("--bare")
    p.add_argument("--record", choices=("summary", "forces"), help="what is kept: summary")
    p.add_argument("--alpha-max", type=float, help="the largest angle, 1.57 rad")
    p.add_argument("--fine", choices=("a", "b"), help="one of {a, b}")
    found = problems(p)
    assert len(found) == 3
    assert "--bare: no help" in found[0] and "['forces']" in found[1] and "['deg']" in found[2]


def test_scene_angles_are_read_in_rad_or_deg():
    from sliders.runs.ensemble import build_parser

    args = build_parser().parse_args(["--out", "x.h5", "--alpha-max", "30deg", "--incline", "0.1"])
    assert args.alpha_max == pytest.approx(math.radians(30)) and args.incline == 0.1
    help_text = build_parser().format_help()
    assert format_angle(math.pi / 2 - 1e-6) in " ".join(help_text.split())
    assert parse_angle("27.5 deg") == pytest.approx(27.5 * DEGREE)
    assert parse_angle("27.5", DEGREE) == parse_angle("27.5deg")
    with pytest.raises(ValueError, match="not understood"):
        parse_angle("steep")


def test_a_bad_angle_is_refused_in_one_line(capsys):
    from sliders.runs import ensemble

    assert ensemble.main(["--out", "x.h5", "-R", "1", "--alpha-max", "90 grad"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "alpha_max expects an angle" in lines[0], lines
