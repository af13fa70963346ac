"""A flight's rotor shares and regime as sufficient statistics (``FlightSummary``), fed one step or a whole table.

Per accepted step t (airborne, all four values finite, past the take-off settle time; an unknown tilt reads 0): x_t the four rotors'
omega^2 (kRPM^2, from the ESC fit or ESC telemetry), or the raw command where no RPM is known (``basis``); the
share s_t = x_t / mean(x_t); the regime f_t = (1, roll_rad, pitch_rad). Kept: sums of s, f f^T and f s^T (the
regression of shares on tilt: forward flight into wind tilts the vehicle and shifts load between front and rear
rotors), the mean collective, and 2-s block means of s (how much a mean over a few seconds still wanders within one
flight). Feeding a table in one call or step by step gives the same sums (a test checks it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from monitor.errors import ConfigError
from monitor.flight import FlightTable

# Seconds after each take-off whose steps are not accepted: the climb-out from the ground (spool-up, ground effect).
# Chosen, not measured: our simulator's flights start in hover and model no ground effect.
SETTLE_S = 2.0
# Block length of the within-flight wander (10 blocks in 20 s: a covariance from one flight). Chosen, not measured;
# the thresholds of monitor/memory/thresholds.py were measured with it (`make tune-memory`).
BLOCK_S = 2.0
N_REGIME = 3  # (1, roll, pitch)


@dataclass
class FlightSummary:
    """Sufficient statistics of one flight's shares (``basis``: "omega2" or "command")."""

    basis: str
    rate_hz: float
    n: int = 0
    sum_share: np.ndarray = field(default_factory=lambda: np.zeros(4))
    ftf: np.ndarray = field(default_factory=lambda: np.zeros((N_REGIME, N_REGIME)))
    fts: np.ndarray = field(default_factory=lambda: np.zeros((N_REGIME, 4)))
    sum_collective: float = 0.0
    n_blocks: int = 0
    sum_block: np.ndarray = field(default_factory=lambda: np.zeros(4))
    sum_block_outer: np.ndarray = field(default_factory=lambda: np.zeros((4, 4)))

    @property
    def seconds(self) -> float:
        return self.n / self.rate_hz

    def mean_share(self) -> np.ndarray:
        return self.sum_share / max(self.n, 1)

    def mean_regime(self) -> np.ndarray:
        """(3,) mean of (1, roll, pitch) over the accepted steps."""
        return self.ftf[0] / max(self.n, 1)

    def within_cov(self) -> np.ndarray | None:
        """(4, 4) covariance of the 2-s block means within this flight, None below 3 blocks."""
        if self.n_blocks < 3:
            return None
        m = self.sum_block / self.n_blocks
        return (self.sum_block_outer - self.n_blocks * np.outer(m, m)) / (self.n_blocks - 1)

    def to_dict(self) -> dict:
        return {
            "basis": self.basis,
            "rate_hz": self.rate_hz,
            "n": self.n,
            "sum_share": self.sum_share.tolist(),
            "ftf": self.ftf.tolist(),
            "fts": self.fts.tolist(),
            "sum_collective": self.sum_collective,
            "n_blocks": self.n_blocks,
            "sum_block": self.sum_block.tolist(),
            "sum_block_outer": self.sum_block_outer.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict, origin: str = "summary") -> FlightSummary:
        try:
            s = cls(
                basis=str(d["basis"]),
                rate_hz=float(d["rate_hz"]),
                n=int(d["n"]),
                sum_share=np.asarray(d["sum_share"], dtype=np.float64).reshape(4),
                ftf=np.asarray(d["ftf"], dtype=np.float64).reshape(N_REGIME, N_REGIME),
                fts=np.asarray(d["fts"], dtype=np.float64).reshape(N_REGIME, 4),
                sum_collective=float(d["sum_collective"]),
                n_blocks=int(d["n_blocks"]),
                sum_block=np.asarray(d["sum_block"], dtype=np.float64).reshape(4),
                sum_block_outer=np.asarray(d["sum_block_outer"], dtype=np.float64).reshape(4, 4),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"{origin}: malformed flight summary: {exc!r}") from exc
        if s.basis not in ("omega2", "command") or s.n < 0 or not s.rate_hz > 0:
            raise ConfigError(f"{origin}: malformed flight summary: basis {s.basis!r}, n {s.n}, rate {s.rate_hz}")
        for name in ("sum_share", "ftf", "fts", "sum_block", "sum_block_outer"):
            if not np.all(np.isfinite(getattr(s, name))):
                raise ConfigError(f"{origin}: flight summary field {name} holds a non-finite value")
        return s


