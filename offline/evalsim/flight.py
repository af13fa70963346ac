"""One evaluation flight: a frozen ``FlightSpec`` in, a ``FlightLog`` (PX4 NED/FRD, quad-X order) and its truth out.

Rates: physics and the attitude/rate loop at ``PHYSICS_RATE_HZ`` (RK4 on
RotorPy's state derivative), position/velocity loop at ``POSITION_RATE_HZ``,
telemetry at the spec's rate with jitter. The vehicle first hovers
``WARMUP_S`` unlogged so integrators settle, as a real log starts after
take-off. Frames and rotor order are converted in ``frames`` only.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from monitor.esc import PAPER_ESC, RAD_S_PER_RPM
from monitor.labels import label_for
from monitor.resample import US_PER_S
from offline.evalsim import frames
from offline.evalsim.airframe import Airframe, Damage, thrust_torque_factors
from offline.evalsim.controller import CascadeController, ControllerGains, qmul
from offline.evalsim.dynamics import BatchedDerivative, PerRotorMultirotor, rk4_step, rotorpy_params
from offline.evalsim.environment import Battery, Sensors, Telemetry, Wind, sample_times_s
from offline.sim.log import BOOT_OFFSET_US, FlightLog

PHYSICS_RATE_HZ = 250.0
POSITION_RATE_HZ = 50.0
WARMUP_S = 3.0
START_NED_M = (0.0, 0.0, -10.0)
ACCEPTANCE_RADIUS_M = 1.5  # PX4 NAV_ACC_RAD order
YAW_SLEW_RAD_S = np.deg2rad(30.0)
FLUTTER_TAU_S = 0.05
ESTIMATOR_TAU_S = 1.0  # correlation time of the position / velocity estimate's error
EST_A = float(np.exp(-1.0 / (PHYSICS_RATE_HZ * ESTIMATOR_TAU_S)))

if PHYSICS_RATE_HZ % POSITION_RATE_HZ != 0:
    raise ValueError("PHYSICS_RATE_HZ must be a multiple of POSITION_RATE_HZ")


@dataclass(frozen=True)
class FlightSpec:
    """Everything that decides one flight. Same spec -> byte-identical flight."""

    name: str
    airframe: Airframe
    waypoints_ned_m: tuple[tuple[float, float, float], ...]
    duration_s: float
    seed: int
    wind: Wind = field(default_factory=Wind)
    sensors: Sensors = field(default_factory=Sensors)
    telemetry: Telemetry = field(default_factory=Telemetry)
    nuisance: str = ""  # the one hidden effect of a healthy/hidden-set flight
    airframe_id: str = ""  # flights of one airframe share it (hidden set)
    # The position controller's horizontal speed limit (PX4 MPC_XY_VEL_MAX; evalsim's gentle routes: 3 m/s).
    # Flights of one batch share it (one controller flies them).
    vel_xy_max_m_s: float = ControllerGains.vel_xy_max_m_s
    # The vehicle as its file says, what the controller is tuned for and knows (mass, inertia, geometry, kF, kτ, ω
    # limits, ESC curve): None flies the paper quad's controller on the airframe's own geometry (every set before the
    # ``strangers_*`` sets). Flights of one batch share it.
    nominal: Airframe | None = None
    # The controller's gains (None: ``ControllerGains(vel_xy_max_m_s=vel_xy_max_m_s)``). Flights of one batch share them.
    gains: ControllerGains | None = None

    @property
    def controller_gains(self) -> ControllerGains:
        return self.gains if self.gains is not None else ControllerGains(vel_xy_max_m_s=self.vel_xy_max_m_s)

    @property
    def faulty_propellers(self) -> tuple[int, ...]:
        return self.airframe.damage.faulty

    @property
    def label(self) -> int:
        return label_for(self.faulty_propellers)


def truth(spec: FlightSpec, file: str = "") -> dict:
    """Ground truth of ``spec``: faulty propellers (PX4 numbers), per-rotor factors, every hidden parameter."""
    af = spec.airframe
    omega_h = np.full(4, af.hover_omega_rad_s)
    tf, qf = thrust_torque_factors(af, omega_h, damaged=True)
    return {
        "name": spec.name,
        "file": file,
        "seed": spec.seed,
        "label": spec.label,
        "faulty_propellers": list(spec.faulty_propellers),
        "fault_onset_s": af.damage.onset_time_s,
        "thrust_factor_at_hover": [float(x) for x in tf],
        "torque_factor_at_hover": [float(x) for x in qf],
        "motor_thrust_efficiency": list(af.motor_thrust_efficiency),
        "nuisance": spec.nuisance,
        "airframe_id": spec.airframe_id,
        "duration_s": spec.duration_s,
        "waypoints_ned_m": [list(w) for w in spec.waypoints_ned_m],
        "vel_xy_max_m_s": spec.vel_xy_max_m_s,
        "airframe": af.asdict(),
        "wind": asdict(spec.wind),
        "sensors": asdict(spec.sensors),
        "telemetry": asdict(spec.telemetry),
        "frames": "NED/FRD, rotors in PX4 quad-X order (1 FR CCW, 2 RL CCW, 3 FL CW, 4 RR CW)",
    }


def _coefficient_fn(afs: list[Airframe], damaged: np.ndarray):
    """Batched (thrust, torque) coefficients in RotorPy order; ``damaged`` (B,) is read at call time."""
    kf = np.array([[a.kf_n_per_rad_s2] for a in afs])
    kt = np.array([[a.ktau_nm_per_rad_s2] for a in afs])
    loss0 = np.array([a.damage.thrust_loss_at_hover for a in afs])
    expo = np.array([a.damage.loss_speed_exponent for a in afs])
    dq = np.array([a.damage.torque_per_thrust_change for a in afs])
    w_h = np.array([[a.hover_omega_rad_s] for a in afs])

    def coefficients(omega_rp: np.ndarray):
        omega = frames.rotorpy_to_px4(omega_rp)
        tf, qf = damage_factors(omega, w_h, loss0, expo, dq)
        on = damaged[:, None]
        tf = np.where(on, tf, 1.0)
        qf = np.where(on, qf, 1.0)
        return kf * frames.px4_to_rotorpy(tf), kt * frames.px4_to_rotorpy(qf)

    return coefficients


def damage_factors(omega, w_h, loss0, expo, dq) -> tuple[np.ndarray, np.ndarray]:
    """Batched ``airframe.thrust_torque_factors`` (damaged branch), PX4 order."""
    ratio = np.maximum(omega, 1.0) / w_h
    loss = np.minimum(loss0 * ratio ** (-expo), Damage.MAX_LOSS)
    tf = 1.0 - loss
    return tf, tf * (1.0 + dq)


def multirotor_for(af: Airframe, coefficients) -> PerRotorMultirotor:
    """RotorPy model of ``af`` (RotorPy frames and order; CG offset moves every rotor)."""
    pos_frd = np.asarray(af.rotor_positions_frd_m) - np.asarray(af.cg_offset_frd_m)
    params = rotorpy_params(
        af.mass_kg,
        af.inertia_diag_kg_m2,
        frames.positions_flu_rotorpy(pos_frd),
        frames.rotorpy_directions(af.rotor_spin),
        af.kf_n_per_rad_s2,
        af.ktau_nm_per_rad_s2,
        frames.px4_to_rotorpy(np.asarray(af.motor_time_constant_s)),
        0.0,
        af.omega_max_rad_s * 1.2,
        af.drag_quadratic_n_per_m2_s2,
        af.rotor_drag_kg_per_rad,
        af.flapping_nm_per_rad_s_m_s,
    )
    return PerRotorMultirotor(params, coefficients)


def simulate_flight(spec: FlightSpec) -> FlightLog:
    """Fly one ``spec``; a ``FlightLog`` with one flight (leading axis 1)."""
    return simulate_flights([spec])[0]


def simulate_flights(specs: list[FlightSpec]) -> list[FlightLog]:
    """Fly ``specs`` together (vectorised over flights); one ``FlightLog`` each.

    Every flight draws its noise from its own ``default_rng(spec.seed)`` before the
    loop, so a flight is the same whichever flights it is batched with.
    """
    if not specs:
        return []
    nb = len(specs)
    afs = [sp.airframe for sp in specs]
    v0 = specs[0].nominal if specs[0].nominal is not None else afs[0]
    if len({sp.nominal for sp in specs}) > 1:
        raise ValueError("simulate_flights: flights of one batch must share the nominal vehicle")
    for a in afs:
        if (a.rotor_positions_frd_m, a.rotor_spin, a.kf_n_per_rad_s2) != (
            v0.rotor_positions_frd_m,
            v0.rotor_spin,
            v0.kf_n_per_rad_s2,
        ):
            raise ValueError("simulate_flights: flights of one batch must share the nominal vehicle")
    if len({sp.controller_gains for sp in specs}) > 1:
        raise ValueError("simulate_flights: flights of one batch must share vel_xy_max_m_s and gains (one controller)")
    dt = 1.0 / PHYSICS_RATE_HZ
    pos_every = int(PHYSICS_RATE_HZ // POSITION_RATE_HZ)

    damaged = np.array([a.damage.onset_time_s <= 0.0 for a in afs])
    onset = np.array([a.damage.onset_time_s for a in afs])
    coefficients = _coefficient_fn(afs, damaged)
    mrs = [multirotor_for(a, None) for a in afs]
    payload_now = np.array([a.payload_pickup_time_s <= 0.0 for a in afs])
    pickup = np.array([a.payload_pickup_time_s for a in afs])
    for m, a, on in zip(mrs, afs, payload_now, strict=True):
        _set_mass(m, a.mass_kg + (a.payload_kg if on else 0.0))
    f = BatchedDerivative(mrs, coefficients)
    ctrl = CascadeController(
        nb,
        v0.mass_kg,
        v0.inertia_diag_kg_m2,
        np.asarray(v0.rotor_positions_frd_m),
        np.array([1.0 if s == "ccw" else -1.0 for s in v0.rotor_spin]),
        v0.kf_n_per_rad_s2,
        v0.ktau_nm_per_rad_s2,
        v0.omega_min_rad_s,
        v0.omega_max_rad_s,
        specs[0].controller_gains,
        v0.esc if specs[0].nominal is not None else PAPER_ESC,
    )
    stop_rotor = np.array([a.motor_stop_rotor for a in afs])
    stop_at = np.where(stop_rotor > 0, np.array([a.motor_stop_time_s for a in afs]), np.inf)
    stop_mask = np.arange(1, 5)[None, :] == stop_rotor[:, None]  # (B, 4)

    # Per-flight randomness, drawn up front from the flight's own generator.
    plans = [_plan(sp) for sp in specs]
    n_steps = max(int(p["log_steps"][-1]) + 1 for p in plans)
    noise = np.stack([np.pad(p["noise"], ((0, n_steps - len(p["noise"])), (0, 0))) for p in plans])  # (B, S, K)
    gyro_bias = np.stack([p["gyro_bias"] for p in plans])
    att_bias = np.stack([p["att_bias"] for p in plans])
    phase = np.stack([p["phase"] for p in plans])
    wind_mean = np.array([sp.wind.mean_ned_m_s for sp in specs])
    wind_std = np.array([sp.wind.gust_std_m_s for sp in specs])
    wind_a = np.exp(-dt / np.array([sp.wind.gust_time_constant_s for sp in specs]))
    gust = np.stack([p["gust0"] for p in plans]) * wind_std
    sens = [sp.sensors for sp in specs]
    gyro_std = np.array([[s.gyro_noise_std_rad_s] for s in sens])
    pos_std = np.array([[s.position_noise_std_m] for s in sens])
    vel_std = np.array([[s.velocity_noise_std_m_s] for s in sens])
    vib_filter = np.array([[s.vibration_filter_gain] for s in sens])
    vib_gyro_k = np.array([[s.gyro_vibration_rad_s_per_m_s2] for s in sens])
    loss0 = np.array([a.damage.thrust_loss_at_hover for a in afs])
    vib_amp = np.maximum(
        np.where(loss0 > 0, np.array([a.damage.vibration_1p_m_s2 for a in afs]), 0.0),
        np.array([[s.healthy_vibration_m_s2] for s in sens]),
    )
    flutter_std = np.array([a.damage.flutter_thrust_std for a in afs])
    flutter = np.zeros((nb, 4))
    flutter_a = np.exp(-dt / FLUTTER_TAU_S)
    w_h = np.array([[a.hover_omega_rad_s] for a in afs])
    eff_sqrt = np.sqrt(np.array([a.motor_thrust_efficiency for a in afs]))
    distinct_esc = any(a.esc != v0.esc for a in afs)
    esc_sag = np.array([a.esc_rpm_per_volt for a in afs])
    esc_ref = np.array([a.esc_reference_v for a in afs])
    omega_lo = np.array([[a.omega_min_rad_s] for a in afs])
    omega_hi = np.array([[a.omega_max_rad_s] for a in afs])
    ktau = np.array([[a.ktau_nm_per_rad_s2] for a in afs])
    kf = np.array([[a.kf_n_per_rad_s2] for a in afs])
    p_eff = np.array([a.power_efficiency for a in afs])
    dmg = (
        np.array([[a.hover_omega_rad_s] for a in afs]),
        loss0,
        np.array([a.damage.loss_speed_exponent for a in afs]),
        np.array([a.damage.torque_per_thrust_change for a in afs]),
    )
    battery = Battery(
        *(
            np.array([getattr(a, n) for a in afs])
            for n in (
                "battery_full_v",
                "battery_empty_v",
                "battery_capacity_mah",
                "battery_internal_resistance_ohm",
                "battery_start_soc",
            )
        )
    )
    volt, amp = battery.voltage_v, battery.current_a

    s = np.zeros((nb, 20))
    s[:, 0:3] = frames.vec_from_ned(np.array(START_NED_M))
    s[:, 9] = 1.0
    s[:, 16:20] = np.sqrt(f.mass * f.g / (4 * kf[:, 0]))[:, None]
    waypoints = np.stack([np.asarray(sp.waypoints_ned_m, dtype=np.float64) for sp in specs])  # (B, W, 3)
    n_wp = waypoints.shape[1]
    wp_i = np.zeros(nb, dtype=np.int64)
    yaw_sp = np.zeros(nb)
    rows = np.arange(nb)

    log_steps = [p["log_steps"] for p in plans]
    n_log = np.array([len(x) for x in log_steps])
    next_j = np.zeros(nb, dtype=np.int64)
    next_step = np.array([x[0] for x in log_steps])
    rec = {
        k: np.zeros((nb, int(n_log.max())) + shp)
        for k, shp in {
            "pos": (3,),
            "vel": (3,),
            "q": (4,),
            "att": (3,),
            "gyro": (3,),
            "acc": (3,),
            "omega": (4,),
            "thrust": (4,),
            "torque": (4,),
            "pwm": (4,),
            "volt": (),
            "amp": (),
            "wperr": (3,),
            "wpi": (),
        }.items()
    }
    v_prev = s[:, 3:6].copy()
    pos_err = pos_std * np.stack([p["est0"][:3] for p in plans])
    vel_err = vel_std * np.stack([p["est0"][3:] for p in plans])
    start_ned = np.broadcast_to(np.array(START_NED_M), (nb, 3))
    for k in range(n_steps):
        t = k * dt - WARMUP_S
        nz = noise[:, k]
        newly = (~damaged) & (t >= onset)
        if np.any(newly):
            damaged |= newly  # the coefficient closure reads this array
        picked = (~payload_now) & (t >= pickup)
        if np.any(picked):
            payload_now |= picked
            for i in np.flatnonzero(picked):
                _set_mass(mrs[i], afs[i].mass_kg + afs[i].payload_kg)
            f.refresh()
        gust = wind_a * gust + wind_std * np.sqrt(1.0 - wind_a**2) * nz[:, N_WIND]
        # The estimator's position / velocity errors wander slowly (an EKF output is smooth).
        pos_err = EST_A * pos_err + pos_std * np.sqrt(1.0 - EST_A**2) * nz[:, N_POS]
        vel_err = EST_A * vel_err + vel_std * np.sqrt(1.0 - EST_A**2) * nz[:, N_VEL]
        s[:, 13:16] = frames.vec_from_ned(wind_mean + gust)

        # Truth in NED/FRD.
        pos = frames.vec_to_ned(s[:, 0:3])
        vel = frames.vec_to_ned(s[:, 3:6])
        q = frames.quat_rotorpy_to_px4(s[:, 6:10])
        rates = frames.vec_to_ned(s[:, 10:13])
        omega = frames.rotorpy_to_px4(s[:, 16:20])
        phase = (phase + omega * dt) % (2 * np.pi)
        vib = vib_amp * (omega / w_h) ** 2
        vib_acc = np.column_stack([np.sum(vib * np.cos(phase), 1), np.sum(vib * np.sin(phase), 1), np.zeros(nb)])
        vib_gyro = vib_gyro_k * vib_acc[:, [1, 0, 2]] * np.array([1.0, 1.0, 0.0])
        gyro = rates + gyro_bias + vib_filter * vib_gyro + gyro_std * nz[:, N_GYRO]
        q_est = _tilt(q, att_bias)

        if k % pos_every == 0:
            flying = t >= 0
            if flying:
                reached = np.linalg.norm(waypoints[rows, wp_i] - pos, axis=1) < ACCEPTANCE_RADIUS_M
                wp_i = np.where(reached, (wp_i + 1) % n_wp, wp_i)
            target = waypoints[rows, wp_i] if flying else start_ned
            d = target - pos
            bearing = np.arctan2(d[:, 1], d[:, 0])
            err = (bearing - yaw_sp + np.pi) % (2 * np.pi) - np.pi
            step = np.clip(err, -YAW_SLEW_RAD_S / POSITION_RATE_HZ, YAW_SLEW_RAD_S / POSITION_RATE_HZ)
            # PX4 MIS_YAWMODE 0: heading towards the waypoint, held when close to it.
            yaw_sp = np.where(np.hypot(d[:, 0], d[:, 1]) > 2.0, yaw_sp + step, yaw_sp)
            yaw_sp = (yaw_sp + np.pi) % (2 * np.pi) - np.pi
            ctrl.position_step(target, pos + pos_err, vel + vel_err, yaw_sp, 1.0 / POSITION_RATE_HZ)
        thrust_cmd = ctrl.rate_step(q_est, gyro, dt)
        pwm = ctrl.pwm_us(thrust_cmd)
        pwm = np.where(stop_mask & (t >= stop_at)[:, None], ctrl.esc.cmd_min, pwm)
        # The vehicle's ESC: its own curve, RPM sagging with pack voltage; weak motors slower.
        sag = (1.0 - esc_sag * np.maximum(esc_ref - volt, 0.0))[:, None]
        rpm = np.stack([a.esc.cmd_to_rpm(pwm[i]) for i, a in enumerate(afs)]) if distinct_esc else v0.esc.cmd_to_rpm(pwm)
        omega_target = np.clip(rpm * sag * RAD_S_PER_RPM * eff_sqrt, omega_lo, omega_hi)
        if np.any(flutter_std > 0):
            flutter = flutter_a * flutter + flutter_std * np.sqrt(1 - flutter_a**2) * nz[:, N_FLUTTER]
            f.thrust_multiplier = frames.px4_to_rotorpy(np.where(damaged[:, None], 1.0 + flutter, 1.0))

        hit = next_step == k
        if np.any(hit):
            ii = np.flatnonzero(hit)
            jj = next_j[ii]
            tf, qf = damage_factors(omega[ii], *(x[ii] for x in dmg))
            on = damaged[ii, None]
            tf, qf = np.where(on, tf, 1.0), np.where(on, qf, 1.0)
            mult = frames.rotorpy_to_px4(f.thrust_multiplier[ii])
            acc_ned = frames.vec_to_ned((s[ii, 3:6] - v_prev[ii]) / dt)
            g_vec = np.column_stack([np.zeros(len(ii)), np.zeros(len(ii)), f.g[ii]])
            R = frames.rotation_matrices_wxyz(q[ii])
            specific = np.sum(R * (acc_ned - g_vec)[:, :, None], axis=1)  # R^T a, row by row
            att = frames.euler_zyx_batch(frames.rotation_matrices_wxyz(q_est[ii]))
            lg = nz[ii]
            rec["pos"][ii, jj] = pos[ii] + pos_err[ii]
            rec["vel"][ii, jj] = vel[ii] + vel_err[ii]
            rec["q"][ii, jj] = q[ii]
            att_std = np.array([[sens[i].attitude_noise_std_rad] for i in ii])
            rec["att"][ii, jj] = att + att_std * lg[:, N_LOGATT]
            rec["gyro"][ii, jj] = gyro[ii]
            acc_std = np.array([[sens[i].accel_noise_std_m_s2] for i in ii])
            rec["acc"][ii, jj] = specific + vib_filter[ii] * vib_acc[ii] + acc_std * lg[:, N_LOGACC]
            rec["omega"][ii, jj] = omega[ii]
            rec["thrust"][ii, jj] = kf[ii] * tf * mult * omega[ii] ** 2
            rec["torque"][ii, jj] = ktau[ii] * qf * mult * omega[ii] ** 2
            rec["pwm"][ii, jj] = pwm[ii]
            rec["volt"][ii, jj] = volt[ii]
            rec["amp"][ii, jj] = amp[ii]
            rec["wperr"][ii, jj] = waypoints[ii, wp_i[ii]] - pos[ii]
            rec["wpi"][ii, jj] = wp_i[ii]
            next_j[ii] += 1
            for i in ii:
                next_step[i] = log_steps[i][next_j[i]] if next_j[i] < n_log[i] else -1

        v_prev = s[:, 3:6].copy()
        logging = next_step >= 0  # a flight whose log has ended (a shorter one) stays where it is
        s = np.where(logging[:, None], rk4_step(f, s, frames.px4_to_rotorpy(omega_target), dt), s)
        omega_now = frames.rotorpy_to_px4(s[:, 16:20])
        _, qf_now = damage_factors(omega_now, *dmg)
        qf_now = np.where(damaged[:, None], qf_now, 1.0)
        shaft_w = np.sum(ktau * qf_now * omega_now**3, axis=1)
        battery.step(shaft_w / p_eff, dt)
        volt, amp = battery.voltage_v, battery.current_a
        bad_rows = ~np.isfinite(s).all(1) | (s[:, 2] < -50.0)
        if np.any(bad_rows):
            bad = [specs[i].name for i in np.flatnonzero(bad_rows)]
            raise RuntimeError(f"evalsim flights {bad} diverged at t={t:.2f} s")

    out = []
    for i, sp in enumerate(specs):
        n = n_log[i]
        t_s = log_steps[i] * dt - WARMUP_S
        r = {k: v[i, :n][np.newaxis] for k, v in rec.items()}
        out.append(
            FlightLog(
                time_s=t_s,
                timestamp_us=BOOT_OFFSET_US + np.rint(t_s * US_PER_S).astype(np.int64),
                pos_ned_m=r["pos"],
                vel_ned_m_s=r["vel"],
                q_world_body=r["q"],
                roll_rad=r["att"][..., 0],
                pitch_rad=r["att"][..., 1],
                yaw_rad=(r["att"][..., 2] + np.pi) % (2 * np.pi) - np.pi,
                rates_frd_rad_s=r["gyro"],
                accel_frd_m_s2=r["acc"],
                motor_omega_rad_s=r["omega"],
                thrust_n=r["thrust"],
                torque_nm=r["torque"],
                pwm_us=r["pwm"],
                motor_rpm=ctrl.esc.cmd_to_rpm(r["pwm"]),
                battery_v=r["volt"],
                battery_current_a=r["amp"],
                waypoint_error_ned_m=r["wperr"],
                waypoint_index=r["wpi"].astype(np.int64),
                log_rate_hz=sp.telemetry.rate_hz,
            )
        )
    return out


# Columns of a flight's per-step noise array (standard normal draws).
N_WIND, N_GYRO, N_POS, N_VEL = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)
N_FLUTTER = slice(12, 16)
N_LOGATT, N_LOGACC = slice(16, 19), slice(19, 22)
N_NOISE = 22


def _plan(spec: FlightSpec) -> dict:
    """Every random draw of one flight, from its own generator, in a fixed order."""
    rng = np.random.default_rng(spec.seed)
    t_log = sample_times_s(spec.telemetry, spec.duration_s, rng)
    steps = np.rint((t_log + WARMUP_S) * PHYSICS_RATE_HZ).astype(np.int64)
    steps = np.unique(steps)  # increasing, one sample per physics step at most
    sens = spec.sensors
    return {
        "log_steps": steps,
        "gyro_bias": rng.normal(0.0, sens.gyro_bias_std_rad_s, 3) + np.asarray(sens.gyro_bias_frd_rad_s),
        "att_bias": np.array([*rng.normal(0.0, sens.attitude_bias_std_rad, 2), 0.0]),
        "phase": rng.uniform(0.0, 2 * np.pi, 4),
        "gust0": rng.standard_normal(3),
        "est0": rng.standard_normal(6),
        "noise": rng.standard_normal((int(steps[-1]) + 1, N_NOISE)),
    }


def _set_mass(mr: PerRotorMultirotor, mass_kg: float) -> None:
    mr.mass = mass_kg
    mr.weight = np.array([0.0, 0.0, -mass_kg * mr.g])


def _tilt(q: np.ndarray, small_angle_rad: np.ndarray) -> np.ndarray:
    """q followed by a small body rotation (the estimator's attitude error), (B, 4)."""
    d = np.column_stack([np.ones(len(q)), 0.5 * small_angle_rad])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return qmul(q, d)
