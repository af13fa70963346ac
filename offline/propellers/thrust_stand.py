"""Read RCbenchmark / Tyto thrust-stand CSV exports and fit the propeller constants from them.

The exports (series 1520 and 1580, "StepsTest" and ramp tests) have a header
row of ``Name (unit)`` columns. Quirks handled here, the one place they are:
- encodings: UTF-8 with a byte-order mark, or Latin-1 (``µ`` as one byte);
- line endings: LF, CRLF or old-Mac CR;
- units: thrust in gf, kgf, N, lbf or ozf; torque in N·m (``N·m``, ``N.m``,
  ``Nm``) or ozf·in; every value becomes SI on reading;
- RPM: the optical sensor when it reads (non-zero), else the electrical one
  (pole count set in the stand software); both zero means no RPM (``None``);
- the 1520 has no torque channel (``torque_nm is None``).

A file without a needed column, with a unit we do not know, or whose time goes
backwards raises ``LogFormatError`` naming the file and the column. Real 1580
exports repeat a time, or stamp their first sample a few ms after the second
(``StepsTest202306052008``: 0.114 s then 0.107 s); steps back of at most
``TIME_JITTER_S`` are that timestamp jitter and are kept in file order.
"""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.errors import LogFormatError
from monitor.esc import RAD_S_PER_RPM, EscCurve
from monitor.vehicle import GRAVITY_M_S2

THRUST_UNITS_TO_N = {"gf": GRAVITY_M_S2 / 1000.0, "kgf": GRAVITY_M_S2, "N": 1.0, "lbf": 4.4482216152605, "ozf": 0.27801385095378}
TORQUE_UNITS_TO_NM = {"N·m": 1.0, "N.m": 1.0, "Nm": 1.0, "N m": 1.0, "ozf·in": 0.00706155183333, "ozf.in": 0.00706155183333}
TIME_JITTER_S = 0.05
_HEADER = re.compile(r"^(?P<name>.*?)\s*\((?P<unit>[^)]*)\)\s*$")


@dataclass(frozen=True)
class ThrustStandRun:
    """One export, SI units, rows in file order. Optional channels are None when the stand lacks them."""

    path: str
    time_s: np.ndarray
    esc_us: np.ndarray
    thrust_n: np.ndarray
    torque_nm: np.ndarray | None
    rpm: np.ndarray | None
    voltage_v: np.ndarray | None
    current_a: np.ndarray | None

    @property
    def omega_rad_s(self) -> np.ndarray | None:
        return None if self.rpm is None else self.rpm * RAD_S_PER_RPM


def _decode(raw: bytes) -> str:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return text.lstrip("\ufeff")


def _columns(header: list[str]) -> dict[str, tuple[int, str]]:
    """``{name: (index, unit)}``; a column without ``(unit)`` gets unit ''."""
    cols: dict[str, tuple[int, str]] = {}
    for i, h in enumerate(header):
        h = h.strip()
        if not h:
            continue
        m = _HEADER.match(h)
        name, unit = (m["name"], m["unit"].strip()) if m else (h, "")
        cols.setdefault(name.strip(), (i, unit.replace("\u00b5", "µ").replace("\u03bc", "µ")))
    return cols


def _column(path: Path, rows: list[list[str]], cols: dict, name: str, required: bool) -> tuple[np.ndarray, str] | None:
    if name not in cols:
        if required:
            raise LogFormatError(f"{path}: missing column {name!r} (has: {', '.join(cols)})")
        return None
    idx, unit = cols[name]
    values = np.full(len(rows), np.nan)
    for r, row in enumerate(rows):
        cell = row[idx].strip() if idx < len(row) else ""
        if cell:
            try:
                values[r] = float(cell)
            except ValueError:
                raise LogFormatError(f"{path}: column {name!r} row {r + 2}: not a number: {cell!r}") from None
    return values, unit


def _convert(path: Path, name: str, values: np.ndarray, unit: str, table: dict[str, float]) -> np.ndarray:
    if unit not in table:
        raise LogFormatError(f"{path}: column {name!r}: unknown unit {unit!r} (known: {', '.join(table)})")
    return values * table[unit]


def _expect_unit(path: Path, name: str, unit: str, allowed: tuple[str, ...]) -> None:
    if unit not in allowed:
        raise LogFormatError(f"{path}: column {name!r}: unknown unit {unit!r} (expected {' or '.join(allowed)})")


