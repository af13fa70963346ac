"""PX4 ULog (``.ulg``, pyulog) -> ``RawFlight``.

Topics: actuator_outputs (instance 0, ``output[0..3]`` PWM µs, in PX4 motor
order where PWM_MAIN_FUNC1..4 are Motor1..4 or not logged), else actuator_motors
(PX4 >= 1.14, ``control[0..3]``, each motor's command normalised 0..1, unit
``norm``; the PWM µs it became, where the log's parameters say, is
``RawFlight.norm_range_us``), vehicle_attitude (``q``, scalar-first, FRD->NED),
vehicle_angular_velocity (``xyz`` rad/s FRD), battery_status (``voltage_v``),
esc_status (``esc[i].esc_rpm``), and for the airborne rule and calibration
vehicle_status (arming_state), vehicle_land_detected (landed),
vehicle_local_position (NED) and sensor_combined (accelerometer).
ULog timestamps are µs on the boot clock already.

The file's message framing is walked first (``_extent``, on a memory map:
cost linear in the messages, not the file): a last message cut off by the end
of the file, or a tail of zeros or junk (a header whose type is no ULog
message type), is cut with a warning, and pyulog reads only what precedes it
(it would scan a zero-filled tail byte by byte for a sync marker).
"""

from __future__ import annotations

import contextlib
import io
import mmap
import struct
from pathlib import Path

import numpy as np

from monitor.errors import LogFormatError
from monitor.logs.raw import RawFlight, Stream
from monitor.logs.units import quat_wxyz_to_euler_zyx

TOPICS = [
    "actuator_outputs",
    "actuator_motors",
    "vehicle_attitude",
    "vehicle_angular_velocity",
    "battery_status",
    "esc_status",
    "vehicle_status",
    "vehicle_land_detected",
    "vehicle_local_position",
    "sensor_combined",
]
ARMING_STATE_ARMED = 2  # PX4 vehicle_status.arming_state
QUADROTOR_NAME = "MAV_TYPE_QUADROTOR"
OUTPUT_FUNCTION_MOTOR1 = 101  # PX4 >= 1.14 <driver>_FUNCn: 101..108 = Motor1..Motor8
# PX4 output drivers whose channels take PWM µs between <prefix>_MINn and <prefix>_MAXn (PX4 >= 1.14 parameters).
PWM_PREFIXES = ("PWM_MAIN", "PWM_AUX", "PWM_EXTR")
# SITL's pwm_out_sim has no MIN/MAX parameters: it maps 0..1 onto 1000..2000 µs (900 disarmed). Checked on
# ../shared/data/px4_ulog/sample_px4_events.ulg: actuator_outputs = 1000 + 1000 * actuator_motors to within 0.5 µs
# (tests/test_logs_third_party.py).
SITL_RANGE_US = (1000.0, 2000.0)


def _pyulog():
    try:
        from pyulog import ULog
    except ImportError as exc:  # optional dependency
        raise LogFormatError("reading .ulg needs pyulog, a base dependency: pip install pyulog") from exc
    return ULog


ULOG_HEADER_BYTES = 16
MSG_HEADER = struct.Struct("<HB")


def _message_types(ULog) -> frozenset[int]:
    return frozenset(v for k, v in vars(ULog).items() if k.startswith("MSG_TYPE_") and isinstance(v, int))


def _extent(path: Path, types: frozenset[int]) -> tuple[int, str]:
    """(bytes worth reading, why the rest is not: '' when the file ends on a whole message).

    Walks the message headers (uint16 size, uint8 type) from the file header on: a type that is no ULog
    message (zeros, junk: the next header is none either) or a message running past the end stops the walk there.
    """
    n = path.stat().st_size
    if n <= ULOG_HEADER_BYTES:
        return n, ""
    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as data:
        off = ULOG_HEADER_BYTES
        while off + MSG_HEADER.size <= n:
            size, kind = MSG_HEADER.unpack_from(data, off)
            if kind not in types and not _known_next(data, off + MSG_HEADER.size + size, n, types):
                return off, f"{n - off} bytes of zeros or junk after the last message (byte {off} on)"
            if off + MSG_HEADER.size + size > n:
                return off, f"last message cut off ({n - off} bytes; truncated log)"
            off += MSG_HEADER.size + size
        if off < n:
            return off, f"last message cut off ({n - off} bytes; truncated log)"
        return n, ""


