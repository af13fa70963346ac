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
BASELINE_S = 10.0  # classified seconds that define the airframe's own baseline evidence (chosen, not measured)
# The pair statistic's vector is (CCW up, CCW up, CW up, CW up): index i holds the evidence for i's same-spin pair.
SAME_SPIN_PAIRS = ((1, 2), (3, 4))  # PX4 quad-X: 1, 2 CCW (diagonal), 3, 4 CW (diagonal)


def trimmed_mean(x: np.ndarray, cut: float) -> np.ndarray:
    """The mean over axis 0 of ``x`` with ``int(cut * len(x))`` of its values dropped at each end, per column
    (scipy.stats.trim_mean's, without scipy onboard): what the baseline's plane learns each span's trims as."""
    n = x.shape[0]
    k = int(cut * n)
    return np.sort(x, axis=0)[k : n - k].sum(axis=0) / (n - 2 * k)


def _clip_llr(llr: np.ndarray) -> np.ndarray:
    """np.clip(llr, -LLR_CLIP, LLR_CLIP), NaN kept, without np.clip's Python-level wrappers (every window)."""
    return np.minimum(np.maximum(llr, -LLR_CLIP), LLR_CLIP)


# Projection that removes the collective (1,1,1,1)/2 and yaw (1,1,-1,-1)/2 directions (PX4 order: 1, 2 CCW; 3, 4 CW).
_C, _Y = np.full(4, 0.5), np.array([0.5, 0.5, -0.5, -0.5])
_YAW_FREE = np.eye(4) - np.outer(_C, _C) - np.outer(_Y, _Y)
# What is left is two-dimensional: the pitch and roll trims. PX4 quad-X order 1 front-right, 2 rear-left,
# 3 front-left, 4 rear-right: pitch (-1, +1, -1, +1)/2 (rear rotors up: a nose-down moment), roll (-1, +1, +1, -1)/2
# (left rotors up: a right-wing-down moment). Orthonormal; yaw-free x = a_pitch * pitch + a_roll * roll.
_PITCH, _ROLL = np.array([-0.5, 0.5, -0.5, 0.5]), np.array([-0.5, 0.5, 0.5, -0.5])
_AXES = np.stack([_PITCH, _ROLL])  # (2, 4): x -> (a_pitch, a_roll)
_U = _AXES.T.copy()  # (4, 2): rotor i's direction in (pitch, roll); a loss f on rotor i moves (a_pitch, a_roll) by f U[i]


