"""What the library cannot express is reported as an "unexplained residual" with its size and where it sits,
never forced onto a term. Flights of our own simulator (``offline.calibrate.nominal_flights``: the
register drawn, 20 Hz with the link's delay, jitter and drops)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.calibrate.calibrate import calibrate_vehicle
from offline.calibrate.nominal_flights import nominal_flights

NOM = load_vehicle(DEFAULT_VEHICLE)


@pytest.fixture(scope="module")
def weak_rotor_3():
    """Rotor 3 reaches 93 % of its commanded speed: its thrust and torque fall by 13.5 %."""
    return nominal_flights(dataclasses.replace(NOM, motor_efficiency=(1.0, 1.0, 0.93, 1.0)), 2, 901, 30.0)


def test_an_effect_outside_the_library_is_an_unexplained_residual_at_its_rotor(weak_rotor_3):
    # Without motor_efficiency in the library nothing can express one rotor's torque deficit.
    r = calibrate_vehicle(weak_rotor_3, NOM, ["cg_offset", "mass", "drag"])
    assert r.cause is None, r.findings  # no term forced onto it
    u = r.to_json()["unexplained_residual"]
    assert u["found"] and "rotor_torque_3" in u["probes"], u
    p = u["probes"]["rotor_torque_3"]
    assert p["heldout_bic_gain"] > u["threshold"]
    assert -0.2 < p["value"] < -0.08, p  # the torque deficit, 1 - 0.93^2 = 0.135
    assert "yaw_accel_rad_s2, rotor 3" in u["summary"]
    assert any(n.startswith("unexplained residual") for n in r.notes)


def test_the_same_effect_inside_the_library_is_named_and_leaves_nothing_unexplained(weak_rotor_3):
    r = calibrate_vehicle(weak_rotor_3, NOM)
    assert r.cause == "motor_efficiency"
    assert not r.unexplained["found"], r.unexplained["summary"]
    # One rotor singled out: the caveat that a damaged propeller there would look the same, with the one-rotor
    # reading: a motor scales thrust and torque alike, so its torque per thrust stays near 0.
    ins = r.inspect_rotor
    assert ins["rotor"] == 3 and any("damaged propeller on rotor 3" in n for n in r.notes), r.notes
    one = ins["if_only_this_rotor"]
    assert -16.0 < one["thrust_pct"] < -11.0 and abs(one["torque_per_thrust_pct"]) < 2.0, one


@pytest.fixture(scope="module")
def nominal_pair():
    return nominal_flights(NOM, 2, 902, 30.0)


def test_nominal_flights_leave_nothing_unexplained(nominal_pair):
    r = calibrate_vehicle(nominal_pair, NOM)
    assert not r.unexplained["found"], r.unexplained["summary"]
    slow = r.unexplained["probes"]["slow_kinematic_error"]
    assert not slow["found"] and slow["corr_time_samples"] < slow["threshold"], slow


def test_rates_and_attitude_drifting_apart_slowly_are_an_unexplained_residual(nominal_pair):
    """Coloured (AR(1), about 1 s) noise on the logged rates: the kinematic residual stays correlated for seconds,
    which no term expresses; reported with its signal and size, nothing named for it."""
    tabs = []
    for i, t in enumerate(nominal_pair):
        rng = np.random.default_rng(i)
        z = np.zeros((len(t.timestamp_us), 3))
        e = rng.normal(size=z.shape) * np.sqrt(1 - 0.95**2)
        for k in range(1, len(z)):
            z[k] = 0.95 * z[k - 1] + e[k]
        tabs.append(
            dataclasses.replace(
                t,
                roll_rate_rad_s=t.roll_rate_rad_s + 0.02 * z[:, 0],
                pitch_rate_rad_s=t.pitch_rate_rad_s + 0.02 * z[:, 1],
                yaw_rate_rad_s=t.yaw_rate_rad_s + 0.02 * z[:, 2],
            )
        )
    r = calibrate_vehicle(tabs, NOM)
    slow = r.unexplained["probes"]["slow_kinematic_error"]
    assert r.unexplained["found"] and slow["found"], slow
    assert slow["corr_time_samples"] > slow["threshold"] and slow["signal"].endswith("_kin_rad_s")
    assert 0.005 < slow["slow_rms"] < 0.03, slow  # the slow part of 0.02 rad/s AR(1) noise, after the filters
    assert "slow_kinematic_error" in r.unexplained["summary"]


def test_a_delayed_segment_reads_the_motor_outputs_later():
    from offline.calibrate.prepare import prepare
    from offline.calibrate.unexplained import delayed

    seg = prepare(nominal_flights(NOM, 1, 903, 12.0), NOM)[0]
    late = delayed(seg, 0.03)  # three fine steps at 20 Hz
    k = round(0.03 / seg.dt_fine_s)
    np.testing.assert_allclose(late.motor_cmd_fine[k:], seg.motor_cmd_fine[:-k], rtol=1e-9)
    np.testing.assert_array_equal(late.rates_fine_rad_s, seg.rates_fine_rad_s)  # the estimator's side untouched


def test_a_rotor_singled_out_by_motor_efficiency_is_to_be_inspected():
    from offline.calibrate.calibrate import inspect_rotor

    # A damaged propeller on rotor 1 (evaluation simulator, 8-15 % thrust lost): fitted as these efficiencies.
    got = inspect_rotor([0.940, 0.992, 1.007, 1.008])
    assert got["rotor"] == 1 and got["thrust_vs_others_pct"] < -5.0 and "damaged propeller on rotor 1" in got["why"]
    assert inspect_rotor([1.0, 1.0, 0.97, 1.0])["rotor"] == 3  # a weak motor, 6 % thrust: the same caveat
    assert inspect_rotor([1.0, 1.0, 0.985, 1.0]) is None  # 3 % thrust: below it
    # A four-way spread (+-8 % thrust, the matrix's pattern): no single rotor stands out.
    assert inspect_rotor(list(np.sqrt(1.0 + 0.08 * np.array([1.0, -1.0, 0.5, -0.5])))) is None


def test_nominal_flights_fix_the_library_terms_and_draw_the_rest():
    """The gates are set on these flights: a term named on them is named wrongly only if its register entry is
    held at nominal, and the nuisances must vary from flight to flight."""
    from offline.calibrate.nominal_flights import LIBRARY_ENTRIES, nominal_register
    from offline.sim.assumptions import AIRFRAME_TERMS, draw_flights

    reg = nominal_register()
    flights = draw_flights(reg, 3, range(2))
    for name in LIBRARY_ENTRIES + AIRFRAME_TERMS:
        assert reg[name].low == reg[name].high == reg[name].nominal, name
    for name in ("battery_internal_resistance_ohm", "attitude_log_delay_s", "turbulence_sigma_w_m_s", "mc_rollrate_p"):
        assert flights[0][name] != flights[1][name], name


def test_the_delay_rival_keeps_a_term_unnamed_only_beyond_its_margin():
    """The rule by hand: the round's best passing term loses its name only when the outside-library rival's held-out
    BIC is lower than its own by more than the margin; the verdict names the gate, the rival and the numbers."""
    from types import SimpleNamespace

    from offline.calibrate.fit import RIVAL_MARGIN_BIC, rival_verdict

    trial = SimpleNamespace(bic=100.0)
    rival = {"name": "telemetry_delay", "describe": "estimator signals 80 ms later", "bic": 100.0 - RIVAL_MARGIN_BIC - 1.0}
    v = rival_verdict("motor_time_constant", trial, rival, 500.0)
    assert not v.named and v.gate == "outside_library" and v.gain == 400.0
    assert "telemetry_delay" in v.why and "not motor_time_constant" in v.why, v.why
    (check,) = v.checks
    assert check.numbers["lead"] == RIVAL_MARGIN_BIC + 1.0 and not check.passed
    assert rival_verdict("motor_time_constant", trial, rival | {"bic": 100.0 - RIVAL_MARGIN_BIC + 1.0}, 500.0) is None
