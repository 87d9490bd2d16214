"""``python -m sliders.forecast infer``: the posterior of the pile's material from its catalogue.

    python -m sliders.forecast infer CATALOGUE.csv [--tilt-now ANGLE] [--json] [--plot FILE.png]

The options are checked here; the posterior and its predictive check are the forecasting
layer's (``sliders.forecasting.infer``), given how the check's piles are made
(``CHECK_SIMULATION``): the prior's base scene by ``prior_base_scene`` (a posterior stores the
prior it was fitted on as the ``prior`` command's specification), each pile run by
``simulate_pile``, stoppable by a signal.
"""

from __future__ import annotations

import json
import math

from ...driver import run
from ...forecasting.catalogue import measurement_from, prepared, read_source
from ...forecasting.infer import MAX_CHECK_DRAWS, PileSimulation, load_posterior
from ...io.forecast_files import ForecastInputError, angle_option, parse_angle, tilt_in_range
from ...io.forecast_model import default_posterior_path
from ...preparation import prepare
from ...scene import check_memory
from ..command import DEFAULT_BACKEND
from ..prior_spec import parse_prior
from .cli import measurement_options
from .predict import check_plot_target


def prior_base_scene(spec: dict):
    """The base scene of the prior a posterior stores (the ``prior`` command's specification)."""
    return parse_prior(spec, "the posterior's prior").base_scene


def simulate_pile(scene, backend: str = DEFAULT_BACKEND):
    """The run of one pile of the check (``driver.run``), stopped at once by Ctrl-C or SIGTERM.

    The run's memory is checked first (``scene.check_memory``), then the chain is prepared
    here, outside the run: ``run`` finishes a preparation a signal interrupts (the milliseconds
    of Python around its engine), which for a pile of millions of sliders is half a minute
    and more; here the signal's exception goes on up at once.  The same state, so the same
    run as ``run(scene)``.  A history preparation (``initial_forces = "history"``) answers a
    signal with ``PreparationInterrupted``, a KeyboardInterrupt too."""
    check_memory(scene)
    return run(scene, backend, state=prepare(scene))


#: how ``infer``'s predictive check makes its piles: the stored prior's base scene, each pile
#: run on the commands' default backend, stoppable by a signal
CHECK_SIMULATION = PileSimulation(prior_base_scene, simulate_pile)


def infer(args, argv=None) -> int:
    """The posterior of a measured catalogue: the text (or ``--json``), the corner plot."""
    check_infer_options(args)
    # the catalogue read and checked before the posterior's seconds of loading
    measurement = measurement_from(**measurement_options(args))
    cat, notes = prepared(read_source(args.catalogue, angle_resolution=measurement.angle_resolution,
                                      position_unit=measurement.position_unit),
                          args.tilt_now, measurement)
    model = load_posterior(args.posterior, CHECK_SIMULATION)
    result = model.infer_catalogue(cat, measurement, not args.no_check, args.check_draws,
                                   args.seed, notes)
    print(json.dumps(result.to_dict()) if args.json else str(result))
    if args.plot:
        result.plot(args.plot)
    return 0


def check_infer_options(args) -> None:
    """The options of ``infer`` in range (one line naming the option), before a file is read."""
    if args.tilt_now is not None:
        if not isinstance(args.tilt_now, str) or not args.tilt_now.strip():
            raise ForecastInputError("--tilt-now: give the tilt reached, e.g. 27.5deg or 0.48rad")
        tilt_in_range(parse_angle(args.tilt_now, math.pi / 180.0), f"--tilt-now {args.tilt_now}")
    angle_option(args.angle_resolution, "--angle-resolution")
    if not 3 <= args.check_draws <= MAX_CHECK_DRAWS:
        raise ForecastInputError(f"--check-draws {args.check_draws}: must lie in "
                                 f"[3, {MAX_CHECK_DRAWS}]")
    if not 0 <= args.seed < 2**32:
        raise ForecastInputError(f"--seed {args.seed}: must lie in [0, 2^32)")
    check_plot_target(args.plot, {
        "the catalogue": args.catalogue,
        "the posterior file": (args.posterior if args.posterior is not None
                               else default_posterior_path())})
