"""A physics-free toy data set for tests: seconds to build, with a known, learnable fault signature.

A faulty rotor turns faster (it must, to make up its lost thrust) and tilts
the attitude towards its corner; the rest is noise. Used by the classifier
tests so they exercise the real training/export/evaluation code without
running the simulator.
"""

from __future__ import annotations

import numpy as np

from monitor.labels import LABEL_MASKS
from offline.dataset.records import FaultDataset

_ROLL_SIGN = np.array([1.0, -1.0, -1.0, 1.0])  # right-side rotors 1, 4 (PX4 quad-X)
_PITCH_SIGN = np.array([1.0, -1.0, 1.0, -1.0])  # front rotors 1, 3


def synthetic_dataset(
    flights_per_label: int = 2,
    n_steps: int = 300,
    seed: int = 0,
    payload_kg: float = 0.0,
    rpm_gain: float = 0.04,
    name: str = "synthetic",
    vehicle_name: str = "paper-quad-1.5kg",
) -> FaultDataset:
    rng = np.random.default_rng(seed)
    cond = np.repeat((LABEL_MASKS > 0).astype(np.int8), flights_per_label, axis=0)
    cond = cond * rng.integers(1, 3, cond.shape).astype(np.int8)  # bent or cracked
    b = len(cond)
    t = np.arange(n_steps) / 20.0
    base = 6000.0 * np.sqrt(1.0 + payload_kg / 1.5) + 300.0 * np.sin(2 * np.pi * t / 7.0 + rng.uniform(0, 6, (b, 1)))
    faulty = (cond > 0).astype(np.float64)
    rpm = base[..., None] * (1.0 + rpm_gain * faulty[:, None, :]) + rng.normal(0.0, 20.0, (b, n_steps, 4))
    signals = {"motor_rpm": rpm}
    tilt_roll = 0.01 * faulty @ _ROLL_SIGN
    tilt_pitch = 0.01 * faulty @ _PITCH_SIGN
    for k, bias in (
        ("roll_rad", tilt_roll),
        ("pitch_rad", tilt_pitch),
        ("yaw_rad", 0.0),
        ("roll_rate_rad_s", 0.0),
        ("pitch_rate_rad_s", 0.0),
        ("yaw_rate_rad_s", 0.0),
    ):
        signals[k] = rng.normal(0.0, 0.02, (b, n_steps)) + np.reshape(bias, (-1, 1))
    return FaultDataset(
        name,
        vehicle_name,
        20.0,
        signals,
        cond,
        np.full(b, payload_kg),
        ("synthetic",) * b,
        {"kind": "synthetic", "seed": seed, "vehicle": {"name": vehicle_name, "esc": {}}},
    )
