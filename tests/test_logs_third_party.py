"""Logs as third parties write them, each case made at test time from a real log in ../shared/data.

- an ArduCopter log that begins at arming: no ARMED event, only the DISARMED one at its end;
- SERVOn_FUNCTION rewritten mid-log (ArduPilot SITL's motor-fault injection);
- a PX4 1.14+ ULog whose motors are logged only as ``actuator_motors`` (normalised 0..1);
- motor outputs logged at 10 Hz;
- a log that is not a quad X, refused by name.
"""

from __future__ import annotations

import json
from pathlib import Path

import dataflash_edit as de
import numpy as np
import pytest
import ulog_edit as ue

from monitor.errors import LogFormatError
from monitor.esc import PAPER_ESC
from monitor.logs import read_log, read_raw
from monitor.logs.ardupilot_params import lift_pwm
from monitor.logs.dataflash import EV_ARMED, EV_DISARMED
from monitor.logs.ulog import motor_pwm_range_us

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
LOG171 = DATA / "ardupilot_log171" / "log171.bin"
needs_log171 = pytest.mark.skipif(not LOG171.is_file(), reason=f"real ArduPilot log not found at {LOG171}")
# log171.bin (its README, and the reader): EV ARMED at 72.6 s, the motors idle armed at 1049 µs on the
# ground until 82.9 s, then take off; no DISARMED event (the flight ends in a flip).
ARMED_S, TAKEOFF_S = 72.6, 82.9


def _begins_at_arming(tmp_path: Path, end_s: float | None = None, disarm: str = "EV") -> Path:
    """log171 as a log written from arming on (LOG_DISARMED 0): no message before arming, no ARMED event,
    a DISARMED event at its end (``end_s``: cut there), as an EV message, or as ArduCopter 4's ARM message
    (``disarm="ARM"``, its format added to the log)."""
    msgs, fm = de.messages(LOG171)
    ev = de.by_name(fm, "EV")
    arm = de.Format(200, 3 + 5, "ARM", "IB", ("TimeMS", "ArmState"))
    out = []
    for m in msgs:
        t = de.message_time_us(m, fm)
        if t is not None and (t < ARMED_S * 1e6 or (end_s is not None and t > end_s * 1e6)):
            continue
        if m.type_id == ev.type_id and de.fields(m, fm)["Id"] == EV_ARMED:
            continue
        out.append(m)
    if disarm == "ARM":
        fmt = de.by_name(fm, "FMT")
        cols = {"Type": arm.type_id, "Length": arm.length, "Name": arm.name, "Format": arm.fmt, "Columns": "TimeMS,ArmState"}
        last_ms = max(de.message_time_us(m, fm) or 0 for m in out) // 1000
        out = [de.pack(fmt, cols), *out, de.pack(arm, {"TimeMS": last_ms, "ArmState": 0})]
    else:
        out.append(de.pack(ev, {"Id": EV_DISARMED}))
    return de.write(tmp_path / f"from_arming_{disarm}.bin", out)


@pytest.mark.realdata
@needs_log171
def test_dataflash_that_begins_at_arming_finds_its_flight(tmp_path):
    path = _begins_at_arming(tmp_path)
    raw = read_raw(path)
    assert raw.armed.values[0] == 1.0 and raw.armed.values[-1] == 0.0  # armed before its only event, the DISARMED
    table = read_log(path, esc=PAPER_ESC)
    seg = table.airborne_segments()
    assert seg, table.warnings
    start_s = table.timestamp_us[seg[0][0]] / 1e6
    assert TAKEOFF_S - 0.1 < start_s < TAKEOFF_S + 3.0  # not during the ten seconds idling armed on the ground
    assert sum(e - s for s, e in seg) / table.rate_hz > 130.0
    # Armed and idling on the ground only (the same log cut before take-off): never airborne.
    idle = read_log(_begins_at_arming(tmp_path, end_s=TAKEOFF_S - 0.2), esc=PAPER_ESC)
    assert len(idle) > 150 and not idle.airborne.any()
    # ArduCopter 4 logs the disarming as an ARM message (ArmState 0) too: the same reading.
    arm = read_log(_begins_at_arming(tmp_path, disarm="ARM"), esc=PAPER_ESC)
    assert arm.airborne_segments() == seg


def test_lift_level_from_the_logs_motor_parameters():
    # ArduCopter >= 3.5: the in-flight minimum on the output range; a higher armed idle raises it.
    assert lift_pwm({"MOT_PWM_MIN": 1100.0, "MOT_PWM_MAX": 1900.0, "MOT_SPIN_MIN": 0.15}) == pytest.approx(1220.0)
    assert lift_pwm({"RC3_MIN": 1000.0, "RC3_MAX": 2000.0, "MOT_PWM_MIN": 0.0, "MOT_SPIN_MIN": 0.1, "MOT_SPIN_ARM": 0.2}) == (
        pytest.approx(1200.0)
    )
    assert lift_pwm({"MOT_SPIN_ARMED": 50.0, "RC3_MIN": 1000.0}) is None  # Copter 3.3: the reader's default level


