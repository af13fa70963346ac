"""offline.evalsim: frames and rotor numbering, RotorPy equivalence, hover by hand, determinism, I/O, no training use."""

from __future__ import annotations

import ast
import json
import math
from dataclasses import replace
from pathlib import Path

import evalsim_flights
import numpy as np
import pytest

pytest.importorskip("rotorpy")

from monitor.esc import PAPER_ESC  # noqa: E402
from monitor.logs import read_log  # noqa: E402
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle  # noqa: E402
from offline.evalsim import frames  # noqa: E402
from offline.evalsim.airframe import Airframe, Damage  # noqa: E402
from offline.evalsim.environment import Sensors, Wind  # noqa: E402
from offline.evalsim.flight import START_NED_M, FlightSpec, multirotor_for, simulate_flights, truth  # noqa: E402
from offline.share_baseline import omega2_shares, share_baseline  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
V = load_vehicle(DEFAULT_VEHICLE)
HOVER = (START_NED_M,) * 5
QUIET = Sensors(gyro_bias_std_rad_s=0.0, attitude_bias_std_rad=0.0)


def _spec(name, loss=(0.0, 0.0, 0.0, 0.0), seed=1, duration_s=8.0, route=HOVER, **af_kw) -> FlightSpec:
    af = Airframe.from_vehicle(V, damage=Damage(thrust_loss_at_hover=loss), **af_kw)
    return FlightSpec(name, af, route, duration_s, seed, wind=Wind(), sensors=QUIET)


def _fixture_specs() -> list[FlightSpec]:
    route = ((8.0, 4.0, -9.0), (-6.0, 8.0, -11.0), (0.0, 0.0, -10.0), (5.0, -5.0, -10.0), (0.0, 0.0, -10.0))
    return [
        _spec("hover"),
        _spec("weak1", (0.15, 0.0, 0.0, 0.0)),
        _spec("weak3", (0.0, 0.0, 0.15, 0.0)),
        _spec("route", route=route, seed=5),
    ]


evalsim_flights.declare(__name__, "flights", _fixture_specs)


@pytest.fixture(scope="module")
def flights():
    """Healthy hover, rotor 1 weak (15 %), rotor 3 weak, and a flown route: flown in the session's evalsim batch
    (tests/evalsim_flights.py), beside whatever other flights the session's tests declared."""
    specs = _fixture_specs()
    return specs, evalsim_flights.simulate_flights(specs)


# --- frames and numbering -------------------------------------------------------------


def test_rotor_numbering_round_trip_and_positions():
    x = np.array([10.0, 20.0, 30.0, 40.0])  # PX4 order
    assert np.array_equal(frames.rotorpy_to_px4(frames.px4_to_rotorpy(x)), x)
    pos = frames.positions_flu_rotorpy(np.asarray(V.rotor_positions_frd_m))
    # RotorPy r1 front-left, r2 front-right, r3 rear-right, r4 rear-left (FLU: +x forward, +y left).
    assert np.all(np.sign(pos[:, :2]) == [[1, 1], [1, -1], [-1, -1], [-1, 1]])
    # r1 is PX4 3 (front-left, CW: drag torque about +z up), r2 is PX4 1 (CCW: about -z up).
    assert frames.PX4_OF_ROTORPY == (3, 1, 4, 2)
    assert np.array_equal(frames.rotorpy_directions(V.rotor_spin), [1.0, -1.0, 1.0, -1.0])


def test_quaternion_conversion_is_flip_conjugation():
    rng = np.random.default_rng(0)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)  # RotorPy [x, y, z, w]
    x, y, z, w = q
    R_nwu = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    R_ned = frames.rotation_matrix_wxyz(frames.quat_rotorpy_to_px4(q))
    assert np.allclose(R_ned, frames.FLIP @ R_nwu @ frames.FLIP)
    assert np.allclose(frames.quat_px4_to_rotorpy(frames.quat_rotorpy_to_px4(q)), q)


def _derivative(af: Airframe, kf4=None, kt4=None):
    from offline.evalsim.dynamics import BatchedDerivative

    kf = np.full(4, af.kf_n_per_rad_s2) if kf4 is None else kf4
    kt = np.full(4, af.ktau_nm_per_rad_s2) if kt4 is None else kt4
    mr = multirotor_for(af, lambda om: (kf, kt))
    f = BatchedDerivative([mr], lambda om: (kf[None], kt[None]))
    return mr, f


