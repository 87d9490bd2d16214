"""The engine contract (src/sliders/engine/contract.py) is the one declaration of the
per-event schema and the packed kernel parameters: the Fortran side agrees."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest

from sliders import Scene, status
from sliders.engine import contract
from sliders.engine.contract import Chunk, join_chunks
from sliders.parts.loading import LOADINGS

ROOT = Path(__file__).resolve().parents[1]


def _fortran_constants() -> dict[str, int]:
    text = (ROOT / "fortran" / "sliders_contract.f90").read_text()
    return {name: int(value) for name, value in re.findall(r"\b(\w+)\s*=\s*(\d+)\b", text)}


@pytest.mark.parametrize("prefix, counts, groups", [
    ("ev", ("n_event_real", "n_event_int"), (contract.REAL_FIELDS, contract.INT_FIELDS)),
    ("par", ("n_real_params", "n_int_params"),
     (contract.REAL_PARAMETERS, contract.INT_PARAMETERS)),
])
def test_fortran_positions_match_the_contract(prefix, counts, groups):
    """<prefix>_<name> is the name's 1-based position in its group (event
    columns by type, packed parameters by type); n_* are the group sizes."""
    consts = _fortran_constants()
    for count, names in zip(counts, groups):
        assert consts[count] == len(names)
        for position, name in enumerate(names, start=1):
            assert consts[f"{prefix}_{name}"] == position, name


def test_schema_covers_every_event_field():
    assert contract.REAL_FIELDS + contract.INT_FIELDS != ()
    assert set(contract.REAL_FIELDS) | set(contract.INT_FIELDS) == set(contract.EVENT_FIELDS)


def test_pack_parameters_takes_the_scene_values():
    scene = Scene(n_sliders=5, xi=0.01, seed=2**31 + 3, ends="walls", alpha_max=1.0)
    real, ints = contract.pack_parameters(scene, 0.25, True, False, 7)
    by_name = dict(zip(contract.REAL_PARAMETERS, real))
    assert by_name["xi"] == 0.01 and by_name["drive"] == 0.25 and by_name["alpha_max"] == 1.0
    assert by_name["max_event_duration"] == scene.max_event_duration
    ints = dict(zip(contract.INT_PARAMETERS, ints))
    assert ints == {"walls": 1, "seed": 2**31 + 3, "record_sparse": 1, "relax_only": 0,
                    "max_events": 7, "loading": contract.LOADING_CODES["tilt"]}
    pushed = Scene(n_sliders=5, loading="pushed_end", incline=0.1, driver_stiffness=3.0,
                   drive_max=9.0)
    real, ints = contract.pack_parameters(pushed, 0.5, False, False, 1)
    by_name = dict(zip(contract.REAL_PARAMETERS, real))
    assert (by_name["incline"], by_name["driver_stiffness"], by_name["drive_max"]) == (0.1, 3.0, 9.0)
    assert dict(zip(contract.INT_PARAMETERS, ints))["loading"] == \
        contract.LOADING_CODES["pushed_end"]


def test_fortran_loading_codes_match_the_contract():
    consts = _fortran_constants()
    assert {name: consts[f"loading_{name}"] for name in contract.LOADING_CODES} == \
        contract.LOADING_CODES
    assert set(contract.LOADING_CODES) == set(LOADINGS)


def test_kernel_boundary_is_packed():
    """tilt_advance takes at most 12 arguments from Python."""
    from sliders import _kernel

    doc = _kernel.tilt_advance.__doc__
    call = re.search(r"tilt_advance\(([^)]*)\)", doc).group(1)
    assert len([a for a in call.split(",") if a.strip()]) <= 12


def test_the_fortran_backend_does_not_depend_on_the_reference():
    tree = ast.parse((ROOT / "src" / "sliders" / "engine" / "fortran_engine.py").read_text())
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert "reference" not in imported


def _chunk(alphas, moved):
    events = {f: np.zeros(len(alphas), dtype=contract.EVENT_DTYPES[f]) for f in contract.EVENT_FIELDS}
    events["drive"] = np.array(alphas, dtype=float)
    ptr = np.concatenate([[0], np.cumsum([len(m) for m in moved])]).astype(np.int64)
    index = np.array([i for m in moved for i in m], dtype=np.int64)
    return Chunk(status.RUNNING, events, ptr, index, index.astype(float) / 10)


def test_join_chunks_shifts_the_csr_pointers():
    joined = join_chunks([_chunk([0.1, 0.2], [[0], [1, 2]]), _chunk([0.3], [[4, 5, 6]])],
                         status.AVALANCHE, alpha_c=0.4)
    assert joined.status == status.AVALANCHE and joined.alpha_c == 0.4
    assert joined.events["drive"].tolist() == [0.1, 0.2, 0.3]
    assert joined.sparse_ptr.tolist() == [0, 1, 3, 6]
    assert joined.sparse_index.tolist() == [0, 1, 2, 4, 5, 6]
    assert joined.events["n_moved"].dtype == np.int64
    empty = join_chunks([], status.INTERRUPTED)
    assert empty.n_events == 0 and empty.sparse_ptr.tolist() == [0]
