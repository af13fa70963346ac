"""A motor that stops or saturates is named within 1 s, as a motor, and healthy outputs raise nothing."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.decision.motor_output import PINNED_S, MotorOutputWatch, scan

RATE_HZ = 20.0
LO, HI = 1000.0, 11000.0  # RPM at the ends of the command range


def outputs(n: int, seed: int = 0) -> np.ndarray:
    """(n, 4) RPM of a hovering quad: around 60 % of the range, a few per cent of noise and manoeuvres."""
    rng = np.random.default_rng(seed)
    base = LO + 0.6 * (HI - LO)
    slow = np.cumsum(rng.normal(0, 30, (n, 4)), axis=0) * 0.1
    return base + slow + rng.normal(0, 150, (n, 4))


def stepwise(t, rpm, air):
    w = MotorOutputWatch(RATE_HZ, LO, HI)
    return [a for j in range(len(t)) if (a := w.step(float(t[j]), rpm[j], bool(air[j]))) is not None]


@pytest.mark.parametrize("kind", ["stopped", "saturated"])
def test_a_pinned_output_is_named_within_one_second_as_a_motor(kind):
    n = 400
    t = np.arange(n) / RATE_HZ
    rpm = outputs(n)
    at = 200
    rpm[at:, 2] = LO if kind == "stopped" else HI  # rotor 3 pinned from 10 s on
    air = np.ones(n, dtype=bool)
    alarms = scan(t, rpm, air, RATE_HZ, LO, HI)
    assert [(a.rotor, a.kind) for a in alarms] == [(3, kind)]
    assert 0 < alarms[0].t_s - t[at] <= 1.0 and alarms[0].since_s == t[at]
    assert alarms[0].text == f"MOTOR 3 {kind.upper()}"
    assert [a.to_json() for a in stepwise(t, rpm, air)] == [a.to_json() for a in alarms]  # the daemon's way: the same


def test_healthy_outputs_and_brief_excursions_raise_nothing():
    n = 2000
    t = np.arange(n) / RATE_HZ
    rpm = outputs(n, seed=3)
    short = int(PINNED_S * RATE_HZ) - 1
    rpm[500 : 500 + short, 0] = LO  # a hard manoeuvre: one motor at idle for just under PINNED_S
    rpm[900 : 900 + short, 1] = HI
    rpm[1200:1300] = HI  # a full-power climb: every motor at the top alike is no motor failure
    air = np.ones(n, dtype=bool)
    assert scan(t, rpm, air, RATE_HZ, LO, HI) == []
    assert stepwise(t, rpm, air) == []


def test_on_the_ground_and_after_landing_nothing_is_carried_over():
    n = 600
    t = np.arange(n) / RATE_HZ
    rpm = outputs(n, seed=5)
    rpm[:100, 3] = LO  # idle on the ground: not airborne, never a stopped motor
    air = np.ones(n, dtype=bool)
    air[:100] = False
    air[300:320] = False  # a landing: the second flight may name the same motor again
    rpm[250:300, 3] = LO
    rpm[340:400, 3] = LO
    alarms = scan(t, rpm, air, RATE_HZ, LO, HI)
    assert [(a.rotor, round(a.since_s, 2)) for a in alarms] == [(4, 12.5), (4, 17.0)]
    assert [a.to_json() for a in stepwise(t, rpm, air)] == [a.to_json() for a in alarms]


def test_the_network_gate_silences_the_classifier_off_its_airframe_only():
    from monitor.decision.network_gate import MIN_S, NetworkGate

    trained = 6400.0
    home, stranger = NetworkGate(trained, RATE_HZ), NetworkGate(trained, RATE_HZ)
    for j in range(int(12 * RATE_HZ)):
        home.step(np.full(4, trained * 1.05), True)
        stranger.step(np.full(4, trained * 0.68), True)  # a bigger propeller: hover at 2/3 of the RPM
        if j + 1 < MIN_S * RATE_HZ:
            assert home.speaks and stranger.speaks  # too soon to say: as before
    assert home.speaks and not stranger.speaks and abs(stranger.ratio - 0.68) < 1e-9
    stranger.step(None, False)  # landed: the next flight is judged again
    assert stranger.speaks and stranger.ratio is None
    assert NetworkGate(None, RATE_HZ).speaks  # a model without RPM statistics always speaks


def test_the_daemon_network_speaks_only_on_a_declared_airframe(tmp_path):
    from monitor.daemon.config import load_monitor_config, monitor_config_from_mapping
    from monitor.decision.network_gate import NetworkGate
    from monitor.vehicle import REPO_ROOT

    trained = 6400.0
    undeclared = NetworkGate(trained, RATE_HZ, declared=False)
    for _ in range(int(12 * RATE_HZ)):
        undeclared.step(np.full(4, trained), True)  # at the trained RPM itself
    assert not undeclared.speaks and not NetworkGate(None, RATE_HZ, declared=False).speaks
    # the defaults and the shipped deploy file declare nothing; naming the model or a vehicle file does
    assert not load_monitor_config(None).airframe_declared
    assert not load_monitor_config(REPO_ROOT / "deploy" / "monitor.yaml").airframe_declared
    assert not monitor_config_from_mapping({"vehicle_path": ""}).airframe_declared
    for declared in ({"model_path": "m.onnx"}, {"vehicle_path": "v.yaml"}, {"airframe_declared": True}):
        assert monitor_config_from_mapping(declared).airframe_declared, declared
