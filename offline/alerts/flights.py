"""Flights for judging alert rules: healthy ones with randomised physics, and ones with an in-flight onset.

Drawn from our simulator and classified at every step (hop 1, as the daemon
does at 20 Hz). Two ways to draw the physics:

* ``physics="randomised"`` (the default for calibration and evaluation): every
  flight's physics from the assumption register (``offline/sim/assumptions.py``;
  flight i gets ``draw_flight(register, SeedSequence([seed, i]))``), airframe
  terms included (motor efficiency spread, CG offset, arm errors, ESC offsets,
  motor lag, inertia, drag, gusty wind, battery internal resistance and sag,
  controller gains, gyro noise), the damaged blades' own drawn signatures, and
  the register's telemetry delay, jitter and drops applied to the logged
  signals. On top, a ``pickup_fraction`` of flights picks up or drops a payload
  mid-flight: all four rotors' thrust and torque scale by the same factor at a
  drawn time, which is to the controller exactly a mass step of
  ``1 / factor`` (the regime a collective step must re-learn from).
* ``physics="fixed"``: the data set's shift options (random routes, payload,
  steady wind, per-motor efficiency spread, CG offset: one vehicle variant per
  chunk of flights), as before.

What a rule needs per flight is kept: the window outputs, the per-step flight
state for the regime tracker, the accelerometer (for PX4's imbalance metric),
the truth and the onset time.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from monitor.decision.regime import heading_velocity
from monitor.decision.replay import FlightSteps
from monitor.esc import RPM_PER_RAD_S
from monitor.labels import LABEL_MASKS
from monitor.model import Classifier
from monitor.resample import US_PER_S
from monitor.vehicle import VehicleConfig
from offline.dataset.generate import DatasetSpec, degraded_signals, routes, simulate_flights, vehicle_variant
from offline.dataset.onset import SwitchedPropellers


@dataclass(frozen=True)
class FlightSet:
    """How a set of flights is drawn."""

    kind: str  # "healthy" | "single" | "pair" | "any"
    n_flights: int = 16
    duration_s: float = 80.0
    payload_kg: tuple[float, float] = (0.0, 0.6)
    wind_max_m_s: float = 6.0  # physics "fixed" only (these three are drawn from the register under "randomised")
    motor_efficiency_spread: float = 0.06
    cg_offset_max_m: float = 0.01
    onset_s: tuple[float, float] = (25.0, 50.0)
    chunk_flights: int = 8  # one vehicle variant (wind, motor spread, CG) per chunk
    propellers: str = "quadratic"
    seed: int = 0
    physics: str = "fixed"  # "randomised": each flight's physics from the assumption register (airframe drawn)
    pickup_fraction: float = 0.0  # randomised only: flights with a mid-flight payload pick-up or drop
    pickup_mass_step: tuple[float, float] = (0.1, 0.4)  # the mass step, fraction of the flight's mass (+ pick-up)
    first_flight: int = 0  # index of the set's first flight: flights first_flight .. first_flight + n_flights - 1

    def rng(self) -> np.random.Generator:
        """The stream of the set's per-flight draws (conditions, payload, onset, payload step), drawn as arrays
        of ``n_flights``: a set of n flights is not the first n of a larger set. A set appended to another
        (``first_flight`` > 0) draws from its own stream and, under randomised physics, gives its flights the
        indices ``first_flight`` on, so their physics, routes and sensor seeds are new flights of the seed."""
        return np.random.default_rng([self.seed, 13] if self.first_flight == 0 else [self.seed, 13, self.first_flight])


@dataclass
class AlertFlight:
    name: str
    rate_hz: float
    window: int
    fault_probability: np.ndarray  # (N, 4): window k ends at step k + window - 1
    motor_rpm: np.ndarray  # (T, 4) commanded RPM (ESC fit of PWM), PX4 order
    mean_rpm: np.ndarray  # (T,)
    tilt_rad: np.ndarray
    rate_rad_s: np.ndarray
    battery_v: np.ndarray
    accel_frd_m_s2: np.ndarray  # (T, 3)
    truth: tuple[int, ...]  # faulty propellers after onset (1..4)
    onset_s: float  # inf for healthy; time of the first faulty sample (step index / rate)
    thrust_loss: tuple[float, ...] = ()  # per faulty propeller (truth order), fraction of thrust lost at hover; () unknown
    # (T, 2) velocity over ground in the heading frame (forward, right; NED rotated by the logged yaw), m/s; None in
    # flights cached before it was kept (ALERT_FLIGHT_FIELDS). The share baseline's line follows it.
    vel_heading_m_s: np.ndarray | None = None

    def steps(self) -> FlightSteps:
        """The flight's steps as the decision's replay reads them (airborne: every step of these flights is)."""
        return FlightSteps(
            airborne=np.ones(len(self.mean_rpm), dtype=bool),
            motor_rpm=self.motor_rpm,
            tilt_rad=self.tilt_rad,
            rate_rad_s=self.rate_rad_s,
            battery_v=self.battery_v,
            vel_heading_m_s=self.vel_heading_m_s,
            accel_xy_frd_m_s2=None if self.accel_frd_m_s2 is None else self.accel_frd_m_s2[:, :2],
        )

    @property
    def hours(self) -> float:
        return len(self.fault_probability) / self.rate_hz / 3600.0


# What an AlertFlight holds (cache keys carry it, so flights cached without a field are simulated again).
ALERT_FLIGHT_FIELDS = "v2: vel_heading_m_s"


def _conditions(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    if kind == "healthy":
        return np.zeros((n, 4), np.int8)
    n_faulty = LABEL_MASKS.sum(axis=1)
    pool = {"single": np.flatnonzero(n_faulty == 1), "pair": np.flatnonzero(n_faulty == 2), "any": np.arange(1, 16)}[kind]
    masks = LABEL_MASKS[rng.choice(pool, n)] > 0
    return (masks * rng.integers(1, 3, (n, 4))).astype(np.int8)  # each faulty propeller bent or cracked


def simulate_set(vehicle: VehicleConfig, fs: FlightSet, clf: Classifier, log=print) -> list[AlertFlight]:
    if fs.physics == "randomised":
        return _simulate_randomised(vehicle, fs, clf, log)
    if fs.physics != "fixed":
        raise ValueError(f"physics: 'fixed' or 'randomised', got {fs.physics!r}")
    rng = fs.rng()
    out: list[AlertFlight] = []
    spec = DatasetSpec(
        "alerts",
        waypoints=("random",),
        duration_s=fs.duration_s,
        propellers=fs.propellers,
        wind_max_m_s=fs.wind_max_m_s,
        motor_efficiency_spread=fs.motor_efficiency_spread,
        cg_offset_max_m=fs.cg_offset_max_m,
        seed=fs.seed,
    )
    from offline.propellers import build_propellers

    for c0 in range(0, fs.n_flights, fs.chunk_flights):
        n = min(fs.chunk_flights, fs.n_flights - c0)
        cond = _conditions(fs.kind, n, rng)
        payload = rng.uniform(*fs.payload_kg, n)
        onset = np.full(n, np.inf) if fs.kind == "healthy" else rng.uniform(*fs.onset_s, n)
        veh = vehicle_variant(vehicle, spec, rng)
        seed = int(rng.integers(2**31))
        wps, _ = routes(spec, n, seed=seed)
        props = None
        if fs.kind != "healthy":
            before = build_propellers(veh, np.zeros_like(cond), kind=fs.propellers, rng_seed=seed)
            after = build_propellers(veh, cond, kind=fs.propellers, rng_seed=seed + 1)
            props = SwitchedPropellers(before, after, onset)
        flog = simulate_flights(veh, wps, cond, payload, dataclasses.replace(spec, seed=seed), seed, propellers=props)
        out += _classify(flog, clf, cond, onset, f"{fs.kind}-s{fs.seed}-{fs.first_flight + c0}")
        log(f"alerts: {fs.kind} seed {fs.seed}: {len(out)}/{fs.n_flights} flights")
    return out


@dataclass(frozen=True)
class RandomisedChunk:
    """One simulated chunk of a randomised set: the simulator's log and what each flight of it holds."""

    flog: object  # offline.sim.log.FlightLog of len(names) flights
    phys: list  # each flight's draw from the register
    cond: np.ndarray  # (n, 4) 0 healthy, 1 bent, 2 cracked (after the onset)
    onset_s: np.ndarray  # (n,) inf for healthy
    names: list[str]
    after: np.ndarray  # (n, 4) each rotor's signature after the switch

    def hover_thrust_factors(self, b: int, motor_rpm: np.ndarray, vehicle: VehicleConfig, duration_s: float) -> np.ndarray:
        """(4,) flight ``b``'s thrust factor of each rotor after the switch, at that rotor's own hover speed (the
        median of ``motor_rpm`` (T, 4) before the switch)."""
        n0 = max(int(min(self.onset_s[b], duration_s) * self.flog.log_rate_hz), 1)
        s_hover = np.median(np.asarray(motor_rpm)[:n0], axis=0) / (vehicle.omega_max_rad_s * RPM_PER_RAD_S)
        return np.array([self.after[b, r].thrust_factor(s_hover[r]) for r in range(4)])


