"""Onboard figures: the time-switched propellers, onset flights, detection times of the replayed comparison rule."""

from __future__ import annotations

import numpy as np
import pytest

from offline.classifier.consecutive import ConsecutiveConfig
from offline.classifier.onboard import ShiftFlights, detection_times, simulate_onset
from offline.dataset.onset import SwitchedPropellers


class _Const:
    def __init__(self, value: float):
        self.value = value

    def reset(self, omega):
        pass

    def __call__(self, omega, dt):
        return np.full(omega.shape, self.value), np.full(omega.shape, self.value / 10)


def test_switched_propellers_change_at_each_flights_onset():
    sw = SwitchedPropellers(_Const(1.0), _Const(2.0), onset_s=[0.02, 1.0])
    omega = np.ones((2, 4))
    sw.reset(omega)
    seen = [sw(omega, 0.01)[0][:, 0] for _ in range(5)]  # t = 0, .01, .02, .03, .04
    assert [s[0] for s in seen] == [1.0, 1.0, 2.0, 2.0, 2.0]
    assert all(s[1] == 1.0 for s in seen)


@pytest.mark.slow
def test_onset_flights_and_detection_with_an_rpm_rule():
    pytest.importorskip("offline.sim.simulator")
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

    cfg = ShiftFlights(n_flights=4, duration_s=14.0, payload_kg=(0.0, 0.0), fault="bent", onset_s=(7.0, 7.0), seed=5)
    ds = simulate_onset(load_vehicle(DEFAULT_VEHICLE), cfg, healthy=False)
    assert np.all(ds.onset_step == 139) and ds.fault_mask.any(axis=1).all()
    rpm = ds.signals["motor_rpm"]
    # after onset the faulty rotors need more speed relative to the others than before
    rel = rpm / rpm.mean(axis=-1, keepdims=True)
    before, after = rel[:, 60:135].mean(axis=1), rel[:, 200:].mean(axis=1)
    mask = ds.fault_mask & ~ds.fault_mask.all(axis=1, keepdims=True)
    if mask.any():
        assert np.mean((after - before)[mask]) > 0.005


def _rpm_rule(w):
    """A stand-in classifier: a rotor is faulty when its last second runs >1 % above the mean of the four."""
    r = w[:, -20:, :4].mean(axis=1)
    p = (r / r.mean(axis=1, keepdims=True) > 1.01).astype(np.float32)
    return np.zeros((len(w), 16), np.float32), p


def test_detection_time_counts_from_onset_and_checks_the_named_propellers():
    import dataclasses

    from offline.dataset.synthetic import synthetic_dataset

    healthy = synthetic_dataset(1, 400, seed=2, rpm_gain=0.0)
    faulty = synthetic_dataset(1, 400, seed=2, rpm_gain=0.04)
    onset = 250
    rpm = healthy.signals["motor_rpm"].copy()
    rpm[:, onset:] = faulty.signals["motor_rpm"][:, onset:]
    ds = dataclasses.replace(faulty, signals={**faulty.signals, "motor_rpm": rpm}, onset_step=np.full(16, onset))
    ds = ds.subset(np.arange(1, 15))  # labels 2..15: at least one rotor healthy, so "above the mean" is defined
    rule = ConsecutiveConfig(threshold=0.8, consecutive=3, refractory_s=30.0)  # pinned: the default may change
    det = detection_times(_rpm_rule, ds, ("rpm_1", "rpm_2", "rpm_3", "rpm_4"), 100, rule)
    assert det["flights"] == 14 and det["alerts_before_onset"] == 0
    assert det["first_alert"]["detected"] == 1.0 and det["first_correct_alert"]["detected"] == 1.0
    # 5 of 20 faulty samples lift the 1-s mean over 1 %, then 3 consecutive windows: ~0.25-0.5 s after onset
    assert 0.1 < det["first_alert"]["median_s"] < 0.8
