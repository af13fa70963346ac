"""One pymavlink message -> typed samples on the autopilot's boot clock (µs).

Shared by the onboard daemon (message by message, live) and the tlog reader of
``propwatch diagnose`` (a whole file): both feed every message, in the order it
was received, to one ``MavlinkDecoder`` and so decode identically.

What the decoder owns, because it needs state across messages:
- **which system is the autopilot.** Only messages from the autopilot's
  (system id, component id) are decoded; the system id is taken from the first
  autopilot HEARTBEAT (GCS, companion computers and other vehicles ignored)
  unless it is configured. Everything else is counted in ``ignored``.
- **the boot clock.** ATTITUDE carries ``time_boot_ms``; SERVO_OUTPUT_RAW a
  32-bit ``time_usec`` that wraps every 71.6 min (unwrapped to the candidate
  nearest the current clock); ACTUATOR_OUTPUT_STATUS and ESC_STATUS a 64-bit
  ``time_usec``; LOCAL_POSITION_NED ``time_boot_ms`` as ATTITUDE; HIGHRES_IMU a
  64-bit ``time_usec`` and SCALED_IMU ``time_boot_ms``. Messages without a time (HEARTBEAT, BATTERY_STATUS,
  SYS_STATUS, EXTENDED_SYS_STATE) are stamped with the latest boot time seen
  (``None`` before any). A timestamp that goes back by more than
  ``reboot_jump_us`` means the autopilot rebooted: a ``ClockReset`` is emitted
  before the sample, so consumers can drop what they hold.

Values the autopilot marks as unknown (PWM 0 or 65535, voltage 65535 mV) come
out as NaN; NaN and inf in float fields pass through untouched: the decoder
never invents a value.
"""

from __future__ import annotations

import math
import struct
import sys
from collections import Counter
from dataclasses import dataclass
from typing import Any

from monitor.mavlink import esc as mavlink_esc
from monitor.vehicle import GRAVITY_M_S2

# MAVLink constants (common.xml), named here so the module needs no dialect import.
MAV_AUTOPILOT_INVALID = 8
MAV_TYPE_GCS = 6
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_COMP_ID_AUTOPILOT1 = 1
MAV_LANDED_STATE_UNDEFINED = 0
MAV_LANDED_STATE_ON_GROUND = 1
MAV_LANDED_STATE_IN_AIR = 2
MAV_LANDED_STATE_TAKEOFF = 3
MAV_LANDED_STATE_LANDING = 4
UINT16_UNKNOWN = 65535
ESC_STATUS_ID = 291
# The accelerometer, optional context for the decision (not in STREAM_IDS: a diagnosis's tlog read does not unpack them).
HIGHRES_IMU_ID = 105
SCALED_IMU_ID = 26

_WRAP_US = 1 << 32
US_PER_MS = 1000
MV_PER_V = 1000.0
M_S2_PER_MG = GRAVITY_M_S2 / 1000.0  # SCALED_IMU's accelerometer unit, milli-g
# Types of a vehicle's own flight stack never include these: their heartbeats
# are other components (ground station, companion computers such as us).
_NOT_AUTOPILOT_TYPES = {MAV_TYPE_GCS, MAV_TYPE_ONBOARD_CONTROLLER}


@dataclass(frozen=True)
class Attitude:
    timestamp_us: int
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    roll_rate_rad_s: float
    pitch_rate_rad_s: float
    yaw_rate_rad_s: float


@dataclass(frozen=True)
class ActuatorOutputs:
    """Output channel commands in µs (PWM); ``values[j]`` is output ``first_channel + j`` (1-based)."""

    timestamp_us: int
    first_channel: int
    values_us: tuple[float, ...]
    source: str  # "SERVO_OUTPUT_RAW" or "ACTUATOR_OUTPUT_STATUS"


@dataclass(frozen=True)
class EscRpm:
    """ESC telemetry; ``rpm[j]`` is ESC ``first_index + j`` (0-based, as in ESC_STATUS.index)."""

    timestamp_us: int
    first_index: int
    rpm: tuple[float, ...]


