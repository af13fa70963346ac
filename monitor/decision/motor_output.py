"""A motor that stops or saturates: one output pinned at an end of its range while the others are not.

A propeller that loses thrust asks its motor for a little more; a motor or ESC that fails does something no
propeller does: its output sits at the bottom of the range (a stopped motor, an ESC that dropped out, an output
forced off) or at the top (the controller asking a dead or weak motor for all it has), while the other three fly
in the middle. That is named as a motor or ESC failure, never as a propeller.

Per grid step, each rotor's output as a fraction of the command range, ``u = (rpm - rpm_min) / (rpm_max - rpm_min)``
(the commanded RPM of the range's ends, from the ESC curve), is **pinned low** at ``u <= PINNED_LOW_U`` while the
other three's median is at least ``OTHERS_LOW_U``, and **pinned high** at ``u >= PINNED_HIGH_U`` while their
median is at most ``OTHERS_HIGH_U``. A rotor pinned for ``PINNED_S`` of airborne steps in a row is named once per
flight. Chosen, not fitted: a healthy flight's outputs meet an end only for a fraction of a second in a hard
manoeuvre, and the alarm must come within 1 s. Checked, never tuned, on the evaluation-only simulator's healthy
(hard manoeuvres included) and stopped-motor flights of other airframes: `python -m bench.strangers --set
strangers_healthy` and `--set strangers_stopped` (figures in docs/PHYSICS_FIRST.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PINNED_LOW_U = 0.05
PINNED_HIGH_U = 0.97
OTHERS_LOW_U = 0.2  # the others hold the vehicle up: well above idle
OTHERS_HIGH_U = 0.85  # the others are not all at full output (a climb at full power saturates every motor alike)
PINNED_S = 0.6  # seconds pinned before it is named (with a 20 Hz grid: 12 steps)


@dataclass(frozen=True)
class MotorOutputAlarm:
    t_s: float  # the step at which it was named
    since_s: float  # the first pinned step
    rotor: int  # PX4 number
    kind: str  # "stopped" | "saturated"

    @property
    def text(self) -> str:
        """STATUSTEXT (<= 50 characters)."""
        return f"MOTOR {self.rotor} {'STOPPED' if self.kind == 'stopped' else 'SATURATED'}"

    def announcement(self):
        """The rule's ``Announcement`` of it: a FAULT naming the motor (CRITICAL: the vehicle may not hold), or a
        WARNING for a saturated one (a corner at its limit)."""
        from monitor.decision.rule import MAV_SEVERITY_CRITICAL, MAV_SEVERITY_WARNING, Announcement

        sev = MAV_SEVERITY_CRITICAL if self.kind == "stopped" else MAV_SEVERITY_WARNING
        return Announcement(self.t_s, "fault", (self.rotor,), self.text, sev, (), "motor output", (), ((self.rotor,),))

    def to_json(self) -> dict:
        return {"t_boot_s": round(self.t_s, 2), "since_boot_s": round(self.since_s, 2), "rotor": self.rotor, "kind": self.kind}


class MotorOutputWatch:
    """Step by step (the daemon) or over a table (``scan``): the same rule."""

    def __init__(self, rate_hz: float, rpm_min: float, rpm_max: float) -> None:
        if not rpm_max > rpm_min:
            raise ValueError(f"motor output range: rpm_max {rpm_max} must exceed rpm_min {rpm_min}")
        self.rpm_min, self.rpm_span = float(rpm_min), float(rpm_max - rpm_min)
        self.need = max(int(round(PINNED_S * rate_hz)), 1)
        self.reset()

    def reset(self) -> None:
        """A new flight: nothing pinned, nothing named."""
        self._run = np.zeros(4, dtype=np.int64)
        self._kind = [""] * 4
        self._since = np.zeros(4)
        self.named: list[MotorOutputAlarm] = []

    def step(self, t_s: float, rpm: np.ndarray, airborne: bool) -> MotorOutputAlarm | None:
        if not airborne:
            if self._run.any() or self.named:
                self.reset()
            return None
        u = (np.asarray(rpm, dtype=np.float64) - self.rpm_min) / self.rpm_span
        if not np.all(np.isfinite(u)):
            self._run[:] = 0
            return None
        out = None
        for k in range(4):
            kind = pinned(u, k)
            if kind and kind == self._kind[k]:
                self._run[k] += 1
            else:
                self._run[k], self._kind[k], self._since[k] = (1, kind, t_s) if kind else (0, "", 0.0)
            if self._run[k] == self.need and not any(a.rotor == k + 1 for a in self.named):
                out = MotorOutputAlarm(float(t_s), float(self._since[k]), k + 1, kind)
                self.named.append(out)
        return out


def watch_for(rate_hz: float, esc, motor_source: str = "command") -> MotorOutputWatch | None:
    """The daemon's watch over commanded RPM (its ends from the ESC curve); None where the motor stream is ESC
    telemetry, which has no fixed range."""
    if esc is None or motor_source == "esc":
        return None
    return MotorOutputWatch(rate_hz, float(esc.cmd_to_rpm(esc.cmd_min)), float(esc.cmd_to_rpm(esc.cmd_max)))


def pinned(u: np.ndarray, k: int) -> str:
    """ "stopped", "saturated" or "" for rotor k (0-based) given the four outputs as fractions of the range."""
    a, b, c = (float(u[j]) for j in range(4) if j != k)
    others = a + b + c - max(a, b, c) - min(a, b, c)  # the median of three, without numpy's per-call cost (every step)
    if u[k] <= PINNED_LOW_U and others >= OTHERS_LOW_U:
        return "stopped"
    if u[k] >= PINNED_HIGH_U and others <= OTHERS_HIGH_U:
        return "saturated"
    return ""


def pinned_kinds(rpm: np.ndarray, rpm_min: float, rpm_max: float) -> np.ndarray:
    """(T, 4) int: 1 pinned low, 2 pinned high, 0 neither (``pinned`` on every row at once; NaN rows 0)."""
    u = (np.asarray(rpm, dtype=np.float64) - rpm_min) / (rpm_max - rpm_min)
    out = np.zeros(u.shape, dtype=np.int8)
    finite = np.all(np.isfinite(u), axis=1)
    for k in range(4):
        others = np.median(np.delete(u, k, axis=1), axis=1)
        with np.errstate(invalid="ignore"):
            low = (u[:, k] <= PINNED_LOW_U) & (others >= OTHERS_LOW_U)
            high = ~low & (u[:, k] >= PINNED_HIGH_U) & (others <= OTHERS_HIGH_U)
        out[:, k] = np.where(finite & low, 1, np.where(finite & high, 2, 0))
    return out


def scan(t_s: np.ndarray, rpm: np.ndarray, airborne: np.ndarray, rate_hz: float, rpm_min: float, rpm_max: float):
    """Every alarm over a whole flight table, as ``MotorOutputWatch.step`` raises them row by row (a test checks
    it), in one pass of array arithmetic."""
    need = max(int(round(PINNED_S * rate_hz)), 1)
    air = np.asarray(airborne, dtype=bool)
    kinds = pinned_kinds(rpm, rpm_min, rpm_max) * air[:, None]
    flight = np.cumsum(np.concatenate([[1], (air[1:] & ~air[:-1]).astype(np.int64)]))  # a new flight at each take-off
    out = []
    for k in range(4):
        col = kinds[:, k].astype(np.int64)
        change = np.flatnonzero(np.diff(np.concatenate([[0], col, [0]])) != 0)
        seen = set()
        for a, b in zip(change[:-1], change[1:]):
            if col[a] == 0 or b - a < need or flight[a] in seen:
                continue
            seen.add(flight[a])
            j = a + need - 1
            out.append(MotorOutputAlarm(float(t_s[j]), float(t_s[a]), k + 1, "stopped" if col[a] == 1 else "saturated"))
    return sorted(out, key=lambda x: (x.t_s, x.rotor))
