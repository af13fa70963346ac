"""``simulate``: fly B quadrotors through their waypoints at once and log them.

Three explicit rates, checked to divide: physics (rigid body, motors,
propeller model), control (attitude + rate loops and the ESC command, as
PX4's rate controller), position (PX4's position/velocity controller), and
the log rate. Every flight starts hovering at ``SimConfig.start_ned_m``.

Randomness (sensor noise) is per flight: with an integer ``seed`` flight i
draws from ``SeedSequence([seed, i])``; with one seed per flight, flight i
draws from ``SeedSequence([seeds[i], 0])``. So a single flight with seed s
equals flight 0 of a batch with seed s, and a batch given per-flight seeds
equals those flights run one at a time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from monitor.errors import ConfigError, ModelError
from monitor.resample import US_PER_S
from monitor.vehicle import VehicleConfig
from offline.sim.battery import Battery
from offline.sim.controller import Controller, ControllerConfig, clip_in_place
from offline.sim.dynamics import GRAVITY_M_S2, Dynamics, VehicleState
from offline.sim.log import BOOT_OFFSET_US, FlightLog
from offline.sim.mission import START_NED_M
from offline.sim.perflight import PerFlightTerms
from offline.sim.quat import quat_to_euler
from offline.sim.wind import gust_series

Vec3 = tuple[float, float, float]
NOISE_CHUNK_S = 1.0  # gyro noise is drawn per flight in blocks of this much flight time


@dataclass(frozen=True)
class SimConfig:
    # 400 Hz: above PX4 SIH's 250 Hz (SIH_LOOP_PERIOD 4000 us) and a multiple of the 20 Hz log.
    physics_rate_hz: int = 400
    control_rate_hz: int = 200  # PX4's rate loop runs at the gyro rate, >= 200 Hz on most boards
    position_rate_hz: int = 50  # PX4 MulticopterPositionControl runs at the estimator rate (~50 Hz)
    log_rate_hz: int = 20  # the paper samples every 0.05 s
    duration_s: float = 80.0  # the paper's flights are 80 s
    # Sensor noise, 0 = off. Gyro: white noise on the filtered gyro the rate loop and the log see
    # (a few mrad/s, typical of PX4 logs of a well-damped quad). Attitude: estimator error on the
    # logged Euler angles (EKF2 attitude is good to ~1 mrad in steady flight).
    gyro_noise_std_rad_s: float = 0.003
    attitude_noise_std_rad: float = 0.001
    start_ned_m: Vec3 = (float(START_NED_M[0]), float(START_NED_M[1]), float(START_NED_M[2]))
    controller: ControllerConfig = field(default_factory=ControllerConfig)

    def __post_init__(self) -> None:
        for name in ("physics_rate_hz", "control_rate_hz", "position_rate_hz", "log_rate_hz"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"{name}: must be a positive integer, got {getattr(self, name)}")
        if self.physics_rate_hz < 250:
            raise ConfigError(f"physics_rate_hz: must be at least 250 Hz, got {self.physics_rate_hz}")
        for name, outer in (
            ("control_rate_hz", self.physics_rate_hz),
            ("position_rate_hz", self.control_rate_hz),
            ("log_rate_hz", self.physics_rate_hz),
        ):
            if outer % getattr(self, name):
                raise ConfigError(f"{name}: {getattr(self, name)} Hz must divide {outer} Hz")
        if not (self.duration_s > 0 and math.isfinite(self.duration_s)):
            raise ConfigError(f"duration_s: must be positive, got {self.duration_s}")
        n = self.duration_s * self.log_rate_hz
        if abs(n - round(n)) > 1e-9:
            raise ConfigError(f"duration_s: {self.duration_s} s is not a whole number of log periods at {self.log_rate_hz} Hz")
        for name in ("gyro_noise_std_rad_s", "attitude_noise_std_rad"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"{name}: must be >= 0, got {getattr(self, name)}")

    @property
    def n_log_samples(self) -> int:
        return int(round(self.duration_s * self.log_rate_hz))

    @property
    def n_physics_steps(self) -> int:
        return self.n_log_samples * (self.physics_rate_hz // self.log_rate_hz)


def flight_seed_sequences(seed, n: int) -> list[np.random.SeedSequence]:
    if np.ndim(seed) == 0:
        return [np.random.SeedSequence([int(seed), i]) for i in range(n)]
    seeds = np.asarray(seed).reshape(-1)
    if len(seeds) != n:
        raise ConfigError(f"seed: got {len(seeds)} per-flight seeds for {n} flights")
    return [np.random.SeedSequence([int(s), 0]) for s in seeds]


def _per_flight(value, n: int, name: str) -> np.ndarray:
    arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).copy() if np.ndim(value) <= 1 else None
    if arr is None or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name}: expected a number or one finite number per flight")
    return arr


def _checked(propellers, shape: tuple[int, int]):
    """``propellers`` that fails by name on wrong output shapes; used for the first step only,
    so a stateful model sees exactly the calls it would see without the check."""

    def call(omega_rad_s: np.ndarray, dt_s: float):
        out = propellers(omega_rad_s, dt_s)
        if not (isinstance(out, tuple) and len(out) == 2):
            raise ModelError(f"propeller model {type(propellers).__name__}: must return (thrust_n, torque_nm)")
        for name, arr in zip(("thrust_n", "torque_nm"), out):
            if np.shape(arr) != shape:
                raise ModelError(
                    f"propeller model {type(propellers).__name__}: {name} has shape {np.shape(arr)}, expected {shape}"
                )
        return out

    return call


def simulate(
    vehicle: VehicleConfig,
    waypoints_ned_m: np.ndarray,
    propellers,
    sim: SimConfig = SimConfig(),
    *,
    payload_kg: np.ndarray | float = 0.0,
    seed=0,
    progress: bool = False,
    per_flight: PerFlightTerms | None = None,
    motor_stop_s: np.ndarray | None = None,
) -> FlightLog:
    """Simulate B flights through ``waypoints_ned_m`` (B, N, 3); see the module doc for seeds.

    ``motor_stop_s`` (B, 4): from this flight time on (s; inf: never) a motor's command is held at the ESC's
    minimum, as an ESC or output that stopped: the controller still asks, the motor no longer follows, and the
    log shows the output at its minimum.

    ``per_flight``: each flight's own drawn physics (``offline.sim.perflight``: motors, ESC, geometry,
    inertia, drag, gusty wind, battery sag, controller gains, gyro bias and noise levels) in place of
    the vehicle's and ``sim``'s single values; None runs the fixed simulator, unchanged.
    """
    wps = np.asarray(waypoints_ned_m, dtype=np.float64)
    if wps.ndim != 3 or wps.shape[2] != 3 or wps.shape[1] < 1 or not np.all(np.isfinite(wps)):
        raise ConfigError(f"waypoints_ned_m: expected finite (B, N, 3), got shape {wps.shape}")
    n = wps.shape[0]
    payload = _per_flight(payload_kg, n, "payload_kg")
    if np.any(payload < 0):
        raise ConfigError("payload_kg: must be >= 0")
    mass = vehicle.mass_kg + payload

    k_ctrl = sim.physics_rate_hz // sim.control_rate_hz
    k_pos = sim.physics_rate_hz // sim.position_rate_hz
    k_log = sim.physics_rate_hz // sim.log_rate_hz
    dt = 1.0 / sim.physics_rate_hz
    pf = per_flight
    dyn = Dynamics(vehicle, mass, dt, pf)
    ctrl = Controller(
        sim.controller, vehicle, mass, 1.0 / sim.position_rate_hz, 1.0 / sim.control_rate_hz, None if pf is None else pf.gains
    )
    esc = vehicle.esc
    battery = Battery(vehicle, n)
    gusts = None
    if pf is not None:
        battery.r_ohm = pf.battery_internal_resistance_ohm.copy()
        n_pos = sim.n_physics_steps // k_pos + 1
        gusts = np.stack(
            [
                gust_series(
                    n_pos,
                    1.0 / sim.position_rate_hz,
                    float(pf.turbulence_sigma_w_m_s[i]),
                    float(np.linalg.norm(pf.wind_mean_ned_m_s[i])),
                    -sim.start_ned_m[2],
                    np.random.default_rng(int(pf.noise_seeds[i])),
                )
                for i in range(n)
            ],
            axis=1,
        )  # (steps, B, 3), time-major like the gyro noise

    hover = np.sqrt(mass * GRAVITY_M_S2 / (4 * vehicle.kf_n_per_rad_s2))[:, None] * np.ones(4)
    state = VehicleState.hover(n, sim.start_ned_m, hover)
    cstate = ctrl.initial_state(n)
    propellers.reset(state.omega_rad_s.copy())

    seqs = [s.spawn(2) for s in flight_seed_sequences(seed, n)]
    gyro_rngs = [np.random.default_rng(s[0]) for s in seqs]
    att_rngs = [np.random.default_rng(s[1]) for s in seqs]
    gyro_bias = np.array(vehicle.gyro_bias_frd_rad_s, dtype=np.float64) if pf is None else pf.gyro_bias_frd_rad_s
    chunk = max(1, int(round(NOISE_CHUNK_S * sim.control_rate_hz)))
    gyro_noise = np.zeros((chunk, n, 3))  # time-major, so one control step's noise is a plain view
    noise_on = sim.gyro_noise_std_rad_s > 0 if pf is None else bool(np.any(pf.gyro_noise_std_rad_s > 0))

    T = sim.n_log_samples
    # PWM and the waypoint error are worked out after the loop from the logged command and
    # waypoint index (elementwise, so the same numbers as step by step).
    log_pos = np.empty((n, T, 3))
    log_vel = np.empty((n, T, 3))
    log_q = np.empty((n, T, 4))
    log_rates = np.empty((n, T, 3))
    log_accel = np.empty((n, T, 3))
    log_omega = np.empty((n, T, 4))
    log_thrust = np.empty((n, T, 4))
    log_torque = np.empty((n, T, 4))
    log_cmd = np.empty((n, T, 4))
    battery_v = np.empty((n, T))
    battery_a = np.empty((n, T))
    wp_index = np.empty((n, T), dtype=np.int64)

    bar = None
    if progress:
        from tqdm import tqdm

        # The n flights advance together, one log step at a time: the bar counts flights done (fractions
        # of each), so its rate and ETA are in flights.
        bar = tqdm(total=n, unit="flight", unit_scale=True, desc="simulate", leave=False)
        per_step = n / T

    # The ESC turns PWM into speed through its fit; the command is the speed the controller
    # asks for, inside the ESC's range. PWM itself (its inverse) is only needed for the log.
    # (0-d arrays: numpy takes those faster than Python floats.)
    omega_lo = np.array(float(esc.cmd_to_omega_rad_s(esc.cmd_min)))
    omega_hi = np.array(float(esc.cmd_to_omega_rad_s(esc.cmd_max)))
    omega_cmd = hover.copy()
    omega_target = dyn.motor_target(omega_cmd)
    gyro = gyro_bias + state.rates_frd_rad_s
    gyro_buf = np.empty((n, 3))  # what the gyro reports, rewritten every control step
    # Hoisted out of the 400 Hz loop: bound methods and the state's views (updated in place).
    update_position, update_attitude, motor_target, step = ctrl.update_position, ctrl.update_attitude, dyn.motor_target, dyn.step
    pos, vel, q, rates, omega = state.pos_ned_m, state.vel_ned_m_s, state.q_world_body, state.rates_frd_rad_s, state.omega_rad_s
    noise_std, log_dt = sim.gyro_noise_std_rad_s, 1.0 / sim.log_rate_hz
    if pf is not None:
        noise_std = pf.gyro_noise_std_rad_s[:, None]
    prop = _checked(propellers, (n, 4))  # the first step only
    stop_s = None
    if motor_stop_s is not None:
        stop_s = np.asarray(motor_stop_s, dtype=np.float64)
        if stop_s.shape != (n, 4) or np.any(np.isnan(stop_s)) or np.any(stop_s < 0):
            raise ConfigError(f"motor_stop_s: expected (B, 4) = ({n}, 4) times >= 0 (inf: never), got shape {stop_s.shape}")
        first_stop_k = int(np.ceil(stop_s.min() * sim.physics_rate_hz)) if np.isfinite(stop_s.min()) else None
    j_ctrl = 0
    for k in range(sim.n_physics_steps):
        if k % k_pos == 0:
            update_position(cstate, pos, vel, wps)
            if gusts is not None:
                np.add(pf.wind_mean_ned_m_s, gusts[k // k_pos], dyn.wind_ned_m_s)
        if k % k_ctrl == 0:
            gyro = np.add(rates, gyro_bias, gyro_buf)
            if noise_on:
                jc = j_ctrl % chunk
                if jc == 0:
                    for i, g in enumerate(gyro_rngs):
                        gyro_noise[:, i] = g.standard_normal((chunk, 3))
                    gyro_noise *= noise_std
                gyro += gyro_noise[jc]
            j_ctrl += 1
            omega_cmd = update_attitude(cstate, q, gyro)
            clip_in_place(omega_cmd, omega_lo, omega_hi)
            if stop_s is not None and first_stop_k is not None and k >= first_stop_k:
                omega_cmd[stop_s <= k * dt] = omega_lo
            omega_target = motor_target(omega_cmd)
        thrust, torque = step(state, omega_target, prop)
        prop = propellers
        if (k + 1) % k_log == 0:
            j = (k + 1) // k_log - 1
            log_pos[:, j] = pos
            log_vel[:, j] = vel
            log_q[:, j] = q
            log_rates[:, j] = gyro  # what the gyro last reported
            log_accel[:, j] = dyn.specific_force_frd_m_s2()
            log_omega[:, j] = omega
            log_thrust[:, j] = thrust
            log_torque[:, j] = torque
            log_cmd[:, j] = omega_cmd
            wp_index[:, j] = cstate.waypoint_index
            battery_v[:, j] = battery.update(np.einsum("ij,ij->i", torque, omega), log_dt)
            battery_a[:, j] = battery.current_a
            if pf is not None:  # battery sag on the speed an open-loop ESC reaches
                dyn.voltage_scale[:, 0] = (battery_v[:, j] / battery.full_v) ** pf.esc_voltage_exponent
            if bar is not None:
                bar.update(per_step)
    if bar is not None:
        bar.close()
    # In place and by blocks of samples, so peak memory stays that of the logs themselves.
    block = sim.log_rate_hz  # one second of samples
    for j0 in range(0, T, block):
        log_cmd[:, j0 : j0 + block] = esc.omega_rad_s_to_cmd(log_cmd[:, j0 : j0 + block])
    wp_error = wps[np.arange(n)[:, None], wp_index]
    wp_error -= log_pos
    log = {
        "pos_ned_m": log_pos,
        "vel_ned_m_s": log_vel,
        "q_world_body": log_q,
        "rates_frd_rad_s": log_rates,
        "accel_frd_m_s2": log_accel,
        "motor_omega_rad_s": log_omega,
        "thrust_n": log_thrust,
        "torque_nm": log_torque,
        "pwm_us": log_cmd,
        "waypoint_error_ned_m": wp_error,
    }

    bad = ~np.all(np.isfinite(log["pos_ned_m"]), axis=(1, 2))
    if bad.any():
        raise ModelError(
            f"simulate: flight(s) {np.flatnonzero(bad).tolist()} diverged (non-finite state); "
            "check the propeller model and the vehicle terms"
        )

    roll, pitch, yaw = quat_to_euler(log["q_world_body"])
    att_std = sim.attitude_noise_std_rad if pf is None else pf.attitude_noise_std_rad[:, None, None]
    if np.any(np.asarray(att_std) > 0):
        att_noise = np.stack([g.standard_normal((T, 3)) for g in att_rngs]) * att_std
        roll, pitch = roll + att_noise[..., 0], pitch + att_noise[..., 1]
        yaw = (yaw + att_noise[..., 2] + math.pi) % (2 * math.pi) - math.pi
    time_s = np.arange(1, T + 1) / sim.log_rate_hz
    timestamp_us = BOOT_OFFSET_US + np.round(np.arange(1, T + 1) * (US_PER_S / sim.log_rate_hz)).astype(np.int64)
    return FlightLog(
        time_s=time_s,
        timestamp_us=timestamp_us,
        roll_rad=roll,
        pitch_rad=pitch,
        yaw_rad=yaw,
        motor_rpm=esc.cmd_to_rpm(log["pwm_us"]),
        battery_v=battery_v,
        battery_current_a=battery_a,
        waypoint_index=wp_index,
        log_rate_hz=float(sim.log_rate_hz),
        **log,
    )
