"""The physical envelope of the decision's context streams, shared by the daemon and the log reader.

Velocity (LOCAL_POSITION_NED, or a log's estimator velocity) and the accelerometer's horizontal specific force are
optional context for the omega^2 shares' baseline (monitor/decision/rotor_share.py): a sample that is not finite, beyond its
envelope, or bit-identical for ``FROZEN_S`` of boot time is never evidence. The daemon checks each sample as it
arrives (``monitor.daemon.plausible``); ``propwatch diagnose`` checks a log's samples the same way before they reach
the 20 Hz grid (``implausible_context``), so both feed the decision the same context.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

# Ground speed no multirotor reaches (PX4 MPC_XY_VEL_MAX defaults to 12 m/s; racing quadrotors stay below ~50 m/s):
# beyond it the estimator has diverged or the field is garbage.
VELOCITY_MAX_M_S = 60.0
# 16 g: the range most of PX4's IMU drivers set (ICM-20602, ICM-42688-P; the BMI088 reads to 24 g). No drag on a
# multirotor comes near it (a few m/s^2): beyond it the field is garbage or the sensor saturated in a crash.
ACCEL_XY_MAX_M_S2 = 160.0
FROZEN_S = 1.0  # a stream whose values stay bit-identical this long is a frozen channel (plausible.frozen_s)


def implausible_context(
    t_us: np.ndarray, values: np.ndarray, kind: str, frozen_s: float = FROZEN_S
) -> tuple[np.ndarray, Counter]:
    """(bad (N,), reasons) for a context stream's samples, as the daemon judges them one by one.

    ``kind``: "velocity" (N, 3) NED m/s, its norm against VELOCITY_MAX_M_S, an all-zero sample allowed to stand
    still (a vehicle at rest); "imu" (N, 3) FRD m/s^2, x and y against ACCEL_XY_MAX_M_S2. Frozen: from the first
    sample of a run of bit-identical samples, those ``frozen_s`` or more after it (a later sample with other values,
    or time running back, starts a new run)."""
    t = np.asarray(t_us, dtype=np.int64)
    v = np.asarray(values, dtype=np.float64)
    v = v[:, None] if v.ndim == 1 else v
    if kind == "velocity":
        checked, limit, unit = v, VELOCITY_MAX_M_S, "m/s"
        rest = ~np.any(v != 0.0, axis=1) & np.isfinite(v).all(axis=1)
    elif kind == "imu":
        checked, limit, unit = v[:, :2], ACCEL_XY_MAX_M_S2, "m/s^2"
        rest = np.zeros(len(t), dtype=bool)
    else:
        raise ValueError(f"kind: 'velocity' or 'imu', got {kind!r}")
    not_finite = ~np.isfinite(checked).all(axis=1)
    with np.errstate(invalid="ignore", over="ignore"):
        beyond = ~not_finite & (np.linalg.norm(np.where(np.isfinite(checked), checked, 0.0), axis=1) > limit)
    # Runs among the samples that passed the range checks (the daemon never compares a dropped sample's values).
    ok = np.flatnonzero(~not_finite & ~beyond)
    tk, vk, rk = t[ok], v[ok], rest[ok]
    new_run = np.ones(len(ok), dtype=bool)
    if len(ok) > 1:
        new_run[1:] = ~((vk[1:] == vk[:-1]).all(axis=1) & (tk[1:] >= tk[:-1]) & ~rk[1:] & ~rk[:-1])
    run_start = tk[np.maximum.accumulate(np.where(new_run, np.arange(len(ok)), 0))] if len(ok) else tk
    frozen = np.zeros(len(t), dtype=bool)
    frozen[ok] = ~rk & (tk - run_start >= int(round(frozen_s * 1e6)))
    reasons = Counter(
        {
            k: int(n)
            for k, n in (
                ("not finite", not_finite.sum()),
                (f"beyond {limit:g} {unit}", beyond.sum()),
                ("frozen", frozen.sum()),
            )
            if n
        }
    )
    return not_finite | beyond | frozen, reasons
