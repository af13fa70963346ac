"""The fast per-window path of monitor.decision.effectiveness gives the numbers of the straightforward one.

``window_balance`` sums all its segments (the window and its sub-blocks) in one reduction, and
``HypothesisBank.window_posterior`` scores a window in data space (3 x 3 per set) instead of through
``Evidence`` (11 x 11 per set). ``reference_window_balance`` below is the balance as first written
(one segment at a time, as the module's docstring states it); ``Evidence`` + ``posterior`` is the
information-form path that diagnose sums over a flight.
"""

import numpy as np
import pytest

from monitor.decision.effectiveness import (
    RPM_TO_RAD_S,
    SUB_BLOCKS,
    Baseline,
    Evidence,
    HypothesisBank,
    Priors,
    RotorGeometry,
    window_balance,
)
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

GEOM = RotorGeometry.from_vehicle(load_vehicle(DEFAULT_VEHICLE))
RATE_HZ = 20.0
RTOL = 1e-9


def reference_balance(rpm, w, g, rate_hz):
    """Euler's equation averaged over one segment, written out as in the module docstring."""
    dt = 1.0 / rate_hz
    u = np.square(rpm * RPM_TO_RAD_S)
    u_bar = u[..., :-1, :].mean(axis=-2)
    u_ref = u_bar.mean(axis=-1, keepdims=True)
    share = u_bar / np.where(u_ref > 0, u_ref, np.nan)
    inertia = np.asarray(g.inertia_diag_kg_m2)
    w_mid = 0.5 * (w[..., 1:, :] + w[..., :-1, :])
    gyro = np.cross(w_mid, inertia * w_mid).mean(axis=-2)
    required = inertia * (w[..., -1, :] - w[..., 0, :]) / ((w.shape[-2] - 1) * dt) + gyro
    b = required / (np.array([g.kf_n_per_rad_s2 * g.arm_m] * 2 + [g.ktau_nm_per_rad_s2]) * u_ref)
    h = np.zeros(share.shape[:-1] + (3, 8))
    h[..., 0, :4] = share * np.asarray(g.lever_roll)
    h[..., 1, :4] = share * np.asarray(g.lever_pitch)
    h[..., 2, 4:] = share * np.asarray(g.spin_sign)
    return h.sum(axis=-1) - b, h


def reference_window_balance(rpm, w, g, rate_hz):
    z, h = reference_balance(rpm, w, g, rate_hz)
    n = rpm.shape[-2]
    k = SUB_BLOCKS if n >= 4 * SUB_BLOCKS else 1
    if k == 1:
        return z, h, np.zeros_like(z)
    m = n // k
    zb = np.stack(
        [reference_balance(rpm[..., j * m : (j + 1) * m, :], w[..., j * m : (j + 1) * m, :], g, rate_hz)[0] for j in range(k)], -2
    )
    return z, h, zb.std(axis=-2, ddof=1) / np.sqrt(k)


def flight_like(rng, lead=(), steps=100):
    """Commands around hover with a per-rotor offset (a weak rotor) and manoeuvring body rates."""
    rpm = 5200 + rng.uniform(-400, 400, lead + (1, 4)) + rng.uniform(20, 300) * rng.standard_normal(lead + (steps, 4))
    t = np.arange(steps) / RATE_HZ
    rates = rng.uniform(0.05, 1.5) * np.sin(rng.uniform(0.2, 2.0, lead + (1, 3)) * t[:, None] + rng.uniform(0, 6, lead + (1, 3)))
    return rpm, rates + 0.02 * rng.standard_normal(rates.shape)


@pytest.mark.parametrize("lead,steps", [((), 100), ((5,), 100), ((2, 3), 60), ((), 103), ((), 10)])
def test_window_balance_equals_the_segment_by_segment_reference(lead, steps):
    rng = np.random.default_rng(steps + len(lead))
    rpm, rates = flight_like(rng, lead, steps)
    fast = window_balance(rpm, rates, GEOM, RATE_HZ)
    ref = reference_window_balance(rpm, rates, GEOM, RATE_HZ)
    for got, want, name in zip(fast, ref, ("z", "H", "std")):
        assert got.shape == want.shape, name
        # z is a small difference of O(1) shares: compare to the scale of the terms it is made of
        np.testing.assert_allclose(got, want, rtol=RTOL, atol=1e-12, err_msg=name)


def test_window_balance_of_a_nan_sample_is_not_a_number():
    rng = np.random.default_rng(3)
    rpm, rates = flight_like(rng)
    rates[40, 1] = np.nan
    z, _, std = window_balance(rpm, rates, GEOM, RATE_HZ)
    assert np.isnan(z).any() and np.isnan(std).any()


@pytest.mark.parametrize(
    "priors,baseline",
    [
        (Priors(), None),
        (Priors().for_measurement(), None),
        (Priors.unmeasured_airframe(), None),
        (
            Priors(),
            Baseline(disturbance_mean=(0.01, -0.02, 0.005), disturbance_std=(0.005, 0.005, 0.005), healthy_spread_std=0.01),
        ),
    ],
)
def test_window_posterior_equals_the_evidence_path(priors, baseline):
    bank = HypothesisBank(priors, GEOM, baseline)
    rng = np.random.default_rng(7)
    for trial in range(12):
        windows = 1 + trial % 3  # one window (3 x 3 per set) and several
        z, h, std = window_balance(*flight_like(rng, (windows,)), GEOM, RATE_HZ)
        ev = Evidence()
        ev.add(z, h, std, priors)
        want = bank.posterior(ev)
        got = bank.window_posterior(z, h, std)
        assert got.windows == want.windows == windows
        np.testing.assert_allclose(got.log_likelihood, want.log_likelihood, rtol=RTOL)
        np.testing.assert_allclose(got.probability, want.probability, rtol=RTOL, atol=1e-15)
        for name in ("thrust_fraction", "thrust_fraction_std", "torque_fraction"):
            np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=RTOL, err_msg=name)
        assert got.best == want.best


def test_window_posterior_skips_unmeasured_windows_like_evidence():
    bank = HypothesisBank(Priors(), GEOM)
    rng = np.random.default_rng(11)
    z, h, std = window_balance(*flight_like(rng, (3,)), GEOM, RATE_HZ)
    z[1, 0] = np.nan
    ev = Evidence()
    ev.add(z, h, std, Priors())
    got, want = bank.window_posterior(z, h, std), bank.posterior(ev)
    assert got.windows == want.windows == 2
    np.testing.assert_allclose(got.log_likelihood, want.log_likelihood, rtol=RTOL)
    nothing = bank.window_posterior(np.full(3, np.nan), h[0], std[0])  # no evidence: the prior
    assert nothing.windows == 0
    np.testing.assert_allclose(nothing.thrust_fraction, bank.posterior(Evidence()).thrust_fraction)
