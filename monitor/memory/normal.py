"""A vehicle's normal from its healthy flights' summaries: share intercepts, tilt slopes, flight-to-flight spread.

Model, per rotor k: share_k(t) = c_k + slopes[:, k] . (roll_rad, pitch_rad). The slopes are one pooled
within-flight regression over every flight (each flight its own intercept), ridged toward zero by
``TILT_RIDGE_RAD2`` per step (tilt that barely varies says nothing about a slope). A flight's intercept is its mean
share minus its mean tilt times the slopes; the normal is the mean of its flights' intercepts and their spread the
covariance, pooled with the population's prior (``thresholds.PRIOR_COV`` weighing ``PRIOR_FLIGHTS``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.memory import thresholds as th
from monitor.memory.summary import FlightSummary

# Ridge of the tilt slopes: (0.01 rad)^2 per step, i.e. tilt that varies by less than about half a degree within the
# flights carries no slope. Chosen, not measured: a floor against a singular regression on hover-only flights.
TILT_RIDGE_RAD2 = 1.0e-4


@dataclass(frozen=True)
class Normal:
    intercept: np.ndarray  # (4,) normal share at zero tilt
    slopes: np.ndarray  # (2, 4) share per rad of (roll, pitch)
    cov: np.ndarray  # (4, 4) flight-to-flight covariance of intercepts (prior pooled with the vehicle's own)
    own_cov: np.ndarray  # (4, 4) the vehicle's own (zeros with one flight)
    within_block_cov: np.ndarray  # (4, 4) 2-s block means' covariance within a flight, pooled
    n_flights: int

    def intercept_of(self, s: FlightSummary) -> np.ndarray:
        return s.mean_share() - s.mean_regime()[1:] @ self.slopes

    def deviation(self, s: FlightSummary) -> np.ndarray:
        """(4,) the flight's intercept minus the normal (shares; sums to ~0)."""
        return self.intercept_of(s) - self.intercept

    def deviation_cov(self, s: FlightSummary) -> np.ndarray:
        """(4, 4) covariance of ``deviation`` for a healthy flight: a new flight against the mean of n (prediction
        interval), plus the wander of a mean over the flight's blocks so far (large in its first seconds)."""
        blocks = max(s.n / (s.rate_hz * 2.0), 1.0)
        return self.cov * (1.0 + 1.0 / self.n_flights) + self.within_block_cov / blocks


def slopes_of(summaries: list[FlightSummary]) -> np.ndarray:
    w = sum(s.ftf[1:, 1:] - np.outer(s.ftf[0, 1:], s.ftf[0, 1:]) / max(s.n, 1) for s in summaries)
    v = sum(s.fts[1:] - np.outer(s.ftf[0, 1:], s.fts[0]) / max(s.n, 1) for s in summaries)
    n = sum(s.n for s in summaries)
    return np.linalg.solve(w + TILT_RIDGE_RAD2 * n * np.eye(2), v)


def normal_of(summaries: list[FlightSummary]) -> Normal:
    """The normal of ``summaries`` (at least one flight with accepted steps)."""
    summaries = [s for s in summaries if s.n > 0]
    if not summaries:
        raise ValueError("normal_of: no flight with airborne steps")
    slopes = slopes_of(summaries)
    c = np.array([s.mean_share() - s.mean_regime()[1:] @ slopes for s in summaries])
    m = len(c)
    own = np.cov(c.T, ddof=1) if m > 1 else np.zeros((4, 4))
    prior = np.asarray(th.PRIOR_COV, dtype=np.float64)
    cov = (th.PRIOR_FLIGHTS * prior + (m - 1) * own) / (th.PRIOR_FLIGHTS + m - 1)
    within = [w for s in summaries if (w := s.within_cov()) is not None]
    wcov = np.mean(within, axis=0) if within else np.zeros((4, 4))
    return Normal(c.mean(axis=0), slopes, cov, own, wcov, m)