class ShareAccumulator:
    """Builds a ``FlightSummary`` step by step (the daemon) or a table at a time (a log): identical sums."""

    def __init__(self, basis: str, rate_hz: float) -> None:
        self.summary = FlightSummary(basis=basis, rate_hz=float(rate_hz))
        self._settle = int(round(SETTLE_S * rate_hz))
        self._block = int(round(BLOCK_S * rate_hz))
        self._since_takeoff = 0
        self._blk_n = 0
        self._blk_sum = np.zeros(4)

    def step(self, x: np.ndarray, roll_rad: float, pitch_rad: float, airborne: bool) -> bool:
        """One grid step: ``x`` (4,) omega^2 or command. Returns whether the step was accepted."""
        if not airborne:
            self._since_takeoff = 0
            return False
        self._since_takeoff += 1
        x = np.asarray(x, dtype=np.float64)
        if self._since_takeoff <= self._settle or not np.all(np.isfinite(x)):
            return False
        roll_rad, pitch_rad = _tilt(roll_rad), _tilt(pitch_rad)
        mean = float(np.mean(x))
        if not mean > 0:
            return False
        self._add(x[None, :] / mean, np.array([[1.0, roll_rad, pitch_rad]]), np.array([mean]))
        return True

    def table(self, x: np.ndarray, roll_rad: np.ndarray, pitch_rad: np.ndarray, airborne: np.ndarray) -> None:
        """Every step of a flight at once; the same acceptance rule and sums as ``step`` called per row."""
        x = np.asarray(x, dtype=np.float64)
        ok = np.zeros(len(x), dtype=bool)
        since = self._since_takeoff
        for t, a in enumerate(np.asarray(airborne, dtype=bool)):  # settle counter: cheap, order-dependent
            since = since + 1 if a else 0
            ok[t] = a and since > self._settle
        self._since_takeoff = since
        with np.errstate(invalid="ignore"):
            mean = np.mean(x, axis=1)
            ok &= np.all(np.isfinite(x), axis=1) & (mean > 0)
        if not ok.any():
            return
        s = x[ok] / mean[ok, None]
        f = np.column_stack([np.ones(int(ok.sum())), _tilt(np.asarray(roll_rad)[ok]), _tilt(np.asarray(pitch_rad)[ok])])
        self._add(s, f, mean[ok])

    def _add(self, s: np.ndarray, f: np.ndarray, collective: np.ndarray) -> None:
        sm = self.summary
        sm.n += len(s)
        sm.sum_share = sm.sum_share + s.sum(axis=0)
        sm.ftf = sm.ftf + f.T @ f
        sm.fts = sm.fts + f.T @ s
        sm.sum_collective += float(collective.sum())
        # 2-s blocks of consecutive accepted steps (a block may span a landing: its steps are still this flight's)
        i = 0
        while i < len(s):
            take = min(self._block - self._blk_n, len(s) - i)
            self._blk_sum = self._blk_sum + s[i : i + take].sum(axis=0)
            self._blk_n += take
            i += take
            if self._blk_n == self._block:
                m = self._blk_sum / self._block
                sm.n_blocks += 1
                sm.sum_block = sm.sum_block + m
                sm.sum_block_outer = sm.sum_block_outer + np.outer(m, m)
                self._blk_n, self._blk_sum = 0, np.zeros(4)


def _tilt(a):
    """A tilt angle for the regime; unknown (a log without it, CrazyPAD's pitch) reads 0: no tilt regime is learnt."""
    if isinstance(a, np.ndarray):
        return np.nan_to_num(a, nan=0.0, posinf=0.0, neginf=0.0)
    return float(a) if np.isfinite(a) else 0.0


def rotor_values(table: FlightTable) -> tuple[np.ndarray, str]:
    """(T, 4) omega^2 in kRPM^2 where RPM is known on some airborne step, else the raw command; and the basis."""
    rpm = np.asarray(table.motor_rpm, dtype=np.float64)
    if np.any(table.airborne & np.all(np.isfinite(rpm), axis=1)):
        return (rpm / 1000.0) ** 2, "omega2"
    return np.asarray(table.motor_cmd, dtype=np.float64), "command"


def summarize(table: FlightTable) -> FlightSummary:
    """The whole flight's summary (every airborne span of the log)."""
    x, basis = rotor_values(table)
    acc = ShareAccumulator(basis, table.rate_hz)
    acc.table(x, table.roll_rad, table.pitch_rad, table.airborne)
    return acc.summary
