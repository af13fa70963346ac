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
weak motor it never saw: issue 12) keeps ``A`` growing on every such flight;
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
  relation, ARL0 ~ e^(b h)); so ``h = (a - ln rate) / b``. A statistic whose
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
(tilt or body rate beyond the training envelope), a collective step (payload
drop or pick-up) or battery sag add nothing, and a collective step or a sag
also halves what was gathered before it (it was evidence about another
vehicle state; a collective step also re-learns the baselines). A stopped
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
"""

from __future__ import annotations

import hashlib
import json
import math
import statistics
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from monitor.errors import ConfigError
from monitor.labels import N_PROPS
from monitor.resources import shipped

LEVELS = ("none", "suspect", "fault")
FAULT_RANK = LEVELS.index("fault")
LLR_CLIP = math.log(0.999 / 0.001)  # |logit P| beyond P = 0.999 is the network's over-confidence, not evidence
STATUSTEXT_MAX_CHARS = 50
MAV_SEVERITY_CRITICAL, MAV_SEVERITY_WARNING, MAV_SEVERITY_NOTICE = 2, 4, 5
SECONDS_PER_HOUR = 3600.0
VIBE_MAX_M_S2 = 100.0  # a vibration metric beyond this is a sensor fault, not a propeller
FROZEN_REPEATS = 20  # identical float readings in a row: a stuck stream
VIBE_BASELINE_S = 10.0  # airborne seconds that define the flight's own vibration level
BASELINE_S = 10.0  # classified seconds that define the airframe's own baseline evidence
COLLECTIVE_MEDIAN_S = 10.0  # a collective step compares the median mean RPM of two such spans (manoeuvres average out)
VIBE_MIN_RATIO = 1.5  # CUSUM reference: the smallest rise over baseline worth calling (log-ratio drift)
# The checkout's models/decision-calibration.json, or the installed package data (monitor/resources.py).
DEFAULT_CALIBRATION = shipped("decision-calibration.json")


def _check(cond: bool, key: str, msg: str) -> None:
    if not cond:
        raise ConfigError(f"{key}: {msg}")


@dataclass(frozen=True)
class DecisionConfig:
    """The decision rule's settings (``alerts:`` in the monitor YAML; diagnose uses the defaults)."""

    false_alarms_per_hour: float = 0.1  # fault level: the target rate on healthy flights
    # Suspect level (a NOTICE): may be wrong more often. 1.0/h (was 2.0/h): fewer NOTICEs a pilot learns to ignore
    # (models/decision-evaluation.md measures both).
    suspect_false_alarms_per_hour: float = 1.0
    faulty_probability: float = 0.9  # diagnose: FAULTY only when the chosen label's probability reaches this
    aggressive_tilt_deg: float = 45.0  # beyond: outside the training envelope (diagnose warns at the same angle)
    aggressive_rate_deg_s: float = 200.0
    # Change of the 10-s median mean RPM between consecutive 10 s: a payload drop or pick-up. On 4.7 h of randomised
    # healthy flights of our simulator manoeuvres moved it by at most 6.1 % (99 % of flights < 4.4 %); payload steps
    # of >= 20 % of the mass by >= 10.6 % (bench/alerts_flights.py data; 0.07 ~ a 15 % mass step).
    collective_step_fraction: float = 0.07
    battery_sag_fraction: float = 0.04  # pack voltage lost within one window
    # The smallest per-rotor thrust loss the omega^2-share evidence must call (issue 13: >= 8 % alerted): the
    # CUSUM's reference is half of its share shift, so smaller excursions (manoeuvres, gusts) add nothing.
    min_thrust_loss: float = 0.08
    # Which statistics may raise FAULT: "physics" (the omega^2 shares alone; the network's statistics raise at most
    # suspect) or "all". Default physics: on our own randomised flights the network adds one pair in 25 at fault
    # level, while on airframes it never saw (drawn motor spread and CG) it flips to P ~ 1 mid-flight and is
    # confidently wrong (docs/ALERTS.md).
    fault_evidence: str = "physics"
    # Which statistics may raise SUSPECT: "all" (the network's too) or "physics" (the omega^2 shares and the yaw
    # balance alone; the network then only words). On 10 classified healthy hours per simulator the network's
    # statistics raised every healthy NOTICE and no detection the shares did not make; but with the suspect rate
    # shared by two statistics instead of four, the physics ones raise 4.2 NOTICEs/h on the evaluation-only
    # simulator (0.0/h at a 0.5/h target): models/decision-evaluation.md. Default "all".
    suspect_evidence: str = "all"
    calibration_path: str = ""  # '' = models/decision-calibration.json

    def __post_init__(self) -> None:
        for key in ("false_alarms_per_hour", "suspect_false_alarms_per_hour"):
            v = getattr(self, key)
            _check(1e-4 <= v <= 1e3, f"alerts.{key}", f"must be in [0.0001, 1000] per flight-hour, got {v}")
        _check(
            self.suspect_false_alarms_per_hour >= self.false_alarms_per_hour,
            "alerts.suspect_false_alarms_per_hour",
            "must be >= alerts.false_alarms_per_hour (suspect comes before fault)",
        )
        _check(0.5 <= self.faulty_probability < 1.0, "alerts.faulty_probability", "must be in [0.5, 1)")
        _check(0 < self.aggressive_tilt_deg <= 90, "alerts.aggressive_tilt_deg", "must be in (0, 90]")
        _check(0 < self.aggressive_rate_deg_s <= 2000, "alerts.aggressive_rate_deg_s", "must be in (0, 2000]")
        _check(0 < self.collective_step_fraction <= 1, "alerts.collective_step_fraction", "must be in (0, 1]")
        _check(0 < self.battery_sag_fraction <= 1, "alerts.battery_sag_fraction", "must be in (0, 1]")
        _check(0.01 <= self.min_thrust_loss <= 0.5, "alerts.min_thrust_loss", "must be in [0.01, 0.5]")
        _check(self.fault_evidence in ("physics", "all"), "alerts.fault_evidence", "must be 'physics' or 'all'")
        _check(self.suspect_evidence in ("physics", "all"), "alerts.suspect_evidence", "must be 'physics' or 'all'")
        _check(
            not (self.fault_evidence == "all" and self.suspect_evidence == "physics"),
            "alerts.suspect_evidence",
            "'physics' with fault_evidence 'all' would let the network fault but not suspect",
        )


