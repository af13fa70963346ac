"""``VehicleBaseline``: one vehicle's healthy history in one JSON format (``B.json``; ``DIR/baseline.json``).

::

    {"format": "propwatch-vehicle-baseline", "version": 1,
     "vehicle": {"id": "uid:0x...", "id_source": "tlog AUTOPILOT_VERSION uid", "motor_names": ["1","2","3","4"],
                 "basis": "omega2", "cg_damage_separable": null | true | false},
     "epoch": 2,                         # restarts so far (a maintenance event that changes the airframe)
     "flights": [{"name": "flight_03.tlog", "date": "2026-05-01" | null, "epoch": 2,
                  "source": "declared" | "no fault", "summary": {...monitor.memory.summary},
                  "excluded": "why" (only where a flight that raised nothing proved unlike the others)}, ...],
     "events": [{"event": "props-replaced", "date": "2026-05-04", "epoch": 2}, ...]}

The normal is computed from the flights of the current epoch (``active``); earlier ones stay as history. Saving is
atomic (a temporary file, fsync, rename): a power cut mid-write leaves the old file or the new one, never half.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from monitor.errors import ConfigError
from monitor.memory.normal import Normal, normal_of
from monitor.memory.summary import FlightSummary

FORMAT = "propwatch-vehicle-baseline"
VERSION = 1
MIN_FLIGHTS = 3  # healthy flights before a vehicle's normal is used (a spread needs at least two)
BASELINE_FILE = "baseline.json"
# Maintenance events; True where the event changes the airframe, so the normal restarts from the next flight.
EVENTS = {
    "props-replaced": True,
    "motor-replaced": True,
    "esc-replaced": True,
    "payload-changed": True,
    "frame-repaired": True,
    "battery-replaced": False,
    "firmware-updated": False,
    "inspected": False,
}


class BaselineError(ConfigError):
    """A baseline that cannot be used: unreadable, another vehicle's, from a future version, too few flights."""


