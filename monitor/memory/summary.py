"""A flight's rotor shares and regime as sufficient statistics (``FlightSummary``), fed one step or a whole table.

Per accepted step t (airborne, all four values finite and non-negative, past the take-off settle time; an unknown
tilt, or one beyond +-pi, reads 0): x_t the four rotors' omega^2 (kRPM^2, from the ESC fit or ESC telemetry), or
the raw command where no RPM is known (``basis``); the share s_t = x_t / mean(x_t); the regime
f_t = (1, roll_rad, pitch_rad). Kept: sums of s, f f^T and f s^T (the regression of shares on tilt: forward flight
into wind tilts the vehicle and shifts load between front and rear rotors), the mean collective, and 2-s block means
of s (how much a mean over a few seconds still wanders within one flight). Feeding a table in one call or step by
step gives the same sums (a test checks it). The accumulator also marks the sums at the end of each 2-s block
(``Mark``): the flight from any mark to its end is the whole flight ``minus`` that mark, which is how a flight is
judged through time (``monitor.memory.through_time``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

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
# What a flight can produce, the bounds a stored summary is checked against (``FlightSummary.check``). Chosen, not
# measured: longer than any multirotor flight, faster than any log or grid rate, past any rotor's omega^2 (kRPM^2)
# or raw command (PWM us).
MAX_FLIGHT_S = 86400.0
MAX_RATE_HZ = 10000.0
MAX_COLLECTIVE = 1.0e7
MAX_TILT_RAD = np.pi  # roll and pitch are Euler angles


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

    def mean_collective(self) -> float:
        """The mean of the four rotors' values over the accepted steps (omega^2 in kRPM^2, or the raw command)."""
        return self.sum_collective / max(self.n, 1)

    def mean_regime(self) -> np.ndarray:
        """(3,) mean of (1, roll, pitch) over the accepted steps."""
        return self.ftf[0] / max(self.n, 1)

    def within_cov(self) -> np.ndarray | None:
        """(4, 4) covariance of the 2-s block means within this flight, None below 3 blocks."""
        if self.n_blocks < 3:
            return None
        m = self.sum_block / self.n_blocks
        return (self.sum_block_outer - self.n_blocks * np.outer(m, m)) / (self.n_blocks - 1)

    def minus(self, earlier: FlightSummary) -> FlightSummary:
        """The steps after ``earlier`` (a ``Mark``'s sums of this flight, taken at a block's end)."""
        return FlightSummary(
            basis=self.basis,
            rate_hz=self.rate_hz,
            n=self.n - earlier.n,
            sum_share=self.sum_share - earlier.sum_share,
            ftf=self.ftf - earlier.ftf,
            fts=self.fts - earlier.fts,
            sum_collective=self.sum_collective - earlier.sum_collective,
            n_blocks=self.n_blocks - earlier.n_blocks,
            sum_block=self.sum_block - earlier.sum_block,
            sum_block_outer=self.sum_block_outer - earlier.sum_block_outer,
        )

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
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise ConfigError(f"{origin}: malformed flight summary: {exc!r}") from exc
        s.check(origin)
        return s

    def check(self, origin: str = "summary") -> None:
        """Raise ``ConfigError`` naming the first field no flight can produce. Each accepted step adds a share vector
        in [0, 4] that sums to 4, a regime (1, roll, pitch) with tilts within +-pi, and a positive collective; each
        2-s block, the mean of its steps' shares. The sums of n steps are bounded accordingly."""
        n, nb = self.n, self.n_blocks
        tol = 1e-6 * (max(n, 1) + 1.0)

        def bad(name: str, why: str):
            return ConfigError(f"{origin}: flight summary field {name}: {why}")

        if self.basis not in ("omega2", "command"):
            raise bad("basis", f"{self.basis!r} is neither 'omega2' nor 'command'")
        if not 0 < self.rate_hz <= MAX_RATE_HZ:
            raise bad("rate_hz", f"{self.rate_hz!r} is not in (0, {MAX_RATE_HZ:g}]")
        if not 0 <= n <= self.rate_hz * MAX_FLIGHT_S:
            raise bad("n", f"{n} steps is not in [0, {MAX_FLIGHT_S:g} s at {self.rate_hz:g} Hz]")
        for name in ("sum_share", "ftf", "fts", "sum_block", "sum_block_outer"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise bad(name, "holds a non-finite value")
        if not (np.isfinite(self.sum_collective) and 0 <= self.sum_collective <= MAX_COLLECTIVE * n):
            raise bad("sum_collective", f"{self.sum_collective!r} is not in [0, {MAX_COLLECTIVE:g} n] (n {n})")
        if np.any(self.sum_share < -tol) or np.any(self.sum_share > 4 * n + tol) or abs(self.sum_share.sum() - 4 * n) > tol:
            raise bad("sum_share", f"{self.sum_share.tolist()} is not n shares in [0, 4] summing to 4 (n {n})")
        t = MAX_TILT_RAD
        ftf, fts = self.ftf, self.fts
        if (
            abs(ftf[0, 0] - n) > tol
            or np.any(np.abs(ftf - ftf.T) > tol * t * t)
            or np.any(np.abs(ftf[0, 1:]) > t * n + tol)
            or np.any(np.diag(ftf)[1:] < -tol)
            or np.any(np.diag(ftf)[1:] > t * t * n + tol)
            or np.linalg.eigvalsh((ftf + ftf.T) / 2).min() < -tol * t * t  # a sum of f f^T
        ):
            raise bad("ftf", f"is not the regime sums of {n} steps with tilts within +-{t:.4g} rad")
        if (
            np.any(np.abs(fts[0] - self.sum_share) > tol)
            or np.any(np.abs(fts[1:]) > 4 * t * n + tol)
            or np.any(np.abs(fts.sum(axis=1) - 4 * ftf[0]) > tol * t)
        ):
            raise bad("fts", f"is not the regime-by-share sums of {n} steps")
        block = max(int(round(BLOCK_S * self.rate_hz)), 1)
        if not 0 <= nb * block <= n:
            raise bad("n_blocks", f"{nb} blocks of {block} steps do not fit in {n} steps")
        sb, sbo = self.sum_block, self.sum_block_outer
        btol = 1e-6 * (nb + 1.0)
        if np.any(sb < -btol) or np.any(sb > 4 * nb + btol) or abs(sb.sum() - 4 * nb) > btol:
            raise bad("sum_block", f"{sb.tolist()} is not {nb} block means in [0, 4] summing to 4")
        if (
            np.any(np.abs(sbo - sbo.T) > 16 * btol)
            or np.any(np.abs(sbo) > 16 * nb + btol)
            or abs(sbo.sum() - 16 * nb) > 16 * btol
            or np.linalg.eigvalsh((sbo + sbo.T) / 2 - np.outer(sb, sb) / max(nb, 1)).min() < -16 * btol  # a scatter
        ):
            raise bad("sum_block_outer", f"is not the outer products of {nb} block means")


@dataclass(frozen=True)
class Mark:
    """The sums at the end of a 2-s block: ``row`` is the first step fed after it (a table's row index)."""

    row: int
    summary: FlightSummary


class ShareAccumulator:
    """Builds a ``FlightSummary`` step by step (the daemon) or a table at a time (a log): identical sums and marks."""

    def __init__(self, basis: str, rate_hz: float) -> None:
        self.summary = FlightSummary(basis=basis, rate_hz=float(rate_hz))
        self.marks: list[Mark] = []
        self._settle = int(round(SETTLE_S * rate_hz))
        self._block = int(round(BLOCK_S * rate_hz))
        self._since_takeoff = 0
        self._rows = 0  # steps fed so far, accepted or not
        self._blk_n = 0
        self._blk_sum = np.zeros(4)

    def step(self, x: np.ndarray, roll_rad: float, pitch_rad: float, airborne: bool) -> bool:
        """One grid step: ``x`` (4,) omega^2 or command. Returns whether the step was accepted."""
        row = self._rows
        self._rows += 1
        if not airborne:
            self._since_takeoff = 0
            return False
        self._since_takeoff += 1
        x = np.asarray(x, dtype=np.float64)
        if self._since_takeoff <= self._settle or not np.all(np.isfinite(x) & (x >= 0)):
            return False
        roll_rad, pitch_rad = _tilt(roll_rad), _tilt(pitch_rad)
        mean = float(x.sum()) / len(x)  # np.mean's sum and division, without its per-call cost (every grid step)
        if not mean > 0:
            return False
        self._add(x[None, :] / mean, np.array([[1.0, roll_rad, pitch_rad]]), np.array([mean]), np.array([row]))
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
            ok &= np.all(np.isfinite(x) & (x >= 0), axis=1) & (mean > 0)
        rows = self._rows + np.nonzero(ok)[0]
        self._rows += len(x)
        if not ok.any():
            return
        s = x[ok] / mean[ok, None]
        f = np.column_stack([np.ones(int(ok.sum())), _tilt(np.asarray(roll_rad)[ok]), _tilt(np.asarray(pitch_rad)[ok])])
        self._add(s, f, mean[ok], rows)

    def _add(self, s: np.ndarray, f: np.ndarray, collective: np.ndarray, rows: np.ndarray) -> None:
        """Accepted steps ``s`` (shares), ``f`` (regimes), their collectives and the rows they were fed at, added in
        runs that end where a 2-s block of consecutive accepted steps ends (a block may span a landing: its steps
        are still this flight's); at each block's end, a ``Mark``."""
        sm = self.summary
        i = 0
        while i < len(s):
            take = min(self._block - self._blk_n, len(s) - i)
            si, fi = s[i : i + take], f[i : i + take]
            sm.n += take
            sm.sum_share = sm.sum_share + si.sum(axis=0)
            sm.ftf = sm.ftf + fi.T @ fi
            sm.fts = sm.fts + fi.T @ si
            sm.sum_collective += float(collective[i : i + take].sum())
            self._blk_sum = self._blk_sum + si.sum(axis=0)
            self._blk_n += take
            i += take
            if self._blk_n == self._block:
                m = self._blk_sum / self._block
                sm.n_blocks += 1
                sm.sum_block = sm.sum_block + m
                sm.sum_block_outer = sm.sum_block_outer + np.outer(m, m)
                self._blk_n, self._blk_sum = 0, np.zeros(4)
                # every field is replaced, never changed in place: a shallow copy keeps these sums
                self.marks.append(Mark(int(rows[i - 1]) + 1, replace(sm)))


def _tilt(a):
    """A tilt angle for the regime; unknown (a log without it, CrazyPAD's pitch) or not an Euler angle (beyond +-pi)
    reads 0: no tilt regime is learnt from it."""
    if isinstance(a, np.ndarray):
        a = np.nan_to_num(a, nan=0.0, posinf=0.0, neginf=0.0)
        return np.where(np.abs(a) <= MAX_TILT_RAD, a, 0.0)
    return float(a) if np.isfinite(a) and abs(a) <= MAX_TILT_RAD else 0.0


def rotor_values(table: FlightTable) -> tuple[np.ndarray, str]:
    """(T, 4) omega^2 in kRPM^2 where RPM is known on some airborne step, else the raw command; and the basis."""
    rpm = np.asarray(table.motor_rpm, dtype=np.float64)
    if np.any(table.airborne & np.all(np.isfinite(rpm), axis=1)):
        return (rpm / 1000.0) ** 2, "omega2"
    return np.asarray(table.motor_cmd, dtype=np.float64), "command"


def accumulate(table: FlightTable) -> ShareAccumulator:
    """The whole flight's summary (every airborne span of the log) and its block marks."""
    x, basis = rotor_values(table)
    acc = ShareAccumulator(basis, table.rate_hz)
    acc.table(x, table.roll_rad, table.pitch_rad, table.airborne)
    return acc


def summarize(table: FlightTable) -> FlightSummary:
    """The whole flight's summary (every airborne span of the log)."""
    return accumulate(table).summary
