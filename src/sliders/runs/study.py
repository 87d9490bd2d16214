"""``python -m sliders.study STUDY.toml --out FILE.h5``: a sweep over scene parameters.

    mpirun -n 2 python -m sliders.study mpi_runs/scenes/study_dmu.toml --out dmu.h5

A study file holds the base scene, the axes and the number of realisations::

    [study]
    realisations = 8          # R per point
    zip = [["mu_d", "sigma_mu"]]   # optional: axes that vary together (equal lengths)
    [scene]                   # the base scene (keys of sliders.Scene)
    n_sliders = 100
    [axes]                    # scene parameter -> list of values; points = their product
    xi = [0, 1e-4, 1e-3]
    mu_d = [0.5, 0.55]

Common random numbers: realisation r has the seed ``realisation_seed(seed, r)``
at every point, so that two points differ only by their parameters and their
difference is measured on pairs (``study_analysis``).  ``seed`` cannot be an
axis for that reason.

Scheduling is every run command's (``runs.scheduler``, dynamic, one file; the
command's shape: ``runs.command``): row t of the run is realisation ``t % R`` of point ``t // R``; the
queue holds the rows of the most expensive points first (cost ~ N^2 / dt), so
that the last rows to finish are short ones.  A row depends only on its point
and realisation, so the file is the same with any number of ranks.

The file (one group per point, the ensemble layout in each, and a view xarray
opens as one dataset): ``sliders.io.study_file``.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from .command import (DEFAULT_BACKEND, CommandParser, RunCommand, RunPlan, UsageError,
                      add_storage_option, resume_header, check_run_options,
                      input_command_parser, open_output, run_planned)
from .rows import compute_row, realisation_seeds
from .scheduler import serve_rows
from ..io.study_file import (HANDLERS, read_study_header, study_attributes, study_layout,
                            write_view)

from ..analysis.observables import (StatisticsGrids, default_grids, statistic_conventions,
                                    statistics_layout)
from ..analysis.study_spec import STUDY_PREFIX, Study, check_points_memory, load_study
from ..analysis.precursors import burst_periods, sync_profile
from ..analysis.study_spec import spec_difference
from ..io.storage import (StorageError, check_room, file_attributes, make_layout,
                          statistics_row_bytes)


# ---------------------------------------------------------------------------
# the rows: one (point, realisation) pair each
# ---------------------------------------------------------------------------
def extra_statistics(result) -> dict[str, np.ndarray]:
    """Burst periods and the synchronisation share of one run (REPRODUCTION.md definitions)."""
    sc = result.scene
    bp = burst_periods([result], sc.delta_mu, sc.mu_s_mean)
    sy = sync_profile([result])
    return {
        STUDY_PREFIX + "early_period": np.float64(bp["early_median"]),
        STUDY_PREFIX + "early_pred": np.float64(bp["early_pred"]),
        STUDY_PREFIX + "early_n": np.int64(bp["early_n"]),
        STUDY_PREFIX + "late_period": np.float64(bp["late_median"]),
        STUDY_PREFIX + "late_n": np.int64(bp["late_n"]),
        STUDY_PREFIX + "sync_share": np.float64(sy["overall_weighted"]),
        STUDY_PREFIX + "sync_event_share": np.float64(sy["overall"]),
    }


#: the study's own statistics (``extra_statistics``), one number a row: name -> (dtype, units,
#: meaning)
STUDY_STATISTICS = {STUDY_PREFIX + k: v for k, v in {
    "early_period": (np.float64, "rad", "median angle between two lone slips of one slider "
                                        "below alpha = 0.3"),
    "early_pred": (np.float64, "rad", "median single-slider period 2 dmu / (1 + mu_s tan alpha) "
                                      "at those slips"),
    "early_n": (np.int64, "1", "number of those early periods"),
    "late_period": (np.float64, "rad", "median angle between two group slips (size >= 3) of one "
                                       "slider above alpha = 0.35"),
    "late_n": (np.int64, "1", "number of those late periods"),
    "sync_share": (np.float64, "1", "share of the displacement in events of two or more groups"),
    "sync_event_share": (np.float64, "1", "share of the events of two or more groups"),
}.items()}
EXTRA_LAYOUT = {k: ((), dtype) for k, (dtype, _, _) in STUDY_STATISTICS.items()}


def _point_statistics(scene, grids=None) -> dict:
    """The statistics columns of one point's rows (the ensemble's plus the study's own)."""
    stats = dict(statistics_layout(grids or default_grids(scene), scene.n_sliders))
    stats.update(EXTRA_LAYOUT)
    return stats


def _point_layout(study: Study, p: int, backend: str):
    scene = study.scenes[p]
    R = study.realisations
    seeds = realisation_seeds(study.base_seed, 0, R)  # the same at every point
    grids = default_grids(scene)
    stats = _point_statistics(scene, grids)
    attrs = file_attributes(scene.to_dict(), study.base_seed, R, backend)
    attrs.update({"point": p, "point_values": json.dumps(study.points[p])})
    return make_layout(R, seeds, grids.to_arrays(), stats, attrs)


