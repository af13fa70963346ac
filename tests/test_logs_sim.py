"""The tlog reader against the simulator's own truth (its PX4-like tlog writer):
what the reader puts on the grid is what the simulator flew, to the precision of the wire."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

sim = pytest.importorskip("offline.sim.simulator", reason="the simulator (offline extra) is not installed")

from monitor.esc import PAPER_ESC  # noqa: E402
from monitor.logs import read_log  # noqa: E402
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle  # noqa: E402


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    from offline.sim.io_tlog import write_tlog
    from offline.sim.mission import random_waypoints
    from offline.simulate import TLOG_RATE_HZ, build_propellers

    vehicle = load_vehicle(DEFAULT_VEHICLE)
    cfg = dataclasses.replace(sim.SimConfig(), duration_s=12.0, log_rate_hz=TLOG_RATE_HZ)
    conditions = np.zeros((1, 4), dtype=np.int64)
    log = sim.simulate(
        vehicle, random_waypoints(1, 5, seed=4), build_propellers(vehicle, conditions, "quadratic", 4), cfg, seed=4
    )
    path = write_tlog(tmp_path_factory.mktemp("sim") / "f.tlog", log, 0)
    return log, path


def test_reader_recovers_the_simulated_flight(flown):
    log, path = flown
    table = read_log(path, esc=PAPER_ESC)
    t = log.timestamp_us.astype(np.int64)
    idx = np.searchsorted(t, table.timestamp_us, side="right") - 1
    ok = idx >= 0
    i = idx[ok]
    np.testing.assert_array_equal(table.motor_cmd[ok], np.rint(log.pwm_us[0][i]))  # whole µs on the wire
    np.testing.assert_allclose(table.roll_rad[ok], log.roll_rad[0][i], atol=1e-6)  # float32 on the wire
    np.testing.assert_allclose(table.yaw_rad[ok], log.yaw_rad[0][i], atol=1e-6)
    np.testing.assert_allclose(table.pitch_rate_rad_s[ok], log.rates_frd_rad_s[0][i, 1], atol=1e-6)
    # The accelerometer is each step's mean of the samples in its own period (g - 50 ms, g], as the daemon's; a
    # period with none holds the last one.
    acc = log.accel_frd_m_s2[0]
    want = np.array(
        [acc[(t > g - 50_000) & (t <= g)].mean(axis=0) if ((t > g - 50_000) & (t <= g)).any() else acc[k]
         for g, k in zip(table.timestamp_us[ok], i)]
    )  # fmt: skip
    np.testing.assert_allclose(table.accel_frd_m_s2[ok], want, atol=1e-4)
    np.testing.assert_allclose(table.vel_ned_m_s[ok], log.vel_ned_m_s[0][i], atol=1e-5)
    np.testing.assert_allclose(table.extras["esc_rpm"][ok], np.rint(log.motor_omega_rad_s[0][i] * 60 / (2 * np.pi)))
    # Battery comes at 2 Hz (SYS_STATUS, whole mV) and is held: it is the pack voltage of a recent sample.
    for g, v in zip(table.timestamp_us[ok], table.battery_v[ok]):
        recent = log.battery_v[0][(t <= g) & (t > g - 600_000)]
        assert np.abs(recent - v).min() < 0.001
    # The simulated flight is airborne throughout once the first HEARTBEAT has set the armed state.
    assert table.airborne[ok].mean() > 0.85 and table.warnings == ()
