"""Writers round-trip: npz, the PX4-like .tlog through pymavlink, the sidecar, and the CLI."""

from __future__ import annotations

import dataclasses
import json
from collections import defaultdict

import numpy as np
import pytest
from pymavlink import mavutil

from monitor.errors import LogFormatError
from monitor.esc import RPM_PER_RAD_S
from monitor.mavlink import esc as mavlink_esc
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.sim.io_npz import read_npz, write_npz
from offline.sim.io_tlog import DEFAULT_WALL_BOOT_US, write_tlog
from offline.sim.mission import random_waypoints
from offline.sim.propeller import QuadraticPropeller
from offline.sim.simulator import SimConfig, simulate
from offline.simulate import main as simulate_main


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle(DEFAULT_VEHICLE)


@pytest.fixture(scope="module")
def log50(vehicle):
    sim = dataclasses.replace(SimConfig(), duration_s=6.0, log_rate_hz=50)
    return simulate(vehicle, random_waypoints(2, 5, seed=9), QuadraticPropeller.for_vehicle(vehicle), sim, seed=1)


def test_npz_round_trip(tmp_path, log50):
    path = write_npz(tmp_path / "f.npz", log50, {"label": 3, "waypoints": np.zeros((1, 2))})
    back, sidecar = read_npz(path)
    assert sidecar == {"label": 3, "waypoints": [[0.0, 0.0]]}
    assert back.log_rate_hz == 50.0
    for name in log50.array_fields():
        np.testing.assert_array_equal(getattr(back, name), getattr(log50, name), err_msg=name)
    assert not list(tmp_path.glob("*.tmp"))


def test_npz_rejects_other_files(tmp_path):
    np.savez(tmp_path / "x.npz", a=np.zeros(3))
    with pytest.raises(LogFormatError, match="x.npz"):
        read_npz(tmp_path / "x.npz")


def read_tlog(path):
    mavlink_esc.register()
    conn = mavutil.mavlink_connection(str(path), dialect="common")
    msgs = defaultdict(list)
    while (m := conn.recv_match()) is not None:
        msgs[m.get_type()].append(m)
    return msgs


