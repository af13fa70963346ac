"""Regime changes for the decision rule: landing, take-off, aggressive manoeuvres, payload steps, battery sag.

Part of the decision rule (``monitor.decision``): ``RegimeTracker`` reads each grid step's flight state
(``StepInputs``) and says when windows must be held and evidence discounted.
"""

from __future__ import annotations

import bisect
import math
import statistics
from collections import deque
from dataclasses import dataclass

import numpy as np

from monitor.decision.config import DecisionConfig

# A collective step compares the median mean RPM of two such spans (manoeuvres average out). Chosen, not measured;
# alerts.collective_step_fraction was measured at this span.
COLLECTIVE_MEDIAN_S = 10.0
# The step rule above sees a payload step only once the last 10 s are mostly after it: 5-7 s late. A payload picked
# up off-centre moves the trims at once: on flight healthy-r601-227 of our simulator's randomised healthy set
# (`python -m bench.alerts_flights --set ours-healthy --seed 601 --flights 228`) a 38 % payload made the omega^2
# shares call rotor 3 FAULT 4.8 s after the pick-up, 1.7 s before the step rule fired. So while the
# median mean RPM of the last COLLECTIVE_SHIFT_S differs from that of the COLLECTIVE_MEDIAN_S before it by more than
# alerts.collective_step_fraction, windows are held (nothing is discounted: a climb does it too, and comes back);
# a step that lasts is then caught by the step rule, which re-learns. On 120 healthy flights of ours without a
# payload (`python -m bench.alerts_flights --set ours-healthy --seed 100 --flights 120 --pickup-fraction 0`, counting
# RegimeTracker.shift_steps) that holds 1.5 % of the airborne time (48 flights, a hard climb or descent); it starts
# 0.25-2.5 s after pick-ups and drops of 15-40 % of the mass (one of 11 % after 13.8 s, 10 % not at all); single
# and pair onsets (a propeller's loss raises the collective RPM by ~1-2 %) are held 2.6 % of their time after it.
COLLECTIVE_SHIFT_S = 2.0


@dataclass(frozen=True)
class StepInputs:
    """One grid step's flight state, for the regime tracker (NaN where unknown)."""

    airborne: bool
    mean_rpm: float = math.nan
    tilt_rad: float = math.nan
    rate_rad_s: float = math.nan  # largest |body rate|
    battery_v: float = math.nan
    motor_rpm: np.ndarray | None = None  # (4,) per-rotor RPM, PX4 order (commanded, or ESC telemetry)
    # (2,) horizontal ground velocity in the heading frame (forward, right), m/s; None where the autopilot streams
    # no velocity. The omega^2 shares' baseline follows it (blade flapping trims the rotors with airspeed).
    vel_heading_m_s: np.ndarray | None = None
    # (2,) horizontal specific force in the body frame (IMU accelerometer x, y; FRD), m/s^2; None where not streamed.
    # Thrust is along body z, so this is the air's drag on the body: a measure of the airspeed, wind included.
    accel_xy_frd_m_s2: np.ndarray | None = None

    @classmethod
    def of_state(
        cls,
        airborne: bool,
        motor_rpm: np.ndarray | None = None,
        tilt_rad: float = math.nan,
        rate_rad_s: float = math.nan,
        battery_v: float = math.nan,
        vel_heading_m_s: np.ndarray | None = None,
        accel_xy_frd_m_s2: np.ndarray | None = None,
    ) -> StepInputs:
        """The one place a step's inputs are made, live (the daemon's pipeline) and replayed (``monitor.decision
        .replay``): the mean RPM as sum / size, np.mean bit for bit without its wrapper."""
        mean = math.nan if motor_rpm is None else float(motor_rpm.sum() / motor_rpm.size)
        return cls(
            bool(airborne),
            mean,
            float(tilt_rad),
            float(rate_rad_s),
            float(battery_v),
            motor_rpm,
            vel_heading_m_s=vel_heading_m_s,
            accel_xy_frd_m_s2=accel_xy_frd_m_s2,
        )


def heading_velocity(vel_ned_m_s, yaw_rad) -> np.ndarray | None:
    """(T, 2) (or (2,)) horizontal velocity in the heading frame (forward, right) from NED velocity and yaw (rad);
    None without either. NED/FRD: forward = north cos(yaw) + east sin(yaw), right = -north sin(yaw) + east cos(yaw)."""
    if vel_ned_m_s is None or yaw_rad is None:
        return None
    v = np.asarray(vel_ned_m_s, dtype=np.float64)
    yaw = np.asarray(yaw_rad, dtype=np.float64)
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1]], axis=-1)


