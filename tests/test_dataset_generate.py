"""The generator on the real simulator (short flights, analytic propellers): labels line up with physics."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("offline.sim.simulator")

from monitor.features import compute_features  # noqa: E402
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle  # noqa: E402
from offline.dataset.generate import DatasetSpec, generate  # noqa: E402

PARTNER = {0: 1, 1: 0, 2: 3, 3: 2}  # diagonal rotor sharing the spin direction (PX4 quad-X)


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle(DEFAULT_VEHICLE)


@pytest.fixture(scope="module")
def small(vehicle):
    spec = DatasetSpec("A-bent", fault="bent", flights_per_label=1, duration_s=8.0, propellers="quadratic", seed=3)
    return generate(spec, vehicle, log=lambda *_: None)


def test_shape_labels_and_manifest(small, vehicle):
    assert small.n_flights == 16 and small.n_steps == 160
    assert list(small.labels) == list(range(1, 17))
    assert small.manifest["config"]["fault"] == "bent" and small.manifest["vehicle"]["name"] == vehicle.name
    assert "git_revision" in small.manifest and small.manifest["seed"] == 3
    assert set(np.unique(small.conditions)) == {0, 1}


def test_chunked_generation_keeps_label_order(vehicle):
    spec = DatasetSpec(
        "R",
        fault="mixed",
        waypoints=("random", "B"),
        payload_kg=(0.0, 0.5),
        flights_per_label=1,
        duration_s=6.0,
        propellers="quadratic",
        chunk_flights=5,
        vehicle_variants=2,
        wind_max_m_s=2.0,
    )
    ds = generate(spec, vehicle, log=lambda *_: None)
    assert list(ds.labels) == list(range(1, 17))
    assert ds.waypoint_set[:2] == ("random", "B") and 0.0 <= ds.payload_kg.min() < ds.payload_kg.max() <= 0.5
    assert len(ds.manifest["variants"]) == 2 and ds.manifest["variants"][0]["wind_ned_m_s"] != [0.0, 0.0, 0.0]
    assert set(np.unique(ds.conditions[ds.conditions > 0])) == {1, 2}


def test_a_faulty_rotor_spins_faster_than_its_diagonal_partner(small):
    # A bent blade loses thrust, so holding attitude needs more speed on that rotor than on its twin.
    rpm = compute_features(small.signals, ("rpm_1", "rpm_2", "rpm_3", "rpm_4"))[:, 40:].mean(axis=1)
    for rotor in range(4):
        flight = rotor + 1  # labels 2..5 are rotors 1..4 alone, flights are in label order
        assert rpm[flight, rotor] > rpm[flight, PARTNER[rotor]] * 1.01, (rotor, rpm[flight])
    # all four bent: the whole vehicle needs more speed for the same weight
    assert rpm[15].mean() > rpm[0].mean() * 1.02


def test_same_spec_same_data_and_payload_raises_rpm(small, vehicle):
    spec = DatasetSpec("A-bent", fault="bent", flights_per_label=1, duration_s=8.0, propellers="quadratic", seed=3)
    again = generate(spec, vehicle, log=lambda *_: None)
    np.testing.assert_array_equal(again.signals["motor_rpm"], small.signals["motor_rpm"])
    heavy = generate(
        DatasetSpec(
            "C-bent", fault="bent", flights_per_label=1, duration_s=8.0, propellers="quadratic", payload_kg=(0.45, 0.45), seed=3
        ),
        vehicle,
        log=lambda *_: None,
    )
    assert np.all(heavy.payload_kg == 0.45)
    assert heavy.signals["motor_rpm"][0, 40:].mean() > 1.05 * small.signals["motor_rpm"][0, 40:].mean()
