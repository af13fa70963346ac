"""A vehicle's normal from its healthy flights' summaries: share intercepts, tilt slopes, flight-to-flight spread.

Model, per rotor k: share_k(t) = c_k + slopes[:, k] . (roll_rad, pitch_rad). The slopes are one pooled
within-flight regression over every flight (each flight its own intercept), ridged toward zero by
``TILT_RIDGE_RAD2`` per step (tilt that barely varies says nothing about a slope). A flight's intercept is its mean
share minus its mean tilt times the slopes; the normal is the mean of its flights' intercepts and their spread the
covariance, pooled with the population's prior (``thresholds.PRIOR_COV`` weighing ``PRIOR_FLIGHTS``). With omega^2
shares, the normal also keeps the range of its flights' mean collectives (mean omega^2, proportional to the thrust
the vehicle carried): the load its shares were learnt at (``monitor.memory.load``).
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
    # (lowest, highest) mean collective of its flights (kRPM^2); None where the shares are raw commands or unknown
    collective_range: tuple[float, float] | None = None

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


@dataclass(frozen=True)
class FlightStack:
    """The per-flight terms of a normal, stacked once (``of``): the normal of any subset of the flights (``normal``,
    leave-one-out in ``monitor.memory.learn.outliers``) is then one vectorised pass, not a loop over summaries."""

    n: np.ndarray  # (k,) accepted steps
    w: np.ndarray  # (k, 2, 2) within-flight tilt scatter
    v: np.ndarray  # (k, 2, 4) within-flight tilt-by-share scatter
    mean_share: np.ndarray  # (k, 4)
    mean_tilt: np.ndarray  # (k, 2) mean (roll, pitch)
    within: np.ndarray  # (k, 4, 4) 2-s block means' covariance (zeros where fewer than 3 blocks)
    has_within: np.ndarray  # (k,) bool
    collective: np.ndarray | None  # (k,) mean collective (kRPM^2); None unless every flight's basis is omega2

    @classmethod
    def of(cls, summaries: list[FlightSummary]) -> FlightStack:
        k = len(summaries)
        n = np.array([s.n for s in summaries], dtype=np.float64)
        ftf = np.array([s.ftf for s in summaries]).reshape(k, 3, 3)
        fts = np.array([s.fts for s in summaries]).reshape(k, 3, 4)
        nn = np.maximum(n, 1.0)[:, None, None]
        w = ftf[:, 1:, 1:] - ftf[:, 0, 1:, None] * ftf[:, 0, None, 1:] / nn
        v = fts[:, 1:] - ftf[:, 0, 1:, None] * fts[:, 0, None, :] / nn
        covs = [s.within_cov() for s in summaries]
        within = np.array([np.zeros((4, 4)) if c is None else c for c in covs]).reshape(k, 4, 4)
        return cls(
            n,
            w,
            v,
            np.array([s.mean_share() for s in summaries]).reshape(k, 4),
            np.array([s.mean_regime()[1:] for s in summaries]).reshape(k, 2),
            within,
            np.array([c is not None for c in covs], dtype=bool),
            np.array([s.mean_collective() for s in summaries], dtype=np.float64).reshape(k)
            if summaries and all(s.basis == "omega2" for s in summaries)
            else None,
        )

    def normal(self, keep: np.ndarray | None = None, prior_cov=None) -> Normal:
        """The normal of the flights ``keep`` (a (k,) mask; default all) that have accepted steps; ``prior_cov`` the
        flight-to-flight prior (default ``thresholds.PRIOR_COV``, our simulator's)."""
        keep = (self.n > 0) if keep is None else (np.asarray(keep, dtype=bool) & (self.n > 0))
        if not keep.any():
            raise ValueError("normal_of: no flight with airborne steps")
        slopes = np.linalg.solve(
            self.w[keep].sum(axis=0) + TILT_RIDGE_RAD2 * self.n[keep].sum() * np.eye(2), self.v[keep].sum(axis=0)
        )
        c = self.mean_share[keep] - self.mean_tilt[keep] @ slopes
        m = len(c)
        own = np.cov(c.T, ddof=1) if m > 1 else np.zeros((4, 4))
        prior = np.asarray(th.PRIOR_COV if prior_cov is None else prior_cov, dtype=np.float64)
        cov = (th.PRIOR_FLIGHTS * prior + (m - 1) * own) / (th.PRIOR_FLIGHTS + m - 1)
        wk = keep & self.has_within
        wcov = self.within[wk].mean(axis=0) if wk.any() else np.zeros((4, 4))
        load = None if self.collective is None else self.collective[keep]
        load_range = None if load is None else (float(load.min()), float(load.max()))
        return Normal(c.mean(axis=0), slopes, cov, own, wcov, m, load_range)


def slopes_of(summaries: list[FlightSummary]) -> np.ndarray:
    return FlightStack.of(summaries).normal().slopes


def normal_of(summaries: list[FlightSummary], prior_cov=None) -> Normal:
    """The normal of ``summaries`` (at least one flight with accepted steps)."""
    return FlightStack.of(summaries).normal(prior_cov=prior_cov)
