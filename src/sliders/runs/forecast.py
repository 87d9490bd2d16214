"""``python -m sliders.forecast``: evaluate the forecasters of the avalanche angle, or forecast a catalogue.

    python -m sliders.forecast evaluate --data prior.h5 --robust zero=zero.h5 --out results/forecast
    python -m sliders.forecast evaluate --dev 300 --out /tmp/forecast      # serial development data
    python -m sliders.forecast predict CATALOGUE.csv [--tilt-now ANGLE] [--json] [--model FILE]
    python -m sliders.forecast predict CATALOGUE.csv --method all --size-unit arbitrary --verbose
    python -m sliders.forecast train --prior my.toml --out my_model.skops --np 2
    python -m sliders.forecast catalogue --data prior.h5 --row 7 --lead 3deg --out row7.csv

``evaluate`` splits the prior ensemble by realisation (train, validation,
test), fits every forecaster on the training part (the learned ones are
recalibrated on the validation part), cuts the test realisations at leads
before their avalanche and at fixed tilts, prints the table of metrics with
bootstrap intervals, writes it (markdown and JSON, with provenance) and
draws the figures; the forecasters ``predict`` offers are kept in a model
file (``io.forecast_model``, data and not code).  The data are prior ensembles (``python -m sliders.prior``,
``sliders.io.prior_file``) or, for development, a small set run here
(``dev_catalogue_set``).

``predict`` reads a measured catalogue (docs/forecasting.md, "Your own
catalogue"): a CSV file with a header, one event per row, columns
``angle [deg]`` or ``angle [rad]`` (increasing), ``size`` (sliders or grains
moved, >= 1), optionally ``displacement``, ``first`` and ``last`` (0-based
positions of the first and last mover).  Bad input gets one line naming the
row and the column.  Without ``--model`` it uses the forecaster shipped in the
package.  ``train`` and ``catalogue``: ``sliders.runs.forecast_train``.

Every subcommand runs inside one error boundary (``main``): parse, check the
options, check the inputs and outputs, compute, publish; every failure is one
line (status 2 for bad input, 1 for an I/O error or a fault, 128 + signal when
stopped).  ``evaluate`` claims its output folders, refuses an output that is an
input (by device and inode) and publishes its files as one set
(``io.forecast_files.OutputSet``; docs/reliability.md, "The forecast commands").
A new subcommand adds its options in ``build_parser``, its function to
``COMMANDS``, and raises ``ForecastInputError`` for bad input.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import signal
import sys
import time

import numpy as np

from .._version import __version__
from ..io.catalogue import Catalogue, CatalogueSet
from ..io.filelock import ClaimError
from ..io.forecast_files import (ForecastInputError,
                                parse_angle, read_catalogue_csv,
                                tilt_in_range)
from ..io.safeio import describe_os_error, os_reason
from ..analysis.forecast.registry import (METHODS, fit_sharing_cuts, make_forecasters, method_of,
                                          names_where)
from ..io.forecast_model import forecasters_bytes
from . import forecast_train
from .forecast_train import add_catalogue_arguments, add_train_arguments

#: the prior ensembles' default prior (mpi_runs/priors/default.toml): name -> (law, bounds)
DEV_PRIOR = {"mu_d": ("uniform", (0.3, 0.8)), "mu_s_minus_mu_d": ("loguniform", (0.02, 0.12)),
             "sigma_mu": ("uniform", (0.005, 0.03)), "xi": ("loguniform", (1e-4, 1e-2)),
             "n_sliders": ("choice", (100, 200, 400))}


def draw_dev_parameters(n: int, seed: int, prior: dict | None = None) -> dict:
    """Draw ``n`` materials from ``prior`` (default ``DEV_PRIOR``; xi = 0 with probability 1/2)."""
    rng = np.random.default_rng(seed)
    prior = DEV_PRIOR if prior is None else prior
    out = {}
    for name, (law, b) in prior.items():
        if law == "uniform":
            out[name] = rng.uniform(b[0], b[1], n)
        elif law == "loguniform":
            out[name] = np.exp(rng.uniform(np.log(b[0]), np.log(b[1]), n))
        elif law == "choice":
            out[name] = rng.choice(np.asarray(b), n)
        elif law == "point":
            out[name] = np.full(n, b)
        else:
            raise ValueError(f"unknown law {law!r} for {name}")
    if prior is DEV_PRIOR:
        out["xi"] = np.where(rng.random(n) < 0.5, 0.0, out["xi"])
    return out


def dev_catalogue_set(n: int, seed: int = 0, initial_forces: str = "uniform", mode: str = "explore",
                      prior: dict | None = None) -> CatalogueSet:
    """A small prior ensemble run serially here: development and test data, no ceiling.

    Parameters
    ----------
    n : int
        Realisations.
    seed : int
        Seeds the draws and (``seed * 100003 + row``) the scenes.
    initial_forces : {"uniform", "zero"}
        The preparation.
    mode : str
        Speed mode of the scenes.
    prior : dict, optional
        ``DEV_PRIOR``'s form.
    """
    from ..driver import tilt
    from ..scene import Scene

    par = draw_dev_parameters(n, seed, prior)
    cats, alpha_c, status = [], [], []
    for r in range(n):
        mu_d = float(par["mu_d"][r])
        scene = Scene(n_sliders=int(par["n_sliders"][r]), xi=float(par["xi"][r]), mu_d=mu_d,
                      mu_s_mean=mu_d + float(par["mu_s_minus_mu_d"][r]),
                      sigma_mu=float(par["sigma_mu"][r]), seed=(seed * 100003 + r) % 2**32,
                      initial_forces=initial_forces, mode=mode, record="displacements")
        res = tilt(scene)
        cats.append(Catalogue.from_result(res))
        status.append(res.status)
        alpha_c.append(res.alpha_c if res.status == "avalanche" else np.nan)
    params = {"mu_d": par["mu_d"], "mu_s_mean": par["mu_d"] + par["mu_s_minus_mu_d"],
              "sigma_mu": par["sigma_mu"], "xi": par["xi"], "n_sliders": par["n_sliders"]}
    return CatalogueSet.from_catalogues(cats, params, alpha_c, status,
                                        attrs={"source": "sliders.runs.forecast.dev_catalogue_set",
                                               "seed": seed, "initial_forces": initial_forces,
                                               "mode": mode})


# ---------------------------------------------------------------------------
# the evaluation
# ---------------------------------------------------------------------------
#: leads before the avalanche at which the test runs are cut, degrees
DEFAULT_LEADS_DEG = (0.25, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0)
#: fixed tilts at which the test runs are cut, radians
DEFAULT_TILTS = (0.1, 0.2, 0.3, 0.4, 0.5)
#: the alarm: "the avalanche within DELTA", judged every STEP over the last WINDOW, degrees
ALARM_DELTA_DEG, ALARM_WINDOW_DEG, ALARM_STEP_DEG = 1.0, 6.0, 0.25
#: the lead at which the forecasters' targets are stated, degrees
TARGET_LEAD_DEG = 3.0




def _fmt(triple, scale=1.0, nd=3):
    v, lo, hi = triple
    if not np.isfinite(v):
        return "—"
    return f"{v * scale:.{nd}f} [{lo * scale:.{nd}f}, {hi * scale:.{nd}f}]"


def format_table(scores: dict, labels: dict, group_names: list, group: int) -> str:
    """One markdown table: every forecaster's metrics on one group of cuts (one lead or tilt)."""
    head = ("| forecaster | median abs err (deg) | p90 abs err (deg) | safe | 80 % coverage | "
            "CRPS (deg) | skill vs clim. | / cond. clim. | / remaining | p90 / remaining | fallback |")
    lines = [f"**{group_names[group]}** (n = {next(iter(scores.values()))[group]['n']})", "",
             head, "|" + "---|" * 11]
    deg = 180.0 / math.pi
    for name, rows in scores.items():
        m = rows[group]
        lines.append(
            f"| {labels[name]} | {_fmt(m['median_abs'], deg, 2)} | {_fmt(m['p90_abs'], deg, 2)} | "
            f"{_fmt(m['safe'], 1, 2)} | {_fmt(m['coverage'], 1, 2)} | {_fmt(m['crps'], deg, 2)} | "
            f"{_fmt(m['skill'], 1, 2)} | {_fmt(m['vs_conditioned'], 1, 2)} | "
            f"{_fmt(m['vs_remaining'], 1, 2)} | {_fmt(m['p90_vs_remaining'], 1, 2)} | "
            f"{m['fallback']:.2f} |")
    return "\n".join(lines)