@dataclass
class VehicleBaseline:
    vehicle_id: str | None
    id_source: str | None
    motor_names: tuple[str, str, str, str]
    basis: str
    epoch: int = 0
    flights: list[dict] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)
    # Whether this kind of airframe's flights tell a CG offset toward a rotor from damage on it: False where measured
    # not to (CrazyPAD: offline/crazypad/README.md), None where nobody measured it. False turns a propeller verdict
    # into an imbalance near its rotors, never a confident fault.
    cg_damage_separable: bool | None = None

    # -- the history
    def active(self) -> list[dict]:
        """The flights the normal rests on: this epoch's, less those set aside as unlike the others (``excluded``)."""
        return [f for f in self.flights if f["epoch"] == self.epoch and not f.get("excluded")]

    def summaries(self) -> list[FlightSummary]:
        return [FlightSummary.from_dict(f["summary"], f"flight {f['name']}") for f in self.active()]

    @property
    def ready(self) -> bool:
        return len(self.active()) >= MIN_FLIGHTS

    def normal(self) -> Normal:
        if not self.ready:
            raise BaselineError(f"baseline of {self.vehicle_id}: {len(self.active())} of {MIN_FLIGHTS} healthy flights")
        return normal_of(self.summaries())

    def compared_with(self) -> dict:
        """{"flights", "first", "last"}: the flights the normal rests on and their dates (None where unknown)."""
        dates = sorted(f["date"] for f in self.active() if f.get("date"))
        return {"flights": len(self.active()), "first": dates[0] if dates else None, "last": dates[-1] if dates else None}

    def compared_with_text(self) -> str:
        c = self.compared_with()
        when = f", {c['first']} to {c['last']}" if c["first"] else ", dates unknown"
        return f"against {c['flights']} healthy flights of this vehicle{when}"

    def add(self, name: str, date: str | None, summary: FlightSummary, source: str) -> None:
        if summary.basis != self.basis:
            raise BaselineError(f"{name}: its shares are {summary.basis}, the baseline's {self.basis}")
        self.flights.append({"name": name, "date": date, "epoch": self.epoch, "source": source, "summary": summary.to_dict()})

    def note(self, event: str, date: str | None) -> bool:
        """Record a maintenance event; True where it restarted the normal."""
        if event not in EVENTS:
            raise BaselineError(f"unknown event {event!r}; known: {', '.join(EVENTS)}")
        if EVENTS[event]:
            self.epoch += 1
        self.events.append({"event": event, "date": date, "epoch": self.epoch})
        return EVENTS[event]

    def check_vehicle(self, vehicle_id: str | None, motor_names, basis: str, origin: str) -> None:
        """Raise naming ``origin`` where a flight is not of this vehicle (identity or geometry)."""
        if vehicle_id is not None and self.vehicle_id is not None and vehicle_id != self.vehicle_id:
            raise BaselineError(f"{origin}: vehicle {vehicle_id}, but the baseline is of vehicle {self.vehicle_id}")
        if tuple(motor_names) != tuple(self.motor_names) or basis != self.basis:
            raise BaselineError(
                f"{origin}: rotors {list(motor_names)} on {basis} shares, but the baseline's are "
                f"{list(self.motor_names)} on {self.basis} (another airframe)"
            )

    # -- the file
    def to_dict(self) -> dict:
        return {
            "format": FORMAT,
            "version": VERSION,
            "vehicle": {
                "id": self.vehicle_id,
                "id_source": self.id_source,
                "motor_names": list(self.motor_names),
                "basis": self.basis,
                "cg_damage_separable": self.cg_damage_separable,
            },
            "epoch": self.epoch,
            "flights": self.flights,
            "events": self.events,
        }

    @classmethod
    def from_dict(cls, d: dict, origin: str) -> VehicleBaseline:
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise BaselineError(
                f"{origin}: not a propwatch vehicle baseline (format {d.get('format') if isinstance(d, dict) else None!r})"
            )
        if not isinstance(d.get("version"), int) or d["version"] > VERSION:
            raise BaselineError(f"{origin}: baseline version {d.get('version')!r} is newer than this propwatch reads ({VERSION})")
        try:
            v = d["vehicle"]
            b = cls(
                vehicle_id=None if v["id"] is None else str(v["id"]),
                id_source=None if v.get("id_source") is None else str(v["id_source"]),
                motor_names=tuple(str(x) for x in v["motor_names"]),
                basis=str(v["basis"]),
                epoch=int(d["epoch"]),
                flights=list(d["flights"]),
                events=list(d["events"]),
                cg_damage_separable=None if v.get("cg_damage_separable") is None else bool(v["cg_damage_separable"]),
            )
            if len(b.motor_names) != 4:
                raise ValueError(f"motor_names: 4 rotors, got {len(b.motor_names)}")
            for f in b.flights:
                FlightSummary.from_dict(f["summary"], f"{origin}: flight {f.get('name')}")
                int(f["epoch"])
        except (KeyError, TypeError, ValueError) as exc:
            raise BaselineError(f"{origin}: corrupt vehicle baseline: {exc!r}") from exc
        except ConfigError as exc:  # a flight's summary
            raise BaselineError(f"corrupt vehicle baseline: {exc}") from exc
        return b

    def save(self, path: str | Path) -> Path:
        return write_atomic(Path(path), json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> VehicleBaseline:
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise BaselineError(f"{path}: cannot read the vehicle baseline: {exc}") from exc
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise BaselineError(f"{path}: corrupt vehicle baseline (not JSON: {exc})") from exc
        return cls.from_dict(d, str(path))


def write_atomic(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` so that a crash leaves either the old file or the new one."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def is_vehicle_baseline(path: str | Path) -> bool:
    """Whether ``path`` holds this format (an older adapt folder's ``baseline.json`` does not)."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8")).get("format") == FORMAT
    except (OSError, ValueError, AttributeError):
        return True  # unreadable: let VehicleBaseline.load say why
