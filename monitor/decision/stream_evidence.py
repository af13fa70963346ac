"""Evidence streams beside the motor commands: VIBRATION (imbalance) and ESC_STATUS rpm, validated.

Part of the decision rule (``monitor.decision``). NaN, negative, absurd or frozen readings are rejected and
counted, never evidence.
"""

from __future__ import annotations

import math

import numpy as np

# The next three are chosen, not measured: sanity guards, and no simulator here produces VIBRATION.
VIBE_MAX_M_S2 = 100.0  # a vibration metric beyond this is a sensor fault, not a propeller
FROZEN_REPEATS = 20  # identical float readings in a row: a stuck stream
VIBE_BASELINE_S = 10.0  # airborne seconds that define the flight's own vibration level
# CUSUM reference: the smallest rise over the flight's own baseline worth calling (log-ratio drift). Not measured:
# no simulator here produces VIBRATION, so it is chosen by hand (a 50 % rise of PX4's accelerometer vibration
# metric), as the statistic's analytic threshold is (monitor/decision/rule.py).
VIBE_MIN_RATIO = 1.5


class VibrationEvidence:
    """VIBRATION samples -> validated log-ratio to the flight's baseline; bad values counted, never used."""

    def __init__(self):
        self.rejected = {"nan": 0, "negative": 0, "absurd": 0, "frozen": 0}
        self.accepted = 0
        self._last: tuple | None = None
        self._repeats = 0
        self._baseline: list[float] = []
        self._baseline_t0: float | None = None
        self.baseline: float | None = None
        self.last_t_s: float | None = None

    def reset(self) -> None:
        self._baseline, self._baseline_t0, self.baseline = [], None, None

    def validate(self, values: tuple[float, ...]) -> str:
        """'' when usable, else the reason it is rejected (and counted)."""
        if not all(math.isfinite(v) for v in values):
            why = "nan"
        elif any(v < 0 for v in values):
            why = "negative"
        elif any(v > VIBE_MAX_M_S2 for v in values):
            why = "absurd"
        else:
            key = tuple(values)
            self._repeats = self._repeats + 1 if key == self._last else 1
            self._last = key
            why = "frozen" if self._repeats >= FROZEN_REPEATS else ""
        if why:
            self.rejected[why] += 1
        return why

    def observe(self, t_s: float, accel_metric: float, airborne: bool) -> float | None:
        """The log-ratio of the accel vibration metric to its baseline, or None (no baseline yet)."""
        self.accepted += 1
        self.last_t_s = t_s
        if not airborne:
            return None
        if self.baseline is None:
            if self._baseline_t0 is None:
                self._baseline_t0 = t_s
            self._baseline.append(accel_metric)
            if t_s - self._baseline_t0 >= VIBE_BASELINE_S:
                self.baseline = max(float(np.median(self._baseline)), 1e-6)
            return None
        return math.log(max(accel_metric, 1e-9) / self.baseline)


class EscTelemetry:
    """ESC_STATUS rpm validated like VIBRATION: NaN, negative, absurd or frozen readings are counted, never used."""

    MAX_RPM = 100_000.0

    def __init__(self):
        self.rejected = {"nan": 0, "negative": 0, "absurd": 0, "frozen": 0}
        self.accepted = 0
        self._last: tuple | None = None
        self._repeats = 0

    def observe(self, rpm: tuple[float, ...]) -> str:
        """'' when usable, else why not."""
        vals = tuple(float(r) for r in rpm)
        if not all(math.isfinite(v) for v in vals):
            why = "nan"
        elif any(v < 0 for v in vals):
            why = "negative"
        elif any(v > self.MAX_RPM for v in vals):
            why = "absurd"
        else:
            self._repeats = self._repeats + 1 if vals == self._last and any(vals) else 1
            self._last = vals
            why = "frozen" if self._repeats >= FROZEN_REPEATS else ""
        if why:
            self.rejected[why] += 1
        else:
            self.accepted += 1
        return why
