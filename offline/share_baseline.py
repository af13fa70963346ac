"""The ω²-share baseline: a physics single-fault locator with no training.

A propeller that lost thrust is spun faster by the attitude controller to hold
the vehicle level, so its share of the total ω² rises. Per rotor, the
flight-mean over airborne steps of ω² (PWM -> RPM through the ESC fit, squared)
divided by the mean of the four is its *share* (1.0 on a perfect airframe); the
rotor with the largest share is named. It always names exactly one rotor, so it
is a single-fault locator only. An airframe's own imbalance (CG offset, weak
motor) shifts the shares of healthy flights too: pass that airframe's healthy
shares and they are subtracted first. numpy only; rotors in PX4 order.
"""

from __future__ import annotations

import numpy as np

from monitor.esc import PAPER_ESC, EscCurve


def omega2_shares(motor_cmd: np.ndarray, airborne: np.ndarray, esc: EscCurve = PAPER_ESC) -> np.ndarray:
    """(4,) flight-mean ω² per rotor over airborne rows with all four commands known, over the mean of the four."""
    cmd = np.asarray(motor_cmd, dtype=np.float64)
    rows = np.asarray(airborne, dtype=bool) & np.all(np.isfinite(cmd), axis=1)
    if not np.any(rows):
        raise ValueError("omega2_shares: no airborne step with all four motor commands")
    w2 = np.mean(esc.cmd_to_rpm(cmd[rows]) ** 2, axis=0)
    return w2 / np.mean(w2)


def share_baseline(shares: np.ndarray, healthy_shares: np.ndarray | None = None) -> int:
    """PX4 number (1..4) of the rotor with the largest share (less the airframe's healthy shares, if given)."""
    s = np.asarray(shares, dtype=np.float64)
    if healthy_shares is not None:
        s = s - np.asarray(healthy_shares, dtype=np.float64)
    return int(np.argmax(s)) + 1