def test_tlog_round_trips_through_pymavlink(tmp_path, log50):
    i = 1
    msgs = read_tlog(write_tlog(tmp_path / "f.tlog", log50, i))
    n = log50.n_samples
    for kind in ("ATTITUDE", "SERVO_OUTPUT_RAW", "ESC_STATUS", "HIGHRES_IMU", "LOCAL_POSITION_NED"):
        assert len(msgs[kind]) == n, kind
    assert "BAD_DATA" not in msgs
    # HEARTBEAT at 1 Hz from a PX4 quadrotor, armed, in flight.
    hb = msgs["HEARTBEAT"]
    assert len(hb) == len(np.unique(log50.timestamp_us // 1_000_000))  # one per second of boot time
    assert all(h.type == mavutil.mavlink.MAV_TYPE_QUADROTOR and h.autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4 for h in hb)
    assert all(h.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED for h in hb)
    assert all(e.landed_state == mavutil.mavlink.MAV_LANDED_STATE_IN_AIR for e in msgs["EXTENDED_SYS_STATE"])
    assert np.allclose(np.diff([h._timestamp for h in hb])[1:], 1.0)
    assert msgs["BATTERY_STATUS"] and msgs["SYS_STATUS"]

    # Boot-clock fields and the .tlog wall-clock prefix agree with the log.
    att = msgs["ATTITUDE"]
    np.testing.assert_array_equal([a.time_boot_ms for a in att], log50.timestamp_us // 1000)
    np.testing.assert_array_equal([m.time_usec for m in msgs["HIGHRES_IMU"]], log50.timestamp_us)
    np.testing.assert_array_equal([m.time_usec for m in msgs["ESC_STATUS"]], log50.timestamp_us)
    wall = np.array([a._timestamp for a in att])
    np.testing.assert_allclose(wall, (DEFAULT_WALL_BOOT_US + log50.timestamp_us) / 1e6, atol=1e-5)
    assert np.diff(wall).mean() == pytest.approx(1 / 50)

    # Values (float32 on the wire, PWM and RPM as integers).
    np.testing.assert_allclose([a.roll for a in att], log50.roll_rad[i], atol=1e-6)
    np.testing.assert_allclose([a.yawspeed for a in att], log50.rates_frd_rad_s[i, :, 2], atol=1e-6)
    servo = np.array([[m.servo1_raw, m.servo2_raw, m.servo3_raw, m.servo4_raw] for m in msgs["SERVO_OUTPUT_RAW"]])
    np.testing.assert_array_equal(servo, np.rint(log50.pwm_us[i]))
    esc = np.array([m.rpm for m in msgs["ESC_STATUS"]])
    np.testing.assert_allclose(esc, log50.motor_omega_rad_s[i] * RPM_PER_RAD_S, atol=0.5)
    lp = msgs["LOCAL_POSITION_NED"]
    np.testing.assert_allclose([[m.x, m.y, m.z] for m in lp], log50.pos_ned_m[i], atol=1e-5)
    imu = msgs["HIGHRES_IMU"]
    np.testing.assert_allclose([[m.xacc, m.yacc, m.zacc] for m in imu], log50.accel_frd_m_s2[i], atol=1e-5)
    assert msgs["SYS_STATUS"][0].voltage_battery == round(log50.battery_v[i, 0] * 1000)


def test_cli_writes_flights_and_ground_truth(tmp_path):
    out = tmp_path / "run"
    rc = simulate_main(
        [
            "--out",
            str(out),
            "--flights",
            "2",
            "--label",
            "7",
            "--fault",
            "cracked",
            "--payload-kg",
            "0.45",
            "--duration-s",
            "3",
            "--propellers",
            "quadratic",
            "--seed",
            "4",
            "--waypoints-seed",
            "8",
            "--format",
            "npz",
        ]
    )
    assert rc == 0
    log, embedded = read_npz(out / "flights.npz")
    sidecar = json.loads((out / "sidecar.json").read_text())
    assert embedded["flights"] == sidecar["flights"]
    assert len(log) == 2 and log.n_samples == 60
    f0 = sidecar["flights"][0]
    assert f0["label"] == 7 and f0["faulty_propellers"] == [1, 3]
    assert f0["propeller_conditions"] == ["cracked", "normal", "cracked", "normal"]
    assert f0["payload_kg"] == 0.45
    np.testing.assert_allclose(f0["waypoints_ned_m"], random_waypoints(2, 5, seed=8)[0])
    assert sidecar["seed"] == 4 and sidecar["git_revision"]
    assert sidecar["config"]["vehicle"]["kf_n_per_rad_s2"] == 1.076e-5
    assert sidecar["config"]["sim"]["physics_rate_hz"] == SimConfig().physics_rate_hz
    assert "kf_n_per_rad_s2" in sidecar["config"]["vehicle_sources"]


def test_cli_tlog_format(tmp_path):
    out = tmp_path / "t"
    assert simulate_main(["--out", str(out), "--duration-s", "2", "--format", "tlog", "--propellers", "quadratic"]) == 0
    msgs = read_tlog(out / "flight_000.tlog")
    # 2 s of flight at 50 Hz, then the landing tail (offline.sim.io_tlog.landing_tail: 1 s landed, 2 s disarmed)
    assert len(msgs["ATTITUDE"]) == 100 + 150
    assert json.loads((out / "sidecar.json").read_text())["flights"][0]["label"] == 1


def test_cli_rejects_bad_arguments(tmp_path, capsys):
    from monitor.cli import main as propwatch

    assert propwatch(["simulate", "--out", str(tmp_path / "x"), "--label", "17"]) == 2
    assert "--label" in capsys.readouterr().err
    assert propwatch(["simulate", "--out", str(tmp_path / "y"), "--duration-s", "0.01", "--propellers", "quadratic"]) == 2
    assert "duration_s" in capsys.readouterr().err
    assert not (tmp_path / "y" / "sidecar.json").exists()


def test_select_and_concatenate_are_inverse(log50):
    from offline.sim.log import FlightLog

    parts = [log50.select(1), log50.select([0])]
    joined = FlightLog.concatenate(parts)
    assert len(joined) == 2 and joined.log_rate_hz == log50.log_rate_hz
    for name in log50.array_fields():
        a = getattr(log50, name)
        b = getattr(joined, name)
        if name in ("time_s", "timestamp_us"):
            np.testing.assert_array_equal(a, b)
        else:
            np.testing.assert_array_equal(b, a[[1, 0]], err_msg=name)
    with pytest.raises(ValueError, match="length or rate"):
        FlightLog.concatenate([log50, dataclasses.replace(log50, log_rate_hz=20.0)])
