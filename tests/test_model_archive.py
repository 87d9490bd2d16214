"""The model files' archive: fitted objects written as JSON and packed arrays, read back equal,
never building or importing what the allow-list does not name; and the trees of a boosted
model checked together, naming the tree that fails."""

from __future__ import annotations

import copy
import io
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from sliders.analysis.forecast.integrity import IntegrityError, check_boosting
from sliders.io import model_archive
from sliders.io.forecast_model import ALLOWED_NAMES, ModelFileError, load_forecasters


def zip_of(path, members: dict):
    """A zip at ``path`` of ``members``: text as it is, arrays as NumPy members."""
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in members.items():
            if isinstance(data, np.ndarray):
                buf = io.BytesIO()
                np.lib.format.write_array(buf, data)
                data = buf.getvalue()
            zf.writestr(name, data)
    return path


@pytest.fixture(scope="module")
def boosted():
    """A quantile regressor of 6 trees on 3 features, as the learned forecasters fit them."""
    from sklearn.ensemble import HistGradientBoostingRegressor

    rng = np.random.default_rng(0)
    x = rng.normal(size=(300, 3))
    y = x[:, 0] + 0.1 * rng.normal(size=300)
    return HistGradientBoostingRegressor(loss="quantile", quantile=0.5, max_iter=6,
                                         early_stopping=False, random_state=0).fit(x, y), x


def test_a_tree_of_python_and_numpy_values_comes_back_equal_and_shared():
    shared = np.arange(6.0).reshape(2, 3)
    records = np.zeros(3, dtype=[("value", "<f8"), ("left", "<u4"), ("leaf", "u1")])
    records["left"] = [1, 2, 0]
    root = {"tuple": (1, 2.5, None, True, "text"), 7: "an int key", "nan": float("nan"),
            "arrays": [shared, shared, records, np.float32(1.5), np.int64(-3), np.array(4.0)],
            "dtype": records.dtype, "empty": np.empty((0, 2), dtype=np.int32)}
    back = model_archive.loads(model_archive.dumps(root, ALLOWED_NAMES), ALLOWED_NAMES)
    assert back["tuple"] == root["tuple"] and back[7] == "an int key"
    assert np.isnan(back["nan"])
    a, b, rec, f32, i64, zero_d = back["arrays"]
    assert a is b and np.array_equal(a, shared) and a.flags.c_contiguous
    assert rec.dtype == records.dtype and np.array_equal(rec, records)
    assert type(f32) is np.float32 and f32 == 1.5 and type(i64) is np.int64 and i64 == -3
    assert zero_d.shape == () and zero_d == 4.0
    assert back["dtype"] == records.dtype and back["empty"].shape == (0, 2)


def test_a_fitted_regressor_predicts_the_same_after_the_archive(boosted):
    model, x = boosted
    blob = model_archive.dumps({"m": model}, ALLOWED_NAMES)
    assert model_archive.dumps({"m": model}, ALLOWED_NAMES) == blob  # no date: the same bytes
    with zipfile.ZipFile(io.BytesIO(blob)) as zf:  # 6 trees' nodes in one packed array
        assert sum(n.startswith("arrays/") for n in zf.namelist()) <= 8
    back = model_archive.loads(blob, ALLOWED_NAMES)["m"]
    assert np.array_equal(back.predict(x), model.predict(x))


def test_a_name_off_the_list_is_refused_before_anything_is_imported():
    """``this`` prints the Zen of Python when imported: the refusal comes first."""
    code = ("import io, json, sys, zipfile\n"
            "from sliders.io import model_archive as ma\n"
            "tree = json.dumps({'object': ['this.s', [], None], 'id': 0})\n"
            "buf = io.BytesIO()\n"
            "with zipfile.ZipFile(buf, 'w') as z: z.writestr('tree.json', tree)\n"
            "try:\n"
            "    ma.loads(buf.getvalue(), {'copyreg.__newobj__'})\n"
            "except ma.UntrustedNames as e:\n"
            "    print('refused', e.names)\n"
            "print('this' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.splitlines() == ["refused ['this.s']", "False"], out.stdout


def test_the_writer_refuses_what_is_not_data():
    with pytest.raises(model_archive.ArchiveError, match="holds objects"):
        model_archive.dumps(np.array([object()]), ALLOWED_NAMES)
    with pytest.raises(model_archive.ArchiveError, match="allow-list"):
        model_archive.dumps({"f": zipfile.ZipInfo()}, ALLOWED_NAMES)


@pytest.mark.parametrize("tree, change, words", [
    (3, lambda nodes: nodes["left"].__setitem__(0, nodes.size + 5), "child index"),
    (0, lambda nodes: nodes["left"].__setitem__(0, 0), "child index"),
    (5, lambda nodes: nodes["right"].__setitem__(0, nodes["left"][0]), "one tree"),
    (2, lambda nodes: nodes["value"].__setitem__(np.flatnonzero(nodes["is_leaf"])[0], np.nan),
     "leaf value"),
    (4, lambda nodes: nodes["feature_idx"].__setitem__(0, 3), "feature"),
])
def test_the_trees_are_checked_together_and_the_failing_one_named(boosted, tree, change, words):
    model, _ = boosted
    check_boosting(model, 3, "regressor")
    broken = copy.deepcopy(model)
    change(broken._predictors[tree][0].nodes)
    with pytest.raises(IntegrityError, match=f"regressor, tree {tree}: .*{words}"):
        check_boosting(broken, 3, "regressor")


def test_a_tree_of_more_than_16_mb_is_refused_before_it_is_parsed(tmp_path):
    """20 MB of JSON (a list of zeros) deflated to a few kB: refused from its declared size."""
    path = tmp_path / "wide.zip"
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("tree.json", "[" + "0," * 10_000_000 + "0]")
    assert path.stat().st_size < 2**20
    with pytest.raises(ModelFileError, match="tree inflates to 19 MB"):
        load_forecasters(path)


@pytest.mark.parametrize("tree, words", [
    ("[" * 5000 + "]" * 5000, "not JSON"),
    ("{{{", "not JSON"),
    ('{"dict": [["format", "sliders-forecaster-4"], ["forecasters", {"ref": 99}]]}', "KeyError"),
    ('{"dict": [["forecasters", {"array": [5, 0, [3]], "id": 0}]]}', "IndexError"),
    ('{"dict": [["forecasters", {"array": [0, -1, [3]], "id": 0}]]}', "past the end"),
    ('{"dict": [[[1, 2], 3]]}', "TypeError"),
    ('{"object": ["builtins.eval", ["1"], null], "id": 0}', "refused"),
])
def test_a_malformed_tree_is_one_line_naming_the_file(tmp_path, tree, words):
    path = zip_of(tmp_path / "bad.zip", {"tree.json": tree, "arrays/0.npy": np.zeros(2)})
    with pytest.raises(ModelFileError, match=words) as exc:
        load_forecasters(path)
    assert str(path) in str(exc.value) and "\n" not in str(exc.value)


def test_a_zip_of_another_format_asks_to_be_trained_again(tmp_path):
    """A zip of NumPy members and a schema of its own (as other model formats write)."""
    path = zip_of(tmp_path / "other.skops", {"schema.json": '{"__class__": "dict"}',
                                              "0.npy": np.zeros(2)})
    with pytest.raises(ModelFileError, match="no tree.json.*train it again"):
        load_forecasters(path)
