"""The extremity indicator of scene C (``observables.extremity_activity``) on hand-made events."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import sliders
from sliders.analysis import observables as ob
from sliders.result import EventSparse

pytestmark = pytest.mark.slow  # ensembles run as commands


def fake_run(n, events):
    """A run of n sliders whose events are (alpha, {slider (0-based): displacement})."""
    ptr, index, value = [0], [], []
    for _, moved in events:
        index += sorted(moved)
        value += [moved[k] for k in sorted(moved)]
        ptr.append(len(index))
    d = EventSparse(np.array(ptr), np.array(index, dtype=np.int64), np.array(value, dtype=float), n)
    return SimpleNamespace(scene=SimpleNamespace(n_sliders=n), displacement=d,
                           alpha=np.array([a for a, _ in events]))


def test_shares_and_extents_by_hand():
    run = fake_run(8, [
        (0.05, {0: 1.0, 1: 1.0, 2: 1.0}),  # bin 0: region of 3 at the up-slope end
        (0.07, {5: 0.5}),  # bin 0: middle-ish, not attached to an end
        (0.15, {7: 2.0, 6: -2.0}),  # bin 1: region of 2 at the down-slope end (signs ignored)
        (0.16, {4: 1.0, 5: 1.0}),  # bin 1: sliders 5, 6, next to the region of sliders 7, 8
    ])
    e = ob.extremity_activity(run, [0.0, 0.1, 0.2, 0.3])
    np.testing.assert_array_equal(e["events"], [2, 2, 0])
    np.testing.assert_allclose(e["total"], [3.5, 6.0, 0.0])
    np.testing.assert_allclose(e["up"], [2.0, 0.0, 0.0])  # sliders 1, 2 (first quarter of 8)
    np.testing.assert_allclose(e["down"], [0.0, 4.0, 0.0])  # sliders 7, 8
    np.testing.assert_allclose(e["extent_up"], [3 / 8, 0.0, 0.0])
    # bin 1: sliders 5..8 all moved (4, 5 in one event, 6, 7 in the other): 4 of 8
    np.testing.assert_allclose(e["extent_down"], [0.0, 4 / 8, 0.0])


def test_whole_chain_moving_spans_both_ends():
    run = fake_run(4, [(0.2, {0: 1.0, 1: 1.0, 2: 1.0, 3: 1.0})])
    e = ob.extremity_activity(run, [0.0, 0.5])
    assert e["extent_up"][0] == e["extent_down"][0] == 1.0
    assert e["up"][0] == e["down"][0] == 1.0  # one slider is the end quarter of 4


def test_matches_the_dense_map_of_a_real_run():
    r = sliders.tilt(sliders.Scene(n_sliders=12, xi=0.001, seed=2))
    edges = np.arange(0.0, 0.6, 0.05)
    e = ob.extremity_activity(r, edges)
    dense = np.abs(r.displacement.dense())
    b = np.searchsorted(edges, r.alpha, side="right") - 1
    for j in range(edges.size - 1):
        rows = dense[b == j]
        assert e["total"][j] == pytest.approx(rows.sum())
        assert e["up"][j] == pytest.approx(rows[:, :3].sum())
        assert e["down"][j] == pytest.approx(rows[:, -3:].sum())


def test_onset_of_a_region_spanning_half_the_chain():
    """The reproduction's onset: from the first bin where the end region spans >= half of N
    in every later bin with events, the avalanche's own bin excluded."""
    from sliders.analysis.precursors import extremity_profile

    n = 8
    events = [(0.11, {0: 0.1}),  # small activity at the up-slope end
              (0.41, {4: 1.0, 5: 1.0, 6: 1.0, 7: 1.0}),  # down-slope half from bin 0.40
              (0.45, {3: 1.0, 4: 1.0, 5: 1.0, 6: 1.0, 7: 1.0}),
              (0.47, {7: 1.0}),  # the avalanche's bin (alpha_c = 0.475): not judged
              ]
    run = fake_run(n, events)
    run.alpha_c = 0.475
    p = extremity_profile([run])
    assert p["onset_down"][0] == pytest.approx(0.40)
    assert np.isnan(p["onset_up"][0])
    assert p["overall_down"] == pytest.approx(5.0 / 10.1)  # sliders 7, 8: 2 + 2 + 1 of 10.1