def randomised_chunks(vehicle: VehicleConfig, fs: FlightSet):
    """The set's flights, chunk by chunk, as the simulator logged them (``RandomisedChunk``).

    Flight i's physics, route and sensor seed depend on (seed, i) only (i counts from ``fs.first_flight``);
    its payload and payload step come from the set's stream (``FlightSet.rng``)."""
    from offline.dataset.generate import flight_sim_seed, sim_config
    from offline.propellers import build_propellers
    from offline.sim.assumptions import REGISTER, draw_flights
    from offline.sim.perflight import PerFlightTerms
    from offline.sim.simulator import simulate

    spec = DatasetSpec(
        "alerts", waypoints=("random",), duration_s=fs.duration_s, propellers="quadratic", physics="randomised", seed=fs.seed
    )
    rng = fs.rng()
    n = fs.n_flights
    first = fs.first_flight
    cond = _conditions(fs.kind, n, rng)
    payload = rng.uniform(*fs.payload_kg, n)
    onset = np.full(n, np.inf) if fs.kind == "healthy" else rng.uniform(*fs.onset_s, n)
    pickup = rng.random(n) < fs.pickup_fraction
    pickup_s = rng.uniform(0.3 * fs.duration_s, 0.7 * fs.duration_s, n)
    step = rng.uniform(*fs.pickup_mass_step, n) * np.where(rng.random(n) < 0.75, 1.0, -1.0)  # 3 in 4 pick up
    wps = routes(spec, first + n, seed=fs.seed)[0][first:]  # flight i's route depends on (seed, i) only
    for c0 in range(0, n, fs.chunk_flights):
        idx = np.arange(c0, min(n, c0 + fs.chunk_flights))  # into this set's arrays; flight first + i of the seed
        phys = draw_flights(REGISTER, fs.seed, first + idx)
        seeds = np.array([flight_sim_seed(fs.seed, first + i) for i in idx])
        before = np.empty((len(idx), 4), dtype=object)
        after = np.empty((len(idx), 4), dtype=object)
        switch_s = np.full(len(idx), np.inf)
        for b, (i, f) in enumerate(zip(idx, phys)):
            for r in range(4):
                c = cond[i, r]
                healthy = f.healthy_signature(r)
                before[b, r] = healthy
                after[b, r] = healthy if c == 0 else _damaged(f, r, c)
                if pickup[i]:  # the payload step scales every rotor: thrust / (1 + step) is mass * (1 + step)
                    k = 1.0 / (1.0 + step[i])
                    after[b, r] = dataclasses.replace(
                        after[b, r],
                        thrust_loss_low=1 - k * (1 - after[b, r].thrust_loss_low),
                        thrust_loss_high=1 - k * (1 - after[b, r].thrust_loss_high),
                        torque_gain_low=k * (1 + after[b, r].torque_gain_low) - 1,
                        torque_gain_high=k * (1 + after[b, r].torque_gain_high) - 1,
                    )
            switch_s[b] = pickup_s[i] if pickup[i] else onset[i]
            if pickup[i] and np.isfinite(onset[i]):
                raise ValueError("pickup_fraction: only for healthy flights (one switch per flight)")
        props = SwitchedPropellers(
            build_propellers(vehicle, np.zeros_like(cond[idx]), kind="quadratic", rng_seed=seeds, rotor_signatures=before),
            build_propellers(vehicle, cond[idx], kind="quadratic", rng_seed=seeds + 1, rotor_signatures=after),
            switch_s,
        )
        flog = simulate(
            vehicle,
            wps[idx],
            props,
            sim_config(spec),
            payload_kg=payload[idx],
            seed=seeds,
            per_flight=PerFlightTerms.from_flights(phys, vehicle),
        )
        names = [
            f"{fs.kind}-r{fs.seed}-{first + i}" + (f"-pickup{step[i]:+.2f}@{pickup_s[i]:.0f}s" if pickup[i] else "") for i in idx
        ]
        yield RandomisedChunk(flog, list(phys), cond[idx], onset[idx], names, after)


