"""Each rotor's share of omega^2 against the flight's own baseline: the decision rule's physics evidence.

Part of the decision rule (``monitor.decision``): ``RotorShare`` gives the ``physics`` statistic's per-rotor
log-likelihood ratios and the ``pair`` statistic's yaw balance (docs/ALERTS.md), with the noise model and the
constants they were measured with. Needs no network and no fault model.
"""

from __future__ import annotations

import math

import numpy as np

from monitor.labels import N_PROPS

LLR_CLIP = math.log(0.999 / 0.001)  # |logit P| beyond P = 0.999 is the network's over-confidence, not evidence
BASELINE_S = 10.0  # classified seconds that define the airframe's own baseline evidence
# The pair statistic's vector is (CCW up, CCW up, CW up, CW up): index i holds the evidence for i's same-spin pair.
SAME_SPIN_PAIRS = ((1, 2), (3, 4))  # PX4 quad-X: 1, 2 CCW (diagonal), 3, 4 CW (diagonal)


def _clip_llr(llr: np.ndarray) -> np.ndarray:
    """np.clip(llr, -LLR_CLIP, LLR_CLIP), NaN kept, without np.clip's Python-level wrappers (every window)."""
    return np.minimum(np.maximum(llr, -LLR_CLIP), LLR_CLIP)


# Projection that removes the collective (1,1,1,1)/2 and yaw (1,1,-1,-1)/2 directions (PX4 order: 1, 2 CCW; 3, 4 CW).
_C, _Y = np.full(4, 0.5), np.array([0.5, 0.5, -0.5, -0.5])
_YAW_FREE = np.eye(4) - np.outer(_C, _C) - np.outer(_Y, _Y)


# -- physics: each rotor's share of omega^2 ---------------------------------------------------------
# The healthy spread of the yaw-free share (mean over SHARE_AVERAGE_S) around the flight's own first 10 s, on
# 4.7 h of randomised healthy flights of our simulator (register physics, drawn airframes, payload steps;
# `bench/alerts_flights.py --share-spread`): rms 0.006, 99 % within 0.020, 99.9 % within 0.032 (manoeuvres,
# gusts, motor lag). The Gaussian noise model takes the tail's scale, so a manoeuvre's excursion is not read as
# decisive evidence; the calibrated thresholds absorb what the model gets wrong.
SHARE_SIGMA = 0.01
SHARE_BASELINE_TAU_S = 60.0  # slow drifts (battery sag, motor warm-up) enter the baseline over a minute
# Seconds of shares averaged per sample. Shorter reacts sooner to an onset (the mean ramps over this time) but is
# noisier; chosen on our simulator (calibration flights seed 100, onset flights seed 400: 5 s gave a median
# latency of 7.7 s at >= 8 % loss, 2 s 4.2 s with the fault threshold 1.5x the highest healthy value, 1 s 3.8 s
# at only 1.1x), never on the evaluation-only simulator.
SHARE_AVERAGE_S = 2.0
# The pair statistic: a same-spin diagonal pair (1+2 CCW or 3+4 CW) that loses thrust f on both rotors keeps roll
# and pitch balanced (T1 = T2, T3 = T4 still hold), so the yaw-free shares do not move. What moves is the yaw
# balance: the damaged pair's drag torque per omega^2 changes by g = 1 - (1 - f)(1 + c), c the unmeasured change
# of torque per unit thrust, and the controller re-trims yaw: y = (s1 + s2 - s3 - s4) / 2 moves by +g for 1+2
# and -g for 3+4. With c = 0 (torque scales with thrust) g = f, so the CUSUM reference is half of
# alerts.min_thrust_loss; the sign of c is unknown (issue 12), so a shift names both pairs ("1+2 or 3+4?"), the
# one it fits with c = 0 first. YAW_SIGMA: the healthy spread of y (mean over SHARE_AVERAGE_S) around the flight's
# own first 10 s on the 4.7 calibration hours of our simulator (bench/alerts_flights.py --share-spread, seed 100):
# over 2 s, rms 0.052 (99 % within 0.11: yaw manoeuvres re-trim it within seconds), over 10 s rms 0.017 (99 % within
# 0.044). So the yaw balance is averaged over YAW_AVERAGE_S = 10 s (pairs have no latency target; singles keep
# their 2 s), and YAW_SIGMA takes the tail's scale (99 % / 2) as SHARE_SIGMA does; the calibrated thresholds absorb
# what the Gaussian model gets wrong.
YAW_AVERAGE_S = 10.0
YAW_SIGMA = 0.022
# What a yaw-balance alert names. A single rotor i losing thrust f with a torque-per-thrust change c moves the yaw
# balance by (f - c) / 2 and its yaw-free share by +f/2 (its same-spin partner's by -f/2); a same-spin pair moves
# y by f - c and the yaw-free shares not at all (docs/ALERTS.md "The pair statistic"). So a yaw shift alone is
# a same-spin pair, or a small single with a large torque change, and the single is the rotor whose yaw-free share
# rose most over the same YAW_AVERAGE_S: it is always one of the alert's hypotheses, first when its rise exceeds
# what healthy flights reach. YAW_FREE_RISE: the 99 % quantile of the largest rotor's rise (10-s mean against the
# flight's first 10 s) on 96 randomised healthy flights of our simulator, the calibration seed
# (`bench/alerts_flights.py --seed 100 --flights 96 --share-spread`: 0.0116; 99.9 %: 0.0159).
YAW_FREE_RISE = 0.012


