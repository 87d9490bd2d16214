"""``python -m sliders.forecast``: evaluate the forecasters of the avalanche angle, or forecast a catalogue.

    python -m sliders.forecast evaluate --data prior.h5 --robust zero=zero.h5 --out results/forecast
    python -m sliders.forecast evaluate --dev 300 --out /tmp/forecast      # serial development data
    python -m sliders.forecast predict CATALOGUE.csv [--tilt-now ANGLE] [--json] [--model FILE]
    python -m sliders.forecast predict CATALOGUE.csv --method all --size-unit arbitrary --verbose
    python -m sliders.forecast train --prior my.toml --out my_model.zip --np 2
    python -m sliders.forecast infer CATALOGUE.csv [--tilt-now ANGLE] [--json] [--plot FILE.png]
    python -m sliders.forecast train --data prior.h5 --fit posterior --out my_posterior.zip
    python -m sliders.forecast catalogue --data prior.h5 --row 7 --lead 3deg --out row7.csv

The parser and the error boundary.  Each subcommand is the function of the
same name in the module of the same name (``evaluate``, ``predict``,
``train``, ``catalogue``, ``infer``), imported when it runs: ``--help`` reads no
scikit-learn.

Every subcommand runs inside one error boundary (``main``): parse, check the
options, check the inputs and outputs, compute, publish; every failure is one
line (status 2 for bad input, 1 for an I/O error or a fault, 128 + signal when
stopped).  A new subcommand adds its options in ``build_parser``, its module
and function (the subcommand's name) to ``COMMANDS``, and raises
``ForecastInputError`` for bad input.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import time

from ..parallel import (MPIUnavailable, error_line, get_comm, launcher_rank, stopped_job_status,
                        under_mpi_launcher)
from ..signals import STOP_SIGNALS, stop_signal, stopped_by_sigterm
from ...forecasting.common import (ALARM_DELTA_DEG, CHECK_DRAWS, DEFAULT_LEADS_DEG, DEFAULT_TILTS,
                     POSTERIOR_MAX_ITER, PREDICT_METHODS, TRAIN_MAX_ITER)

#: the subcommands: each is the function of its name in the module of its name (this package's)
COMMANDS = ("evaluate", "predict", "train", "catalogue", "infer")


class _Parser(argparse.ArgumentParser):
    """argparse whose refusal of the command line is one line (``ForecastInputError``)."""

    def error(self, message):
        """Raise the one-line refusal (exit status 2)."""
        raise _refusal().command_line_error(f"{message} (see {self.prog} --help)")


def _refusal():
    """The module that says what a failed command says (``refusal``), read when one fails."""
    return importlib.import_module(f"{__package__}.refusal")


def build_parser() -> argparse.ArgumentParser:
    """The subcommands' parsers (``COMMANDS`` names each one's module and function)."""
    p = _Parser(prog="python -m sliders.forecast", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    add_evaluate_arguments(sub.add_parser(
        "evaluate", help="fit, test and score every forecaster; table and figures"))
    add_predict_arguments(sub.add_parser(
        "predict", help="forecast the avalanche angle of a measured catalogue"))
    add_train_arguments(sub.add_parser(
        "train", help="run a prior ensemble and fit the forecasters of a model file"))
    add_catalogue_arguments(sub.add_parser(
        "catalogue", help="write a simulated row as a catalogue CSV cut at a tilt or lead"))
    add_infer_arguments(sub.add_parser(
        "infer", help="the posterior of the pile's material parameters from a measured catalogue"))
    return p


def add_evaluate_arguments(e: argparse.ArgumentParser) -> None:
    """The options of ``evaluate``."""
    src = e.add_mutually_exclusive_group(required=True)
    src.add_argument("--data", metavar="PRIOR.h5", help="prior ensemble split into train/validation/test")
    src.add_argument("--dev", type=int, metavar="R", help="run R realisations here instead (development)")
    e.add_argument("--robust", action="append", default=[], metavar="LABEL=FILE.h5",
                   help="a test-only set with another preparation (repeatable)")
    e.add_argument("--out", default=os.path.join("results", "forecast"), help="output directory")
    e.add_argument("--figures", default=None, help="where the figures go (default --out)")
    e.add_argument("--fractions", type=float, nargs=3, default=(0.5, 0.1, 0.4),
                   metavar=("TRAIN", "VALID", "TEST"), help="the split by realisation")
    e.add_argument("--leads-deg", type=float, nargs="+", default=list(DEFAULT_LEADS_DEG),
                   metavar="DEG", help="leads before the avalanche at which test runs are cut, degrees")
    e.add_argument("--tilts", type=float, nargs="+", default=list(DEFAULT_TILTS),
                   help="fixed tilts at which the test runs are cut, radians")
    e.add_argument("--boot", type=int, default=400, help="bootstrap resamples")
    e.add_argument("--alarm-rows", type=int, default=1000, help="test realisations for the alarm")
    e.add_argument("--max-iter", type=int, default=300, help="boosting iterations")
    e.add_argument("--only", default=None, help="comma-separated forecaster names (and the baselines)")
    e.add_argument("--seed", type=int, default=0,
                   help="key of the split and of the forecasters' random draws")
    e.add_argument("--all-tables", action="store_true", help="print every lead and tilt")
    e.add_argument("--no-figures", action="store_true", help="publish no figures")
    e.add_argument("--quiet", action="store_true", help="no progress lines")


def add_predict_arguments(pr: argparse.ArgumentParser) -> None:
    """The options of ``predict``."""
    add_measured_catalogue_arguments(pr)
    pr.add_argument("--within", default=ALARM_DELTA_DEG, metavar="ANGLE",
                    help="the alarm's horizon: 1deg, 0.02rad, or a bare number of degrees")
    pr.add_argument("--model", default=None, metavar="FILE",
                    help="model file written by train or evaluate (default: the one shipped "
                         "inside the package)")
    pr.add_argument("--method", default="learned", choices=PREDICT_METHODS,
                    help="the forecaster, one of {" + ", ".join(PREDICT_METHODS)
                         + "} (all: every one side by side)")
    pr.add_argument("--json", action="store_true",
                    help="one JSON object (radians); with --follow one per update (JSON Lines)")
    pr.add_argument("--plot", default=None, metavar="FILE.png",
                    help="draw the catalogue against tilt and the forecast into FILE.png "
                         "(replaced whole, at each update with --follow)")
    pr.add_argument("--size-label", default=None, metavar="TEXT",
                    help="the sizes' unit as --plot's axis names it, e.g. 'mm²' or 'grains' "
                         "(default: sliders, or \"CSV's unit\" with --size-unit arbitrary); "
                         "a label only: the sizes are read as --size-unit says")
    pr.add_argument("--follow", action="store_true",
                    help="keep following the file (-: standard input) as the acquisition "
                         "appends to it, and forecast again when rows arrive or the tilt "
                         "advances (a bad row is named and skipped); stops at a '# avalanche' "
                         "line or --until (status 0), on Ctrl-C (130) or SIGTERM (143)")
    pr.add_argument("--tilt-rate", default=None, metavar="RATE",
                    help="with --follow: the tilt advances at RATE (0.1deg/s, 0.002rad/s, or "
                         "a bare number of degrees per second) from the latest of --tilt-now, "
                         "a '# tilt-now ANGLE' line and an event, from when it was read")
    pr.add_argument("--until", default=None, metavar="ANGLE",
                    help="with --follow: stop once the tilt reaches ANGLE (27deg, 0.47rad, or "
                         "a bare number of degrees)")
    pr.add_argument("--alarm-threshold", default=None, metavar="P",
                    help="the alarm sounds when P(avalanche within --within) reaches P, above "
                         "0.05 and at most 0.95 (default: the forecaster's own, 0.5); without "
                         "--follow, --json's 'alarm' and a last line say whether it does")
    pr.add_argument("--alarm-release", default=None, metavar="P",
                    help="with --follow: a raised alarm stays raised until P(within) falls "
                         "below P (default: 0.1 below the threshold, or half a threshold "
                         "below 0.2)")
    pr.add_argument("--on-alarm", default=None, metavar="'CMD ARGS'",
                    help="with --follow: run CMD ARGS (one argument, split as a shell splits "
                         "words, run without a shell) each time the alarm is raised, the "
                         "forecast in its environment (SLIDERS_ALARM_P, SLIDERS_ALARM_ANGLE_DEG, "
                         "...; docs/forecasting.md)")
    pr.add_argument("--verbose", action="store_true", help="print the model's whole provenance")


def add_measured_catalogue_arguments(pr: argparse.ArgumentParser) -> None:
    """The catalogue and how it was measured: the options ``predict`` and ``infer`` share."""
    pr.add_argument("catalogue", metavar="CATALOGUE.csv",
                    help="the measured events: angle [deg] or angle [rad], size (docs/forecasting.md)")
    pr.add_argument("--tilt-now", default=None, metavar="ANGLE",
                    help="tilt reached: 27.5deg, 0.48rad, or a bare number in the catalogue's "
                         "angle unit (its header's [deg] or [rad]); default: the last event's "
                         "angle.  Below it by less than 3 angle resolutions, the last event's "
                         "angle is taken (and said)")
    pr.add_argument("--angle-resolution", default="0", metavar="ANGLE",
                    help="standard deviation of each measured angle's error: 0.3deg, 0.005rad, "
                         "or a bare number of degrees")
    pr.add_argument("--min-size", type=float, default=1.0, metavar="SIZE",
                    help="smallest event size detected, in the size column's unit: sliders, or "
                         "with --size-unit arbitrary the unit of your sizes (grains, pixels, "
                         "mm²), read against the catalogue's median size")
    pr.add_argument("--missed-fraction", type=float, default=0.0, metavar="SHARE",
                    help="share of events missed at random, in [0, 1)")
    pr.add_argument("--size-unit", default="sliders", choices=("sliders", "arbitrary"),
                    help="sliders: sizes count sliders; arbitrary: an unknown unit (grains, area, pixels)")
    pr.add_argument("--sliders", default=None, metavar="N",
                    help="the number of sliders of the pile, or a range (100-300), if known: "
                         "a pile outside the training piles' is out of the domain")
    pr.add_argument("--displacement-unit", default="model", choices=("model", "arbitrary"),
                    help="model: displacements in g tau^2; arbitrary: a camera's unit (pixels, "
                         "mm, any positive scale), read relative to the catalogue's own")
    pr.add_argument("--position-unit", default="sliders", choices=("sliders", "fraction", "mm"),
                    help="the movers' positions (first, last) -- sliders: slider indices from "
                         "the up-slope end; fraction: fractions of the pile's length from that "
                         "end; mm: millimetres from it (with --pile-length)")
    pr.add_argument("--pile-length", type=float, default=None, metavar="MM",
                    help="the pile's length along the slope in mm (with --position-unit mm)")


def measurement_options(args) -> dict:
    """The measurement's keywords of the API (``ForecastModel.predict``) from the flags."""
    return {"angle_resolution": args.angle_resolution, "min_size": args.min_size,
            "missed_fraction": args.missed_fraction, "size_unit": args.size_unit,
            "sliders": args.sliders, "displacement_unit": args.displacement_unit,
            "position_unit": args.position_unit, "pile_length": args.pile_length}