# -- thresholds -----------------------------------------------------------------------------
STATISTICS = ("absolute", "change", "physics", "pair")
ROTOR_STATISTICS = ("absolute", "change", "physics")  # evidence about one propeller each
# The pair statistic's vector is (CCW up, CCW up, CW up, CW up): index i holds the evidence for i's same-spin pair.
SAME_SPIN_PAIRS = ((1, 2), (3, 4))  # PX4 quad-X: 1, 2 CCW (diagonal), 3, 4 CW (diagonal)


@dataclass(frozen=True)
class Calibration:
    """Per statistic, the exceedance-rate tail ``ln(rate per flight-hour) = a - b * h`` on healthy flights;
    ``None`` for a statistic the calibration disabled (its crossings do not fall off exponentially).

    ``peaks``: per statistic, the highest value any calibration flight reached. A rate rarer than one per
    calibrated flight-time cannot be shown by those flights, so its threshold is at least above all of them.
    """

    fits: dict  # statistic -> (a, b) | None
    model_sha256: str
    provenance: dict = field(default_factory=dict)
    peaks: dict = field(default_factory=dict)  # statistic -> highest healthy value (nat-s or nats)

    def threshold(self, statistic: str, rate_per_hour: float) -> float:
        fit = self.fits.get(statistic)
        if fit is None:
            return math.inf
        a, b = fit
        h = max((a - math.log(rate_per_hour)) / b, 0.0)
        hours = float(self.provenance.get("flight_hours") or 0.0)
        peak = self.peaks.get(statistic)
        if peak is not None and rate_per_hour * hours < 1.0:
            h = max(h, peak * (1.0 + 1e-6))
        return h


def analytic_threshold(rate_per_hour: float, window_s: float, n_props: int = N_PROPS) -> float:
    """Wald's bound with one independent sample per window length (see the module doc)."""
    samples_per_hour = SECONDS_PER_HOUR / window_s
    return window_s * math.log(n_props * samples_per_hour / rate_per_hour)


