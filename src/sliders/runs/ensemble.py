"""``python -m sliders.ensemble``: many realisations of one scene over MPI ranks, one HDF5 file.

    mpirun -n 2 python -m sliders.ensemble --scene S.toml --realisations 100 --out E.h5
    python -m sliders.ensemble --n-sliders 10 --realisations 4 --out E.h5   # serial

Realisation ``r`` is the scene with seed ``realisation_seed(scene.seed, r)``;
its row of the file (``storage`` module) depends on nothing else, so the file
is the same (bit for bit, apart from wall times and the creation date) with 1,
2 or 4 ranks.

The command's shape (agreement rounds, claim, plan) is ``runs.command``; the
rows are served dynamically over the ranks by ``runs.scheduler``, a row being
``runs.rows.compute_row``.

Storage: ``storage.MpioFile`` (parallel h5py, every rank writes its own rows)
or ``storage.GatherFile`` (rows shipped to rank 0 with the "done" message);
``--storage auto`` picks mpio with several ranks when h5py has MPI.

Interruption: SIGTERM/SIGINT on any rank stops the whole run at the next safe
point (between chunks of events): runs in progress are dropped, rows already
written stay, the file is closed, rank 0 prints one line and every rank exits
with 128 + signal number.  ``--resume`` then computes the missing rows only.

Ensemble statistics are not stored: ``analysis.summary.load_summary(path)`` derives them with
``observables.combine`` from the rows marked done.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from .command import (DEFAULT_BACKEND, CommandParser, RunCommand, RunPlan, UsageError,
                      add_output_options, add_storage_option, check_new_or_resume,
                      check_run_options, open_output, run_planned)
from .merge import chunk_range, parse_chunk
from .rows import compute_row
from .scheduler import serve_rows
from ..analysis.observables import (StatisticsGrids, default_grids, statistic_conventions,
                                    statistics_layout)
from ..parts.checks import SceneError
from ..scene import Scene, check_memory, check_tilt_statistics
from .cli import add_scene_arguments, disagreements, given_scene_values, scene_from_args
from ..driver import make_engine
from ..io.conventions import describe_ensemble_file
from ..io.storage import (HANDLERS, StorageError, check_room, damaged_rows, file_attributes,
                          make_layout, read_header, statistics_row_bytes)
from ..keyed_random import realisation_seed


def build_parser(rank: int = 0) -> CommandParser:
    """The command line of ``python -m sliders.ensemble`` (only ``rank`` 0 prints help and errors)."""
    p = CommandParser(
        prog="python -m sliders.ensemble",
        description="Tilt R realisations of one scene (seed of realisation r = "
                    "realisation_seed(scene seed, r)), spread over MPI ranks with dynamic load "
                    "balancing, into one HDF5 file (one row per realisation).  Run under "
                    "`mpirun -n P` or plainly (serial).",
    )
    p.rank = rank
    add_scene_arguments(p)
    g = p.add_argument_group("ensemble")
    g.add_argument("--realisations", "-R", type=int, metavar="R",
                   help="number of realisations (required unless --resume, which takes the file's)")
    add_output_options(g, progress_interval=5.0)
    add_storage_option(g)
    g.add_argument("--chunk", type=parse_chunk, metavar="I/K",
                   help="compute only chunk I (0..K-1) of K of the R realisations (rows "
                        "I*R//K to (I+1)*R//K - 1, same seeds as in the whole run), e.g. one task "
                        "of a job array; `python -m sliders.merge` joins the chunk files")
    return p


def prepare_ensemble(args, inputs, world) -> dict:
    """Every check that needs no file (every rank, same answer): the scene, the counts,
    the options, the backend, the memory of ``world.node_ranks`` runs."""
    scene = scene_from_args(args, inputs.get(args.scene))
    if args.realisations is not None and args.realisations < 1:
        raise UsageError(f"--realisations={args.realisations} must be at least 1")
    if args.realisations is None and not args.resume:
        raise UsageError("--realisations R is required (unless --resume)", code=2)
    if args.chunk is not None and args.realisations is None:
        raise UsageError("--chunk I/K needs --realisations R (the whole ensemble's)", code=2)
    storage = check_run_options(args, world.comm, world.have_mpi)
    backend = args.backend or DEFAULT_BACKEND
    try:
        make_engine(scene, backend)
    except (ImportError, AttributeError) as exc:  # not built, or built from older sources
        raise UsageError(f"backend {backend!r} is not available ({exc}); "
                         "build it (scripts/setup.sh) or use --backend numpy") from None
    check_tilt_statistics(scene)
    check_memory(scene, world.node_ranks)
    return {"scene": scene, "storage": storage, "scene_values": inputs.get(args.scene)}


def run_ensemble(comm, args, local, plan: RunPlan) -> int:
    """Create or open the file, serve the rows, report (every rank)."""
    storage = local["storage"]
    handler = open_output(comm, args, plan, HANDLERS, storage,
                          lambda path: describe_ensemble_file(path, statistic_conventions()))
    if handler is None:
        return 1
    layout, scene = plan.layout, plan.scene
    grids = StatisticsGrids.from_arrays(layout.grids)
    first = int(layout.attrs.get("first_realisation", 0))

    def row(r, progress):
        return compute_row(scene, r, plan.backend, grids, progress, first)

    ctx = {"compute_row": row, "interval": args.progress_interval, "quiet": args.quiet,
           "label": ("ensemble", "realisations")}
    if comm.rank == 0 and not args.quiet:
        if plan.pending.size == 0:
            sys.stderr.write(f"ensemble: all {plan.total} realisations of {args.out} are "
                             "done already; nothing to do\n")
        else:
            sys.stderr.write(
                f"ensemble: {'resuming' if plan.resume else 'starting'} {plan.pending.size} "
                f"of {plan.total} realisations of N={scene.n_sliders} xi={scene.xi:g} "
                f"(backend {plan.backend}) on {comm.size} rank{'s' if comm.size > 1 else ''}, "
                f"storage {storage} -> {args.out}\n")
        sys.stderr.flush()
    return serve_rows(comm, handler, plan.pending, plan.total, ctx, args.out,
                      rank_timings=True)


def _resumed_scene(args, attrs: dict, scene_text) -> Scene:
    """The scene of the file to resume, checked against the scene options given."""
    out = args.out
    try:
        file_scene = Scene.from_stored(json.loads(attrs["scene"]))
    except (SceneError, ValueError, KeyError) as exc:
        raise UsageError(f"--resume: {out!r} holds an unreadable scene ({exc})") from None
    try:
        differ = disagreements(file_scene, given_scene_values(args, scene_text))
    except SceneError as exc:
        raise UsageError(f"--resume: {exc}") from None
    if differ:
        raise UsageError(f"--resume: {out!r} holds a different scene ({differ}); give no "
                         "scene options with --resume, or ones that agree with the file")
    return file_scene


def _resume_counts(args, attrs: dict, R, first: int) -> tuple[str, int, int]:
    """The backend, count and first realisation of the file to resume, checked against
    the options given."""
    out = args.out
    if R is not None and R != attrs["realisations"]:
        raise UsageError(f"--resume: {out!r} has {attrs['realisations']} realisations, "
                         f"--realisations {R} requested")
    if args.backend is not None and attrs["backend"] != args.backend:
        raise UsageError(f"--resume: {out!r} was computed with --backend {attrs['backend']}, "
                         f"not {args.backend}; resume with the same backend")
    file_first = int(attrs.get("first_realisation", 0))
    if args.chunk is not None and first != file_first:
        raise UsageError(f"--resume: {out!r} starts at realisation {file_first}, chunk "
                         f"{args.chunk[0]}/{args.chunk[1]} at {first}")
    return attrs["backend"], int(attrs["realisations"]), file_first


def _check_resumable(out: str, head: dict, layout, grids: dict) -> np.ndarray:
    """The rows of ``out`` still to compute (missing or failing their checksums); the
    file's grids, columns and seeds must be this version's."""
    for k, v in grids.items():
        if k not in head["grids"] or not np.array_equal(head["grids"][k], v):
            raise UsageError(f"--resume: the statistics grid {k!r} of {out!r} differs from "
                             "this version's; start a new file")
    cols = head["columns"]
    for c in layout.columns:
        if c.name not in cols or tuple(cols[c.name][0]) != c.shape:
            raise UsageError(f"--resume: {out!r} has no dataset /realisations/{c.name} of shape "
                             f"(R, *{c.shape}); it was written by another version of sliders")
    if not np.array_equal(head["seeds"], layout.seeds):
        raise UsageError(f"--resume: the seeds of {out!r} differ from this version's")
    done = head["done"]
    try:
        damaged = damaged_rows(out)
    except StorageError as exc:
        raise UsageError(f"--resume: {exc}") from None
    if damaged:  # recomputed like the missing ones (keyed seeds: the same values)
        done[damaged] = False
        sys.stderr.write(f"ensemble: note: {len(damaged)} finished row(s) of {out} fail "
                         f"their checksums (rows {damaged[:10]}); recomputing them\n")
    return done


def plan_ensemble(args, local: dict) -> RunPlan:
    """Rank 0 (holding the claim on --out): output file checks, resume compatibility, the
    scene and backend (the file's with --resume), the layout; ``local``: ``prepare_ensemble``'s."""
    scene, scene_text = local["scene"], local["scene_values"]
    backend = args.backend or DEFAULT_BACKEND
    out = args.out
    resume = check_new_or_resume(args)
    R = args.realisations
    first = 0  # index of the file's first realisation (a chunk of a larger ensemble)
    if args.chunk is not None:
        first, R = chunk_range(args.chunk, R)
    if R is None and not resume:
        raise UsageError(f"--resume: {out!r} does not exist; give --realisations R to start it")
    if resume:
        try:
            head = read_header(out)
        except StorageError as exc:
            raise UsageError(f"--resume: {exc}") from None
        scene = _resumed_scene(args, head["attrs"], scene_text)
        backend, R, first = _resume_counts(args, head["attrs"], R, first)
    # record = "summary": the per-realisation summary only (no displacements, no statistics)
    stats = {} if scene.record == "summary" else statistics_layout(default_grids(scene),
                                                                   scene.n_sliders)
    if not resume:  # before any per-row array: an absurd count is refused at once
        try:
            check_room(out, R, statistics_row_bytes(stats))
        except StorageError as exc:
            raise UsageError(f"--realisations {R}: {exc}") from None
        file_attrs = file_attributes(scene.to_dict(), scene.seed, R, backend)
        file_attrs["first_realisation"] = first
    else:
        file_attrs = head["attrs"]
    grids = default_grids(scene).to_arrays()
    seeds = np.array([realisation_seed(scene.seed, first + r) for r in range(R)], dtype=np.uint32)
    layout = make_layout(R, seeds, grids, stats, file_attrs)
    done = _check_resumable(out, head, layout, grids) if resume else np.zeros(R, dtype=bool)
    return RunPlan(layout, backend, resume, done, np.flatnonzero(~done), scene)


def main(argv: list[str] | None = None) -> int:
    """Run ``python -m sliders.ensemble`` with ``argv``; returns the exit code (0: every realisation done)."""
    return run_planned(RunCommand("ensemble", build_parser, prepare_ensemble, plan_ensemble,
                                  run_ensemble, input_option=("scene", "scene file")), argv)


if __name__ == "__main__":
    sys.exit(main())
