"""A 4S LiPo with linear open-circuit voltage and internal resistance.

Electrical power is the rotors' shaft power divided by a powertrain
efficiency; the pack voltage is ``V_oc(charge) - I R``. Only the logged
``battery_v`` depends on it (the ESC fit maps PWM to RPM whatever the
voltage, as in the paper's model).
"""

from __future__ import annotations

import numpy as np

from monitor.vehicle import VehicleConfig
from offline.sim.controller import clip_in_place

# Motor + ESC efficiency, shaft power / electrical power: typical 0.75-0.85 for
# 10-inch multirotor powertrains (manufacturers' test tables); assumption.
POWERTRAIN_EFFICIENCY = 0.8


class Battery:
    def __init__(self, vehicle: VehicleConfig, n: int):
        self.full_v = vehicle.battery_full_v
        self.empty_v = vehicle.battery_empty_v
        self.capacity_c = vehicle.battery_capacity_mah * 3.6  # mAh -> coulomb
        self.r_ohm = vehicle.battery_internal_resistance_ohm
        self.used_c = np.zeros(n)
        self.voltage_v = np.full(n, self.full_v)
        self.current_a = np.zeros(n)

    def update(self, shaft_power_w: np.ndarray, dt_s: float) -> np.ndarray:
        """Draw ``shaft_power_w`` (B,) for ``dt_s``; returns the loaded pack voltage (B,)."""
        ocv = self.full_v - (self.full_v - self.empty_v) * clip_in_place(self.used_c / self.capacity_c, 0.0, 1.0)
        p = np.maximum(shaft_power_w, 0.0) / POWERTRAIN_EFFICIENCY
        # Solve P = I (V_oc - I R) for the smaller root (the stable operating point).
        disc = np.maximum(ocv * ocv - 4.0 * self.r_ohm * p, 0.0)
        self.current_a = p / np.maximum(0.5 * (ocv + np.sqrt(disc)), 1e-6)
        self.voltage_v = ocv - self.current_a * self.r_ohm
        self.used_c += self.current_a * dt_s
        return self.voltage_v
