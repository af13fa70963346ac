"""The decision rule's thresholds: from the configured false-alarm rates, calibrated or Wald's bound.

Part of the decision rule (``monitor.decision``; its docstring states how thresholds follow the rates). Also the
calibration file (``models/decision-calibration.json``, written by ``propwatch tune alerts``, ``offline.tune.alerts``) and the
description of the statistic forms a calibration holds for.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from monitor.decision.config import DecisionConfig
from monitor.decision.regime import COLLECTIVE_SHIFT_S
from monitor.decision.rotor_share import (
    FLAP_SLOPE_Q,
    PLANE_CUT,
    QUIET_NATS,
    SAME_SPIN_PAIRS,
    SHARE_AVERAGE_S,
    SHARE_SIGMA,
    YAW_AVERAGE_S,
    YAW_SIGMA,
)
from monitor.errors import ConfigError
from monitor.labels import N_PROPS
from monitor.resources import shipped

SECONDS_PER_HOUR = 3600.0
# The checkout's models/decision-calibration.json, or the installed package data (monitor/resources.py).
DEFAULT_CALIBRATION = shipped("decision-calibration.json")
STATISTICS = ("absolute", "change", "physics", "pair")
ROTOR_STATISTICS = ("absolute", "change", "physics")  # evidence about one propeller each


@dataclass(frozen=True)
class Calibration:
    """Per statistic, the exceedance-rate tail ``ln(rate per flight-hour) = a - b * h`` on healthy flights;
    ``None`` for a statistic the calibration disabled (its crossings do not fall off exponentially).

    ``peaks``: per statistic, the highest value any calibration flight reached. A rate rarer than one per
    calibrated flight-time cannot be shown by those flights, so its threshold is at least above all of them.

    ``bootstrap``: per statistic, the tail fitted on resamples of the calibration flights (``(a, b)`` each; a
    resample with no tail to fit is in ``bootstrap_failed`` and counts as an infinite threshold). When present,
    a rate's threshold is the ``confidence`` quantile of the resamples' thresholds, not the point fit's: a point
    fit of a thin tail moved the fault threshold by 0.7 nat-s between 5 and 10 calibration hours, and that was
    the difference between 0 and 17 false FAULTs on another simulator (offline/tune/alerts.py).
    """

    fits: dict  # statistic -> (a, b) | None
    model_sha256: str
    provenance: dict = field(default_factory=dict)
    peaks: dict = field(default_factory=dict)  # statistic -> highest healthy value (nat-s or nats)
    bootstrap: dict = field(default_factory=dict)  # statistic -> np.ndarray (k, 2) of (a, b)
    bootstrap_failed: dict = field(default_factory=dict)  # statistic -> resamples with no tail
    confidence: float | None = None

    def threshold(self, statistic: str, rate_per_hour: float) -> float:
        fit = self.fits.get(statistic)
        if fit is None:
            return math.inf
        a, b = fit
        h = max((a - math.log(rate_per_hour)) / b, 0.0)
        boot = self.bootstrap.get(statistic)
        if boot is not None and self.confidence is not None and len(boot):
            failed = int(self.bootstrap_failed.get(statistic, 0))
            hs = np.concatenate([(boot[:, 0] - math.log(rate_per_hour)) / boot[:, 1], np.full(failed, np.inf)])
            h = max(float(np.quantile(hs, self.confidence, method="higher")), 0.0)
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
        fits, peaks, boot, failed = {}, {}, {}, {}
        for name in STATISTICS:
            if name == "pair" and name not in d["fits"]:  # a file from before the pair statistic: Wald's bound for it
                continue
            f = d["fits"][name]
            fits[name] = None if f is None else (float(f["a"]), float(f["b"]))
            if f is not None and f.get("h_max_healthy") is not None:
                peaks[name] = float(f["h_max_healthy"])
            if f is not None and f.get("bootstrap_ab") is not None:  # files from before the bootstrap: point fit
                boot[name] = np.asarray(f["bootstrap_ab"], dtype=np.float64).reshape(-1, 2)
                failed[name] = int(f.get("bootstrap_failed", 0))
        confidence = d.get("confidence")
        cal = Calibration(
            fits,
            str(d["model_sha256"]),
            d.get("provenance", {}),
            peaks,
            boot,
            failed,
            None if confidence is None else float(confidence),
        )
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ConfigError(f"{path}: not a decision calibration: {exc}") from exc
    for name, fit in cal.fits.items():
        if fit is not None and not (math.isfinite(fit[0]) and math.isfinite(fit[1]) and fit[1] > 0):
            raise ConfigError(f"{path}: fit '{name}' needs finite a and b > 0, got {fit}")
    for name, ab in cal.bootstrap.items():
        if not (np.isfinite(ab).all() and (ab[:, 1] > 0).all()):
            raise ConfigError(f"{path}: fit '{name}': every bootstrap draw needs finite a and b > 0")
    if cal.confidence is not None and not 0.5 <= cal.confidence < 1.0:
        raise ConfigError(f"{path}: confidence must lie in [0.5, 1), got {cal.confidence}")
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
        source = f"calibrated on {hours} healthy flight-hours (exponential tail"
        if calibration.bootstrap and calibration.confidence is not None:
            source += f", {100 * calibration.confidence:.0f} % flight bootstrap"
        source += ")"
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
        # v3: the baseline spans BASELINE_S of evidence windows; v4: its plane learns trimmed means; v5: windows are
        # held while the collective RPM stands apart (monitor.decision.regime.COLLECTIVE_SHIFT_S); v6: the plane's slopes drift
        # a tenth as fast (monitor.decision.rotor_share.FLAP_SLOPE_Q); v7: it learns while every statistic is below QUIET_NATS
        "form": "share-cusum-v7",
        "min_thrust_loss": cfg.min_thrust_loss,
        "share_sigma": SHARE_SIGMA,
        "share_average_s": SHARE_AVERAGE_S,
        "plane_cut": PLANE_CUT,
        "collective_shift_s": COLLECTIVE_SHIFT_S,
        "flap_slope_q_per_s": FLAP_SLOPE_Q,
        "quiet_nats": QUIET_NATS,
    }


def pair_statistic(cfg: DecisionConfig) -> dict:
    """What a pair-statistic calibration holds for (reference and noise model of the yaw balance)."""
    noise = {"yaw_sigma": YAW_SIGMA, "yaw_average_s": YAW_AVERAGE_S}
    # v2: its baseline as the shares'; v3: held as the shares are while the collective RPM stands apart
    form = {"form": "yaw-balance-cusum-v3", "min_thrust_loss": cfg.min_thrust_loss}
    return {**form, **noise, "collective_shift_s": COLLECTIVE_SHIFT_S}


def file_sha256(path: str | Path) -> str:
    """The model file's digest: a calibration belongs to exactly one model."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
