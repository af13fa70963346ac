"""A flight judged through time against its vehicle's normal (monitor.memory.through_time): the marks, the ends of
the flight they start, and a change in the air that the whole flight's mean dilutes."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.memory import thresholds as th
from monitor.memory.judge import judge
from monitor.memory.normal import normal_of
from monitor.memory.summary import BLOCK_S, SETTLE_S, ShareAccumulator
from monitor.memory.through_time import MIN_SUFFIX_S, judge_through_time, marks_from_json, marks_to_json, thin

RATE_HZ = 20.0


def omega2(shares_before, shares_after, change_s: float, seconds: float, rng) -> np.ndarray:
    """(n, 4) omega^2 of a level flight: ``shares_before`` until ``change_s``, then ``shares_after``; 1 % noise."""
    n = int(seconds * RATE_HZ)
    t = np.arange(n) / RATE_HZ
    shares = np.where((t < change_s)[:, None], np.asarray(shares_before), np.asarray(shares_after))
    return 40.0 * shares * (1.0 + 0.01 * rng.standard_normal((n, 4)))


def fed(x: np.ndarray, step_by_step: bool = False) -> ShareAccumulator:
    n = len(x)
    acc = ShareAccumulator("omega2", RATE_HZ)
    if step_by_step:
        for row in x:
            acc.step(row, 0.0, 0.0, True)
    else:
        acc.table(x, np.zeros(n), np.zeros(n), np.ones(n, dtype=bool))
    return acc


def test_marks_are_the_same_step_by_step_and_whole_and_an_end_is_the_steps_after_its_mark():
    x = omega2(np.ones(4), [0.9, 1.3, 0.9, 0.9], 50.0, 80.0, np.random.default_rng(1))
    a, b = fed(x), fed(x, step_by_step=True)
    assert [m.row for m in a.marks] == [m.row for m in b.marks]
    assert all(np.allclose(m.summary.sum_share, k.summary.sum_share) for m, k in zip(a.marks, b.marks, strict=True))
    settle, block = int(SETTLE_S * RATE_HZ), int(BLOCK_S * RATE_HZ)
    assert a.marks[0].row == settle + block and a.marks[1].row - a.marks[0].row == block
    # the end from the mark at row 1000 (50 s): exactly rows 1000.. of the flight
    m = next(m for m in a.marks if m.row == 1000)
    end = a.summary.minus(m.summary)
    assert end.n == len(x) - 1000
    s = x[1000:] / x[1000:].mean(axis=1, keepdims=True)
    assert end.mean_share() == pytest.approx(s.mean(axis=0), abs=1e-12)
    assert end.n_blocks == a.summary.n_blocks - (1000 - settle) // block
    # every look leaves at least MIN_SUFFIX_S to the end
    assert all(a.summary.n - k.summary.n >= MIN_SUFFIX_S * RATE_HZ for k in thin(a.marks, a.summary))


@pytest.fixture()
def normal():
    rng = np.random.default_rng(3)
    return normal_of([fed(omega2(np.ones(4), np.ones(4), 0.0, 80.0, rng)).summary for _ in range(3)])


def test_damage_in_the_last_fifth_of_a_flight_is_named_where_the_flight_mean_is_not(normal):
    # rotor 3 works 5 % harder from 64 s of 80 s (a damaged propeller 3, its torque unchanged: the yaw move with it)
    after = np.array([0.985, 0.985, 1.045, 0.985])
    acc = fed(omega2(np.ones(4), after / after.mean(), 64.0, 80.0, np.random.default_rng(4)))
    whole = judge(normal, acc.summary)
    assert whole["fault_statistic"] < th.FAULT_STATISTIC  # diluted by the 62 healthy seconds before
    v = judge_through_time(normal, acc.summary, acc.marks, lambda row: 5.0 + row / RATE_HZ)
    assert v["through_time"]["overrules"] and v["faulty_propellers"] == [3]
    assert v["through_time"]["statistic"] >= th.SCAN_FAULT_STATISTIC
    # the end that deviates most lies inside the change (any end inside it deviates alike: the longest is not
    # preferred, the flight-to-flight spread dominating the wander of a mean of 10 s or more)
    assert 62.0 <= v["through_time"]["from_boot_s"] - 5.0 <= 70.0
    assert v["through_time"]["whole_flight"]["fault_statistic"] == pytest.approx(whole["fault_statistic"])


def test_a_healthy_flight_is_not_overruled_and_stays_confident(normal):
    for seed in range(5, 10):
        acc = fed(omega2(np.ones(4), np.ones(4), 0.0, 80.0, np.random.default_rng(seed)))
        v = judge_through_time(normal, acc.summary, acc.marks)
        assert v["faulty_propellers"] == [] and not v["through_time"]["overrules"]
        assert v["through_time"]["statistic"] < th.SCAN_SUSPECT_STATISTIC and v["confidence"] == "confident"


def test_marks_round_trip_as_the_fleet_keeps_them_and_an_impossible_one_is_refused(normal):
    from monitor.errors import ConfigError

    acc = fed(omega2(np.ones(4), np.ones(4), 0.0, 80.0, np.random.default_rng(11)))
    items = marks_to_json(acc.marks, acc.summary, lambda row: row / RATE_HZ)
    marks, boot = marks_from_json(items, "row x")
    assert [m.row for m in marks] == [m.row for m in thin(acc.marks, acc.summary)]
    assert judge_through_time(normal, acc.summary, marks, boot.get)["through_time"]["statistic"] == pytest.approx(
        judge_through_time(normal, acc.summary, acc.marks)["through_time"]["statistic"]
    )
    items[2]["summary"]["sum_share"] = [1e300, 0, 0, 0]
    with pytest.raises(ConfigError, match="row x: mark 2"):
        marks_from_json(items, "row x")
