"""Plausibility before evidence: each signal's physical envelope, checked on every sample.

A sample outside its envelope is never evidence. The pipeline replaces it by
NaN at its time (so the grid instants it would have held are invalid, the
100-step ring empties and no window ever holds it) and counts it here with a
reason; while a stream stays outside, every step says why it is not
classified. Finite but impossible values are the case this exists for: NaN is
already handled by the hold, but 1e30 rad or a PWM of 1 µs clipped into the
ESC curve's range would otherwise look like data.

Envelopes (``PlausibleConfig``): |roll|, |yaw| <= pi and |pitch| <= pi/2
(MAVLink ATTITUDE's ranges); body rates within the gyro range; PWM within
[pwm_min_us, pwm_max_us] or exactly the disarmed value (the ESC curve's own
range when its unit is not µs); ESC rpm in [0, rpm_max]; and no frozen
channel: a fast stream whose values stay bit-identical for ``frozen_s`` of
boot time while armed-looking (motor values at the disarmed command or 0 rpm
are allowed to stand still).

LOCAL_POSITION_NED's velocity is optional context (the omega^2 shares' baseline
follows it), not a signal the classifier needs: a NaN, absurd (|v| beyond
``VELOCITY_MAX_M_S``) or frozen sample is dropped and counted like the others,
but it only makes the step's velocity unknown; it never invalidates a step.
The accelerometer's horizontal specific force (HIGHRES_IMU / SCALED_IMU) is
context the same way: NaN, beyond ``ACCEL_XY_MAX_M_S2`` or frozen is dropped
and counted as ``imu: ...``.
"""

from __future__ import annotations

import math
from collections import Counter

from monitor.daemon.config import PlausibleConfig
from monitor.decision.envelope import ACCEL_XY_MAX_M_S2, VELOCITY_MAX_M_S
from monitor.esc import EscCurve
from monitor.resample import US_PER_S

HALF_PI = math.pi / 2
PITCH_SLACK_RAD = 1e-3  # float32 rounding of +-pi/2