def format_compact(scores: dict, labels: dict, columns: list, metric: str, scale: float,
                   title: str, nd: int = 2) -> str:
    """One metric of every forecaster (rows) over the groups (columns: leads or tilts)."""
    lines = [f"**{title}**", "", "| forecaster | " + " | ".join(columns) + " |",
             "|---|" + "---|" * len(columns)]
    for name, rows in scores.items():
        vals = [m[metric][0] if isinstance(m[metric], tuple) else m[metric] for m in rows]
        lines.append(f"| {labels[name]} | " + " | ".join(
            "—" if not np.isfinite(v) else f"{v * scale:.{nd}f}" for v in vals) + " |")
    return "\n".join(lines)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    return x


def provenance(argv) -> dict:
    """Versions and command of a file this command writes (the installed distributions' versions)."""
    from importlib.metadata import PackageNotFoundError, version

    def installed(package: str) -> str:
        try:
            return version(package)
        except PackageNotFoundError:
            return "?"

    return {"sliders": __version__, "python": sys.version.split()[0],
            **{p: installed(p) for p in ("numpy", "scikit-learn", "skops", "crepes")},
            "command": "python -m sliders.forecast " + " ".join(argv),
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


#: the forecasters a model file holds (their names)
METHOD_NAMES = {f.name for f in make_forecasters(methods_only=True)}


def evaluate(args, argv) -> int:
    """The whole evaluation (module docstring): options checked, inputs read and checked, every
    forecaster fitted and scored, the table printed, the outputs published as one set."""
    log = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
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


# ---------------------------------------------------------------------------
# evaluate: the checks before anything is read or fitted
# ---------------------------------------------------------------------------
#: the files an evaluation writes: in --out, and the figures (png and pdf) in --figures
TABLE_NAME, METRICS_NAME, MODEL_NAME = "forecast_table.md", "forecast_metrics.json", "forecaster.skops"
FIGURE_NAMES = tuple(f"forecast_{n}.{ext}" for n in ("error", "coverage", "convergence", "roc")
                     for ext in ("png", "pdf"))
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
    from ..io.safeio import resolve_target

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
    from ..io.safeio import check_output_name

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
    from ..io.forecast_files import check_output_target, claim_folder, complete_publication
    from ..io.safeio import leftovers_note, remove_leftovers, resolve_target

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


# ---------------------------------------------------------------------------
# evaluate: the inputs
# ---------------------------------------------------------------------------
def load_set(path: str, what: str = "--data") -> CatalogueSet:
    """A prior ensemble file (``sliders.io.prior_file``) as a ``CatalogueSet``; one line naming
    ``what`` if it is not one (another kind, damaged, truncated, of a newer format)."""
    from ..io.prior_file import read_prior_ensemble
    from ..io.safeio import describe_os_error, os_reason
    from ..io.storage import StorageError

    try:
        return read_prior_ensemble(path)
    except (StorageError, ValueError) as exc:
        raise ForecastInputError(f"{what}: {' '.join(str(exc).split())}") from None
    except OSError as exc:
        raise ForecastInputError(f"{what}: {describe_os_error(exc, path)}") from None


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
    from ..analysis.forecast import evaluation as ev

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


# ---------------------------------------------------------------------------
# evaluate: fitting and scoring
# ---------------------------------------------------------------------------
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


def score_forecasters(args, argv, data, robust, split, forecasters, log) -> tuple[dict, str]:
    """The metrics of every forecaster on the test part (at leads and tilts) and on the robustness
    sets (at leads), and the alarm's; returns the results (forecast_metrics.json) and the table."""
    log(f"forecast: {len(data)} realisations ({len(split.train)} train, {len(split.validation)} "
        f"validation, {len(split.test)} test) + robustness {[(k, len(v)) for k, v in robust.items()]}")
    labels = {f.name: f.label for f in forecasters}
    sets = {"test": (data, split.test)} | {k: (v, np.arange(len(v))) for k, v in robust.items()}
    results = {"provenance": provenance(argv), "split": {k: v.size for k, v in vars(split).items()},
               "leads_deg": list(args.leads_deg), "tilts": list(args.tilts),
               "labels": labels, "sets": {}}
    tables = []
    for set_name, (cset, rows) in sets.items():
        tables += score_set(args, set_name, cset, rows, forecasters, labels, results, log)
    alarm_lines = score_alarm(args, data, split, forecasters, labels, results, log)
    pr = next((f for f in forecasters if f.name == "paper_rule"), None)
    if pr is not None and pr.c_quantiles_ is not None:
        from ..analysis.forecast.base import LOWER, MEDIAN, UPPER

        results["paper_rule"] = {"c_median": pr.c_quantiles_[MEDIAN], "c_10": pr.c_quantiles_[LOWER],
                                 "c_90": pr.c_quantiles_[UPPER], "detected_share": pr.detected_share_}
    text = "\n\n".join(tables + [f"**alarm: the avalanche within {ALARM_DELTA_DEG:g}°** "
                                 f"(last {ALARM_WINDOW_DEG:g}° every {ALARM_STEP_DEG:g}°, "
                                 f"{results['alarm']['rows']} test realisations)", "\n".join(alarm_lines)])
    if "paper_rule" in results:
        c = results["paper_rule"]
        text += (f"\n\npaper's rule: alpha_c / alpha_t = {c['c_median']:.2f} "
                 f"(80 %: {c['c_10']:.2f}-{c['c_90']:.2f}), transition found in "
                 f"{100 * c['detected_share']:.0f} % of training runs")
    return results, text


def score_set(args, set_name, cset, rows, forecasters, labels, results, log) -> list[str]:
    """One set's scores at the leads (and, for the test part, the tilts) into ``results``;
    returns its tables."""
    from ..analysis.forecast import evaluation as ev

    leads = np.radians(np.asarray(args.leads_deg, dtype=float))
    tables = []
    for kind, (cuts, group, names) in {
            "lead": (*ev.cuts_at_leads(cset, rows, leads),
                     [f"{set_name}: {d:g}° before the avalanche" for d in args.leads_deg]),
            "tilt": (*ev.cuts_at_tilts(cset, rows, np.asarray(args.tilts, dtype=float)),
                     [f"{set_name}: at tilt {a:g} rad" for a in args.tilts])}.items():
        if set_name != "test" and kind == "tilt":
            continue
        preds = {}
        for f in forecasters:
            if any(getattr(cuts, n) is None for n in f.needs):
                continue
            t = time.time()
            preds[f.name] = f.quantiles(cuts, levels=True)
            log(f"forecast: {set_name}/{kind}: {f.name} on {len(cuts)} cuts in {time.time() - t:.1f} s")
        sc = ev.score(preds, cuts, group, len(names), n_boot=args.boot, seed=args.seed)
        results["sets"].setdefault(set_name, {})[kind] = {"groups": names, "scores": sc}
        tables += set_tables(args, set_name, kind, sc, labels, names)
    return tables


def set_tables(args, set_name, kind, sc, labels, names) -> list[str]:
    """The compact tables of one set and kind of cut, and the full ones asked for."""
    cols = ([f"{d:g}°" for d in args.leads_deg] if kind == "lead"
            else [f"{a:g} rad" for a in args.tilts])
    where = "before the avalanche" if kind == "lead" else "at the tilt"
    deg = 180.0 / math.pi
    tables = [format_compact(sc, labels, cols, "median_abs", deg,
                             f"{set_name}: median |error| (deg) {where}"),
              format_compact(sc, labels, cols, "coverage", 1.0,
                             f"{set_name}: coverage of the 80 % interval {where}")]
    if kind == "lead":
        tables.append(format_compact(sc, labels, cols, "vs_conditioned", 1.0,
                                     f"{set_name}: median |error| / that of the conditioned "
                                     f"climatology {where}"))
        tables.append(format_compact(sc, labels, cols, "skill", 1.0,
                                     f"{set_name}: CRPS skill against climatology {where}"))
    for g in range(len(names)):
        if args.all_tables or (kind == "lead" and args.leads_deg[g] == TARGET_LEAD_DEG):
            tables.append(format_table(sc, labels, names, g))
    return tables


def score_alarm(args, data, split, forecasters, labels, results, log) -> list[str]:
    """The alarm "the avalanche within ALARM_DELTA_DEG" on the test part into ``results``;
    returns its table's lines."""
    from ..analysis.forecast import evaluation as ev

    delta = math.radians(ALARM_DELTA_DEG)
    cuts, lead = ev.alarm_cuts(data, split.test[:args.alarm_rows], math.radians(ALARM_WINDOW_DEG),
                               math.radians(ALARM_STEP_DEG))
    alarm = {}
    thresholds = np.linspace(0.0, 1.0, 101)
    for f in forecasters:
        if f.name not in names_where("alarm") or any(getattr(cuts, n) is None for n in f.needs):
            continue
        t = time.time()
        q, _, levels = f.quantiles(cuts, levels=True)
        p = ev.alarm_probabilities(q, cuts, delta, levels)
        roc = ev.alarm_roc(p, lead, delta)
        seq = ev.alarm_sequences(p, lead, cuts.row, thresholds)
        rec = ev.recommended_threshold(seq)
        k = int(np.argmin(np.abs(thresholds - rec)))
        alarm[f.name] = {"auc": roc["auc"], "fpr": roc["fpr"], "tpr": roc["tpr"], "threshold": rec,
                         "safe": seq["safe"][k], "median_warning_deg": math.degrees(seq["median_warning"][k])
                         if np.isfinite(seq["median_warning"][k]) else None}
        log(f"forecast: alarm {f.name} on {len(cuts)} cuts in {time.time() - t:.1f} s")
    results["alarm"] = {"delta_deg": ALARM_DELTA_DEG, "window_deg": ALARM_WINDOW_DEG,
                        "step_deg": ALARM_STEP_DEG, "rows": int(np.unique(cuts.row).size), **alarm}
    lines = ["| forecaster | AUC | threshold | alarms before the avalanche | median warning (deg) |",
             "|---|---|---|---|---|"]
    for name, a in alarm.items():
        w = a["median_warning_deg"]
        lines.append(f"| {labels[name]} | {a['auc']:.3f} | {a['threshold']:.2f} | {a['safe']:.2f} | "
                     f"{'—' if w is None else f'{w:.2f}'} |")
    return lines


# ---------------------------------------------------------------------------
# evaluate: the outputs, published as one set
# ---------------------------------------------------------------------------
def publish_evaluation(args, argv, outputs, inputs, results, text, forecasters, data, split,
                       log) -> None:
    """Stage the table, the metrics, the model kept for ``predict`` and the figures whole, then
    publish them together (``forecast_files.OutputSet``): a run stopped or failing before the
    end leaves the previous run's set as it was."""
    import tempfile

    from ..io.forecast_files import OutputSet
    from ..io.safeio import resolve_target

    with OutputSet(resolve_target(args.out).real, inputs) as staged:
        staged.add(outputs[TABLE_NAME], (text + "\n").encode())
        staged.add(outputs[METRICS_NAME], (json.dumps(_jsonable(results), indent=1) + "\n").encode())
        kept = {method_of(f): f for f in forecasters if f.name in METHOD_NAMES}
        if kept:
            staged.add(outputs[MODEL_NAME], forecasters_bytes(
                kept, provenance(argv) | {"rows": int(len(split.train)), "prior": data.attrs.get(
                    "prior_digest", "dev"), "mode": str(data.attrs.get("mode", "explore"))}))
        if not args.no_figures:
            from ..figures.forecast import draw_all

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
    from ..analysis.forecast import Cuts

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


# ---------------------------------------------------------------------------
# predict: a measured catalogue
# ---------------------------------------------------------------------------
#: the choices of ``predict --method`` (the registry's): "learned" picks the learned forecaster
#: for the columns given (every feature, or angles and sizes only)
PREDICT_METHODS = ("learned", *(m for m in METHODS if m not in ("learned", "learned_blind")), "all")
#: why a method gave no forecast of its own (printed with the fallback)
FALLBACK_REASONS = {
    "ffm": "no acceleration of the rate in the last half of the tilt range seen (or fewer than "
           "10 events there): the conditioned climatology is given instead",
    "conditioned": "the conditioned climatology is the fallback itself",
    "no_displacement": "the catalogue has no displacement column: the conditioned climatology "
                       "is given instead",
    "model_based": "no lone-slider slips (they need the displacement and first/last columns) "
                   "and too few early events to estimate mu_d: the conditioned climatology is "
                   "given instead",
    "learned": "out of the training domain: the interval is widened to hold the conditioned "
               "climatology's and the training's remaining angles too",
}


def predict(args, argv=None) -> int:
    """Forecast a measured catalogue: every method asked, the domain, the model's provenance."""
    from ..analysis.forecast import Cuts

    check_predict_options(args)
    measurement = measurement_of(args)
    cat = read_catalogue_csv(args.catalogue, tilt_now_text=args.tilt_now)
    path, models, prov = load_predict_model(args)
    complete = not np.isnan(cat.displacement).any() and bool((cat.first >= 0).all())
    if not complete:  # angles and sizes only: no displacement, no movers
        cat = Catalogue(cat.alpha, cat.size, np.zeros(len(cat)), np.full(len(cat), -1),
                        np.full(len(cat), -1), cat.tilt_now)
    learned = models["learned"] if complete and "learned" in models else models["learned_blind"]
    try:
        inside, reasons = learned.domain(Cuts.from_catalogues([cat], measurement))
        chosen = {m: learned if m == "learned" else models[m] for m in
                  (PREDICT_METHODS[:-1] if args.method == "all" else (args.method,))
                  if m == "learned" or m in models}
        forecasts = [(m, f, f.predict(cat, measurement)) for m, f in chosen.items()]
    except AttributeError:  # a forecaster of another version lacks what this one reads
        raise ForecastInputError(f"{path}: written by sliders {prov.get('sliders', '?')}, whose "
                                 "forecasters this version cannot use; train it again") from None
    in_domain, reason = bool(inside[0]), reasons[0]
    top = float(learned.climatology_.alpha_c_[-1])
    if in_domain and any(fc.point > top for _, _, fc in forecasts):
        in_domain = False
        reason = (f"a forecast lies above every training avalanche angle ({math.degrees(top):.2f}°)")
    within = math.radians(args.within)
    report = {"in_domain": in_domain, "domain_reason": reason, "events": len(cat),
              "measurement": vars_of(measurement), "model": {"path": str(path), **prov},
              "methods": {m: fc.as_dict(within) | {"label": f.label,
                                                   "fallback_reason": fallback_reason(m, fc, complete)}
                          for m, f, fc in forecasts}}
    first = forecasts[0][2].as_dict(within)
    if args.json:
        print(json.dumps(_jsonable(first | report)))
    else:
        print_forecasts(args, report, forecasts, path, prov, complete)
    return 0


def measurement_of(args):
    """The ``Measurement`` the flags of ``predict`` describe (one line naming a bad flag)."""
    from ..analysis.forecast import Measurement

    try:
        return Measurement(math.radians(args.angle_resolution), args.min_size,
                           args.missed_fraction, args.size_unit, args.sliders)
    except ValueError as exc:
        raise ForecastInputError(f"measurement flags: {exc}") from None


def vars_of(measurement) -> dict:
    """The measurement as JSON values (the angle error in degrees, as given)."""
    return {"angle_resolution_deg": math.degrees(measurement.angle_resolution),
            "min_size": measurement.min_size, "missed_fraction": measurement.missed_fraction,
            "size_unit": measurement.size_unit, "n_sliders": measurement.n_sliders}


def fallback_reason(method: str, forecast, complete: bool = True) -> str | None:
    """Why ``forecast`` is a fallback (None if it is the method's own); ``complete``: the
    catalogue has displacements and movers."""
    if not forecast.fallback:
        return None
    if not complete and method.endswith("_disp"):
        return FALLBACK_REASONS["no_displacement"]
    return FALLBACK_REASONS.get("ffm" if method.startswith("ffm") else method,
                                FALLBACK_REASONS["learned"])


def load_predict_model(args):
    """The model file of ``--model`` (default: the one shipped in the package), read as data."""
    from ..io.forecast_model import ModelFileError, default_model_path, load_forecasters

    path = default_model_path() if args.model is None else args.model
    if args.model is None and not path.is_file():
        raise ForecastInputError(f"{path}: the default forecaster is missing from this "
                                 "installation; reinstall sliders, or train one with python -m "
                                 "sliders.forecast train and pass --model FILE")
    try:
        models, prov = load_forecasters(path)
    except ModelFileError as exc:
        raise ForecastInputError(str(exc)) from None
    from ..analysis.forecast import Forecaster

    wrong = next((k for k, f in models.items() if not isinstance(f, Forecaster)), None)
    if wrong is not None:
        raise ForecastInputError(f"{path}: {wrong!r} holds a {type(models[wrong]).__name__}, not "
                                 "the fitted forecasters a model file holds")
    if "learned_blind" not in models:
        raise ForecastInputError(f"{path}: no forecaster of angles and sizes (learned_blind) in it")
    return path, models, prov


def print_forecasts(args, report: dict, forecasts, path, prov, complete: bool) -> None:
    """The text output: one block per method, the domain line, the provenance if ``--verbose``."""
    deg = math.degrees
    first = forecasts[0][2]
    print(f"events: {report['events']}, tilt reached: {first.tilt_now:.4f} rad "
          f"({deg(first.tilt_now):.2f}°)")
    if not report["in_domain"]:
        print(f"OUT OF THE TRAINING DOMAIN: {report['domain_reason']}; the learned interval is "
              "widened to hold the conditioned climatology's and the training's remaining "
              "angles too, and no forecast here is "
              "calibrated: retrain on a prior that holds this pile (python -m sliders.forecast train)")
    for method, f, fc in forecasts:
        lo, hi = fc.interval
        print(f"{method} ({f.label}): avalanche angle {fc.point:.4f} rad ({deg(fc.point):.2f}°), "
              f"80 % interval {lo:.4f}-{hi:.4f} rad ({deg(lo):.2f}-{deg(hi):.2f}°), "
              f"P(within the next {args.within:g}°) = {fc.probability_within(math.radians(args.within)):.2f}")
        why = fallback_reason(method, fc, complete)
        if why:
            print(f"  fallback: {why}")
    print(f"model: {path} ({prov.get('rows', '?')} training rows, "
          f"{prov.get('created', '?')})")
    if args.verbose:
        for k, v in prov.items():
            print(f"  {k}: {f'{len(v)} rows' if k == 'held_out_rows' else v}")


def check_predict_options(args) -> None:
    """The options of ``predict`` in range (one line naming the option), before the file is read."""
    if args.tilt_now is not None:
        if not isinstance(args.tilt_now, str) or not args.tilt_now.strip():
            # argparse turns "--tilt-now=--" into an empty list
            raise ForecastInputError("--tilt-now: give the tilt reached, e.g. 27.5deg or 0.48rad")
        tilt_in_range(parse_angle(args.tilt_now, math.pi / 180.0), f"--tilt-now {args.tilt_now}")
    if not 0.0 < args.within < 90.0:
        raise ForecastInputError(f"--within {args.within:g}: the alarm's horizon must lie in "
                                 "(0, 90) degrees")


# ---------------------------------------------------------------------------
# command line: parse -> check -> compute -> publish, inside one error boundary
# ---------------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    """argparse whose refusal of the command line is one line (``ForecastInputError``)."""

    def error(self, message):
        """Raise the one-line refusal (exit status 2)."""
        raise ForecastInputError(f"{message} (see {self.prog} --help)")


def build_parser() -> argparse.ArgumentParser:
    """The ``evaluate`` and ``predict`` commands (``COMMANDS`` runs each)."""
    p = _Parser(prog="python -m sliders.forecast", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    add_evaluate_arguments(sub.add_parser(
        "evaluate", help="fit, test and score every forecaster; table and figures"))
    add_predict_arguments(sub.add_parser(
        "predict", help="forecast the avalanche angle of a measured catalogue"))
    add_train_arguments(sub.add_parser(
        "train", help="run a prior ensemble and fit the forecasters of a model file"))
    add_catalogue_arguments(sub.add_parser(
        "catalogue", help="write a simulated row as a catalogue CSV cut at a tilt or lead"))
    return p


def add_evaluate_arguments(e: argparse.ArgumentParser) -> None:
    """The options of ``evaluate``."""
    src = e.add_mutually_exclusive_group(required=True)
    src.add_argument("--data", metavar="PRIOR.h5", help="prior ensemble split into train/validation/test")
    src.add_argument("--dev", type=int, metavar="R", help="run R realisations here instead (development)")
    e.add_argument("--robust", action="append", default=[], metavar="LABEL=FILE.h5",
                   help="a test-only set with another preparation (repeatable)")
    e.add_argument("--out", default=os.path.join("results", "forecast"), help="output directory")
    e.add_argument("--figures", default=None, help="where the figures go (default --out)")
    e.add_argument("--fractions", type=float, nargs=3, default=(0.5, 0.1, 0.4),
                   metavar=("TRAIN", "VALID", "TEST"), help="the split by realisation")
    e.add_argument("--leads-deg", type=float, nargs="+", default=list(DEFAULT_LEADS_DEG),
                   metavar="DEG", help="leads before the avalanche at which test runs are cut, degrees")
    e.add_argument("--tilts", type=float, nargs="+", default=list(DEFAULT_TILTS),
                   help="fixed tilts at which the test runs are cut, radians")
    e.add_argument("--boot", type=int, default=400, help="bootstrap resamples")
    e.add_argument("--alarm-rows", type=int, default=1000, help="test realisations for the alarm")
    e.add_argument("--max-iter", type=int, default=300, help="boosting iterations")
    e.add_argument("--only", default=None, help="comma-separated forecaster names (and the baselines)")
    e.add_argument("--seed", type=int, default=0,
                   help="key of the split and of the forecasters' random draws")
    e.add_argument("--all-tables", action="store_true", help="print every lead and tilt")
    e.add_argument("--no-figures", action="store_true", help="publish no figures")
    e.add_argument("--quiet", action="store_true", help="no progress lines")


def add_predict_arguments(pr: argparse.ArgumentParser) -> None:
    """The options of ``predict``."""
    pr.add_argument("catalogue", metavar="CATALOGUE.csv",
                    help="the measured events: angle [deg] or angle [rad], size (docs/forecasting.md)")
    pr.add_argument("--tilt-now", default=None, metavar="ANGLE",
                    help="tilt reached: 0.48rad, 27.5deg, or a bare number in rad (default: the last "
                         "event's angle)")
    pr.add_argument("--within", type=float, default=ALARM_DELTA_DEG, metavar="DEG",
                    help="the alarm's horizon, degrees")
    pr.add_argument("--model", default=None, metavar="FILE",
                    help="model file written by train or evaluate (default: the one shipped "
                         "inside the package)")
    pr.add_argument("--method", default="learned", choices=PREDICT_METHODS,
                    help="the forecaster, one of {" + ", ".join(PREDICT_METHODS)
                         + "} (all: every one side by side)")
    pr.add_argument("--angle-resolution", type=float, default=0.0, metavar="DEG",
                    help="standard deviation of each measured angle's error, degrees")
    pr.add_argument("--min-size", type=float, default=1.0, metavar="SIZE",
                    help="smallest event size detected, in the size column's unit")
    pr.add_argument("--missed-fraction", type=float, default=0.0, metavar="SHARE",
                    help="share of events missed at random, in [0, 1)")
    pr.add_argument("--size-unit", default="sliders", choices=("sliders", "arbitrary"),
                    help="sliders: sizes count sliders; arbitrary: an unknown unit (grains, area, pixels)")
    pr.add_argument("--sliders", type=int, default=None, metavar="N",
                    help="the number of sliders of the pile, if known: a pile outside the "
                         "training piles' is out of the domain")
    pr.add_argument("--json", action="store_true", help="one JSON object (radians)")
    pr.add_argument("--verbose", action="store_true", help="print the model's whole provenance")


#: subcommand -> its function ``f(args, argv) -> exit status``; a new subcommand adds its parser
#: in ``build_parser`` and its entry here, and raises ForecastInputError for bad input
COMMANDS = {"evaluate": evaluate, "predict": predict,
            "train": lambda args, argv: forecast_train.train(args, argv, load_set, provenance),
            "catalogue": lambda args, argv: forecast_train.catalogue(args, argv, load_set)}


class Stopped(KeyboardInterrupt):
    """SIGTERM (or SIGINT) received: the command stops, nothing half-written is published."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _stop(signum, frame):
    raise Stopped(signum)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m sliders.forecast``: every failure is one line on stderr
    (status 2 for bad input, 1 for an I/O error or a fault, 128 + signal when stopped)."""
    from .parallel import launcher_rank

    if launcher_rank() > 0:  # a serial command: under mpirun, rank 0 alone runs it
        return 0
    argv = sys.argv[1:] if argv is None else list(argv)
    old = signal.signal(signal.SIGTERM, _stop)
    try:
        args = build_parser().parse_args(argv)
        return COMMANDS[args.command](args, argv)
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", signal.SIGINT)
        return _error(f"interrupted ({signal.Signals(signum).name}); nothing half-written was "
                      "published", 128 + signum)
    except (ForecastInputError, ClaimError) as exc:
        return _error(str(exc), 2)
    except OSError as exc:
        return _error(describe_os_error(exc, exc.filename) if exc.filename else os_reason(exc), 1)
    except MemoryError:
        return _error("out of memory", 1)
    except Exception as exc:  # noqa: BLE001 - a fault: one line, the traceback with SLIDERS_DEBUG
        if os.environ.get("SLIDERS_DEBUG"):
            import traceback

            traceback.print_exc()
        return _error(f"{type(exc).__name__}: {' '.join(str(exc).split())} (an internal error; "
                      "SLIDERS_DEBUG=1 shows where)", 1)
    finally:
        signal.signal(signal.SIGTERM, old)


def _error(message: str, code: int) -> int:
    from .parallel import error_line

    print(f"sliders.forecast: {error_line(message)}", file=sys.stderr, flush=True)
    return code
