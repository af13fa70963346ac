"""Fault data sets: labels and per-propeller conditions, storage round trip, and refusal of mismatched data."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.errors import ConfigError, ModelError
from monitor.features import PAPER_FEATURES, SIGNALS
from monitor.labels import LABEL_TABLE
from offline.classifier.windows import gather, valid_starts, window_index
from offline.dataset.generate import DatasetSpec, flight_conditions, from_log
from offline.dataset.records import concat, load_dataset, save_dataset
from offline.dataset.synthetic import synthetic_dataset


def test_conditions_follow_the_label_table():
    rng = np.random.default_rng(0)
    for fault, kinds in (("bent", {1}), ("cracked", {2}), ("mixed", {1, 2})):
        cond = flight_conditions(fault, 3, rng)
        assert cond.shape == (48, 4)
        for i, row in enumerate(cond):
            label = i // 3 + 1
            assert tuple(p + 1 for p in np.flatnonzero(row)) == LABEL_TABLE[label]
        assert set(np.unique(cond[cond > 0])) == kinds


def test_varied_faults_give_uniform_and_mixed_flights():
    cond = flight_conditions("varied", 60, np.random.default_rng(1))
    multi = cond[(cond > 0).sum(axis=1) >= 2]
    kinds = [set(row[row > 0]) for row in multi]
    uniform_bent, uniform_cracked = sum(k == {1} for k in kinds), sum(k == {2} for k in kinds)
    mixed = sum(k == {1, 2} for k in kinds)
    # a third each of all-bent, all-cracked and per-propeller draws (of which 3/4+ mix on a 2+ fault set)
    assert 0.38 < uniform_bent / len(kinds) < 0.5 and 0.38 < uniform_cracked / len(kinds) < 0.5, (uniform_bent, uniform_cracked)
    assert 0.15 < mixed / len(kinds) < 0.3
    label16 = cond[15 * 60 :]
    assert ((label16 == 1).all(axis=1).mean() > 0.25) and ((label16 == 2).all(axis=1).mean() > 0.25)


def test_round_trip_keeps_every_propellers_condition(tmp_path):
    ds = synthetic_dataset(2, 150, seed=3)
    back = load_dataset(save_dataset(tmp_path / "d.npz", ds))
    np.testing.assert_array_equal(back.conditions, ds.conditions)
    np.testing.assert_array_equal(back.labels, ds.labels)
    assert back.labels[5] == 3 and set(back.conditions[5]) <= {0, 1, 2}
    for k in SIGNALS:
        np.testing.assert_allclose(back.signals[k], ds.signals[k], rtol=1e-6)
    assert back.vehicle_name == ds.vehicle_name and back.manifest == ds.manifest
    assert back.waypoint_set == ds.waypoint_set


def test_mismatches_are_refused_by_name(tmp_path):
    ds = synthetic_dataset(1, 150)
    with pytest.raises(ModelError, match="vehicle"):
        ds.check_model("crazyflie-2.1", 20.0, PAPER_FEATURES)
    with pytest.raises(ModelError, match="Hz"):
        ds.check_model(ds.vehicle_name, 50.0, PAPER_FEATURES)
    with pytest.raises(ModelError, match="unknown feature"):
        ds.check_model(ds.vehicle_name, 20.0, ("rpm_1", "airspeed_m_s"))
    with pytest.raises(ModelError, match="vehicle"):
        concat([ds, synthetic_dataset(1, 150, vehicle_name="other")], "x")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ModelError, match="bad.npz"):
        load_dataset(tmp_path / "bad.npz")


def test_bad_specs_are_config_errors():
    with pytest.raises(ConfigError, match="fault"):
        DatasetSpec("x", fault="melted")
    with pytest.raises(ConfigError, match="waypoints"):
        DatasetSpec("x", waypoints=("Z",))


class _FakeLog:
    """The FlightLog interface the generator needs: ``signals()`` and ``log_rate_hz``."""

    def __init__(self, b: int, t: int, rate: float = 20.0):
        rng = np.random.default_rng(0)
        self.log_rate_hz = rate
        self._s = {k: rng.normal(size=(b, t, 4) if k == "motor_rpm" else (b, t)) for k in SIGNALS}

    def signals(self):
        return self._s


def test_from_log_checks_the_rate():
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

    v = load_vehicle(DEFAULT_VEHICLE)
    cond = flight_conditions("bent", 1, np.random.default_rng(0))
    ds = from_log(_FakeLog(16, 120), "x", v, cond, np.zeros(16), ("A",) * 16, {})
    assert ds.n_flights == 16 and ds.vehicle_name == v.name
    with pytest.raises(ConfigError, match="50.0 Hz"):
        from_log(_FakeLog(16, 120, rate=50.0), "x", v, cond, np.zeros(16), ("A",) * 16, {})


def test_windows_are_views_and_skip_nan():
    ds = synthetic_dataset(1, 200)
    f = ds.features(PAPER_FEATURES)
    f[3, 150] = np.nan  # flight 3 loses windows starting at 51..100
    ok = valid_starts(f, 100)
    assert ok.shape == (16, 101) and ok[3].sum() == 101 - 50 and ok[2].all()
    idx = window_index(f, 100, stride=1)
    assert len(idx) == 16 * 101 - 50
    w = gather(f, idx[:5], 100)
    np.testing.assert_array_equal(w[2], f[idx[2, 0], idx[2, 1] : idx[2, 1] + 100])
