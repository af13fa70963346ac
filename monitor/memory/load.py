"""A load carried off-centre, the rival of a damaged propeller when a flight carries another load than its normal's.

A payload of a fraction p of the vehicle's weight, placed r from the centre of gravity, moves the CG by
delta = p r / (1 + p). On a quad-X with arm L (rotors at x, y = +-L/sqrt(2)), the moment balance about the moved CG
shares the thrust as e_k = sqrt(2) (x_k delta_x + y_k delta_y) / L^2 per rotor (shares of mean 1): a share pattern in
the plane spanned by pitch (front rotors 1, 3 up) and roll (right rotors 1, 4 up), of size |(pitch, roll)| =
sqrt(2) |delta| / L (one rotor's share moves by up to 2 |delta| / L, along the diagonal through it), with no yaw move (the controller keeps the yaw torque balanced). Along the diagonal
through a rotor it is exactly the one-propeller-plus-yaw pattern of ``monitor.memory.judge`` (the CG-vs-damage
ceiling); only its size, bounded by the load the flight carried, tells them apart.

The load change p is read from the collective: the flight's mean omega^2 against the range its normal's flights
flew at (thrust ~ omega^2 ~ weight in hover), less the rise the best damage hypothesis itself causes (a damaged
rotor's omega^2 rises by its share move a, the mean by a / 4 per rotor). A flight within its normal's range of loads
has no rival: its normal already carries that load's CG.

Where the rival, within that bound, explains the flight within ``thresholds.SET_STATISTIC`` of the best damage
hypothesis, no propeller is called faulty: the rotors that work harder are an imbalance near them, the load and a
damaged propeller both named (``rival_verdict``). A healthy verdict is confident only where the loss such a load can
hide (``hidden_loss``) plus the smallest loss the flight could show stays under ``thresholds.CLAIMED_LOSS``.
"""

from __future__ import annotations

import numpy as np

# Where a payload may sit: within this fraction of the arm length from the centre of gravity (carried on the body,
# not out on the arms). Chosen, not measured: a bound from the airframe's geometry, stated so the rival's size can be
# checked by hand; no flight of either simulator set it.
PAYLOAD_RADIUS_ARM = 0.5
# Share patterns (PX4 order: 1 front-right, 2 rear-left, 3 front-left, 4 rear-right) of a CG moved forward and right.
PITCH = np.array([1.0, -1.0, 1.0, -1.0])
ROLL = np.array([1.0, -1.0, -1.0, 1.0])
CG_PATTERNS = np.column_stack([PITCH, ROLL])


def collective_change(normal, s) -> float | None:
    """How far the flight ``s``'s mean collective lies above (+) or below (-) its normal's range, as a fraction of
    that range's nearer end (0 within it); None where the normal keeps no range."""
    rng = normal.collective_range
    if rng is None or s.n == 0 or s.basis != "omega2":
        return None
    c = s.mean_collective()
    lo, hi = rng
    return c / hi - 1.0 if c > hi else c / lo - 1.0 if c < lo else 0.0


def load_change(collective: float, damage_rise: float) -> float:
    """The load change (fraction of weight) behind a ``collective`` change, less ``damage_rise``: the rise the best
    damage hypothesis itself explains (a damaged propeller raises the collective, never lowers it)."""
    return max(collective - damage_rise, 0.0) if collective > 0 else collective


def cg_shift_arm(p: float) -> float:
    """The largest CG move, in arm lengths, a load change ``p`` placed within ``PAYLOAD_RADIUS_ARM`` of the arm from
    the CG can cause (a removed load counted from the heavier vehicle). It moves the (pitch, roll) share pattern by
    at most sqrt(2) times that, one rotor's share by at most twice that (along the diagonal through it)."""
    frac = p / (1.0 + p) if p >= 0 else -p
    return float(frac * PAYLOAD_RADIUS_ARM)


