"""``python -m sliders.forecast``: the measured-catalogue reader, predict, and the scores."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from sliders.analysis.forecast import LEVELS
from sliders.analysis.forecast import evaluation as ev
from sliders.analysis.forecast.learned import Learned
from sliders.analysis.forecast.registry import METHODS, method_of
from sliders.io.forecast_files import ForecastInputError, read_catalogue_csv
from sliders.analysis.forecast.model_file import load_forecasters, save_forecasters
from sliders.io.forecast_model import ModelFileError
from sliders.runs.forecast import cli
from sliders.runs.forecast.evaluate import MODEL_NAME

from helpers import synthetic_set

pytestmark = pytest.mark.slow  # the forecast commands, each a process loading scikit-learn


def write(tmp_path, text, name="cat.csv"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


GOOD = "angle [deg],size,displacement\n1.0,1,0.01\n2.5,3,0.05\n4.0,2,0.02\n"


@pytest.mark.parametrize("text, message", [
    ("", "empty file"),
    ("# only a comment\n", "empty file"),
    ("size,displacement\n1,0.1\n", "missing column 'angle"),
    ("angle [deg],displacement\n1,0.1\n", "missing column 'size'"),
    ("angle,size\n1,1\n", "needs its unit"),
    ("angle [grad],size\n1,1\n", "unit 'grad' not understood"),
    ("angle [deg],size\n2,1\n1,1\n", "row 3, column 'angle': '1' is below the previous row"),
    ("angle [deg],size\n1,1\n2,x\n", "row 3, column 'size': 'x' is not a number"),
    ("angle [deg],size\n1,1\n2,0\n", "row 3, column 'size': '0' must be a positive number"),
    ("angle [deg],size\n1,1,3\n", "row 2: 3 fields"),
    ("angle [deg],size\n", "no events"),
    ("# a comment line\nangle [deg],size\n\n1,1\n2,y\n", "row 5, column 'size'"),
])
def test_bad_catalogues_get_one_line_naming_row_and_column(tmp_path, text, message):
    with pytest.raises(ForecastInputError, match=message):
        read_catalogue_csv(write(tmp_path, text))


def test_catalogue_units_and_tilt_now(tmp_path):
    cat = read_catalogue_csv(write(tmp_path, GOOD), tilt_now_text="5deg")
    assert np.allclose(cat.alpha, np.radians([1.0, 2.5, 4.0]))
    assert math.isclose(cat.tilt_now, math.radians(5.0))
    rad = read_catalogue_csv(write(tmp_path, "angle [rad],size\n0.1,1\n0.2,1\n"))
    assert rad.tilt_now == 0.2 and np.all(rad.first == -1)
    with pytest.raises(ForecastInputError, match="below the last event"):
        read_catalogue_csv(write(tmp_path, GOOD), tilt_now_text="3deg")
    with pytest.raises(ForecastInputError, match="not understood"):
        read_catalogue_csv(write(tmp_path, GOOD), tilt_now_text="five")


def test_predict_command_prints_the_forecast_and_json(tmp_path):
    train = synthetic_set(30)
    models = {"learned": Learned(draws_per_row=6, max_iter=10, random_state=0).fit(train),
              "learned_blind": Learned(draws_per_row=6, max_iter=10, inputs="angles_sizes").fit(train)}
    path = str(tmp_path / "model.zip")
    save_forecasters(path, models, {"command": "test"})
    cat = write(tmp_path, "angle [deg],size,displacement\n"
                + "".join(f"{a:.3f},1,0.01\n" for a in np.linspace(1, 20, 80)))
    run = [sys.executable, "-m", "sliders.forecast", "predict", cat, "--model", path]
    out = subprocess.run(run + ["--json", "--tilt-now", "21deg"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    # no slider positions in the file: the forecaster of angles and sizes
    assert d["forecaster"] == "learned_blind" and d["interval"][0] <= d["alpha_c"] <= d["interval"][1]
    assert d["alpha_c"] > math.radians(21) and 0 <= d["probability_within"] <= 1
    text = subprocess.run(run, capture_output=True, text=True)
    assert text.returncode == 0 and "80 % interval" in text.stdout
    bad = subprocess.run(run[:4] + [write(tmp_path, "angle,size\n1,1\n", "b.csv"), "--model", path],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    # a byte flipped inside the archive's header: its CRC-32 fails before anything is built
    damaged = tmp_path / "damaged.zip"
    raw = bytearray(open(path, "rb").read())
    tree = zipfile.ZipFile(path).getinfo("header.json")
    raw[tree.header_offset + 30 + len(tree.filename) + tree.compress_size // 2] ^= 0xFF
    damaged.write_bytes(bytes(raw))
    with pytest.raises(ModelFileError, match="damaged model file"):
        load_forecasters(str(damaged))


def test_scores_of_a_perfect_and_of_a_late_forecaster():
    cset = synthetic_set(60)
    cuts, group = ev.cuts_at_leads(cset, np.arange(60), [0.01, 0.05])
    truth = cuts.alpha_c
    perfect = np.repeat(truth[:, None], LEVELS.size, axis=1)
    late = perfect + 0.02
    clim = np.tile(np.quantile(cset.alpha_c, LEVELS), (len(cuts), 1))
    preds = {"climatology": (clim, np.zeros(len(cuts), bool)),
             "conditioned": (clim, np.zeros(len(cuts), bool)),
             "perfect": (perfect, np.zeros(len(cuts), bool)),
             "late": (late, np.zeros(len(cuts), bool))}
    sc = ev.score(preds, cuts, group, 2, n_boot=50)
    p, lt = sc["perfect"][1], sc["late"][1]
    assert p["median_abs"][0] == 0 and p["skill"][0] == 1.0 and p["coverage"][0] == 1.0
    assert math.isclose(lt["median_abs"][0], 0.02) and lt["safe"][0] == 0.0
    assert math.isclose(lt["vs_remaining"][0], 0.02 / 0.05)
    assert lt["crps"][1] <= lt["crps"][0] <= lt["crps"][2]


def test_recalibrated_intervals_cover_about_their_share():
    # 80 calibration rows: about 600 cuts, two Mondrian bins of the tilt reached
    train, valid, test = synthetic_set(60, seed=1), synthetic_set(80, seed=2), synthetic_set(60, seed=3)
    f = Learned(draws_per_row=10, max_iter=30, random_state=0).fit(train, validation=valid)
    from sliders.analysis.forecast import training_cuts

    cuts = training_cuts(test, 10, np.random.default_rng(9))
    q, _ = f.quantiles(cuts)
    cov = np.mean((q[:, 1] <= cuts.alpha_c) & (cuts.alpha_c <= q[:, 17]))
    assert 0.65 < cov < 0.92


def test_out_of_fold_calibration_covers_about_its_share_in_tilt_and_event_bins():
    """Without a validation set the calibration uses every training row's out-of-fold residuals,
    in Mondrian bins of the tilt reached, of the events so far within each, and of the predicted
    remaining angle within those; every bin holds MIN_PER_BIN calibration cuts at least."""
    from sliders.analysis.forecast.learned import MIN_PER_BIN

    train, test = synthetic_set(150, seed=1), synthetic_set(60, seed=3)
    f = Learned(draws_per_row=24, max_iter=30, calibration_bins=2, calibration_event_bins=2,
                calibration_remaining_bins=2, random_state=0).fit(train)
    assert f.n_calibration_cuts_ == f.n_training_cuts_ >= 8 * MIN_PER_BIN
    assert f.calibration_edges_.size == 1 and f.calibration_event_edges_.shape == (2, 1)
    assert f.calibration_remaining_edges_.shape == (4, 1)  # two of predicted remaining angle
    filled = f.calibration_counts_[f.calibration_counts_ > 0]
    assert filled.size > 4 and filled.min() >= MIN_PER_BIN
    assert filled.sum() == f.n_calibration_cuts_
    from sliders.analysis.forecast import training_cuts

    cuts = training_cuts(test, 10, np.random.default_rng(9))
    q, _ = f.quantiles(cuts)
    cov = np.mean((q[:, 1] <= cuts.alpha_c) & (cuts.alpha_c <= q[:, 17]))
    assert 0.65 < cov < 0.92
    with pytest.raises(ValueError, match="calibration"):
        Learned(calibration="lead").fit(train)


def test_alarm_sequences_and_roc():
    lead = np.tile([0.05, 0.03, 0.01], 4)
    row = np.repeat(np.arange(4), 3)
    prob = np.tile([0.1, 0.4, 0.9], 4)
    seq = ev.alarm_sequences(prob, lead, row, [0.3, 0.95])
    assert list(seq["safe"]) == [1.0, 0.0] and math.isclose(seq["median_warning"][0], 0.03)
    assert ev.recommended_threshold(seq) == 0.3
    assert ev.alarm_roc(prob, lead, 0.015)["auc"] == 1.0


def test_evaluate_command_end_to_end(tmp_path, capsys):
    """A tiny development evaluation: the table printed, the files and the four figures written."""
    out = tmp_path / "fc"
    code = cli.main(["evaluate", "--dev", "16", "--out", str(out), "--max-iter", "5", "--boot", "20",
                    "--alarm-rows", "4", "--leads-deg", "1", "3", "--tilts", "0.2", "--quiet"])
    assert code == 0
    text = capsys.readouterr().out
    assert "3° before the avalanche" in text and "learned, every feature" in text and "AUC" in text
    metrics = json.loads((out / "forecast_metrics.json").read_text())
    assert metrics["split"] == {"train": 8, "validation": 2, "test": 6}
    assert "zero" in metrics["sets"] and metrics["provenance"]["command"].startswith("python -m")
    for name in ("forecast_error", "forecast_coverage", "forecast_convergence", "forecast_roc"):
        assert (out / f"{name}.png").stat().st_size > 10000
    model, prov = load_forecasters(out / MODEL_NAME)
    assert set(model) == set(METHODS) and prov["rows"] == 8 and prov["prior"] == "dev"
    assert all(method_of(f) == m for m, f in model.items())
