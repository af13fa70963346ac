"""CSV logs through a named column mapping (``monitor/formats.yaml``) -> ``RawFlight``.

A mapping says, per signal, which column holds it (or that it is not
logged), in which unit, and with which sign/frame flip. Plain or gzip CSV,
streamed (time and memory follow the rows, not the file's size); a damaged
gzip stream, a cut-off last line or a tail of zeros or junk is read up to the
damage with a warning.
"""

from __future__ import annotations

import csv
import zlib
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from monitor.config import from_mapping, read_yaml
from monitor.errors import ConfigError, LogFormatError
from monitor.logs.mixers import MIXERS, mix
from monitor.logs.raw import DEFAULT_MIN_HEIGHT_M, RawFlight, Stream
from monitor.logs.units import M_S2_PER_G, RAD_PER_DEG, US_PER_MS, US_PER_S, V_PER_MV

FORMATS_FILE = Path(__file__).resolve().parent.parent / "formats.yaml"

# Unit -> factor into the project unit (rad, rad/s, V, m, m/s, m/s², µs).
TO_PROJECT = {
    "": 1.0,
    "rad": 1.0,
    "deg": RAD_PER_DEG,
    "rad_s": 1.0,
    "deg_s": RAD_PER_DEG,
    "V": 1.0,
    "mV": V_PER_MV,
    "m": 1.0,
    "m_s": 1.0,
    "m_s2": 1.0,
    "g": M_S2_PER_G,
    "us": 1.0,
    "ms": float(US_PER_MS),
    "s": float(US_PER_S),
}


@dataclass(frozen=True)
class ColumnSpec:
    column: str | None = None  # None: not logged in this layout
    unit: str = ""
    scale: float = 1.0  # sign / frame flip after the unit conversion
    required: bool = True  # a named column missing from the file is an error unless False

    def __post_init__(self) -> None:
        if self.unit not in TO_PROJECT:
            raise ConfigError(f"unit: unknown unit {self.unit!r} (known: {', '.join(sorted(TO_PROJECT))})")


_NONE = ColumnSpec()


@dataclass(frozen=True)
class MixerSpec:
    """Motor commands rebuilt from logged controller outputs (``monitor.logs.mixers``)."""

    kind: str = ""  # "": no mixer; else one of monitor.logs.mixers.MIXERS
    thrust: str = ""  # column names of the controller's outputs, firmware units
    roll: str = ""
    pitch: str = ""
    yaw: str = ""
    # For PX4 rotors 1..4, which mixer output (1-based, the vehicle's own numbering) drives it.
    outputs_to_px4: tuple[int, int, int, int] = (1, 2, 3, 4)

    def __post_init__(self) -> None:
        if self.kind and self.kind not in MIXERS:
            raise ConfigError(f"mixer.kind: unknown mixer {self.kind!r} (known: {', '.join(MIXERS)})")
        if self.kind and not all((self.thrust, self.roll, self.pitch, self.yaw)):
            raise ConfigError("mixer: thrust, roll, pitch and yaw columns are all needed")
        if sorted(self.outputs_to_px4) != [1, 2, 3, 4]:
            raise ConfigError(f"mixer.outputs_to_px4: must be a permutation of 1..4, got {list(self.outputs_to_px4)}")

    def columns(self) -> list[str]:
        return [self.thrust, self.roll, self.pitch, self.yaw] if self.kind else []


