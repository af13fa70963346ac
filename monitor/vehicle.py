"""The vehicle as data: a frozen dataclass loaded from a cited YAML file.

Frames, stated once for the whole project: world NED (north, east, down),
body FRD (forward, right, down); quaternions are scalar-first (w, x, y, z)
and rotate body vectors into the world (``R_world_body``).

Rotors are indexed 0..3 in arrays and numbered 1..4 for people, in PX4 quad-X
order: 1 front-right CCW, 2 rear-left CCW, 3 front-left CW, 4 rear-right CW
(spin as seen from above). Another vehicle (the Crazyflie) states its own
positions and spins here and its logs are mapped onto this order at the
boundary.

The calibration terms (``cg_offset_frd_m`` .. ``gyro_bias_frd_rad_s``) are all
neutral by default; ``offline.calibrate`` fits them and writes a new YAML.
``motor_efficiency[i]`` scales the rotor speed motor i reaches for its
command (a weak motor or sagging ESC), so its thrust scales with the square;
the paper's unbalance ratio (eqs. 14-17) divides omega by U_r in the same way.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path

import numpy as np

from monitor.errors import ConfigError, PropwatchError
from monitor.esc import EscCurve
from monitor.resources import models_dir, shipped

GRAVITY_M_S2 = 9.80665  # standard gravity (ISO 80000-3), PX4 CONSTANTS_ONE_G; the one definition

Vec3 = tuple[float, float, float]
Vec4 = tuple[float, float, float, float]


def _positive(name: str, value: float) -> None:
    if not (value > 0 and math.isfinite(value)):
        raise ConfigError(f"{name}: must be a positive finite number, got {value}")


@dataclass(frozen=True)
class VehicleConfig:
    name: str
    mass_kg: float
    arm_length_m: float
    inertia_diag_kg_m2: Vec3
    rotor_positions_frd_m: tuple[Vec3, Vec3, Vec3, Vec3]
    rotor_spin: tuple[str, str, str, str]
    kf_n_per_rad_s2: float
    ktau_nm_per_rad_s2: float
    motor_time_constant_s: float
    omega_min_rad_s: float
    omega_max_rad_s: float
    esc: EscCurve
    battery_full_v: float
    battery_empty_v: float
    battery_capacity_mah: float
    battery_internal_resistance_ohm: float
    # Calibration terms: neutral by default.
    cg_offset_frd_m: Vec3 = (0.0, 0.0, 0.0)
    motor_efficiency: Vec4 = (1.0, 1.0, 1.0, 1.0)  # rotor-speed scale per motor (thrust ~ square)
    # Per-motor multiple of motor_time_constant_s: one slow motor or ESC (rotor i lags by tau * ratio[i]).
    motor_time_constant_ratio: Vec4 = (1.0, 1.0, 1.0, 1.0)
    linear_drag_n_per_m_s: Vec3 = (0.0, 0.0, 0.0)
    wind_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    gyro_bias_frd_rad_s: Vec3 = (0.0, 0.0, 0.0)
    # Rotor + motor bell inertia about the spin axis: spinning a rotor up takes motor torque whose reaction
    # yaws the body (J dω/dt, the drag torque's sign). 0 leaves the spin-up reaction out.
    rotor_inertia_kg_m2: float = 0.0

    def __post_init__(self) -> None:
        for name in (
            "mass_kg",
            "arm_length_m",
            "kf_n_per_rad_s2",
            "ktau_nm_per_rad_s2",
            "motor_time_constant_s",
            "omega_max_rad_s",
            "battery_full_v",
            "battery_empty_v",
            "battery_capacity_mah",
        ):
            _positive(name, getattr(self, name))
        for i, v in enumerate(self.inertia_diag_kg_m2):
            _positive(f"inertia_diag_kg_m2[{i}]", v)
        if not 0 <= self.omega_min_rad_s < self.omega_max_rad_s:
            raise ConfigError("omega_min_rad_s: must be >= 0 and below omega_max_rad_s")
        if self.battery_internal_resistance_ohm < 0:
            raise ConfigError("battery_internal_resistance_ohm: must be >= 0")
        if self.battery_empty_v >= self.battery_full_v:
            raise ConfigError("battery_empty_v: must be below battery_full_v")
        for i, s in enumerate(self.rotor_spin):
            if s not in ("ccw", "cw"):
                raise ConfigError(f"rotor_spin[{i}]: must be 'ccw' or 'cw', got {s!r}")
        for i, e in enumerate(self.motor_efficiency):
            if not 0 < e <= 2:
                raise ConfigError(f"motor_efficiency[{i}]: must be in (0, 2], got {e}")
        for i, r in enumerate(self.motor_time_constant_ratio):
            if not 0 < r <= 20:
                raise ConfigError(f"motor_time_constant_ratio[{i}]: must be in (0, 20], got {r}")
        if any(d < 0 for d in self.linear_drag_n_per_m_s):
            raise ConfigError("linear_drag_n_per_m_s: must be >= 0")
        if not self.rotor_inertia_kg_m2 >= 0:
            raise ConfigError(f"rotor_inertia_kg_m2: must be >= 0, got {self.rotor_inertia_kg_m2}")

    # Derived arrays (cheap; the simulator caches what it needs).
    @property
    def rotor_positions_array_m(self) -> np.ndarray:
        return np.array(self.rotor_positions_frd_m, dtype=np.float64)

    @property
    def spin_sign(self) -> np.ndarray:
        """+1 for a CCW rotor, -1 for CW.

        A rotor spinning CCW seen from above (about body -z) exerts a reaction
        torque on the body about +z (FRD down), i.e. nose-right yaw: the drag
        yaw moment of rotor i is ``spin_sign[i] * torque_i``.
        """
        return np.array([1.0 if s == "ccw" else -1.0 for s in self.rotor_spin])

    @property
    def rotor_time_constants_s(self) -> np.ndarray:
        """(4,) each rotor's first-order lag, PX4 order."""
        return self.motor_time_constant_s * np.asarray(self.motor_time_constant_ratio, dtype=np.float64)

    @property
    def hover_omega_rad_s(self) -> float:
        return math.sqrt(self.mass_kg * GRAVITY_M_S2 / (4.0 * self.kf_n_per_rad_s2))


