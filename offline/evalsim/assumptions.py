"""evalsim's unmeasured assumptions, each with its value and why it sits where it does.

Recorded in every set manifest; README.md shows the same table. "training"
is offline/sim + offline/sim/faults.py as of this branch.
"""

from __future__ import annotations

ASSUMPTIONS: dict[str, dict[str, str]] = {
    "damaged_thrust_loss": {
        "value": "bent 8-13 %, cracked 12-20 % at hover, per damaged rotor; onset/effectiveness sets 5-20 %",
        "why": "the issue's range for thrust loss; each rotor draws its own value",
    },
    "thrust_loss_vs_speed": {
        "value": "loss(ω) = loss_hover·(ω/ω_hover)^-γ, γ in [0, 0.5] (constant or falling with speed)",
        "why": "a bent tip unloads at speed; training's loss does not fall with speed",
    },
    "torque_per_thrust_change": {
        "value": "bent -8..-2 %, cracked -12..-4 % (FALLING); effectiveness set 0 or -5 %",
        "why": "training's drag torque at equal speed rises 2-10 % (per unit thrust +10..+30 %); unmeasured, so evaluate on the opposite sign",
    },
    "flutter": {
        "value": "thrust noise 0.5-1 % (bent), 1-3 % (cracked), Gauss-Markov, 50 ms correlation",
        "why": "a cracked blade flexes; its own process, not training's",
    },
    "vibration_1p": {
        "value": "rotating 1P acceleration 0.4-1.0 m/s² (bent), 0.2-0.6 (cracked), 0.05 healthy, x0.35 by the IMU low-pass",
        "why": "mass imbalance at rotor frequency (~90 Hz), aliased into 20 Hz telemetry",
    },
    "motor_time_constant": {
        "value": "30 ms (training 20 ms); slow motor 45-75 ms",
        "why": "vehicle.yaml's 20 ms is itself an assumption; PX4 SIH uses 20-50 ms",
    },
    "motor_efficiency_spread": {
        "value": "paper/healthy ±1 %; shift ±4-8 % (thrust, via rotor speed); weak motor -6 %",
        "why": "real Crazyflies show ±4-8 %",
    },
    "cg_offset": {"value": "shift ±1 cm; nuisance 1.5-2.5 cm", "why": "payload mounting"},
    "inertia_error": {"value": "shift ±10 % per axis; nuisance +25 %", "why": "the paper's inertia is computed, not measured"},
    "drag": {
        "value": "RotorPy parasitic c_D (0.02, 0.02, 0.04) N/(m/s)²; rotor H-force k_d 2e-5 (body-drag nuisance x4-6)",
        "why": "RotorPy's aerodynamic model; training has none by default",
    },
    "blade_flapping": {
        "value": "off (k_flap = 0) except the forward_flight set: uniform 0..1.8e-5 N m per rad/s per m/s, routes at up to 10 m/s",
        "why": "unmeasured for this quad; the upper end is the forward-flight trim of the one real quad here flown fast (ArduPilot log171, front rotors' yaw-free share -0.025 per m/s), carried to the paper quad; blowback's sign (nose-up forward)",
    },
    "esc_curve": {
        "value": "paper fit; hidden set scales it by 0.96-0.98 or 1.02-1.04",
        "why": "the fit is from one load-cell session",
    },
    "battery_sag": {
        "value": "4S 5 Ah, 20 mΩ, RPM -1 %/V below 16 V; nuisance: 35 % charge, 60 mΩ, -3 %/V",
        "why": "ESC speed depends on pack voltage; training's ESC curve is voltage-free",
    },
    "wind": {
        "value": "light: 0-1.5 m/s mean, 0.2 m/s gusts; gusty: 2-5 m/s mean, 0.8-1.5 m/s Gauss-Markov gusts (τ 3 s, 1 s vertical)",
        "why": "first-order Dryden approximation at low altitude",
    },
    "imu": {
        "value": "gyro 0.004 rad/s noise + 0.003 rad/s bias, attitude 0.15° noise + 0.4° tilt bias; nuisance x3-4",
        "why": "PX4 EKF-like outputs after its filters",
    },
    "telemetry": {
        "value": "20 Hz, 4 ms jitter, 0.3 % single-sample drops",
        "why": "MAVLink over a radio as QGroundControl records it",
    },
    "controller": {
        "value": "evalsim's own PX4-like cascade; heading towards the next waypoint (MIS_YAWMODE 0) at 30°/s",
        "why": "training holds yaw; a different controller and route style",
    },
    "routes": {
        "value": "5 waypoints in ±20 m, 6-14 m up, ≤3 m/s, 1.5 m acceptance radius, looped",
        "why": "gentle like the paper's, but new routes in a different box",
    },
    "gravity": {"value": "RotorPy's 9.81 m/s² in the body dynamics; controller uses 9.80665", "why": "RotorPy's own constant"},
}
