"""Stacked-LSTM propellers: torch/numpy parity, stateful = windowed, shipped accuracy, hover, scaling."""

import dataclasses
import json

import numpy as np
import pytest

from monitor.errors import ModelError
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.propellers import CONDITIONS, MODELS_DIR, build_propellers
from offline.propellers.loadcell import LoadCellConfig, run_load_cell
from offline.propellers.lstm_runtime import load_condition_models
from offline.sim.faults import SIGNATURES

VEHICLE = load_vehicle(DEFAULT_VEHICLE)
MODELS = load_condition_models(MODELS_DIR)
MANIFEST = json.loads((MODELS_DIR / "manifest.json").read_text())


def test_numpy_runtime_matches_torch():
    torch = pytest.importorskip("torch")
    from offline.propellers.lstm_train import Normalisation, StackedLstmNet, to_numpy

    torch.manual_seed(1)
    net = StackedLstmNet(12, 8).eval()
    norm = Normalisation(0.5, 0.3, (0.3, 0.3), (0.25, 0.2))
    model = to_numpy(net, norm, "normal", 0.025, 16)
    s = np.random.default_rng(0).uniform(0, 1, (3, 50))
    with torch.no_grad():
        ref = net(torch.as_tensor((s - 0.5) / 0.3, dtype=torch.float32)[..., None]).double().numpy()
    ref = np.array(norm.output_mean) + np.array(norm.output_std) * ref
    out, _ = model.run(s)
    np.testing.assert_allclose(out, ref, atol=2e-6)


@pytest.mark.parametrize("condition", CONDITIONS)
def test_stateful_equals_windowed(condition):
    """Stepping the state over a whole sweep gives what the paper's windowed model gives at every step."""
    model = MODELS[condition]
    s, _ = run_load_cell(VEHICLE, condition, LoadCellConfig(duration_s=30.0, seed=11)).normalised(VEHICLE)
    stateful, _ = model.run(s[None, :])
    windowed = model.windowed(s[None, :])
    # Outputs are fractions of full-scale thrust/torque: within 1e-4 of full scale (measured: < 1e-5).
    np.testing.assert_allclose(stateful[0, model.window_steps :], windowed[0, model.window_steps :], atol=1e-4)


@pytest.mark.parametrize("condition", CONDITIONS)
def test_shipped_lstms_learn_the_load_cell_formula_back_to_its_noise_floor(condition):
    """Regenerate the shipped training sweep (same seed), score the shipped weights on its last 20 %.

    What this shows is not a result about propellers: the load cell's thrust and torque come from a formula
    we wrote (kF·ω² times a guessed signature, plus chosen noise), and the LSTM's error sits at that formula's
    own error against its noisy samples. The recorded figures are the ones these weights give.
    """
    pytest.importorskip("torch")
    from offline.propellers.lstm_train import TrainConfig, evaluate

    cfg = TrainConfig(**MANIFEST["config"]["training"])
    cell = LoadCellConfig(seed=MANIFEST["seed"])
    s, y = run_load_cell(VEHICLE, condition, cell).normalised(VEHICLE)
    m = evaluate(MODELS[condition], s, y, cfg, formula=SIGNATURES[condition])
    for out in ("thrust", "torque"):
        floor = m[f"formula_{out}_mape_pct"]
        assert floor * 0.9 <= m[f"lstm_{out}_mape_pct"] <= floor * 1.1, out  # at the floor, not beyond it
    assert m["lstm_thrust_mape_pct"] == pytest.approx(MANIFEST["metrics"][condition]["lstm_thrust_mape_pct"], rel=1e-4)
    if condition == "normal":  # the formula IS kF·ω² here: the LSTM adds nothing over the quadratic fit
        assert m["lstm_thrust_mape_pct"] == pytest.approx(m["quadratic_thrust_mape_pct"], rel=0.05)
    else:  # the signature we wrote into the formula is what the LSTM adds over kF·ω²
        assert m["lstm_thrust_mape_pct"] < 0.5 * m["quadratic_thrust_mape_pct"]


