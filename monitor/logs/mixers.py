"""Motor commands rebuilt from a controller's logged outputs, for logs that lack them.

Only the Crazyflie's legacy quad-X mixer is here: CrazyPAD's controller-config logs hold
``controller.cmd_thrust/cmd_roll/cmd_pitch/cmd_yaw`` (the PID controller's outputs,
``controller_pid.c``) but no motor commands.

Crazyflie firmware, ``src/modules/src/power_distribution_quadrotor.c``,
``powerDistributionLegacy()`` (the same sums as ``power_distribution_stock.c``,
``powerDistribution()`` with ``QUAD_FORMATION_X`` in older releases):

    r = (int16) (roll / 2);  p = (int16) (pitch / 2)
    m1 = thrust - r + p + yaw
    m2 = thrust - r - p - yaw
    m3 = thrust + r - p + yaw
    m4 = thrust + r + p - yaw

then ``powerDistributionCap()``: if the largest exceeds 65535 every motor drops by the
excess (attitude authority kept over collective), and each is floored at the idle thrust
(0 unless ``powerDist.idleThrust`` is set, unknown here: taken as 0). The Bitcraze
numbering (M1..M4) is returned; the CSV format maps it onto the PX4 order.
"""

from __future__ import annotations

import numpy as np

from monitor.errors import LogFormatError

CF16_MAX = 65535.0
MIXERS = ("crazyflie-legacy",)


def crazyflie_legacy(thrust, roll, pitch, yaw) -> np.ndarray:
    """(N,) controller outputs (firmware units) -> (N, 4) Bitcraze M1..M4 commands, 0..65535."""
    t, y = (np.asarray(v, dtype=np.float64) for v in (thrust, yaw))
    # The firmware truncates the halved roll/pitch to int16 (toward zero).
    r = np.trunc(np.asarray(roll, dtype=np.float64) / 2.0)
    p = np.trunc(np.asarray(pitch, dtype=np.float64) / 2.0)
    m = np.stack([t - r + p + y, t - r - p - y, t + r - p + y, t + r + p - y], axis=-1)
    excess = np.maximum(np.max(m, axis=-1, keepdims=True) - CF16_MAX, 0.0)
    out = np.maximum(m - excess, 0.0)
    # Motors are off (0) when the commander sends no thrust: the firmware stops them then.
    return np.where((t > 0.0)[..., None], out, 0.0)


def mix(kind: str, thrust, roll, pitch, yaw) -> np.ndarray:
    if kind == "crazyflie-legacy":
        return crazyflie_legacy(thrust, roll, pitch, yaw)
    raise LogFormatError(f"unknown mixer {kind!r}; known: {', '.join(MIXERS)}")
