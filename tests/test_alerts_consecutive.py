"""The consecutive-window rule, the offline comparison beside the daemon's sequential rule (offline.classifier.consecutive)."""

from __future__ import annotations

import numpy as np
import pytest

from offline.classifier.consecutive import ConsecutiveConfig, ConsecutiveRule, replay_consecutive


def test_a_streak_of_consecutive_windows_alerts_then_the_propeller_is_quiet_for_the_refractory_time():
    rule = ConsecutiveRule(ConsecutiveConfig(threshold=0.8, consecutive=3, refractory_s=10.0))
    hot = [0.1, 0.2, 0.97, 0.1]
    assert rule.update(0.05, hot) == () and rule.update(0.10, hot) == ()
    assert rule.update(0.15, [0.1, 0.2, 0.5, 0.1]) == ()  # breaks the streak
    assert rule.update(0.20, hot) == () and rule.update(0.25, hot) == ()
    assert rule.update(0.30, hot) == (3,)
    assert all(rule.update(0.35 + 0.05 * i, hot) == () for i in range(5))  # refractory
    assert rule.update(10.25, hot) == ()  # 9.95 s after its alert: still quiet
    both = [0.9, 0.2, 0.97, 0.1]
    assert rule.update(10.30, both) == (3,)  # 10 s on: propeller 3 again; propeller 1 has a streak of 1 only
    assert rule.update(10.35, both) == ()
    assert rule.update(10.40, both) == (1,)


def test_several_propellers_at_once_nan_is_no_evidence_and_reset_breaks_streaks():
    rule = ConsecutiveRule(ConsecutiveConfig(consecutive=1))
    assert rule.update(0.0, [0.999] * 4) == (1, 2, 3, 4)
    nan = ConsecutiveRule(ConsecutiveConfig(consecutive=2))
    assert nan.update(0.0, [np.nan] * 4) == () and nan.update(0.05, [np.nan] * 4) == ()
    assert nan.update(0.10, [0.95, np.nan, 0, 0]) == () and nan.update(0.15, [0.95, 0.95, 0, 0]) == (1,)
    gap = ConsecutiveRule(ConsecutiveConfig(consecutive=2))
    gap.update(0.0, [0.95, 0, 0, 0])
    gap.reset()  # classification stopped: the next window starts a new streak
    assert gap.update(5.0, [0.95, 0, 0, 0]) == () and gap.update(5.05, [0.95, 0, 0, 0]) == (1,)


def test_replayed_over_a_flight_window_k_ends_at_step_k_plus_window_minus_one():
    cfg = ConsecutiveConfig(threshold=0.8, consecutive=3, refractory_s=1.0)
    p = np.zeros((60, 4))
    p[10:12, 0] = 0.9  # two in a row: no alert
    p[20:50, 2] = 0.95  # alert at the 3rd window (22), again 1 s (20 windows) later at 42
    alerts = replay_consecutive(p, 20.0, 100, cfg)
    assert alerts == [((22 + 100) / 20, (3,)), ((42 + 100) / 20, (3,))]


@pytest.mark.parametrize(
    "kw,field", [({"threshold": 0.0}, "threshold"), ({"consecutive": 0}, "consecutive"), ({"refractory_s": -1.0}, "refractory_s")]
)
def test_settings_out_of_range_are_named(kw, field):
    with pytest.raises(ValueError, match=field):
        ConsecutiveConfig(**kw)
