"""The rotors' spin-up reaction in yaw (rotor inertia x dω/dt): the term a motor lag needs to fit yaw.

Hidden-effect tests on our own simulator's fixed path (``offline.sim``, which applies ``rotor_inertia_kg_m2``):
a lag on all four rotors with the spin-up reaction present is vetoed by the yaw axis when the lag is fitted
without the reaction (the model before the term), and named with the right value when it is fitted with it;
with nothing hidden, neither the lag nor the rotor inertia is named.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.calibrate.fit import Data, select_terms
from offline.calibrate.nominal_flights import fixed_flights
from offline.calibrate.physics import rotor_forces
from offline.calibrate.prepare import prepare
from offline.calibrate.terms import TERMS, without_spin_up
from offline.calibrate.unexplained import delay_probe

NOM = load_vehicle(DEFAULT_VEHICLE)
LAG_S = 0.06
ROTOR_INERTIA_KG_M2 = 2.0e-5  # inside the assumption register's 1e-5 .. 4e-5


def test_the_spin_up_reaction_is_rotor_inertia_times_the_lagged_speed_rate():
    """Steady ramp of one rotor's target: the lagged speed trails it by tau and the torque carries J * slope."""
    seg = prepare(fixed_flights(NOM, 1, 0, 12.0), NOM)[0]
    n = len(seg.motor_cmd_fine)
    slope_rad_s2 = 50.0
    w_target = 500.0 + slope_rad_s2 * np.arange(n) * seg.dt_fine_s
    cmd = NOM.esc.omega_rad_s_to_cmd(np.column_stack([w_target] * 4))
    s = dataclasses.replace(seg, motor_cmd_fine=cmd)
    with_j = dataclasses.replace(NOM, rotor_inertia_kg_m2=ROTOR_INERTIA_KG_M2)
    f0, q0 = rotor_forces(s, NOM)
    f1, q1 = rotor_forces(s, with_j)
    np.testing.assert_array_equal(f0, f1)  # thrust does not see it
    late = slice(n // 2, None)  # after the lag's transient (many time constants)
    np.testing.assert_allclose((q1 - q0)[late], ROTOR_INERTIA_KG_M2 * slope_rad_s2, rtol=1e-3)


@pytest.fixture(scope="module")
def lag_and_spin_up():
    truth = dataclasses.replace(NOM, motor_time_constant_s=LAG_S, rotor_inertia_kg_m2=ROTOR_INERTIA_KG_M2)
    return Data.split(prepare(fixed_flights(truth, 2, 0), NOM))


def test_a_lag_fitted_without_the_spin_up_reaction_is_vetoed_by_yaw(lag_and_spin_up):
    """The cause of the veto: without the reaction, the lag buys roll and pitch and loses yaw."""
    lags = [without_spin_up(TERMS[n]) for n in ("motor_time_constant", "rotor_time_constant")]
    sel = select_terms(lag_and_spin_up, NOM, lags, rival=delay_probe)
    v = sel.steps[0].verdicts["motor_time_constant"]
    assert not v.named and v.gate == "consistency", v.why
    assert "yaw_accel_rad_s2" in v.why and v.gain > 200


def test_a_lag_with_the_spin_up_reaction_is_named_with_both_values(lag_and_spin_up):
    sel = select_terms(lag_and_spin_up, NOM, list(TERMS.values()), rival=delay_probe)
    assert sel.chosen[0] in ("motor_time_constant", "rotor_time_constant"), sel.chosen
    v = sel.final.vehicle
    assert abs(v.motor_time_constant_s - LAG_S) <= 0.15 * LAG_S, v.motor_time_constant_s
    assert abs(v.rotor_inertia_kg_m2 - ROTOR_INERTIA_KG_M2) <= 0.25 * ROTOR_INERTIA_KG_M2, v.rotor_inertia_kg_m2


def test_nothing_hidden_names_neither_a_lag_nor_rotor_inertia():
    data = Data.split(prepare(fixed_flights(NOM, 2, 0), NOM))
    sel = select_terms(data, NOM, list(TERMS.values()), rival=delay_probe)
    assert not set(sel.chosen) & {"motor_time_constant", "rotor_time_constant", "rotor_inertia"}, sel.chosen