@dataclass(frozen=True)
class CsvFormat:
    description: str
    time: ColumnSpec
    cmd_unit: str
    motors: tuple[str | None, str | None, str | None, str | None]
    motor_names: tuple[str, str, str, str]
    roll: ColumnSpec
    pitch: ColumnSpec
    yaw: ColumnSpec
    roll_rate: ColumnSpec
    pitch_rate: ColumnSpec
    yaw_rate: ColumnSpec
    battery: ColumnSpec = _NONE
    armed: ColumnSpec = _NONE
    height: ColumnSpec = _NONE
    acc_x: ColumnSpec = _NONE
    acc_y: ColumnSpec = _NONE
    acc_z: ColumnSpec = _NONE
    vel_n: ColumnSpec = _NONE
    vel_e: ColumnSpec = _NONE
    vel_d: ColumnSpec = _NONE
    pos_n: ColumnSpec = _NONE
    pos_e: ColumnSpec = _NONE
    pos_d: ColumnSpec = _NONE
    # Optional second set of motor columns (PX4 order), e.g. the PWM applied after battery
    # compensation: FlightTable.extras["motor_cmd_applied"], same unit as ``motors``.
    motors_applied: tuple[str, str, str, str] | None = None
    # Where no motor command is logged: rebuild it from the controller's outputs.
    mixer: MixerSpec = MixerSpec()
    # World-frame acceleration (NED after scale), e.g. an estimator's: FlightTable.extras["accel_ned_m_s2"].
    acc_world_n: ColumnSpec = _NONE
    acc_world_e: ColumnSpec = _NONE
    acc_world_d: ColumnSpec = _NONE
    min_height_m: float = DEFAULT_MIN_HEIGHT_M
    delimiter: str = ","

    def __post_init__(self) -> None:
        if self.cmd_unit not in ("us", "cf16"):
            raise ConfigError(f"cmd_unit: must be 'us' or 'cf16', got {self.cmd_unit!r}")
        if self.time.column is None:
            raise ConfigError("time.column: a CSV format needs a time column")
        if self.time.unit not in ("us", "ms", "s"):
            raise ConfigError(f"time.unit: must be us, ms or s, got {self.time.unit!r}")

    def required_columns(self) -> list[str]:
        """Columns that must be in the file: time, motors, and every signal not marked ``required: false``."""
        specs = [getattr(self, f.name) for f in fields(self)]
        out = [self.time.column] + [m for m in self.motors if m] + self.mixer.columns()
        out += [c.column for c in specs if isinstance(c, ColumnSpec) and c.column and c.required]
        return list(dict.fromkeys(out))


_LOADED_FORMATS: dict[tuple[str, bytes], dict[str, CsvFormat]] = {}  # (path, its bytes) -> its formats (frozen)


def load_formats(path: str | Path = FORMATS_FILE) -> dict[str, CsvFormat]:
    """The formats in ``path``: parsed once per content of the file (one CSV read asks for them up to four times,
    and parsing the YAML costs more than reading a short log)."""
    try:
        key = (str(Path(path).resolve()), Path(path).read_bytes())
    except OSError:  # read_yaml says why, naming the file
        key = None
    if key in _LOADED_FORMATS:
        return dict(_LOADED_FORMATS[key])
    data = read_yaml(path)
    out = {}
    for name, spec in data.items():
        if not isinstance(spec, dict):
            raise ConfigError(f"{path}: format {name!r} must be a mapping")
        out[name] = _build_format(spec, f"{path}: {name}")
    if key is not None:
        if len(_LOADED_FORMATS) >= 8:
            _LOADED_FORMATS.clear()
        _LOADED_FORMATS[key] = out
    return dict(out)


def _build_format(spec: dict, origin: str) -> CsvFormat:
    # The loader builds nested dataclasses from mappings; ColumnSpec fields are mappings.
    return from_mapping(CsvFormat, spec, origin=origin)[0]


def get_format(name: str, path: str | Path = FORMATS_FILE) -> CsvFormat:
    formats = load_formats(path)
    if name not in formats:
        raise LogFormatError(f"unknown CSV format {name!r}; known: {', '.join(sorted(formats))} (in {path})")
    return formats[name]


READ_CHUNK_BYTES = 1 << 16
# A line longer than this is not a log row (PX4 / CrazyPAD rows are a few hundred bytes): the file's junk tail.
MAX_LINE_BYTES = 1 << 16