def add_infer_arguments(inf: argparse.ArgumentParser) -> None:
    """The options of ``infer``."""
    add_measured_catalogue_arguments(inf)
    inf.add_argument("--posterior", default=None, metavar="FILE",
                     help="posterior file written by train --fit posterior (default: the one "
                          "shipped inside the package)")
    inf.add_argument("--json", action="store_true",
                     help="one JSON object: each parameter's median and 80 and 95 %% intervals, "
                          "the contraction, the domain, the predictive check")
    inf.add_argument("--plot", default=None, metavar="FILE.png",
                     help="draw the marginals and pairs of the posterior (a corner plot, the "
                          "prior's range shaded) into FILE.png")
    inf.add_argument("--no-check", action="store_true",
                     help="skip the predictive check (the piles simulated at posterior draws)")
    inf.add_argument("--check-draws", type=int, default=CHECK_DRAWS, metavar="R",
                     help="piles simulated at posterior draws for the predictive check")
    inf.add_argument("--seed", type=int, default=0,
                     help="key of the posterior draws and of the check's simulations")


def add_train_arguments(t) -> None:
    """The options of ``train``."""
    src = t.add_mutually_exclusive_group(required=True)
    src.add_argument("--prior", metavar="PRIOR.toml", help="run this prior ensemble, then fit")
    src.add_argument("--data", nargs="+", metavar="PRIOR.h5",
                     help="fit on prior files already computed (several: their rows together)")
    t.add_argument("--out", required=True, metavar="MODEL.zip", help="the model file written")
    t.add_argument("--np", type=int, default=1, help="MPI ranks of the prior ensemble")
    t.add_argument("--fit", default="forecasters", choices=("forecasters", "posterior"),
                   help="what --out holds: forecasters (the forecasters of predict) or "
                        "posterior (the posterior of the pile's parameters, read by infer)")
    t.add_argument("--max-iter", type=int, default=None,
                   help=f"boosting iterations (default {TRAIN_MAX_ITER}; "
                        f"{POSTERIOR_MAX_ITER} with --fit posterior)")
    t.add_argument("--calibration-data", nargs="+", default=None, metavar="PRIOR.h5",
                   help="with --fit posterior: the same prior drawn with other seeds, whose "
                        "rows calibrate the posterior beside its held-out share (none is fitted)")
    t.add_argument("--hold-out", type=float, default=0.0, metavar="SHARE",
                   help="share of the rows kept out of the fit, to measure the model on "
                        "(their indices go into the provenance)")
    t.add_argument("--seed", type=int, default=0, help="key of the fit's random draws")
    t.add_argument("--quiet", action="store_true", help="no progress lines")