def _damaged(flight_draw, r: int, c: int):
    """Rotor r's signature after the onset for condition c (1 bent, 2 cracked): the flight's register draw."""
    return flight_draw.signature(r, "bent" if c == 1 else "cracked")


def onset_draws(fs: FlightSet) -> list[tuple[tuple[int, ...], list]]:
    """Each flight of a randomised onset set: (faulty propellers 1..4, their signatures after the onset), as
    ``randomised_chunks`` draws them, without simulating (what a flight's damage was: bench/bench_pair_physics.py)."""
    from offline.sim.assumptions import REGISTER, draw_flights

    cond = _conditions(fs.kind, fs.n_flights, fs.rng())  # the set stream's first draw, as in randomised_chunks
    phys = draw_flights(REGISTER, fs.seed, fs.first_flight + np.arange(fs.n_flights))
    out = []
    for i, f in enumerate(phys):
        faulty = [r for r in range(4) if cond[i, r]]
        out.append((tuple(r + 1 for r in faulty), [_damaged(f, r, cond[i, r]) for r in faulty]))
    return out


def _simulate_randomised(vehicle: VehicleConfig, fs: FlightSet, clf: Classifier, log) -> list[AlertFlight]:
    """Flights with physics from the assumption register (see the module doc), classified at every step."""
    out: list[AlertFlight] = []
    for ch in randomised_chunks(vehicle, fs):
        degraded = degraded_signals(ch.flog, ch.phys)
        part = _classify(ch.flog, clf, ch.cond, ch.onset_s, "", signals=degraded, names=ch.names)
        for b, f in enumerate(part):  # each damaged rotor's loss at its own hover speed
            factor = ch.hover_thrust_factors(b, f.motor_rpm, vehicle, fs.duration_s)
            f.thrust_loss = tuple(round(float(1.0 - factor[p - 1]), 4) for p in f.truth)
        out += part
        log(f"alerts: {fs.kind} seed {fs.seed} (randomised): {len(out)}/{fs.n_flights} flights")
    return out


def _classify(
    flog, clf: Classifier, cond: np.ndarray, onset: np.ndarray, prefix: str, signals: dict | None = None, names=None
) -> list[AlertFlight]:
    """``signals``: the logged signals as the monitor sees them (telemetry degraded), default the simulator's."""
    from monitor.features import compute_features

    info = clf.info
    w = info.window
    sig = flog.signals() if signals is None else signals
    flights = []
    for b in range(len(cond)):
        feats = compute_features({k: v[b] for k, v in sig.items()}, info.features).astype(np.float32)
        idx = np.arange(len(feats) - w + 1)[:, None] + np.arange(w)[None, :]
        probs = np.concatenate([clf.predict(feats[idx[i : i + 2048]])[1] for i in range(0, len(idx), 2048)])
        rates = np.stack([sig[k][b] for k in ("roll_rate_rad_s", "pitch_rate_rad_s", "yaw_rate_rad_s")], axis=1)
        # The onset switches at the first physics step at or after onset_s; its first logged sample is the next one.
        onset_s = float(np.ceil(onset[b] * flog.log_rate_hz) / flog.log_rate_hz) if np.isfinite(onset[b]) else np.inf
        flights.append(
            AlertFlight(
                f"{prefix}-{b}" if names is None else names[b],
                float(flog.log_rate_hz),
                w,
                probs.astype(np.float64),
                np.asarray(sig["motor_rpm"][b], np.float64),
                np.asarray(sig["motor_rpm"][b], np.float64).mean(axis=1),
                np.maximum(np.abs(sig["roll_rad"][b]), np.abs(sig["pitch_rad"][b])),
                np.abs(rates).max(axis=1),
                flog.battery_v[b].astype(np.float64),
                flog.accel_frd_m_s2[b].astype(np.float64),
                tuple(int(i) + 1 for i in np.flatnonzero(cond[b])),
                onset_s,
                vel_heading_m_s=heading_velocity(flog.vel_ned_m_s[b], sig["yaw_rad"][b]),
            )
        )
    return flights


