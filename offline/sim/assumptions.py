"""The register of unmeasured assumptions: every simulator quantity no measurement pins down.

Each ``Assumption`` holds a name (unit in the name), its range, the
distribution a flight's value is drawn from, the value the fixed simulator
uses (``nominal``), and the reason for the range. ``REGISTER`` is the one
place these live; ``draw_flight(register, seed_sequence)`` turns it into one
flight's physics (``FlightPhysics``), and ``stack`` batches flights for the
simulator (leading axis = flight).

Determinism: each assumption draws from its own child of the flight's
``SeedSequence`` (spawn key extended by a CRC of its name), so a flight's
draws depend only on (register, seed sequence) -- not on the batch, the chunk
or the order of the register -- and adding an entry leaves the others' draws
unchanged. Data sets give flight i ``SeedSequence([seed, i])``.

Entries with ``modelled=False`` name physics the simulator leaves out, so the
list of what is assumed is complete rather than flattering.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from dataclasses import dataclass, field

import numpy as np

from monitor.errors import ConfigError
from offline.sim.faults import FaultSignature

DISTRIBUTIONS = ("uniform", "loguniform")


@dataclass(frozen=True)
class Assumption:
    name: str  # unit in the name
    low: float
    high: float
    nominal: float  # what the fixed (non-randomised) simulator uses
    reason: str
    shape: tuple[int, ...] = ()  # () per flight, (4,) per rotor, (3,) per axis
    distribution: str = "uniform"
    group: str = ""
    modelled: bool = True

    def __post_init__(self) -> None:
        if self.distribution not in DISTRIBUTIONS:
            raise ConfigError(f"assumption {self.name}: distribution must be one of {DISTRIBUTIONS}")
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low <= self.high):
            raise ConfigError(f"assumption {self.name}: need finite low <= high, got {self.low}, {self.high}")
        if self.distribution == "loguniform" and self.low <= 0:
            raise ConfigError(f"assumption {self.name}: a log-uniform range must be positive")
        if not self.reason.strip():
            raise ConfigError(f"assumption {self.name}: give the reason for the range")

    def draw(self, rng: np.random.Generator) -> np.ndarray | float:
        if self.distribution == "loguniform":
            v = np.exp(rng.uniform(math.log(self.low), math.log(self.high), self.shape))
        else:
            v = rng.uniform(self.low, self.high, self.shape)
        return float(v) if self.shape == () else v

    def to_mapping(self) -> dict:
        return dataclasses.asdict(self)


PX4_DOCS = "PX4 v1.14 parameter reference (mc_rate_control / mc_att_control / mc_pos_control params)"
# Damaged blades: no public load-cell data exists for bent or cracked propellers
# (../shared/data/README.md); the fixed signatures of offline/sim/faults.py are one guess inside these ranges.
_NO_DATA = "no public load-cell measurement of damaged blades exists (../shared/data/README.md)"
# A damaged blade's torque per unit thrust, relative to healthy. Its sign is unknown: lost lift lowers the induced
# drag per thrust (as sqrt(1 - loss)), while profile drag per thrust rises as 1/(1 - loss) and more with a rough
# crack, and for a 10 % loss the two nearly cancel (README's hand calculation). So the range favours neither sign:
# a 30 % fall to a 30 % rise, which holds every guess made so far (offline/sim/faults.py's fixed signatures
# +5..+25 %, the evaluation simulator's -12..-2 %). Until 2026-11 it was -10..+30 %, centred on a rise, and the
# network learned that centre as the sign (the torque-sign check, bench/bench_torque_sign.py).
TORQUE_PER_THRUST_CHANGE = (-0.30, 0.30)


def _blade(kind: str, loss_lo, loss_hi, ripple, flutter, fixed: FaultSignature) -> list[Assumption]:
    fixed_c_lo = (1 + fixed.torque_gain_low) / (1 - fixed.thrust_loss_low) - 1
    fixed_c_hi = (1 + fixed.torque_gain_high) / (1 - fixed.thrust_loss_high) - 1
    g = f"damaged blade ({kind})"
    return [
        Assumption(
            f"{kind}_thrust_loss_low_frac",
            *loss_lo,
            fixed.thrust_loss_low,
            f"thrust lost at low speed; {_NO_DATA}. The paper's Figs. 20-23 show losses of a few to ~15 %; "
            "the range brackets the fixed signature with room on both sides.",
            (4,),
            group=g,
        ),
        Assumption(
            f"{kind}_thrust_loss_high_frac",
            *loss_hi,
            fixed.thrust_loss_high,
            f"thrust lost at full speed (the loss varies as s^2 between low and high, so it may grow or shrink with "
            f"speed); {_NO_DATA}.",
            (4,),
            group=g,
        ),
        Assumption(
            f"{kind}_torque_per_thrust_change_low_frac",
            *TORQUE_PER_THRUST_CHANGE,
            fixed_c_lo,
            "change of drag torque per unit thrust at low speed, both signs: more profile drag raises it, lost lift "
            "lowers induced drag and may lower it; nobody has measured which wins. The range is "
            f"symmetric, a 30 % fall to a 30 % rise: the fixed signature's rise ({100 * fixed_c_lo:+.0f} % here, up "
            "to +25 % at full speed) and every other guess so far lie inside it, neither sign is favoured.",
            (4,),
            group=g,
        ),
        Assumption(
            f"{kind}_torque_per_thrust_change_high_frac",
            *TORQUE_PER_THRUST_CHANGE,
            fixed_c_hi,
            f"as the low-speed entry, at full speed (fixed signature: {100 * fixed_c_hi:+.0f} %).",
            (4,),
            group=g,
        ),
        Assumption(
            f"{kind}_ripple_1p_thrust_frac",
            *ripple,
            fixed.ripple_1p_thrust,
            "once-per-revolution thrust imbalance of the two blades; balancing standards allow ~1 % for a healthy "
            f"prop, a damaged one several times that; {_NO_DATA}.",
            (4,),
            group=g,
        ),
        Assumption(
            f"{kind}_ripple_1p_torque_frac",
            *ripple,
            fixed.ripple_1p_torque,
            "once-per-revolution torque imbalance, same argument as the thrust ripple.",
            (4,),
            group=g,
        ),
        Assumption(
            f"{kind}_flutter_thrust_std_frac",
            *flutter,
            fixed.flutter_thrust_std,
            "broadband thrust flutter of a loose section at full speed (scales with s^2); " + _NO_DATA + ".",
            (4,),
            group=g,
        ),
        Assumption(
            f"{kind}_flutter_time_constant_s",
            0.004,
            0.03,
            fixed.flutter_time_constant_s,
            "flutter correlation time: a few blade passes (1P is 10-180 Hz here); not measured.",
            (4,),
            distribution="loguniform",
            group=g,
        ),
    ]


def _default_register() -> tuple[Assumption, ...]:
    from offline.sim.faults import BENT, CRACKED

    gains = "PX4 controller gain"
    a: list[Assumption] = []
    a += _blade("bent", (0.03, 0.12), (0.05, 0.18), (0.01, 0.06), (0.0, 0.01), BENT)
    a += _blade("cracked", (0.0, 0.06), (0.05, 0.20), (0.0, 0.03), (0.01, 0.05), CRACKED)
    a += [
        # Healthy airframe.
        Assumption(
            "motor_efficiency_spread_frac",
            0.04,
            0.08,
            0.0,
            "half-width of the per-motor speed spread (each motor draws uniform in +-spread): healthy CrazyPAD "
            "Crazyflies hold static hover shares of omega^2 such as 1.083 0.864 1.143 0.910 (offline/crazypad/README.md, "
            "E8), i.e. about +-4-7 % in speed; real Crazyflies show +-4-8 %. ESCs and motors of one batch differ alike.",
            group="healthy airframe",
        ),
        Assumption(
            "healthy_torque_per_thrust_spread_frac",
            -0.03,
            0.03,
            0.0,
            "per-rotor drag torque per unit thrust of healthy props: props of one batch differ in pitch and finish "
            "by a few %, which moves the yaw balance as damage does; not measured here.",
            (4,),
            group="healthy airframe",
        ),
        Assumption(
            "cg_offset_frd_m",
            -0.01,
            0.01,
            0.0,
            "horizontal CG offset (z unused): battery and payload placement by hand is good to about a centimetre "
            "on a 0.16 m arm.",
            (2,),
            group="healthy airframe",
        ),
        Assumption(
            "arm_position_error_m",
            -0.003,
            0.003,
            0.0,
            "per-rotor x/y mounting error: frame and motor-mount tolerances of a few mm (not measured here).",
            (4, 2),
            group="healthy airframe",
        ),
        Assumption(
            "inertia_error_frac",
            -0.15,
            0.15,
            0.0,
            "per-axis error of the paper's Table 4.1 inertia for a real build (CAD vs swing test typically 10-20 %).",
            (3,),
            group="healthy airframe",
        ),
        Assumption(
            "linear_drag_n_per_m_s",
            0.1,
            0.7,
            0.0,
            "body-axis linear (rotor) drag; the fixed vehicle has none, so wind does nothing there. Rotor drag of "
            "a few tenths of (m/s^2)/(m/s) is reported for small quads (e.g. Faessler et al. 2018, RA-L), i.e. "
            "0.3-0.7 N/(m/s) at 1.5 kg; not measured for this airframe.",
            (3,),
            group="healthy airframe",
        ),
        Assumption(
            "quadratic_drag_n_per_m2_s2",
            0.0,
            0.05,
            0.0,
            "body-axis parasitic drag quadratic in the airspeed, |v| v per axis (the body and arms as bluff bodies: "
            "0.5 rho C_d A, C_d ~1 on 0.02-0.08 m^2 of a 1-2 kg quad's frontal or top area gives 0.01-0.05 N/(m/s)^2); "
            "beside the linear rotor drag, which dominates at low speed; at 0 the specific force grows only linearly "
            "with airspeed. Not measured for this airframe.",
            (3,),
            group="healthy airframe",
        ),
        # Motors and ESCs.
        Assumption(
            "motor_time_constant_s",
            0.015,
            0.05,
            0.02,
            "first-order motor + ESC lag; PX4 SIH uses ~0.02-0.05 s, 10-inch props spin up in 20-50 ms "
            "(models/vehicle.yaml; refit by calibration when a log exists).",
            distribution="loguniform",
            group="motor and ESC",
        ),
        Assumption(
            "esc_offset_rpm",
            -150.0,
            150.0,
            0.0,
            "per-motor offset of the true command->RPM map from the paper's single quadratic fit (about +-2.5 % at "
            "hover); the fit is of one ESC at one voltage.",
            (4,),
            group="motor and ESC",
        ),
        Assumption(
            "rotor_inertia_kg_m2",
            1.0e-5,
            4.0e-5,
            0.0,
            "rotor + bell inertia for the spin-up yaw reaction J dω/dt (10-inch props ~1-2e-5 kg m^2 plus the motor "
            "bell), drawn on top of the vehicle's rotor_inertia_kg_m2 (0 in models/vehicle.yaml: the fixed simulator "
            "applies the vehicle's value). At hover it leads the yaw drag torque by J / (2 ktau w_hover): 52-210 ms "
            "over this range, more than the motor lag, so a lag fitted without it fits yaw worse; the calibrator fits "
            "it (term rotor_inertia, and with every lag term).",
            distribution="loguniform",
            group="motor and ESC",
        ),
        Assumption(
            "esc_voltage_exponent",
            0.0,
            1.0,
            0.0,
            "speed reached scales as (V / V_full)^k with battery sag: k = 1 for an open-loop (duty-cycle) ESC "
            "(speed ~ KV x voltage), 0 for closed-loop RPM control; PX4's MC_BAT_SCALE_EN is off by default.",
            group="battery",
        ),
        Assumption(
            "battery_internal_resistance_ohm",
            0.01,
            0.05,
            0.02,
            "4S pack resistance: new ~10 mOhm, aged ~50 mOhm (PX4 BAT1_R_INTERNAL order of magnitude).",
            distribution="loguniform",
            group="battery",
        ),
        # Controller gains within the documented PX4 ranges, around the defaults.
        Assumption(
            "mc_rollrate_p",
            0.10,
            0.22,
            0.15,
            f"MC_ROLLRATE_P (= pitch), default 0.15, doc range 0.01-0.5 ({PX4_DOCS}); tuned quads sit near the default.",
            group=gains,
        ),
        Assumption(
            "mc_rollrate_i", 0.10, 0.30, 0.2, f"MC_ROLLRATE_I (= pitch), default 0.2, doc min 0 ({PX4_DOCS}).", group=gains
        ),
        Assumption(
            "mc_rollrate_d",
            0.001,
            0.005,
            0.003,
            f"MC_ROLLRATE_D (= pitch), default 0.003, doc range 0-0.01 ({PX4_DOCS}).",
            group=gains,
        ),
        Assumption(
            "mc_yawrate_p",
            0.12,
            0.30,
            0.2,
            f"MC_YAWRATE_P, default 0.2 ({PX4_DOCS}); a band around the default (documented min 0).",
            group=gains,
        ),
        Assumption("mc_yawrate_i", 0.05, 0.20, 0.1, f"MC_YAWRATE_I, default 0.1, doc min 0 ({PX4_DOCS}).", group=gains),
        Assumption(
            "mc_roll_p",
            5.0,
            8.0,
            6.5,
            f"MC_ROLL_P (= pitch), default 6.5, documented 0-8 in mc_att_control_params.c ({PX4_DOCS}).",
            group=gains,
        ),
        Assumption(
            "mc_yaw_p",
            2.0,
            4.0,
            2.8,
            f"MC_YAW_P, default 2.8 ({PX4_DOCS}); a band around the default (documented min 0).",
            group=gains,
        ),
        Assumption(
            "mpc_xy_vel_p_acc",
            1.4,
            2.6,
            1.8,
            f"MPC_XY_VEL_P_ACC, default 1.8 ({PX4_DOCS}); a band around the default.",
            group=gains,
        ),
        Assumption(
            "mpc_xy_vel_i_acc",
            0.2,
            0.8,
            0.4,
            f"MPC_XY_VEL_I_ACC, default 0.4 ({PX4_DOCS}); a band around the default.",
            group=gains,
        ),
        Assumption(
            "mpc_z_vel_p_acc", 3.0, 6.0, 4.0, f"MPC_Z_VEL_P_ACC, default 4 ({PX4_DOCS}); a band around the default.", group=gains
        ),
        Assumption(
            "mpc_z_vel_i_acc", 1.0, 3.0, 2.0, f"MPC_Z_VEL_I_ACC, default 2 ({PX4_DOCS}); a band around the default.", group=gains
        ),
        # Sensors.
        Assumption(
            "gyro_bias_frd_rad_s",
            -0.005,
            0.005,
            0.0,
            "residual gyro bias after EKF2's bias estimate (a few mrad/s in PX4 logs).",
            (3,),
            group="IMU and attitude",
        ),
        Assumption(
            "gyro_noise_std_rad_s",
            0.002,
            0.01,
            0.003,
            "white noise on the filtered gyro: 2-10 mrad/s in PX4 logs of well- and poorly-damped quads.",
            distribution="loguniform",
            group="IMU and attitude",
        ),
        Assumption(
            "attitude_noise_std_rad",
            0.0005,
            0.003,
            0.001,
            "EKF2 attitude error on the logged Euler angles, ~1 mrad steady, worse with vibration.",
            distribution="loguniform",
            group="IMU and attitude",
        ),
        Assumption(
            "attitude_log_delay_s",
            0.0,
            0.03,
            0.0,
            "logged attitude and rates lag the logged motor commands (estimator output delay, uORB/MAVLink "
            "timestamps); up to about half a 20 Hz period.",
            group="IMU and attitude",
        ),
        # Telemetry.
        Assumption(
            "telemetry_jitter_std_s",
            0.0,
            0.01,
            0.0,
            "std of each 20 Hz sample's true time around its grid slot (MAVLink stream jitter on a busy link).",
            group="telemetry",
        ),
        Assumption(
            "telemetry_drop_prob",
            0.0,
            0.03,
            0.0,
            "per-sample chance a message is lost and the previous value is held (zero-order hold, as "
            "monitor/resample.py does within its staleness limit); radio links lose a few %.",
            group="telemetry",
        ),
        # Wind.
        Assumption(
            "wind_mean_m_s",
            0.0,
            5.0,
            0.0,
            "steady wind speed, random direction; the paper flew in still air, field flights see 0-5 m/s.",
            group="wind",
        ),
        Assumption(
            "turbulence_sigma_w_m_s",
            0.0,
            0.6,
            0.0,
            "Dryden vertical gust intensity at ~10 m (MIL-F-8785C low altitude: sigma_w = 0.1 W20, light to "
            "moderate W20 = 3-6 m/s); horizontal sigma = sigma_w / (0.177 + 0.000823 h)^0.4.",
            group="wind",
        ),
        # Blade flapping: in edgewise flow each rotor's disc tilts back (blowback) and pitches the vehicle nose-up
        # in forward flight (rolls it away from a side flow), linear in airspeed; the controller trims it with the
        # rotors, so the front rotors' omega^2 share falls with forward speed. Drawn as that trim, which a log shows
        # (the share of the front rotors at speed against hover), not as a rotor coefficient nobody measured here.
        Assumption(
            "blade_flapping_trim_per_m_s",
            0.0,
            0.025,
            0.0,
            "fall of each front rotor's yaw-free omega^2 share per m/s of forward airspeed at hover thrust (blade "
            "flapping, blowback's sign). No measurement of this vehicle; bounded by the one real quad here flown "
            "fast, ArduPilot log171, whose front rotors' share falls ~0.025 per m/s (0.11-0.27 at 5-10 m/s). "
            "Zero (no flapping) is inside the range.",
            group="aerodynamics",
        ),
        # Not modelled (recorded so the list is complete).
        Assumption("ground_effect", 0.0, 0.0, 0.0, "not modelled: flights stay at ~10 m.", group="not modelled", modelled=False),
        Assumption(
            "rotor_inflow_vs_airspeed",
            0.0,
            0.0,
            0.0,
            "not modelled: thrust change with inflow (kF fixed in forward flight).",
            group="not modelled",
            modelled=False,
        ),
        Assumption(
            "ekf_dynamics",
            0.0,
            0.0,
            0.0,
            "not modelled: the controller sees the true attitude plus gyro noise.",
            group="not modelled",
            modelled=False,
        ),
        Assumption(
            "payload_inertia",
            0.0,
            0.0,
            0.0,
            "not modelled: a payload is a point mass at the CG.",
            group="not modelled",
            modelled=False,
        ),
    ]
    return tuple(a)


@dataclass(frozen=True)
class AssumptionRegister:
    assumptions: tuple[Assumption, ...] = field(default_factory=_default_register)

    def __post_init__(self) -> None:
        names = [x.name for x in self.assumptions]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ConfigError(f"assumption register: duplicate names {dup}")

    def __getitem__(self, name: str) -> Assumption:
        for x in self.assumptions:
            if x.name == name:
                return x
        raise ConfigError(f"assumption register: no entry {name!r}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(x.name for x in self.assumptions)

    def with_range(self, name: str, low: float, high: float) -> AssumptionRegister:
        """A register with one range changed (e.g. an evaluation set with the torque change's sign flipped).

        A point range (``low == high``) is drawn as uniform, so a log-uniform entry can be pinned at 0; the draw
        takes one uniform variate either way, so every other entry's draw is unchanged."""
        self[name]  # raises on an unknown name
        point = {"distribution": "uniform"} if low == high else {}
        return AssumptionRegister(
            tuple(dataclasses.replace(x, low=low, high=high, **point) if x.name == name else x for x in self.assumptions)
        )

    def to_mapping(self) -> dict:
        return {x.name: x.to_mapping() for x in self.assumptions}


REGISTER = AssumptionRegister()

# The airframe's own terms: what `propwatch adapt` measures from the vehicle's healthy flights. Fixed at
# their nominal values they give the register of a calibrated airframe ("the vehicle is as its file says").
AIRFRAME_TERMS = (
    "cg_offset_frd_m",
    "motor_efficiency_spread_frac",
    "arm_position_error_m",
    "esc_offset_rpm",
    "healthy_torque_per_thrust_spread_frac",
)


def nominal_airframe(register: AssumptionRegister = REGISTER) -> AssumptionRegister:
    """``register`` with the airframe's own terms (``AIRFRAME_TERMS``) at their nominal values."""
    return scaled_airframe(0.0, register)


def scaled_airframe(scale: float, register: AssumptionRegister = REGISTER) -> AssumptionRegister:
    """``register`` with every airframe term's range scaled about its nominal value: 0 the airframe as its file
    says, 1 the register's own (an airframe nobody measured)."""
    for name in AIRFRAME_TERMS:
        a = register[name]
        register = register.with_range(name, a.nominal + scale * (a.low - a.nominal), a.nominal + scale * (a.high - a.nominal))
    return register


def _child_rng(seq: np.random.SeedSequence, name: str) -> np.random.Generator:
    key = tuple(seq.spawn_key) + (zlib.crc32(name.encode()),)
    return np.random.default_rng(np.random.SeedSequence(seq.entropy, spawn_key=key, pool_size=seq.pool_size))


@dataclass(frozen=True)
class FlightPhysics:
    """One flight's drawn values, by assumption name (modelled entries only)."""

    values: dict[str, np.ndarray | float]

    def __getitem__(self, name: str):
        return self.values[name]

    def signature(self, rotor: int, kind: str) -> FaultSignature:
        """The drawn fault signature of ``rotor`` (0..3) for ``kind`` ("bent"/"cracked").

        The torque factor is the thrust factor times (1 + torque-per-thrust change), matched at s = 0 and
        s = 1 (FaultSignature's s^2 form; between them the product differs by < 0.2 % of torque).
        """
        v = lambda n: float(np.asarray(self.values[f"{kind}_{n}"])[rotor])  # noqa: E731
        lo, hi = v("thrust_loss_low_frac"), v("thrust_loss_high_frac")
        c_lo, c_hi = v("torque_per_thrust_change_low_frac"), v("torque_per_thrust_change_high_frac")
        return FaultSignature(
            thrust_loss_low=lo,
            thrust_loss_high=hi,
            torque_gain_low=(1 - lo) * (1 + c_lo) - 1,
            torque_gain_high=(1 - hi) * (1 + c_hi) - 1,
            ripple_1p_thrust=v("ripple_1p_thrust_frac"),
            ripple_1p_torque=v("ripple_1p_torque_frac"),
            flutter_thrust_std=v("flutter_thrust_std_frac"),
            # torque flutter follows thrust flutter at the fixed signature's ratio (2/3)
            flutter_torque_std=v("flutter_thrust_std_frac") * 2.0 / 3.0,
            flutter_time_constant_s=v("flutter_time_constant_s"),
        )

    def healthy_signature(self, rotor: int) -> FaultSignature:
        """A healthy rotor: kF·ω², and kτ·ω² times its drawn torque-per-thrust spread."""
        c = float(np.asarray(self.values["healthy_torque_per_thrust_spread_frac"])[rotor])
        return FaultSignature(torque_gain_low=c, torque_gain_high=c)

    def motor_efficiency(self) -> np.ndarray:
        """(4,) speed scale per motor: 1 + uniform(-1, 1) x the drawn spread."""
        return 1.0 + np.asarray(self.values["motor_efficiency_unit"]) * self.values["motor_efficiency_spread_frac"]

    def to_mapping(self) -> dict:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.values.items()}


def draw_flight(register: AssumptionRegister, seq: np.random.SeedSequence) -> FlightPhysics:
    """One flight's physics from ``register``; a pure function of (register, seq)."""
    values: dict[str, np.ndarray | float] = {}
    for x in register.assumptions:
        if x.modelled:
            values[x.name] = x.draw(_child_rng(seq, x.name))
    # Auxiliary unit draws that turn a drawn spread or speed into per-rotor / per-axis values.
    values["motor_efficiency_unit"] = _child_rng(seq, "motor_efficiency_unit").uniform(-1.0, 1.0, 4)
    values["wind_heading_rad"] = float(_child_rng(seq, "wind_heading_rad").uniform(0.0, 2 * math.pi))
    # Seeds the flight's own gust and telemetry noise (drawn in the simulator, not stored here).
    values["noise_seed"] = int(_child_rng(seq, "noise_seed").integers(2**63 - 1))
    return FlightPhysics(values)


def draw_flights(register: AssumptionRegister, seed: int, flights) -> list[FlightPhysics]:
    """Flight i of a data set with seed ``seed``: ``SeedSequence([seed, i])``, whatever the chunking."""
    return [draw_flight(register, np.random.SeedSequence([int(seed), int(i)])) for i in flights]
