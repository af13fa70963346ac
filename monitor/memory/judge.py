"""A flight against its vehicle's normal: which propellers, how sure, and what it was compared with.

The deviation d (4 shares, summing to 0) of the flight from the vehicle's normal is weighed by its healthy
covariance (``Normal.deviation_cov``) in the 3-dimensional space of shares that sum to 4. Each hypothesis S says
d = a u_S + b y: the damaged propellers' rotors work harder (u_S: +1 on S, centred; a >= 0, a ~ loss / (1 - loss)),
and the yaw balance y = (1, 1, -1, -1) / 2 moves by any b (a damaged blade's drag torque may rise or fall). Its
statistic is chi^2(as normal) - chi^2(S): how much better S explains the flight than "as this vehicle's healthy
flights". Hypotheses: one propeller, or two of opposite spin. Two of the same spin move only the yaw balance, which
healthy flights move too, and three look like one rotor of the other spin working less with the yaw balance moved:
no share comparison can name them, and the set says what it can (docs/VEHICLE_MEMORY.md).

Verdict: statistic below ``SUSPECT_STATISTIC``: healthy (confident only where a ``CLAIMED_LOSS`` on any rotor would
have shown); up to ``FAULT_STATISTIC``: suspect; above: the hypotheses within ``SET_STATISTIC`` of the best: one
set is ``confident`` FAULTY, several ``ambiguous``; and where a load other than the normal's, carried off centre,
explains the flight as well (``monitor.memory.load``), an imbalance with no propeller faulty. Thresholds:
``monitor.memory.thresholds``.
"""

from __future__ import annotations

import numpy as np

from monitor.labels import label_for
from monitor.memory import load
from monitor.memory import thresholds as th
from monitor.memory.normal import Normal
from monitor.memory.summary import FlightSummary

HYPOTHESES = ((1,), (2,), (3,), (4,), (1, 3), (1, 4), (2, 3), (2, 4))
YAW = np.array([1.0, 1.0, -1.0, -1.0]) / 2.0
# Orthonormal basis (4, 3) of shares that sum to zero.
_Q = np.linalg.svd(np.eye(4) - 0.25)[0][:, :3]
_CG = _Q.T @ load.CG_PATTERNS  # (3, 2) a CG moved forward and right, in that basis


def _template(rotors) -> np.ndarray:
    u = np.zeros(4)
    u[[k - 1 for k in rotors]] = 1.0
    return u - u.mean()


_YQ = _Q.T @ YAW
# Each hypothesis's design in that basis: its rotors working harder, and the yaw balance; the yaw move alone.
_DESIGNS = {s: np.column_stack([_Q.T @ _template(s), _YQ]) for s in HYPOTHESES}
_YAW_ONLY = _YQ[:, None]


def statistics(d: np.ndarray, cov: np.ndarray) -> tuple[dict[tuple[int, ...], float], np.ndarray, dict]:
    """Each hypothesis's statistic for deviation ``d`` under healthy covariance ``cov``; the weight matrix; and each
    hypothesis's share move ``a`` of its rotors (0 where they work less than normal)."""
    wi = np.linalg.inv(_Q.T @ cov @ _Q)
    dq = _Q.T @ d
    chi0 = float(dq @ wi @ dq)
    out, moves = {}, {}
    for s in HYPOTHESES:
        a_mat = _DESIGNS[s]
        coef = np.linalg.solve(a_mat.T @ wi @ a_mat, a_mat.T @ wi @ dq)
        if coef[0] < 0:  # the rotors work less than normal: the yaw move alone
            a_mat = _YAW_ONLY
            coef = np.linalg.solve(a_mat.T @ wi @ a_mat, a_mat.T @ wi @ dq)
        r = dq - a_mat @ coef
        out[s] = chi0 - float(r @ wi @ r)
        moves[s] = float(coef[0]) if a_mat.shape[1] == 2 else 0.0
    return out, wi, moves


def detectable_loss(wi: np.ndarray) -> float:
    """The thrust loss on the worst-placed rotor that would just reach ``FAULT_STATISTIC`` (one propeller, no yaw)."""
    yq = _Q.T @ YAW
    worst = 0.0
    for k in range(1, 5):
        u = _Q.T @ _template((k,))
        # the part of u that the free yaw move cannot absorb, in the metric wi
        u_perp = u - yq * float(yq @ wi @ u) / float(yq @ wi @ yq)
        a = np.sqrt(th.FAULT_STATISTIC / max(float(u_perp @ wi @ u_perp), 1e-12))
        worst = max(worst, a / (1.0 + a))
    return float(worst)


def statistic_of(verdict: dict, rotors) -> float:
    """The statistic ``judge`` gave the hypothesis ``rotors`` (0 for one outside the hypotheses)."""
    want = sorted(rotors)
    return next((h["statistic"] for h in verdict["statistics"] if h["faulty_propellers"] == want), 0.0)