def _chunks(path: Path) -> tuple[list[str], object]:
    """(damage warnings, an iterator of byte chunks): plain or gzip, decompressed as it is read, so a huge file
    costs what its lines cost. A gzip stream cut short or corrupt ends the chunks with a warning."""
    damage: list[str] = []

    def plain(fh):
        while chunk := fh.read(READ_CHUNK_BYTES):
            yield chunk

    def gunzip(fh):
        d = zlib.decompressobj(wbits=31)
        while raw := fh.read(READ_CHUNK_BYTES):
            try:
                out = d.decompress(raw, READ_CHUNK_BYTES)
                while True:
                    if out:
                        yield out
                    if not d.unconsumed_tail:
                        break
                    out = d.decompress(d.unconsumed_tail, READ_CHUNK_BYTES)
            except zlib.error as exc:
                damage.append(f"{path.name}: corrupt gzip data ({exc}): read up to the damage")
                return
            if d.eof:
                return
        if not d.eof:
            damage.append(f"{path.name}: gzip stream ends early: read up to the damage")

    def chunks():
        with open(path, "rb") as fh:
            gz = fh.read(2) == b"\x1f\x8b"
            fh.seek(0)
            yield from (gunzip if gz else plain)(fh)

    return damage, chunks()


def _lines(path: Path, damage: list[str], chunks) -> object:
    """Text lines of the file, streamed; stops at the first line holding a NUL byte or longer than
    ``MAX_LINE_BYTES`` (a zero-filled or junk tail), with a warning saying where."""
    pending = b""
    offset = 0  # bytes of (decompressed) text before ``pending``
    for chunk in chunks:
        pending += chunk
        *complete, pending = pending.split(b"\n")
        for line in complete:
            if b"\x00" in line or len(line) > MAX_LINE_BYTES:
                damage.append(f"{path.name}: zeros or junk from byte {offset} on: cut there (read up to it)")
                return
            offset += len(line) + 1
            yield line.decode("utf-8", errors="replace")
        if len(pending) > MAX_LINE_BYTES or b"\x00" in pending:
            damage.append(f"{path.name}: zeros or junk from byte {offset} on: cut there (read up to it)")
            return
    if pending:
        yield pending.decode("utf-8", errors="replace")


def _parse(path: Path, delimiter: str) -> tuple[list[str], np.ndarray, list[str]]:
    """Header, rows and warnings (damage first), the file streamed line by line."""
    damage, chunks = _chunks(path)
    reader = csv.reader(_lines(path, damage, chunks), delimiter=delimiter)
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise LogFormatError(f"{path}: empty CSV file" if not damage else f"{path}: {damage[0]}") from None
    except csv.Error as exc:  # binary junk: a bare CR inside a field
        raise LogFormatError(f"{path}: not a CSV file: {exc}") from None
    rows, bad = [], 0
    while True:
        try:
            row = next(reader)
        except StopIteration:
            break
        except csv.Error:  # one damaged line: skipped like a malformed row
            bad += 1
            continue
        if len(row) != len(header):
            bad += 1
            continue
        try:
            rows.append([float(v) if v.strip() else np.nan for v in row])
        except ValueError:
            bad += 1
    warnings = list(damage)
    if bad:
        warnings.append(f"{path.name}: {bad} malformed row(s) skipped (truncated or corrupted)")
    return header, np.array(rows, dtype=np.float64).reshape(-1, len(header)), warnings


