"""One replay: a recorded flight, step by step, through the decision rule exactly as the daemon runs it live.

``FlightSteps`` is the flight state the rule reads (``StepInputs``), one row per grid step: built from a log's
``FlightTable`` (``FlightSteps.of_table``: ``propwatch diagnose`` and ``fleet ingest``) or held by an offline flight
(``offline.alerts.flights.AlertFlight``). ``FlightSteps.inputs`` is where a replay makes each step's ``StepInputs``,
with the daemon's own arithmetic (``StepInputs.of_state``); ``replay`` feeds them and the classified windows to a
``Decision`` and returns its announcements. The daemon's pipeline makes its live steps with the same ``of_state``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

import numpy as np

from monitor.decision.regime import StepInputs, heading_velocity
from monitor.decision.rule import Announcement, Decision, WindowEvidence


@dataclass(frozen=True)
class FlightSteps:
    airborne: np.ndarray  # (T,) bool
    motor_rpm: np.ndarray  # (T, 4) PX4 order (commanded, or ESC telemetry)
    tilt_rad: np.ndarray  # (T,) the larger of |roll| and |pitch|
    rate_rad_s: np.ndarray  # (T,) the largest |body rate|
    battery_v: np.ndarray  # (T,)
    vel_heading_m_s: np.ndarray | None = None  # (T, 2) forward, right; None without velocity
    accel_xy_frd_m_s2: np.ndarray | None = None  # (T, 2) body x, y specific force; None without an IMU stream

    def __len__(self) -> int:
        return len(self.airborne)

    @classmethod
    def of_table(cls, table) -> FlightSteps:
        """A log's steps (``monitor.flight.FlightTable``) with the daemon's arithmetic for each derived value."""
        rpm = np.asarray(table.motor_rpm, dtype=np.float64)
        rates = np.stack([table.roll_rate_rad_s, table.pitch_rate_rad_s, table.yaw_rate_rad_s], axis=1)
        acc = None if table.accel_frd_m_s2 is None else np.asarray(table.accel_frd_m_s2, dtype=np.float64)[:, :2]
        return cls(
            airborne=np.asarray(table.airborne, dtype=bool),
            motor_rpm=rpm,
            tilt_rad=np.maximum(np.abs(table.roll_rad), np.abs(table.pitch_rad)),
            rate_rad_s=np.abs(rates).max(axis=1),
            battery_v=np.asarray(table.battery_v, dtype=np.float64),
            vel_heading_m_s=heading_velocity(table.vel_ned_m_s, table.yaw_rad),
            accel_xy_frd_m_s2=acc,
        )

    def inputs(self, j: int) -> StepInputs:
        """Step ``j`` as the decision reads it."""
        return StepInputs.of_state(
            self.airborne[j],
            self.motor_rpm[j],
            self.tilt_rad[j],
            self.rate_rad_s[j],
            self.battery_v[j],
            None if self.vel_heading_m_s is None else self.vel_heading_m_s[j],
            None if self.accel_xy_frd_m_s2 is None else self.accel_xy_frd_m_s2[j],
        )

    def each(self) -> Iterator[StepInputs]:
        """``inputs(j)`` of every step in order, the same values at half the cost: each column converted to
        Python once, and every row's mean RPM at once as ``of_state``'s sum / size (numpy adds a row's values in the
        same order either way; tests/test_decision_replay_steps.py holds the two equal)."""
        n = len(self)
        rpm = self.motor_rpm
        mean = (rpm.sum(axis=1) / rpm.shape[1]).tolist()
        vel = [None] * n if self.vel_heading_m_s is None else list(self.vel_heading_m_s)
        acc = [None] * n if self.accel_xy_frd_m_s2 is None else list(self.accel_xy_frd_m_s2)
        columns = (
            np.asarray(self.airborne, dtype=bool).tolist(),
            mean,
            np.asarray(self.tilt_rad, dtype=np.float64).tolist(),
            np.asarray(self.rate_rad_s, dtype=np.float64).tolist(),
            np.asarray(self.battery_v, dtype=np.float64).tolist(),
            list(rpm),
            vel,
            acc,
        )
        for airborne, m, tilt, rate, volts, row, v, a in zip(*columns, strict=True):
            yield StepInputs(airborne, m, tilt, rate, volts, row, vel_heading_m_s=v, accel_xy_frd_m_s2=a)


def replay(
    decision: Decision,
    steps: FlightSteps,
    t_s: np.ndarray,
    evidence_at: Mapping[int, WindowEvidence],
    after_window: Callable[[int, float], None] | None = None,
) -> list[Announcement]:
    """Feed every step (its time ``t_s[j]``) and, at the steps in ``evidence_at``, that window's evidence to
    ``decision``; ``after_window(j, t)`` runs after each window (a caller's bookkeeping). The announcements, in order."""
    out: list[Announcement] = []
    times = np.asarray(t_s, dtype=np.float64)[: len(steps)].tolist()
    for j, (t, s) in enumerate(zip(times, steps.each())):
        decision.step(t, s)
        ev = evidence_at.get(j)
        if ev is not None:
            out.extend(decision.window_evidence(t, ev))
            if after_window is not None:
                after_window(j, t)
    return out
