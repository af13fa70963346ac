"""The moment features added for the classifier agree with the simulator's own rotor geometry."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.features import compute_features
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle


def test_moment_features_have_the_signs_of_the_vehicles_wrench():
    # A thrust T along -z at (x, y) gives the body moment (-y T, x T); a rotor's drag torque yaws by its spin sign.
    v = load_vehicle(DEFAULT_VEHICLE)
    pos = v.rotor_positions_array_m
    rng = np.random.default_rng(0)
    rpm = rng.uniform(3000, 9000, (50, 4))
    feats = compute_features({"motor_rpm": rpm}, ("roll_moment_krpm2", "pitch_moment_krpm2", "yaw_moment_krpm2"))
    thrust = (rpm / 1000.0) ** 2  # any common thrust-per-rpm^2 constant
    mx, my, mz = thrust @ -pos[:, 1], thrust @ pos[:, 0], thrust @ v.spin_sign
    # same direction up to each axis' positive scale (arm length, torque constant)
    for f, m in zip(feats.T, (mx, my, mz)):
        scale = np.dot(f, m) / np.dot(f, f)
        assert scale > 0
        np.testing.assert_allclose(f * scale, m, rtol=1e-5, atol=1e-5)  # features are float32


def test_moment_features_vanish_for_equal_rotors():
    rpm = np.full((3, 4), 6000.0)
    f = compute_features({"motor_rpm": rpm}, ("roll_moment_krpm2", "pitch_moment_krpm2", "yaw_moment_krpm2"))
    np.testing.assert_allclose(f, 0.0, atol=1e-6)


def test_each_feature_names_the_signals_it_needs():
    from monitor.errors import ModelError
    from monitor.features import FEATURES, SIGNALS, signals_needed

    assert signals_needed("yaw_cos") == ("yaw_rad",)
    assert signals_needed("collective_krpm2") == ("motor_rpm",) == signals_needed("rpm_rel_2")
    full = {"motor_rpm": np.full((5, 4), 5000.0), **{k: np.zeros(5) for k in SIGNALS[1:]}}
    for name in FEATURES:  # computing a feature from only the signals it names works
        need = signals_needed(name)
        assert need and compute_features({k: full[k] for k in need}, (name,)).shape == (5, 1)
    with pytest.raises(ModelError, match="nope"):
        signals_needed("nope")