# The calibration terms: the fields with a neutral default, which a vehicle file may leave out (no source to cite).
CALIBRATION_TERMS: tuple[str, ...] = tuple(f.name for f in fields(VehicleConfig) if f.default is not MISSING)


@dataclass(frozen=True)
class LoadedVehicle:
    config: VehicleConfig
    sources: dict[str, str] = field(default_factory=dict)
    path: str = ""
    provenance: dict | None = None


def load_vehicle(path: str | Path) -> VehicleConfig:
    """Load a cited vehicle YAML (every value as ``{value, source}``)."""
    return load_vehicle_with_sources(path).config


def load_vehicle_with_sources(path: str | Path) -> LoadedVehicle:
    from monitor.config import from_mapping, read_yaml

    data = read_yaml(path)
    provenance = data.pop("provenance", None)
    cfg, sources = from_mapping(VehicleConfig, data, origin=str(path), cited=True)
    return LoadedVehicle(cfg, sources, str(path), provenance)


def quad_x_positions(arm_length_m: float) -> tuple[Vec3, Vec3, Vec3, Vec3]:
    """PX4 quad-X rotor positions (FRD, m): 1 front-right, 2 rear-left, 3 front-left, 4 rear-right."""
    d = arm_length_m / math.sqrt(2.0)
    return ((d, d, 0.0), (-d, -d, 0.0), (d, -d, 0.0), (-d, d, 0.0))


# The repository root (a checkout's models/ lives there); shipped files are found through monitor.resources.
REPO_ROOT = Path(__file__).resolve().parent.parent
DEFAULT_VEHICLE = shipped("vehicle.yaml")


def vehicle_of_model(model_path) -> Path | None:
    """The shipped vehicle YAML a shipped classifier was trained for (``NAME-classifier.onnx`` beside ``NAME.yaml``;
    ``classifier.onnx``: the paper quad's ``vehicle.yaml``); None for any other model."""
    path = Path(model_path)
    if path.parent.resolve() != models_dir().resolve():
        return None
    stem = path.name.removesuffix(".onnx")
    own = DEFAULT_VEHICLE if stem == "classifier" else path.with_name(stem.removesuffix("-classifier") + ".yaml")
    return own if stem.endswith("classifier") and own.is_file() else None


def vehicles_for_cmd_unit(unit: str) -> list[Path]:
    """Shipped vehicle YAMLs whose ESC curve takes motor commands in ``unit`` (and that ship their own classifier)."""
    found = []
    for path in sorted(models_dir().glob("*.yaml")):
        try:
            if load_vehicle(path).esc.cmd_unit == unit and path.with_name(f"{path.stem}-classifier.onnx").is_file():
                found.append(path)
        except PropwatchError:
            continue
    return found