# -- the evaluation-only simulator (offline/evalsim): never used to calibrate, only to score ---------------
def evalsim_set(
    kind: str, n_flights: int, seed: int, clf: Classifier, duration_s: float = 80.0, log=print, start: int = 0
) -> list[AlertFlight]:
    """``kind``: evalsim's ``healthy`` (one nuisance each: gusts, CG, weak motor, sag, payload pick-up, ...) or
    ``onset`` (5-20 % thrust loss on singles and pairs). Each flight goes through its .tlog and the log reader,
    as diagnose and the daemon would see it (telemetry jitter and drops included). Flights ``start`` to
    ``start + n_flights - 1`` of the set (evalsim's flight i depends on (seed, i) only), so a larger set extends
    a smaller one."""
    from offline.evalsim.sets import build_set

    specs = build_set(kind, flights=start + n_flights, seed=seed, duration_s=duration_s)[start:]
    return [fl for fl, _ in evalsim_specs(specs, clf, log=lambda m: log(f"alerts: evalsim {kind} seed {seed}: {m}"))]


def evalsim_specs(specs: list, clf: Classifier, log=None) -> list[tuple[AlertFlight, object]]:
    """(AlertFlight, the log reader's FlightTable) of each evalsim ``FlightSpec``, through its .tlog and the log
    reader, 8 flights per batch (flights of a batch must share the nominal vehicle and speed limit)."""
    import tempfile
    from pathlib import Path

    from monitor.logs import read_log
    from monitor.model import choose_esc
    from offline.evalsim.flight import simulate_flights as evalsim_flights
    from offline.evalsim.flight import truth
    from offline.sim.io_tlog import write_tlog
    from offline.sim.log import BOOT_OFFSET_US

    esc = choose_esc(clf, "")
    out = []
    with tempfile.TemporaryDirectory(prefix="propwatch-alerts-") as tmp:
        for c0 in range(0, len(specs), 8):
            chunk = specs[c0 : c0 + 8]
            for spec, flog in zip(chunk, evalsim_flights(chunk)):
                path = write_tlog(Path(tmp) / f"{spec.name}.tlog", flog, 0)
                table = read_log(path, esc=esc, rate_hz=clf.info.sample_rate_hz, extras=True)
                tr = truth(spec)
                onset = tr["fault_onset_s"] if tr["faulty_propellers"] else math.inf
                fl = _from_table(table, clf, tuple(tr["faulty_propellers"]), onset, BOOT_OFFSET_US, f"evalsim-{spec.name}")
                fl.thrust_loss = tuple(round(1.0 - tr["thrust_factor_at_hover"][p - 1], 4) for p in fl.truth)
                out.append((fl, table))
            if log is not None:
                log(f"{len(out)}/{len(specs)} flights")
    return out


def _from_table(table, clf: Classifier, truth_props, onset_log_s: float, boot_offset_us: int, name: str) -> AlertFlight:
    from monitor.features import compute_features, valid_windows

    info = clf.info
    w = info.window
    feats = compute_features(table.signals(), info.features).astype(np.float32)
    idx = np.arange(len(feats) - w + 1)[:, None] + np.arange(w)[None, :]
    probs = np.full((len(idx), 4), np.nan)
    ok = valid_windows(feats[idx]) & np.array([table.airborne[i].all() for i in idx])
    good = np.flatnonzero(ok)
    for i in range(0, len(good), 2048):
        probs[good[i : i + 2048]] = clf.predict(feats[idx[good[i : i + 2048]]])[1]
    ts = np.asarray(table.timestamp_us, dtype=np.int64)
    rate = float(table.rate_hz)
    # Step j is at (j + 1) / rate s of this flight; the onset is on the log's clock (boot offset + onset).
    onset_s = (
        (boot_offset_us + onset_log_s * US_PER_S - ts[0]) / US_PER_S + 1.0 / rate if math.isfinite(onset_log_s) else math.inf
    )
    rates = np.abs(np.stack([table.roll_rate_rad_s, table.pitch_rate_rad_s, table.yaw_rate_rad_s], axis=1))
    acc = table.accel_frd_m_s2 if table.accel_frd_m_s2 is not None else np.full((len(ts), 3), np.nan)
    return AlertFlight(
        name,
        rate,
        w,
        probs,
        np.asarray(table.motor_rpm, dtype=np.float64),
        np.asarray(table.motor_rpm, dtype=np.float64).mean(axis=1),
        np.maximum(np.abs(table.roll_rad), np.abs(table.pitch_rad)),
        np.nanmax(np.where(np.isfinite(rates), rates, -np.inf), axis=1),
        np.asarray(table.battery_v, dtype=np.float64),
        np.asarray(acc, dtype=np.float64),
        truth_props,
        float(onset_s),
        vel_heading_m_s=heading_velocity(table.vel_ned_m_s, table.yaw_rad),
    )
