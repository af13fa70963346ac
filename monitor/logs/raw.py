"""What a log reader hands over before resampling: time-stamped streams.

Every reader (tlog, ULog, DataFlash, CSV) decodes its format into a
``RawFlight`` of ``Stream``s in project units and frames (rad, rad/s, V, m,
FRD/NED, PX4 rotor order) on the autopilot's boot clock in µs. One function,
``to_flight_table``, then puts any ``RawFlight`` onto the model's grid, so the
grid, the staleness rule, the ESC conversion and the airborne rule are the same
for every format.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from monitor.decision.envelope import implausible_context
from monitor.errors import LogFormatError
from monitor.esc import EscCurve
from monitor.flight import FlightTable, true_runs
from monitor.resample import US_PER_S, grid_us, hold, period_us, span_mean

# A held sample is used for at most this long, then it is NaN: a stream that
# stopped is not held forever. Fixed (not derived from the log's own rate) and
# equal to the daemon's defaults (monitor.daemon.config.ResampleConfig:
# max_gap_s, state_max_age_s, battery_max_age_s), so that a whole log and a
# live stream hold the same values (a test checks the numbers agree).
MAX_AGE_US = 250_000  # attitude, rates, motor outputs, ESC telemetry, extras
STATE_MAX_AGE_US = 3_000_000  # armed / landed flags (1 Hz class messages)
BATTERY_MAX_AGE_US = 5_000_000
EVENT_MAX_AGE_US = int(np.iinfo(np.int64).max // 2)

# Mean throttle above which the rotors are taken as lifting (airborne rule), per
# command unit: 15 % of the command range above idle. PX4 idles armed near
# 1100 µs (PWM_MAIN_MIN), ArduCopter log171 at 1049 µs (MOT_SPIN_ARMED 50); both
# hover well above 1300 µs. The Crazyflie sends 0 when not flying; PX4's normalised
# actuator_motors (unit "norm") idles at 0.
LIFT_CMD = {"us": 1150.0, "cf16": 0.15 * 65535.0, "norm": 0.15}
# Height above the first sample that counts as off the ground, where a
# height stream exists (CrazyPAD's README uses z > 0.25 m).
DEFAULT_MIN_HEIGHT_M = 0.25
# Airborne stretches shorter than this are take-off bounces, not flight. Chosen, not measured.
MIN_SEGMENT_S = 1.0
# A mean motor command below lift throttle for at most this long between two airborne stretches, while armed and
# (where logged) the land detector says in the air, is a throttle dip in flight (a fast descent, a controller
# transient, a dropped output sample), not a landing: evalsim's controller dips to 1104 us for 0.2 s on descents,
# which reset the in-flight rule's evidence as if the vehicle had landed. Chosen, not measured: five times that dip.
MAX_THROTTLE_DIP_S = 1.0


@dataclass(frozen=True)
class Stream:
    """Samples of one message/topic: sorted boot-clock times and (N, ...) values."""

    t_us: np.ndarray
    values: np.ndarray
    # None: the default for its field below. Event streams (ArduPilot's EV
    # armed/disarmed) hold until the next event: EVENT_MAX_AGE_US.
    max_age_us: int | None = None

    @classmethod
    def build(cls, t_us, values, max_age_us: int | None = None) -> Stream:
        t = np.asarray(t_us, dtype=np.int64)
        v = np.asarray(values, dtype=np.float64)
        if len(t) != len(v):
            raise ValueError(f"stream has {len(t)} times but {len(v)} values")
        if len(t) and np.any(np.diff(t) < 0):
            # Logs interleave several sources; a stable sort keeps the last-written duplicate last.
            order = np.argsort(t, kind="stable")
            t, v = t[order], v[order]
        return cls(t, v, max_age_us)

    def __len__(self) -> int:
        return len(self.t_us)

    def rate_hz(self) -> float:
        """Median sample rate (0 when fewer than two samples)."""
        if len(self.t_us) < 2:
            return 0.0
        d = np.diff(self.t_us)
        d = d[d > 0]
        return float(US_PER_S / np.median(d)) if len(d) else 0.0


@dataclass
class RawFlight:
    """A decoded log. Required: motor commands, attitude, body rates."""

    source: str
    cmd_unit: str  # "us" (PWM µs), "cf16" (Crazyflie 0..65535) or "norm" (PX4 actuator_motors, 0..1)
    motor_cmd: Stream  # (N, 4) PX4 rotor order
    attitude_rad: Stream  # (N, 3) roll, pitch, yaw (Euler ZYX, FRD/NED); NaN column = not logged
    rates_rad_s: Stream  # (N, 3) body rates FRD
    battery_v: Stream | None = None  # (N,)
    armed: Stream | None = None  # (N,) 1 armed, 0 disarmed
    landed: Stream | None = None  # (N,) 1 on the ground, 0 in the air (autopilot's land detector)
    height_m: Stream | None = None  # (N,) up, above the first sample
    esc_rpm: Stream | None = None  # (N, 4) ESC telemetry, PX4 order
    accel_frd_m_s2: Stream | None = None
    vel_ned_m_s: Stream | None = None
    pos_ned_m: Stream | None = None
    motor_names: tuple[str, str, str, str] = ("1", "2", "3", "4")
    vehicle_type: str = ""  # the log's MAV_TYPE name ("MAV_TYPE_QUADROTOR", ...); "" when it does not say
    extra_streams: dict[str, Stream] = field(default_factory=dict)  # reader-specific, held into FlightTable.extras
    min_height_m: float = DEFAULT_MIN_HEIGHT_M
    # "norm" commands: the PWM (min, max) µs each motor's 0..1 spans, from the log's parameters; None: not known.
    norm_range_us: tuple[tuple[float, float], ...] | None = None
    lift_cmd: float | None = None  # the log's own lift level (its autopilot's parameters); None: LIFT_CMD[cmd_unit]
    warnings: list[str] = field(default_factory=list)


def _check_required(raw: RawFlight) -> None:
    for name in ("motor_cmd", "attitude_rad", "rates_rad_s"):
        if len(getattr(raw, name)) == 0:
            raise LogFormatError(f"{raw.source}: no {name} samples: the log lacks the messages that carry them")


def rate_warnings(raw: RawFlight, rate_hz: float) -> list[str]:
    """Streams logged slower than the model's grid are held between samples: say so."""
    out = []
    for name in ("motor_cmd", "attitude_rad", "rates_rad_s"):
        r = getattr(raw, name).rate_hz()
        if 0 < r < 0.9 * rate_hz:
            out.append(f"{name} logged at {r:.1f} Hz, below the model's {rate_hz:g} Hz: values are held between samples")
    return out


