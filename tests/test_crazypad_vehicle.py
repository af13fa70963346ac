"""models/crazyflie.yaml: cited, physically consistent, and numbered like Bitcraze."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.vehicle import REPO_ROOT, load_vehicle_with_sources
from offline.crazypad.vehicle import BITCRAZE_OF_PROJECT, G_M_S2, bitcraze_order, hover_cmd, torque_signs_frd

YAML = REPO_ROOT / "models" / "crazyflie.yaml"

# Signs of the firmware mixer (crazyflie-firmware power_distribution_quadrotor.c,
# powerDistributionForceTorque) for M1..M4, body FLU: motor force gets
# -roll -pitch -yaw, -roll +pitch +yaw, +roll +pitch -yaw, +roll -pitch +yaw.
FIRMWARE_FLU = np.array([[-1, -1, 1, 1], [-1, 1, 1, -1], [-1, 1, -1, 1]], dtype=float)
FLU_TO_FRD = np.array([1.0, -1.0, -1.0])[:, None]


@pytest.fixture(scope="module")
def loaded():
    return load_vehicle_with_sources(YAML)


def test_every_value_is_cited(loaded):
    assert loaded.sources, "no citations read"
    assert all(s.strip() for s in loaded.sources.values())
    assert "esc.b_rpm_per_cmd" in loaded.sources and "Foerster" in loaded.sources["esc.b_rpm_per_cmd"]
    assert loaded.config.esc.cmd_unit == "cf16"


def test_rotor_layout_reproduces_the_firmware_mixer(loaded):
    # The mixer is the inverse allocation: motor i's share of a torque has the
    # sign of its own torque. Our geometry, reordered to M1..M4, must match it.
    ours_m1_to_m4 = bitcraze_order(torque_signs_frd(loaded.config))
    np.testing.assert_array_equal(ours_m1_to_m4, FIRMWARE_FLU * FLU_TO_FRD)


def test_mapping_is_a_permutation():
    assert sorted(BITCRAZE_OF_PROJECT) == ["M1", "M2", "M3", "M4"]
    cols = np.arange(4.0)  # project rotor indices
    assert bitcraze_order(cols).tolist() == [0.0, 3.0, 1.0, 2.0]  # M1=rotor1, M2=rotor4, M3=rotor2, M4=rotor3


def test_symmetric_hover_balances_weight_and_all_moments(loaded):
    v = loaded.config
    cmd = hover_cmd(v)
    omega = v.esc.cmd_to_omega_rad_s(np.full(4, cmd))
    thrust = v.kf_n_per_rad_s2 * omega**2
    assert thrust.sum() == pytest.approx(v.mass_kg * G_M_S2, rel=1e-9)
    moments = torque_signs_frd(v)[:2] @ thrust, v.spin_sign @ (v.ktau_nm_per_rad_s2 * omega**2)
    assert np.allclose(moments[0], 0.0, atol=1e-15) and abs(moments[1]) < 1e-15
    # Hover needs a command well inside the range, with authority left to climb.
    assert 0.3 * v.esc.cmd_max < cmd < 0.8 * v.esc.cmd_max


def test_thrust_to_torque_ratio_is_foersters(loaded):
    v = loaded.config
    assert v.ktau_nm_per_rad_s2 / v.kf_n_per_rad_s2 == pytest.approx(0.005964552, rel=1e-3)
