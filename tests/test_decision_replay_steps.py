"""A replay's steps are the daemon's: ``FlightSteps.each`` (every step at once, as ``replay`` feeds them) gives the
same ``StepInputs`` as ``FlightSteps.inputs(j)``, which goes through the daemon's ``StepInputs.of_state``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from monitor.decision.replay import FlightSteps


def _steps(dtype, with_context: bool, n: int = 3000) -> FlightSteps:
    rng = np.random.default_rng(7)
    # RPM spread over several magnitudes, so that adding a row's values in another order would round differently
    rpm = (rng.uniform(0.5, 2.0, (n, 6)) * 10.0 ** rng.integers(0, 5, (n, 6))).astype(dtype)[:, 1:5]  # not contiguous
    rpm[5] = np.nan
    tilt = rng.uniform(0.0, 0.5, n).astype(dtype)
    tilt[7] = np.nan
    context = rng.normal(size=(n, 3)).astype(dtype)[:, :2] if with_context else None
    return FlightSteps(
        airborne=rng.uniform(size=n) < 0.9,
        motor_rpm=rpm,
        tilt_rad=tilt,
        rate_rad_s=rng.uniform(0.0, 2.0, n).astype(dtype),
        battery_v=rng.uniform(14.0, 16.8, n).astype(dtype),
        vel_heading_m_s=context,
        accel_xy_frd_m_s2=None if context is None else context * 2.0,
    )


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True)
    return type(a) is type(b) and (a == b or (math.isnan(a) and math.isnan(b)))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("with_context", [True, False])
def test_each_step_is_the_daemons_step_bit_for_bit(dtype, with_context):
    steps = _steps(dtype, with_context)
    every = list(steps.each())
    assert len(every) == len(steps)
    fields = ("airborne", "mean_rpm", "tilt_rad", "rate_rad_s", "battery_v", "motor_rpm", "vel_heading_m_s")
    for j, s in enumerate(every):
        one = steps.inputs(j)
        for k in (*fields, "accel_xy_frd_m_s2"):
            assert _same(getattr(s, k), getattr(one, k)), (j, k, getattr(s, k), getattr(one, k))