class Plausibility:
    def __init__(self, config: PlausibleConfig, esc: EscCurve, motor_source: str):
        self.cfg = config
        self.motor_is_rpm = motor_source == "esc"
        if esc.cmd_unit == "us":
            self.cmd_range = (config.pwm_min_us, config.pwm_max_us)
            self.cmd_rest = (config.pwm_disarmed_us,)
        else:  # e.g. Crazyflie cf16: the curve's own domain is the envelope
            self.cmd_range = (esc.cmd_min, esc.cmd_max)
            self.cmd_rest = (0.0,)
        self.frozen_us = int(round(config.frozen_s * US_PER_S))
        self.dropped: Counter = Counter()  # "stream: reason" -> samples dropped
        self.last: dict[str, tuple[int, str]] = {}  # stream -> (boot time µs, reason) of its latest drop
        self._same: dict[str, tuple[tuple, int]] = {}  # stream -> (values, first boot time µs with them)

    def reset(self) -> None:
        self._same.clear()
        self.last.clear()

    # -- one sample --------------------------------------------------------------------
    def attitude(self, t_us: int, vals: tuple[float, ...]) -> str | None:
        roll, pitch, yaw, p, q, r = vals
        lim, rlim = self.cfg.attitude_max_rad, self.cfg.rate_max_rad_s
        bad = None
        # abs(x) > limit is True for inf and False for NaN (NaN is 'unknown': the hold makes it a gap).
        if abs(roll) > lim or abs(yaw) > lim or abs(pitch) > HALF_PI + PITCH_SLACK_RAD:
            bad = "attitude outside +-pi"
        elif abs(p) > rlim or abs(q) > rlim or abs(r) > rlim:
            bad = f"rate beyond the gyro range {self.cfg.rate_max_rad_s:g} rad/s"
        if bad is None:  # NaN never equals itself, so a NaN sample never counts as frozen
            bad = self._frozen("attitude", t_us, tuple(vals), rest=False)
        return self._count("attitude", t_us, bad, vals)

    def motor(self, t_us: int, vals) -> str | None:
        vals = tuple(vals.tolist()) if hasattr(vals, "tolist") else tuple(map(float, vals))
        bad = None
        # Comparisons with NaN are False: NaN (unknown) is neither outside the range nor frozen.
        if self.motor_is_rpm:
            if any(v < 0.0 or v > self.cfg.rpm_max for v in vals):
                bad = f"ESC rpm outside [0, {self.cfg.rpm_max:g}]"
            rest = all(v == 0.0 for v in vals)
        else:
            lo, hi = self.cmd_range
            if any((v < lo or v > hi) and v not in self.cmd_rest for v in vals):
                bad = f"motor command outside [{lo:g}, {hi:g}] and not disarmed"
            rest = all(v in self.cmd_rest for v in vals)
        if bad is None:
            bad = self._frozen("motor", t_us, vals, rest)
        return self._count("motor", t_us, bad, vals)

    def velocity(self, t_us: int, vel_ned_m_s: tuple[float, float, float]) -> str | None:
        """Why a LOCAL_POSITION_NED velocity is not usable (counted in ``dropped``), else None. Unlike attitude and
        motor data it never goes into ``last``: an unusable velocity is no reason for a step not to be classified."""
        bad = None
        if not all(math.isfinite(v) for v in vel_ned_m_s):
            bad = "not finite"
        elif math.hypot(*vel_ned_m_s) > VELOCITY_MAX_M_S:
            bad = f"beyond {VELOCITY_MAX_M_S:g} m/s"
        # Exactly zero may stand still (a simulator's vehicle on the ground); as evidence it says "hover", the
        # baseline the shares have without any velocity.
        elif self._frozen("velocity", t_us, tuple(vel_ned_m_s), rest=not any(vel_ned_m_s)) is not None:
            bad = "frozen"
        if bad is not None:
            self.dropped[f"velocity: {bad}"] += 1
        return bad

    def imu(self, t_us: int, accel_frd_m_s2: tuple[float, float, float]) -> str | None:
        """Why an accelerometer sample is not usable as context (counted in ``dropped``), else None; like
        ``velocity`` it never goes into ``last``. Range on x, y (what the decision uses); frozen on all three axes
        (a live sensor's noise moves at least one)."""
        x, y = accel_frd_m_s2[0], accel_frd_m_s2[1]
        bad = None
        if not (math.isfinite(x) and math.isfinite(y)):
            bad = "not finite"
        elif math.hypot(x, y) > ACCEL_XY_MAX_M_S2:
            bad = f"beyond {ACCEL_XY_MAX_M_S2:g} m/s^2"
        elif self._frozen("imu", t_us, tuple(accel_frd_m_s2), rest=False) is not None:
            bad = "frozen"
        if bad is not None:
            self.dropped[f"imu: {bad}"] += 1
        return bad

    def battery(self, t_us: int | None, voltage_v: float) -> bool:
        ok = not math.isfinite(voltage_v) or 0.0 <= voltage_v <= self.cfg.battery_max_v
        if not ok:
            self.dropped["battery: voltage out of range"] += 1
        return ok

    # -- helpers -----------------------------------------------------------------------
    def _frozen(self, stream: str, t_us: int, vals: tuple, rest: bool) -> str | None:
        prev = self._same.get(stream)
        if prev is None or prev[0] != vals or rest or t_us < prev[1]:
            self._same[stream] = (vals, t_us)
            return None
        if t_us - prev[1] >= self.frozen_us:
            return f"{stream} frozen (identical for >= {self.cfg.frozen_s:g} s)"
        return None

    def _count(self, stream: str, t_us: int, bad: str | None, vals) -> str | None:
        if bad is not None:
            self.dropped[f"{stream}: {bad.split(' (')[0]}"] += 1
            self.last[stream] = (t_us, bad)
        return bad