def _rivals_with_the_load_cg(d, wi, stats, moves, collective, best) -> list[tuple[int, ...]]:
    """The hypotheses other than ``best`` that, each with the CG moved as far as the load it leaves (the collective
    change less its own rise) can move it (``load.with_load``), explain deviation ``d`` within ``SET_STATISTIC`` of
    the best one so; [] where the flight carried its normal's load (or the normal keeps no range)."""
    if not collective:
        return []
    dq = _Q.T @ d
    with_cg = {}
    for h in HYPOTHESES:
        shift_h = load.cg_shift_arm(load.load_change(collective, damage_rise=len(h) * moves[h] / 4.0))
        with_cg[h] = load.with_load(dq, wi, _CG, shift_h, _DESIGNS[h]) if shift_h > 0 else stats[h]
    top_cg = max(with_cg.values())
    return [h for h in HYPOTHESES if h != best and top_cg - with_cg[h] <= th.SET_STATISTIC]


def judge(normal: Normal, s: FlightSummary) -> dict:
    """The flight (or the part flown so far) summarised in ``s`` against ``normal``: the verdict's fields."""
    d = normal.deviation(s)
    cov = normal.deviation_cov(s)
    stats, wi, moves = statistics(d, cov)
    best = max(stats, key=stats.get)
    top = stats[best]
    # a load other than the normal's, carried off centre: a rival of the damage hypotheses (monitor.memory.load)
    collective = load.collective_change(normal, s)
    p = None if collective is None else load.load_change(collective, damage_rise=len(best) * moves[best] / 4.0)
    shift_arm = 0.0 if p is None else load.cg_shift_arm(p)
    hidden = load.hidden_loss(shift_arm)
    load_stat = load.rival_statistic(_Q.T @ d, wi, _CG, shift_arm)
    sigma = np.sqrt(np.diag(cov))
    in_set = sorted((h for h in HYPOTHESES if top - stats[h] <= th.SET_STATISTIC), key=lambda h: -stats[h])
    loss = detectable_loss(wi)
    base = {
        "deviation": [float(x) for x in d],
        "deviation_sigma": [float(x) for x in d / sigma],
        "fault_statistic": float(top),
        "statistics": [{"faulty_propellers": list(h), "statistic": float(v)} for h, v in stats.items()],
        "detectable_loss": loss,
        "tested_s": s.seconds,
        "load": None
        if p is None
        else {
            "collective_change": collective,
            "change": p,
            "cg_shift_arm": shift_arm,
            "hidden_loss": hidden,
            "statistic": load_stat,
            "radius_arm": load.PAYLOAD_RADIUS_ARM,
        },
        "thresholds": {
            "suspect": th.SUSPECT_STATISTIC,
            "fault": th.FAULT_STATISTIC,
            "set": th.SET_STATISTIC,
            "claimed_loss": th.CLAIMED_LOSS,
            "measured_by": th.MEASURED_BY,
        },
    }
    if top < th.SUSPECT_STATISTIC:
        conf = "confident" if loss + hidden <= th.CLAIMED_LOSS else "ambiguous"
        why = (
            f"every rotor within this vehicle's normal (statistic {top:.1f} < {th.SUSPECT_STATISTIC:g}); a loss of "
            f"{100 * loss:.0f} % on any one propeller would have shown"
        ) + (f", less the {100 * hidden:.0f} % loss a load off centre could hide" if hidden > 0 else "")
        return base | {"label": 1, "faulty_propellers": [], "confidence": conf, "hypotheses": [], "rule": why}
    sets = [{"faulty_propellers": list(h), "statistic": float(stats[h])} for h in in_set]
    if top < th.FAULT_STATISTIC:
        why = f"statistic {top:.1f}: beyond the suspect level {th.SUSPECT_STATISTIC:g}, below the fault level {th.FAULT_STATISTIC:g}"
        return base | {
            "label": 1,
            "faulty_propellers": [],
            "suspect_propellers": sorted({k for h in in_set for k in h}),
            "confidence": "suspect",
            "hypotheses": [{"faulty_propellers": [], "statistic": 0.0}] + sets,
            "rule": why,
        }
    conf = "confident" if len(in_set) == 1 else "ambiguous"
    why = f"statistic {top:.1f} >= {th.FAULT_STATISTIC:g}; " + (
        "one hypothesis" if len(in_set) == 1 else f"{len(in_set)} hypotheses within {th.SET_STATISTIC:g} of the best"
    )
    v = base | {"label": label_for(best), "faulty_propellers": list(best), "confidence": conf, "hypotheses": sets, "rule": why}
    if top - load_stat <= th.SET_STATISTIC:
        return load.rival_verdict(v, collective, load_stat)
    rivals = _rivals_with_the_load_cg(d, wi, stats, moves, collective, best) if conf == "confident" else []
    if rivals:
        extra = [{"faulty_propellers": list(h), "statistic": float(stats[h])} for h in sorted(rivals, key=lambda h: -stats[h])]
        return v | {
            "confidence": "ambiguous",
            "hypotheses": sets + extra,
            "rule": why + f"; with the CG moved by the load ({100 * collective:+.0f} % thrust), {len(rivals)} more "
            f"explain it within {th.SET_STATISTIC:g}",
        }
    return v