def read_csv(path: str | Path, fmt: str | CsvFormat, formats_path: str | Path = FORMATS_FILE) -> RawFlight:
    path = Path(path)
    spec = get_format(fmt, formats_path) if isinstance(fmt, str) else fmt
    name = fmt if isinstance(fmt, str) else _name(spec, formats_path)  # for messages: found once
    if not path.is_file():
        raise LogFormatError(f"{path}: no such file")
    header, data, warnings = _parse(path, spec.delimiter)
    missing = [c for c in spec.required_columns() if c not in header]
    if missing:
        hint = _matching_formats(header, formats_path)
        raise LogFormatError(
            f"{path}: columns {missing} needed by format {name!r} are missing"
            + (f"; the header fits format(s) {hint}" if hint else "")
        )
    if len(data) == 0:
        raise LogFormatError(f"{path}: no data rows")
    col = {h: i for i, h in enumerate(header)}

    def values(cs: ColumnSpec, what: str) -> np.ndarray:
        if cs.column is None or cs.column not in col:
            if cs.column is not None:
                warnings.append(f"{what} ({cs.column}) not in this file: unknown")
            return np.full(len(data), np.nan)
        return data[:, col[cs.column]] * TO_PROJECT[cs.unit] * cs.scale

    t_us = np.round(data[:, col[spec.time.column]] * TO_PROJECT[spec.time.unit]).astype(np.int64)
    for what in ("roll", "pitch", "yaw", "roll_rate", "pitch_rate", "yaw_rate"):
        if getattr(spec, what).column is None:
            warnings.append(f"{what} is not logged in format {name!r}")
    motors = np.stack([data[:, col[m]] if m else np.full(len(data), np.nan) for m in spec.motors], axis=1)
    if not any(spec.motors) and spec.mixer.kind:
        mx = spec.mixer
        own = mix(mx.kind, *(data[:, col[c]] for c in mx.columns()))
        motors = own[:, [k - 1 for k in mx.outputs_to_px4]]
        warnings.append(f"motor commands rebuilt from {', '.join(mx.columns())} with the {mx.kind} mixer (not logged)")
    elif not any(spec.motors):
        warnings.append(f"motor commands are not logged in format {name!r}")

    def opt(*specs: ColumnSpec) -> Stream | None:
        if all(s.column is None or s.column not in col for s in specs):
            return None
        v = np.stack([values(s, s.column or "") for s in specs], axis=1)
        return Stream.build(t_us, v if len(specs) > 1 else v[:, 0])

    extra = {}
    if spec.motors_applied and all(m in col for m in spec.motors_applied):
        extra["motor_cmd_applied"] = Stream.build(t_us, np.stack([data[:, col[m]] for m in spec.motors_applied], axis=1))
    acc_world = opt(spec.acc_world_n, spec.acc_world_e, spec.acc_world_d)
    if acc_world is not None:
        extra["accel_ned_m_s2"] = acc_world
    height = opt(spec.height)
    if height is not None:
        height = Stream(height.t_us, height.values - height.values[0])
    return RawFlight(
        source=str(path),
        cmd_unit=spec.cmd_unit,
        motor_cmd=Stream.build(t_us, motors),
        attitude_rad=Stream.build(
            t_us, np.stack([values(spec.roll, "roll"), values(spec.pitch, "pitch"), values(spec.yaw, "yaw")], axis=1)
        ),
        rates_rad_s=Stream.build(
            t_us,
            np.stack(
                [values(spec.roll_rate, "roll_rate"), values(spec.pitch_rate, "pitch_rate"), values(spec.yaw_rate, "yaw_rate")],
                axis=1,
            ),
        ),
        battery_v=opt(spec.battery),
        armed=opt(spec.armed),
        height_m=height,
        accel_frd_m_s2=opt(spec.acc_x, spec.acc_y, spec.acc_z),
        vel_ned_m_s=opt(spec.vel_n, spec.vel_e, spec.vel_d),
        pos_ned_m=opt(spec.pos_n, spec.pos_e, spec.pos_d),
        motor_names=spec.motor_names,
        extra_streams=extra,
        min_height_m=spec.min_height_m,
        warnings=warnings,
    )


def _name(spec: CsvFormat, formats_path) -> str:
    for name, s in load_formats(formats_path).items():
        if s == spec:
            return name
    return spec.description


def _matching_formats(header: list[str], formats_path) -> list[str]:
    return [n for n, s in load_formats(formats_path).items() if all(c in header for c in s.required_columns())]