def _servo_fault(tmp_path: Path, change_s: float) -> Path:
    """log171 with motor 1 on output 2 and motor 2 on output 1 (SERVOn_FUNCTION after the parameter dump), and
    SERVO2_FUNCTION set to 0 at ``change_s``, as SITL's motor-fault injection does to a motor in flight."""
    msgs, fm = de.messages(LOG171)
    parm = de.by_name(fm, "PARM")
    last_parm = max(i for i, m in enumerate(msgs) if m.type_id == parm.type_id)
    mapping = [de.pack(parm, {"Name": f"SERVO{n}_FUNCTION", "Value": float(f)}) for n, f in ((1, 34), (2, 33), (3, 35), (4, 36))]
    at = next(i for i, m in enumerate(msgs) if (de.message_time_us(m, fm) or 0) >= change_s * 1e6)
    fault = de.pack(parm, {"Name": "SERVO2_FUNCTION", "Value": 0.0})
    out = msgs[: last_parm + 1] + mapping + msgs[last_parm + 1 : at] + [fault] + msgs[at:]
    return de.write(tmp_path / "servo_fault.bin", out)


@pytest.mark.realdata
@needs_log171
def test_servo_function_changed_mid_log_reads_with_the_mapping_at_take_off(tmp_path):
    change_s = 150.0
    raw = read_raw(_servo_fault(tmp_path, change_s))
    plain = read_raw(LOG171)
    # The mapping at take-off, through the whole log: motor 1 on output 2, motor 2 on output 1.
    np.testing.assert_array_equal(raw.motor_cmd.values[:, [1, 0, 2, 3]], plain.motor_cmd.values)
    (said,) = [w for w in raw.warnings if "SERVO2_FUNCTION" in w]
    assert "from 33 (Motor1) to 0" in said and "mapping at take-off" in said
    after_s = float(said.split(" s after take-off")[0].rsplit(" ", 1)[-1])
    assert after_s == pytest.approx(change_s - TAKEOFF_S, abs=0.3)
    table = read_log(tmp_path / "servo_fault.bin", esc=PAPER_ESC)
    assert table.airborne.any() and any("SERVO2_FUNCTION" in w for w in table.warnings)


@pytest.mark.realdata
@needs_log171
def test_servo_function_change_before_a_complete_mapping_is_still_refused(tmp_path):
    # A log whose mapping never assigns all four motors while they lift is refused, naming the parameter.
    msgs, fm = de.messages(LOG171)
    parm = de.by_name(fm, "PARM")
    last_parm = max(i for i, m in enumerate(msgs) if m.type_id == parm.type_id)
    half = [de.pack(parm, {"Name": "SERVO1_FUNCTION", "Value": 33.0})]
    de.write(tmp_path / "half.bin", msgs[: last_parm + 1] + half + msgs[last_parm + 1 :])
    with pytest.raises(LogFormatError, match="does not assign all of Motor1..Motor4"):
        read_raw(tmp_path / "half.bin")


ULOGS = DATA / "px4_ulog"
EVENTS = ULOGS / "sample_px4_events.ulg"
needs_ulogs = pytest.mark.skipif(not EVENTS.is_file(), reason=f"real PX4 ULogs not found at {ULOGS}")