def airborne_mask(raw: RawFlight, grid: np.ndarray, motor_cmd: np.ndarray, rate_hz: float) -> np.ndarray:
    """Armed, rotors above lift throttle, off the ground (height / land detector when logged)."""
    lift = raw.lift_cmd if raw.lift_cmd is not None else LIFT_CMD[raw.cmd_unit]
    # The mean, not each rotor: in hard manoeuvres one rotor can drop to idle while flying.
    # A row with any unknown motor is not counted as airborne (NaN compares False), unless it lies in a short dip.
    mask = _fill_short_gaps(np.mean(motor_cmd, axis=1) > lift, int(round(MAX_THROTTLE_DIP_S * rate_hz)))
    if raw.armed is not None and len(raw.armed):
        mask &= _hold_flag(raw.armed, grid) == 1.0
    if raw.landed is not None and len(raw.landed):
        mask &= _hold_flag(raw.landed, grid) == 0.0
    if raw.height_m is not None and len(raw.height_m) and not (raw.landed is not None and len(raw.landed)):
        # Height only where the autopilot's own land detector is not logged: it knows better.
        h = hold(raw.height_m.t_us, raw.height_m.values, grid, MAX_AGE_US)
        mask &= h > raw.min_height_m
    return _drop_short(mask, int(round(MIN_SEGMENT_S * rate_hz)))


def _hold_flag(s: Stream, grid: np.ndarray) -> np.ndarray:
    return hold(s.t_us, s.values, grid, s.max_age_us or STATE_MAX_AGE_US)


def _fill_short_gaps(mask: np.ndarray, max_len: int) -> np.ndarray:
    """``mask`` with its false runs of at most ``max_len`` steps between two true runs set true."""
    out = mask.copy()
    runs = true_runs(mask)
    for (_, e), (s, _) in zip(runs[:-1], runs[1:], strict=True):
        if s - e <= max_len:
            out[e:s] = True
    return out


def _drop_short(mask: np.ndarray, min_len: int) -> np.ndarray:
    out = mask.copy()
    for s, e in true_runs(mask):
        if e - s < min_len:
            out[s:e] = False
    return out


def _plausible_context(s: Stream | None, kind: str, warnings: list, source: str) -> Stream | None:
    """The context stream with its implausible samples (``monitor.decision.envelope``, the daemon's checks) set to NaN:
    never evidence, a step without context. A warning counts them."""
    if s is None or len(s) == 0:
        return None
    bad, why = implausible_context(s.t_us, s.values, kind)
    if not bad.any():
        return s
    values = np.array(s.values, dtype=np.float64)
    values[bad] = np.nan
    what = ", ".join(f"{k}: {n}" for k, n in why.items())
    warnings.append(f"{source}: {int(bad.sum())} {kind} samples ignored as implausible ({what})")
    return Stream(s.t_us, values, s.max_age_us)


