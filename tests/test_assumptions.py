"""The register of unmeasured assumptions, per-flight draws, and randomised data sets (a few seconds)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from monitor.errors import ConfigError
from monitor.vehicle import DEFAULT_VEHICLE, GRAVITY_M_S2, load_vehicle
from offline.sim.assumptions import REGISTER, AssumptionRegister, draw_flight, draw_flights

VEHICLE = load_vehicle(DEFAULT_VEHICLE)

# What the register must cover, by entry name.
REQUIRED = [
    *(
        f"{kind}_{q}"
        for kind in ("bent", "cracked")
        for q in (
            "thrust_loss_low_frac",
            "thrust_loss_high_frac",
            "torque_per_thrust_change_low_frac",
            "torque_per_thrust_change_high_frac",
            "ripple_1p_thrust_frac",
            "flutter_thrust_std_frac",
        )
    ),
    "motor_efficiency_spread_frac",
    "healthy_torque_per_thrust_spread_frac",
    "cg_offset_frd_m",
    "arm_position_error_m",
    "inertia_error_frac",
    "motor_time_constant_s",
    "esc_offset_rpm",
    "rotor_inertia_kg_m2",
    "mc_rollrate_p",
    "mc_yawrate_p",
    "mc_roll_p",
    "mpc_xy_vel_p_acc",
    "gyro_bias_frd_rad_s",
    "gyro_noise_std_rad_s",
    "attitude_noise_std_rad",
    "attitude_log_delay_s",
    "telemetry_jitter_std_s",
    "telemetry_drop_prob",
    "wind_mean_m_s",
    "turbulence_sigma_w_m_s",
    "esc_voltage_exponent",
    "battery_internal_resistance_ohm",
    "blade_flapping_trim_per_m_s",
]


def test_register_covers_the_listed_quantities_with_reasons_and_real_ranges():
    for name in REQUIRED:
        a = REGISTER[name]
        assert a.modelled, name
        assert a.high > a.low, f"{name}: degenerate range"
        assert len(a.reason) > 30, f"{name}: give the reason for the range"
    # Whatever is left out is said to be left out.
    assert {a.name for a in REGISTER.assumptions if not a.modelled} >= {"ground_effect", "ekf_dynamics"}
    # Controller gains stay within the PX4-documented ranges quoted in their reasons.
    assert 0.01 <= REGISTER["mc_rollrate_p"].low and REGISTER["mc_rollrate_p"].high <= 0.5
    assert REGISTER["mc_roll_p"].high <= 8.0
    # The spread quoted for real airframes.
    assert (REGISTER["motor_efficiency_spread_frac"].low, REGISTER["motor_efficiency_spread_frac"].high) == (0.04, 0.08)


def test_register_rejects_bad_entries():
    with pytest.raises(ConfigError, match="duplicate"):
        AssumptionRegister(REGISTER.assumptions + REGISTER.assumptions[:1])
    with pytest.raises(ConfigError, match="no entry"):
        REGISTER.with_range("no_such_thing", 0, 1)
    with pytest.raises(ConfigError, match="low <= high"):
        dataclasses.replace(REGISTER["mc_roll_p"], low=2.0, high=1.0)


def _same(a, b) -> bool:
    return a.values.keys() == b.values.keys() and all(np.array_equal(a[k], b[k]) for k in a.values)


def test_draws_are_deterministic_and_independent_of_chunking_and_register_order():
    whole = draw_flights(REGISTER, 11, range(8))
    chunks = draw_flights(REGISTER, 11, range(0, 3)) + draw_flights(REGISTER, 11, range(3, 8))
    assert all(_same(a, b) for a, b in zip(whole, chunks))
    reordered = AssumptionRegister(tuple(reversed(REGISTER.assumptions)))
    assert _same(draw_flight(reordered, np.random.SeedSequence([11, 5])), whole[5])
    assert not _same(whole[0], whole[1])
    # Changing one range changes that entry's draws only.
    narrowed = draw_flight(REGISTER.with_range("mc_roll_p", 6.0, 6.1), np.random.SeedSequence([11, 5]))
    assert narrowed["mc_roll_p"] != whole[5]["mc_roll_p"]
    assert np.array_equal(narrowed["bent_thrust_loss_low_frac"], whole[5]["bent_thrust_loss_low_frac"])


def test_torque_per_thrust_draws_take_both_signs_and_the_signature_matches_them():
    flights = draw_flights(REGISTER, 0, range(100))
    for kind in ("bent", "cracked"):
        c = np.concatenate([f[f"{kind}_torque_per_thrust_change_high_frac"] for f in flights])
        assert c.min() < -0.04 and c.max() > 0.05
        lo, hi = (
            REGISTER[f"{kind}_torque_per_thrust_change_high_frac"].low,
            REGISTER[f"{kind}_torque_per_thrust_change_high_frac"].high,
        )
        assert lo <= c.min() and c.max() <= hi
    # Hand check: the drawn signature's torque factor / thrust factor is 1 + c at s = 0 and s = 1.
    f = flights[3]
    sig = f.signature(2, "cracked")
    for s, key in ((0.0, "low"), (1.0, "high")):
        ratio = sig.torque_factor(np.array(s)) / sig.thrust_factor(np.array(s))
        assert ratio == pytest.approx(1.0 + f[f"cracked_torque_per_thrust_change_{key}_frac"][2], rel=1e-12)


def test_hover_thrust_equals_weight_and_each_rotor_reaches_its_drawn_efficiency():
    """Physics invariant under a draw: in still air, hovering at the start point, total thrust = weight,
    and each rotor's speed is (efficiency x command + ESC offset) x battery-sag scale."""
    from offline.sim.perflight import PerFlightTerms
    from offline.sim.propeller import QuadraticPropeller
    from offline.sim.simulator import SimConfig, simulate

    still = REGISTER.with_range("wind_mean_m_s", 0.0, 0.0).with_range("turbulence_sigma_w_m_s", 0.0, 0.0)
    phys = draw_flights(still, 4, range(2))
    terms = PerFlightTerms.from_flights(phys, VEHICLE)
    sim = dataclasses.replace(SimConfig(), duration_s=8.0)
    hold = np.broadcast_to(np.array(sim.start_ned_m), (2, 1, 3))
    log = simulate(VEHICLE, hold, QuadraticPropeller.for_vehicle(VEHICLE), sim, seed=[1, 2], per_flight=terms)
    late = slice(-60, None)  # the last 3 s
    thrust = log.thrust_n[:, late].sum(axis=2).mean(axis=1)
    np.testing.assert_allclose(thrust, VEHICLE.mass_kg * GRAVITY_M_S2, rtol=0.01)
    cmd = VEHICLE.esc.cmd_to_omega_rad_s(log.pwm_us[:, late])
    sag = (log.battery_v[:, late] / VEHICLE.battery_full_v) ** terms.esc_voltage_exponent[:, None]
    expected = (cmd * terms.motor_efficiency[:, None, :] + terms.esc_offset_rad_s[:, None, :]) * sag[..., None]
    # Averaged over 3 s: the gyro noise moves the 200 Hz command faster than the motor lag follows.
    np.testing.assert_allclose(log.motor_omega_rad_s[:, late].mean(axis=1), expected.mean(axis=1), rtol=0.003)
    # The drawn spread really shows: the four rotors of a flight do not share one efficiency.
    assert np.ptp(terms.motor_efficiency, axis=1).min() > 0.005


