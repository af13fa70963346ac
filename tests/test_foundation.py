"""Shared contracts: config loader, vehicle file, ESC curve, labels, features, resampling, CLI."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from monitor import esc, features, labels, resample
from monitor.config import from_mapping, to_mapping
from monitor.errors import ConfigError
from monitor.vehicle import CALIBRATION_TERMS, DEFAULT_VEHICLE, load_vehicle, load_vehicle_with_sources, quad_x_positions

REPO = Path(__file__).resolve().parent.parent


# --- vehicle file -----------------------------------------------------------------


def test_paper_vehicle_loads_with_every_value_cited():
    lv = load_vehicle_with_sources(DEFAULT_VEHICLE)
    v = lv.config
    assert v.mass_kg == 1.5 and v.arm_length_m == 0.16
    assert v.inertia_diag_kg_m2 == (0.0123, 0.0123, 0.0224)
    assert v.kf_n_per_rad_s2 == 1.076e-5 and v.ktau_nm_per_rad_s2 == 1.632e-7
    # every leaf has a non-empty source
    flat = to_mapping(v)
    n_leaves = sum(len(x) if isinstance(x, dict) else 1 for x in flat.values())
    assert len(lv.sources) == n_leaves - sum(1 for k in flat if k in CALIBRATION_TERMS)


def test_hover_from_hand_calculation():
    v = load_vehicle(DEFAULT_VEHICLE)
    # 1.5 kg * 9.80665 / 4 rotors = kF * w^2  ->  w = 584.6 rad/s
    assert v.hover_omega_rad_s == pytest.approx(584.6, abs=0.2)
    rpm = v.hover_omega_rad_s * 60 / (2 * np.pi)
    assert float(v.esc.rpm_to_cmd(rpm)) == pytest.approx(1368, abs=1.0)


def test_quad_x_layout_and_spins_follow_px4():
    v = load_vehicle(DEFAULT_VEHICLE)
    np.testing.assert_allclose(v.rotor_positions_array_m, np.array(quad_x_positions(0.16)), atol=1e-6)
    pos = v.rotor_positions_array_m
    assert pos[0, 0] > 0 and pos[0, 1] > 0  # 1 front-right
    assert pos[1, 0] < 0 and pos[1, 1] < 0  # 2 rear-left
    assert pos[2, 0] > 0 and pos[2, 1] < 0  # 3 front-left
    assert pos[3, 0] < 0 and pos[3, 1] > 0  # 4 rear-right
    assert list(v.spin_sign) == [1, 1, -1, -1]  # 1,2 CCW; 3,4 CW


def _vehicle_dict():
    return yaml.safe_load(DEFAULT_VEHICLE.read_text())


@pytest.mark.parametrize(
    "mutate, key",
    [
        (lambda d: d.update(mass_g={"value": 1, "source": "x"}), "mass_g"),
        (lambda d: d.pop("mass_kg"), "mass_kg"),
        (lambda d: d.update(mass_kg={"value": -1.5, "source": "x"}), "mass_kg"),
        (lambda d: d.update(mass_kg=1.5), "mass_kg"),
        (lambda d: d["esc"].update(bogus={"value": 1, "source": "x"}), "bogus"),
        (lambda d: d.update(rotor_spin={"value": ["ccw", "ccw", "cw", "up"], "source": "x"}), "rotor_spin"),
        (lambda d: d.update(inertia_diag_kg_m2={"value": [0.01, 0.01], "source": "x"}), "inertia_diag_kg_m2"),
        (lambda d: d.update(motor_time_constant_s={"value": "fast", "source": "x"}), "motor_time_constant_s"),
    ],
)
def test_bad_vehicle_yaml_names_the_key(tmp_path, mutate, key):
    d = _vehicle_dict()
    mutate(d)
    p = tmp_path / "v.yaml"
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(ConfigError) as ei:
        load_vehicle(p)
    assert key in str(ei.value) and str(p) in str(ei.value)


def test_unparseable_yaml_names_the_file(tmp_path):
    p = tmp_path / "broken.yaml"
    p.write_text("mass_kg: [1, 2\n")
    with pytest.raises(ConfigError, match="broken.yaml"):
        load_vehicle(p)


def test_config_round_trip_with_sources():
    lv = load_vehicle_with_sources(DEFAULT_VEHICLE)
    again, sources = from_mapping(type(lv.config), to_mapping(lv.config, lv.sources), cited=True)
    assert again == lv.config
    assert {k: v for k, v in sources.items() if k in lv.sources} == lv.sources


# --- ESC curve --------------------------------------------------------------------


def test_paper_esc_fit_values_and_inverse():
    # RPM = -0.0062 PWM^2 + 29.37 PWM - 22992, by hand at 1500 us: 7113 RPM
    assert float(esc.pwm_us_to_rpm(1500.0)) == pytest.approx(-0.0062 * 1500**2 + 29.37 * 1500 - 22992)
    pwm = np.linspace(1000, 2000, 101)
    np.testing.assert_allclose(esc.rpm_to_pwm_us(esc.pwm_us_to_rpm(pwm)), pwm, atol=1e-6)
    assert float(esc.pwm_us_to_rpm(2500)) == float(esc.pwm_us_to_rpm(2000))  # saturates, never extrapolates


def test_non_invertible_esc_curve_is_rejected():
    with pytest.raises(ConfigError, match="invertible"):
        esc.EscCurve(-0.0062, 29.37, -22992, 1000, 2600)


# --- labels -----------------------------------------------------------------------


def test_label_table_matches_the_paper():
    assert labels.faulty_for(1) == ()
    assert [labels.faulty_for(k) for k in range(2, 6)] == [(1,), (2,), (3,), (4,)]
    assert labels.faulty_for(13) == (1, 2, 4) and labels.faulty_for(14) == (1, 3, 4)  # paper Fig. 30
    assert labels.faulty_for(16) == (1, 2, 3, 4)
    seen = {frozenset(labels.faulty_for(k)) for k in range(1, 17)}
    assert len(seen) == 16  # every subset exactly once
    for k in range(1, 17):
        assert labels.label_from_mask(labels.LABEL_MASKS[k - 1]) == k


def test_marginal_fault_probability():
    p = np.zeros(16)
    p[labels.label_for([3]) - 1] = 0.6
    p[labels.label_for([1, 3]) - 1] = 0.4
    np.testing.assert_allclose(labels.fault_probability_from_label_probs(p), [0.4, 0.0, 1.0, 0.0])


# --- features and windows ---------------------------------------------------------


def _signals(b=2, t=150, seed=0):
    rng = np.random.default_rng(seed)
    s = {n: rng.normal(size=(b, t)) for n in features.SIGNALS[1:]}
    s["motor_rpm"] = 5000 + 100 * rng.normal(size=(b, t, 4))
    return s


def test_paper_features_order_and_values():
    s = _signals()
    x = features.compute_features(s, features.PAPER_FEATURES)
    assert x.shape == (2, 150, 10) and x.dtype == np.float32
    np.testing.assert_allclose(x[..., 2], s["motor_rpm"][..., 2], rtol=1e-6)
    np.testing.assert_allclose(x[..., 9], s["yaw_rate_rad_s"], rtol=1e-6)


def test_relative_rpm_is_invariant_to_a_common_scale():
    s = _signals()
    s2 = dict(s, motor_rpm=s["motor_rpm"] * 1.3)
    names = [f"rpm_rel_{i}" for i in range(1, 5)]
    np.testing.assert_allclose(features.compute_features(s, names), features.compute_features(s2, names), atol=1e-6)


def test_windows_are_strided_views_with_hop():
    x = features.compute_features(_signals(), features.PAPER_FEATURES)
    w = features.sliding_windows(x, 100, 1)
    assert w.shape == (2, 51, 100, 10) and np.shares_memory(w, x)
    np.testing.assert_array_equal(w[1, 7], x[1, 7:107])
    assert features.sliding_windows(x, 100, 5).shape == (2, 11, 100, 10)
    assert features.sliding_windows(x[:, :50], 100).shape[-3] == 0


def test_nan_windows_are_flagged_not_filled():
    x = features.compute_features(_signals(b=1), features.PAPER_FEATURES)[0]
    x[120, 4] = np.nan
    ok = features.valid_windows(features.sliding_windows(x, 100))
    assert ok[:20].all() and not ok[21:].any()  # windows 21..50 contain index 120


def test_unknown_feature_is_rejected():
    from monitor.errors import ModelError

    with pytest.raises(ModelError, match="rpm_9"):
        features.compute_features(_signals(), ["rpm_9"])


# --- resampling -------------------------------------------------------------------


def test_hold_resampling_on_the_boot_clock_grid():
    grid = resample.grid_us(1_030_000, 1_260_000, 20.0)
    np.testing.assert_array_equal(grid, [1_050_000, 1_100_000, 1_150_000, 1_200_000, 1_250_000])
    t = np.array([1_040_000, 1_090_000, 1_100_000, 1_240_000])
    v = np.array([1.0, 2.0, 3.0, 4.0])
    out = resample.hold(t, v, grid, max_age_us=60_000)
    # 1.05 -> 1.0; 1.10 -> 3.0 (sample exactly at the instant); 1.15 -> 3.0; 1.20 -> stale (100 ms); 1.25 -> 4.0
    np.testing.assert_array_equal(out[[0, 1, 2, 4]], [1.0, 3.0, 3.0, 4.0])
    assert np.isnan(out[3])


def test_rates_that_do_not_give_whole_microseconds_are_rejected():
    with pytest.raises(ValueError):
        resample.period_us(3.0)


# --- CLI and the onboard/offline boundary -------------------------------------------


def test_cli_lists_commands_and_rejects_unknown():
    r = subprocess.run([sys.executable, "-m", "monitor.cli", "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "diagnose" in r.stdout and "simulate" in r.stdout
    r = subprocess.run([sys.executable, "-m", "monitor.cli", "fly-to-the-moon"], capture_output=True, text=True)
    assert r.returncode == 2 and "unknown command" in r.stderr


def test_monitor_package_never_imports_torch_or_offline():
    code = (
        "import sys, pkgutil, importlib\n"
        "sys.modules['torch'] = None\n"
        "import monitor\n"
        "for m in pkgutil.walk_packages(monitor.__path__, 'monitor.'):\n"
        "    if m.name.endswith('__main__'): continue\n"
        "    importlib.import_module(m.name)\n"
        "bad = [k for k in sys.modules if k == 'offline' or k.startswith('offline.')]\n"
        "assert not bad, bad\n"
        "print('ok')\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr
