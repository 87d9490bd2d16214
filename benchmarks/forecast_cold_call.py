"""Cost of a cold ``predict``: a fresh interpreter forecasting a 150-event catalogue, against a
fresh interpreter importing NumPy and SciPy; and of ``predict --help``, against one importing
numpy and argparse.

    .venv/bin/python benchmarks/forecast_cold_call.py --runs 7

A bench forecast is typed, or called by an acquisition script, in a fresh
process: its cost is mostly imports and the model's load.  The model file is
plain arrays evaluated with NumPy (no scikit-learn), so the reference is
``python -c "import numpy, scipy"``, run interleaved with the forecast
(reference, forecast, reference, forecast...) so that both meet the same load
of the machine; the medians of the wall clock and of the CPU time (user +
system of the child) are compared, and their difference.  The target: the
forecast at most ``TARGET_EXTRA_S`` seconds more than the import.  The
catalogue is 150 events accelerating towards an avalanche near 31°
(deterministic, no simulation needed).  ``predict --help`` is timed the same
way against ``python -c "import numpy, argparse"`` (the parser needs no more;
target: a ratio of at most 1).  Every process writes and reads its bytecode in
a folder of this run's (a first, uncounted run of each fills it), as an
installed package's would be.  Prints one JSON line and writes it to
benchmarks/results/forecast_cold_call.json.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
#: the forecast at most this many seconds (wall clock, median) more than importing numpy and scipy
TARGET_EXTRA_S = 0.5
#: ``predict --help`` at most the import of numpy and argparse
HELP_TARGET_RATIO = 1.0


def accelerating_events(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The angles (degrees, increasing) and sizes of ``n`` events accelerating towards an
    avalanche near 31°."""
    rng = np.random.default_rng(seed)
    # an event rate growing as 1 / (31° - alpha): angles from its inverse distribution function
    u = np.sort(rng.random(n))
    alpha = 31.0 - 31.0 * np.exp(-3.0 * u)
    size = np.maximum(1, np.round(rng.pareto(1.5, n) + 1)).astype(int)
    return alpha, size


def publish(out: dict, path: str) -> None:
    """Print a benchmark's figures as one JSON line and write that line to ``path``."""
    line = json.dumps(out)
    print(line)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as fh:
        fh.write(line + "\n")


def example_csv(path: str, n: int = 150, seed: int = 7) -> float:
    """A catalogue of ``n`` events accelerating towards an avalanche near 31°, as the CSV
    ``predict`` reads; returns the tilt reached (degrees)."""
    alpha, size = accelerating_events(n, seed)
    with open(path, "w") as fh:
        fh.write("angle [deg],size\n")
        fh.writelines(f"{a:.4f},{s}\n" for a, s in zip(alpha, size))
    return float(alpha[-1]) + 0.05


def timed(cmd, env) -> tuple[float, float]:
    """Wall and CPU seconds (user + system) of one run of ``cmd``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=env)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=7, help="runs of each, interleaved")
    ap.add_argument("--out", default=os.path.join(HERE, "results", "forecast_cold_call.json"))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        env["PYTHONPYCACHEPREFIX"] = os.path.join(tmp, "pycache")
        cat = os.path.join(tmp, "c150.csv")
        tilt = example_csv(cat)
        forecast = [sys.executable, "-m", "sliders.forecast", "predict", cat,
                    "--tilt-now", f"{tilt:.4f}deg", "--json"]
        commands = {"forecast": forecast,
                    "import_numpy_scipy": [sys.executable, "-c", "import numpy, scipy"],
                    "help": [sys.executable, "-m", "sliders.forecast", "predict", "--help"],
                    "import_numpy_argparse": [sys.executable, "-c", "import numpy, argparse"]}
        for cmd in commands.values():
            timed(cmd, env)  # warm the disk cache and the .pyc files
        times = {k: [] for k in commands}
        for _ in range(args.runs):
            for k, cmd in commands.items():
                times[k].append(timed(cmd, env))
    med = {k: {"wall_s": statistics.median(w for w, _ in v),
               "cpu_s": statistics.median(c for _, c in v)} for k, v in times.items()}
    ratio = {k: med["forecast"][k] / med["import_numpy_scipy"][k] for k in ("wall_s", "cpu_s")}
    extra = {k: med["forecast"][k] - med["import_numpy_scipy"][k] for k in ("wall_s", "cpu_s")}
    help_ratio = {k: med["help"][k] / med["import_numpy_argparse"][k] for k in ("wall_s", "cpu_s")}
    out = {"benchmark": "forecast_cold_call", "events": 150, "runs": args.runs,
           "median": med, "extra_s": extra, "ratio": ratio, "target_extra_s": TARGET_EXTRA_S,
           "within_target": bool(extra["wall_s"] <= TARGET_EXTRA_S),
           "help_ratio": help_ratio, "help_target_ratio": HELP_TARGET_RATIO,
           "help_within_target": bool(help_ratio["wall_s"] <= HELP_TARGET_RATIO),
           "load_average": os.getloadavg()[0], "cpus": os.cpu_count(),
           "raw": {k: [[round(w, 4), round(c, 4)] for w, c in v] for k, v in times.items()},
           "python": sys.version.split()[0], "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    publish(out, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