def test_randomised_dataset_records_the_register_and_shards_equal_the_whole():
    from offline.dataset.generate import DatasetSpec, generate

    spec = DatasetSpec(
        "R",
        fault="varied",
        waypoints=("random",),
        flights_per_label=1,
        duration_s=3.0,
        propellers="quadratic",
        physics="randomised",
        seed=9,
        chunk_flights=16,
    )
    quiet = dict(log=lambda *_: None)
    whole = generate(spec, VEHICLE, **quiet)
    chunked = generate(dataclasses.replace(spec, chunk_flights=5), VEHICLE, **quiet)
    for k in whole.signals:
        np.testing.assert_array_equal(whole.signals[k], chunked.signals[k])
    m = whole.manifest
    assert m["config"]["physics"] == "randomised"
    for name in REQUIRED:
        assert m["assumptions"][name]["low"] == REGISTER[name].low and m["assumptions"][name]["reason"]
    assert "SeedSequence([seed, i])" in m["physics_draws"]["rule"] and m["physics_draws"]["seed"] == 9
    assert list(whole.labels) == list(range(1, 17))
    assert all(np.isfinite(v).all() for v in whole.signals.values())


def test_randomised_physics_refuses_what_it_cannot_apply():
    from offline.dataset.generate import DatasetSpec

    with pytest.raises(ConfigError, match="quadratic"):
        DatasetSpec("R", physics="randomised", propellers="lstm")
    with pytest.raises(ConfigError, match="wind_max_m_s"):
        DatasetSpec("R", physics="randomised", propellers="quadratic", wind_max_m_s=2.0)
    with pytest.raises(ConfigError, match="physics"):
        DatasetSpec("R", physics="sometimes")


