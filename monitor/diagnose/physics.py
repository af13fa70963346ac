"""The physics evidence of one flight: rotor effectiveness and the sets of propellers it allows.

Non-overlapping 5 s windows lying wholly in the air with every signal measured give their
moment balances (``monitor.decision.effectiveness``); the balances add up over the flight and the 16
propeller sets are weighed against them. What comes out is what a flight-test engineer can
check by hand: "rotor 3 delivers 0.90 ± 0.02 of nominal thrust", and, where the balance
cannot tell sets apart (a same-spin diagonal pair against a healthy vehicle, all four against
payload), a credible set with more than one member instead of a guess.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.decision.effectiveness import (
    HYPOTHESES,
    PLAUSIBLE_EFFECTIVENESS,
    SET_PRIOR,
    Baseline,
    Evidence,
    HypothesisBank,
    Priors,
    RotorGeometry,
    baseline_from_balances,
    credible_set,
    window_balance,
)
from monitor.flight import FlightTable
from monitor.resample import US_PER_S

CREDIBLE_MASS = 0.95


@dataclass(frozen=True)
class PhysicsEvidence:
    hypotheses: list[dict]  # credible set, most probable first: {"faulty_propellers": [...], "probability": p}
    rotor_effectiveness: list[float]  # η per rotor under the most probable set, PX4 order
    rotor_effectiveness_std: list[float]
    windows: int
    fault_probability: list[float]  # P(rotor i in the faulty set), PX4 order
    log_likelihood: tuple[float, ...] = ()  # marginal log-likelihood of each of the 16 sets (label order)
    # The same balances with the airframe widened to an unmeasured one (motor spread ±4-8 %, CG ±1 cm), and
    # the log Bayes factor unmeasured : as-its-file-says over all 16 sets (prior SET_PRIOR, damage of any size
    # worth locating: Priors.for_airframe_check): large when no damage on the nominal airframe explains this
    # flight, i.e. the airframe is not as its file says.
    log_likelihood_unmeasured: tuple[float, ...] = ()
    airframe_log_bayes_factor: float | None = None

    @property
    def ambiguous(self) -> bool:
        return len(self.hypotheses) > 1


def usable_window_starts(table: FlightTable, window: int) -> np.ndarray:
    """Starts of non-overlapping windows wholly airborne with rates and RPM measured."""
    sig = table.signals()
    ok = table.airborne.copy()
    ok &= np.isfinite(sig["motor_rpm"]).all(axis=1)
    for k in ("roll_rate_rad_s", "pitch_rate_rad_s", "yaw_rate_rad_s"):
        ok &= np.isfinite(sig[k])
    starts = []
    a, n = 0, len(ok)
    while a + window <= n:
        if ok[a : a + window].all():
            starts.append(a)
            a += window
        else:
            a += int(np.argmin(ok[a : a + window])) + 1  # restart after the first unusable step
    return np.asarray(starts, dtype=np.int64)


def table_balances(
    table: FlightTable, geometry: RotorGeometry, window: int, between_boot_s: tuple[float, float] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(z, H, std) of the flight's usable non-overlapping windows (``monitor.decision.effectiveness.window_balance``);
    ``between_boot_s``: only windows lying wholly inside that span of boot time (s)."""
    starts = usable_window_starts(table, window)
    if between_boot_s is not None and len(starts):
        t_s = np.asarray(table.timestamp_us, dtype=np.float64) / US_PER_S
        lo, hi = between_boot_s
        starts = starts[(t_s[starts] >= lo) & (t_s[starts + window - 1] <= hi)]
    if len(starts) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3, 8)), np.zeros((0, 3))
    sig = table.signals()
    rates = np.stack([sig["roll_rate_rad_s"], sig["pitch_rate_rad_s"], sig["yaw_rate_rad_s"]], axis=-1)
    idx = starts[:, None] + np.arange(window)[None, :]
    return window_balance(sig["motor_rpm"][idx], rates[idx], geometry, table.rate_hz)


def table_evidence(
    table: FlightTable, geometry: RotorGeometry, priors: Priors, window: int, between_boot_s: tuple[float, float] | None = None
) -> Evidence:
    ev = Evidence()
    z, h, std = table_balances(table, geometry, window, between_boot_s)
    if len(z):
        ev.add(z, h, std, priors)
    return ev