def test_register_signature_training_on_a_tiny_run(tmp_path):
    """--signatures register: damaged conditions are measured over sweeps with drawn signatures (both signs of
    the torque-per-thrust change among them), recorded in the manifest; metrics carry the formula floor."""
    pytest.importorskip("torch")
    from offline.propellers.cli import train_all
    from offline.propellers.drawn import drawn_sweeps, register_signatures

    sigs = register_signatures("bent", 0, 12)
    ratio = np.array([(1 + g.torque_gain_high) / (1 - g.thrust_loss_high) - 1 for g in sigs])
    assert ratio.min() < 0 < ratio.max()
    s, y, form = drawn_sweeps(VEHICLE, "bent", LoadCellConfig(duration_s=8.0, seed=3), sigs[:2])
    assert len(s) == len(y) == len(form) == 2 * int(4.0 / 0.025)
    half = len(s) // 2
    fast = s > 0.5  # the two sweeps' formulas differ where the signatures' s² terms act
    per = [np.median(form[sl][fast[sl], 1] / form[sl][fast[sl], 0]) for sl in (slice(None, half), slice(half, None))]
    assert abs(per[0] - per[1]) > 1e-3

    manifest = train_all(tmp_path, DEFAULT_VEHICLE, 0, 1, signatures="register", sweeps=2, load_cell_duration_s=20.0)
    assert manifest["config"]["signatures"] == "register"
    assert (
        len(manifest["drawn_signatures"]["cracked"]) == 2 and "bent_torque_per_thrust_change_high_frac" in manifest["assumptions"]
    )
    assert all("formula_thrust_mape_pct" in m for m in manifest["metrics"].values())
    assert (tmp_path / "bent.npz").is_file() and "formula (floor)" in (tmp_path / "metrics.md").read_text()


@pytest.mark.parametrize("condition", CONDITIONS)
def test_learned_steady_state_follows_the_fault_signature(condition):
    omega = np.linspace(0.3, 0.95, 8) * VEHICLE.omega_max_rad_s
    prop = build_propellers(VEHICLE, np.full((2, 4), CONDITIONS.index(condition)), kind="lstm", vibration=False)
    prop.reset(omega.reshape(2, 4))
    thrust, torque = prop(omega.reshape(2, 4), 0.0025)
    sig = SIGNATURES[condition]
    s = omega / VEHICLE.omega_max_rad_s
    expected_t = VEHICLE.kf_n_per_rad_s2 * omega**2 * sig.thrust_factor(s)
    expected_q = VEHICLE.ktau_nm_per_rad_s2 * omega**2 * sig.torque_factor(s)
    np.testing.assert_allclose(thrust.ravel(), expected_t, rtol=0.015)
    np.testing.assert_allclose(torque.ravel(), expected_q, rtol=0.02)


def _steady_total_thrust(prop, omega: float) -> float:
    w = np.full((1, 4), omega)
    prop.reset(w)
    return float(prop(w, 0.0025)[0].sum())


def test_hover_pwm_matches_quadratic():
    """Bisect the hover speed of four normal LSTM rotors; the ESC command differs < 2 % from kF·ω²'s."""
    weight_n = VEHICLE.mass_kg * 9.80665
    prop = build_propellers(VEHICLE, np.zeros((1, 4), dtype=int), kind="lstm", vibration=False)
    lo, hi = 0.2 * VEHICLE.omega_max_rad_s, VEHICLE.omega_max_rad_s
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _steady_total_thrust(prop, mid) < weight_n else (lo, mid)
    pwm_lstm = float(VEHICLE.esc.omega_rad_s_to_cmd(0.5 * (lo + hi)))
    pwm_quad = float(VEHICLE.esc.omega_rad_s_to_cmd(VEHICLE.hover_omega_rad_s))
    assert pwm_lstm == pytest.approx(pwm_quad, rel=0.02)
    # Stronger than the issue asks: the normal LSTM's hover thrust is within 1 % of kF·ω².
    assert _steady_total_thrust(prop, VEHICLE.hover_omega_rad_s) == pytest.approx(weight_n, rel=0.01)