def add_catalogue_arguments(c) -> None:
    """The options of ``catalogue``."""
    c.add_argument("--data", required=True, metavar="PRIOR.h5", help="a prior ensemble file")
    c.add_argument("--row", type=int, required=True, help="the realisation")
    at = c.add_mutually_exclusive_group(required=True)
    at.add_argument("--lead", metavar="ANGLE", help="cut this far before the avalanche, e.g. 3deg")
    at.add_argument("--at", metavar="ANGLE", help="cut at this tilt, e.g. 25deg")
    c.add_argument("--out", required=True, metavar="FILE.csv", help="the catalogue CSV written")


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m sliders.forecast``: every failure is one line on stderr
    (status 2 for bad input, 1 for an I/O error or a fault, 128 + signal when stopped).

    Under ``mpirun -n K`` (K > 1) rank 0 runs the command and the other ranks wait for its
    status: a job stopped by SIGINT or SIGTERM then ends by ``MPI_Abort(128 + signal)``, the
    one way MPICH's ``mpiexec`` returns it when the terminal's Ctrl-C reaches it too."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not under_mpi_launcher():
        return _command(argv)
    try:
        comm, _ = get_comm()
    except MPIUnavailable:
        comm = None
    if comm is None or comm.size < 2:  # no MPI to wait with (or srun's tasks without it):
        return 0 if launcher_rank() > 0 else _command(argv, resignal=True)  # rank 0 alone
    if comm.rank > 0:
        return _wait_for_rank_0(comm)
    code = 1  # what the others hear if an exception escapes the error boundary
    try:
        code = _command(argv)
    except SystemExit as exc:  # --help (argparse's exit): the others must still hear of it
        code = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    finally:
        for rank in range(1, comm.size):
            comm.send(code, dest=rank, tag=_STATUS_TAG)
    return stopped_job_status(comm, code)