def _known_next(data, off: int, n: int, types: frozenset[int]) -> bool:
    """A message type newer than pyulog is skipped when the framing goes on after it; zeros and junk do not."""
    return off + MSG_HEADER.size <= n and MSG_HEADER.unpack_from(data, off)[1] in types


def _open_ulog(ULog, path: Path, end: int):
    """pyulog on the file's first ``end`` bytes (a copy of the real content only when there is a tail)."""
    if end >= path.stat().st_size:
        return ULog(str(path), TOPICS)
    with open(path, "rb") as fh:
        return ULog(io.BytesIO(fh.read(end)), TOPICS)


# PX4 VT_TYPE (vtol_att_control): the kind of VTOL.
VTOL_TYPES = {0: "tailsitter", 1: "tiltrotor", 2: "standard VTOL"}
# PX4 >= 1.14 control allocation, quad X (CA_AIRFRAME 0, CA_ROTORn_PX/PY in m FRD, CA_ROTORn_KM > 0 for CCW):
# rotor n is motor n + 1 in PX4's quad-X order, 1 front-right CCW, 2 rear-left CCW, 3 front-left CW, 4 rear-right CW.
QUAD_X_SIGNS = ((1, 1, 1), (-1, -1, 1), (1, -1, -1), (-1, 1, -1))  # (PX, PY, KM) signs of rotors 0..3
CA_AIRFRAME_MULTIROTOR = 0


def describe_airframe(params: dict) -> str:
    """What the log says the vehicle is: its MAV_TYPE, and for a VTOL its VT_TYPE and airframe number."""
    name = mav_type_name(params.get("MAV_TYPE"))
    if not name or name.startswith(QUADROTOR_NAME + " "):
        return name
    parts = [name]
    if "VT_TYPE" in params and int(params["VT_TYPE"]) in VTOL_TYPES and "VTOL" in name:
        parts.append(f"a {VTOL_TYPES[int(params['VT_TYPE'])]} (VT_TYPE {int(params['VT_TYPE'])})")
    if params.get("SYS_AUTOSTART"):
        parts.append(f"airframe SYS_AUTOSTART {int(params['SYS_AUTOSTART'])}")
    return ", ".join(parts)


def check_quad_x(params: dict, path: Path) -> None:
    """Refuse a multirotor whose control-allocation parameters (where logged) are not a quad X, saying what they are."""
    if params.get("CA_AIRFRAME", CA_AIRFRAME_MULTIROTOR) != CA_AIRFRAME_MULTIROTOR or "CA_ROTOR_COUNT" not in params:
        return
    count = int(params["CA_ROTOR_COUNT"])
    if count != 4:
        raise LogFormatError(f"{path}: not a quad-X: the log says CA_ROTOR_COUNT {count} rotors; the model is for quad X")
    for n, signs in enumerate(QUAD_X_SIGNS):
        got = [params.get(f"CA_ROTOR{n}_{axis}", 0.0) for axis in ("PX", "PY", "KM")]
        if any(g * s <= 0 for g, s in zip(got, signs, strict=True)):
            where = ", ".join(f"{axis} {g:g}" for axis, g in zip(("PX", "PY", "KM"), got, strict=True))
            raise LogFormatError(
                f"{path}: not a quad-X: the log's rotor {n + 1} is at CA_ROTOR{n} {where}, not PX4's quad X "
                "(1 front-right CCW, 2 rear-left CCW, 3 front-left CW, 4 rear-right CW)"
            )


