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

Scheduling is the ensemble's (``ensemble._Root`` / ``ensemble._worker``, dynamic,
one file): row t of the run is realisation ``t % R`` of point ``t // R``; the
queue holds the rows of the most expensive points first (cost ~ N^2 / dt), so
that the last rows to finish are short ones.  A row depends only on its point
and realisation, so the file is the same with any number of ranks.

The file (one group per point, the ensemble layout in each, and a view xarray
opens as one dataset): ``sliders.io.study_file``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

import numpy as np

from ..io.study_file import (HANDLERS, read_study_header, study_attributes, study_layout,
                            write_view)
from .parallel import abort

from ..analysis.study_spec import (NOT_AXES, STUDY_PREFIX, Study, StudyError,  # noqa: F401 - kept importable here
                                      check_points_memory, load_study, parse_study)


# ---------------------------------------------------------------------------
# the rows: one (point, realisation) pair each
# ---------------------------------------------------------------------------
def extra_statistics(result) -> dict[str, np.ndarray]:
    """Burst periods and the synchronisation share of one run (REPRODUCTION.md definitions)."""
    from ..analysis.reproduction import burst_periods, sync_profile

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


EXTRA_LAYOUT = {STUDY_PREFIX + k: ((), t) for k, t in (
    ("early_period", np.float64), ("early_pred", np.float64), ("early_n", np.int64),
    ("late_period", np.float64), ("late_n", np.int64), ("sync_share", np.float64),
    ("sync_event_share", np.float64))}


def _point_statistics(scene, grids=None) -> dict:
    """The statistics columns of one point's rows (the ensemble's plus the study's own)."""
    from ..analysis.observables import default_grids, statistics_layout

    stats = dict(statistics_layout(grids or default_grids(scene), scene.n_sliders))
    stats.update(EXTRA_LAYOUT)
    return stats


def _point_layout(study: Study, p: int, backend: str):
    from ..keyed_random import realisation_seed
    from ..analysis.observables import default_grids
    from ..io.storage import file_attributes, make_layout

    scene = study.scenes[p]
    R = study.realisations
    seeds = [realisation_seed(study.base_seed, r) for r in range(R)]  # the same at every point
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
def build_parser(rank: int = 0) -> argparse.ArgumentParser:
    """The command line of ``python -m sliders.study`` (help printed by rank 0 only)."""
    from .ensemble import _Parser, add_output_options
    from ..io.storage import STORAGES

    p = _Parser(prog="python -m sliders.study",
                description="Sweep scene parameters: R realisations (common random numbers: the "
                            "same seeds at every point) at each point of the product of the axes, "
                            "over MPI ranks with the ensemble's dynamic scheduling, into one HDF5 "
                            "file (one group per point).")
    p.rank = rank
    p.add_argument("study", metavar="STUDY.toml", help="study file: [study], [scene], [axes]")
    add_output_options(p)
    p.add_argument("--storage", choices=STORAGES, default="auto", help="file writer (as ensemble)")
    return p


def _plan_root(args, study: Study) -> dict[str, Any]:
    """Rank 0, holding the claim: new file or resume against the same study."""
    from .ensemble import DEFAULT_BACKEND, UsageError
    from ..analysis.study_spec import spec_difference
    from ..io.storage import StorageError, check_room, statistics_row_bytes

    out = args.out
    backend = args.backend or DEFAULT_BACKEND
    resume = args.resume and os.path.exists(out)
    if os.path.exists(out) and not (args.overwrite or resume):
        raise UsageError(f"--out {out!r} exists; pass --resume to complete it or --overwrite "
                         "to replace it")
    P, R = len(study.points), study.realisations
    done = np.zeros(P * R, dtype=bool)
    attrs = None
    if resume:
        try:
            head = read_study_header(out)
        except StorageError as exc:
            raise UsageError(f"--resume: {exc}") from None
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
    return {"layout": layout, "resume": resume, "done": done, "pending": pending,
            "backend": backend}


def main(argv: list[str] | None = None) -> int:
    """``python -m sliders.study STUDY.toml --out FILE.h5``: run (or resume) a study; the exit code."""
    from .ensemble import _claim_output, check_run_options, compute_row, run_planned

    def prepare(comm, have_mpi, node_ranks, claims):  # a StudyError is a ValueError
        args = build_parser(comm.rank).parse_args(argv)
        storage = check_run_options(args, comm, have_mpi)
        study = load_study(args.study)
        check_points_memory(study, node_ranks)  # every point, before the file is created
        plan = None
        if comm.rank == 0:
            claims.append(_claim_output(args, "study"))
            plan = _plan_root(args, study)
        return args, study, storage, plan

    return run_planned(prepare, lambda comm, args, study, storage, plan:
                       _run(args, comm, study, plan, storage, compute_row))


def _run(args, comm, study, plan, storage, compute_row) -> int:
    from .ensemble import _error_line, serve_rows
    from ..analysis.observables import StatisticsGrids
    from ..io.safeio import os_reason

    rank = comm.rank
    layout = plan["layout"]
    handler = err = None
    try:
        cls = HANDLERS[storage]
        if not plan["resume"]:
            cls.create(args.out, layout, comm, overwrite=args.overwrite).close()
        handler = cls.open_for_resume(args.out, layout, comm)
    except Exception as exc:  # noqa: BLE001
        err = f"cannot {'open' if plan['resume'] else 'create'} {args.out!r}: {os_reason(exc)}"
    errors = comm.allgather(err)
    if any(errors):
        if rank == next(i for i, e in enumerate(errors) if e):
            sys.stderr.write(_error_line(errors[rank]) + "\n")
        if all(errors):
            return 1
        abort(comm)

    R = study.realisations
    grids = [StatisticsGrids.from_arrays(lay.grids) for lay in layout.points]
    backend = plan["backend"]

    def compute(t: int, progress):
        p, r = divmod(int(t), R)
        # the point's scene keeps the base seed: realisation r has the same seed at every point
        return compute_row(study.scenes[p], r, backend, grids[p], progress, 0, extra_statistics)

    pending = plan["pending"]
    total = len(study.points) * R
    ctx = {"R": total, "compute_row": compute, "interval": args.progress_interval,
           "quiet": args.quiet, "label": ("study", "(point, realisation) rows")}
    if rank == 0 and not args.quiet:
        verb = "resuming" if plan["resume"] else "starting"
        sys.stderr.write(f"study: {verb} {pending.size} of {total} rows ({len(study.points)} points "
                         f"x {R} realisations, backend {backend}) on {comm.size} rank(s), storage "
                         f"{storage} -> {args.out}\n")
        sys.stderr.flush()
    return serve_rows(comm, handler, pending, total, ctx, "study", args.out,
                      lambda: write_view(args.out, study))


if __name__ == "__main__":
    sys.exit(main())
