"""``python -m sliders.forecast train`` and ``catalogue``: a forecaster for a prior of one's own.

    python -m sliders.forecast train --prior my.toml --out my_model.skops --np 2
    python -m sliders.forecast catalogue --data prior.h5 --row 7 --lead 3deg --out row7.csv

``train`` runs the prior ensemble (``python -m sliders.prior``, on ``--np``
MPI ranks, ``--resume``: an interrupted training run completes its file),
then fits every forecaster a model file holds
(``analysis.forecast.registry.fit_methods``) and writes the model file
(``io.forecast_model``: data, not code) with its provenance.  With
``--data`` it fits on a prior file already computed (e.g. on a cluster).

``catalogue`` writes one simulated row as the CSV ``predict`` reads, cut at a
tilt or a lead before its avalanche: the documentation's examples are made so.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import time

import numpy as np

from ..io.forecast_files import ForecastInputError, parse_angle

#: boosting iterations of the default model: each iteration adds 7 trees per learned forecaster
#: to the model file (150 iterations of 31 leaves made an 8 MB file)
TRAIN_MAX_ITER = 100


def add_train_arguments(t) -> None:
    """The options of ``train``."""
    src = t.add_mutually_exclusive_group(required=True)
    src.add_argument("--prior", metavar="PRIOR.toml", help="run this prior ensemble, then fit")
    src.add_argument("--data", nargs="+", metavar="PRIOR.h5",
                     help="fit on prior files already computed (several: their rows together)")
    t.add_argument("--out", required=True, metavar="MODEL.skops", help="the model file written")
    t.add_argument("--np", type=int, default=1, help="MPI ranks of the prior ensemble")
    t.add_argument("--max-iter", type=int, default=TRAIN_MAX_ITER, help="boosting iterations")
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


def run_prior(args, prior_out: str, log) -> None:
    """The prior ensemble of ``--prior`` into ``prior_out`` (resumed if it exists)."""
    cmd = [sys.executable, "-m", "sliders.prior", args.prior, "--out", prior_out, "--resume",
           "--progress-interval", "60"] + (["--quiet"] if args.quiet else [])
    if args.np > 1:
        launcher = shutil.which("mpirun") or shutil.which("mpiexec")
        if launcher is None:
            raise ForecastInputError(f"--np {args.np}: no mpirun on PATH; use --np 1")
        cmd = [launcher, "-n", str(args.np)] + cmd
    log("forecast: " + " ".join(cmd))
    code = subprocess.call(cmd)
    if code != 0:
        raise ForecastInputError(f"--prior {args.prior}: the prior ensemble stopped with status "
                                 f"{code}; run the same command again to resume it")


def train(args, argv, load_set, provenance) -> int:
    """Run the prior (unless ``--data``), fit the forecasters, write the model file.

    ``load_set(path, what)`` reads a prior file, ``provenance(argv)`` gives the versions and
    the command (``sliders.runs.forecast``'s, passed in: this module is imported by it).
    """
    from ..analysis.forecast.evaluation import measure_expected_accuracy
    from ..analysis.forecast.registry import fit_methods
    from ..io.forecast_model import save_forecasters

    log = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    if not 1 <= args.np <= 4096:
        raise ForecastInputError(f"--np {args.np}: must lie in [1, 4096]")
    if not 1 <= args.max_iter <= 100_000:
        raise ForecastInputError(f"--max-iter {args.max_iter}: must lie in [1, 100000]")
    folder = os.path.dirname(os.path.abspath(args.out))
    if not os.path.isdir(folder):
        raise ForecastInputError(f"--out {args.out}: the folder {folder} does not exist")
    t0 = time.time()
    paths = args.data
    if args.prior is not None:
        if not os.path.isfile(args.prior):
            raise ForecastInputError(f"--prior {args.prior}: no such file")
        paths = [args.out + ".prior.h5"]
        run_prior(args, paths[0], log)
    t_sim = time.time() - t0
    data = concatenate([load_set(p, "--data" if args.data else "the prior ensemble") for p in paths])
    data_path = " + ".join(paths)
    ok = np.isfinite(np.asarray(data.alpha_c, dtype=float))
    if ok.sum() < 20:
        raise ForecastInputError(f"{data_path}: {int(ok.sum())} realisations reached the "
                                 "avalanche; at least 20 are needed to train")
    if not 0.0 <= args.hold_out < 0.9:
        raise ForecastInputError(f"--hold-out {args.hold_out:g}: must lie in [0, 0.9)")
    held = np.random.default_rng([args.seed, 7]).random(len(data)) < args.hold_out
    train_set = data.subset(np.flatnonzero(ok & ~held))
    models = fit_methods(train_set, args.max_iter, args.seed, log)
    measure_expected_accuracy(models, data.subset(np.flatnonzero(ok & held)), args.seed)
    prov = provenance([portable_path(a) for a in argv]) | training_provenance(data, data_path, args)
    prov["rows"] = len(train_set)
    prov["held_out_rows"] = [int(r) for r in np.flatnonzero(held)]
    prov["data_files"] = [portable_path(p) for p in paths]
    prov["seconds_simulation"], prov["seconds_fit"] = t_sim, time.time() - t0 - t_sim
    size = save_forecasters(args.out, models, prov)
    log(f"forecast: wrote {args.out} ({size / 1e6:.2f} MB) from {prov['rows']} rows in "
        f"{time.time() - t0:.0f} s")
    return 0


def portable_path(path: str) -> str:
    """A path as a model file's provenance names it: relative to the current folder (the
    repository) if inside it, else its file name (``--opt=PATH`` too); nothing else changes."""
    if path.startswith("--") and "=" in path:
        option, _, value = path.partition("=")
        return f"{option}={portable_path(value)}"
    if not os.path.isabs(path):
        return path
    rel = os.path.relpath(path, os.getcwd())
    return rel if not rel.startswith(os.pardir) else os.path.basename(path)


def concatenate(sets):
    """One ``CatalogueSet`` of the rows of several (their parameters in common; no ceiling)."""
    from ..io.catalogue import CatalogueSet

    if len(sets) == 1:
        return sets[0]
    common = set.intersection(*(set(s.parameters) for s in sets))
    cats = [s.catalogue(i) for s in sets for i in range(len(s))]
    return CatalogueSet.from_catalogues(
        cats, {k: np.concatenate([np.asarray(s.parameters[k]) for s in sets]) for k in sorted(common)},
        np.concatenate([s.alpha_c for s in sets]), np.concatenate([s.status for s in sets]),
        attrs=sets[0].attrs | {"prior_digest": "+".join(str(s.attrs.get("prior_digest", ""))
                                                         for s in sets)})


def training_provenance(data, data_path: str, args) -> dict:
    """The prior and the mode a model was trained on (shown by ``predict --verbose``; ``train``
    adds the rows it fitted)."""
    attrs = data.attrs
    prior = attrs.get("prior") or attrs.get("prior_spec")
    return {"prior": str(prior) if prior is not None else str(args.prior or data_path),
            "prior_digest": str(attrs.get("prior_digest", "")),
            "prior_file": portable_path(str(args.prior or data_path)),
            "mode": str(attrs.get("mode", _scene_mode(attrs)))}


def _scene_mode(attrs) -> str:
    import json

    try:
        return json.loads(attrs.get("prior", "{}")).get("scene", {}).get("mode", "explore")
    except (TypeError, ValueError, AttributeError):
        return "explore"


def catalogue_csv_text(cat) -> str:
    """A catalogue as the CSV ``predict`` reads (angles in radians, every column)."""
    lines = ["angle [rad],size,displacement,first,last"]
    for a, s, d, f, la in zip(cat.alpha, cat.size, cat.displacement, cat.first, cat.last):
        lines.append(f"{a:.10g},{int(s)},{d:.10g},{int(f)},{int(la)}")
    return "\n".join(lines) + "\n"


def catalogue(args, argv, load_set) -> int:
    """Write row ``--row`` of ``--data`` as a catalogue CSV cut at ``--at`` or ``--lead``
    (``load_set(path)`` reads the prior file)."""
    from ..io.safeio import publish_bytes

    data = load_set(args.data)
    if not 0 <= args.row < len(data):
        raise ForecastInputError(f"--row {args.row}: {args.data} has rows 0..{len(data) - 1}")
    a_c = float(data.alpha_c[args.row])
    if args.lead is not None:
        if not math.isfinite(a_c):
            raise ForecastInputError(f"--lead: row {args.row} did not reach the avalanche")
        tilt = a_c - parse_angle(args.lead, math.pi / 180.0)
    else:
        tilt = parse_angle(args.at, math.pi / 180.0)
    if not 0.0 < tilt < (a_c if math.isfinite(a_c) else math.pi / 2):
        raise ForecastInputError(f"--lead/--at: the cut at {math.degrees(tilt):.3f}° is not "
                                 f"between 0 and the row's end ({math.degrees(a_c):.3f}°)")
    cut = data.catalogue(args.row).cut(tilt)
    text = f"# row {args.row} of {os.path.basename(args.data)} cut at {tilt:.10g} rad; " \
           f"alpha_c = {a_c:.10g} rad\n" + catalogue_csv_text(cut)
    publish_bytes(args.out, text.encode(), overwrite=True)
    print(f"{args.out}: {len(cut)} events up to {math.degrees(tilt):.3f}° (alpha_c "
          f"{math.degrees(a_c):.3f}°); predict with --tilt-now {tilt:.10g}rad")
    return 0