def hidden_loss(shift_arm: float) -> float:
    """The thrust loss on one propeller that a CG moved by ``shift_arm`` arm lengths can hide. A damaged propeller
    whose torque per omega^2 is unchanged moves the shares by a (1/2, -1/2, 0, 0) from its rotor, a = 2 loss / (2 -
    loss) (the controller keeps thrust, pitch and roll, and the yaw torque balanced): exactly the CG moved toward it
    by a / 4 arm."""
    a = 4.0 * shift_arm
    return float(2.0 * a / (2.0 + a))


def rival_statistic(dq: np.ndarray, wi: np.ndarray, cg: np.ndarray, shift_arm: float) -> float:
    """The load alone, propellers intact (no yaw move): chi^2(as normal) - chi^2 of the best fit of deviation ``dq``
    (weight ``wi``, in the basis of ``monitor.memory.judge``) by the CG moved at most ``shift_arm`` arm lengths
    (``cg``: the pitch and roll share patterns in that basis)."""
    if shift_arm <= 0:
        return 0.0
    h = cg.T @ wi @ cg  # 2 x 2, positive semi-definite (singular where other columns were profiled out of wi)
    g = cg.T @ wi @ dq
    c = np.linalg.lstsq(h, g, rcond=None)[0]  # the smallest CG move with the best fit
    bound = np.sqrt(2.0) * shift_arm  # on |(pitch, roll)| of the share pattern
    if np.hypot(*c) > bound:  # on the bound: (h + lam I) c = g with |c| = bound, lam > 0 found by bisection
        lo, hi = 0.0, float(np.linalg.norm(g) / bound + np.abs(h).max())
        for _ in range(60):
            lam = 0.5 * (lo + hi)
            c = np.linalg.solve(h + lam * np.eye(2), g)
            lo, hi = (lam, hi) if np.hypot(*c) > bound else (lo, lam)
        c = np.linalg.solve(h + hi * np.eye(2), g)
    r = dq - cg @ c
    return float(dq @ wi @ dq - r @ wi @ r)


def with_load(dq: np.ndarray, wi: np.ndarray, cg: np.ndarray, shift_arm: float, design: np.ndarray) -> float:
    """chi^2(as normal) - the least penalised misfit of ``dq`` by a damage hypothesis (``design``'s columns: its
    rotors working harder by a >= 0, the yaw balance moved by any b) together with the CG moved by c, c's (pitch, roll)
    pattern drawn with standard deviation half its bound sqrt(2) ``shift_arm`` (a Gaussian prior: a small move
    likelier than one at the bound): chi^2 + |c|^2 / sigma^2. As in ``monitor.memory.judge.statistics``, where the
    rotors would work less than normal, the yaw move alone."""
    sigma = np.sqrt(2.0) * shift_arm / 2.0
    for free in (design, design[:, 1:]):
        x = np.column_stack([free, cg])
        pen = np.diag([0.0] * free.shape[1] + [1.0 / sigma**2] * cg.shape[1])
        coef = np.linalg.solve(x.T @ wi @ x + pen, x.T @ wi @ dq)
        if free.shape[1] == 1 or coef[0] >= 0:
            break
    r = dq - x @ coef
    return float(dq @ wi @ dq) - float(r @ wi @ r + coef @ pen @ coef)


def rival_verdict(v: dict, collective: float, statistic: float) -> dict:
    """The judgement ``v`` (a fault-level one) where the load behind a ``collective`` change, off centre, explains
    the flight as well: no propeller faulty, the harder-working rotors an imbalance, both causes in the hypotheses
    (never confident)."""
    rotors = sorted({k for h in v["hypotheses"] for k in h["faulty_propellers"]})
    change = f"{100 * collective:+.0f} % thrust against its references"
    return v | {
        "label": 1,
        "faulty_propellers": [],
        "suspect_propellers": rotors,
        "imbalance_rotors": rotors,
        "imbalance_why": f"This flight carried another load ({change}); a load off centre and a damaged propeller "
        "move the rotors' shares alike.",
        "confidence": "ambiguous",
        "hypotheses": v["hypotheses"]
        + [{"faulty_propellers": [], "statistic": statistic, "cause": f"the load ({change}) off centre, propellers intact"}],
        "rule": v["rule"] + f"; the load ({change}) carried off centre explains it as well (statistic {statistic:.1f})",
    }