_STATUS_TAG = 17  # rank 0's exit status, to the ranks that wait for it


def _wait_for_rank_0(comm) -> int:
    """Rank 0's exit status, polled (no core kept busy); a stop signal here is rank 0's to act
    on (the terminal's Ctrl-C reaches every rank), so it is ignored."""
    for s in STOP_SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    pending = comm.irecv(source=0, tag=_STATUS_TAG)
    while True:
        done, code = pending.test()
        if done:
            return code
        time.sleep(0.05)


def _command(argv: list[str], resignal: bool = False) -> int:
    """Parse and run one subcommand inside the error boundary; ``resignal``: a stopped command
    ends by its signal (a lone rank under a launcher, which reads the signal itself)."""
    try:
        with stopped_by_sigterm():
            args = build_parser().parse_args(argv)
            module, function = ((("follow", "follow_command") if getattr(args, "follow", False)
                                 else (args.command, args.command)))
            command = importlib.import_module(f"{__package__}.{module}")
            return getattr(command, function)(args, argv)
    except KeyboardInterrupt as exc:
        signum = stop_signal(exc)
        code = _error(f"interrupted ({signal.Signals(signum).name}); nothing half-written was "
                      "published", 128 + signum)
        if resignal:
            sys.stdout.flush()
            sys.stderr.flush()
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
        return code
    except Exception as exc:  # noqa: BLE001 - bad input, an I/O error or a fault: one line
        code, line = _refusal().status_and_line(exc)
        return _error(line, code)


def _error(message: str, code: int) -> int:
    print(f"sliders.forecast: {error_line(message)}", file=sys.stderr, flush=True)
    return code
