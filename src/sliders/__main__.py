"""``python -m sliders tilt ...``: run one scene and write its HDF5 file."""

from __future__ import annotations

import argparse
import math
import sys

from .cli import ProgressLine, add_scene_arguments, check_output, fail, scene_from_args
from .scene import BACKENDS, SceneError


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m sliders",
        description="Tilt a chain of frictional sliders quasi-statically to the avalanche.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("tilt", help="run one scene and write its HDF5 file",
                       description="Run one scene to the avalanche and write an HDF5 file "
                                   "(load it with sliders.TiltResult.load).")
    add_scene_arguments(p)
    p.add_argument("--backend", choices=BACKENDS, default="fortran")
    p.add_argument("--out", required=True, metavar="FILE.h5", help="output HDF5 file")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        scene = scene_from_args(args)
        check_output(args.out, args.overwrite)
    except SceneError as exc:
        fail(str(exc))

    from .driver import tilt

    line = None if args.quiet else ProgressLine()

    def progress(p):
        if line is not None:
            line.show(f"tilt N={scene.n_sliders}: alpha={p.alpha:.5f}  events={p.n_events}  "
                      f"slider-steps={p.slider_steps:.3g}  {p.elapsed:.1f} s")

    try:
        result = tilt(scene, backend=args.backend, progress=progress)
    except ImportError as exc:
        fail(f"backend {args.backend!r} is not available: {exc}")
    if line is not None:
        line.close()
    result.save(args.out)
    alpha_c = "n/a" if math.isnan(result.alpha_c) else f"{result.alpha_c:.5f}"
    print(f"{result.status}: alpha_c={alpha_c}  events={result.n_events}  "
          f"wall={result.wall_time:.2f} s  -> {args.out}")
    if result.message:
        print(f"note: {result.message}", file=sys.stderr)
    if result.status == "interrupted":
        return 130
    return 0 if result.status in ("avalanche", "alpha_max", "max_events") else 1


if __name__ == "__main__":
    raise SystemExit(main())