def mav_type_name(mav_type) -> str:
    """``MAV_TYPE_QUADROTOR`` for PX4's MAV_TYPE parameter 2 (pymavlink's enum); "" when not logged."""
    if mav_type is None:
        return ""
    from pymavlink.dialects.v20 import common

    entry = common.enums["MAV_TYPE"].get(int(mav_type))
    return f"{entry.name} ({int(mav_type)})" if entry else f"MAV_TYPE {int(mav_type)}"


def _topic(ulog, name: str) -> dict | None:
    sets = [d for d in ulog.data_list if d.name == name]
    if not sets:
        return None
    return min(sets, key=lambda d: d.multi_id).data  # instance 0: main outputs / primary sensor


def _cols(data: dict, names: list[str]) -> np.ndarray | None:
    if not all(n in data for n in names):
        return None
    return np.stack([np.asarray(data[n], dtype=np.float64) for n in names], axis=1)


def read_ulog(path: str | Path) -> RawFlight:
    path = Path(path)
    if not path.is_file():
        raise LogFormatError(f"{path}: no such file")
    ULog = _pyulog()
    try:
        end, tail = _extent(path, _message_types(ULog))
    except (OSError, ValueError) as exc:
        raise LogFormatError(f"{path}: cannot read: {exc}") from None
    chatter = io.StringIO()
    try:
        with contextlib.redirect_stdout(chatter):  # pyulog prints its corruption notices
            ulog = _open_ulog(ULog, path, end)
    except Exception as exc:  # pyulog raises plain exceptions on bad headers
        raise LogFormatError(f"{path}: not a readable ULog file: {exc}") from exc
    check_quad_x(ulog.initial_parameters, path)
    warnings = []
    damage = None  # what a missing topic may be owed to
    if getattr(ulog, "file_corruption", False):
        warnings.append(f"{path.name}: ULog file is corrupted: damaged data skipped")
        damage = "damaged ULog (pyulog found corrupt data and skipped it)"
    if tail:
        warnings.append(f"{path.name}: {tail}: read up to the damage")
        damage = f"truncated ULog ({path.stat().st_size} bytes: {tail})"

    def need(name: str, fields: list[str]) -> Stream:
        d = _topic(ulog, name)
        if d is None and damage:
            raise LogFormatError(f"{path}: {damage}: topic {name} is not in what could be read: cannot diagnose")
        if d is None:
            raise LogFormatError(f"{path}: topic {name} not logged: cannot diagnose")
        v = _cols(d, fields)
        if v is None:
            raise LogFormatError(f"{path}: topic {name} lacks fields {fields}")
        return Stream.build(d["timestamp"], v)

    def opt(name: str, fields: list[str]) -> Stream | None:
        d = _topic(ulog, name)
        v = None if d is None else _cols(d, fields)
        return None if v is None else Stream.build(d["timestamp"], v if v.shape[1] > 1 else v[:, 0])

    cmd_unit, norm_range_us = "us", None
    moved = motors_off_first_outputs(ulog.initial_parameters)
    if _topic(ulog, "actuator_motors") is not None and (_topic(ulog, "actuator_outputs") is None or moved):
        cmd, cmd_unit = need("actuator_motors", [f"control[{i}]" for i in range(4)]), "norm"
        norm_range_us, why = motor_pwm_range_us(ulog.initial_parameters, ulog.msg_info_dict.get("ver_hw", ""))
        if moved:
            why = f"{moved}, so actuator_outputs[0..3] are not motors 1..4; {why}"
        warnings.append(f"motor commands from actuator_motors (normalised 0..1): {why}")
    else:
        cmd = need("actuator_outputs", [f"output[{i}]" for i in range(4)])
        if moved:
            warnings.append(f"{moved}: actuator_outputs[0..3] may not be motors 1..4 (no actuator_motors logged)")
        if len(cmd) and np.nanmax(cmd.values) <= 1.0:
            warnings.append("actuator_outputs look normalised (<= 1), not PWM µs: the ESC fit will not apply")
    q = need("vehicle_attitude", [f"q[{i}]" for i in range(4)])
    rates = opt("vehicle_angular_velocity", [f"xyz[{i}]" for i in range(3)])
    if rates is None:
        # PX4 before v1.11 has no vehicle_angular_velocity; vehicle_attitude carried the rates.
        rates = opt("vehicle_attitude", ["rollspeed", "pitchspeed", "yawspeed"])
        if rates is None:
            raise LogFormatError(f"{path}: neither vehicle_angular_velocity nor vehicle_attitude rates logged: cannot diagnose")
        warnings.append("body rates from vehicle_attitude.rollspeed/pitchspeed/yawspeed (PX4 before v1.11)")
    battery = opt("battery_status", ["voltage_v"]) or opt("battery_status", ["voltage_filtered_v"])
    status = opt("vehicle_status", ["arming_state"])
    armed = None if status is None else Stream(status.t_us, (status.values == ARMING_STATE_ARMED).astype(float))
    pos = opt("vehicle_local_position", ["x", "y", "z"])
    height = None if pos is None else Stream(pos.t_us, -(pos.values[:, 2] - pos.values[0, 2]))
    return RawFlight(
        source=str(path),
        vehicle_type=describe_airframe(ulog.initial_parameters),
        cmd_unit=cmd_unit,
        norm_range_us=norm_range_us,
        motor_cmd=cmd,
        attitude_rad=Stream(q.t_us, quat_wxyz_to_euler_zyx(q.values)),
        rates_rad_s=rates,
        battery_v=battery,
        armed=armed,
        landed=opt("vehicle_land_detected", ["landed"]),
        height_m=height,
        esc_rpm=opt("esc_status", [f"esc[{i}].esc_rpm" for i in range(4)]),
        accel_frd_m_s2=opt("sensor_combined", [f"accelerometer_m_s2[{i}]" for i in range(3)]),
        vel_ned_m_s=opt("vehicle_local_position", ["vx", "vy", "vz"]),
        pos_ned_m=pos,
        warnings=warnings,
    )