class RegimeTracker:
    """Per-step state -> (hold the next windows, discount what was gathered), see the module doc."""

    def __init__(self, cfg: DecisionConfig, rate_hz: float, window: int):
        self.cfg = cfg
        self.window = window
        self.rate_hz = rate_hz
        self._median_n = max(int(round(COLLECTIVE_MEDIAN_S * rate_hz)), 1)
        self._shift_n = max(int(round(COLLECTIVE_SHIFT_S * rate_hz)), 1)
        self._rpm: deque[float] = deque(maxlen=2 * self._median_n)  # the last 2 x 10 s of mean RPM (collective step)
        # The same values kept sorted for the shift test, which runs every step: the last COLLECTIVE_SHIFT_S and
        # the COLLECTIVE_MEDIAN_S before them (``_collective_shifted``), updated as values enter and leave.
        self._new_sorted: list[float] = []
        self._old_sorted: list[float] = []
        self._volts: deque[float] = deque(maxlen=window)
        self._n = 0
        self.hold_until_step = 0
        self.sag_until_step = 0
        self.step = 0
        self.counts = {"aggressive": 0, "collective_step": 0, "battery_sag": 0, "landed": 0}
        self.shift_steps = 0  # steps held for a collective shift (COLLECTIVE_SHIFT_S) not yet a step
        self.last_reason = ""
        self._tilt_max = math.radians(cfg.aggressive_tilt_deg)
        self._rate_max = math.radians(cfg.aggressive_rate_deg_s)
        self._check_every = max(window // 5, 1)

    def reset(self) -> None:
        self._clear_rpm()
        self._volts.clear()
        self._n = 0
        self.hold_until_step = self.step + self.window  # a window must lie wholly after take-off

    def update(self, s: StepInputs) -> str:
        """'' or the event of this step: 'landed', 'aggressive', 'collective_step', 'battery_sag'."""
        self.step += 1
        if not s.airborne:
            was_flying = self._n > 0
            if was_flying:
                self.counts["landed"] += 1
            self.reset()
            return "landed" if was_flying else ""
        self._n += 1
        if math.isfinite(s.mean_rpm):
            self._push_rpm(s.mean_rpm)
        if math.isfinite(s.battery_v):
            self._volts.append(s.battery_v)
        event = ""
        c = self.cfg
        if s.tilt_rad > self._tilt_max or s.rate_rad_s > self._rate_max:
            event = "aggressive"
        elif len(self._rpm) == 2 * self._median_n and self._n % self._check_every == 0:
            if self._collective_moved(self._median_n):
                event = "collective_step"
                self._clear_rpm()  # measure the next step from the new level
        if not event and len(self._rpm) >= self._median_n + self._shift_n and self._collective_shifted():
            self.hold_until_step = max(self.hold_until_step, self.step + 1)  # this step's window is held
            self.shift_steps += 1
            self.last_reason = "collective_shift"
        if not event and len(self._volts) == self.window:
            v0, v1 = self._volts[0], self._volts[-1]
            if v0 > 0 and (v0 - v1) / v0 > c.battery_sag_fraction:
                event = "battery_sag"
                self._volts.clear()
        if event:
            self.counts[event] += 1
            self.last_reason = event
            if event == "battery_sag":  # the network's inputs moved; the omega^2 shares are ratios (see below)
                self.sag_until_step = self.step + self.window
            else:
                self.hold_until_step = self.step + self.window
        return event

    def _clear_rpm(self) -> None:
        self._rpm.clear()
        self._new_sorted.clear()
        self._old_sorted.clear()

    def _push_rpm(self, rpm: float) -> None:
        """Append to ``_rpm`` and move the sorted spans along: the value ``_shift_n`` back passes from the new span
        to the old, the one ``_median_n`` before that leaves the old."""
        q = self._rpm
        n = len(q) + 1  # values once this one is in (the deque drops its oldest only beyond both spans)
        if n > self._shift_n:
            moved = q[-self._shift_n]
            del self._new_sorted[bisect.bisect_left(self._new_sorted, moved)]
            bisect.insort(self._old_sorted, moved)
        if n > self._shift_n + self._median_n:
            left = q[-(self._shift_n + self._median_n)]
            del self._old_sorted[bisect.bisect_left(self._old_sorted, left)]
        q.append(rpm)
        bisect.insort(self._new_sorted, rpm)

    @staticmethod
    def _sorted_median(x: list[float]) -> float:
        """``statistics.median`` of an already sorted list (the same arithmetic)."""
        n = len(x)
        return x[n // 2] if n % 2 else (x[n // 2 - 1] + x[n // 2]) / 2

    def _collective_shifted(self) -> bool:
        """``_collective_moved(self._shift_n)`` from the spans kept sorted."""
        old, new = self._sorted_median(self._old_sorted), self._sorted_median(self._new_sorted)
        return old > 0 and abs(new - old) / old > self.cfg.collective_step_fraction

    def _collective_moved(self, n_new: int) -> bool:
        """The median mean RPM of the last ``n_new`` steps against that of the COLLECTIVE_MEDIAN_S before them:
        moved by more than alerts.collective_step_fraction?"""
        rpm = list(self._rpm)[-(self._median_n + n_new) :]
        old, new = statistics.median(rpm[: self._median_n]), statistics.median(rpm[self._median_n :])
        return old > 0 and abs(new - old) / old > self.cfg.collective_step_fraction

    @property
    def holding(self) -> bool:
        """No evidence at all: take-off, an aggressive manoeuvre, a collective step."""
        return self.step < self.hold_until_step

    @property
    def network_holding(self) -> bool:
        """No network evidence: ``holding``, or a battery sag. A sag scales every rotor's speed for its command
        alike, so the omega^2 shares and the yaw balance (ratios) do not see it, while the network's inputs (RPM from
        the ESC curve, at the trained voltage) do. A thrust loss itself draws more current and can sag a weak pack:
        on one of our onsets (rotor 4 losing 13 %) the sag was detected 9 times after the onset. So a sag never
        holds or halves the shares (tests/test_decision_regimes.py,
        test_a_battery_sag_does_not_hide_a_loss_from_the_omega2_shares: a 12 % loss that sags the pack is named
        within 5 s; held and halved it came 5 s later)."""
        return self.holding or self.step < self.sag_until_step
