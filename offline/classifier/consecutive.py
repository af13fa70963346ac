"""The consecutive-window rule: the comparison beside the shipped sequential rule, offline only.

The daemon decides with ``monitor.decision.rule.Decision`` (shared with
``propwatch diagnose``); this rule is replayed over the same window outputs
as a row of ``make evaluate-alerts`` (``offline.alerts.rules.consecutive_rule``)
and in the classifier card's onboard figures (``offline.classifier.onboard``).

Per propeller: P(faulty) >= ``threshold`` in ``consecutive`` classified
windows in a row raises an alert, then that propeller stays quiet for
``refractory_s`` seconds of the flight's own clock. A NaN probability is no
evidence (it breaks the streak).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.labels import N_PROPS


@dataclass(frozen=True)
class ConsecutiveConfig:
    # 0.9 x 20 windows (1 s at 20 Hz): its false alarms and detection are the "P >= 0.9 for 20 windows" row of
    # `make evaluate-alerts` (models/decision-evaluation.md) and "default" in the card's rule sweep (`make classifier`).
    threshold: float = 0.9  # P(propeller faulty) at or above this counts
    consecutive: int = 20  # windows in a row before an alert
    refractory_s: float = 30.0  # per propeller, after each of its alerts

    def __post_init__(self) -> None:
        if not 0.0 < self.threshold <= 1.0:
            raise ValueError(f"threshold: must be in (0, 1], got {self.threshold!r}")
        if not 1 <= self.consecutive <= 100_000:
            raise ValueError(f"consecutive: must be in [1, 100000], got {self.consecutive!r}")
        if not 0.0 <= self.refractory_s <= 86_400.0:
            raise ValueError(f"refractory_s: must be in [0, 86400], got {self.refractory_s!r}")


class ConsecutiveRule:
    """Feed every classified window in order (``update``); ``reset`` where classification stopped (a gap)."""

    def __init__(self, config: ConsecutiveConfig):
        self.config = config
        self._streak = np.zeros(N_PROPS, dtype=np.int64)
        self._quiet_until = np.full(N_PROPS, -np.inf)

    def reset(self) -> None:
        self._streak[:] = 0

    def update(self, t_s: float, fault_probability) -> tuple[int, ...]:
        """The propellers (1..4, PX4 order) this window at ``t_s`` alerts on; () for none."""
        p = np.asarray(fault_probability, dtype=np.float64)
        hot = np.isfinite(p) & (p >= self.config.threshold)
        self._streak = np.where(hot, self._streak + 1, 0)
        firing = (self._streak >= self.config.consecutive) & (t_s >= self._quiet_until)
        self._quiet_until[firing] = t_s + self.config.refractory_s
        return tuple(int(i) + 1 for i in np.flatnonzero(firing))


def replay_consecutive(
    fault_probability: np.ndarray, rate_hz: float, window: int, config: ConsecutiveConfig
) -> list[tuple[float, tuple[int, ...]]]:
    """The rule over one flight's windows (hop 1) -> ``[(t_s, propellers)]``.

    Window k ends at log sample k + window - 1, whose time is (k + window) / rate.
    """
    rule = ConsecutiveRule(config)
    out = []
    for k, p in enumerate(fault_probability):
        t_s = (k + window) / rate_hz
        props = rule.update(t_s, p)
        if props:
            out.append((t_s, props))
    return out