def make_study_layout(study: Study, backend: str, attrs: dict | None = None):
    """The file's layout: one ensemble layout per point (``points``) under study attributes."""
    layouts = [_point_layout(study, p, backend) for p in range(len(study.points))]
    return study_layout(layouts, study.realisations, attrs or study_attributes(study, backend))


# ---------------------------------------------------------------------------
# command line and run
# ---------------------------------------------------------------------------
def build_parser(rank: int = 0) -> CommandParser:
    """The command line of ``python -m sliders.study`` (help printed by rank 0 only)."""
    p = input_command_parser(
        "python -m sliders.study",
        "Sweep scene parameters: R realisations (common random numbers: the same seeds at every "
        "point) at each point of the product of the axes, over MPI ranks with dynamic scheduling, "
        "into one HDF5 file (one group per point).",
        rank, "study", "STUDY.toml", "study file: [study], [scene], [axes]")
    add_storage_option(p)
    return p


def plan_study(args, study: Study) -> RunPlan:
    """Rank 0, holding the claim: new file or resume against the same study."""
    out = args.out
    backend = args.backend or DEFAULT_BACKEND
    head = resume_header(args, read_study_header)
    resume = head is not None
    P, R = len(study.points), study.realisations
    done = np.zeros(P * R, dtype=bool)
    attrs = None
    if resume:
        attrs = head["attrs"]
        differ = (spec_difference(json.loads(attrs["study"]), study, repr(args.study))
                  if attrs.get("study_digest") != study.digest else "")
        if differ:  # compared by meaning: the same study written differently is the same
            raise UsageError(f"--resume: {out!r} holds a different study ({differ}); start a new "
                             "file or resume with the study file that made it")
        if args.backend is not None and attrs["backend"] != args.backend:
            raise UsageError(f"--resume: {out!r} was computed with --backend {attrs['backend']}")
        backend = attrs["backend"]
        done = np.concatenate(head["done"])
        n_bad = sum(len(b) for b in head["damaged"])
        if n_bad:
            sys.stderr.write(f"study: note: {n_bad} finished row(s) of {out} fail their "
                             "checksums; recomputing them\n")
    if not resume:  # before any per-row array: an absurd count is refused at once
        try:
            check_room(out, R, sum(statistics_row_bytes(_point_statistics(scene))
                                   for scene in study.scenes))
        except StorageError as exc:
            raise UsageError(f"[study] realisations = {R}: {exc}") from None
    layout = make_study_layout(study, backend, attrs)
    # most expensive points first (then realisation order), so that the tail is short
    order = sorted(range(P), key=lambda p: (-study.cost(p), p))
    tasks = [p * R + r for p in order for r in range(R)]
    pending = np.array([t for t in tasks if not done[t]], dtype=np.int64)
    return RunPlan(layout, backend, resume, done, pending)


def prepare_study(args, inputs, world) -> dict:
    """The study and every point's memory (every rank, rank 0's bytes); a StudyError is a
    ValueError."""
    storage = check_run_options(args, world.comm, world.have_mpi)
    study = load_study(args.study, inputs[args.study])
    check_points_memory(study, world.node_ranks)  # every point, before the file is created
    return {"study": study, "storage": storage}


def run_study(comm, args, local, plan: RunPlan) -> int:
    """Create or open the file, serve the rows, report (every rank)."""
    study, storage = local["study"], local["storage"]
    handler = open_output(comm, args, plan, HANDLERS, storage)
    if handler is None:
        return 1
    R = study.realisations
    grids = [StatisticsGrids.from_arrays(lay.grids) for lay in plan.layout.points]

    def compute(t: int, progress):
        p, r = divmod(int(t), R)
        # the point's scene keeps the base seed: realisation r has the same seed at every point
        return compute_row(study.scenes[p], r, plan.backend, grids[p], progress, 0,
                           extra_statistics)

    ctx = {"compute_row": compute, "interval": args.progress_interval, "quiet": args.quiet,
           "label": ("study", "(point, realisation) rows")}
    if comm.rank == 0 and not args.quiet:
        sys.stderr.write(f"study: {'resuming' if plan.resume else 'starting'} "
                         f"{plan.pending.size} of {plan.total} rows ({len(study.points)} "
                         f"points x {R} realisations, backend {plan.backend}) on {comm.size} "
                         f"rank(s), storage {storage} -> {args.out}\n")
        sys.stderr.flush()
    return serve_rows(comm, handler, plan.pending, plan.total, ctx, args.out,
                      lambda: write_view(args.out, study, study_conventions()))


def study_conventions() -> dict:
    """What a study file says of every statistic of its rows (``io.conventions.ensemble_variables``):
    the ensemble's and the study's own."""
    return {**statistic_conventions(),
            **{k: ((), units, meaning) for k, (_, units, meaning) in STUDY_STATISTICS.items()}}


def main(argv: list[str] | None = None) -> int:
    """``python -m sliders.study STUDY.toml --out FILE.h5``: run (or resume) a study; the exit code."""
    return run_planned(RunCommand("study", build_parser, prepare_study,
                                  lambda args, local: plan_study(args, local["study"]), run_study,
                                  input_option=("study", "study file")), argv)


if __name__ == "__main__":
    sys.exit(main())
