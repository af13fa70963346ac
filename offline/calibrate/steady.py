"""Steady state: the per-motor command the vehicle holds in hover and cruise, measured vs model.

This is the view the paper used (its Fig. 9): in a steady phase the
controller settles each motor where the real vehicle needs it, so a mismatch
between the measured mean command and the model's trim command is a direct
picture of what the model gets wrong (an off-centre CG tilts the split along a
diagonal, a weak motor raises its own command alone).
"""

from __future__ import annotations

import numpy as np

from monitor.vehicle import VehicleConfig
from offline.calibrate.physics import SpeedScale, steady_thrust_n, trim_commands
from offline.calibrate.prepare import Segment

STEADY_PHASES = ("hover", "cruise")


def command_unit(segments: list[Segment]) -> str:
    return "rpm" if all(np.all(np.isnan(s.motor_cmd)) for s in segments) else "cmd"


def steady_state(
    segments: list[Segment], vehicle: VehicleConfig, masks: list[np.ndarray] | None = None, speed_scale: SpeedScale = None
) -> dict[str, dict]:
    """Per steady phase: measured and predicted mean per-motor command (RPM when the log has no command)."""
    use_rpm = command_unit(segments) == "rpm"
    out: dict[str, dict] = {}
    for phase in STEADY_PHASES:
        meas, pred = [], []
        for i, s in enumerate(segments):
            m = (s.phase == phase) & s.valid
            if masks is not None:
                m &= masks[i]
            if not m.any():
                continue
            cmd = trim_commands(vehicle, steady_thrust_n(s, vehicle)[m], speed_scale)
            if use_rpm:
                pred.append(vehicle.esc.cmd_to_rpm(cmd))
                meas.append(s.motor_rpm[m])
            else:
                pred.append(cmd)
                meas.append(s.motor_cmd[m])
        if not meas:
            continue
        mm, pp = np.concatenate(meas).mean(axis=0), np.concatenate(pred).mean(axis=0)
        out[phase] = {
            "n_samples": int(sum(len(x) for x in meas)),
            "measured": mm.tolist(),
            "predicted": pp.tolist(),
            "error": (mm - pp).tolist(),
            "error_rms": float(np.sqrt(np.mean((mm - pp) ** 2))),
            # Differential part: what a mass or ESC-scale error (common to all motors) cannot explain.
            "spread_error_rms": float(np.sqrt(np.mean(((mm - mm.mean()) - (pp - pp.mean())) ** 2))),
        }
    return out
