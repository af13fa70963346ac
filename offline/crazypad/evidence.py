"""Native-rate evidence per real CrazyPAD flight, and how far each condition moves it from healthy.

Which evidence separates a CG offset (masses taped or hung near M3,
propellers intact) from a damaged M3 propeller (cuts, tape) on the real flights:

- the **moment pattern**: each motor's mean command share, minus its airframe's healthy
  shares. A weak M3 needs more M3 command only; a CG offset near M3 needs more M3 *thrust*
  and less from its diagonal partner M1 (the static moment), so M1's share separates them
  if anything does;
- **activity**: std of each motor's sample-to-sample command change over its mean, at 100 Hz
  (``monitor.features.motor_command_activity``), M3 over the mean of the other three;
- **response gain** (``offline.response_gain``): per rotor, the roll acceleration per change of its command
  (gyro rate differentiated in controller logs, the estimator's roll angle twice in motor logs, which log
  no rate), relative to the mean of the four; a damaged M3 should lower M3's, a mass near it should not;
- **command couplings**: the controller's roll/pitch/yaw/thrust channels recovered from the four commands
  (Hadamard transform of the quad-X mixer), high-passed; in closed loop a rotor whose thrust or torque per
  command differs from the others makes one channel answer another (yaw answering thrust: ``coupling_YT``,
  cov(Y, T) / var(T); roll against pitch: ``coupling_RP``, cov(R, P) / (var R + var P));
- **vibration**: mean-square of the acceleration above 15 Hz (motor logs: the estimator's
  acceleration; ``monitor.features.vibration_energy``) or of the gyro rates (controller logs).

Effect sizes are (condition mean - healthy mean) / healthy flight-to-flight std, per airframe
and per log config, so a condition is compared only with healthy flights of the same vehicle
and the same logged signals.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.errors import LogFormatError, ModelError
from monitor.features import motor_command_activity, vibration_energy
from monitor.flight import true_runs
from monitor.logs import read_log
from offline.crazypad.data import DEFAULT_ROOT, CrazypadFlight
from offline.crazypad.real import core_mask, log_format
from offline.crazypad.vehicle import bitcraze_order
from offline.response_gain import angular_acceleration, fit_response_gain

NATIVE_RATE_HZ = 100.0  # CrazyPAD's logging rate (data README: median dt 9.9 ms)
M3 = 2  # index of Bitcraze M3 in M1..M4 order
# Command-to-thrust lag of the response-gain fit: the Crazyflie's motor time constant (models/crazyflie.yaml,
# motor_time_constant_s); on the healthy calibration flights 3-4 samples at 100 Hz explain most variance.
MOTOR_LAG_S = 0.03
# Roll moment sign of each rotor for more thrust, PX4 order (Bitcraze M1, M3, M4, M2): -y of its arm (FRD).
ROLL_SIGNS_PX4 = np.array([-1.0, 1.0, 1.0, -1.0])
PITCH_SIGNS_PX4 = np.array([1.0, -1.0, 1.0, -1.0])  # +x of its arm
YAW_SIGNS_PX4 = np.array([1.0, 1.0, -1.0, -1.0])  # spin: M1, M3 CCW; M4, M2 CW
COUPLING_HIGHPASS_S = 0.5  # as the response-gain fit: the trim and the flight script's manoeuvres (< 2 Hz) drop out

# Conditions by what they are physically: a CG offset (propellers intact) or propeller damage.
CG_OFFSET_KINDS = ("added_mass_near_motor", "hanging_mass_on_string")
DAMAGE_KINDS = ("propeller_cut", "tape_on_propeller")
# What bench/crazypad_separation.py measured on the shared flights (README, "CG offset or damage?"); a Crazyflie
# adapted on CrazyPAD logs carries it in its healthy baseline, so its one-rotor verdicts name both causes.
CG_DAMAGE_SEPARABLE = False
CG_DAMAGE_EVIDENCE = (
    "offline/crazypad/README.md, bench/crazypad_separation.py: on the shared CrazyPAD flights no activity, vibration, "
    "moment-pattern, 100 Hz response-gain or command-coupling evidence separates masses near M3 from a damaged M3 "
    "propeller"
)


@dataclass(frozen=True)
class FlightEvidence:
    flight: CrazypadFlight
    shares: np.ndarray  # (4,) mean command / mean of the four, Bitcraze M1..M4
    activity: np.ndarray  # (4,) motor_command_activity, Bitcraze M1..M4
    vibration: float  # accel (m/s^2)^2 (motor logs) or gyro (rad/s)^2 (controller logs) above 15 Hz
    roll_gain: np.ndarray  # (4,) roll response gain per rotor over the mean of the four, Bitcraze M1..M4
    roll_gain_r2: float  # variance of the roll acceleration that fit explains
    couplings: dict  # {"YT": ..., "RP": ...}, see command_couplings

    @property
    def config(self) -> str:
        return "motor" if self.flight.has_motor_commands else "controller"

    @property
    def m3_activity_ratio(self) -> float:
        others = np.delete(self.activity, M3)
        return float(self.activity[M3] / np.mean(others))

    def metrics(self) -> dict[str, float]:
        return {
            "share_M1": float(self.shares[0]),
            "share_M2": float(self.shares[1]),
            "share_M3": float(self.shares[2]),
            "share_M4": float(self.shares[3]),
            "activity_M3_over_others": self.m3_activity_ratio,
            "activity_mean": float(np.mean(self.activity)),
            "vibration_log10": float(np.log10(self.vibration)) if self.vibration > 0 else float("nan"),
            "response_gain_M3": float(self.roll_gain[M3]),
            "response_gain_M1": float(self.roll_gain[0]),
            "coupling_YT": float(self.couplings["YT"]),
            "coupling_RP": float(self.couplings["RP"]),
        }


def flight_evidence(flight: CrazypadFlight, root: str | Path = DEFAULT_ROOT) -> FlightEvidence:
    """Read one flight at its native rate and measure its evidence over the core (hover + translation)."""
    tab = read_log(Path(root) / flight.file, fmt=log_format(flight), rate_hz=NATIVE_RATE_HZ)
    mask = core_mask(tab)
    if mask.sum() < NATIVE_RATE_HZ:
        raise LogFormatError(f"{flight.file}: less than 1 s of steady flight")
    cmd = tab.motor_cmd
    m = np.nanmean(cmd[mask], axis=0)
    shares = bitcraze_order(m / m.mean())
    activity = bitcraze_order(motor_command_activity(cmd, NATIVE_RATE_HZ, mask))
    if flight.has_motor_commands:
        acc = tab.extras.get("accel_ned_m_s2")
        sig = None if acc is None else np.asarray(acc)
    else:
        sig = np.stack([tab.roll_rate_rad_s, tab.pitch_rate_rad_s, tab.yaw_rate_rad_s], axis=1)
    vib = _segment_mean(sig, mask) if sig is not None else float("nan")
    acc = angular_acceleration(tab.roll_rate_rad_s, tab.roll_rad, NATIVE_RATE_HZ)
    try:
        fit = fit_response_gain(cmd, acc, NATIVE_RATE_HZ, mask, MOTOR_LAG_S)
        gain, r2 = bitcraze_order(fit.relative(ROLL_SIGNS_PX4)), fit.r2
    except ModelError:  # too little steady flight for the fit: no gain evidence, the rest stands
        gain, r2 = np.full(4, np.nan), float("nan")
    return FlightEvidence(flight, shares, activity, vib, gain, r2, command_couplings(cmd, mask))


def command_couplings(motor_cmd: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """Closed-loop couplings between the controller's channels, from (T, 4) commands in PX4 order (module doc)."""
    h = np.stack([np.full(4, 0.25), ROLL_SIGNS_PX4 / 4, PITCH_SIGNS_PX4 / 4, YAW_SIGNS_PX4 / 4])
    w = int(round(COUPLING_HIGHPASS_S * NATIVE_RATE_HZ))
    parts = []
    for a, b in true_runs(mask):
        c = np.asarray(motor_cmd[a:b], dtype=np.float64) @ h.T  # T, R, P, Y
        if b - a < 3 * w or not np.isfinite(c).all():
            continue
        k = np.ones(w) / w
        c = c - np.stack([np.convolve(c[:, j], k, mode="same") for j in range(4)], axis=1)
        parts.append(c[w:-w])
    if not parts:
        return {"YT": float("nan"), "RP": float("nan")}
    cov = np.cov(np.concatenate(parts).T)
    return {"YT": float(cov[3, 0] / cov[0, 0]), "RP": float(cov[1, 2] / (cov[1, 1] + cov[2, 2]))}


