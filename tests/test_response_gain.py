"""``offline.response_gain``: the 100 Hz per-rotor response-gain fit, checked against hand-built open-loop flights.

The fit's physics: a damaged rotor buys less angular acceleration per command change (its gain drops); a CG
offset adds a constant moment (trim) and leaves the gains alone. On an open-loop synthetic flight with known
gains the fit must recover both. (In closed loop it does not: offline/crazypad/README.md.)"""

from __future__ import annotations

import numpy as np
import pytest

from monitor.errors import ModelError
from offline.response_gain import angular_acceleration, fit_response_gain

RATE_HZ = 100.0
LAG_S = 0.03
ROLL_SIGNS = np.array([-1.0, 1.0, 1.0, -1.0])  # PX4 quad-X roll moment sign per rotor for more thrust


def _flight(gains, trim_moment=0.0, seconds=20.0, seed=0, noise=0.05):
    """(T, 4) commands (a trim plus independent random steps of 0.05-0.5 s) and the roll acceleration they cause
    ``LAG_S`` later: sum_i sign_i * gain_i * u_i + a constant moment + white noise."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE_HZ)
    u = np.full((n, 4), 40000.0)
    for j in range(4):
        t = 0
        while t < n:
            dur = int(rng.integers(5, 50))
            u[t : t + dur, j] += rng.normal(0.0, 800.0)
            t += dur
    lag = int(round(LAG_S * RATE_HZ))
    drive = (u - 40000.0) @ (ROLL_SIGNS * np.asarray(gains) * 1e-3)
    acc = np.full(n, trim_moment) + noise * rng.standard_normal(n)
    acc[lag:] += drive[:-lag]
    return u, acc, np.ones(n, dtype=bool)


def test_recovers_known_gains_by_hand():
    gains = np.array([1.0, 0.8, 1.1, 0.95])
    u, acc, mask = _flight(gains)
    fit = fit_response_gain(u, acc, RATE_HZ, mask, LAG_S)
    assert fit.beta == pytest.approx(ROLL_SIGNS * gains * 1e-3, rel=0.03)
    assert fit.r2 > 0.95
    assert fit.relative(ROLL_SIGNS) == pytest.approx(gains / gains.mean(), rel=0.03)


def test_damaged_rotor_and_cg_offset_told_apart_in_open_loop():
    """A 20 % gain loss on rotor 2 lowers its relative gain by ~20 %; a CG offset (a constant moment, here 30x
    the noise) leaves all four at 1."""

    def relative(**kw):
        u, acc, mask = _flight(**kw)
        return fit_response_gain(u, acc, RATE_HZ, mask, LAG_S).relative(ROLL_SIGNS)

    healthy = relative(gains=[1.0] * 4, seed=1)
    cg = relative(gains=[1.0] * 4, trim_moment=1.5, seed=2)
    damaged = relative(gains=[1.0, 0.8, 1.0, 1.0], seed=3)
    assert healthy == pytest.approx(1.0, abs=0.03) and cg == pytest.approx(1.0, abs=0.03)
    assert damaged[1] == pytest.approx(0.8 / 0.95, abs=0.03)  # 0.8 over the mean of (1, 0.8, 1, 1)
    assert damaged[1] < cg[1] - 0.1


def test_angular_acceleration_by_hand():
    t = np.arange(200) / RATE_HZ
    assert angular_acceleration(None, 0.5 * 3.0 * t**2, RATE_HZ)[2:-2] == pytest.approx(3.0, rel=1e-6)
    assert angular_acceleration(2.0 * t, None, RATE_HZ) == pytest.approx(2.0, rel=1e-6)
    with pytest.raises(ModelError, match="neither a body rate nor an angle"):
        angular_acceleration(np.full(5, np.nan), None, RATE_HZ)


def test_bad_input_is_refused_by_name():
    u, acc, mask = _flight([1.0] * 4, seconds=3.0)
    with pytest.raises(ModelError, match="usable samples"):
        fit_response_gain(u, acc, RATE_HZ, mask, LAG_S)
    u, acc, mask = _flight([1.0] * 4)
    with pytest.raises(ModelError, match=">= 50 Hz"):
        fit_response_gain(u, acc, 20.0, mask, LAG_S)
    with pytest.raises(ModelError, match=r"\(T, 4\)"):
        fit_response_gain(u[:, :3], acc, RATE_HZ, mask, LAG_S)
