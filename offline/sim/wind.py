"""Wind for the simulator: a steady mean plus Dryden-like gusts, generated per flight from its own RNG.

The gust of each NED axis is a first-order Gauss-Markov process with the
Dryden low-altitude variance and length scale (MIL-F-8785C): at height h (m),
``L_w = h``, ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2``, ``sigma_u = sigma_v =
sigma_w / (0.177 + 0.000823 h)^0.4``, correlation time ``L / V``. Dryden's
lateral and vertical spectra are second order; one first-order filter per axis
with the same variance and time scale is the simplification (the classifier
sees 20 Hz data, far below the spectra's knee). ``V`` is the speed at which the
frozen turbulence sweeps past the vehicle: the mean wind, but at least
``MIN_SWEEP_SPEED_M_S`` since the vehicle itself flies at a few m/s.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

MIN_SWEEP_SPEED_M_S = 2.5  # half the mission cruise speed (MPC_XY_CRUISE 5 m/s)


def dryden_scales(sigma_w_m_s: float, height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(sigma (3,), length (3,)) for the north, east, down gust components."""
    h = max(float(height_m), 1.0)
    base = 0.177 + 0.000823 * h
    l_u = h / base**1.2
    s_u = sigma_w_m_s / base**0.4
    return np.array([s_u, s_u, sigma_w_m_s]), np.array([l_u, l_u, h])


def gust_series(
    n_steps: int, dt_s: float, sigma_w_m_s: float, mean_speed_m_s: float, height_m: float, rng: np.random.Generator
) -> np.ndarray:
    """(n_steps, 3) gust velocity (NED, m/s), stationary from the first step."""
    sigma, length = dryden_scales(sigma_w_m_s, height_m)
    speed = max(float(mean_speed_m_s), MIN_SWEEP_SPEED_M_S)
    a = np.exp(-dt_s * speed / length)  # (3,)
    b = sigma * np.sqrt(1.0 - a * a)
    white = rng.standard_normal((n_steps, 3))
    out = np.empty((n_steps, 3))
    for j in range(3):  # g[k] = a g[k-1] + b w[k], started from the stationary distribution
        out[:, j], _ = lfilter([b[j]], [1.0, -a[j]], white[:, j], zi=[a[j] * sigma[j] * rng.standard_normal()])
    return out


def mean_wind_ned(speed_m_s: float, heading_rad: float) -> np.ndarray:
    return np.array([speed_m_s * math.cos(heading_rad), speed_m_s * math.sin(heading_rad), 0.0])