def _segment_mean(sig: np.ndarray, mask: np.ndarray) -> float:
    """Vibration energy over each contiguous stretch of ``mask``, weighted by its length."""
    idx = np.flatnonzero(mask)
    cuts = np.flatnonzero(np.diff(idx) > 1) + 1
    total, n = 0.0, 0
    for seg in np.split(idx, cuts):
        x = sig[seg]
        if len(seg) < NATIVE_RATE_HZ or not np.isfinite(x).all():
            continue
        total += float(vibration_energy(x, NATIVE_RATE_HZ)) * len(seg)
        n += len(seg)
    return total / n if n else float("nan")


def physical_class(flight: CrazypadFlight) -> str:
    if flight.fault_kind in CG_OFFSET_KINDS:
        return "cg_offset"
    if flight.fault_kind in DAMAGE_KINDS:
        return "damage"
    return flight.fault_kind


def effect_sizes(evidence: list[FlightEvidence]) -> list[dict]:
    """Per (log config, airframe, condition group): n and each metric's (mean - healthy) / healthy std."""
    groups: dict[tuple[str, str, str], list[FlightEvidence]] = defaultdict(list)
    for e in evidence:
        groups[(e.config, e.flight.airframe, e.flight.group)].append(e)
    rows = []
    for (config, airframe, group), members in sorted(groups.items()):
        healthy = groups.get((config, airframe, "healthy"), [])
        if len(healthy) < 2:
            continue
        h = _matrix(healthy)
        mu, sd = np.nanmean(h, axis=0), np.nanstd(h, axis=0, ddof=1)
        g = np.nanmean(_matrix(members), axis=0)
        names = list(members[0].metrics())
        rows.append(
            {
                "config": config,
                "airframe": airframe,
                "group": group,
                "class": physical_class(members[0].flight),
                "n": len(members),
                "n_healthy": len(healthy),
                "mean": dict(zip(names, map(float, g))),
                "effect": {k: float((g[i] - mu[i]) / sd[i]) if sd[i] > 0 else float("nan") for i, k in enumerate(names)},
            }
        )
    return rows


