"""The alarm's skill on follows of known answer (plain arrays, fast)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sliders.analysis.forecast.alarm_skill import (FALSE_ALARM_DEG, alarm_table,
                                                   choose_threshold, first_alarms)


def follows():
    """Three piles followed from 10° to 0.1° before their avalanche (0.1° steps): P rises
    1° before the first, 5° before the second (a false alarm at any threshold below 0.8),
    never above 0.5 for the third."""
    lead = np.radians(np.arange(10.0, 0.05, -0.1))
    p1 = np.where(lead <= math.radians(1.0) + 1e-9, 0.9, 0.1)
    p2 = np.where(lead <= math.radians(5.0) + 1e-9, 0.7, 0.2)
    p3 = np.full(lead.size, 0.45)
    prob = np.concatenate([p1, p2, p3])
    return prob, np.tile(lead, 3), np.repeat([7, 8, 9], lead.size)


def test_the_first_alarm_hits_warnings_and_false_alarms_of_known_follows():
    prob, lead, row = follows()
    thresholds = np.array([0.4, 0.6, 0.8])
    first, piles = first_alarms(prob[::-1], lead[::-1], row[::-1], thresholds)  # any order
    assert list(piles) == [7, 8, 9]
    assert np.degrees(first[1]) == pytest.approx([1.0, 5.0, np.nan], nan_ok=True)
    table = alarm_table(first, thresholds)
    low, mid, high = table
    assert low["hit_share"] == 1.0 and low["false_alarm_share"] == pytest.approx(2 / 3)
    assert mid["hit_share"] == pytest.approx(2 / 3) and mid["false_alarm_share"] == pytest.approx(1 / 3)
    assert mid["warning_median_deg"] == pytest.approx(3.0)
    assert high["hit_share"] == pytest.approx(1 / 3) and high["false_alarm_share"] == 0.0
    assert high["warning_median_deg"] == pytest.approx(1.0) and FALSE_ALARM_DEG == 3.0
    # the default: the most hits with at most 10 % false alarms
    assert choose_threshold(table)["threshold"] == 0.8
    assert choose_threshold(table, max_false=0.4)["threshold"] == 0.6
    assert choose_threshold(table[:2], max_false=0.1) is None


def test_a_forecasters_alarm_skill_is_checked_and_said_in_one_line():
    from sliders.analysis.forecast.integrity import IntegrityError, check_fields
    from sliders.analysis.forecast.learned import Learned
    from sliders.forecasting.alarm import alarm_skill_line

    f = Learned(inputs="angles_sizes")
    assert "holds no measure" in alarm_skill_line(f, 0.5)
    f.alarm_threshold_ = 0.35
    f.alarm_skill_ = {"hit_share": 0.8, "false_alarm_share": 0.06, "warning_median_deg": 0.42,
                      "warning_p10_deg": 0.1, "within_deg": 1.0, "piles": 200}
    alarm = {k: Learned.FIELDS[k] for k in ("alarm_threshold_", "alarm_skill_")}
    check_fields(f, "", alarm)
    line = alarm_skill_line(f, 0.35, "0.5")
    assert "≥ 0.5" in line and "default 0.35" in line and "80%" in line and "0.42°" in line
    assert "\n" not in line
    for bad in ({"alarm_threshold_": 1.2}, {"alarm_skill_": {"hit_share": 2.0}}):
        g = Learned(inputs="angles_sizes")
        g.alarm_threshold_, g.alarm_skill_ = f.alarm_threshold_, dict(f.alarm_skill_)
        for k, v in bad.items():
            if k == "alarm_skill_":
                g.alarm_skill_.update(v)
            else:
                setattr(g, k, v)
        with pytest.raises(IntegrityError):
            check_fields(g, "", alarm)