def load_calibration(path: str | Path | None = None) -> Calibration | None:
    """The stored calibration, or None when there is none; a malformed file is an error naming it."""
    path = Path(path) if path else DEFAULT_CALIBRATION
    if not path.is_file():
        return None
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
        fits, peaks = {}, {}
        for name in STATISTICS:
            if name == "pair" and name not in d["fits"]:  # a file from before the pair statistic: Wald's bound for it
                continue
            f = d["fits"][name]
            fits[name] = None if f is None else (float(f["a"]), float(f["b"]))
            if f is not None and f.get("h_max_healthy") is not None:
                peaks[name] = float(f["h_max_healthy"])
        cal = Calibration(fits, str(d["model_sha256"]), d.get("provenance", {}), peaks)
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ConfigError(f"{path}: not a decision calibration: {exc}") from exc
    for name, fit in cal.fits.items():
        if fit is not None and not (math.isfinite(fit[0]) and math.isfinite(fit[1]) and fit[1] > 0):
            raise ConfigError(f"{path}: fit '{name}' needs finite a and b > 0, got {fit}")
    return cal


@dataclass(frozen=True)
class Thresholds:
    suspect: dict  # statistic -> nat-seconds (inf = disabled)
    fault: dict
    source: str

    def as_dict(self) -> dict:
        r = lambda v: None if math.isinf(v) else round(v, 3)  # noqa: E731
        return {
            "suspect": {k: r(v) for k, v in self.suspect.items()},
            "fault": {k: r(v) for k, v in self.fault.items()},
            "source": self.source,
        }


PHYSICS_STATISTICS = ("physics", "pair")  # the omega^2 shares and the yaw balance: no network


def fault_statistics(cfg: DecisionConfig) -> tuple[str, ...]:
    """The statistics that may raise FAULT (``alerts.fault_evidence``)."""
    return STATISTICS if cfg.fault_evidence == "all" else PHYSICS_STATISTICS


def suspect_statistics(cfg: DecisionConfig) -> tuple[str, ...]:
    """The statistics that may raise SUSPECT (``alerts.suspect_evidence``)."""
    return STATISTICS if cfg.suspect_evidence == "all" else PHYSICS_STATISTICS


def thresholds(
    cfg: DecisionConfig, window_s: float, model_sha256: str | None = None, calibration: Calibration | None = None
) -> Thresholds:
    """Thresholds for the configured rates: calibrated when the file is this model's.

    A level's rate is shared equally by the statistics that may raise it (those of ``alerts.suspect_evidence``,
    of ``alerts.fault_evidence``), so their false alarms add up to at most the configured rate. A statistic that
    may not raise suspect has an infinite suspect threshold.
    """
    allowed = {"suspect": suspect_statistics(cfg), "fault": fault_statistics(cfg)}
    rates = {
        lvl: rate / len(allowed[lvl])
        for lvl, rate in (("suspect", cfg.suspect_false_alarms_per_hour), ("fault", cfg.false_alarms_per_hour))
    }
    th = _thresholds(cfg, window_s, rates, model_sha256, calibration)
    for st in STATISTICS:
        if st not in allowed["suspect"]:
            th.suspect[st] = math.inf  # (a fault statistic not allowed keeps its number: levels_now skips it)
    return th


def _thresholds(cfg: DecisionConfig, window_s: float, rates: dict, model_sha256, calibration) -> Thresholds:
    """Every statistic's threshold at each level's per-statistic rate (``rates``): calibrated or Wald's bound."""

    def wald(st: str, r: float) -> float:
        # The share statistics count nats per independent sample (SHARE_AVERAGE_S of shares), the others nat-seconds;
        # the pair statistic is two one-sided tests (CCW pair up, CW pair up).
        if st == "physics":
            return analytic_threshold(r, SHARE_AVERAGE_S) / SHARE_AVERAGE_S
        if st == "pair":
            return analytic_threshold(r, YAW_AVERAGE_S, n_props=len(SAME_SPIN_PAIRS)) / YAW_AVERAGE_S
        return analytic_threshold(r, window_s)

    analytic = {lvl: {st: wald(st, r) for st in STATISTICS} for lvl, r in rates.items()}
    if calibration is not None and (model_sha256 is None or calibration.model_sha256 == model_sha256):
        hours = calibration.provenance.get("flight_hours")
        th = {lvl: {st: calibration.threshold(st, r) for st in STATISTICS} for lvl, r in rates.items()}
        source = f"calibrated on {hours} healthy flight-hours (exponential tail)"
        if calibration.provenance.get("physics_statistic") != physics_statistic(cfg):
            for lvl in th:  # calibrated for another share statistic (reference, noise model): Wald's bound instead
                th[lvl]["physics"] = analytic[lvl]["physics"]
            source += "; physics: analytic (calibrated for another min_thrust_loss or share statistic)"
        if "pair" not in calibration.fits or calibration.provenance.get("pair_statistic") != pair_statistic(cfg):
            for lvl in th:
                th[lvl]["pair"] = analytic[lvl]["pair"]
            source += "; pair: analytic (not calibrated for this pair statistic)"
        else:
            # The yaw balance rests on what our simulator models least (yaw drag and rotor inflow with airspeed,
            # blade flapping: not modelled, assumption register), and its calibrated tail on a handful of
            # crossings: its thresholds never go below Wald's bound for the same rate.
            for lvl in th:
                th[lvl]["pair"] = max(th[lvl]["pair"], analytic[lvl]["pair"])
            source += "; pair: not below Wald's bound"
        return Thresholds(th["suspect"], th["fault"], source)
    return Thresholds(analytic["suspect"], analytic["fault"], "analytic (Wald bound, one sample per window)")


