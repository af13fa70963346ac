"""Can the response to differential commands locate a damaged rotor on an airframe nobody measured?

The moment balance (monitor.decision.effectiveness) reads each rotor's thrust from the steady balance, where a CG offset or
a motor spread looks exactly like damage. The *dynamic* response is immune to both: write the four commanded ω²
(times kF·L) in the quad-X Hadamard patterns, collective T, roll R, pitch P and yaw Y. With per-rotor thrust
effectiveness η, Euler's equation gives (FRD, PX4 order, levers r, p, spin s, c = 1)::

    roll moment  = (η·r) T + (η·c) R - (η·s) P - (η·p) Y + CG offset x thrust
    pitch moment = (η·p) T - (η·s) R + (η·c) P - (η·r) Y + CG offset x thrust

A CG offset only moves the T column (and the trim); the R, P and Y columns read all four projections of η
without it (the CG changes them only to second order). So a band-passed regression of I·dω/dt on T, R, P, Y
recovers η up to scale, free of the airframe's static imbalance, and names the rotor with the lowest η.

This bench measures that on our own simulator's randomised flights at the logs' 20 Hz: single-propeller flights
named right and the relative spread of η on healthy flights, beside the ω²-share baseline. Measured (40 singles
and 10 healthy flights per set; span 3, high-pass 81 samples):

    RNcal  (nominal airframe)                 dynamic η 62 % of singles, healthy spread 5.4 %;  ω²-share 70 %
    RRcal  (drawn: CG ±1 cm, motors ±4-8 %)   dynamic η 58 %,            healthy spread 8.2 %;  ω²-share 32 %
    RRfall (drawn, torque per thrust falling) dynamic η 62 %,            healthy spread 7.1 %;  ω²-share 48 %

So the dynamic reading does shed the CG offset (it beats the ω²-share on drawn airframes) but not a motor's own
spread (a weak motor has less thrust per command, like damage), and its scatter at 20 Hz (5-8 % per rotor over an
80 s flight, against the register's 3-11 % damage) makes it weak evidence: a likelihood ratio of about 1.7 for a
typical 7 % loss. It is not used in the verdict; at 100 Hz (CrazyPAD) the scatter is smaller.

    python -m bench.bench_dynamic_effectiveness out/data-rrcal/RRcal-varied.npz   (seconds)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from monitor.labels import LABEL_TABLE  # noqa: E402
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle  # noqa: E402
from offline.share_baseline import share_baseline  # noqa: E402

RPM_TO_RAD_S = 2.0 * np.pi / 60.0


def moving_mean(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving mean of each column (zero-padded at the ends, which the caller trims)."""
    k = np.ones(n) / n
    return np.stack([np.convolve(x[:, j], k, mode="same") for j in range(x.shape[1])], axis=1)


def dynamic_eta(rpm: np.ndarray, rates_rad_s: np.ndarray, vehicle, rate_hz: float, span: int, highpass: int) -> np.ndarray:
    """(4,) relative thrust effectiveness (mean 1) from the response to differential commands; see the module doc.

    ``span`` samples per angular-momentum difference (with the mean command over the same span); ``highpass``
    samples of the moving mean removed from both sides (the trim, the CG moment's slow part)."""
    pos = np.asarray(vehicle.rotor_positions_frd_m, dtype=np.float64)
    arm_m = float(np.mean(np.abs(pos[:, :2])))
    r, p = -pos[:, 1] / arm_m, pos[:, 0] / arm_m
    s, c = np.asarray(vehicle.spin_sign, dtype=np.float64), np.ones(4)
    patterns = np.stack([c, r, p, s])  # rows: collective, roll, pitch, yaw (orthogonal, norm^2 4)
    u = (np.asarray(rpm, dtype=np.float64) * RPM_TO_RAD_S) ** 2 * vehicle.kf_n_per_rad_s2 * arm_m
    h = np.asarray(rates_rad_s, dtype=np.float64) * np.asarray(vehicle.inertia_diag_kg_m2)
    dt_s = 1.0 / rate_hz
    torque = (h[span:] - h[:-span]) / (span * dt_s)  # mean moment over the span (gyroscopic term negligible here)
    csum = np.cumsum(np.vstack([np.zeros((1, 4)), u]), axis=0)
    u_mean = (csum[span : len(u)] - csum[: len(u) - span]) / span
    x = u_mean @ patterns.T
    n = min(len(x), len(torque))
    trim = highpass
    xh = (x[:n] - moving_mean(x[:n], highpass))[trim:-trim]
    mh = (torque[:n] - moving_mean(torque[:n], highpass))[trim:-trim]
    a = np.linalg.lstsq(xh, mh[:, 0], rcond=None)[0]  # roll on T, R, P, Y
    b = np.linalg.lstsq(xh, mh[:, 1], rcond=None)[0]  # pitch on T, R, P, Y
    eta_c, eta_s = 0.5 * (a[1] + b[2]), -0.5 * (a[2] + b[1])
    eta_p, eta_r = -a[3], -b[3]
    eta = (c * eta_c + r * eta_r + p * eta_p + s * eta_s) / 4.0
    return eta / np.mean(eta)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", type=Path, help="a randomised data set (.npz), e.g. RRcal (drawn airframes)")
    args = ap.parse_args(argv)
    z = np.load(args.data)
    rate_hz = 20.0
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    rpm = z["signal_motor_rpm"]
    rates = np.stack([z["signal_roll_rate_rad_s"], z["signal_pitch_rate_rad_s"], z["signal_yaw_rate_rad_s"]], axis=-1)
    truth = [LABEL_TABLE[int(k)] for k in z["labels"]]
    singles = [i for i, t in enumerate(truth) if len(t) == 1]
    healthy = [i for i, t in enumerate(truth) if len(t) == 0]
    w2 = (rpm.astype(np.float64) * RPM_TO_RAD_S) ** 2
    share = w2.mean(axis=1) / w2.mean(axis=(1, 2))[:, None]
    right = sum(share_baseline(share[i]) == truth[i][0] for i in singles)
    print(f"{args.data.name}: {len(singles)} single-propeller flights, {len(healthy)} healthy")
    print(
        f"  ω²-share baseline                         singles named {right}/{len(singles)} ({100 * right / len(singles):.0f} %)"
    )
    for span, highpass in ((1, 41), (3, 41), (3, 81), (6, 81)):
        eta = {i: dynamic_eta(rpm[i], rates[i], vehicle, rate_hz, span, highpass) for i in singles + healthy}
        named = sum(int(np.argmin(eta[i])) + 1 == truth[i][0] for i in singles)
        spread = float(np.std([eta[i] for i in healthy]))
        print(
            f"  dynamic η (span {span}, high-pass {highpass:2d} samples) singles named {named}/{len(singles)} "
            f"({100 * named / len(singles):.0f} %), healthy η spread {100 * spread:.1f} %"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
