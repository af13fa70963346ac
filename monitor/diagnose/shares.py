"""A flight's own balance, from its rotors' shares alone: the physics that needs no airframe file and no network.

On a quad-X whose four rotors sit at equal arms, holding roll, pitch and the total thrust level asks every rotor for
the same thrust (PX4 quad-X: 1 front-right CCW, 2 rear-left CCW, 3 front-left CW, 4 rear-right CW). A rotor whose
propeller lost a fraction f of its thrust must spin faster to give it: its omega^2 rises by 1 / (1 - f) and its
**share** (its omega^2 over the mean of the four) stands above the others'. Nothing here needs the vehicle's mass,
inertia, arm length or propeller constants, so it reads any quad-X: shares are ratios.

``level_shares`` is each rotor's share at level flight: the flight's mean share with its regression on roll and
pitch taken out (``monitor.memory``'s normal, on this one flight). ``standout`` is how far the highest rotor stands
above the next one, in share. Two things move one rotor's share alone, and a first flight cannot tell them apart:
a damaged propeller on it, and the airframe's own balance (a CG off towards that rotor, with the diagonally opposite
rotor falling as far; a weaker motor or ESC). That is the CG-vs-damage ceiling; the vehicle's history removes it.

The yaw balance ``(s1 + s2 - s3 - s4) / 2`` is the CCW pair's share over the CW pair's: a propeller whose drag
torque falls with its thrust moves it towards its own spin direction. It is reported, not judged on: on healthy
airframes the motors' own torque spread moves it as far (``bench.first_flight``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.flight import FlightTable
from monitor.memory.normal import normal_of
from monitor.memory.summary import rotor_values, summarize

# How far one rotor's level share must stand above every other rotor's before a first flight names it: the 99th
# percentile of ``standout`` on healthy flights of our simulator with drawn airframes (register physics: CG offsets,
# motor and ESC spread, arm errors, payload) -- `python -m bench.first_flight --kind healthy --seed 100 --flights 96`.
STANDOUT_SHARE = 0.30
# Fewer accepted level-flight seconds than this and the shares are not judged (a hop, a take-off and landing).
MIN_SECONDS = 5.0


@dataclass(frozen=True)
class ShareEvidence:
    """One flight's own balance. Shares are fractions of the mean of the four (1.0 = an equal share)."""

    basis: str  # "omega2" (RPM known) or "command" (raw outputs)
    seconds: float  # accepted airborne seconds
    level_shares: tuple[float, float, float, float]  # PX4 order
    yaw_balance: float  # (s1 + s2 - s3 - s4) / 2 at level flight: CCW pair over CW pair
    top_rotor: int  # PX4 number of the highest level share
    standout: float  # its share minus the next highest
    threshold: float  # STANDOUT_SHARE

    @property
    def judged(self) -> bool:
        return self.seconds >= MIN_SECONDS

    @property
    def named_rotor(self) -> int | None:
        """The one rotor that stands out beyond what healthy airframes show, else None."""
        return self.top_rotor if self.judged and self.standout > self.threshold else None

    def to_json(self) -> dict:
        return {
            "basis": self.basis,
            "seconds": round(self.seconds, 2),
            "level_shares": [round(float(x), 5) for x in self.level_shares],
            "yaw_balance": round(self.yaw_balance, 5),
            "top_rotor": self.top_rotor,
            "standout": round(self.standout, 5),
            "standout_threshold": self.threshold,
            "named_rotor": self.named_rotor,
        }


def share_evidence(table: FlightTable, mask: np.ndarray | None = None) -> ShareEvidence | None:
    """The flight's own balance over its airborne steps (and ``mask``, when given); None without one accepted step."""
    if mask is not None:
        table = _masked(table, mask)
    s = summarize(table)
    if s.n == 0:
        return None
    level = normal_of([s]).intercept
    level = level / level.mean()
    order = np.argsort(-level, kind="stable")
    return ShareEvidence(
        basis=s.basis,
        seconds=s.seconds,
        level_shares=tuple(float(x) for x in level),
        yaw_balance=float((level[0] + level[1] - level[2] - level[3]) / 2.0),
        top_rotor=int(order[0]) + 1,
        standout=float(level[order[0]] - level[order[1]]),
        threshold=STANDOUT_SHARE,
    )


def _masked(table: FlightTable, mask: np.ndarray) -> FlightTable:
    from dataclasses import replace

    return replace(table, airborne=np.asarray(table.airborne, dtype=bool) & np.asarray(mask, dtype=bool))


def has_outputs(table: FlightTable) -> bool:
    """Whether the log gives all four rotors' outputs on some airborne step (RPM or raw command)."""
    x, _ = rotor_values(table)
    return bool(np.any(np.asarray(table.airborne, dtype=bool) & np.all(np.isfinite(x), axis=1)))