@dataclass(frozen=True)
class Vibration:
    """VIBRATION (#241). PX4 fills x = gyro coning metric, y = gyro and z = accelerometer high-frequency
    vibration metrics (filtered |delta - previous delta| of the IMU integrals); clipping = cumulative counts."""

    timestamp_us: int
    vibration: tuple[float, float, float]  # (x, y, z) as sent
    clipping: tuple[int, int, int]


@dataclass(frozen=True)
class LocalVelocity:
    """LOCAL_POSITION_NED (#32): the estimator's ground velocity in the local NED frame (position unused)."""

    timestamp_us: int
    vel_ned_m_s: tuple[float, float, float]  # (vx north, vy east, vz down) as sent


@dataclass(frozen=True)
class ImuAccel:
    """The accelerometer's specific force in the body frame: HIGHRES_IMU (#105, m/s^2) of the first IMU (id 0,
    PX4's selected one, bias-corrected), or SCALED_IMU (#26, IMU 1, milli-g converted here)."""

    timestamp_us: int
    accel_frd_m_s2: tuple[float, float, float]  # (x forward, y right, z down) specific force
    source: str  # "HIGHRES_IMU" or "SCALED_IMU"


@dataclass(frozen=True)
class Battery:
    timestamp_us: int | None
    voltage_v: float
    source: str  # "BATTERY_STATUS" or "SYS_STATUS"


@dataclass(frozen=True)
class Heartbeat:
    timestamp_us: int | None
    system_id: int
    component_id: int
    armed: bool
    mav_type: int


@dataclass(frozen=True)
class LandedState:
    timestamp_us: int | None
    landed_state: int  # MAV_LANDED_STATE_*


@dataclass(frozen=True)
class ClockReset:
    """The autopilot's boot clock went backwards (reboot): drop everything held."""

    timestamp_us: int
    previous_us: int


Sample = (
    Attitude | ActuatorOutputs | EscRpm | Vibration | LocalVelocity | ImuAccel | Battery | Heartbeat | LandedState | ClockReset
)


def _register_esc_in_loaded_dialects() -> None:
    """Teach the dialects already imported to parse ESC_STATUS (cheap: importing every dialect costs ~1 s).

    A dialect imported later yields UNKNOWN_291, which ``decode`` still reads.
    """
    for name, mod in list(sys.modules.items()):
        if name.startswith("pymavlink.dialects.v") and hasattr(mod, "mavlink_map"):
            mavlink_esc.register(mod)


def is_flying(landed_state: int) -> bool:
    """In the air for classification: IN_AIR only (take-off and landing transients are not in training)."""
    return landed_state == MAV_LANDED_STATE_IN_AIR


