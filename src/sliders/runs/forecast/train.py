"""``python -m sliders.forecast train``: a forecaster for a prior of one's own.

    python -m sliders.forecast train --prior my.toml --out my_model.zip --np 2

``train`` runs the prior ensemble (``python -m sliders.prior``, on ``--np``
MPI ranks, ``--resume``: an interrupted training run completes its file),
then fits every forecaster a model file holds
(``analysis.forecast.fitting.fit_methods``) and writes the model file
(``io.forecast_model``: data, not code) with its provenance.  With
``--data`` it fits on a prior file already computed (e.g. on a cluster).
With ``--fit posterior`` it fits the posterior of the pile's parameters
instead (``analysis.forecast.posterior``, read by ``infer``): its own file,
fitted in a minute or two where the forecasters take a quarter of an hour,
so that either can be refitted alone and the shipped forecaster's bytes (and
digest) stay as they are.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np

from ...analysis.forecast.evaluation import measure_expected_accuracy
from ...analysis.forecast.posterior import ParameterPosterior
from ...analysis.forecast.fitting import fit_methods
from ...analysis.forecast.model_file import save_forecasters
from ...io.catalogue import CatalogueSet
from ...io.forecast_files import ForecastInputError, check_output_target
from ...io.prior_file import another_draw, prior_seed, same_draw, shared_piles
from ...io.safeio import resolve_target
from .catalogue import load_set
from ...forecasting.common import POSTERIOR_MAX_ITER, TRAIN_MAX_ITER, progress_log, provenance


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


def train(args, argv) -> int:
    """Run the prior (unless ``--data``), fit the forecasters, write the model file."""
    log = progress_log(args.quiet)
    if args.max_iter is None:
        args.max_iter = POSTERIOR_MAX_ITER if args.fit == "posterior" else TRAIN_MAX_ITER
    if not 1 <= args.np <= 4096:
        raise ForecastInputError(f"--np {args.np}: must lie in [1, 4096]")
    if not 1 <= args.max_iter <= 100_000:
        raise ForecastInputError(f"--max-iter {args.max_iter}: must lie in [1, 100000]")
    folder = os.path.dirname(os.path.abspath(args.out))
    if not os.path.isdir(folder):
        raise ForecastInputError(f"--out {args.out}: the folder {folder} does not exist")
    if args.prior is not None and not os.path.isfile(args.prior):
        raise ForecastInputError(f"--prior {args.prior}: no such file")
    check_outputs(args)
    t0 = time.time()
    paths = args.data
    if args.prior is not None:
        paths = [args.out + ".prior.h5"]
        run_prior(args, paths[0], log)
    t_sim = time.time() - t0
    what = "--data" if args.data else "the prior ensemble"
    sets = [(f"{what} {p}", resolve_target(p), load_set(p, what)) for p in paths]
    check_disjoint(sets)
    data = CatalogueSet.joined([s for _, _, s in sets])
    data_path = " + ".join(paths)
    ok = np.isfinite(np.asarray(data.alpha_c, dtype=float))
    if ok.sum() < 20:
        raise ForecastInputError(f"{data_path}: {int(ok.sum())} realisations reached the "
                                 "avalanche; at least 20 are needed to train")
    if not 0.0 <= args.hold_out < 0.9:
        raise ForecastInputError(f"--hold-out {args.hold_out:g}: must lie in [0, 0.9)")
    held = np.random.default_rng([args.seed, 7]).random(len(data)) < args.hold_out
    train_set = data.subset(np.flatnonzero(ok & ~held))
    calibration, calibration_seeds = calibration_sets(args, data, sets)
    if args.fit == "posterior":
        models = {"posterior": ParameterPosterior(max_iter=args.max_iter,
                                                  random_state=args.seed).fit(
            train_set, calibration=calibration)}
        log(f"forecast: fitted the posterior in {time.time() - t0 - t_sim:.1f} s")
    else:
        models = fit_methods(train_set, args.max_iter, args.seed, log)
        measure_expected_accuracy(models, data.subset(np.flatnonzero(ok & held)), args.seed)
    prov = provenance([portable_path(a) for a in argv]) | training_provenance(data, data_path, args)
    prov["rows"] = len(train_set)
    prov["held_out_rows"] = [int(r) for r in np.flatnonzero(held)]
    prov["data_files"] = [portable_path(p) for p in paths]
    if calibration is not None:
        prov["calibration_files"] = [portable_path(p) for p in args.calibration_data]
        prov["calibration_seeds"] = calibration_seeds
    prov["seconds_simulation"], prov["seconds_fit"] = t_sim, time.time() - t0 - t_sim
    size = save_forecasters(args.out, models, prov)
    log(f"forecast: wrote {args.out} ({size / 1e6:.2f} MB) from {prov['rows']} rows in "
        f"{time.time() - t0:.0f} s")
    return 0


def calibration_sets(args, data, sets) -> tuple[CatalogueSet | None, list]:
    """The rows of ``--calibration-data`` and the seeds of its files, each file checked to draw
    the training prior with a seed of its own (none of the data files', none of another
    calibration file's), and to share no file and no pile with any other input
    (``check_disjoint``); ``sets``: the data files' ``(label, target, set)``."""
    if args.calibration_data is None:
        return None, []
    if args.fit != "posterior":
        raise ForecastInputError("--calibration-data: only with --fit posterior (the forecasters "
                                 "calibrate on a share of --data)")
    inputs = list(sets)
    owners = {prior_seed(s.attrs): label for label, _, s in reversed(sets)}  # seed: first user
    parts, seeds = [], []
    for path in args.calibration_data:
        part = load_set(path, "--calibration-data")
        why = another_draw(data.attrs, part.attrs, [k for k in owners if k is not None])
        if why is not None:
            owner = owners.get(prior_seed(part.attrs)) if "already used" in why else None
            raise ForecastInputError(f"--calibration-data {path}: {why}"
                                     f"{f' by {owner}' if owner else ''}: it must draw the "
                                     "training prior with another seed")
        label = f"--calibration-data {path}"
        owners.setdefault(prior_seed(part.attrs), label)
        inputs.append((label, resolve_target(path), part))
        parts.append(part)
        seeds.append(prior_seed(part.attrs))
    check_disjoint(inputs)
    return CatalogueSet.joined(parts), seeds


def check_outputs(args) -> None:
    """Every output of ``train`` (the model file; with ``--prior``, the prior ensemble it runs
    beside it) is none of its inputs, by device and inode (symlinks and hard links included),
    before anything is run or fitted: an output never replaces an input."""
    inputs = [("--prior", args.prior)] if args.prior is not None else []
    inputs += [("--data", p) for p in args.data or ()]
    inputs += [("--calibration-data", p) for p in args.calibration_data or ()]
    outputs = [args.out]
    if args.prior is not None:
        outputs.append(args.out + ".prior.h5")  # written by the prior run, read by the fit
        check_output_target(args.out, {"the prior ensemble it runs": resolve_target(outputs[1])})
    for out in outputs:
        for what, path in inputs:
            check_output_target(out, {what: resolve_target(path)})


def check_disjoint(inputs) -> None:
    """Training inputs (``(label, FileTarget, CatalogueSet)``) that share no pile: no two are
    the same file (device and inode), the same draw (the same prior and seed: a copy, or the
    prior run again), or hold a pile in common (the rows' seeds and events' CRC-32s,
    ``prior_file.shared_piles``).  A pile given twice would be fitted twice, or held out and
    fitted, and the calibration and the expected accuracy would be measured in-sample."""
    for j, (label, target, cset) in enumerate(inputs):
        for other, other_target, other_set in inputs[:j]:
            if target.same_file(other_target):
                why = "the same file as"
            elif same_draw(other_set.attrs, cset.attrs):
                why = f"the same draw (the same prior, seed {prior_seed(cset.attrs)}) as"
            elif n := shared_piles(other_set.attrs, cset.attrs):
                why = f"{n} of its piles are piles of"
            else:
                continue
            raise ForecastInputError(f"{label}: {why} {other}; training inputs must not "
                                     "overlap (a pile fitted twice, or held out and fitted)")


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
    try:
        return json.loads(attrs.get("prior", "{}")).get("scene", {}).get("mode", "explore")
    except (TypeError, ValueError, AttributeError):
        return "explore"
