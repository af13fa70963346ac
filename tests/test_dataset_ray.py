"""propwatch dataset --ray: chunks as Ray tasks give the serial run's arrays bit for bit, with 1 or 2 workers."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ray")
pytest.importorskip("offline.sim.simulator")

from ray_fixture import ray_local  # noqa: E402,F401

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle  # noqa: E402
from offline.dataset.generate import DatasetSpec, generate  # noqa: E402
from offline.dataset.ray_shard import ray_chunks  # noqa: E402

SPEC = DatasetSpec(
    "R",
    fault="mixed",
    waypoints=("random", "B"),
    payload_kg=(0.0, 0.4),
    flights_per_label=1,
    duration_s=5.0,
    propellers="quadratic",
    chunk_flights=3,  # 16 flights in 2 variants -> 6 chunks
    vehicle_variants=2,
    wind_max_m_s=2.0,
    seed=11,
)


def arrays(ds) -> dict[str, np.ndarray]:
    out = {f"signal/{k}": v for k, v in ds.signals.items()}
    out.update(conditions=ds.conditions, payload_kg=ds.payload_kg, labels=ds.labels)
    return out


RANDOMISED = DatasetSpec(
    "RR",
    fault="varied",
    waypoints=("random",),
    flights_per_label=1,
    duration_s=3.0,
    propellers="quadratic",
    physics="randomised",  # every flight's physics drawn from the assumption register
    seed=9,
    chunk_flights=5,
)


@pytest.mark.usefixtures("ray_local")
@pytest.mark.parametrize("spec", [SPEC, RANDOMISED], ids=["fixed-physics", "randomised-physics"])
def test_ray_shards_equal_the_serial_run_bit_for_bit(spec):
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    serial = arrays(generate(spec, vehicle, log=lambda *_: None))
    for workers in (1, 2):
        sharded = generate(spec, vehicle, log=lambda *_: None, run_chunks=ray_chunks(workers=workers, progress=False))
        got = arrays(sharded)
        assert got.keys() == serial.keys()
        for k, v in serial.items():
            assert got[k].dtype == v.dtype and got[k].shape == v.shape, k
            assert np.array_equal(got[k], v, equal_nan=True) and got[k].tobytes() == v.tobytes(), (
                f"{k} differs with {workers} workers"
            )
    assert len(np.unique(serial["signal/roll_rad"][:, -1])) == 16  # a real, varied data set, not 16 copies
