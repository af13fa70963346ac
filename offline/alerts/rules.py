"""Alert rules replayed over one flight's window outputs -> the alerts they would raise.

Times: step j of a flight is at (j + 1) / rate s; window k (hop 1) ends at step
k + window - 1. Every rule returns ``[(t_s, level, propellers)]`` or
``[(t_s, level, propellers, sets)]`` (``sets``: the candidate faulty sets the
alert names, e.g. ``((1,), (1, 2))`` for ``PROP 1 or 1+2?``); an empty
propeller tuple is an alert that names none (vibration metrics).

* ``decision``: ``monitor.decision.rule.Decision``, the shipped rule, fed step by step as the daemon feeds it.
* ``consecutive``: the comparison rule (``offline.classifier.consecutive``: P >= 0.9 in 20 windows in a row).
* ``px4_imbalance``: PX4's imbalanced-propeller check (commander FailureDetector::updateImbalancedPropStatus):
  metric = (std(acc_x) + std(acc_y)) / 2 - std(acc_z) from vehicle_imu_status.var_accel, low-passed with a
  5 s time constant, flagged above FD_IMB_PROP_THR (default 30). Here the variances come from the 20 Hz
  accelerometer samples over each second (PX4 uses the raw IMU rate; the 1P ripple folds into 20 Hz
  samples with its variance intact, manoeuvre accelerations are in both).
"""

from __future__ import annotations

import math

import numpy as np

from monitor.decision.config import DecisionConfig
from monitor.decision.replay import replay
from monitor.decision.rule import Decision, WindowEvidence
from offline.alerts.flights import AlertFlight
from offline.classifier.consecutive import ConsecutiveConfig, replay_consecutive

PX4_FD_IMB_PROP_THR = 30.0  # PX4 parameter FD_IMB_PROP_THR default
PX4_IMB_LPF_TAU_S = 5.0  # FailureDetector _imbalanced_prop_lpf_time_constant


def replay_decision(f: AlertFlight, decision: Decision, with_sets: bool = False) -> list[tuple]:
    """``[(t_s, level, propellers)]``, with each alert's candidate sets as a fourth element when ``with_sets``: the
    flight through ``monitor.decision.replay`` (window k ends at step k + window - 1; step j at (j + 1) / rate)."""
    w = f.window
    t_s = (np.arange(len(f.mean_rpm)) + 1) / f.rate_hz
    evidence = {k + w - 1: WindowEvidence(p) for k, p in enumerate(f.fault_probability)}
    out = []
    for a in replay(decision, f.steps(), t_s, evidence):
        sets = tuple(getattr(a, "sets", ())) or (a.propellers,)
        out.append((a.t_s, a.level, a.propellers, sets) if with_sets else (a.t_s, a.level, a.propellers))
    return out


def decision_rule(cfg: DecisionConfig, calibration=None, use_stored: bool = True):
    def run(f: AlertFlight):
        d = Decision(cfg, f.rate_hz, f.window, calibration=calibration, use_stored_calibration=use_stored)
        return replay_decision(f, d, with_sets=True)

    return run


def consecutive_rule(cfg: ConsecutiveConfig):
    def run(f: AlertFlight):
        return [(t, "fault", props) for t, props in replay_consecutive(f.fault_probability, f.rate_hz, f.window, cfg)]

    return run


def px4_imbalance_metric(f: AlertFlight) -> tuple[np.ndarray, np.ndarray]:
    """(t_s, low-passed metric) once per second."""
    n = int(f.rate_hz)
    blocks = len(f.accel_frd_m_s2) // n
    acc = f.accel_frd_m_s2[: blocks * n].reshape(blocks, n, 3)
    std = np.sqrt(np.maximum(acc.var(axis=1), 0.0))
    metric = (std[:, 0] + std[:, 1]) / 2.0 - std[:, 2]
    alpha = 1.0 / (1.0 + PX4_IMB_LPF_TAU_S / 1.0)  # AlphaFilter with dt = 1 s
    lpf, state = np.empty(blocks), 0.0
    for i, m in enumerate(metric):
        state += alpha * (m - state)
        lpf[i] = state
    return (np.arange(blocks) + 1.0) * n / f.rate_hz, lpf