def physics_statistic(cfg: DecisionConfig) -> dict:
    """What a physics-statistic calibration holds for: its thresholds mean nothing for another reference or noise model."""
    return {
        "form": "share-cusum-v3",  # v3: the baseline spans BASELINE_S of evidence windows, not of flight
        "min_thrust_loss": cfg.min_thrust_loss,
        "share_sigma": SHARE_SIGMA,
        "share_average_s": SHARE_AVERAGE_S,
    }


def pair_statistic(cfg: DecisionConfig) -> dict:
    """What a pair-statistic calibration holds for (reference and noise model of the yaw balance)."""
    noise = {"yaw_sigma": YAW_SIGMA, "yaw_average_s": YAW_AVERAGE_S}
    return {"form": "yaw-balance-cusum-v2", "min_thrust_loss": cfg.min_thrust_loss, **noise}  # v2: its baseline as the shares'


def _clip_llr(llr: np.ndarray) -> np.ndarray:
    """np.clip(llr, -LLR_CLIP, LLR_CLIP), NaN kept, without np.clip's Python-level wrappers (every window)."""
    return np.minimum(np.maximum(llr, -LLR_CLIP), LLR_CLIP)


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
class StepInputs:
    """One grid step's flight state, for the regime tracker (NaN where unknown)."""

    airborne: bool
    mean_rpm: float = math.nan
    tilt_rad: float = math.nan
    rate_rad_s: float = math.nan  # largest |body rate|
    battery_v: float = math.nan
    motor_rpm: np.ndarray | None = None  # (4,) per-rotor RPM, PX4 order (commanded, or ESC telemetry)


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


