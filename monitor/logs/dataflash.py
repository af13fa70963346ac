"""ArduPilot DataFlash ``.bin`` logs (pymavlink's DFReader) -> ``RawFlight``.

Messages used, old (Copter 3.3: ``TimeMS``, ``Ch1..``, CURR) and new
(``TimeUS``, ``C1..``, BAT) field names alike:
- RCOU: motor PWM µs. ArduCopter quad-X numbers its motors as PX4 does
  (1 front-right CCW, 2 rear-left CCW, 3 front-left CW, 4 rear-right CW:
  ardupilot.org/copter/docs/connect-escs-and-motors.html, quad X diagram;
  "1, 4, 2, 3 going clockwise from the top right",
  discuss.ardupilot.org/t/understanding-motor-numbering/104537). Motor k is
  on the output whose SERVOn_FUNCTION is 32 + k (ArduPilot >= 3.5), else on
  output k (Copter 3.3 has no such parameter). FRAME / FRAME_CLASS /
  FRAME_TYPE are checked: only a quad X fits the model.
- ATT: Roll, Pitch, Yaw in degrees (yaw 0..360) -> rad.
- RATE: R, P, Y in deg/s (centi-deg/s in Copter 3.3, told apart by their ratio to the
  IMU gyro) -> rad/s (IMU GyrX/Y/Z in rad/s if RATE is absent).
- BAT.Volt (V) or CURR.Volt (cV); EV 10/11 armed/disarmed and ARM.ArmState (4.x);
  CTUN.Alt height; IMU Acc (m/s², FRD) and EKF1/NKF1/XKF1 velocity/position (NED) as extras.

Logs written by third parties are read as they come:
- a log that begins at arming has no ARMED event, only the DISARMED one at its end:
  an event stream says the state before its first event too (the opposite of that
  event), and with no event at all the airborne rule stands on outputs and height;
- the motor outputs' lift level comes from the log's MOT_PWM_MIN/MAX and
  MOT_SPIN_MIN/ARM where it has them (ArduCopter >= 3.5), so a vehicle idling
  armed on the ground above the default level is not taken as flying;
- SERVOn_FUNCTION rewritten mid-log (SITL's motor-fault injection): the motors
  are read on the outputs the mapping at take-off gave them, and each change is
  a warning with its time after take-off.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np

from monitor.errors import LogFormatError
from monitor.logs.ardupilot_params import ParamHistory, lift_pwm, takeoff_mapping
from monitor.logs.guards import check_marker_gaps
from monitor.logs.raw import EVENT_MAX_AGE_US, LIFT_CMD, RawFlight, Stream
from monitor.logs.units import V_PER_CV, deg_to_rad, ms_to_us, wrap_pi

WANTED = ["RCOU", "ATT", "RATE", "IMU", "BAT", "CURR", "EV", "ARM", "CTUN", "EKF1", "NKF1", "XKF1", "PARM"]
EV_ARMED, EV_DISARMED = 10, 11  # ArduCopter LogEvent DATA_ARMED / DATA_DISARMED


def _time_us(msg, names, last_us: int) -> int:
    if "TimeUS" in names:
        return int(msg.TimeUS)
    if "TimeMS" in names:
        return int(ms_to_us(msg.TimeMS))
    return last_us  # EV has no time field in Copter 3.3: it happened at the last stamped message


def read_dataflash(path: str | Path) -> RawFlight:
    from pymavlink import mavutil

    path = Path(path)
    if not path.is_file():
        raise LogFormatError(f"{path}: no such file")
    check_marker_gaps(path, (b"\xa3\x95",), "DataFlash")
    err = io.StringIO()
    rows: dict[str, list] = {k: [] for k in ("cmd", "att", "rate", "imu", "bat", "armed", "alt", "ekf")}
    try:
        with contextlib.redirect_stderr(err):
            m = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
            if not hasattr(m, "formats"):
                raise LogFormatError(f"{path}: not an ArduPilot DataFlash log")
            last_us = 0
            param_log: list[tuple[int, str, float]] = []  # (time, name, value) in the order written
            while True:
                msg = m.recv_match(type=WANTED)
                if msg is None:
                    break
                typ = msg.get_type()
                names = msg.get_fieldnames()
                t = _time_us(msg, names, last_us)
                last_us = max(last_us, t)
                if typ == "PARM":
                    param_log.append((t, msg.Name, float(msg.Value)))
                    continue
                _collect(typ, {n: getattr(msg, n) for n in names}, t, rows)
            leftover = _cut_off_bytes(path.read_bytes(), {k: f.len for k, f in m.formats.items()})
            m.close()
    except LogFormatError:
        raise
    except Exception as exc:  # pymavlink raises bare exceptions on garbage headers
        raise LogFormatError(f"{path}: cannot read as DataFlash: {exc}") from exc

    warnings = []
    skipped = [ln for ln in err.getvalue().splitlines() if "Skipped" in ln or "Failed to parse" in ln]
    if skipped:
        warnings.append(f"{path.name}: corrupted data skipped ({len(skipped)} place(s), first: {skipped[0].strip()})")
    if leftover > 0:
        warnings.append(f"{path.name}: last message cut off {leftover} bytes short (truncated log): read up to the damage")
    if not rows["cmd"]:
        raise LogFormatError(f"{path}: no RCOU messages (motor outputs): cannot diagnose")
    history = ParamHistory(param_log)
    lift = lift_pwm(history.latest())
    takeoff_us, channels, changes = takeoff_mapping(history, rows["cmd"], lift or LIFT_CMD["us"], path)
    warnings += [c.warning(takeoff_us) for c in changes]
    for i, (t, outs) in enumerate(rows["cmd"]):
        rows["cmd"][i] = (t, [outs.get(c, np.nan) for c in channels])
    if not rows["att"]:
        raise LogFormatError(f"{path}: no ATT messages (attitude): cannot diagnose")
    rates = rows["rate"]
    if not rows["rate"] and rows["imu"]:
        warnings.append("no RATE messages: body rates taken from IMU gyro")
        rates = [(t, v[:3]) for t, v in rows["imu"]]
    if not rates:
        raise LogFormatError(f"{path}: no RATE or IMU messages (body rates): cannot diagnose")

    def stream(items, cols=None):
        if not items:
            return None
        t = np.array([i[0] for i in items], dtype=np.int64)
        v = np.array([i[1] for i in items], dtype=np.float64)
        return Stream.build(t, v if cols is None else v[:, cols])

    att = stream(rows["att"])
    att_v = att.values.copy()
    att_v[:, :2] = deg_to_rad(att_v[:, :2])
    att_v[:, 2] = wrap_pi(deg_to_rad(att_v[:, 2]))
    rate_s = stream(rates)
    rate_v = rate_s.values
    if rows["rate"]:
        per_unit, unit = rate_unit(rate_s, stream(rows["imu"], [0, 1, 2]))
        rate_v = deg_to_rad(rate_s.values) * per_unit
        if unit != "deg/s":
            warnings.append(f"RATE logged in {unit} (checked against the IMU gyro): converted")
    alt = stream(rows["alt"])
    if alt is not None:
        alt = Stream(alt.t_us, alt.values - alt.values[0])
    ekf = stream(rows["ekf"])
    return RawFlight(
        source=str(path),
        cmd_unit="us",
        motor_cmd=stream(rows["cmd"]),
        attitude_rad=Stream(att.t_us, att_v),
        rates_rad_s=Stream(rate_s.t_us, rate_v),
        battery_v=stream(rows["bat"]),
        armed=_events(stream(rows["armed"]), min(rows["cmd"][0][0], rows["att"][0][0])),
        height_m=alt,
        accel_frd_m_s2=stream(rows["imu"], [3, 4, 5]),
        vel_ned_m_s=None if ekf is None else Stream(ekf.t_us, ekf.values[:, :3]),
        pos_ned_m=None if ekf is None else Stream(ekf.t_us, ekf.values[:, 3:]),
        lift_cmd=lift,
        warnings=warnings,
    )


TAIL_BYTES = 2048


def _cut_off_bytes(data: bytes, lengths: dict[int, int]) -> int:
    """Bytes missing from a final message cut off by the end of the file (0: it ends cleanly).

    DFReader stops silently at a cut-off message. From the first header in the
    last 2 KiB that chains header to header, walk to the end of the file.
    """
    n = len(data)
    for c in range(max(0, n - TAIL_BYTES), n - 2):
        p = c
        while p + 3 <= n and data[p] == 0xA3 and data[p + 1] == 0x95 and data[p + 2] in lengths:
            p += lengths[data[p + 2]]
        if p >= n:
            return p - n
        if p > c and p + 3 > n:
            return 1  # a header fragment at the very end
    return 0


# RATE.R/P/Y are deg/s in current ArduPilot but centi-degrees/s in Copter 3.3
# (log171: RATE.R / IMU.GyrX ~ 5700 = 100 * 180/pi over the flight), and old
# logs carry no FMTU unit message. The IMU gyro (rad/s in every version) decides.
CDEG_THRESHOLD = 10.0 * 180.0 / 3.141592653589793  # between 57.3 (deg/s) and 5730 (cdeg/s)


def rate_unit(rate: Stream, gyro: Stream | None) -> tuple[float, str]:
    """(factor to degrees, unit name) of RATE's R/P/Y, from their ratio to the IMU gyro."""
    if gyro is None or len(gyro) < 10 or len(rate) < 10:
        return 1.0, "deg/s"
    g = np.column_stack([np.interp(rate.t_us, gyro.t_us, gyro.values[:, k]) for k in range(3)])
    moving = np.abs(g) > 0.2  # rad/s: well above gyro noise
    if moving.sum() < 10:
        return 1.0, "deg/s"
    ratio = float(np.median(np.abs(rate.values[moving]) / np.abs(g[moving])))
    return (0.01, "centi-degrees/s") if ratio > CDEG_THRESHOLD else (1.0, "deg/s")