class RotorShare:
    """Window-mean share of omega^2 per rotor against the flight's own baseline: thrust-loss evidence.

    A rotor that lost a fraction f of its thrust must spin faster for the
    controller to hold roll and pitch: its omega^2 rises by ~f. The yaw
    balance moves the shares too, along (+1, +1, -1, -1) (CCW against CW
    rotors), by an amount that depends on how the damaged blade's torque per
    thrust changed, which nobody has measured (issue 12): that direction and
    the collective one are projected out (``_YAW_FREE``). What is left of a
    thrust loss on rotor i is +f/2 on i and -f/2 on its same-spin diagonal
    partner, whatever the torque change. The share needs no fault model and
    no training; against the airframe's own baseline it is blind to CG
    offsets and motor spread (issue 12's baseline names 24 of 24 that way).

    Baseline: the mean over the first ``BASELINE_S`` of evidence windows (held ones do not count), then an
    exponential average (time constant ``SHARE_BASELINE_TAU_S``) fed only while
    no evidence is gathering (``quiet``), so slow drifts (battery sag) are
    absorbed and a step is not.

    Per window: the Gaussian mean-shift log-likelihood ratio of the mean share over the last ``average_s``
    ``delta (x - b - delta/2) / sigma^2`` with ``delta = f_min / 2`` (the
    smallest thrust loss worth an alert, ``alerts.min_thrust_loss``: the CUSUM
    reference is half of it) and ``sigma = SHARE_SIGMA``, the healthy spread.
    Windows that overlap by all but one step are not independent: the caller
    weighs each by ``dt / average_s`` (one independent sample per averaging span).
    """

    def __init__(
        self, window: int, rate_hz: float, min_thrust_loss: float, sigma: float = SHARE_SIGMA, average_s: float | None = None
    ):
        self.window = window if average_s is None else max(int(round(average_s * rate_hz)), 1)  # steps averaged
        self.average_s = self.window / rate_hz
        self.rate_hz = rate_hz
        self.delta = 0.5 * min_thrust_loss
        self.sigma = sigma
        self._ring = np.full((self.window, N_PROPS), np.nan)
        self._i = 0
        self._n = 0
        self._base: list[np.ndarray] = []
        self._base_s = 0.0  # seconds of evidence windows the baseline has seen (held windows are not evidence)
        self.baseline: np.ndarray | None = None
        # The yaw balance (pair statistic): y = (s1 + s2 - s3 - s4) / 2, mean over YAW_AVERAGE_S, against its baseline.
        self.yaw_delta = min_thrust_loss
        self.yaw_sigma = YAW_SIGMA
        self.yaw_window = max(int(round(YAW_AVERAGE_S * rate_hz)), 1)
        self._yring = np.full(self.yaw_window, np.nan)
        self._sring = np.full((self.yaw_window, N_PROPS), np.nan)  # the shares over YAW_AVERAGE_S (alert wording)
        self._yi = 0
        self._yn = 0
        self.yaw_baseline: float | None = None
        self.yaw_llr = np.zeros(len(SAME_SPIN_PAIRS))  # (CCW pair up, CW pair up) of the last window

    def reset(self) -> None:
        self._ring[:] = np.nan
        self._yring[:] = np.nan
        self._sring[:] = np.nan
        self._n = self._yn = 0
        self._base, self.baseline, self.yaw_baseline = [], None, None
        self._base_s = 0.0

    def push(self, rpm: np.ndarray | None) -> None:
        if rpm is None:
            return
        w2 = np.asarray(rpm, dtype=np.float64) ** 2
        m = w2.sum() / w2.size  # w2.mean() bit for bit, without its wrapper: this runs at every step
        if not (np.isfinite(w2).all() and m > 0):
            self._n = self._yn = 0  # a gap: the window starts again
            return
        share = w2 / m
        self._ring[self._i] = share
        self._i = (self._i + 1) % self.window
        self._n += 1
        s1, s2, s3, s4 = share.tolist()  # Python floats: the same double arithmetic as numpy scalars, cheaper
        self._yring[self._yi] = 0.5 * (s1 + s2 - s3 - s4)
        self._sring[self._yi] = share
        self._yi = (self._yi + 1) % self.yaw_window
        self._yn += 1

    def yaw_free_rise(self) -> np.ndarray | None:
        """(4,) each rotor's yaw-free share over the last YAW_AVERAGE_S less its baseline; None before both exist."""
        if self.baseline is None or self._yn < self.yaw_window:
            return None
        return _YAW_FREE @ (self._sring.sum(axis=0) / self.yaw_window) - self.baseline

    def llr(self, dt_s: float = 0.0, quiet: bool = False, yaw_quiet: bool | None = None) -> np.ndarray | None:
        """Per-rotor evidence of the current window, or None (no full window, or baseline still being learnt).

        ``quiet``: no physics evidence is gathering, so the baseline may follow the window for ``dt_s``
        (``yaw_quiet``: the same for the yaw balance; default ``quiet``). The yaw balance's evidence of the
        same window is left in ``yaw_llr`` (zeros when None is returned).
        """
        self.yaw_llr = np.zeros(len(SAME_SPIN_PAIRS))
        if self._n < self.window:
            return None
        m = self._ring.sum(axis=0) / self.window  # the ring's mean, bit for bit (see push)
        x = _YAW_FREE @ m
        y = float(_Y @ m)  # the baseline's share of the yaw balance: over BASELINE_S like the shares'
        if self.baseline is None:
            self._base.append(np.append(x, y))
            self._base_s += dt_s
            # BASELINE_S of windows that were evidence, not of flight: windows held for a manoeuvre never reach
            # here, and a baseline finalised on the half second after a hold took a transient for the airframe's
            # trim (session 7: a false rotor-2 fault 14 s before an onset, from 10 windows after a 7-s hold).
            if self._base_s >= BASELINE_S and len(self._base) >= 3:
                self.baseline = np.mean(self._base, axis=0)[:N_PROPS]
                # The yaw balance's own mean over the last YAW_AVERAGE_S (its 2-s means scatter by 0.05)
                self.yaw_baseline = float(
                    np.mean(self._yring if self._yn >= self.yaw_window else np.asarray(self._base)[:, N_PROPS])
                )
                self._base = []
            return None
        d = x - self.baseline
        k = min(dt_s / SHARE_BASELINE_TAU_S, 1.0) if dt_s > 0 else 0.0
        if quiet:
            self.baseline = self.baseline + d * k
        if self._yn >= self.yaw_window:
            dy = float(self._yring.sum() / self.yaw_window) - self.yaw_baseline
            if quiet if yaw_quiet is None else yaw_quiet:
                self.yaw_baseline += dy * k
            # Two one-sided tests of the yaw balance: the CCW pair's shares up (+dy) or the CW pair's (-dy).
            yd, ys = self.yaw_delta, self.yaw_sigma
            self.yaw_llr = _clip_llr(np.array([yd * (dy - yd / 2), yd * (-dy - yd / 2)]) / ys**2)
        llr = self.delta * (d - self.delta / 2) / self.sigma**2
        return _clip_llr(llr)