def _random_states(seed: int, n: int):
    """n random (RotorPy state (20,), rotor speed command (4,)): unit quaternion, rotors at 300-900 rad/s."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        s = rng.normal(size=20)
        s[6:10] /= np.linalg.norm(s[6:10])
        s[16:20] = rng.uniform(300, 900, 4)
        yield s, rng.uniform(300, 900, 4)


def test_batched_derivative_equals_rotorpy_s_dot():
    from rotorpy.vehicles.multirotor import Multirotor

    af = Airframe.from_vehicle(
        V, cg_offset_frd_m=(0.01, -0.02, 0.005), rotor_drag_kg_per_rad=1e-4, flapping_nm_per_rad_s_m_s=1e-5
    )
    kf = V.kf_n_per_rad_s2 * np.array([1.0, 0.9, 1.05, 0.97])
    kt = V.ktau_nm_per_rad_s2 * np.array([1.0, 0.8, 1.1, 0.9])
    mr, f = _derivative(af, kf, kt)
    for s, cmd in _random_states(3, 5):
        assert np.allclose(f(s[None], cmd[None])[0], mr._s_dot_fn(0.0, s, cmd), rtol=1e-12, atol=1e-10)
    # Equal rotors: the extension reduces to RotorPy's own Multirotor.
    _, f_eq = _derivative(af)
    plain = Multirotor(_params_of(af), control_abstraction="cmd_motor_speeds", aero=True)
    assert np.allclose(f_eq(s[None], cmd[None])[0], plain._s_dot_fn(0.0, s, cmd), rtol=1e-12, atol=1e-10)


def _params_of(af: Airframe) -> dict:
    from offline.evalsim.dynamics import rotorpy_params

    pos = frames.positions_flu_rotorpy(np.asarray(af.rotor_positions_frd_m) - np.asarray(af.cg_offset_frd_m))
    return rotorpy_params(
        af.mass_kg,
        af.inertia_diag_kg_m2,
        pos,
        frames.rotorpy_directions(af.rotor_spin),
        af.kf_n_per_rad_s2,
        af.ktau_nm_per_rad_s2,
        np.asarray(af.motor_time_constant_s),
        0.0,
        af.omega_max_rad_s * 1.2,
        af.drag_quadratic_n_per_m2_s2,
        af.rotor_drag_kg_per_rad,
        af.flapping_nm_per_rad_s_m_s,
    )


def test_blade_flapping_is_rotorpys_term_with_blowbacks_sign():
    from rotorpy.vehicles.multirotor import Multirotor

    k = 1.8e-5
    af = Airframe.from_vehicle(V, flapping_nm_per_rad_s_m_s=k)
    _, f = _derivative(af)
    # Equal rotors: the batched derivative equals RotorPy's own Multirotor with its k_flap (stored negated).
    plain = Multirotor(_params_of(af), control_abstraction="cmd_motor_speeds", aero=True)
    for s, cmd in _random_states(4, 3):
        assert np.allclose(f(s[None], cmd[None])[0], plain._s_dot_fn(0.0, s, cmd), rtol=1e-12, atol=1e-10)
    # By hand: level, at hover speed, 10 m/s forward through still air. Each rotor adds k w (v x e_z), so the
    # pitch moment is -4 k w_h v about FLU y: 1.8e-5 * 4 * 584.7 * 10 = 0.421 N m, nose-up (blowback), and in
    # FRD pitch acceleration +0.421 / Iyy. The same vehicle without flapping feels no moment.
    w_h = math.sqrt(1.5 * 9.81 / (4 * 1.076e-5))
    s = np.zeros(20)
    s[9] = 1.0
    s[3] = 10.0  # NWU velocity, x: forward for yaw 0
    s[16:20] = w_h
    w_dot_frd = frames.vec_to_ned(f(s[None], np.full((1, 4), w_h))[0, 10:13])
    assert w_dot_frd[1] == pytest.approx(4 * k * w_h * 10.0 / V.inertia_diag_kg_m2[1], rel=1e-6)
    assert w_dot_frd[1] * V.inertia_diag_kg_m2[1] == pytest.approx(0.421, abs=1e-3)
    assert abs(w_dot_frd[0]) < 1e-9 and abs(w_dot_frd[2]) < 1e-9
    _, f0 = _derivative(Airframe.from_vehicle(V))
    assert np.allclose(f0(s[None], np.full((1, 4), w_h))[0, 10:13], 0.0, atol=1e-12)


def test_symmetric_rotors_at_hover_speed_give_zero_moment_and_balance_weight():
    af = Airframe.from_vehicle(V)
    _, f = _derivative(af)
    # By hand: ω_h = sqrt(m g / (4 kF)) with RotorPy's g = 9.81 -> 584.7 rad/s.
    w_h = math.sqrt(1.5 * 9.81 / (4 * 1.076e-5))
    assert w_h == pytest.approx(584.7, abs=0.1)
    s = np.zeros(20)
    s[9] = 1.0
    s[16:20] = w_h
    d = f(s[None], np.full((1, 4), w_h))[0]
    assert np.allclose(d[3:6], 0.0, atol=1e-12)  # thrust = weight
    assert np.allclose(d[10:13], 0.0, atol=1e-12)  # no moment
    # One CCW rotor (PX4 1, front-right) faster: roll left (-), pitch up (+), yaw nose-right (+) in FRD.
    om = np.full(4, w_h)
    om[0] *= 1.05
    s[16:20] = frames.px4_to_rotorpy(om)
    w_dot_frd = frames.vec_to_ned(f(s[None], s[None, 16:20])[0, 10:13])
    assert w_dot_frd[0] < 0 and w_dot_frd[1] > 0 and w_dot_frd[2] > 0


# --- closed loop ----------------------------------------------------------------------------


def test_hover_pwm_and_thrust_match_hand_calculation(flights):
    specs, logs = flights
    lg = logs[0]
    # Thrust = weight (RotorPy g), mean over the hover.
    assert lg.thrust_n[0].sum(axis=1).mean() == pytest.approx(1.5 * 9.81, rel=5e-3)
    # PWM by hand: -0.0062 p² + 29.37 p - 22992 = 5583.6 RPM (584.7 rad/s) -> p = 1367.9 µs.
    p = (29.37 - math.sqrt(29.37**2 - 4 * 0.0062 * (22992 + 5583.6))) / (2 * 0.0062)
    assert p == pytest.approx(1367.9, abs=0.2)
    assert lg.pwm_us[0].mean(axis=0) == pytest.approx(np.full(4, p), abs=4.0)
    assert np.abs(lg.pos_ned_m[0] - START_NED_M).max() < 0.5


def test_weak_rotor_raises_its_own_logged_pwm(flights):
    _, logs = flights
    healthy = logs[0].pwm_us[0].mean(axis=0)
    for i, rotor in ((1, 0), (2, 2)):  # flight "weak1" -> PX4 rotor 1, "weak3" -> PX4 rotor 3
        rise = logs[i].pwm_us[0].mean(axis=0) - healthy
        assert int(np.argmax(rise)) == rotor
        assert rise[rotor] > 20.0  # 15 % thrust loss ~ +8 % ω ~ +30 µs
        # and the controller held the vehicle level: the moment is balanced, not the commands
        assert np.abs(logs[i].roll_rad[0]).max() < 0.1


def test_route_is_flown(flights):
    _, logs = flights
    lg = logs[3]
    assert lg.waypoint_index.max() >= 1
    assert np.all(np.isfinite(lg.pos_ned_m))


def test_flight_is_deterministic_and_independent_of_its_batch(flights):
    specs, logs = flights
    # The same flight in another batch (other partner, other position, batch of 2 not 4, a partner that flies
    # longer: tests/evalsim_flights.py batches flights of every duration together).
    again, other = simulate_flights([specs[2], _spec("weak3", (0.0, 0.0, 0.15, 0.0), seed=2, duration_s=10.0)])
    assert np.array_equal(again.pwm_us, logs[2].pwm_us)
    assert np.array_equal(again.timestamp_us, logs[2].timestamp_us)
    n = min(other.n_samples, again.n_samples)
    assert not np.array_equal(other.pwm_us[0, :n], again.pwm_us[0, :n])  # another seed, another flight


def test_build_set_is_deterministic_and_extends():
    from offline.evalsim.catalog import build_set
    from offline.evalsim.names import SET_NAMES

    for name in SET_NAMES:
        a = build_set(name, 4, seed=3, duration_s=20.0)
        assert a == build_set(name, 4, seed=3, duration_s=20.0)
        assert build_set(name, 5, seed=3, duration_s=20.0)[:4] == a
        assert a != build_set(name, 4, seed=4, duration_s=20.0)
    paper = build_set("paper", 16, seed=0)
    assert sorted(s.label for s in paper) == list(range(1, 17))
    shift = build_set("shift", 2, seed=0)
    assert all(s.airframe.payload_kg == pytest.approx(0.45) for s in shift)
    with pytest.raises(ValueError, match="unknown evalsim set"):
        build_set("nope")


def test_scaled_shift_sets_differ_from_shift_only_in_the_airframe_spread():
    from offline.evalsim.sets import build_set

    shift = build_set("shift", 4, seed=0)
    nominal = np.asarray(build_set("paper", 1, seed=0)[0].airframe.inertia_diag_kg_m2)
    for name, scale in (("shift_half", 0.5), ("shift_quarter", 0.25)):
        for a, b in zip(shift, build_set(name, 4, seed=0), strict=True):
            assert b.name == a.name.replace("shift", name)
            assert (b.seed, b.waypoints_ned_m, b.wind, b.airframe.damage) == (
                a.seed,
                a.waypoints_ned_m,
                a.wind,
                a.airframe.damage,
            )
            assert b.airframe.payload_kg == a.airframe.payload_kg
            eff_a, eff_b = np.asarray(a.airframe.motor_thrust_efficiency), np.asarray(b.airframe.motor_thrust_efficiency)
            np.testing.assert_allclose(eff_b - 1.0, scale * (eff_a - 1.0), rtol=1e-12)
            np.testing.assert_allclose(b.airframe.cg_offset_frd_m, scale * np.asarray(a.airframe.cg_offset_frd_m), rtol=1e-12)
            ia, ib = np.asarray(a.airframe.inertia_diag_kg_m2), np.asarray(b.airframe.inertia_diag_kg_m2)
            np.testing.assert_allclose(ib / nominal - 1.0, scale * (ia / nominal - 1.0), rtol=1e-9)
            assert np.abs(eff_a - 1.0).max() > 0.0 and np.abs(a.airframe.cg_offset_frd_m).max() > 0.0


# --- I/O -----------------------------------------------------------------------------------


def test_tlog_reads_into_a_20hz_flight_table_and_truth_round_trips(flights, tmp_path):
    from offline.sim.io_tlog import write_tlog

    specs, logs = flights
    write_tlog(tmp_path / "f.tlog", logs[1], 0)
    table = read_log(tmp_path / "f.tlog", esc=PAPER_ESC, rate_hz=20.0)
    assert table.rate_hz == 20.0
    assert np.all(np.diff(table.timestamp_us) == 50_000)
    assert table.airborne.mean() > 0.8
    air = table.airborne
    for sig in ("roll_rad", "pitch_rad", "yaw_rate_rad_s", "battery_v"):
        assert np.all(np.isfinite(getattr(table, sig)[air])), sig
    # Telemetry jitter: the grid holds the latest sample; the means agree with the log.
    assert np.nanmean(table.motor_cmd[air], axis=0) == pytest.approx(logs[1].pwm_us[0].mean(axis=0), abs=3.0)
    assert "esc_rpm" in table.extras
    t = truth(specs[1], file="f.tlog")
    (tmp_path / "f.json").write_text(json.dumps(t))
    back = json.loads((tmp_path / "f.json").read_text())
    assert back == json.loads(json.dumps(t))
    assert back["faulty_propellers"] == [1]
    assert back["thrust_factor_at_hover"] == pytest.approx([0.85, 1.0, 1.0, 1.0])
    assert back["airframe"]["mass_kg"] == 1.5 and back["seed"] == specs[1].seed


def test_share_baseline_by_hand():
    # ω² shares from PWM: rotor 2 at 1400 µs, others 1368 µs.
    cmd = np.tile([1368.0, 1400.0, 1368.0, 1368.0], (10, 1))
    sh = omega2_shares(cmd, np.ones(10, bool))
    rpm = PAPER_ESC.cmd_to_rpm(np.array([1368.0, 1400.0]))
    w2 = rpm**2
    assert sh[1] == pytest.approx(w2[1] / ((3 * w2[0] + w2[1]) / 4))
    assert share_baseline(sh) == 2
    assert share_baseline(sh, healthy_shares=np.array([1.0, 1.2, 1.0, 1.0])) != 2
    with pytest.raises(ValueError):
        omega2_shares(cmd, np.zeros(10, bool))


def test_cli_writes_a_set_that_scores_with_the_baseline_and_evaluate(tmp_path):
    from offline.evalsim.cli import main as evalsim_main
    from offline.evalsim.score import read_tables, score, share_predictor

    out = tmp_path / "eff"
    args = ["--set", "effectiveness", "--out", str(out), "--flights", "4", "--seed", "0", "--duration-s", "8"]
    assert evalsim_main(args) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["manifest.json"] + [f"effectiveness_{i:04d}.{e}" for i in range(4) for e in ("tlog", "json")]
    )
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["kind"] == "propwatch-evalsim-set" and manifest["evaluation_only"] is True
    assert manifest["seed"] == 0 and "git_revision" in manifest and "torque_per_thrust_change" in manifest["assumptions"]
    tables = read_tables(out)
    assert [t["faulty_propellers"] for t, _ in tables] == [[1], [2], [3], [4]]
    s = score(tables, share_predictor(), "baseline").summary()
    assert s["flights"] == 4 and s["single_flights"] == 4
    assert s["single_accuracy"] is not None
    # 'propwatch evaluate classifier --evalsim': the shipped model and the baseline as rows of one table.
    from offline.classifier.evaluate_cli import main as evaluate_main

    assert evaluate_main([str(REPO / "models" / "classifier.onnx"), "--evalsim", str(out), "--out", str(tmp_path / "ev")]) == 0
    payload = json.loads((tmp_path / "ev" / "results.json").read_text())
    rows = payload["evalsim"][0]["rows"]
    assert payload["evalsim"][0]["set"] == "effectiveness"
    assert [r["predictor"] for r in rows] == ["classifier", "ω²-share baseline"]
    assert all(r["flights"] == 4 for r in rows)


# --- isolation --------------------------------------------------------------------------


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            names |= {f"{node.module}.{a.name}" for a in node.names}
    return names


# The one reporting entry point allowed to read evalsim sets: 'propwatch evaluate classifier --evalsim'. It is a
# command-line leaf: no training or model-selection code imports it (checked below).
REPORTING_ONLY = REPO / "offline" / "classifier" / "evaluate_cli.py"


def test_no_training_code_imports_evalsim():
    checked = 0
    for pkg in ("dataset", "classifier", "propellers"):
        for path in (REPO / "offline" / pkg).rglob("*.py"):
            names = _imports(path)
            assert not any(n.startswith("offline.classifier.evaluate_cli") for n in names), f"{path} imports evaluate_cli"
            if path == REPORTING_ONLY:
                continue
            bad = [n for n in names if n.startswith("offline.evalsim")]
            assert not bad, f"{path} imports {bad}: evalsim is evaluation-only"
            checked += 1
    assert checked > 10  # the packages are where this test thinks they are


def test_evalsim_shares_no_physics_or_controller_code_with_offline_sim():
    allowed = {"offline.sim.io_tlog", "offline.sim.log", "offline.sim.sidecar"}
    for path in (REPO / "offline" / "evalsim").rglob("*.py"):
        for n in _imports(path):
            if n.startswith("offline.sim"):
                assert any(n == a or n.startswith(a + ".") for a in allowed), f"{path} imports {n}"
            assert not n.startswith(("offline.dataset", "offline.classifier", "offline.propellers")), f"{path} imports {n}"


def test_score_metrics_by_hand():
    from offline.evalsim.score import score

    truths = [
        {"file": "a", "faulty_propellers": []},
        {"file": "b", "faulty_propellers": [1]},
        {"file": "c", "faulty_propellers": [2]},
        {"file": "d", "faulty_propellers": [1, 2]},
    ]
    answers = {
        "a": {
            "faulty_propellers": [],
            "fault_probability": [0.1, 0.2, 0.0, 0.0],
            "hypotheses": [{"faulty_propellers": [], "probability": 1.0}],
        },
        "b": {
            "faulty_propellers": [1],
            "hypotheses": [{"faulty_propellers": [1], "probability": 0.6}, {"faulty_propellers": [1, 2], "probability": 0.4}],
        },
        "c": {"faulty_propellers": [1], "hypotheses": [{"faulty_propellers": [1], "probability": 1.0}]},
        "d": None,  # the predictor refuses this flight: counted wrong, reported
    }

    def predictor(table):
        if answers[table] is None:
            raise ValueError("no verdict")
        return answers[table]

    s = score([(t, t["file"]) for t in truths], predictor, "fake").summary()
    assert s["flights"] == 4 and s["exact_accuracy"] == 0.5
    assert s["single_flights"] == 2 and s["single_accuracy"] == 0.5
    assert s["by_label"] == {"1": 1.0, "2": 1.0, "3": 0.0, "6": 0.0}
    assert s["truth_in_hypotheses"] == 0.5  # a and b of 4 (c's set misses, d gave none)
    assert s["mean_set_size"] == pytest.approx(4 / 3)
    assert s["healthy_mean_p_faulty"] == [0.1, 0.2, 0.0, 0.0]
    assert s["failed"] == [("d", "ValueError: no verdict")]


def test_forward_flight_with_flapping_trims_the_front_rotors_down_by_the_hand_calculation():
    # A straight 60-m leg north at up to 10 m/s, nose-up flapping moment k 4 w v countered by thrust: the yaw-free
    # omega^2 share of the front rotors (1, 3) falls by s = k 4 w_h v / (m g a_x) and the rear's rises by as much
    # (the pattern (-s, +s, -s, +s) is a pitch moment s m g a_x). At 8 m/s with k = 1.8e-5: s = 0.20. The same
    # flight without flapping stays trimmed within a few hundredths.
    from monitor.decision.rotor_share import _YAW_FREE
    from offline.evalsim.sets import FLAPPING_MAX, build_set

    leg = ((60.0, 0.0, -10.0),) * 5
    specs = [
        replace(_spec(n, duration_s=14.0, route=leg, flapping_nm_per_rad_s_m_s=k), vel_xy_max_m_s=10.0)
        for n, k in (("flap", FLAPPING_MAX), ("none", 0.0))
    ]
    trims = []
    for lg in simulate_flights(specs):
        w2 = lg.motor_omega_rad_s[0] ** 2
        x = (w2 / w2.mean(axis=1, keepdims=True)) @ _YAW_FREE.T
        speed = np.linalg.norm(lg.vel_ned_m_s[0, :, :2], axis=1)
        cruise = (speed > 7.0) & (speed < 9.0)
        assert cruise.sum() > 10
        v = speed[cruise].mean()
        front_minus_rear = (x[cruise][:, [0, 2]].mean() - x[cruise][:, [1, 3]].mean()) / 2
        trims.append((front_minus_rear, v))
    (flap, v), (none, _) = trims
    s = FLAPPING_MAX * 4 * V.hover_omega_rad_s * v / (V.mass_kg * 9.81 * 0.113137)
    assert 0.15 < s < 0.25
    assert flap - none == pytest.approx(-s, rel=0.3)
    assert abs(none) < 0.05
    # The set draws its flapping within [0, FLAPPING_MAX] and flies at up to 10 m/s; its flights are healthy.
    ff = build_set("forward_flight", 16, seed=0)
    ks = [sp.airframe.flapping_nm_per_rad_s_m_s for sp in ff]
    assert all(0.0 <= k <= FLAPPING_MAX for k in ks) and max(ks) > 0.5 * FLAPPING_MAX
    assert all(sp.vel_xy_max_m_s == 10.0 and sp.faulty_propellers == () for sp in ff)
    with pytest.raises(ValueError, match="vel_xy_max_m_s"):
        simulate_flights([specs[0], replace(specs[1], vel_xy_max_m_s=3.0)])