def _float(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _pwm(v: Any) -> float:
    v = _float(v)
    return math.nan if v in (0.0, float(UINT16_UNKNOWN)) else v


class MavlinkDecoder:
    """Stateful decoder; feed it every received message in order with ``decode(msg)``."""

    def __init__(
        self,
        system_id: int | None = None,
        component_id: int = MAV_COMP_ID_AUTOPILOT1,
        battery_id: int = 0,
        reboot_jump_us: int = 10_000_000,
    ):
        self.system_id = system_id
        self.component_id = component_id
        self.battery_id = battery_id
        self.reboot_jump_us = reboot_jump_us
        _register_esc_in_loaded_dialects()
        self.clock_us: int | None = None
        self.ignored: Counter = Counter()  # (system, component) -> messages ignored
        self.undecodable: Counter = Counter()  # message type -> count

    # -- the boot clock ------------------------------------------------------------
    def _stamp(self, t_us: int, out: list[Sample]) -> int:
        if self.clock_us is None:
            self.clock_us = t_us
        elif t_us < self.clock_us - self.reboot_jump_us:
            out.append(ClockReset(t_us, self.clock_us))
            self.clock_us = t_us
        elif t_us > self.clock_us:
            self.clock_us = t_us
        return t_us

    def unwrap_u32_us(self, t32: int) -> int:
        """A wrapped 32-bit µs time -> the 64-bit boot time nearest the current clock."""
        t32 = int(t32) & (_WRAP_US - 1)
        if self.clock_us is None:
            return t32
        k = round((self.clock_us - t32) / _WRAP_US)
        return t32 + max(k, 0) * _WRAP_US

    # -- dispatch ----------------------------------------------------------------
    def _is_autopilot(self, msg: Any) -> bool:
        sys_id, comp_id = msg.get_srcSystem(), msg.get_srcComponent()
        if (
            self.system_id is None
            and msg.get_type() == "HEARTBEAT"
            and comp_id == self.component_id
            and msg.autopilot != MAV_AUTOPILOT_INVALID
            and msg.type not in _NOT_AUTOPILOT_TYPES
        ):
            self.system_id = sys_id
        if sys_id == self.system_id and comp_id == self.component_id:
            return True
        self.ignored[(sys_id, comp_id)] += 1
        return False

    def decode(self, msg: Any) -> list[Sample]:
        """Samples from one message ([] for types not used, other systems, and bad data)."""
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self.undecodable[kind] += 1
            return []
        if kind == f"UNKNOWN_{ESC_STATUS_ID}":
            msg = self._esc_from_unknown(msg)
            if msg is None:
                return []
            kind = "ESC_STATUS"
        handler = _HANDLERS.get(kind)
        if handler is None or not self._is_autopilot(msg):
            return []
        out: list[Sample] = []
        try:
            handler(self, msg, out)
        except (AttributeError, TypeError, ValueError, IndexError) as exc:
            # A message of the right id but a shape we cannot read: count it, invent nothing.
            self.undecodable[f"{kind}: {type(exc).__name__}"] += 1
            return []
        return out

    def _esc_from_unknown(self, msg: Any) -> Any | None:
        """An UNKNOWN_291 from a parser that predates ``mavlink_esc.register()``: decode its raw bytes."""
        try:
            index, time_usec, rpm = mavlink_esc.decode_esc_status(msg)
            buf = bytes(msg.get_msgbuf())
            # pymavlink leaves an unknown message's header empty: read the ids from the frame.
            sys_id, comp_id = (buf[5], buf[6]) if buf[0] == 0xFD else (buf[3], buf[4])
        except (ValueError, IndexError, struct.error) as exc:
            self.undecodable[f"UNKNOWN_291: {exc}"] += 1
            return None
        esc = mavlink_esc.MAVLink_esc_status_message(index, time_usec, rpm, [math.nan] * 4, [math.nan] * 4)
        esc._header.srcSystem, esc._header.srcComponent = sys_id, comp_id
        return esc

    # -- one handler per message type ---------------------------------------------
    def _attitude(self, m: Any, out: list[Sample]) -> None:
        t = self._stamp(int(m.time_boot_ms) * US_PER_MS, out)
        out.append(
            Attitude(
                t, _float(m.roll), _float(m.pitch), _float(m.yaw), _float(m.rollspeed), _float(m.pitchspeed), _float(m.yawspeed)
            )
        )

    def _servo(self, m: Any, out: list[Sample]) -> None:
        t = self._stamp(self.unwrap_u32_us(m.time_usec), out)
        port = int(getattr(m, "port", 0) or 0)
        values = tuple(_pwm(getattr(m, f"servo{i}_raw", 0)) for i in range(1, 9))
        out.append(ActuatorOutputs(t, 8 * port + 1, values, "SERVO_OUTPUT_RAW"))

    def _actuator(self, m: Any, out: list[Sample]) -> None:
        t = self._stamp(int(m.time_usec), out)
        active = int(m.active)
        values = tuple(_float(v) if active & (1 << j) else math.nan for j, v in enumerate(m.actuator))
        out.append(ActuatorOutputs(t, 1, values, "ACTUATOR_OUTPUT_STATUS"))

    def _esc(self, m: Any, out: list[Sample]) -> None:
        t = self._stamp(int(m.time_usec), out)
        out.append(EscRpm(t, int(m.index), tuple(_float(r) for r in m.rpm)))

    def _vibration(self, m: Any, out: list[Sample]) -> None:
        if int(m.time_usec) == 0:  # some stacks leave it unset: place it at the latest boot time
            if self.clock_us is None:
                return
            t = self.clock_us
        else:
            t = self._stamp(int(m.time_usec), out)
        vib = (_float(m.vibration_x), _float(m.vibration_y), _float(m.vibration_z))
        out.append(Vibration(t, vib, (int(m.clipping_0), int(m.clipping_1), int(m.clipping_2))))

    def _local_position(self, m: Any, out: list[Sample]) -> None:
        t = self._stamp(int(m.time_boot_ms) * US_PER_MS, out)
        out.append(LocalVelocity(t, (_float(m.vx), _float(m.vy), _float(m.vz))))

    def _highres_imu(self, m: Any, out: list[Sample]) -> None:
        if int(getattr(m, "id", 0)) != 0:  # a MAVLink 2 extension: absent (v1) means the first IMU
            return
        t = self._stamp(int(m.time_usec), out)
        out.append(ImuAccel(t, (_float(m.xacc), _float(m.yacc), _float(m.zacc)), "HIGHRES_IMU"))

    def _scaled_imu(self, m: Any, out: list[Sample]) -> None:
        t = self._stamp(int(m.time_boot_ms) * US_PER_MS, out)
        acc = (_float(m.xacc) * M_S2_PER_MG, _float(m.yacc) * M_S2_PER_MG, _float(m.zacc) * M_S2_PER_MG)
        out.append(ImuAccel(t, acc, "SCALED_IMU"))

    def _battery(self, m: Any, out: list[Sample]) -> None:
        if int(m.id) != self.battery_id:
            return
        cells = [v for v in m.voltages if v != UINT16_UNKNOWN]
        cells += [v for v in getattr(m, "voltages_ext", ()) if v not in (0, UINT16_UNKNOWN)]
        volts = sum(cells) / MV_PER_V if cells else math.nan
        out.append(Battery(self.clock_us, volts, "BATTERY_STATUS"))

    def _sys_status(self, m: Any, out: list[Sample]) -> None:
        mv = int(m.voltage_battery)
        out.append(Battery(self.clock_us, math.nan if mv == UINT16_UNKNOWN else mv / MV_PER_V, "SYS_STATUS"))

    def _heartbeat(self, m: Any, out: list[Sample]) -> None:
        armed = bool(int(m.base_mode) & MAV_MODE_FLAG_SAFETY_ARMED)
        out.append(Heartbeat(self.clock_us, m.get_srcSystem(), m.get_srcComponent(), armed, int(m.type)))

    def _extended_sys_state(self, m: Any, out: list[Sample]) -> None:
        out.append(LandedState(self.clock_us, int(m.landed_state)))


_HANDLERS = {
    "ATTITUDE": MavlinkDecoder._attitude,
    "SERVO_OUTPUT_RAW": MavlinkDecoder._servo,
    "ACTUATOR_OUTPUT_STATUS": MavlinkDecoder._actuator,
    "ESC_STATUS": MavlinkDecoder._esc,
    "VIBRATION": MavlinkDecoder._vibration,
    "LOCAL_POSITION_NED": MavlinkDecoder._local_position,
    "HIGHRES_IMU": MavlinkDecoder._highres_imu,
    "SCALED_IMU": MavlinkDecoder._scaled_imu,
    "BATTERY_STATUS": MavlinkDecoder._battery,
    "SYS_STATUS": MavlinkDecoder._sys_status,
    "HEARTBEAT": MavlinkDecoder._heartbeat,
    "EXTENDED_SYS_STATE": MavlinkDecoder._extended_sys_state,
}

# Messages the monitor needs from PX4, for stream-rate requests and rate checks.
STREAM_IDS = {
    "ATTITUDE": 30,
    "SERVO_OUTPUT_RAW": 36,
    "ACTUATOR_OUTPUT_STATUS": 375,
    "ESC_STATUS": ESC_STATUS_ID,
    "VIBRATION": 241,
    "LOCAL_POSITION_NED": 32,
    "BATTERY_STATUS": 147,
    "SYS_STATUS": 1,
    "EXTENDED_SYS_STATE": 245,
}