def _matrix(evidence: list[FlightEvidence]) -> np.ndarray:
    return np.array([list(e.metrics().values()) for e in evidence], dtype=np.float64)


def separation(evidence: list[FlightEvidence], min_cut_mm: float = 3.0) -> list[dict]:
    """Per (config, airframe, metric): can a threshold tell CG-offset flights from damage flights?

    Damage = cuts >= ``min_cut_mm`` and tape (the faults the issue asks to locate); each metric
    is taken relative to the airframe's healthy mean. ``overlap`` counts the flights on the
    wrong side of the best single threshold; ``d`` is the standardised mean difference
    (pooled std). A metric separates only where ``overlap`` is 0.
    """
    out = []
    by = defaultdict(list)
    for e in evidence:
        by[(e.config, e.flight.airframe)].append(e)
    for (config, airframe), flights in sorted(by.items()):
        healthy = [e for e in flights if e.flight.fault_kind == "healthy"]
        cg = [e for e in flights if physical_class(e.flight) == "cg_offset"]
        dmg = [
            e
            for e in flights
            if physical_class(e.flight) == "damage"
            and (e.flight.fault_kind != "propeller_cut" or e.flight.cut_total_mm >= min_cut_mm - 1e-9)
        ]
        if not healthy or not cg or not dmg:
            continue
        base = np.nanmean(_matrix(healthy), axis=0)
        a, b = _matrix(cg) - base, _matrix(dmg) - base
        for i, name in enumerate(healthy[0].metrics()):
            x, y = a[:, i][np.isfinite(a[:, i])], b[:, i][np.isfinite(b[:, i])]
            if len(x) < 2 or len(y) < 2:
                continue
            pooled = np.sqrt((np.var(x, ddof=1) + np.var(y, ddof=1)) / 2.0)
            out.append(
                {
                    "config": config,
                    "airframe": airframe,
                    "metric": name,
                    "n_cg_offset": len(x),
                    "n_damage": len(y),
                    "cg_offset_mean": float(np.mean(x)),
                    "damage_mean": float(np.mean(y)),
                    "d": float((np.mean(y) - np.mean(x)) / pooled) if pooled > 0 else float("nan"),
                    "overlap": _best_threshold_errors(x, y),
                }
            )
    return out


def _best_threshold_errors(x: np.ndarray, y: np.ndarray) -> int:
    """Fewest flights misplaced by one threshold (either direction) between samples x and y."""
    values = np.sort(np.concatenate([x, y]))
    cands = np.concatenate([[values[0] - 1.0], (values[1:] + values[:-1]) / 2.0, [values[-1] + 1.0]])
    best = len(x) + len(y)
    for t in cands:
        e1 = int(np.sum(x > t) + np.sum(y <= t))
        best = min(best, e1, len(x) + len(y) - e1)
    return best
