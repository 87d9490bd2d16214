"""Coverage per kind of pile under other Mondrian bins of a model's conformal calibration.

    .venv/bin/python benchmarks/forecast_calibration_bins.py MODEL.zip learned_blind \
        4,4,1,1 4,4,3,1 4,4,1,3 4,4,3,3 4,4,4,4

Each scheme is (bins of the tilt reached, of the events so far, of the mean event
size, of the predicted remaining angle), nested in that order, optionally followed by
the interval it reports: ``4,4,2,3:3-10`` the shortest 80 % interval with its low
share from 3 % to 10 % (the model's own is 1-10 %), ``4,4,2,3:central`` the central one.  The model's
regressors are kept; the out-of-fold residuals of its training rows are computed
once (the model's own recipe, ``Learned._out_of_fold``), then each scheme
recalibrates on them and is measured on the held-out rows: random cuts and 3°,
1°, 0.25° and 12° before the avalanche, per kind of pile (``forecast_skill.KINDS``).
Prints one block per scheme.
"""
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from forecast_skill import blind, kinds_of  # noqa: E402
from sliders.analysis.forecast.base import LOWER, UPPER  # noqa: E402
from sliders.analysis.forecast.evaluation import cuts_at_leads  # noqa: E402
from sliders.analysis.forecast.features import training_cuts  # noqa: E402
from sliders.analysis.forecast import learned  # noqa: E402
from sliders.analysis.forecast.learned import with_design  # noqa: E402
from sliders.analysis.forecast.model_file import load_forecasters  # noqa: E402
from sliders.runs.forecast.catalogue import load_set  # noqa: E402

model, which = sys.argv[1], sys.argv[2]
schemes = [(tuple(int(v) for v in a.split(":")[0].split(",")), (a.split(":") + [""])[1])
           for a in sys.argv[3:]]
models, prov = load_forecasters(model)
f = models[which]
data = load_set(os.path.join(os.path.dirname(os.path.abspath(model)),
                             os.path.basename(prov["data_files"][0])))
ok = np.isfinite(data.alpha_c)
held = np.zeros(len(data), bool)
held[prov["held_out_rows"]] = True
train = data.subset(np.flatnonzero(ok & ~held))
test = data.subset(np.flatnonzero(ok & held))
t = time.time()
rng = np.random.default_rng(0)
cuts = f.training_cuts(train, rng)
x = f.design(cuts)[0][:, f.columns_]
y = np.log(np.maximum(cuts.alpha_c - cuts.tilt_now, 1e-9))
z = f._out_of_fold(cuts, x, y, rng)
print(f"oof {time.time() - t:.0f} s", flush=True)
deg = blind if which == "learned_blind" else (lambda c: c)
inputs = f.inputs
groups = {"random": with_design(deg(training_cuts(test, 10, np.random.default_rng(0))), inputs)}
lc, g = cuts_at_leads(test, np.arange(len(test)), np.radians([3.0, 1.0, 0.25, 12.0]))
lc = with_design(deg(lc), inputs)
kinds = kinds_of(test)
print(f"test cuts {time.time() - t:.0f} s", flush=True)
shares, interval = learned.LOW_SHARES, f.interval
for sch, reported in schemes:
    f.calibration_bins, f.calibration_event_bins, f.calibration_size_bins, f.calibration_remaining_bins = sch
    f.interval = "central" if reported == "central" else interval
    low, _, high = reported.partition("-")
    learned.LOW_SHARES = np.arange(float(low), float(high) + 0.5) if high else shares
    f._fit_calibration(cuts, z)
    res = {}
    qr = f.quantiles(groups["random"])[0]
    ql = f.quantiles(lc)[0]
    sets = {"rand": (qr, groups["random"].alpha_c, groups["random"].row, None)}
    for j, name in enumerate(("3", "1", "0.25", "12")):
        sets[name] = (ql, lc.alpha_c, lc.row, g == j)
    line = [f"{sch} {reported or 'own interval'} cells={f.calibration_counts_.size} min={f.calibration_counts_[f.calibration_counts_>0].min()}"]
    for kname, mask in kinds.items():
        parts = []
        for sname, (q, tr, row, keep) in sets.items():
            m = mask[row] if keep is None else mask[row] & keep
            cov = np.mean((q[m, LOWER] <= tr[m]) & (tr[m] <= q[m, UPPER]))
            parts.append(f"{sname}:{cov:.2f}")
        line.append(f"  {kname:9s} " + " ".join(parts))
    print("\n".join(line), flush=True)
