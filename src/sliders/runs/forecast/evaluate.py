"""``python -m sliders.forecast evaluate``: fit, test and score every forecaster.

The prior ensemble is split by realisation (train, validation, test); every
forecaster is fitted on the training part (the learned ones recalibrated on
the validation part); the test realisations are cut at leads before their
avalanche and at fixed tilts (``scoring``); the table of metrics with
bootstrap intervals is printed and written (markdown and JSON, with
provenance) with the figures, and the forecasters ``predict`` offers are kept
in a model file (``io.forecast_model``, data and not code).  The data are
prior ensembles (``python -m sliders.prior``, ``sliders.io.prior_file``) or,
for development, a small set run here (``dev.dev_catalogue_set``).

The command claims its output folders, refuses an output that is an input
(by device and inode) and publishes its files as one set
(``io.forecast_files.OutputSet``; docs/reliability.md, "The forecast commands").
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
import time

import numpy as np

from ...analysis.forecast import Cuts
from ...analysis.forecast import evaluation as ev
from ...analysis.forecast.fitting import fit_sharing_cuts
from ...analysis.forecast.model_file import forecasters_bytes
from ...analysis.forecast.registry import make_forecasters, method_of, names_where
from ...io.catalogue import CatalogueSet
from ...io.forecast_files import (ForecastInputError, OutputSet, check_output_target,
                                  claim_folder, complete_publication)
from ...io.safeio import (check_output_name, leftovers_note, os_reason, remove_leftovers,
                          resolve_target)
from .catalogue import load_set
from ...forecasting.common import jsonable, progress_log, provenance
from .dev import dev_catalogue_set
from .scoring import score_forecasters

#: the files an evaluation writes: in --out, and the figures (png and pdf) in --figures
TABLE_NAME, METRICS_NAME, MODEL_NAME = "forecast_table.md", "forecast_metrics.json", "forecaster.zip"
FIGURE_NAMES = tuple(f"forecast_{n}.{ext}" for n in ("error", "coverage", "convergence", "roc")
                     for ext in ("png", "pdf"))
#: the forecasters a model file holds (their names)
METHOD_NAMES = {f.name for f in make_forecasters(methods_only=True)}


def evaluate(args, argv) -> int:
    """The whole evaluation (module docstring): options checked, inputs read and checked, every
    forecaster fitted and scored, the table printed, the outputs published as one set."""
    log = progress_log(args.quiet)
    t0 = time.time()
    check_evaluate_options(args)
    inputs = input_files(args)
    outputs = output_paths(args)
    with claimed_folders(args, outputs, inputs, log):
        data, robust = read_inputs(args)
        split = split_checked(args, data, robust)
        forecasters, timing = fit_forecasters(args, data, split, log)
        results, text = score_forecasters(args, argv, data, robust, split, forecasters, log)
        results["fit_seconds"] = timing
        results["seconds"] = time.time() - t0
        print(text)
        publish_evaluation(args, argv, outputs, inputs, results, text, forecasters, data, split, log)
    log(f"forecast: done in {time.time() - t0:.0f} s")
    return 0


#: realisations that reached the avalanche each part of the split needs (the fits, the calibration)
MIN_AVALANCHES = {"train": 3, "validation": 1, "test": 1}
#: the bounds of the counts (beyond them a run would not end, or not fit in memory)
COUNT_BOUNDS = {"dev": (1, 100_000), "boot": (1, 100_000), "alarm_rows": (1, 10**7),
                "max_iter": (1, 100_000), "seed": (0, 2**32 - 1)}


def check_evaluate_options(args) -> None:
    """Every option of ``evaluate`` in range (one line naming it), before anything is read."""
    for name, (lo, hi) in COUNT_BOUNDS.items():
        v = getattr(args, name)
        if v is not None and not lo <= v <= hi:
            raise ForecastInputError(f"--{name.replace('_', '-')} {v}: must lie in [{lo}, {hi}]")
    f = np.asarray(args.fractions, dtype=float)
    if not (np.all(np.isfinite(f)) and np.all(f > 0) and math.isclose(f.sum(), 1.0, abs_tol=1e-9)):
        raise ForecastInputError(f"--fractions {' '.join(f'{x:g}' for x in f)}: three shares "
                                 "(train, validation, test), each > 0, summing to 1")
    for option, values, hi, unit in (("--leads-deg", args.leads_deg, 90.0, "°"),
                                     ("--tilts", args.tilts, math.pi / 2, " rad")):
        bad = [v for v in values if not 0.0 < v < hi]
        if bad:
            raise ForecastInputError(f"{option} {bad[0]:g}: must lie in (0, {hi:g}{unit})")
    if args.only is not None:
        known = [f.name for f in make_forecasters(True, 1, 0)]
        unknown = [n for n in args.only.split(",") if n not in known]
        if unknown:
            raise ForecastInputError(f"--only {args.only}: no forecaster {unknown[0]!r} (known: "
                                     f"{', '.join(known)})")
    robust_sets(args)


def robust_sets(args) -> dict[str, str]:
    """``--robust LABEL=FILE`` as ``{label: file}``: labels distinct, not ``test``."""
    out = {}
    for spec in args.robust:
        label, sep, path = spec.partition("=")
        if not sep or not label or not path:
            raise ForecastInputError(f"--robust {spec!r}: give LABEL=FILE.h5")
        if label == "test" or label in out:
            raise ForecastInputError(f"--robust {spec!r}: the label {label!r} is taken (labels "
                                     "are distinct, and 'test' names the test part of --data)")
        out[label] = path
    return out


def input_files(args) -> dict:
    """``{"the --data file": FileTarget, ...}``: every input, existing, each a different file
    (compared by device and inode: a hard link or another path to the same file is refused)."""
    named = {} if args.dev else {"the --data file": args.data}
    named |= {f"the --robust {label} file": path for label, path in robust_sets(args).items()}
    inputs = {}
    for what, path in named.items():
        target = resolve_target(path)
        if target.identity is None:
            raise ForecastInputError(f"{path}: no such file ({what})")
        twin = next((w for w, t in inputs.items() if t.same_file(target)), None)
        if twin is not None:
            raise ForecastInputError(f"{what} {path!r} is {twin} {inputs[twin].given!r} (the same "
                                     "file): a set tested for robustness is never training data")
        inputs[what] = target
    return inputs


def output_paths(args) -> dict[str, str]:
    """``{name: path}`` of every file the evaluation publishes, each name checked."""
    figures = args.figures or args.out
    paths = {n: os.path.join(args.out, n) for n in (TABLE_NAME, METRICS_NAME, MODEL_NAME)}
    if not args.no_figures:
        paths |= {n: os.path.join(figures, n) for n in FIGURE_NAMES}
    for option, folder in (("--out", args.out), ("--figures", figures)):
        if os.path.lexists(folder) and not os.path.isdir(folder):
            raise ForecastInputError(f"{option} {folder!r} exists and is not a folder; "
                                     "give a folder for the outputs")
    for path in paths.values():
        try:
            check_output_name(path)
        except ValueError as exc:
            raise ForecastInputError(f"--out: {exc}") from None
    return paths


@contextlib.contextmanager
def claimed_folders(args, outputs: dict, inputs: dict, log):
    """Create and claim the output folders (``forecast_files.claim_folder``) for the run; finish a
    killed run's committed publication, remove its temporaries, refuse an output that is an input."""
    folders = {}
    for option, folder in (("--out", args.out), ("--figures", args.figures or args.out)):
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as exc:
            raise ForecastInputError(f"{option} {folder!r}: cannot create the folder "
                                     f"({os_reason(exc)})") from None
        real = resolve_target(folder).real
        folders.setdefault(real, folder)
    claims = []
    try:
        for real, folder in folders.items():
            claims.append(claim_folder(real))
            if claims[-1].previous_holder:
                log(f"forecast: note: {folder} was held by {claims[-1].previous_holder}, which is "
                    "no longer running; its stale claim is taken over")
        moved = complete_publication(resolve_target(args.out).real)
        if moved:
            log(f"forecast: note: finished publishing {moved} file(s) of an interrupted run")
        removed = [r for path in outputs.values() for r in remove_leftovers(path)]
        if removed:
            log(f"forecast: note: {leftovers_note(removed)}")
        for path in outputs.values():
            check_output_target(path, inputs)
        yield
    finally:
        for claim in claims:
            claim.release()