def px4_rule(threshold: float = PX4_FD_IMB_PROP_THR):
    def run(f: AlertFlight):
        t, m = px4_imbalance_metric(f)
        over = np.flatnonzero(m > threshold)
        return [(float(t[over[0]]), "fault", ())] if len(over) else []

    return run


MIN_CALLED_LOSS = 0.08  # single-propeller onsets of >= 8 % thrust loss must be alerted
# The onset set: "severities from 5 % to 20 % thrust loss". Our simulator draws each damaged blade's loss
# from the register (0-15 % at hover), so some pairs hold a propeller below 5 %; they are scored among all pairs
# and apart (``pair_*_each_5pct``), never dropped.
MIN_PAIR_LOSS = 0.05
SAME_SPIN = ({1, 2}, {3, 4})


def _with_sets(alert: tuple) -> tuple:
    """(t_s, level, propellers, sets): an alert without sets names one set, its propellers."""
    return alert if len(alert) == 4 else (*alert, (alert[2],))


def _wrong(p: tuple, sets: tuple, truth: set) -> bool:
    """An alert names a wrong propeller when none of its candidate sets lies within the truth."""
    return bool(p) and not any(s and set(s) <= truth for s in sets)


def summarise(rule_alerts: dict[str, list], healthy: list[AlertFlight], onset: list[AlertFlight]) -> dict:
    """One table row: false alarms per healthy hour (fault and suspect), detection, latency, wrong propellers.

    Detection and latency count single-propeller onsets of >= ``MIN_CALLED_LOSS`` thrust loss at hover (all of
    them where a flight does not know its loss); ``single_detected_all`` counts every single onset. An alert
    that names several candidate sets (``PROP 1 or 1+2?``) is wrong only when no set lies within the truth;
    ``set_alerts`` counts the fault alerts after an onset that name more than one set. Pairs: ``overlaps``, a
    fault alert after the onset names a propeller of the pair; ``contains`` (the pairs criterion), the alert
    or one of its sets contains both; ``contains`` again over the pairs whose propellers each lose at least
    ``MIN_PAIR_LOSS`` (the issue's 5-20 %; all where a flight does not know its losses), over same-spin diagonal
    pairs (1+2, 3+4: seen only in the yaw balance) and over adjacent ones. ``pair_alerted``: the pair flights with
    a fault alert after the onset; ``pair_contains_truth_of_alerted``: of those, the share whose alert (or a set
    of it) contains the pair, i.e. what a pilot told of a fault can trust; the silent rest is in ``contains``.
    """
    h_alerts = [[_with_sets(a) for a in al] for al in rule_alerts["healthy"]]
    o_alerts = [[_with_sets(a) for a in al] for al in rule_alerts["onset"]]
    hours = sum(f.hours for f in healthy)
    fa = sum(1 for al in h_alerts for _, lvl, _, _ in al if lvl == "fault")
    fs = sum(1 for al in h_alerts for _, lvl, _, _ in al if lvl == "suspect")
    lat, hit, wrong, pair_ok, n_single, n_pair, early = [], 0, 0, 0, 0, 0, 0
    n_all, hit_all, wrong_suspect, pair_contains, set_alerts = 0, 0, 0, 0, 0
    pair_by = {"each_5pct": [0, 0], "same_spin": [0, 0], "adjacent": [0, 0]}  # [flights, contains truth]
    pair_alerted, pair_alerted_contains = 0, 0
    for f, al in zip(onset, o_alerts):
        truth = set(f.truth)
        faults = [(t, p, sets) for t, lvl, p, sets in al if lvl == "fault"]
        early += sum(1 for t, _, _ in faults if t < f.onset_s)
        wrong += sum(1 for _, p, sets in faults if _wrong(p, sets, truth))
        wrong_suspect += sum(1 for _, lvl, p, sets in al if lvl == "suspect" and _wrong(p, sets, truth))
        set_alerts += sum(1 for t, _, sets in faults if t >= f.onset_s and len(sets) > 1)
        after = [(t - f.onset_s, p) for t, p, _ in faults if t >= f.onset_s]
        if len(truth) == 1:  # a set alert calls a single when one of its sets holds it and none is wrong
            ok = [
                t - f.onset_s
                for t, p, sets in faults
                if t >= f.onset_s
                and (
                    not p
                    or (truth <= set(p) if len(sets) == 1 else not _wrong(p, sets, truth) and any(truth <= set(s) for s in sets))
                )
            ]
            n_all += 1
            hit_all += bool(ok)
            if getattr(f, "thrust_loss", ()) and f.thrust_loss[0] < MIN_CALLED_LOSS:
                continue
            n_single += 1
            if ok:
                hit += 1
                lat.append(ok[0])
        elif len(truth) == 2:
            n_pair += 1
            if any(set(p) & truth for _, p in after):
                pair_ok += 1
            contains = any(t >= f.onset_s and any(truth <= set(s) for s in (p, *sets)) for t, p, sets in faults)
            pair_contains += contains
            if after:
                pair_alerted += 1
                pair_alerted_contains += contains
            groups = ["same_spin" if truth in SAME_SPIN else "adjacent"]
            if not f.thrust_loss or min(f.thrust_loss) >= MIN_PAIR_LOSS:  # unknown losses: the set's own range
                groups.append("each_5pct")
            for g in groups:
                pair_by[g][0] += 1
                pair_by[g][1] += contains
    lat_a = np.asarray(lat)
    return {
        "healthy_flights": len(healthy),
        "healthy_hours": round(hours, 3),
        "false_alarms": fa,
        "false_alarms_per_hour": round(fa / hours, 3) if hours else None,
        "false_alarms_per_hour_upper95": round(_poisson_upper95(fa) / hours, 3) if hours else None,
        "suspect_false_alarms_per_hour": round(fs / hours, 3) if hours else None,
        "single_onsets": n_single,
        "single_detected": round(hit / n_single, 4) if n_single else None,
        "single_onsets_all": n_all,
        "single_detected_all": round(hit_all / n_all, 4) if n_all else None,
        "latency_median_s": round(float(np.median(lat_a)), 2) if len(lat_a) else None,
        "latency_p95_s": round(float(np.percentile(lat_a, 95)), 2) if len(lat_a) else None,
        "wrong_propeller_alerts": wrong,
        "wrong_propeller_suspects": wrong_suspect,
        "alerts_before_onset": early,
        "pair_onsets": n_pair,
        "pair_alert_overlaps_truth": round(pair_ok / n_pair, 4) if n_pair else None,
        "pair_alert_contains_truth": round(pair_contains / n_pair, 4) if n_pair else None,
        "pair_alerted": pair_alerted,
        "pair_contains_truth_of_alerted": round(pair_alerted_contains / pair_alerted, 4) if pair_alerted else None,
        "set_alerts": set_alerts,
        **{f"pair_onsets_{g}": n for g, (n, _) in pair_by.items()},
        **{f"pair_contains_truth_{g}": round(k / n, 4) if n else None for g, (n, k) in pair_by.items()},
    }


def _poisson_upper95(k: int) -> float:
    """One-sided 95 % upper bound of a Poisson mean after k events (k = 0: 3.0, the 'rule of three')."""
    if k == 0:
        return -math.log(0.05)
    lo, hi = float(k), 10.0 * k + 10.0
    for _ in range(60):  # bisection on P(X <= k | mu) = 0.05
        mu = (lo + hi) / 2
        cdf = sum(math.exp(-mu + i * math.log(mu) - math.lgamma(i + 1)) for i in range(k + 1))
        lo, hi = (mu, hi) if cdf > 0.05 else (lo, mu)
    return (lo + hi) / 2