def test_nominal_airframe_fixes_the_airframe_terms_and_draws_everything_else():
    from offline.dataset.generate import DatasetSpec
    from offline.sim.assumptions import AIRFRAME_TERMS, nominal_airframe

    reg = nominal_airframe()
    for name in AIRFRAME_TERMS:
        assert reg[name].low == reg[name].high == REGISTER[name].nominal
    seq = np.random.SeedSequence([5, 0])
    fixed, drawn = draw_flight(reg, seq), draw_flight(REGISTER, seq)
    assert np.all(np.asarray(fixed.values["cg_offset_frd_m"]) == REGISTER["cg_offset_frd_m"].nominal)
    assert np.allclose(fixed.motor_efficiency(), 1.0) and not np.allclose(drawn.motor_efficiency(), 1.0)
    # the damaged blade's terms are still drawn, the same as under the full register
    key = "bent_torque_per_thrust_change_low_frac"
    np.testing.assert_array_equal(fixed.values[key], drawn.values[key])
    with pytest.raises(ConfigError, match="airframe"):
        DatasetSpec("R", airframe="nominal")  # only randomised physics draws an airframe
    with pytest.raises(ConfigError, match="airframe"):
        DatasetSpec("R", physics="randomised", propellers="quadratic", airframe="guessed")


def test_dataset_cli_moves_a_register_range_by_glob_and_the_manifest_says_so(tmp_path, capsys):
    import json

    from offline.dataset import cli

    argv = ["--name", "S", "--fault", "varied", "--physics", "randomised", "--propellers", "quadratic"]
    argv += ["--flights-per-label", "1", "--duration", "3", "--waypoints", "random", "--out", str(tmp_path)]
    assert cli.main([*argv, "--assumption", "*torque_per_thrust_change*=-0.10,0"]) == 0
    m = json.loads((tmp_path / "S-varied.manifest.json").read_text())["assumptions"]
    moved = [n for n in m if "torque_per_thrust_change" in n]
    assert len(moved) == 4  # bent and cracked, low and high speed
    assert all((m[n]["low"], m[n]["high"]) == (-0.10, 0.0) for n in moved)
    assert m["motor_time_constant_s"]["low"] == REGISTER["motor_time_constant_s"].low  # the rest untouched
    assert m["healthy_torque_per_thrust_spread_frac"]["high"] == REGISTER["healthy_torque_per_thrust_spread_frac"].high
    # the names a glob moved are said: a looser one catches the healthy props' spread too
    err = capsys.readouterr().err
    assert all(n in err for n in moved)
    args = cli.build_parser().parse_args([*argv, "--assumption", "*torque_per_thrust*=-0.10,0"])
    assert cli.register_from_args(args)["healthy_torque_per_thrust_spread_frac"].low == -0.10
    assert "healthy_torque_per_thrust_spread_frac" in capsys.readouterr().err
    for bad, why in [
        ("*torque*", "NAME=LOW,HIGH"),
        ("nothing_like_this=0,1", "no register entry"),
        ("*torque_per_thrust*=0.3,-0.1", "LOW <= HIGH"),
        ("*torque_per_thrust*=nan,1", "finite"),
    ]:
        with pytest.raises(ConfigError, match=why):
            cli.main([*argv, "--assumption", bad])
    with pytest.raises(ConfigError, match="randomised"):
        cli.main(["--name", "S", "--assumption", "*torque*=0,0", "--out", str(tmp_path)])


