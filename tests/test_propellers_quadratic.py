"""Analytic propellers: the normal rotor is kF·ω², the faults depart from it as documented."""

import numpy as np
import pytest

from monitor.errors import ConfigError
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.propellers import build_propellers

VEHICLE = load_vehicle(DEFAULT_VEHICLE)
DT_S = 0.004


def _mean_over(model, omega, steps=2000):
    model.reset(omega)
    acc_t, acc_q = np.zeros_like(omega), np.zeros_like(omega)
    for _ in range(steps):
        t, q = model(omega, DT_S)
        acc_t += t
        acc_q += q
    return acc_t / steps, acc_q / steps


def test_normal_rotor_is_kf_omega_squared():
    cond = np.zeros((3, 4), dtype=int)
    model = build_propellers(VEHICLE, cond, kind="quadratic")
    omega = np.linspace(100.0, 1100.0, 12).reshape(3, 4)
    model.reset(omega)
    thrust, torque = model(omega, DT_S)
    np.testing.assert_allclose(thrust, VEHICLE.kf_n_per_rad_s2 * omega**2, rtol=1e-12)
    np.testing.assert_allclose(torque, VEHICLE.ktau_nm_per_rad_s2 * omega**2, rtol=1e-12)
    # Hover: four normal rotors at the hover speed carry the weight.
    w = np.full((1, 4), VEHICLE.hover_omega_rad_s)
    model1 = build_propellers(VEHICLE, np.zeros((1, 4), dtype=int), kind="quadratic")
    model1.reset(w)
    assert model1(w, DT_S)[0].sum() == pytest.approx(VEHICLE.mass_kg * 9.80665, rel=1e-9)


def test_fault_signatures_bent_and_cracked():
    cond = np.array([[0, 1, 2, 0], [0, 1, 2, 0]])
    omega = np.array([[300.0] * 4, [1100.0] * 4])
    model = build_propellers(VEHICLE, cond, kind="quadratic", rng_seed=3)
    thrust, torque = _mean_over(model, omega)
    rel_t = thrust / (VEHICLE.kf_n_per_rad_s2 * omega**2)
    rel_q = torque / (VEHICLE.ktau_nm_per_rad_s2 * omega**2)
    # Bent: ~8-12 % thrust loss at every speed, more drag torque.
    assert 0.86 < rel_t[0, 1] < 0.94 and 0.85 < rel_t[1, 1] < 0.91
    assert rel_q[0, 1] > 1.03 and rel_q[1, 1] > 1.07
    # Cracked: small loss at low speed that grows as the crack opens.
    assert 0.95 < rel_t[0, 2] < 0.99
    assert rel_t[1, 2] < 0.88
    assert rel_t[1, 2] < rel_t[0, 2] - 0.08
    np.testing.assert_allclose(rel_t[:, [0, 3]], 1.0, atol=1e-12)


def test_vibration_is_seeded_and_zero_mean():
    cond = np.array([[1, 2, 1, 2]])
    omega = np.full((1, 4), 900.0)
    runs = []
    for seed in (5, 5, 6):
        m = build_propellers(VEHICLE, cond, kind="quadratic", rng_seed=seed)
        m.reset(omega)
        runs.append(np.array([m(omega, DT_S)[0] for _ in range(50)]))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.allclose(runs[0], runs[2])
    # The ripple and flutter vibrate around the mean signature.
    steady = build_propellers(VEHICLE, cond, kind="quadratic", vibration=False)
    steady.reset(omega)
    mean_t, _ = steady(omega, DT_S)
    vib_t, _ = _mean_over(build_propellers(VEHICLE, cond, kind="quadratic", rng_seed=1), omega, steps=20000)
    np.testing.assert_allclose(vib_t, mean_t, rtol=0.01)
    assert np.std(runs[0][:, 0]) > 0.01 * mean_t[0, 0]


@pytest.mark.parametrize("cond", [np.zeros((2, 3), dtype=int), np.full((1, 4), 3), np.zeros((1, 4)) + 0.5])
def test_bad_conditions_raise(cond):
    with pytest.raises(ConfigError, match="conditions"):
        build_propellers(VEHICLE, cond, kind="quadratic")


def test_unknown_kind_raises():
    with pytest.raises(ConfigError, match="kind"):
        build_propellers(VEHICLE, np.zeros((1, 4), dtype=int), kind="cubic")
