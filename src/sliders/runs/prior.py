"""``python -m sliders.prior PRIOR.toml --out FILE.h5``: realisations whose material is drawn from a prior.

    mpirun -n 2 python -m sliders.prior mpi_runs/priors/default.toml --out prior.h5
    python -m sliders.prior small.toml --out small.h5 --resume

The prior file and its draws: ``runs.prior_spec``.

Scheduling is every run command's (``runs.scheduler``, dynamic, one file,
``--resume``; the command's shape: ``runs.command``); a row depends only on its index and the seed, so the
file's content is the same with any number of ranks and after any
interruption.  A row: the catalogue of every event to the avalanche
(``catalogue.Catalogue``), the parameters, alpha_c, the status, and the
"ceiling": at each grid angle below the row's end, the K smallest distances
``mu_s,n cos(alpha) - |F_n|`` of a slider to its threshold.  The run is cut
at every grid angle (the scene's ``alpha_max`` set to it, then the tilt
continued from the state reached): the events are the same, bit for bit, as
one uninterrupted ``sliders.tilt`` (``tests/test_prior.py``), and the state at
the grid angle gives the thresholds (which change at every stop) and the
forces.  The file: ``sliders.io.prior_file``.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from typing import Any

import numpy as np

from .command import (DEFAULT_BACKEND, CommandParser, RunCommand, RunPlan, UsageError,
                      resume_header, check_run_options, input_command_parser, open_output,
                      run_planned)
from .prior_spec import Prior, check_plan_memory, load_prior
from .rows import run_interruptibly, status_code
from .scheduler import serve_rows
from ..driver import run
from ..io.catalogue import Catalogue
from ..io.prior_file import (HANDLERS, PARAMETERS, catalogue_events, prior_attributes,
                             prior_layout, read_prior_header, write_view)
from ..io.storage import check_room
from ..scene import check_memory


# ---------------------------------------------------------------------------
# one row
# ---------------------------------------------------------------------------
def smallest_distances(distance: np.ndarray, k: int) -> np.ndarray:
    """The ``k`` smallest of ``distance``, increasing (NaN-padded when there are fewer)."""
    out = np.full(k, np.nan)
    m = min(k, distance.size)
    out[:m] = np.sort(np.partition(distance, m - 1)[:m]) if m else []
    return out


def run_with_ceiling(scene, grid: np.ndarray, k: int, backend: str = "fortran", progress=None,
                     run_piece=None):
    """Tilt ``scene`` to its end, cut at every angle of ``grid``: the catalogue, the ceiling, the pieces.

    Returns ``(catalogue, ceiling, pieces)``: the events (the same as one
    uninterrupted tilt), the (G, k) smallest distances ``mu_s,n cos(alpha) -
    |F_n|`` at each grid angle (NaN at and past the end of the run) and the
    ``Result`` of every piece (the last one has the run's status and
    alpha_c).  ``run_piece(scene, backend, progress, state=...)`` runs a piece
    (default: ``sliders.driver.run``).
    """
    if run_piece is None:
        def run_piece(sc, be, pr, state=None):
            return run(sc, be, state=state, progress=pr)

    ceiling = np.full((grid.size, k), np.nan)
    pieces = []
    state = None
    for j, g in enumerate(grid):
        if g >= scene.alpha_max:
            break
        piece = run_piece(scene.replace(alpha_max=float(g)), backend, progress, state=state)
        pieces.append(piece)
        if piece.status != "alpha_max":
            break
        force = piece.force_at([g])[0]
        ceiling[j] = smallest_distances(piece.final.mu_s * math.cos(g) - np.abs(force), k)
        state = piece.final
    if not pieces or pieces[-1].status == "alpha_max" and pieces[-1].scene.alpha_max < scene.alpha_max:
        pieces.append(run_piece(scene, backend, progress, state=state))
    cats = [Catalogue.from_result(p) for p in pieces]
    cat = Catalogue(*(np.concatenate([getattr(c, name) for c in cats])
                      for name in ("alpha", "size", "displacement", "first", "last")))
    return cat, ceiling, pieces


def compute_prior_row(prior: Prior, r: int, backend: str, grid: np.ndarray, progress=None) -> dict:
    """Row ``r`` of the prior file: its catalogue, parameters, alpha_c, status and ceiling."""
    started = time.perf_counter()
    scene = prior.scene(r)

    def piece(sc, be, pr, state=None):
        return run_interruptibly(sc, be, pr, state=state)

    cat, ceiling, pieces = run_with_ceiling(scene, grid, prior.ceiling_k, backend, progress, piece)
    last = pieces[-1]
    row: dict[str, Any] = {
        "status": status_code(last.status),
        "alpha_c": float(last.alpha_c),
        "n_events": len(cat),
        "slider_steps": int(sum(p.total_slider_steps for p in pieces)),
        "ceiling_distance": ceiling,
        "events": catalogue_events(cat),
    }
    choices = prior.choices()
    for name, arr in prior.values().items():
        x = arr[r]
        row[PARAMETERS + name] = choices[name].index(str(x)) if name in choices else x
    row["wall_time"] = time.perf_counter() - started
    return row


# ---------------------------------------------------------------------------
# command line and run
# ---------------------------------------------------------------------------
def build_parser(rank: int = 0) -> CommandParser:
    """The command line of ``python -m sliders.prior`` (help printed by rank 0 only)."""
    p = input_command_parser(
        "python -m sliders.prior",
        "Run a prior ensemble: every row draws its material from the prior (a seeded "
        "scipy.stats.qmc design) and keeps the catalogue of every event up to the avalanche and "
        "the ceiling, over MPI ranks with dynamic scheduling, into one HDF5 file.",
        rank, "prior", "PRIOR.toml", "prior file: [prior], [scene], [parameters]")
    p.set_defaults(storage="gather")  # ragged events: rank 0 writes (sliders.io.prior_file)
    return p


def plan_prior(args, prior: Prior) -> RunPlan:
    """Rank 0, holding the claim: a new file or a resume of the same prior."""

    out = args.out
    backend = args.backend or DEFAULT_BACKEND
    head = resume_header(args, read_prior_header)
    resume = head is not None
    R = prior.realisations
    done = np.zeros(R, dtype=bool)
    attrs = None
    if resume:
        attrs = head["attrs"]
        if attrs.get("prior_digest") != prior.digest:
            raise UsageError(f"--resume: {out!r} holds a different prior; start a new file or "
                             "resume with the prior file that made it")
        if args.backend is not None and attrs["backend"] != args.backend:
            raise UsageError(f"--resume: {out!r} was computed with --backend {attrs['backend']}")
        backend = attrs["backend"]
        done = head["done"]
        if head["damaged"]:
            sys.stderr.write(f"prior: note: {len(head['damaged'])} finished row(s) of {out} fail "
                             "their checksums; recomputing them\n")
    if attrs is None:
        attrs = prior_attributes(prior.spec, prior.digest, prior.base_seed, R, backend,
                                 sorted(prior.values()), prior.ceiling_k)
        attrs["parameter_choices"] = json.dumps(prior.choices())
    layout = prior_layout(R, prior.seeds(), prior.storage_types(), prior.ceiling_alpha(),
                          prior.ceiling_k, attrs)
    # the largest chains first (cost ~ N^2), so that the last rows to finish are short ones
    order = np.argsort(-np.asarray(prior.values()["n_sliders"], dtype=np.int64), kind="stable")
    pending = order[~done[order]]
    return RunPlan(layout, backend, resume, done, pending)


def prepare_prior(args, inputs, world) -> Prior:
    """The prior, every row's scene and the memory checked (every rank, rank 0's bytes)."""
    check_run_options(args, world.comm, world.have_mpi)
    prior = load_prior(args.prior, inputs[args.prior])
    check_plan_memory(prior, world.node_ranks)  # before any row is drawn
    if not (args.resume and os.path.exists(args.out)):
        # a count no disk could hold is refused before any row is drawn; a row holds at
        # least its ceiling (G x K distances) and a few scalars, its events come on top
        check_room(args.out, prior.realisations,
                   8 * prior.ceiling_alpha().size * prior.ceiling_k + 256)
    check_memory(prior.check_rows(), world.node_ranks)  # every row, before anything runs
    return prior


def run_prior(comm, args, prior, plan: RunPlan) -> int:
    """Create or open the file, serve the rows, report (every rank)."""
    handler = open_output(comm, args, plan, HANDLERS, "gather")
    if handler is None:
        return 1
    grid = plan.layout.grids["ceiling_alpha"]

    def compute(r: int, progress):
        return compute_prior_row(prior, int(r), plan.backend, grid, progress)

    ctx = {"compute_row": compute, "interval": args.progress_interval, "quiet": args.quiet,
           "label": ("prior", "rows")}
    if comm.rank == 0 and not args.quiet:
        sys.stderr.write(f"prior: {'resuming' if plan.resume else 'starting'} "
                         f"{plan.pending.size} of {plan.total} rows (backend {plan.backend}) "
                         f"on {comm.size} rank(s) -> {args.out}\n")
        sys.stderr.flush()
    return serve_rows(comm, handler, plan.pending, plan.total, ctx, args.out,
                      lambda: write_view(args.out, prior.base_scene.to_dict()))


def main(argv: list[str] | None = None) -> int:
    """``python -m sliders.prior PRIOR.toml --out FILE.h5``: run (or resume) a prior ensemble; the exit code."""
    return run_planned(RunCommand("prior", build_parser, prepare_prior, plan_prior, run_prior,
                                   input_option=("prior", "prior file")), argv)


if __name__ == "__main__":
    sys.exit(main())