def _events(s: Stream | None, start_us: int) -> Stream | None:
    """EV / ARM are logged once per change: the state holds until the next event, and before the first
    event it was the other one (a log that begins at arming holds only the DISARMED event at its end)."""
    if s is None:
        return None
    t, v = s.t_us, s.values
    if t[0] > start_us:
        t, v = np.concatenate([[start_us], t]), np.concatenate([[1.0 - v[0]], v])
    return Stream(t, v, EVENT_MAX_AGE_US)


def _collect(typ: str, d: dict, t: int, rows: dict) -> None:
    if typ == "RCOU":
        # Output number -> PWM, for the old (Ch1..) and new (C1..) field names.
        rows["cmd"].append((t, {int(k.lstrip("Ch")): v for k, v in d.items() if k.lstrip("Ch").isdigit()}))
    elif typ == "ATT":
        rows["att"].append((t, [d["Roll"], d["Pitch"], d["Yaw"]]))
    elif typ == "RATE":
        rows["rate"].append((t, [d["R"], d["P"], d["Y"]]))
    elif typ == "IMU":
        rows["imu"].append((t, [d["GyrX"], d["GyrY"], d["GyrZ"], d["AccX"], d["AccY"], d["AccZ"]]))
    elif typ == "BAT":
        rows["bat"].append((t, d["Volt"]))
    elif typ == "CURR" and "Volt" in d:
        rows["bat"].append((t, d["Volt"] * V_PER_CV))
    elif typ == "EV" and d.get("Id") in (EV_ARMED, EV_DISARMED):
        rows["armed"].append((t, 1.0 if d["Id"] == EV_ARMED else 0.0))
    elif typ == "ARM" and "ArmState" in d:
        rows["armed"].append((t, 1.0 if d["ArmState"] else 0.0))
    elif typ == "CTUN" and "Alt" in d:
        rows["alt"].append((t, d["Alt"]))
    elif typ in ("EKF1", "NKF1", "XKF1") and "VN" in d and "PN" in d:
        if typ == "XKF1" and d.get("C", 0) != 0:
            return  # XKF1 is logged per EKF core; keep the primary
        rows["ekf"].append((t, [d["VN"], d["VE"], d["VD"], d["PN"], d["PE"], d["PD"]]))