# -- regimes ----------------------------------------------------------------------------------
class RegimeTracker:
    """Per-step state -> (hold the next windows, discount what was gathered), see the module doc."""

    def __init__(self, cfg: DecisionConfig, rate_hz: float, window: int):
        self.cfg = cfg
        self.window = window
        self.rate_hz = rate_hz
        self._median_n = max(int(round(COLLECTIVE_MEDIAN_S * rate_hz)), 1)
        self._rpm: deque[float] = deque(maxlen=2 * self._median_n)  # the last 2 x 10 s of mean RPM (collective step)
        self._volts: deque[float] = deque(maxlen=window)
        self._n = 0
        self.hold_until_step = 0
        self.step = 0
        self.counts = {"aggressive": 0, "collective_step": 0, "battery_sag": 0, "landed": 0}
        self.last_reason = ""
        self._tilt_max = math.radians(cfg.aggressive_tilt_deg)
        self._rate_max = math.radians(cfg.aggressive_rate_deg_s)
        self._check_every = max(window // 5, 1)

    def reset(self) -> None:
        self._rpm.clear()
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
            self._rpm.append(s.mean_rpm)
        if math.isfinite(s.battery_v):
            self._volts.append(s.battery_v)
        event = ""
        c = self.cfg
        if s.tilt_rad > self._tilt_max or s.rate_rad_s > self._rate_max:
            event = "aggressive"
        elif len(self._rpm) == 2 * self._median_n and self._n % self._check_every == 0:
            rpm = list(self._rpm)
            old, new = statistics.median(rpm[: self._median_n]), statistics.median(rpm[self._median_n :])
            if old > 0 and abs(new - old) / old > c.collective_step_fraction:
                event = "collective_step"
                self._rpm.clear()  # measure the next step from the new level
        if not event and len(self._volts) == self.window:
            v0, v1 = self._volts[0], self._volts[-1]
            if v0 > 0 and (v0 - v1) / v0 > c.battery_sag_fraction:
                event = "battery_sag"
                self._volts.clear()
        if event:
            self.counts[event] += 1
            self.last_reason = event
            self.hold_until_step = self.step + self.window
        return event

    @property
    def holding(self) -> bool:
        return self.step < self.hold_until_step


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


# -- vibration --------------------------------------------------------------------------------
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


def file_sha256(path: str | Path) -> str:
    """The model file's digest: a calibration belongs to exactly one model."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# -- the decision -----------------------------------------------------------------------------
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
        self.announcements: list[Announcement] = []
        self.trace: list | None = None  # offline calibration: ("add", {stat: increments}) / ("scale", factor)

    # -- inputs ------------------------------------------------------------------------------
    def step(self, t_s: float, s: StepInputs) -> None:
        event = self.regime.update(s)
        if not s.airborne:
            self._new_flight()
            return
        self.share.push(s.motor_rpm)
        if event in ("collective_step", "battery_sag"):
            for v in self.S.values():
                v *= 0.5  # gathered about another vehicle state: keep half; the hold stops new evidence
            self._last_window_t = None
            if event == "collective_step":  # another mass: what the network says about it is learnt again
                self._forget_baseline()
                self.share.reset()
            if self.trace is not None:
                self.trace.append(("scale", 0.5))

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
        phys = self.share.llr(dt, quiet=not self.S["physics"].any(), yaw_quiet=not self.S["pair"].any())
        inc = {"absolute": llr * dt}
        if self.baseline is None:
            self._baseline_llr.append(llr)
            self._baseline_s += dt
            if self._baseline_s >= BASELINE_S:
                self.baseline = np.maximum(np.median(np.stack(self._baseline_llr), axis=0), 0.0)
                self._baseline_llr = []
        else:
            inc["change"] = (llr - self.baseline) * dt
        if phys is not None:
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
            sets = self.hypothesis_sets(lvl, new)
            if not at:  # the pair statistic alone: both same-spin pairs are named, none is claimed
                at = tuple(sorted(set().union(*sets)))
            sev = MAV_SEVERITY_NOTICE if lvl == "suspect" else (MAV_SEVERITY_CRITICAL if len(at) > 1 else MAV_SEVERITY_WARNING)
            quoted = self._last_p[[i - 1 for i in at]]
            # the network's probability for a one-set fault; none where it classified no window (all NaN)
            p = float(np.nanmax(quoted)) if len(sets) == 1 and lvl == "fault" and np.isfinite(quoted).any() else None
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
        healthy flights reach (``YAW_FREE_RISE``)."""
        pairs = self._pairs_by_sign()
        rise = self.share.yaw_free_rise()
        if rise is None or not np.isfinite(rise).all():
            return pairs
        i = int(np.argmax(rise))
        return [(i + 1,), *pairs] if rise[i] >= YAW_FREE_RISE else [*pairs, (i + 1,)]

    def hypothesis_sets(self, level: str = "fault", now: list[str] | None = None) -> list[tuple[int, ...]]:
        """Candidate faulty sets, most likely first: the window's hypotheses when given, else from the levels.

        The pair statistic (yaw balance) alone, with no propeller at ``level``, is worded from physics whatever
        the window's hypotheses say (``_yaw_alone_sets``): both same-spin pairs (``1+2 or 3+4``, the one the yaw
        shift fits with drag torque scaling with thrust first) and the single whose yaw-free share rose most
        (``1 or 1+2 or 3+4`` when that rise is beyond healthy, else ``1+2 or 3+4 or 1``).
        Without hypotheses: the propellers at ``level``, widened by those at suspect level now (a same-spin
        partner that is only suspected makes ``1`` into ``1 or 1+2``). The pair statistic adds the
        same-spin pair of a single propeller (``1`` -> ``1 or 1+2``: the evidence cannot tell them apart).
        """
        now = now or self.levels_now()
        rank = LEVELS.index(level)
        core = tuple(i + 1 for i in range(N_PROPS) if LEVELS.index(self.level[i]) >= rank)
        if not core and LEVELS.index(self.pair_level) >= rank:  # physics raised it: physics words it
            return list(self._pair_sets)  # set in _levels whenever the pair level rises
        # The network's recent set words a level the network may raise (alerts.suspect_evidence / fault_evidence
        # "all"); a level only physics raises is worded by physics (the evaluation of issue 13 scores that wording).
        network_raises = "absolute" in (self._fault_statistics if level == "fault" else self._suspect_statistics)
        if self._last_hypotheses and network_raises:
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
            "regime_events": dict(self.regime.counts),
            "vibration_rejected": dict(self.vibration.rejected),
        }
