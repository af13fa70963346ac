"""The one decision rule shared by ``propwatch diagnose`` and the daemon: window outputs -> suspect / fault.

Per propeller, three CUSUMs (Page 1954) over per-window log-likelihood ratios,
and one for same-spin diagonal pairs (``pair``, below).
With P the window's P(propeller faulty) from a network trained on a balanced
set (each propeller faulty in 8 of 16 labels: prior odds 1), the window's
log-likelihood ratio faulty : healthy is ``logit(P)``, clipped to
+-``LLR_CLIP`` (one over-confident window cannot decide) and weighted by the
seconds it covers, so the statistics (nat-seconds) do not depend on how often
windows are classified (the daemon: every 0.05 s; diagnose: every hop):

    absolute  A_i <- max(0, A_i + clip(logit P_i) * dt)
    change    C_i <- max(0, C_i + (clip(logit P_i) - B_i) * dt)
    physics   F_i <- max(0, F_i + phys_i * dt / SHARE_AVERAGE_S)

``B_i = max(0, median clip(logit P_i))`` over the first ``BASELINE_S`` of
classified flight (after take-off, and again after a collective step): what
the network already says about this airframe before anything changed. A
network that is confidently wrong about a healthy airframe (a CG offset or a
weak motor it never saw) keeps ``A`` growing on every such flight;
``C`` adds evidence only for a *change*. ``phys_i`` is physics evidence that
needs no network: the rise of rotor i's share of omega^2 over its own
baseline (``RotorShare``), as a log-likelihood ratio per independent sample
(one ``SHARE_AVERAGE_S`` = 2 s mean of shares: means overlapping by all but one
step are not independent), so ``F`` is in
nats; its CUSUM reference is half the share shift of the smallest thrust loss
worth an alert (``alerts.min_thrust_loss``, 8 %), so manoeuvres and gusts
that move the shares by less add nothing. Kept in its own statistic, because
a network that is confidently wrong would cancel it. A propeller's level is
the highest of the three.

``pair``: a same-spin diagonal pair (1+2 CCW, 3+4 CW) losing thrust keeps roll
and pitch balanced (T1 = T2, T3 = T4), so the yaw-free shares do not move; the
yaw trim does, by the change of the pair's drag torque per omega^2. Two
one-sided CUSUMs on the yaw balance ``y = (s1 + s2 - s3 - s4) / 2`` (10-s mean,
one sample per ``YAW_AVERAGE_S``) against its own baseline, reference half of
``alerts.min_thrust_loss`` (the shift of an equal loss with torque scaling with
thrust). Which pair cannot be told (the torque change's sign is unmeasured):
alone it words ``PROP 1+2 or 3+4?``; beside a single propeller it adds that
propeller's pair to the hypotheses (``PROP 1 or 1+2?``).

Thresholds come from the configured false-alarm rates (a level's rate shared
equally by the statistics that may raise it: all four for suspect, those of
``alerts.fault_evidence`` for fault), never hand-set; ``pair``'s never below
Wald's bound (two one-sided tests, one sample per 10 s):

* **calibrated** (when ``models/decision-calibration.json`` belongs to the
  model, by SHA-256): the rate of threshold crossings (any propeller,
  restarting at each) per healthy flight-hour, measured on randomised healthy
  flights of our simulator with exactly this code (``offline/alerts``), has an
  exponential tail ``rate(h) = exp(a - b h)`` (the CUSUM renewal / ARL
  relation, ARL0 ~ e^(b h)); so ``h = (a - ln rate) / b``, taken at the 95 %
  quantile of a bootstrap over the calibration flights (a point fit of a thin
  tail moved 0.7 nat-s between 5 and 10 hours). A statistic whose
  crossings do not fall that way on healthy flights (the network is pinned at
  P ~ 1 on some airframes) is *disabled* by the calibration: no threshold can
  meet the rate, and the file says so.
* **analytic** (fallback for an uncalibrated model): Wald's bound ARL0 >= e^h
  in independent samples; windows overlapping by all but one step are not
  independent, so one window length (5 s) counts as one sample, and with 4
  propellers ``h = window_s * ln(4 * 3600 / window_s / rate)``. Conservative.

Two levels: ``suspect`` at the threshold for ``suspect_false_alarms_per_hour``
(STATUSTEXT NOTICE) and ``fault`` at ``false_alarms_per_hour`` (WARNING, or
CRITICAL for two or more propellers). A lower rate gives a higher threshold.

Regime changes reset or hold the evidence (``RegimeTracker``): landing and
take-off end a flight's evidence; windows containing an aggressive manoeuvre
(tilt or body rate beyond the training envelope) or a collective step (payload
drop or pick-up) add nothing, and a collective step also halves what was
gathered before it (evidence about another vehicle state) and re-learns the
baselines. A battery sag does the same to the network's statistics only: it
scales every rotor's speed for its command alike, which the omega^2 shares
and the yaw balance (ratios) do not see. A stopped
stream pauses the decision (evidence kept, nothing added, nothing announced)
and says why; it is never frozen into an alert.

VIBRATION (MAVLink #241; PX4 fills vibration_z with the accelerometer's
high-frequency vibration metric) is imbalance evidence that names no
propeller: its own CUSUM on the log-ratio to the flight's first 10 s raises
at most ``suspect`` ("VIBE HIGH PROP ?"), with the analytic threshold (no
simulator here makes VIBRATION to calibrate it on). Values that are NaN,
negative, absurd (> ``VIBE_MAX_M_S2``) or frozen (the same value
``FROZEN_REPEATS`` times running) are ignored and counted, never evidence.

The wording: ``PROP 3 FAULT p=0.97`` only when one hypothesis remains; when
the propellers at suspect level widen the set, or the evidence comes with
several hypotheses, ``PROP 1 or 1+2?`` (<= 50 characters).

The parts live beside this module in ``monitor.decision`` (its docstring lists them): the settings and levels in
``config``; the omega^2 shares and the yaw balance in ``rotor_share``; thresholds and the calibration file in
``thresholds``; regimes in ``regime``; VIBRATION and ESC_STATUS validation in ``stream_evidence``. This module
combines them: the CUSUMs, the levels and the wording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from monitor.decision.config import FAULT_RANK, LEVELS, DecisionConfig
from monitor.decision.regime import RegimeTracker, StepInputs
from monitor.decision.rotor_share import (
    BASELINE_S,
    LLR_CLIP,
    QUIET_NATS,
    SAME_SPIN_PAIRS,
    SHARE_AVERAGE_S,
    YAW_AVERAGE_S,
    YAW_FREE_GAP,
    YAW_FREE_RISE,
    RotorShare,
)
from monitor.decision.stream_evidence import VIBE_MIN_RATIO, VibrationEvidence
from monitor.decision.thresholds import (
    ROTOR_STATISTICS,
    STATISTICS,
    Calibration,
    analytic_threshold,
    fault_statistics,
    load_calibration,
    suspect_statistics,
    thresholds,
)
from monitor.labels import N_PROPS

STATUSTEXT_MAX_CHARS = 50
NETWORK_STATISTICS = ("absolute", "change")  # what a battery sag discounts (RegimeTracker.network_holding)
MAV_SEVERITY_CRITICAL, MAV_SEVERITY_WARNING, MAV_SEVERITY_NOTICE = 2, 4, 5


def window_llr(fault_probability) -> np.ndarray:
    """Clipped per-propeller log-likelihood ratio of one window (NaN -> 0: no evidence)."""
    out = np.zeros(N_PROPS)
    for i, p in enumerate(fault_probability):
        p = float(p)
        if p != p:  # NaN
            continue
        if p <= 0.0 or p >= 1.0:
            out[i] = LLR_CLIP if p >= 1.0 else -LLR_CLIP
            continue
        out[i] = min(max(math.log(p / (1.0 - p)), -LLR_CLIP), LLR_CLIP)
    return out


# -- inputs -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class WindowEvidence:
    """What one classified window says; every field but ``fault_probability`` is optional."""

    fault_probability: np.ndarray  # (4,) P(propeller faulty), PX4 order
    label_probability: np.ndarray | None = None  # (16,)
    hypotheses: tuple[tuple[tuple[int, ...], float], ...] | None = None  # ((propellers 1..4), probability)
    rotor_effectiveness: np.ndarray | None = None  # (4,) fraction of nominal thrust
    rotor_effectiveness_std: np.ndarray | None = None


@dataclass(frozen=True)
class Announcement:
    """A level change to tell the pilot about."""

    t_s: float
    level: str  # "suspect" | "fault"
    propellers: tuple[int, ...]  # 1..4; () for unlocalised vibration evidence
    text: str  # STATUSTEXT, <= 50 chars
    severity: int
    statistic: tuple[float, ...]  # S per propeller (nat-seconds)
    evidence: str  # "classifier", "vibration"
    hypotheses: tuple[tuple[tuple[int, ...], float], ...] = ()  # the flight's set when the model has a rule
    sets: tuple[tuple[int, ...], ...] = ()  # the candidate faulty sets the text names, most likely first

    def event(self) -> dict:
        return {
            "kind": "decision",
            "t_s": round(self.t_s, 3),
            "level": self.level,
            "faulty_propellers": list(self.propellers),
            "text": self.text,
            "severity": {2: "CRITICAL", 4: "WARNING", 5: "NOTICE"}[self.severity],
            "statistic": [round(s, 3) for s in self.statistic],
            "evidence": self.evidence,
            **({"hypothesis_sets": [list(s) for s in self.sets]} if len(self.sets) > 1 else {}),
            **(
                {"hypotheses": [{"faulty_propellers": list(h), "probability": round(p, 4)} for h, p in self.hypotheses]}
                if self.hypotheses
                else {}
            ),
        }


def propeller_text(props: tuple[int, ...]) -> str:
    return "+".join(map(str, props))


def statustext(level: str, sets: list[tuple[int, ...]], probability: float | None = None) -> str:
    """``PROP 3 FAULT p=0.97`` for one hypothesis; ``PROP 1 or 1+2?`` for several; <= 50 characters."""
    if len(sets) == 1:
        text = f"PROP {propeller_text(sets[0])} {'FAULT' if level == 'fault' else 'SUSPECT'}"
        if probability is not None and math.isfinite(probability):
            text += f" p={probability:.2f}"
        return text[:STATUSTEXT_MAX_CHARS]
    text = "PROP " + " or ".join(propeller_text(s) for s in sets) + "?"
    if len(text) > STATUSTEXT_MAX_CHARS:  # keep the most likely hypotheses whole
        keep: list[tuple[int, ...]] = []
        for s in sets:
            if len("PROP " + " or ".join(propeller_text(x) for x in [*keep, s]) + " or ...?") > STATUSTEXT_MAX_CHARS:
                break
            keep.append(s)
        text = "PROP " + " or ".join(propeller_text(x) for x in keep) + " or ...?"
    return text


class Decision:
    """The shared sequential rule. Feed every grid step (``step``) and every classified window (``window_evidence``)."""

    def __init__(
        self,
        cfg: DecisionConfig,
        rate_hz: float,
        window: int,
        model_sha256: str | None = None,
        calibration: Calibration | None = None,
        use_stored_calibration: bool = True,
    ):
        self.cfg = cfg
        self.rate_hz = rate_hz
        self.window = window
        self.window_s = window / rate_hz
        if calibration is None and use_stored_calibration:
            calibration = load_calibration(cfg.calibration_path or None)
        self.thresholds = thresholds(cfg, self.window_s, model_sha256, calibration)
        self._fault_statistics = fault_statistics(cfg)
        self._suspect_statistics = suspect_statistics(cfg)
        self.vibe_threshold = analytic_threshold(cfg.suspect_false_alarms_per_hour, self.window_s, 1)
        self.regime = RegimeTracker(cfg, rate_hz, window)
        self.vibration = VibrationEvidence()
        self.share = RotorShare(window, rate_hz, cfg.min_thrust_loss, average_s=SHARE_AVERAGE_S)
        self.S = {k: np.zeros(N_PROPS) for k in STATISTICS}
        self.peak = {k: np.zeros(N_PROPS) for k in STATISTICS}
        self.baseline: np.ndarray | None = None  # B_i, once learnt
        self._baseline_llr: list[np.ndarray] = []
        self._baseline_s = 0.0
        self.vibe_S = 0.0
        self.level = ["none"] * N_PROPS
        self.vibe_level = "none"
        self.pair_level = "none"  # the yaw balance: a same-spin diagonal pair (1+2 or 3+4)
        self.pair_sign = 0  # +1: the CCW pair's shares rose (1+2 first), -1: the CW pair's (3+4 first)
        self._pair_sets: list[tuple[int, ...]] | None = None  # what the yaw balance alone named when it last rose
        self._announced_rank = 0  # the highest level announced this flight (LEVELS index)
        self._last_window_t: float | None = None
        self._last_hypotheses: tuple | None = None
        self._last_p = np.full(N_PROPS, np.nan)
        self.paused_reason = ""
        self.windows = 0
        self.held_windows = 0
        # Seconds of windows whose omega^2 shares were tested against the flight's learnt baseline: 0 means the
        # shares never said anything either way (each flight first learns BASELINE_S of evidence), so "no alert" is
        # then no verdict at all, not one of health.
        self.tested_s = 0.0
        self.announcements: list[Announcement] = []
        self.trace: list | None = None  # offline calibration: ("add", {stat: increments}) / ("scale", factor)

    # -- inputs ------------------------------------------------------------------------------
    def step(self, t_s: float, s: StepInputs) -> None:
        event = self.regime.update(s)
        if not s.airborne:
            self._new_flight()
            return
        self.share.push(s.motor_rpm, s.vel_heading_m_s, s.accel_xy_frd_m_s2)
        if event == "collective_step":
            # Gathered about another vehicle state: keep half; the hold stops new evidence. Half is not measured:
            # chosen by hand between keeping all (evidence about the old mass) and none (a fault hidden by a
            # payload step); no command in the repository compares other factors.
            for v in self.S.values():
                v *= 0.5
            self._last_window_t = None
            self._forget_baseline()  # another mass: what the network says about it is learnt again
            self.share.reset()
            if self.trace is not None:
                self.trace.append(("scale", 0.5))
        elif event == "battery_sag":  # the network's statistics only (RegimeTracker.network_holding)
            for k in NETWORK_STATISTICS:
                self.S[k] *= 0.5  # as for a collective step: half, chosen by hand, not measured
            if self.trace is not None:
                self.trace.append(("scale", {k: 0.5 for k in NETWORK_STATISTICS}))

    def pause(self, reason: str) -> None:
        """A stream stopped: keep the statistics, add nothing until evidence flows again (``resume``)."""
        self.paused_reason = reason
        self._last_window_t = None

    def resume(self) -> None:
        self.paused_reason = ""

    def window_evidence(self, t_s: float, ev: WindowEvidence) -> list[Announcement]:
        """One classified window ending at ``t_s``; returns the level changes it causes."""
        self.windows += 1
        dt = 1.0 / self.rate_hz if self._last_window_t is None else t_s - self._last_window_t
        dt = min(max(dt, 0.0), self.window_s)
        self._last_window_t = t_s
        if self.regime.holding or self.paused_reason:
            self.held_windows += 1
            return []
        llr = window_llr(ev.fault_probability)
        self._last_p = np.asarray(ev.fault_probability, dtype=np.float64)
        # Evidence per independent sample (one share-averaging span), spread over the seconds this window covers.
        phys = self.share.llr(dt, quiet=not (self.S["physics"] > QUIET_NATS).any(), yaw_quiet=not self.S["pair"].any())
        inc = {}
        if self.regime.network_holding:  # a battery sag: the network's evidence waits, the shares' does not
            self.held_windows += 1
        else:
            inc["absolute"] = llr * dt
            if self.baseline is None:
                self._baseline_llr.append(llr)
                self._baseline_s += dt
                if self._baseline_s >= BASELINE_S:
                    self.baseline = np.maximum(np.median(np.stack(self._baseline_llr), axis=0), 0.0)
                    self._baseline_llr = []
            else:
                inc["change"] = (llr - self.baseline) * dt
        if phys is not None:
            self.tested_s += dt
            inc["physics"] = phys * (dt / self.share.average_s)
            ccw, cw = self.share.yaw_llr * (dt / YAW_AVERAGE_S)  # one independent sample per YAW_AVERAGE_S
            inc["pair"] = np.array([ccw, ccw, cw, cw])
        for k, v in inc.items():
            self.S[k] = np.maximum(0.0, self.S[k] + v)
            self.peak[k] = np.maximum(self.peak[k], self.S[k])
        if self.trace is not None:
            self.trace.append(("add", inc))
        if ev.hypotheses:
            self._last_hypotheses = ev.hypotheses
        return self._levels(t_s)

    def vibration_sample(self, t_s: float, values: tuple[float, float, float], airborne: bool) -> list[Announcement]:
        """One VIBRATION message (vibration_x, _y, _z); z is PX4's accelerometer vibration metric."""
        if self.vibration.validate(values):
            return []
        dt = 0.0 if self.vibration.last_t_s is None else min(max(t_s - self.vibration.last_t_s, 0.0), 1.0)
        r = self.vibration.observe(t_s, values[2], airborne)
        if r is None or self.regime.holding:  # its own stream: a stopped motor stream does not pause it
            return []
        self.vibe_S = max(0.0, self.vibe_S + (r - math.log(VIBE_MIN_RATIO)) * dt)
        if self.vibe_level == "none" and self.vibe_S >= self.vibe_threshold:
            self.vibe_level = "suspect"
            a = Announcement(t_s, "suspect", (), "VIBE HIGH PROP ?", MAV_SEVERITY_NOTICE, (self.vibe_S,), "vibration")
            self.announcements.append(a)
            return [a]
        return []

    # -- levels ------------------------------------------------------------------------------
    def _forget_baseline(self) -> None:
        self.baseline, self._baseline_llr, self._baseline_s = None, [], 0.0

    def _new_flight(self) -> None:
        if self.trace is not None and any(v.any() for v in self.S.values()):
            self.trace.append(("scale", 0.0))
        for v in self.S.values():
            v[:] = 0.0
        self.vibe_S = 0.0
        self._forget_baseline()
        self.share.reset()
        self.level = ["none"] * N_PROPS
        self.vibe_level = "none"
        self.pair_level, self.pair_sign = "none", 0
        self._pair_sets = None
        self._announced_rank = 0  # the highest level announced this flight (LEVELS index)
        self._last_window_t = None
        self._last_hypotheses = None
        self.vibration.reset()

    def levels_now(self) -> list[str]:
        """Each propeller's level from its own statistics alone (the highest of the three; the pair: ``pair_level_now``)."""
        th = self.thresholds
        # After a FAULT, the network's statistics raise no new suspect: the windows now carry the announced fault,
        # and a network trained on flights of one fixed condition spreads it over the other propellers (on 10 h of
        # onset flights of ours, 8 NOTICEs naming a healthy propeller, each after a correct fault; none before).
        # The omega^2 shares, whose baseline and noise model do not depend on the network, still may.
        suspect_by = ROTOR_STATISTICS if self._announced_rank < FAULT_RANK else ("physics",)
        out = []
        for i in range(N_PROPS):
            if any(self.S[k][i] >= th.fault[k] for k in self._fault_statistics if k in ROTOR_STATISTICS):
                out.append("fault")
            elif any(self.S[k][i] >= th.suspect[k] for k in suspect_by):
                out.append("suspect")
            else:
                out.append("none")
        return out

    def pair_level_now(self) -> tuple[str, int]:
        """The pair statistic's level and sign (+1: CCW pair's shares up, -1: CW pair's) from the statistic alone."""
        ccw, cw = float(self.S["pair"][0]), float(self.S["pair"][2])
        best, sign = (ccw, 1) if ccw >= cw else (cw, -1)
        if "pair" in self._fault_statistics and best >= self.thresholds.fault["pair"]:
            return "fault", sign
        if best >= self.thresholds.suspect["pair"]:
            return "suspect", sign
        return "none", 0

    def _levels(self, t_s: float) -> list[Announcement]:
        new = self.levels_now()
        new_pair, sign = self.pair_level_now()
        out = []
        for lvl in ("fault", "suspect"):
            rank = LEVELS.index(lvl)
            rising = [i for i in range(N_PROPS) if LEVELS.index(new[i]) >= rank > LEVELS.index(self.level[i])]
            pair_rising = LEVELS.index(new_pair) >= rank > LEVELS.index(self.pair_level)
            if not rising and not pair_rising:
                continue
            for i in rising:
                self.level[i] = lvl
            if pair_rising:
                self.pair_level, self.pair_sign = lvl, sign
                self._pair_sets = self._yaw_alone_sets()  # as the evidence stood when it rose (baselines follow later)
            at = tuple(i + 1 for i in range(N_PROPS) if LEVELS.index(self.level[i]) >= rank)
            if at and not rising and rank < self._announced_rank:
                # the yaw balance rose to suspect after a fault was announced on these propellers: a NOTICE after
                # the WARNING reads as a downgrade; its widening is told when it reaches fault (the status shows it)
                break
            if rising and rank < self._announced_rank:
                # a new propeller at suspect after a FAULT: the NOTICE names it alone ("PROP 4 SUSPECT" after
                # "PROP 2 FAULT", not "PROP 2+4 SUSPECT", which reads as a downgrade of rotor 2)
                at = tuple(i + 1 for i in rising)
                sets = [at]
            else:
                sets = self.hypothesis_sets(lvl, new)
            if not at:  # the pair statistic alone: both same-spin pairs are named, none is claimed
                at = tuple(sorted(set().union(*sets)))
            sev = MAV_SEVERITY_NOTICE if lvl == "suspect" else (MAV_SEVERITY_CRITICAL if len(at) > 1 else MAV_SEVERITY_WARNING)
            quoted = self._last_p[[i - 1 for i in at]]
            # the network's probability for a one-set fault, when it agrees (P >= 0.5): a FAULT the shares raised
            # read "PROP 2 FAULT p=0.01" where the network disagreed; none where it classified no window (all NaN)
            p = float(np.nanmax(quoted)) if len(sets) == 1 and lvl == "fault" and np.isfinite(quoted).any() else None
            p = p if p is not None and p >= 0.5 else None
            stat = tuple(float(max(self.S[k][i] / max(self.thresholds.fault[k], 1e-9) for k in STATISTICS)) for i in range(4))
            hyps = tuple(self._last_hypotheses or ())
            text = statustext(lvl, sets, p)
            out.append(Announcement(t_s, lvl, at, text, sev, stat, "classifier", hyps, tuple(sets)))
            self._announced_rank = max(self._announced_rank, rank)
            break  # one announcement per window: the highest level reached
        self.announcements += out
        return out

    def _pairs_by_sign(self) -> list[tuple[int, ...]]:
        return list(SAME_SPIN_PAIRS) if self.pair_sign >= 0 else list(reversed(SAME_SPIN_PAIRS))

    def _yaw_alone_sets(self) -> list[tuple[int, ...]]:
        """What the yaw balance alone names: both same-spin pairs (by the shift's sign) and the single rotor whose
        yaw-free share rose most (a small loss with a large torque change), first when its rise is beyond what
        healthy flights reach (``YAW_FREE_RISE``), then every other rotor whose rise is within ``YAW_FREE_GAP`` of
        it (the healthy spread of two rotors' rises: the evidence cannot tell them apart)."""
        pairs = self._pairs_by_sign()
        rise = self.share.yaw_free_rise()
        if rise is None or not np.isfinite(rise).all():
            return pairs
        order = [int(j) for j in np.argsort(-rise, kind="stable")]
        i = order[0]
        near = [(j + 1,) for j in order[1:] if rise[j] >= rise[i] - YAW_FREE_GAP]
        return [(i + 1,), *pairs, *near] if rise[i] >= YAW_FREE_RISE else [*pairs, (i + 1,), *near]

    def hypothesis_sets(self, level: str = "fault", now: list[str] | None = None) -> list[tuple[int, ...]]:
        """Candidate faulty sets, most likely first: the window's hypotheses when given, else from the levels.

        The pair statistic (yaw balance) alone, with no propeller at ``level``, is worded from physics whatever
        the window's hypotheses say (``_yaw_alone_sets``): both same-spin pairs (``1+2 or 3+4``, the one the yaw
        shift fits with drag torque scaling with thrust first) and the single whose yaw-free share rose most
        (``1 or 1+2 or 3+4`` when that rise is beyond healthy, else ``1+2 or 3+4 or 1``), then the singles whose
        rise is within ``YAW_FREE_GAP`` of that rotor's (``1+2 or 3+4 or 1 or 4``).
        Without hypotheses: the propellers at ``level``, widened by those at suspect level now (a same-spin
        partner that is only suspected makes ``1`` into ``1 or 1+2``). The pair statistic adds the
        same-spin pair of a single propeller (``1`` -> ``1 or 1+2``: the evidence cannot tell them apart).
        """
        now = now or self.levels_now()
        rank = LEVELS.index(level)
        core = tuple(i + 1 for i in range(N_PROPS) if LEVELS.index(self.level[i]) >= rank)
        if not core and LEVELS.index(self.pair_level) >= rank:  # physics raised it: physics words it
            return list(self._pair_sets)  # set in _levels whenever the pair level rises
        # The network's recent set words a level the network raised: it may raise it (alerts.suspect_evidence /
        # fault_evidence "all") and one of its statistics is at the level on a propeller called. A level physics
        # raised is worded by physics, which is the wording `propwatch evaluate alerts` scores (it replays no set).
        allowed = self._fault_statistics if level == "fault" else self._suspect_statistics
        at_level = self.thresholds.fault if level == "fault" else self.thresholds.suspect
        network_raised = any(self.S[k][i - 1] >= at_level[k] for k in ("absolute", "change") if k in allowed for i in core)
        if self._last_hypotheses and network_raised:
            sets = [tuple(sorted(h)) for h, _ in sorted(self._last_hypotheses, key=lambda x: -x[1]) if h]
            sets = [s for s in sets if set(core) & set(s)] or sets
            return sets[:4] or [core]
        if not core:
            return [core]
        wide = tuple(i + 1 for i in range(N_PROPS) if self.level[i] != "none" or now[i] != "none")
        sets = [core] if wide == core else [core, wide]
        # A second rotor whose yaw-free share rose beyond healthy over the last 10 s (a smaller loss than the
        # called one's, below the statistic's reference): the called rotor with it is a hypothesis too.
        rise = self.share.yaw_free_rise()
        if rise is not None and np.isfinite(rise).all():
            risen = tuple(sorted(set(core) | {j + 1 for j in range(N_PROPS) if rise[j] >= YAW_FREE_RISE}))
            if risen not in sets:
                sets.append(risen)
        if self.pair_level != "none" and len(core) == 1:
            pair = next(p for p in SAME_SPIN_PAIRS if core[0] in p)
            if pair not in sets:
                sets.append(pair)
        return sets

    # -- reporting ---------------------------------------------------------------------------
    def verdict(self) -> dict:
        """The current decision for reports and events."""
        faulty = [i + 1 for i in range(N_PROPS) if self.level[i] == "fault"]
        suspect = [i + 1 for i in range(N_PROPS) if self.level[i] == "suspect"]
        r3 = lambda a: [round(float(x), 3) for x in a]  # noqa: E731
        fault = bool(faulty) or self.pair_level == "fault"
        sus = bool(suspect) or self.vibe_level == "suspect" or self.pair_level == "suspect"
        lvl = "fault" if fault else "suspect" if sus else "none"
        return {
            "level": lvl,
            "faulty_propellers": faulty,
            "suspect_propellers": suspect,
            "pair": self.pair_level,  # the yaw balance: a same-spin diagonal pair (1+2 or 3+4)
            "hypothesis_sets": [list(s) for s in self.hypothesis_sets(lvl) if s] if lvl != "none" else [],
            "vibration": self.vibe_level,
            "statistic": {k: r3(v) for k, v in self.S.items()},
            "peak_statistic": {k: r3(v) for k, v in self.peak.items()},
            "baseline_llr": None if self.baseline is None else r3(self.baseline),
            "thresholds": self.thresholds.as_dict(),
            "windows": self.windows,
            "held_windows": self.held_windows,
            "tested_s": round(self.tested_s, 2),
            "regime_events": dict(self.regime.counts),
            "vibration_rejected": dict(self.vibration.rejected),
        }