@pytest.mark.realdata
@needs_ulogs
def test_ulog_with_only_actuator_motors_is_read_in_its_own_unit(tmp_path, capsys):
    # sample_px4_events.ulg (PX4 SITL, 1.14-era topics) logs actuator_motors and actuator_outputs at 10 Hz.
    path = ue.drop_topics(EVENTS, tmp_path / "motors_only.ulg", {"actuator_outputs"})
    raw = read_raw(path)
    assert raw.cmd_unit == "norm" and np.nanmax(raw.motor_cmd.values) <= 1.0  # not PWM µs
    assert raw.norm_range_us == ((1000.0, 2000.0),) * 4  # SITL's pwm_out_sim range
    both = read_raw(EVENTS)
    assert both.cmd_unit == "us"  # actuator_outputs, where logged, as before
    armed = both.motor_cmd.values[:, 0] > 900.0  # 900 µs: disarmed
    # the range the reader assumes for SITL is the one the log's own PWM outputs show
    np.testing.assert_allclose(1000.0 + 1000.0 * raw.motor_cmd.values[armed], both.motor_cmd.values[armed], atol=0.5)
    table, full = read_log(path, esc=PAPER_ESC), read_log(EVENTS, esc=PAPER_ESC)
    assert table.extras["motor_cmd_unit"] == "norm" and table.extras["esc_cmd_unit"] == "us"
    assert table.airborne_segments() == full.airborne_segments() != []
    air = table.airborne
    slope_rpm_per_us = 2 * PAPER_ESC.a_rpm_per_cmd2 * 1000.0 + PAPER_ESC.b_rpm_per_cmd  # steepest, at 1000 µs
    np.testing.assert_allclose(table.motor_rpm[air], full.motor_rpm[air], atol=0.5 * slope_rpm_per_us)
    assert any("actuator_motors (normalised 0..1)" in w for w in table.warnings)
    # diagnose judges it: no refusal for its command unit
    from monitor.diagnose.cli import main as diagnose

    diagnose([str(path), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert out["verdict"] is not None, out.get("reason")


def test_normalised_motor_commands_take_their_pwm_range_from_the_output_parameters():
    params = {f"PWM_MAIN_FUNC{n}": 100 + n for n in range(1, 5)}
    params |= {f"PWM_MAIN_MIN{n}": 1100.0 for n in range(1, 5)} | {f"PWM_MAIN_MAX{n}": 1900.0 for n in range(1, 5)}
    assert motor_pwm_range_us(params, "PX4_FMU_V5")[0] == ((1100.0, 1900.0),) * 4
    # motors on DShot: no PWM µs, the ESC curve in µs cannot apply
    dshot = {f"DSHOT_FUNC{n}": 100 + n for n in range(1, 5)}
    rng, why = motor_pwm_range_us(dshot, "PX4_FMU_V5")
    assert rng is None and "no PWM" in why


@pytest.mark.realdata
@needs_ulogs
def test_vtol_and_non_quad_x_allocations_are_refused_by_name(tmp_path, capsys):
    from monitor.diagnose.cli import main as diagnose

    assert diagnose([str(ULOGS / "sample_log_small.ulg"), "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["reason"].startswith("not a quad-X")
    assert "standard VTOL (VT_TYPE 2)" in out["reason"] and "SYS_AUTOSTART 13014" in out["reason"]
    hexa = ue.rewrite(EVENTS, tmp_path / "hexa.ulg", lambda _n, _k: True, params={"CA_ROTOR_COUNT": 6})
    with pytest.raises(LogFormatError, match="not a quad-X: the log says CA_ROTOR_COUNT 6"):
        read_raw(hexa)
    plus = ue.rewrite(EVENTS, tmp_path / "plus.ulg", lambda _n, _k: True, params={"CA_ROTOR0_PY": 0.0})
    with pytest.raises(LogFormatError, match="not a quad-X: the log's rotor 1 is at CA_ROTOR0 PX 0.1515, PY 0"):
        read_raw(plus)


@pytest.mark.realdata
@needs_log171
def test_motor_outputs_at_10_hz_give_a_table(tmp_path):
    # log171's RCOU (49 Hz) kept one in five: ~10 Hz, as slow DataFlash and ULog profiles log motor outputs.
    msgs, fm = de.messages(LOG171)
    rcou = de.by_name(fm, "RCOU").type_id
    k = np.cumsum([m.type_id == rcou for m in msgs])  # RCOU messages so far
    kept = [m for m, n in zip(msgs, k, strict=True) if m.type_id != rcou or n % 5 == 0]
    slow = read_log(de.write(tmp_path / "rcou_10hz.bin", kept), esc=PAPER_ESC)
    full = read_log(LOG171, esc=PAPER_ESC)
    assert 9.0 < slow.extras["stream_rates_hz"]["motor_cmd"] < 11.0 and slow.rate_hz == full.rate_hz
    assert any(w.startswith("motor_cmd logged at") and "held between samples" in w for w in slow.warnings)
    _, i, j = np.intersect1d(slow.timestamp_us, full.timestamp_us, return_indices=True)  # the same grid instants
    assert len(i) > 0.99 * len(full)
    assert np.mean(slow.airborne[i] != full.airborne[j]) < 0.01
    air = slow.airborne[i] & full.airborne[j]
    assert np.isfinite(slow.motor_rpm[i][air]).all()
    assert abs(np.mean(slow.motor_rpm[i][air]) - np.mean(full.motor_rpm[j][air])) < 50.0
    # and a 10 Hz actuator_motors ULog (sample_px4_events, natively 10 Hz): see the actuator_motors test


@pytest.mark.realdata
@needs_ulogs
def test_motors_moved_off_the_first_outputs_are_read_from_actuator_motors(tmp_path):
    # PX4 >= 1.14 with motor 1 on output 2 and motor 2 on output 1: actuator_outputs[0..3] are not motors 1..4.
    path = ue.rewrite(
        EVENTS, tmp_path / "swapped.ulg", lambda _n, _k: True, params={"PWM_MAIN_FUNC1": 102, "PWM_MAIN_FUNC2": 101}
    )
    raw, motors = read_raw(path), read_raw(ue.drop_topics(EVENTS, tmp_path / "motors_only.ulg", {"actuator_outputs"}))
    assert raw.cmd_unit == "norm"
    np.testing.assert_array_equal(raw.motor_cmd.values, motors.motor_cmd.values)
    assert any("PWM_MAIN_FUNC1 102, PWM_MAIN_FUNC2 101" in w for w in raw.warnings)
