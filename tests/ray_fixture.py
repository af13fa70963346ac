"""One local Ray instance for the whole test session (2 CPUs), shut down at the end.

Import the fixture into a test module (``from ray_fixture import ray_local``; pytest puts tests/ on sys.path)
or name it from any module once imported; fleet code reuses an initialised Ray.
"""

from __future__ import annotations

import logging

import pytest


@pytest.fixture(scope="session")
def ray_local():
    ray = pytest.importorskip("ray")
    started = not ray.is_initialized()
    if started:
        ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING)
    yield ray
    if started:
        ray.shutdown()
