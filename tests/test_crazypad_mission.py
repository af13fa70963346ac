"""The CrazyPAD mission in the simulator, the cut-propeller data, and the truth labels."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.labels import LABEL_TABLE
from monitor.vehicle import REPO_ROOT, load_vehicle
from offline.crazypad.data import CrazypadFlight
from offline.crazypad.experiment import truth_label
from offline.crazypad.mission import CRAZYPAD, batch_waypoints, sim_config
from offline.crazypad.vehicle import PROJECT_INDEX_OF_BITCRAZE, hover_cmd
from offline.sim.propeller import QuadraticPropeller
from offline.sim.simulator import simulate


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle(REPO_ROOT / "models" / "crazyflie.yaml")


@pytest.fixture(scope="module")
def flown(vehicle):
    """Two flights: healthy, and M3 losing 25 % of its thrust and drag torque."""
    scale = np.ones((2, 4))
    scale[1, PROJECT_INDEX_OF_BITCRAZE["M3"]] = 0.75
    props = QuadraticPropeller.for_vehicle(vehicle, thrust_scale=scale, torque_scale=scale)
    return simulate(vehicle, batch_waypoints(2), props, sim_config(), seed=3)


def test_mission_flies_the_script(flown):
    x, z = flown.pos_ned_m[0, :, 0], -flown.pos_ned_m[0, :, 2]
    assert x.max() == pytest.approx(CRAZYPAD.travel_x_m, abs=0.1)  # out to 2 m ...
    assert x[-1] < 0.3  # ... and back
    assert z.max() == pytest.approx(CRAZYPAD.height_m, abs=0.05)
    assert z.min() > CRAZYPAD.band_m - 0.1  # never below the airborne band
    assert np.abs(flown.pos_ned_m[0, :, 1]).max() < 0.05  # straight along x


def test_level_flight_commands_match_the_hover_trim(vehicle, flown):
    level = np.abs(flown.vel_ned_m_s[0, :, 2]) < 0.02
    assert np.mean(flown.pwm_us[0, level]) == pytest.approx(hover_cmd(vehicle), rel=0.02)


def test_a_weak_rotor_takes_a_larger_share(flown):
    m3 = PROJECT_INDEX_OF_BITCRAZE["M3"]
    cmd = flown.pwm_us[:, 20:]
    share = cmd.mean(axis=1) / cmd.mean(axis=(1, 2))[:, None]
    assert abs(share[0] - 1).max() < 0.01
    assert share[1, m3] > 1.05 and np.argmax(share[1]) == m3


def _flight(kind, faulty=(False, False, False, False)):
    return CrazypadFlight("x", "motor", "motor", "c", kind, faulty, "E8", 0)


def test_truth_labels_use_px4_order():
    m3 = PROJECT_INDEX_OF_BITCRAZE["M3"] + 1
    assert LABEL_TABLE[truth_label(_flight("propeller_cut", (False, False, True, False)))] == (m3,)
    both = truth_label(_flight("tape_on_propeller", (False, False, True, True)))
    assert set(LABEL_TABLE[both]) == {m3, PROJECT_INDEX_OF_BITCRAZE["M4"] + 1}
    for kind in ("healthy", "added_mass_near_motor", "hanging_mass_on_string"):
        assert truth_label(_flight(kind)) == 1


def test_simulated_dataset_is_deterministic_and_labelled(vehicle):
    from offline.crazypad.simdata import Recipe, simulate_dataset

    r = Recipe(flights_per_label=1, labels=(1, 4), seed=5)
    a, b = simulate_dataset(vehicle, r, "t"), simulate_dataset(vehicle, r, "t")
    assert a.labels.tolist() == [1, 4]
    np.testing.assert_array_equal(a.signals["motor_rpm"], b.signals["motor_rpm"])
    assert np.isnan(a.signals["motor_rpm"][:, 0]).all() and np.isfinite(a.signals["motor_rpm"][:, 20:]).all()
    rpm = np.nanmean(a.signals["motor_rpm"], axis=1)
    share = rpm / rpm.mean(axis=1, keepdims=True)
    assert np.argmax(share[1]) == 2 and share[1, 2] > share[0, 2]  # label 4: propeller 3 (index 2) faulty


def test_two_airframe_training_set_keeps_the_esc_curve_for_the_model(vehicle):
    from dataclasses import replace

    from offline.classifier.train import vehicle_info
    from offline.crazypad.simdata import Recipe, training_set

    other = replace(vehicle, motor_efficiency=(0.95, 1.0, 1.05, 1.0))
    ds = training_set([vehicle, other], Recipe(flights_per_label=2, labels=(1,)), "two")
    assert ds.n_flights == 2
    info = vehicle_info(ds)
    assert info["esc"]["cmd_unit"] == "cf16" and info["esc"]["b_rpm_per_cmd"] == vehicle.esc.b_rpm_per_cmd


def test_equivalent_speed_ratio_recovers_a_weak_rotor(vehicle):
    from dataclasses import replace

    from offline.calibrate.fit import equivalent_speed_ratios, predicted_commands

    base = replace(vehicle, motor_efficiency=(0.95, 0.92, 1.05, 1.08))
    np.testing.assert_allclose(equivalent_speed_ratios(base, predicted_commands(base)[None]), 1.0, atol=1e-4)
    m3 = PROJECT_INDEX_OF_BITCRAZE["M3"]
    eff = np.array(base.motor_efficiency)
    eff[m3] *= 0.9
    r = equivalent_speed_ratios(base, predicted_commands(replace(base, motor_efficiency=tuple(eff)))[None])
    assert r[m3] / np.delete(r, m3).mean() == pytest.approx(0.9, rel=2e-3)
