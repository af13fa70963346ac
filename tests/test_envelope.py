"""monitor.decision.envelope: the context streams' envelope, judged on a whole log as the daemon judges sample by sample."""

from __future__ import annotations

import math

import numpy as np
import pytest

from monitor.daemon.config import PlausibleConfig
from monitor.daemon.plausible import Plausibility
from monitor.decision.envelope import implausible_context
from monitor.esc import PAPER_ESC


@pytest.mark.parametrize("kind", ["velocity", "imu"])
def test_the_log_check_drops_exactly_the_samples_the_daemon_drops(kind):
    rng = np.random.default_rng(2)
    t = np.cumsum(rng.integers(15_000, 40_000, 600))  # 25-65 Hz with jitter
    v = rng.normal(0.0, 1.0, (600, 3))
    v[50:60] = np.nan  # not finite
    v[100:140, 0] = 200.0 + np.arange(40)  # beyond either envelope
    v[200:300] = v[200]  # stuck: frozen once 1 s old
    v[310:330] = 0.0  # a vehicle at rest: zeros may stand still (velocity), frozen for the IMU after 1 s
    v[400:420] = v[399]  # stuck for under a second: not frozen
    v[405] = np.nan  # a dropped sample inside a run does not break it (the daemon never compares it)
    p = Plausibility(PlausibleConfig(), PAPER_ESC, "servo")
    check = p.velocity if kind == "velocity" else p.imu
    live = np.array([check(int(ti), tuple(float(x) for x in vi)) is not None for ti, vi in zip(t, v)])
    bad, why = implausible_context(t, v, kind)
    np.testing.assert_array_equal(bad, live)
    assert why["not finite"] == 11 and why["frozen"] > 0
    assert sum(why.values()) == int(bad.sum())
    assert not bad[400:420][~np.isnan(v[400:420, 0])].any()


def test_an_unknown_kind_is_named():
    with pytest.raises(ValueError, match="'velocity' or 'imu'"):
        implausible_context(np.arange(3), np.zeros((3, 3)), "attitude")
    assert math.isfinite(implausible_context(np.arange(0), np.zeros((0, 3)), "imu")[0].sum())