def test_sample_instants_equal_the_lstm_and_fast_part_is_instant():
    """In the physics loop the held departure makes thrust = LSTM output exactly at each 25 ms sample."""
    cond = np.array([[0, 1, 2, 0]])
    prop = build_propellers(VEHICLE, cond, kind="lstm", vibration=False)
    dt = 0.0025  # 400 Hz physics, 10 steps per LSTM sample
    scale = np.array([VEHICLE.kf_n_per_rad_s2, VEHICLE.ktau_nm_per_rad_s2]) * VEHICLE.omega_max_rad_s**2
    rng = np.random.default_rng(2)
    omega = np.full((1, 4), 600.0)
    prop.reset(omega)
    groups = {c: np.flatnonzero(cond[0] == c) for c in range(3)}
    states = {c: MODELS[CONDITIONS[c]].steady_state(omega[0, idx] / VEHICLE.omega_max_rad_s)[1] for c, idx in groups.items()}
    checked = 0
    for k in range(1, 201):
        omega = np.clip(omega + rng.normal(0, 5.0, (1, 4)), 100, 1100)
        thrust, torque = prop(omega, dt)
        if k % 10:
            continue
        for c, idx in groups.items():
            y, states[c] = MODELS[CONDITIONS[c]].step(omega[0, idx] / VEHICLE.omega_max_rad_s, states[c])
            np.testing.assert_allclose(thrust[0, idx], y[:, 0] * scale[0], rtol=1e-9)
            np.testing.assert_allclose(torque[0, idx], y[:, 1] * scale[1], rtol=1e-9)
            checked += 1
    assert checked == 60
    # Between samples a speed change shows at once through kF·ω².
    t_before, _ = prop(omega, dt)
    t_after, _ = prop(omega * 1.01, dt)
    np.testing.assert_allclose(t_after - t_before, VEHICLE.kf_n_per_rad_s2 * omega**2 * (1.01**2 - 1), rtol=1e-9)


def test_other_vehicle_by_scaling():
    """A vehicle with 10x kF and 2x omega_max gets thrust scaled by kF·omega_max² at the same normalised speed."""
    other = dataclasses.replace(
        VEHICLE, kf_n_per_rad_s2=VEHICLE.kf_n_per_rad_s2 * 10, omega_max_rad_s=VEHICLE.omega_max_rad_s * 2
    )
    s = np.full((1, 4), 0.6)
    a = build_propellers(VEHICLE, np.array([[0, 1, 2, 0]]), kind="lstm", vibration=False)
    b = build_propellers(other, np.array([[0, 1, 2, 0]]), kind="lstm", vibration=False)
    a.reset(s * VEHICLE.omega_max_rad_s)
    b.reset(s * other.omega_max_rad_s)
    ta, qa = a(s * VEHICLE.omega_max_rad_s, 0.0025)
    tb, qb = b(s * other.omega_max_rad_s, 0.0025)
    np.testing.assert_allclose(tb, ta * 40.0, rtol=1e-9)
    np.testing.assert_allclose(qb, qa * 4.0, rtol=1e-9)


def test_missing_weights_raise_model_error(tmp_path):
    with pytest.raises(ModelError, match="normal.npz"):
        build_propellers(VEHICLE, np.zeros((1, 4), dtype=int), kind="lstm", models_dir=tmp_path)


@pytest.mark.parametrize(("physics_hz", "expected"), [(250, 40), (400, 40), (1000, 40)])
def test_lstm_samples_every_25_ms_at_any_physics_rate(physics_hz, expected):
    """The held departure changes once per load-cell period, also when the physics period does not divide it."""
    prop = build_propellers(VEHICLE, np.array([[1, 2, 1, 2]]), kind="lstm", vibration=False)
    dt = 1.0 / physics_hz
    prop.reset(np.full((1, 4), 500.0))
    held, changes = None, 0
    for k in range(physics_hz):  # one second
        omega = np.full((1, 4), 500.0 + 300.0 * k / physics_hz)
        thrust, _ = prop(omega, dt)
        delta = thrust - VEHICLE.kf_n_per_rad_s2 * omega**2
        if held is not None and not np.allclose(delta, held, rtol=0, atol=1e-12):
            changes += 1
        held = delta
    assert abs(changes - expected) <= 1


def test_runtime_needs_no_torch():
    """The simulator runs the learned propellers with numpy only (torch is for training)."""
    import subprocess
    import sys

    code = (
        "import sys; sys.modules['torch'] = None\n"
        "import numpy as np\n"
        "from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle\n"
        "from offline.propellers import build_propellers\n"
        "p = build_propellers(load_vehicle(DEFAULT_VEHICLE), np.array([[0, 1, 2, 0]]), kind='lstm')\n"
        "w = np.full((1, 4), 600.0); p.reset(w); t, q = p(w, 0.0025)\n"
        "assert t.shape == (1, 4) and (t > 0).all()\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