# -- physics: each rotor's share of omega^2 ---------------------------------------------------------
# The healthy spread of each rotor's yaw-free share (mean over SHARE_AVERAGE_S) less the decision's baseline plane,
# at every tested window of 96 randomised healthy flights of our simulator (seed 100: register physics, drawn
# airframes, payload steps; `python -m bench.decision_constants`): rms 0.008, 99 % within 0.029, 99.9 % within 0.074.
# The Gaussian noise model takes the tail's scale (99 % / 2), so a manoeuvre's excursion is not read as decisive
# evidence: that measures 0.014 against the 0.01 shipped. 0.01 is the same scale against the flight's first 10 s
# (no plane), for which `python -m bench.alerts_flights --set ours-healthy --seed 100 --flights 96 --share-spread`
# now gives 99 % within 0.19. The calibrated thresholds absorb what the model gets wrong.
SHARE_SIGMA = 0.01
# Slow drifts (battery sag, motor warm-up) enter the baseline over a minute: chosen, not measured.
SHARE_BASELINE_TAU_S = 60.0
# Seconds of shares averaged per sample. Shorter reacts sooner to an onset (the mean ramps over this time) but is
# noisier; chosen on our simulator (calibration flights seed 100, onset flights seed 400: 5 s gave a median
# latency of 7.7 s at >= 8 % loss, 2 s 4.2 s with the fault threshold 1.5x the highest healthy value, 1 s 3.8 s
# at only 1.1x), never on the evaluation-only simulator. No command runs the comparison; each row is this value set,
# `make tune-alerts`, then `propwatch evaluate alerts --seed 400 --no-evalsim`.
SHARE_AVERAGE_S = 2.0
# What the baseline's plane learns from: each span's trims as a 10 %-trimmed mean (``trimmed_mean``), not the mean.
# 20-Hz snapshots of a 200-Hz motor command can catch one controller tick of a transient: evalsim's healthy flight
# seed 300 healthy_0019 (replayed by tests/test_decision_snapshot.py) gave a false FAULT from a single snapshot of a
# sharp stop (rotor 2 at
# 1432 RPM, the others 2463-4790, held for two samples) inside the first 10 s: it put a pitch trim of -0.07 into
# five 2-s means, and a least-squares plane over 10 s took it as a slope in the specific force (-0.27 where the
# flight's other windows give -0.005), which then mispredicted the cruise trim by 0.05 (rotor 2's direction) for
# the rest of the flight. A fit must not be set by one snapshot; 4 of 40 cut at each end leave a span of our
# simulator's healthy flights within 1 % of its mean (rms of 2-s steps, seed 100; not re-measured by a command in
# the repository). The evidence keeps the mean: its noise is what the thresholds were calibrated on (a trimmed mean
# there lowered the calibrated fault threshold from 8.05 to 6.37 nat-s and let one of 10 held-out healthy hours of
# ours cross it: a plane misfit, not noise; `make tune-alerts evaluate-alerts` with the evidence trimmed).
PLANE_CUT = 0.1
# The pair statistic: a same-spin diagonal pair (1+2 CCW or 3+4 CW) that loses thrust f on both rotors keeps roll
# and pitch balanced (T1 = T2, T3 = T4 still hold), so the yaw-free shares do not move. What moves is the yaw
# balance: the damaged pair's drag torque per omega^2 changes by g = 1 - (1 - f)(1 + c), c the unmeasured change
# of torque per unit thrust, and the controller re-trims yaw: y = (s1 + s2 - s3 - s4) / 2 moves by +g for 1+2
# and -g for 3+4. With c = 0 (torque scales with thrust) g = f, so the CUSUM reference is half of
# alerts.min_thrust_loss; the sign of c is unknown, so a shift names both pairs ("1+2 or 3+4?"), the
# one it fits with c = 0 first. YAW_SIGMA: the healthy spread of y (mean over SHARE_AVERAGE_S) around the flight's
# own first 10 s on 96 randomised healthy flights of our simulator (`python -m bench.alerts_flights --set
# ours-healthy --seed 100 --flights 96 --share-spread`, or unclassified `python -m bench.decision_constants`): over
# 10 s rms 0.017 (99 % within 0.043); against the decision's own yaw baseline rms 0.015 (99 % within 0.043); over
# 2 s it scatters by ~0.05 (yaw manoeuvres re-trim it within seconds; no command here measures that). So the yaw
# balance is averaged over YAW_AVERAGE_S = 10 s (pairs have no latency target; singles keep their 2 s), and YAW_SIGMA
# takes the tail's scale (99 % / 2) as SHARE_SIGMA does; the calibrated thresholds absorb what the Gaussian model
# gets wrong.
YAW_AVERAGE_S = 10.0
YAW_SIGMA = 0.022
# What a yaw-balance alert names. A single rotor i losing thrust f with a torque-per-thrust change c moves the yaw
# balance by (f - c) / 2 and its yaw-free share by +f/2 (its same-spin partner's by -f/2); a same-spin pair moves
# y by f - c and the yaw-free shares not at all (docs/ALERTS.md "The pair statistic"). So a yaw shift alone is
# a same-spin pair, or a small single with a large torque change, and the single is the rotor whose yaw-free share
# rose most over the same YAW_AVERAGE_S: it is always one of the alert's hypotheses, first when its rise exceeds
# what healthy flights reach. YAW_FREE_RISE: measured as the decision forms it (``yaw_free_rise`` at every tested
# window of 96 randomised healthy flights of our simulator, the calibration seed 100:
# `python -m bench.decision_constants`), 0.012 is the 96.6 % quantile (99 %: 0.035; 99.9 %: 0.062). Against the
# flight's first 10 s instead (`python -m bench.alerts_flights --set ours-healthy --seed 100 --flights 96
# --share-spread`) the same flights give 0.17 at 99 %. "Beyond healthy" orders the hypotheses, YAW_FREE_GAP below decides who is named.
YAW_FREE_RISE = 0.012
# Which single a yaw-balance alert names is only as sure as the rises differ. A loss f moves its rotor's rise by
# f/2 against its neighbours' (0.0165 at 3.3 %), and two neighbours' healthy 10-s rises differ by up to 0.046
# (99 % quantile of the largest difference between rotors sharing a side, the decision's own rise at every tested
# window of 96 healthy flights of seed 100; `python -m bench.decision_constants`) and 0.076 (99.9 %; 0.069 shipped,
# measured on 10 hours of the same seed every 0.5 s by a script not in the repository). So every rotor whose rise
# is within
# YAW_FREE_GAP of the largest is a hypothesis too, after the pairs: two rotor-4 losses of 3.2-3.3 % on our
# simulator (`python -m bench.alerts_flights --set ours-single --seed 601`) were alerted "PROP 1 or 3+4 or 1+2?",
# rotor 1's rise 0.003-0.008 above rotor 4's. The
# 99.9 % quantile, not the 99 %: an alert is raised at one instant, and at speed, where the plane misfits, the
# rises stray most: with 0.033 a 2.7 % rotor-4 loss (`--set ours-single --seed 201`, 4 m/s, -2.3 m/s^2) read rotor 1 0.036
# above rotor 4. A yaw shift alone says "a same-spin pair or one propeller"; the rises only order the singles.
YAW_FREE_GAP = 0.069
# The trims follow the airspeed. Blade flapping tilts each disc back in edgewise flow (blowback) and the rotors
# trim it: flying forward at airspeed u the front rotors' yaw-free share falls by t u, the rear ones' rises as much
# (a_pitch = 2 t u), and a side flow does the same in roll. t is the airframe's own: 0 to ~0.025 per m/s (our
# register's blade_flapping_trim_per_m_s, bounded by ArduPilot log171; docs/ALERTS.md). Airspeed is not streamed,
# but two things that follow it are: the ground velocity in the heading frame (airspeed less the wind) and the
# body's horizontal specific force (the IMU's x, y: thrust is along body z, so this is the air's drag, which
# grows with airspeed, wind included: what PX4's EKF2 multirotor drag fusion reads). So the baseline is, per
# axis, a plane a = b + k_v v + k_a f (forward velocity and f_x for pitch, right and f_y for roll), learnt by a
# Kalman filter over (b, k_v, k_a) from the flight itself while no evidence gathers, and the evidence is weighed
# by what the plane does not yet know (the larger of the two axes' variances at this v, f): an airframe whose
# slopes are not yet learnt is heard less at speed, not read as a fault. On our simulator (heading towards the waypoint, wind up
# to 5 m/s) the velocity alone leaves 0.1 of the trims unexplained and the specific force 0.007; on evalsim's
# forward flights either leaves ~0.015, both 0.013; on log171 (real) 0.087 / 0.096 / 0.085 (a hard-flown flight).
# The slopes' priors: mean 0 (flapping's sign is blowback's, but other speed-linear trims, e.g. body drag above
# the CG, take either); sd FLAP_SLOPE_PRIOR_SD per m/s puts the register's largest (0.05 per m/s in a_pitch) at
# 1.7 sd (chosen from the register's range); DRAG_SLOPE_PRIOR_SD per m/s^2 covers our simulator's fitted slopes at
# 1 sd: each healthy flight's plane of its 2-s trims, 96 randomised flights of seed 100
# (`python -m bench.decision_constants`), gives specific-force slopes -0.24..-0.009 per m/s^2 (5-95 %, median
# -0.07) and velocity slopes -0.005..0.002 per m/s. SHARE_BASELINE_TAU_S sets the intercept's drift.
# FLAP_SLOPE_Q: how fast the slopes may drift, as a random walk: ~0.005 per m/s in ten minutes (the specific-force
# slope ten times that per m/s^2, in proportion to the priors). The plane stops learning while evidence gathers, so
# after an onset what it does not know at a speed it has flown grows by this drift for as long as the loss is being
# heard: at 0.005 per m/s a minute that is 0.002-0.006 at 3-4 m/s^2 within 10-20 s, 10-30 times one sample's noise,
# and 8-12 % losses flown at speed are heard that much less (p95 latency 10.8-12.9 s on our held-out seeds 300, 600,
# 700). Measured by setting FLAP_SLOPE_Q and running `make tune-alerts evaluate-alerts` (calibration on seed
# 100, onsets on seed 300), one drift per minute of 0.005 / 0.0027 / 0.0016 / 0.0009 / 0 per m/s: fault threshold
# 7.37 / 8.53 / 9.45 / 10.44 / 20.46 nat-s, median / p95 latency 6.05 / 10.77, 5.2 / 9.22, 4.65 / 9.44, 4.8 / 9.7,
# 8.55 / 14.96 s (with none the healthy flights' slow changes are misfits the threshold must absorb). 0.0016 per m/s
# a minute (a tenth of the variance) is the middle of the flat part: healthy slopes do move (payload, sag), but
# slowly.
FLAP_SLOPE_PRIOR_SD = 0.03  # a_pitch / a_roll per m/s
DRAG_SLOPE_PRIOR_SD = 0.3  # a_pitch / a_roll per m/s^2 of specific force
FLAP_SLOPE_Q = 0.005**2 / 600.0  # per s (the specific-force slope drifts in proportion: x DRAG/FLAP prior sd)
# The plane is linear; the trims need not be (quadratic drag against a speed-linear flapping trim, a wind the
# velocity does not see). So beyond the box of (v, f) the plane was learnt on, what it does not know grows by a
# slope's prior sd per unit beyond the box (per m/s, per m/s^2): a trim there is heard less until the plane has
# learnt it while quiet. Without it, flight healthy-r200-381 (`python -m bench.alerts_flights --set ours-healthy
# --seed 200 --flights 382`) gave a false FAULT: the roll trim left the plane by 0.09-0.12 when the lateral specific
# force swung to -1.1 m/s^2, twice what it had seen.
NOVEL_FLAP_SD = FLAP_SLOPE_PRIOR_SD
NOVEL_DRAG_SD = DRAG_SLOPE_PRIOR_SD
BASELINE_PRIOR_VAR = 1.0  # the intercept before any window (diffuse)
# The plane learns while no physics statistic holds more than QUIET_NATS (the decision's ``quiet``). At 0, a statistic
# left at a few hundredths of a nat stopped it for many seconds: where the plane's doubt is large (a speed or drag
# it has not flown) every window's evidence is tiny in both directions, so a CUSUM at 0.05 neither grows nor drains,
# and the plane could not learn the very regime it doubted. Flight `single-r801-26` (`python -m bench.alerts_flights
# --set ours-single --seed 801 --flights 27`, with QUIET_NATS = 0): rotor 1's statistic
# stood at 0.05-0.07 from 19.6 s, the box did not widen to the lateral specific force of -2 m/s^2 the vehicle then
# flew, and a rotor-2 loss at 28.5 s was heard 17.6 s later. 0.1 nat is 1 % of the fault threshold and a sixtieth of
# one 2-s sample of an 8 % loss heard at noise weight (8 nats): a loss heard at all passes it within a step or two.
QUIET_NATS = 0.1


_finite = math.isfinite


def _floats(x) -> list[float]:
    """A short vector as Python floats (the plane's filter runs in floats: numpy's small-array calls cost more)."""
    return x.tolist() if isinstance(x, np.ndarray) else list(x)


def _p_times_h(P: list[list[float]], v: float, f: float) -> list[float]:
    """P h for a 3 x 3 covariance and the regressor h = (1, v, f)."""
    return [P[i][0] + P[i][1] * v + P[i][2] * f for i in range(3)]


class RotorShare:
    """Window-mean share of omega^2 per rotor against the flight's own baseline: thrust-loss evidence.

    A rotor that lost a fraction f of its thrust must spin faster for the
    controller to hold roll and pitch: its omega^2 rises by ~f. The yaw
    balance moves the shares too, along (+1, +1, -1, -1) (CCW against CW
    rotors), by an amount that depends on how the damaged blade's torque per
    thrust changed, which nobody has measured: that direction and
    the collective one are projected out (``_YAW_FREE``). What is left of a
    thrust loss on rotor i is +f/2 on i and -f/2 on its same-spin diagonal
    partner, whatever the torque change. The share needs no fault model and
    no training; against the airframe's own baseline it is blind to CG
    offsets and motor spread (the baseline names 24 of 24 that way).

    What is left lives in two dimensions, the pitch and roll trims (``_AXES``). Baseline: per axis a plane
    ``b + k_v v + k_a f`` in the heading-frame velocity and the body's horizontal specific force (blade flapping
    follows airspeed, see FLAP_SLOPE_PRIOR_SD), a Kalman filter over (b, k_v, k_a) fed by every evidence window of
    the first ``BASELINE_S`` (held ones do not count: a least-squares fit of those windows), then only while no
    evidence is gathering (``quiet``: no physics statistic above ``QUIET_NATS``), so slow drifts (battery sag) are
    absorbed, at the rate of an exponential average over ``SHARE_BASELINE_TAU_S``, and a step is not. Without those
    streams the regressors are 0 and the plane is its intercept: the flight's own mean, as before flapping was
    modelled.

    Per window: the Gaussian mean-shift log-likelihood ratio, for each rotor i, of the window-mean trims e
    (less the plane at this window's mean regressors) shifted by f U_i (a loss ``f = alerts.min_thrust_loss``, the
    smallest worth an alert: the reference is half of it): ``f U_i' S^-1 (e - f U_i / 2)``, S per axis the healthy
    spread 2 sigma^2 (``sigma = SHARE_SIGMA`` per rotor) plus what the plane does not know there. With
    S = 2 sigma^2 on both axes it is ``delta (x_i - b_i - delta/2) / sigma^2``, delta = f/2, the per-rotor test.
    Overlapping windows are not independent: the caller weighs each by ``dt / average_s`` (one independent sample
    per averaging span), and the filter counts each window's new steps, 1/``window`` of a sample each.
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
        # (v_forward, v_right, f_x, f_y): heading-frame velocity and body specific force; NaN where not streamed
        self._vring = np.full((self.window, 4), np.nan)
        self._i = 0
        self._n = 0
        self._base_s = 0.0  # seconds of evidence windows the baseline has seen (held windows are not evidence)
        self.baseline: np.ndarray | None = None  # (4,) the plane's intercept as yaw-free shares (regressors 0)
        # The plane per axis (pitch, roll): theta[axis] = (b, k_v, k_a), P[axis] its covariance. Python lists: a
        # 3-state filter per axis at 20 Hz costs a third as much in floats as in numpy's small-array calls.
        self._th: list[list[float]] = [[0.0] * 3 for _ in range(2)]
        self._P: list[list[list[float]]] = [[[0.0] * 3 for _ in range(3)] for _ in range(2)]
        self._r = 2.0 * sigma**2  # one independent sample's variance per axis
        # Intercept drift per second that makes the filter's steady gain per window dt / SHARE_BASELINE_TAU_S
        # (a random walk with gain K << 1 has K^2 = q dt / R per update; R = r * window / (dt * rate_hz) for a window
        # bringing dt * rate_hz new steps, ``_update_line``), at any cadence.
        self._q_b = self._r * self.window / (SHARE_BASELINE_TAU_S**2 * rate_hz)
        self._base = []  # the yaw balance's windows while the baseline is learnt
        self._wording_b: np.ndarray | None = None  # (pitch, roll) intercept the alert wording reads (yaw_free_rise)
        self._restart_line()
        # The yaw balance (pair statistic): y = (s1 + s2 - s3 - s4) / 2, mean over YAW_AVERAGE_S, against its baseline.
        self.yaw_delta = min_thrust_loss
        self.yaw_sigma = YAW_SIGMA
        self.yaw_window = max(int(round(YAW_AVERAGE_S * rate_hz)), 1)
        self._yring = np.full(self.yaw_window, np.nan)
        self._sring = np.full((self.yaw_window, N_PROPS), np.nan)  # the shares over YAW_AVERAGE_S (alert wording)
        self._svring = np.full((self.yaw_window, 4), np.nan)  # and the velocity and specific force over it
        self._yi = 0
        self._yn = 0
        self.yaw_baseline: float | None = None
        self.yaw_llr = np.zeros(len(SAME_SPIN_PAIRS))  # (CCW pair up, CW pair up) of the last window

    def _restart_line(self) -> None:
        prior = (BASELINE_PRIOR_VAR, FLAP_SLOPE_PRIOR_SD**2, DRAG_SLOPE_PRIOR_SD**2)
        self._th = [[0.0] * 3 for _ in range(2)]
        self._P = [[[prior[i] if i == j else 0.0 for j in range(3)] for i in range(3)] for _ in range(2)]
        # per axis the (v, f) box of the windows the plane was learnt from: (v_min, v_max, f_min, f_max)
        self._seen: list[list[float] | None] = [None, None]

    @property
    def _theta(self) -> np.ndarray:
        """(2, 3) the plane per axis (pitch, roll): (b, k_v, k_a)."""
        return np.array(self._th)

    def _intercepts(self) -> np.ndarray:
        """(2,) the plane's (pitch, roll) intercepts."""
        return np.array([self._th[0][0], self._th[1][0]])

    def reset(self) -> None:
        self._ring[:] = np.nan
        self._vring[:] = np.nan
        self._yring[:] = np.nan
        self._sring[:] = np.nan
        self._svring[:] = np.nan
        self._n = self._yn = 0
        self._base, self.baseline, self.yaw_baseline = [], None, None
        self._wording_b = None
        self._base_s = 0.0
        self._restart_line()

    @property
    def learning_s(self) -> float | None:
        """Seconds of evidence windows learnt towards the baseline (of ``BASELINE_S``), None once it is learnt."""
        return None if self.baseline is not None else self._base_s

    def push(
        self, rpm: np.ndarray | None, vel_heading_m_s: np.ndarray | None = None, accel_xy_frd_m_s2: np.ndarray | None = None
    ) -> None:
        if rpm is None:
            return
        # In Python floats, numpy's arithmetic step by step (this runs at every step): omega^2, their mean
        # (numpy sums four values left to right, as here) and the shares.
        r1, r2, r3, r4 = rpm.tolist() if isinstance(rpm, np.ndarray) else map(float, rpm)
        w1, w2, w3, w4 = r1 * r1, r2 * r2, r3 * r3, r4 * r4
        m = (w1 + w2 + w3 + w4) / 4.0
        if not (_finite(w1) and _finite(w2) and _finite(w3) and _finite(w4) and m > 0):
            self._n = self._yn = 0  # a gap: the window starts again
            return
        share = (w1 / m, w2 / m, w3 / m, w4 / m)
        self._ring[self._i] = share
        v = self._vring[self._i]
        if vel_heading_m_s is None:
            v[:2] = np.nan
        else:
            v[:2] = vel_heading_m_s
        if accel_xy_frd_m_s2 is None:
            v[2:] = np.nan
        else:
            v[2:] = accel_xy_frd_m_s2
        self._i = (self._i + 1) % self.window
        self._n += 1
        s1, s2, s3, s4 = share
        self._yring[self._yi] = 0.5 * (s1 + s2 - s3 - s4)
        self._sring[self._yi] = share
        self._svring[self._yi] = v
        self._yi = (self._yi + 1) % self.yaw_window
        self._yn += 1

    @staticmethod
    def _mean_regressors(ring: np.ndarray) -> np.ndarray:
        """(v_forward, v_right, f_x, f_y) means over the known entries of ``ring``; 0 where none is known (no
        stream: the plane is its intercept in that regressor)."""
        ok = ~np.isnan(ring)
        n = ok.sum(axis=0)
        return np.where(n > 0, np.where(ok, ring, 0.0).sum(axis=0) / np.maximum(n, 1), 0.0)

    def line(self, regressors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The baseline's (pitch, roll) trims at these (v_forward, v_right, f_x, f_y) and their variances (what the
        plane does not know there)."""
        r = _floats(regressors)
        pred, var = [0.0, 0.0], [0.0, 0.0]
        for a in range(2):
            v, f = r[a], r[2 + a]
            b, kv, ka = self._th[a]
            pred[a] = b + kv * v + ka * f
            ph = _p_times_h(self._P[a], v, f)
            var[a] = ph[0] + ph[1] * v + ph[2] * f
            box = self._seen[a]
            if box is not None:  # beyond what it was learnt on, the plane is a guess: a slope's prior per unit beyond
                ev = max(0.0, v - box[1], box[0] - v)
                ef = max(0.0, f - box[3], box[2] - f)
                var[a] += (NOVEL_FLAP_SD * ev) ** 2 + (NOVEL_DRAG_SD * ef) ** 2
        return np.array(pred), np.array(var)

    def _update_line(self, trims: np.ndarray, regressors: np.ndarray, dt_s: float, learn: bool) -> None:
        """Predict the plane over ``dt_s`` (drift), then fold in the window's trims when ``learn``."""
        if dt_s > 0:
            q = (self._q_b * dt_s, FLAP_SLOPE_Q * dt_s, FLAP_SLOPE_Q * (DRAG_SLOPE_PRIOR_SD / FLAP_SLOPE_PRIOR_SD) ** 2 * dt_s)
            for P in self._P:
                for i in range(3):
                    P[i][i] += q[i]
        if not learn:
            return
        # Overlapping windows: a window brings the steps that are new since the last one, each 1/``window`` of an
        # independent sample. At every step (the daemon's default) that is one step; where windows are fed every
        # ``hop`` steps (``propwatch diagnose --hop 20``) it is ``hop`` of them, so the plane learns as fast per
        # second of flight at any cadence.
        new_steps = min(max(round(dt_s * self.rate_hz), 1), self.window)
        r = self._r * self.window / new_steps
        x = _floats(regressors)
        y = _floats(trims)
        for a in range(2):
            h = (1.0, x[a], x[2 + a])
            P, th = self._P[a], self._th[a]
            ph = _p_times_h(P, h[1], h[2])
            s = ph[0] + ph[1] * h[1] + ph[2] * h[2] + r
            gain = [p / s for p in ph]
            innov = y[a] - (th[0] + th[1] * h[1] + th[2] * h[2])
            for i in range(3):
                th[i] += gain[i] * innov
            box = self._seen[a]
            if box is None:
                self._seen[a] = [h[1], h[1], h[2], h[2]]
            else:
                box[0], box[1] = min(box[0], h[1]), max(box[1], h[1])
                box[2], box[3] = min(box[2], h[2]), max(box[3], h[2])
            new = [[P[i][j] - gain[i] * ph[j] for j in range(3)] for i in range(3)]
            self._P[a] = [[0.5 * (new[i][j] + new[j][i]) for j in range(3)] for i in range(3)]

    def _slopes_at(self, regressors: np.ndarray) -> np.ndarray:
        """(pitch, roll) the plane's slopes give at these regressors (the intercept left out)."""
        r = _floats(regressors)
        return np.array([self._th[a][1] * r[a] + self._th[a][2] * r[2 + a] for a in range(2)])

    def yaw_free_rise(self) -> np.ndarray | None:
        """(4,) each rotor's yaw-free share over the last YAW_AVERAGE_S less the baseline's at that span's mean
        velocity; None before both exist."""
        if self.baseline is None or self._yn < self.yaw_window:
            return None
        # Against the wording's intercept (the former 60-s average, fed while quiet): the filter's intercept moves
        # faster in its first minutes and would absorb a loss too small for the statistic, whose rise is what a
        # yaw-balance alert names first (a 3.5 % loss with a 25 % torque change; tests/test_decision_pair.py).
        pred = self._wording_b + self._slopes_at(self._mean_regressors(self._svring))
        return _YAW_FREE @ (self._sring.sum(axis=0) / self.yaw_window) - _U @ pred

    def llr(self, dt_s: float = 0.0, quiet: bool = False, yaw_quiet: bool | None = None) -> np.ndarray | None:
        """Per-rotor evidence of the current window, or None (no full window, or baseline still being learnt).

        ``quiet``: no physics evidence is gathering (the caller's test: every statistic <= ``QUIET_NATS``), so the
        baseline (the plane: intercept and slopes) may follow the window for ``dt_s``
        (``yaw_quiet``: the same for the yaw balance; default ``quiet``). The yaw balance's evidence of the
        same window is left in ``yaw_llr`` (zeros when None is returned).
        """
        self.yaw_llr = np.zeros(len(SAME_SPIN_PAIRS))
        if self._n < self.window:
            return None
        m = self._ring.sum(axis=0) / self.window  # the ring's mean, bit for bit (see push)
        trims = _AXES @ m  # (pitch, roll): the collective and yaw directions are orthogonal to both
        learns = self.baseline is None or quiet
        fit = trimmed_mean(self._ring @ _AXES.T, PLANE_CUT) if learns and PLANE_CUT > 0 else trims  # the plane's
        v = self._mean_regressors(self._vring)
        y = float(_Y @ m)  # the baseline's share of the yaw balance: over BASELINE_S like the shares'
        if self.baseline is None:
            self._update_line(fit, v, dt_s, learn=True)
            self._base.append(y)
            self._base_s += dt_s
            # BASELINE_S of windows that were evidence, not of flight: windows held for a manoeuvre never reach
            # here; a baseline finalised on the half second after a hold takes a transient for the airframe's trim
            # (a false rotor-2 fault 14 s before an onset, from 10 windows after a 7-s hold:
            # tests/test_decision_regimes.py, test_the_share_baseline_spans_ten_seconds_of_evidence_not_the_half_second_after_a_hold).
            if self._base_s >= BASELINE_S and len(self._base) >= 3:
                self._wording_b = self._intercepts()
                self.baseline = _U @ self._wording_b
                # The yaw balance's own mean over the last YAW_AVERAGE_S (its 2-s means scatter by 0.05)
                self.yaw_baseline = float(np.mean(self._yring if self._yn >= self.yaw_window else np.asarray(self._base)))
                self._base = []
            return None
        pred, var = self.line(v)
        e = trims - pred
        # One variance for both axes, the larger: with a variance per axis, a shift along one rotor's direction
        # leaks into its neighbours' tests (U_i' S^-1 U_j != 0 for rotors sharing a side): rotor 4's loss, with
        # the pitch plane less certain than the roll one, read as rotor 1 too (59 of our 150 single onsets had an
        # alert naming a healthy propeller, 19 with one variance; docs/ALERTS.md).
        inv_s = np.full(2, 1.0 / (self._r + float(var.max())))
        self._update_line(fit, v, dt_s, learn=quiet)
        k = min(dt_s / SHARE_BASELINE_TAU_S, 1.0) if dt_s > 0 else 0.0  # the former exponential average's gain
        if quiet and self._wording_b is not None:
            # the wording's intercept: the former exponential average of the trims less the plane's slopes
            self._wording_b += k * (fit - self._slopes_at(v) - self._wording_b)
        if quiet:
            self.baseline = _U @ self._intercepts()
        if self._yn >= self.yaw_window:
            dy = float(self._yring.sum() / self.yaw_window) - self.yaw_baseline
            if quiet if yaw_quiet is None else yaw_quiet:
                self.yaw_baseline += dy * k
            # Two one-sided tests of the yaw balance: the CCW pair's shares up (+dy) or the CW pair's (-dy).
            yd, ys = self.yaw_delta, self.yaw_sigma
            self.yaw_llr = _clip_llr(np.array([yd * (dy - yd / 2), yd * (-dy - yd / 2)]) / ys**2)
        f = 2.0 * self.delta
        # f U_i' S^-1 (e - f U_i / 2), every U_i entry +-1/2 so U_i' S^-1 U_i = (1/S_pitch + 1/S_roll) / 4
        llr = f * (_U @ (e * inv_s)) - (f * f / 8.0) * float(inv_s.sum())
        return _clip_llr(llr)