def read_inputs(args) -> tuple[CatalogueSet, dict]:
    """The data and the robustness sets: read from their files, or run here (``--dev``)."""
    if args.dev:
        data = dev_catalogue_set(args.dev, seed=args.seed)
        robust = {"zero": dev_catalogue_set(max(args.dev // 4, 4), seed=args.seed + 1,
                                            initial_forces="zero")}
        return data, robust
    data = load_set(args.data)
    return data, {label: load_set(path, f"--robust {label}")
                  for label, path in robust_sets(args).items()}


def split_checked(args, data: CatalogueSet, robust: dict):
    """The split by realisation, refused in one line if a part holds too few avalanches."""
    split = ev.split_rows(len(data), args.fractions, seed=args.seed)
    source = f"--dev {args.dev}" if args.dev else f"--data {args.data}"
    for part, least in MIN_AVALANCHES.items():
        rows = getattr(split, part)
        n = int(np.isfinite(np.asarray(data.alpha_c, dtype=float)[rows]).sum())
        if n < least:
            raise ForecastInputError(
                f"{source}: {len(data)} realisations, {len(rows)} in the {part} part of which {n} "
                f"reached the avalanche; at least {least} needed (train, validation, test at least "
                f"{', '.join(map(str, MIN_AVALANCHES.values()))}): give more realisations or other "
                "--fractions")
    for label, cset in robust.items():
        if not np.isfinite(np.asarray(cset.alpha_c, dtype=float)).any():
            raise ForecastInputError(f"--robust {label}: no realisation reached the avalanche")
    return split


def fit_forecasters(args, data: CatalogueSet, split, log) -> tuple[list, dict]:
    """Every forecaster (or those of ``--only`` and the baselines), fitted on the training part
    (the learned ones recalibrated on the validation part); returns them and their fit times."""
    forecasters = make_forecasters(data.ceiling_distance is not None, args.max_iter, args.seed)
    if args.only:
        keep = set(args.only.split(",")) | {"climatology", "conditioned"}
        forecasters = [f for f in forecasters if f.name in keep]
    train, valid = data.subset(split.train), data.subset(split.validation)
    timing = {}
    shared = {}  # the learned forecasters' training and calibration cuts, drawn once per kind
    for f in forecasters:
        t = time.time()
        if hasattr(f, "training_cuts"):
            fit_sharing_cuts(f, train, valid, shared, args.seed)
        else:
            f.fit(train)
        timing[f.name] = time.time() - t
        log(f"forecast: fitted {f.name} in {timing[f.name]:.1f} s")
    return forecasters, timing

def publish_evaluation(args, argv, outputs, inputs, results, text, forecasters, data, split,
                       log) -> None:
    """Stage the table, the metrics, the model kept for ``predict`` and the figures whole, then
    publish them together (``forecast_files.OutputSet``): a run stopped or failing before the
    end leaves the previous run's set as it was."""
    with OutputSet(resolve_target(args.out).real, inputs) as staged:
        staged.add(outputs[TABLE_NAME], (text + "\n").encode())
        staged.add(outputs[METRICS_NAME], (json.dumps(jsonable(results), indent=1) + "\n").encode())
        kept = {method_of(f): f for f in forecasters if f.name in METHOD_NAMES}
        if kept:
            staged.add(outputs[MODEL_NAME], forecasters_bytes(
                kept, provenance(argv) | {"rows": int(len(split.train)), "prior": data.attrs.get(
                    "prior_digest", "dev"), "mode": str(data.attrs.get("mode", "explore"))}))
        if not args.no_figures:
            from ...figures.forecast import draw_all  # matplotlib: imported only to draw

            example = _convergence_example(data, split.test, forecasters, args.seed)
            with tempfile.TemporaryDirectory(prefix="sliders-forecast-figures-") as scratch:
                for path in draw_all(results, example, scratch):
                    name = os.path.basename(path)
                    with open(path, "rb") as fh:
                        staged.add(outputs.get(name) or os.path.join(args.figures or args.out, name),
                                   fh.read())
        staged.publish()
    log("forecast: published " + " ".join(p for n, p in outputs.items() if n != MODEL_NAME or kept))


def _convergence_example(data, test_rows, forecasters, seed):
    """One test realisation's forecasts along its tilt: {name: (tilts, quantiles)}, and the truth."""
    rows = [int(r) for r in test_rows if np.isfinite(data.alpha_c[r])]
    ac = data.alpha_c[rows]
    r = rows[int(np.argsort(ac)[len(ac) // 2])]  # the median avalanche angle
    a_c = float(data.alpha_c[r])
    tilts = np.linspace(0.05, a_c - 1e-4, 60)
    cuts = Cuts.from_set(data, np.full(tilts.size, r), tilts)
    out = {}
    for f in forecasters:
        if f.name in names_where("example") and not any(getattr(cuts, n) is None for n in f.needs):
            out[f.name] = f.quantiles(cuts)[0]
    return {"tilts": tilts, "alpha_c": a_c, "row": r, "forecasts": out,
            "labels": {f.name: f.label for f in forecasters},
            "events": data.catalogue(r).alpha}