def motors_off_first_outputs(params: dict) -> str:
    """What PX4's main outputs 1..4 carry when that is not motors 1..4 (PWM_MAIN_FUNCn, PX4 >= 1.14), else ""."""
    funcs = [params.get(f"PWM_MAIN_FUNC{n}") for n in range(1, 5)]
    if None in funcs or funcs == [OUTPUT_FUNCTION_MOTOR1 + k for k in range(4)]:
        return ""
    return ", ".join(f"PWM_MAIN_FUNC{n} {int(f)}" for n, f in enumerate(funcs, start=1))


def motor_pwm_range_us(params: dict, hardware: str) -> tuple[tuple[tuple[float, float], ...] | None, str]:
    """(PWM µs that motors 1..4's 0..1 command spans, per motor, or None; how that was found, for a warning).

    Motor k is on the channel n whose ``<prefix>_FUNCn`` is 100 + k; a PWM driver's channel spans
    ``<prefix>_MINn``..``<prefix>_MAXn``. A motor on no PWM channel (DShot, UAVCAN) has no µs."""
    ranges, sitl = [], False
    for k in range(4):
        found = None
        for prefix in PWM_PREFIXES:
            n = next((n for n in range(1, 17) if params.get(f"{prefix}_FUNC{n}") == OUTPUT_FUNCTION_MOTOR1 + k), None)
            if n is None:
                continue
            lo, hi = params.get(f"{prefix}_MIN{n}"), params.get(f"{prefix}_MAX{n}")
            if lo is not None and hi is not None and 0 < lo < hi:
                found = (float(lo), float(hi))
            elif lo is None and hi is None and hardware == "PX4_SITL":
                found, sitl = SITL_RANGE_US, True
            break
        if found is None:
            return None, f"motor {k + 1} is on no PWM output with a logged range, so its command has no PWM µs"
        ranges.append(found)
    lo_us, hi_us = min(r[0] for r in ranges), max(r[1] for r in ranges)
    where = "SITL's fixed output range" if sitl else "the PWM_*_MIN/MAX parameters"
    return tuple(ranges), f"PWM {lo_us:g}..{hi_us:g} µs from {where}"