def own_baseline(table: FlightTable, vehicle, until_boot_s: float, window: int = 100) -> Baseline | None:
    """The flight's own balance before ``until_boot_s`` (``baseline_from_balances``)."""
    return baseline_from_balances(table_balances(table, RotorGeometry.from_vehicle(vehicle), window, (-np.inf, until_boot_s))[0])


def physics_evidence(
    table: FlightTable,
    vehicle,
    priors: Priors | None = None,
    baseline: Baseline | None = None,
    window: int = 100,
    between_boot_s: tuple[float, float] | None = None,
) -> tuple[PhysicsEvidence | None, str | None]:
    """(evidence, None), or (None, why not) when there is no usable window or the balance does not close.
    ``between_boot_s``: only the windows inside that span (e.g. after an in-flight change)."""
    priors = priors or Priors()
    geometry = RotorGeometry.from_vehicle(vehicle)
    ev = table_evidence(table, geometry, priors, window, between_boot_s)
    if ev.windows == 0:
        return None, f"no rotor-effectiveness evidence: no {window}-step airborne window with rates and RPM measured"
    v = HypothesisBank(priors, geometry, baseline).posterior(ev)
    best = v.best
    # The effectiveness reported is the balance's own least-squares reading under the chosen set, not pulled
    # toward the register's loss range (Priors.for_measurement); the sets keep the register's prior.
    measured = HypothesisBank(priors.for_measurement(), geometry, baseline).posterior(ev)
    eta = measured.thrust_fraction[best]
    lo, hi = PLAUSIBLE_EFFECTIVENESS
    if not np.all((eta >= lo) & (eta <= hi)):
        return None, (
            f"rotor-effectiveness evidence withheld: the moment balance of vehicle '{getattr(vehicle, 'name', '?')}' "
            f"does not close on this log (effectiveness {np.round(eta, 2).tolist()} outside {lo}-{hi}); "
            "another airframe or a wrong ESC curve: calibrate it with `propwatch adapt`"
        )
    hyps = [
        {"faulty_propellers": list(HYPOTHESES[k]), "probability": round(float(v.probability[k]), 4)}
        for k in credible_set(v, CREDIBLE_MASS)
    ]
    ll_u = HypothesisBank(priors.with_unmeasured_airframe(), geometry, baseline).posterior(ev).log_likelihood
    check = priors.for_airframe_check()
    bf = airframe_log_bayes_factor(
        HypothesisBank(check, geometry, baseline).posterior(ev).log_likelihood,
        HypothesisBank(check.with_unmeasured_airframe(), geometry, baseline).posterior(ev).log_likelihood,
    )
    return PhysicsEvidence(
        hypotheses=hyps,
        rotor_effectiveness=[round(float(x), 4) for x in eta],
        rotor_effectiveness_std=[round(float(x), 4) for x in measured.thrust_fraction_std[best]],
        windows=int(ev.windows),
        fault_probability=[round(float(x), 4) for x in v.fault_probability()],
        log_likelihood=tuple(float(x) for x in v.log_likelihood),
        log_likelihood_unmeasured=tuple(float(x) for x in ll_u),
        airframe_log_bayes_factor=bf,
    ), None


def airframe_log_bayes_factor(log_likelihood: np.ndarray, log_likelihood_unmeasured: np.ndarray) -> float:
    """log p(flight | unmeasured airframe) - log p(flight | airframe as its file says), each summed over the
    16 sets with the balance's own set prior."""
    lp = np.log(SET_PRIOR)

    def lse(x):
        x = np.asarray(x, dtype=np.float64) + lp
        m = float(np.max(x))
        return m + float(np.log(np.sum(np.exp(x - m))))

    return round(lse(log_likelihood_unmeasured) - lse(log_likelihood), 4)


def predict_table(table: FlightTable, vehicle, priors: Priors | None = None, baseline: Baseline | None = None) -> dict:
    """A scoring predictor: the most probable set, the credible set and P(faulty) per rotor (PX4 order).

    A flight without usable evidence gets ``faulty_propellers: None`` and the reason.
    """
    ev, why_not = physics_evidence(table, vehicle, priors, baseline)
    if ev is None:
        return {"faulty_propellers": None, "hypotheses": [], "fault_probability": None, "reason": why_not}
    return {
        "faulty_propellers": ev.hypotheses[0]["faulty_propellers"],
        "hypotheses": ev.hypotheses,
        "fault_probability": ev.fault_probability,
        "rotor_effectiveness": ev.rotor_effectiveness,
        "rotor_effectiveness_std": ev.rotor_effectiveness_std,
    }