def test_blade_flapping_trims_the_front_rotors_by_the_drawn_share_per_m_s():
    """Hand calculation: flying forward at v with a drawn flapping trim t, each front rotor's yaw-free omega^2
    share falls by t v against the same flight without flapping (rear rotors rise by as much), and a flight
    without flapping does not see it."""
    from offline.sim.perflight import PerFlightTerms
    from offline.sim.propeller import QuadraticPropeller
    from offline.sim.simulator import SimConfig, simulate

    still = REGISTER.with_range("wind_mean_m_s", 0.0, 0.0).with_range("turbulence_sigma_w_m_s", 0.0, 0.0)
    trim = 0.02
    phys = [
        draw_flights(still.with_range("blade_flapping_trim_per_m_s", t, t), 4, range(1))[0] for t in (0.0, trim)
    ]  # the same flight (seed, index) but for its flapping
    terms = PerFlightTerms.from_flights(phys, VEHICLE)
    assert terms.flapping_nm_per_rad_s_m_s[0] == 0.0 and terms.flapping_nm_per_rad_s_m_s[1] > 0.0
    sim = dataclasses.replace(SimConfig(), duration_s=32.0)
    start = np.array(sim.start_ned_m)
    north = np.broadcast_to(np.stack([start, start + [400.0, 0.0, 0.0]]), (2, 2, 3))  # heading north at cruise
    log = simulate(VEHICLE, north, QuadraticPropeller.for_vehicle(VEHICLE), sim, seed=[1, 1], per_flight=terms)
    om2 = log.motor_omega_rad_s**2
    share = om2 / om2.mean(axis=2, keepdims=True)
    c, y = np.full(4, 0.5), np.array([0.5, 0.5, -0.5, -0.5])
    yaw_free = share @ (np.eye(4) - np.outer(c, c) - np.outer(y, y))
    late = slice(-200, -40)  # 8 s of steady cruise (20 Hz log)
    v = log.vel_ned_m_s[:, late, 0].mean(axis=1)
    assert np.all(np.abs(v - 5.0) < 0.2)  # MPC_XY_CRUISE
    d = yaw_free[1, late].mean(axis=0) - yaw_free[0, late].mean(axis=0)
    # PX4 order: 1 front-right, 2 rear-left, 3 front-left, 4 rear-right
    np.testing.assert_allclose(d, [-trim * v[1], trim * v[1], -trim * v[1], trim * v[1]], atol=0.006)


def test_quadratic_drag_slows_the_body_by_c_v_squared():
    """Hand calculation: level, at 10 m/s north in still air, with only the drawn parasitic drag c = 0.03 N/(m/s)^2
    on body x, one step of dt changes the north velocity by -c v^2 dt / m (3 N on 1.5 kg: -2 m/s^2), and a flight
    drawn without it by nothing beyond its linear drag."""
    from offline.sim.dynamics import Dynamics, VehicleState
    from offline.sim.perflight import PerFlightTerms
    from offline.sim.propeller import QuadraticPropeller

    still = REGISTER.with_range("wind_mean_m_s", 0.0, 0.0).with_range("turbulence_sigma_w_m_s", 0.0, 0.0)
    still = still.with_range("linear_drag_n_per_m_s", 0.0, 0.0)
    phys = [draw_flights(still.with_range("quadratic_drag_n_per_m2_s2", c, c), 4, range(1))[0] for c in (0.0, 0.03)]
    terms = PerFlightTerms.from_flights(phys, VEHICLE)
    np.testing.assert_allclose(terms.quadratic_drag_n_per_m2_s2, [[0.0] * 3, [0.03] * 3])
    dt, mass = 0.002, VEHICLE.mass_kg
    dyn = Dynamics(VEHICLE, np.full(2, mass), dt, per_flight=terms)
    s = VehicleState.hover(2, (0.0, 0.0, -10.0), np.zeros(4))
    s.vel_ned_m_s[:] = [10.0, 0.0, 0.0]
    prop = QuadraticPropeller.for_vehicle(VEHICLE)
    prop.reset(s.omega_rad_s)
    dyn.step(s, np.zeros((2, 4)), prop)  # rotors off: gravity and drag only
    dv_north = s.vel_ned_m_s[:, 0] - 10.0
    assert dv_north[1] - dv_north[0] == pytest.approx(-0.03 * 10.0**2 * dt / mass, rel=1e-6)  # -0.004 m/s
    assert abs(dv_north[0]) < 1e-12  # no drag drawn: nothing
