"""A PX4-like MAVLink 2 telemetry log (.tlog) of one simulated flight.

A .tlog is what QGroundControl records: each MAVLink packet prefixed by the
8-byte big-endian wall-clock time in microseconds. We write what PX4 streams
during a mission (system 1, component 1 = MAV_COMP_ID_AUTOPILOT1):

| message | rate | content |
| HEARTBEAT | 1 Hz | MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_PX4, armed, custom mode AUTO.MISSION |
| EXTENDED_SYS_STATE | 1 Hz | landed_state IN_AIR |
| SYS_STATUS, BATTERY_STATUS | 2 Hz | pack voltage, current, consumed charge |
| ATTITUDE, LOCAL_POSITION_NED, HIGHRES_IMU, SERVO_OUTPUT_RAW, ESC_STATUS | log rate | state, IMU, PWM, ESC RPM |

Times: ``time_boot_ms`` / ``time_usec`` are the boot clock of the log
(``FlightLog.timestamp_us``); the wall clock is ``wall_boot_us`` + boot time.
ESC_STATUS (id 291, absent from pymavlink 2.4.50) is encoded by
``monitor.mavlink.esc``, the same code the monitor decodes it with; its RPM
is the rotor's actual speed, as ESC telemetry measures it.
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from monitor.esc import RPM_PER_RAD_S
from monitor.logs.units import US_PER_MS, US_PER_S, V_PER_MV
from monitor.mavlink.esc import encode_esc_status
from offline.sim.log import FlightLog
from offline.sim.quat import rotate_world_to_body

# 2024-06-01T12:00:00Z: a fixed wall clock at boot keeps files byte-for-byte reproducible.
DEFAULT_WALL_BOOT_US = 1_717_243_200_000_000
PX4_CUSTOM_MODE_AUTO_MISSION = (4 << 16) | (4 << 24)  # PX4 main mode AUTO (4), sub mode MISSION (4)
BASE_MODE_ARMED_AUTO = (
    mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
    | mavlink2.MAV_MODE_FLAG_STABILIZE_ENABLED
    | mavlink2.MAV_MODE_FLAG_GUIDED_ENABLED
    | mavlink2.MAV_MODE_FLAG_AUTO_ENABLED
    | mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
)
EARTH_FIELD_NED_GAUSS = np.array([0.21, 0.0, 0.43])  # mid-latitude field, for a plausible magnetometer
SLOW_RATE_HZ = 2.0
N_CELLS = 4  # 4S pack (models/vehicle.yaml battery_full_v 16.8 V)


def _pressure_hpa(alt_m: np.ndarray) -> np.ndarray:
    """ISA barometric pressure at ``alt_m`` above mean sea level."""
    return 1013.25 * (1.0 - 2.25577e-5 * alt_m) ** 5.25588


def write_tlog(
    path: str | Path,
    log: FlightLog,
    i: int,
    *,
    wall_boot_us: int = DEFAULT_WALL_BOOT_US,
    battery_full_v: float = 16.8,
    battery_capacity_mah: float = 5000.0,
    landing: bool = False,
) -> Path:
    """Write flight ``i`` of ``log`` as a .tlog at ``path`` (temp file, then rename).

    ``landing``: after the last simulated sample the log ends as PX4 ends a mission (``landing_tail``): the land
    detector says on the ground, the motors idle, then the vehicle disarms. The simulators fly no touchdown; the
    tail carries only the flags and outputs a monitor reads to know the flight ended in landing and disarm."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as fh:
            _write(fh, log, i, wall_boot_us, battery_full_v, battery_capacity_mah)
            if landing:
                landing_tail(fh, int(log.timestamp_us[-1]), 1.0 / log.log_rate_hz, wall_boot_us)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def _write(fh, log: FlightLog, i: int, wall_boot_us: int, battery_full_v: float, capacity_mah: float) -> None:
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=mavlink2.MAV_COMP_ID_AUTOPILOT1)
    mav.robust_parsing = True
    ts = log.timestamp_us.astype(np.int64)
    dt_s = 1.0 / log.log_rate_hz
    pos, vel = log.pos_ned_m[i], log.vel_ned_m_s[i]
    rates, acc = log.rates_frd_rad_s[i], log.accel_frd_m_s2[i]
    pwm = np.rint(log.pwm_us[i]).astype(int)
    esc_rpm = np.rint(log.motor_omega_rad_s[i] * RPM_PER_RAD_S).astype(int)
    mag = rotate_world_to_body(log.q_world_body[i], np.broadcast_to(EARTH_FIELD_NED_GAUSS, (len(ts), 3)))
    alt = -pos[:, 2]
    pressure = _pressure_hpa(alt)
    volt, amp = log.battery_v[i], log.battery_current_a[i]
    consumed_mah = np.cumsum(amp) * dt_s / 3.6
    remaining = np.clip(np.rint(100.0 * (1.0 - consumed_mah / capacity_mah)), 0, 100).astype(int)
    esc_volt = [float(v) for v in volt]

    def emit(t_boot_us: int, msg) -> None:
        fh.write(struct.pack(">Q", wall_boot_us + int(t_boot_us)))
        fh.write(msg.pack(mav))

    def emit_bytes(t_boot_us: int, data: bytes) -> None:
        fh.write(struct.pack(">Q", wall_boot_us + int(t_boot_us)))
        fh.write(data)

    next_hb = next_slow = None
    slow_period_us = int(round(US_PER_S / SLOW_RATE_HZ))
    for j, t in enumerate(ts):
        t = int(t)
        # HEARTBEAT first (a reader learns the autopilot's system id from it), then the time-stamped
        # messages, then the untimed ones, so a reader's boot clock is set before they arrive.
        heartbeat_due = next_hb is None or t >= next_hb
        if heartbeat_due:
            emit(
                t,
                mav.heartbeat_encode(
                    mavlink2.MAV_TYPE_QUADROTOR,
                    mavlink2.MAV_AUTOPILOT_PX4,
                    BASE_MODE_ARMED_AUTO,
                    PX4_CUSTOM_MODE_AUTO_MISSION,
                    mavlink2.MAV_STATE_ACTIVE,
                    3,
                ),
            )
            next_hb = (t // US_PER_S + 1) * US_PER_S
        t_ms = t // US_PER_MS
        emit(
            t,
            mav.attitude_encode(
                t_ms,
                float(log.roll_rad[i, j]),
                float(log.pitch_rad[i, j]),
                float(log.yaw_rad[i, j]),
                float(rates[j, 0]),
                float(rates[j, 1]),
                float(rates[j, 2]),
            ),
        )
        emit(t, mav.local_position_ned_encode(t_ms, *map(float, pos[j]), *map(float, vel[j])))
        emit(
            t,
            mav.highres_imu_encode(
                t,
                *map(float, acc[j]),
                *map(float, rates[j]),
                *map(float, mag[j]),
                float(pressure[j]),
                0.0,
                float(alt[j]),
                25.0,
                0x1FFF,
                0,
            ),
        )
        emit(t, mav.servo_output_raw_encode(t & 0xFFFFFFFF, 0, *map(int, pwm[j]), 0, 0, 0, 0))
        emit_bytes(t, encode_esc_status(mav, t, esc_rpm[j], [esc_volt[j]] * 4, [float(amp[j]) / 4] * 4))
        if heartbeat_due:
            emit(t, mav.extended_sys_state_encode(mavlink2.MAV_VTOL_STATE_UNDEFINED, mavlink2.MAV_LANDED_STATE_IN_AIR))
        if next_slow is None or t >= next_slow:
            mv = int(round(volt[j] / V_PER_MV))
            ca = int(round(amp[j] * 100))
            cells = [int(round(volt[j] / V_PER_MV / N_CELLS))] * N_CELLS + [65535] * (10 - N_CELLS)
            emit(t, mav.sys_status_encode(0, 0, 0, 0, mv, ca, int(remaining[j]), 0, 0, 0, 0, 0, 0))
            emit(
                t,
                mav.battery_status_encode(
                    0,
                    mavlink2.MAV_BATTERY_FUNCTION_ALL,
                    mavlink2.MAV_BATTERY_TYPE_LIPO,
                    32767,
                    cells,
                    ca,
                    int(round(consumed_mah[j])),
                    -1,
                    int(remaining[j]),
                    0,
                    mavlink2.MAV_BATTERY_CHARGE_STATE_OK,
                    [0, 0, 0, 0],
                    0,
                    0,
                ),
            )
            next_slow = (t // slow_period_us + 1) * slow_period_us


# PX4's idle and disarmed outputs (PWM_MAIN_MIN 1100 us, PWM_MAIN_DISARM 900 us) and how long the tail lasts.
IDLE_PWM_US, DISARMED_PWM_US = 1100, 900
LANDED_IDLE_S, DISARMED_S = 1.0, 2.0


def landing_tail(fh, last_us: int, dt_s: float, wall_boot_us: int) -> None:
    """Append a mission's end after boot time ``last_us``: ``LANDED_IDLE_S`` on the ground armed at idle, then
    ``DISARMED_S`` disarmed (HEARTBEAT without MAV_MODE_FLAG_SAFETY_ARMED), level and at rest."""
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=mavlink2.MAV_COMP_ID_AUTOPILOT1)
    step_us = int(round(dt_s * US_PER_S))
    n = int(round((LANDED_IDLE_S + DISARMED_S) / dt_s))
    for j in range(1, n + 1):
        t = last_us + j * step_us
        armed = j * dt_s <= LANDED_IDLE_S
        pwm = IDLE_PWM_US if armed else DISARMED_PWM_US
        msgs = []
        if j == 1 or (t // US_PER_S) != ((t - step_us) // US_PER_S):
            base = BASE_MODE_ARMED_AUTO if armed else BASE_MODE_ARMED_AUTO & ~mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
            msgs.append(
                mav.heartbeat_encode(
                    mavlink2.MAV_TYPE_QUADROTOR,
                    mavlink2.MAV_AUTOPILOT_PX4,
                    base,
                    PX4_CUSTOM_MODE_AUTO_MISSION,
                    mavlink2.MAV_STATE_ACTIVE if armed else mavlink2.MAV_STATE_STANDBY,
                    3,
                )
            )
            msgs.append(mav.extended_sys_state_encode(mavlink2.MAV_VTOL_STATE_UNDEFINED, mavlink2.MAV_LANDED_STATE_ON_GROUND))
        t_ms = t // US_PER_MS
        msgs.append(mav.attitude_encode(t_ms, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        msgs.append(mav.servo_output_raw_encode(t & 0xFFFFFFFF, 0, *([pwm] * 4), 0, 0, 0, 0))
        for m in msgs:
            fh.write(struct.pack(">Q", wall_boot_us + int(t)))
            fh.write(m.pack(mav))