def esc_command(raw: RawFlight, cmd: np.ndarray) -> tuple[str, np.ndarray]:
    """(unit, (T, 4) commands) as the ESCs received them: PX4's normalised ``norm`` commands become the PWM µs
    their output range (``raw.norm_range_us``) makes of them; every other unit is the ESCs' own."""
    if raw.cmd_unit != "norm" or raw.norm_range_us is None:
        return raw.cmd_unit, cmd
    lo, hi = (np.array([r[i] for r in raw.norm_range_us]) for i in (0, 1))
    return "us", lo + cmd * (hi - lo)


def to_flight_table(raw: RawFlight, esc: EscCurve | None = None, rate_hz: float = 20.0) -> FlightTable:
    """Resample a decoded log onto the ``rate_hz`` boot-clock grid (zero-order hold, NaN when stale).

    ``motor_rpm`` comes from ``esc`` (the vehicle's ESC fit) when its command
    unit matches that of the commands the ESCs received (``esc_command``);
    otherwise it is NaN and a warning says why. ``motor_cmd`` keeps the log's unit.
    """
    _check_required(raw)
    period_us(rate_hz)  # raises on a rate that does not give whole µs
    t0 = int(min(raw.motor_cmd.t_us[0], raw.attitude_rad.t_us[0], raw.rates_rad_s.t_us[0]))
    t1 = int(max(raw.motor_cmd.t_us[-1], raw.attitude_rad.t_us[-1], raw.rates_rad_s.t_us[-1]))
    grid = grid_us(t0, t1, rate_hz)
    if len(grid) == 0:
        raise LogFormatError(f"{raw.source}: the log spans less than one {rate_hz:g} Hz grid step")

    def held(s: Stream | None, width: int | None, max_age_us: int = MAX_AGE_US):
        if s is None or len(s) == 0:
            shape = (len(grid),) if width is None else (len(grid), width)
            return np.full(shape, np.nan)
        return hold(s.t_us, s.values, grid, s.max_age_us or max_age_us)

    warnings = list(raw.warnings) + rate_warnings(raw, rate_hz)
    cmd = held(raw.motor_cmd, 4)
    att = held(raw.attitude_rad, 3)
    rates = held(raw.rates_rad_s, 3)
    esc_unit, esc_cmd = esc_command(raw, cmd)
    if esc is not None and esc.cmd_unit == esc_unit:
        rpm = np.where(np.isfinite(esc_cmd), esc.cmd_to_rpm(np.nan_to_num(esc_cmd)), np.nan)
    else:
        rpm = np.full_like(cmd, np.nan)
        why = "no ESC curve given" if esc is None else f"the ESC curve takes '{esc.cmd_unit}' commands"
        warnings.append(f"motor commands are in '{esc_unit}' but {why}: motor RPM unknown")
    extras: dict = {
        "motor_cmd_unit": raw.cmd_unit,
        "esc_cmd_unit": esc_unit,
        "stream_rates_hz": {n: getattr(raw, n).rate_hz() for n in ("motor_cmd", "attitude_rad", "rates_rad_s")},
    }
    if raw.vehicle_type:
        extras["vehicle_type"] = raw.vehicle_type
    if raw.esc_rpm is not None and len(raw.esc_rpm):
        extras["esc_rpm"] = held(raw.esc_rpm, 4)
    if raw.height_m is not None and len(raw.height_m) and not (raw.landed is not None and len(raw.landed)):
        # Height only where the autopilot's own land detector is not logged: it knows better.
        extras["height_m"] = held(raw.height_m, None)
    for name, stream in raw.extra_streams.items():
        extras[name] = held(stream, None if stream.values.ndim == 1 else stream.values.shape[1])
    vel = _plausible_context(raw.vel_ned_m_s, "velocity", warnings, raw.source)
    opt = {"vel_ned_m_s": held(vel, 3) if vel is not None else None}
    opt["pos_ned_m"] = held(raw.pos_ned_m, 3) if raw.pos_ned_m is not None and len(raw.pos_ned_m) else None
    acc = _plausible_context(raw.accel_frd_m_s2, "imu", warnings, raw.source)
    # each step's mean of the samples in its own period, as the daemon's (span_mean)
    opt["accel_frd_m_s2"] = (
        span_mean(acc.t_us, acc.values, grid, period_us(rate_hz), acc.max_age_us or MAX_AGE_US)
        if acc is not None and len(acc)
        else None
    )
    return FlightTable(
        timestamp_us=grid,
        motor_cmd=cmd,
        motor_rpm=rpm,
        roll_rad=att[:, 0],
        pitch_rad=att[:, 1],
        yaw_rad=att[:, 2],
        roll_rate_rad_s=rates[:, 0],
        pitch_rate_rad_s=rates[:, 1],
        yaw_rate_rad_s=rates[:, 2],
        battery_v=held(raw.battery_v, None, BATTERY_MAX_AGE_US),
        airborne=airborne_mask(raw, grid, cmd, rate_hz),
        rate_hz=float(rate_hz),
        source=raw.source,
        motor_names=raw.motor_names,
        warnings=tuple(warnings),
        extras=extras,
        **opt,
    )
