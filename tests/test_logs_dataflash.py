"""The DataFlash reader on the real ArduCopter log171.bin (facts from its README)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from monitor.errors import LogFormatError
from monitor.esc import PAPER_ESC
from monitor.logs import detect_format, read_log, read_raw, to_flight_table

LOG171 = Path(__file__).resolve().parents[2] / "shared" / "data" / "ardupilot_log171" / "log171.bin"
needs_log171 = pytest.mark.skipif(not LOG171.is_file(), reason=f"real ArduPilot log not found at {LOG171}")


@pytest.fixture(scope="module")
def raw():
    return read_raw(LOG171)


@pytest.mark.realdata
@needs_log171
def test_streams_units_and_rates(raw):
    assert detect_format(LOG171) == "dataflash"
    assert 48 < raw.motor_cmd.rate_hz() < 52  # RCOU ~49 Hz
    assert 9 < raw.attitude_rad.rate_hz() < 11  # ATT/RATE 10 Hz
    cmd = raw.motor_cmd.values
    assert cmd.min() == 1000 and 1790 < cmd.max() < 1860  # README: 1000 disarmed, up to 1792-1853
    yaw = raw.attitude_rad.values[:, 2]
    assert yaw.min() >= -np.pi and yaw.max() < np.pi  # 0..360 deg wrapped
    # README: |roll| > 60 deg from t ~ 239 s (the flip); degrees were converted once.
    roll = raw.attitude_rad.values[:, 0]
    first = raw.attitude_rad.t_us[np.flatnonzero(np.abs(roll) > np.deg2rad(60))[0]] / 1e6
    assert 238 < first < 240
    assert np.abs(roll[raw.attitude_rad.t_us < 230e6]).max() < np.deg2rad(60)
    assert 14.0 < raw.battery_v.values[0] < 17.0  # 4S pack; CURR.Volt was centivolts
    assert np.abs(np.median(raw.accel_frd_m_s2.values[:, 2]) + 9.8) < 0.5  # FRD specific force at rest


@pytest.mark.realdata
@needs_log171
def test_rate_units_agree_with_the_imu_gyro(raw):
    # Copter 3.3 logs RATE in centi-degrees/s (the README's "deg/s" is off by 100): the reader finds out.
    assert any("centi-degrees/s" in w for w in raw.warnings)
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(LOG171))
    gyro = []
    while (m := conn.recv_match(type="IMU")) is not None:
        gyro.append((m.TimeMS * 1000, m.GyrX, m.GyrY, m.GyrZ))
    conn.close()
    gyro = np.array(gyro)
    t = raw.rates_rad_s.t_us
    flight = (t > 90e6) & (t < 230e6)
    for k in range(3):
        g = np.interp(t[flight], gyro[:, 0], gyro[:, k + 1])
        slope = np.polyfit(g, raw.rates_rad_s.values[flight, k], 1)[0]
        assert 0.7 < slope < 1.1, (k, slope)  # RATE is the filtered gyro, 10 Hz: close to 1, not 57 or 0.01


@pytest.mark.realdata
@needs_log171
def test_airborne_matches_the_armed_flight(raw):
    table = to_flight_table(raw, esc=PAPER_ESC)
    seg = table.airborne_segments()
    start_s = table.timestamp_us[seg[0][0]] / 1e6
    assert 82 < start_s < 85  # README: armed flight from t = 83 s
    assert table.timestamp_us[seg[-1][1] - 1] / 1e6 < 254.1
    assert any("below the model's 20 Hz" in w for w in table.warnings)  # ATT at 10 Hz


@pytest.mark.realdata
@needs_log171
def test_truncated_dataflash_reads_up_to_the_cut(tmp_path):
    data = LOG171.read_bytes()
    cut = tmp_path / "cut.bin"
    cut.write_bytes(data[: len(data) // 2 + 5])
    raw = read_raw(cut)
    assert any("truncated" in w for w in raw.warnings)
    assert 100 < raw.motor_cmd.t_us[-1] / 1e6 < 200


@pytest.mark.realdata
@needs_log171
def test_dataflash_without_motor_outputs_is_an_error(tmp_path):
    data = LOG171.read_bytes()
    cut = tmp_path / "head.bin"
    cut.write_bytes(data[:3000])  # formats and parameters only
    with pytest.raises(LogFormatError, match="RCOU"):
        read_log(cut, esc=PAPER_ESC)


def test_motor_outputs_follow_servo_functions_and_frame_checks():
    from monitor.logs.ardupilot_params import motor_outputs

    p = Path("x.bin")
    assert motor_outputs({"FRAME": 1.0}, p) == (1, 2, 3, 4)  # Copter 3.3 quad X: motor k on output k
    params = {
        "FRAME_CLASS": 1.0,
        "FRAME_TYPE": 1.0,
        "SERVO1_FUNCTION": 34.0,
        "SERVO2_FUNCTION": 33.0,
        "SERVO5_FUNCTION": 35.0,
        "SERVO6_FUNCTION": 36.0,
        "SERVO3_FUNCTION": 0.0,
    }
    assert motor_outputs(params, p) == (2, 1, 5, 6)
    for bad, msg in (
        ({"FRAME": 0.0}, r"not a quad-X: the log says FRAME 0 \(Plus\)"),
        ({"FRAME_CLASS": 2.0}, r"not a quad-X: the log says FRAME_CLASS 2 \(Hexa\)"),
        ({"FRAME_CLASS": 1.0, "FRAME_TYPE": 3.0}, r"FRAME_TYPE 3 \(H\)"),
        ({"FRAME_CLASS": 1.0, "FRAME_TYPE": 12.0}, r"FRAME_TYPE 12 \(BetaFlightX\): a quad X whose motors"),
        ({"SERVO1_FUNCTION": 33.0}, "Motor1..Motor4"),
    ):
        with pytest.raises(LogFormatError, match=msg):
            motor_outputs(bad, p)
