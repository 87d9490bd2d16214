"""``python -m sliders tilt ...``: run one scene and write its HDF5 file."""

from __future__ import annotations

import argparse
import math
import signal
import sys
import time

from ._forward import interrupted_while_starting

try:
    from . import status
    from .runs.cli import (OneLineParser, ProgressLine, add_scene_arguments, check_output, fail,
                           scene_from_args)
    from .runs.signals import Received
    from .io.filelock import ClaimError, OutputClaim
    from .io.safeio import describe_os_error, leftovers_note
    from .parts.checks import SceneError
    from .scene import BACKENDS, check_memory
    from .driver import run
    from .preparation import PreparationInterrupted, prepare, prepared_at_once
except KeyboardInterrupt:  # Ctrl-C while the command's modules are imported
    if __name__ != "__main__":
        raise
    interrupted_while_starting("sliders")


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m sliders`` (``tilt``)."""
    parser = OneLineParser(
        prog="python -m sliders",
        description="Tilt a chain of frictional sliders quasi-statically to the avalanche.",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    p = sub.add_parser("tilt", prog="python -m sliders tilt", help="run one scene and write its HDF5 file",
                       description="Run one scene to the avalanche and write an HDF5 file "
                                   "(load it with sliders.Result.load).")
    add_scene_arguments(p)
    p.add_argument("--backend", choices=BACKENDS, default="fortran",
                   help=f"tilt backend, one of {{{', '.join(BACKENDS)}}} (default fortran)")
    p.add_argument("--out", required=True, metavar="FILE.h5", help="output HDF5 file")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``python -m sliders`` with ``argv``; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        scene = scene_from_args(args)
        check_output(args.out, args.overwrite)
        check_memory(scene)
    except SceneError as exc:
        fail(str(exc))
    try:
        claim = OutputClaim(args.out).acquire()
    except ClaimError as exc:
        fail(str(exc), code=1)
    try:
        if not claim.locking and args.overwrite:
            fail(f"--out {args.out!r}: this file system does not support file locks, so a "
                 "concurrent writer could not be detected; --overwrite is refused there", code=1)
        if claim.previous_holder and not args.quiet:
            print(f"note: {args.out} was held by {claim.previous_holder}, which is no longer "
                  "running; its stale claim is taken over", file=sys.stderr)
        if claim.leftovers:
            print(f"note: {leftovers_note(claim.leftovers)}", file=sys.stderr)
        return _run(args, scene)
    finally:
        claim.release()


def _run(args, scene) -> int:
    line = None if args.quiet else ProgressLine()
    drive = "alpha" if scene.loading.drive_is_angle else "drive"

    def progress(p):
        if line is not None:
            line.show(f"{scene.loading.name} N={scene.n_sliders}: {drive}={p.drive:.5f}  "
                      f"events={p.n_events}  slider-steps={p.slider_steps:.3g}  {p.elapsed:.1f} s")

    started = time.perf_counter()

    def preparing(phase, alpha, n_events):
        if line is not None:
            line.show(f"{scene.loading.name} N={scene.n_sliders}: preparing the chain's history, "
                      f"{phase}: alpha={alpha:.5f}  events={n_events}  "
                      f"{time.perf_counter() - started:.1f} s")

    history = not prepared_at_once(scene)  # a tilt of its own, minutes for large chains
    if line is not None and history:
        line.show(f"{scene.loading.name} N={scene.n_sliders}: preparing the chain's history "
                  "(its own tilt to the avalanche and back)", force=True)
    # SIGTERM (batch systems, kill) stops the run as Ctrl-C does: finished events are saved;
    # while the result is saved a second signal waits until the file is complete
    received = Received()
    with received.waiting():
        with received.stopping():
            try:
                # the same chain run(scene) prepares, with the history's progress shown
                given = prepare(scene, history_progress=preparing) if history else None
                result = run(scene, backend=args.backend, state=given, progress=progress,
                             keep_partial=True)
            except ImportError as exc:
                fail(f"backend {args.backend!r} is not available: {exc}")
            except PreparationInterrupted:  # no chain yet: nothing to save
                if line is not None:
                    line.close()
                print(f"interrupted ({signal.Signals(received.exit_status() - 128).name}) "
                      "while the chain's history was prepared; nothing written", file=sys.stderr)
                return received.exit_status()
        if line is not None:
            line.close()
        try:
            result.save(args.out, overwrite=args.overwrite)
        except FileExistsError:
            fail(f"--out {args.out!r} was created by another process during the run; "
                 "nothing was replaced (the result is lost: rerun with another --out)", code=1)
        except OSError as exc:
            fail(f"cannot write {describe_os_error(exc, args.out)}", code=1)
    if not scene.loading.drive_is_angle:  # the run ends at a driver position, not an angle
        last = f"{result.drive[-1]:.5f}" if result.n_events else "n/a"
        reached = f"last drive D={last}"
    else:
        reached = "alpha_c=" + ("n/a" if math.isnan(result.alpha_c) else f"{result.alpha_c:.5f}")
    print(f"{result.status}: {reached}  events={result.n_events}  "
          f"wall={result.wall_time:.2f} s  -> {args.out}")
    if result.message:
        print(f"note: {result.message}", file=sys.stderr)
    if result.status == "interrupted":
        return received.exit_status()
    return 0 if result.status in {status.NAMES[code] for code in status.FINAL_OK} else 1


if __name__ == "__main__":
    raise SystemExit(main())