def read_thrust_stand_csv(path: str | Path) -> ThrustStandRun:
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    # splitlines() accepts CR, LF and CRLF alike.
    rows = list(csv.reader(io.StringIO("\n".join(_decode(raw).splitlines()))))
    rows = [r for r in rows if any(c.strip() for c in r)]
    if len(rows) < 2:
        raise LogFormatError(f"{path}: no data rows under the header")
    cols = _columns(rows[0])
    data = rows[1:]

    time_s, unit = _column(path, data, cols, "Time", True)
    _expect_unit(path, "Time", unit, ("s",))
    esc_us, unit = _column(path, data, cols, "ESC signal", True)
    _expect_unit(path, "ESC signal", unit, ("µs", "us"))
    values, unit = _column(path, data, cols, "Thrust", True)
    thrust_n = _convert(path, "Thrust", values, unit, THRUST_UNITS_TO_N)
    torque = _column(path, data, cols, "Torque", False)
    torque_nm = None if torque is None else _convert(path, "Torque", torque[0], torque[1], TORQUE_UNITS_TO_NM)

    for name, arr in (("Time", time_s), ("ESC signal", esc_us), ("Thrust", thrust_n)):
        if not np.all(np.isfinite(arr)):
            raise LogFormatError(
                f"{path}: column {name!r}: empty or non-finite value at row {int(np.argmin(np.isfinite(arr))) + 2}"
            )
    back = np.flatnonzero(np.diff(time_s) < -TIME_JITTER_S)
    if back.size:
        raise LogFormatError(
            f"{path}: column 'Time': time goes backwards at row {back[0] + 3} ({time_s[back[0]]} s -> {time_s[back[0] + 1]} s)"
        )

    rpm = None
    for name in ("Motor Optical Speed", "Motor Electrical Speed"):
        col = _column(path, data, cols, name, False)
        if col is None:
            continue
        _expect_unit(path, name, col[1], ("RPM", "rpm"))
        if np.nanmax(np.abs(col[0]), initial=0.0) > 0:
            rpm = col[0]
            break
    extras = {}
    for name, unit_ok in (("Voltage", ("V",)), ("Current", ("A",))):
        col = _column(path, data, cols, name, False)
        if col is not None:
            _expect_unit(path, name, col[1], unit_ok)
        extras[name] = None if col is None else col[0]
    return ThrustStandRun(str(path), time_s, esc_us, thrust_n, torque_nm, rpm, extras["Voltage"], extras["Current"])


@dataclass(frozen=True)
class Fit:
    """A least-squares fit and its quality on the points it was fitted to."""

    coefficients: tuple[float, ...]
    r2: float
    rmse: float
    n_points: int


def _quality(y: np.ndarray, y_hat: np.ndarray) -> tuple[float, float]:
    ss_res = float(np.sum((y - y_hat) ** 2))
    ss_tot = float(np.sum((y - np.mean(y)) ** 2))
    return (1.0 - ss_res / ss_tot if ss_tot > 0 else math.nan), math.sqrt(ss_res / y.size)


def _spinning(run: ThrustStandRun) -> np.ndarray:
    if run.rpm is None:
        raise LogFormatError(f"{run.path}: column 'Motor Optical Speed'/'Motor Electrical Speed': no RPM measured")
    return np.isfinite(run.rpm) & (run.rpm > 0)


def fit_esc_to_rpm(run: ThrustStandRun) -> Fit:
    """``rpm = a·esc² + b·esc + c`` over the rows where the motor spins (the paper's Sec. IV form)."""
    m = _spinning(run)
    if m.sum() < 3:
        raise LogFormatError(f"{run.path}: column 'ESC signal': fewer than 3 spinning rows to fit")
    x, y = run.esc_us[m], run.rpm[m]
    coef = np.polyfit(x, y, 2)
    return Fit(tuple(float(c) for c in coef), *_quality(y, np.polyval(coef, x)), int(m.sum()))


def esc_curve_from_fit(fit: Fit, cmd_min: float = 1000.0, cmd_max: float = 2000.0) -> EscCurve:
    a, b, c = fit.coefficients
    return EscCurve(a, b, c, cmd_min, cmd_max)


def _fit_through_origin(path: str, column: str, omega: np.ndarray, y: np.ndarray) -> Fit:
    """``y = k·ω²``: the paper's Eqs. (2), (3)."""
    if y.size < 2:
        raise LogFormatError(f"{path}: column {column!r}: fewer than 2 spinning rows to fit")
    w2 = omega**2
    k = float(np.sum(w2 * y) / np.sum(w2 * w2))
    return Fit((k,), *_quality(y, k * w2), int(y.size))


def fit_kf(run: ThrustStandRun) -> Fit:
    """Thrust coefficient kF (N per (rad/s)²)."""
    m = _spinning(run) & np.isfinite(run.thrust_n)
    return _fit_through_origin(run.path, "Thrust", run.omega_rad_s[m], run.thrust_n[m])


def fit_ktau(run: ThrustStandRun) -> Fit:
    """Drag-torque coefficient kτ (N·m per (rad/s)²). Sign-free: stands report either spin direction."""
    if run.torque_nm is None:
        raise LogFormatError(f"{run.path}: column 'Torque': this stand has no torque channel")
    m = _spinning(run) & np.isfinite(run.torque_nm)
    return _fit_through_origin(run.path, "Torque", run.omega_rad_s[m], np.abs(run.torque_nm[m]))


def noise_at_rest(run: ThrustStandRun, esc_below_us: float = 1060.0) -> tuple[float, float | None]:
    """Standard deviation of thrust (N) and torque (N·m) while the motor is stopped: the stand's noise floor.

    Used to check the virtual load cell's sensor-noise defaults against a real stand.
    """
    m = run.esc_us <= esc_below_us
    if m.sum() < 10:
        raise LogFormatError(f"{run.path}: column 'ESC signal': fewer than 10 rows at or below {esc_below_us} µs")
    torque = None if run.torque_nm is None else float(np.std(run.torque_nm[m]))
    return float(np.std(run.thrust_n[m])), torque
