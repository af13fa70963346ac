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
atomic (``monitor.memory.atomic``): a power cut mid-write leaves the old file or the new one, never half. Reading
checks every field against what a flight can produce (``FlightSummary.check``) and names the first bad one; a file's
version is handled in one place (``file_version``, ``READERS``).
"""

from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass, field
from pathlib import Path

from monitor.errors import ConfigError
from monitor.memory.atomic import write_atomic
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


class BaselineNewerError(BaselineError):
    """A baseline written by a newer propwatch: kept as it is, never read or replaced by this one."""


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
    # Each flight's summary, checked once (``summary_of``): id of its flight's dict -> (that dict, its summary).
    _checked: dict = field(default_factory=dict, repr=False, compare=False)

    # -- the history
    def active(self) -> list[dict]:
        """The flights the normal rests on: this epoch's, less those set aside as unlike the others (``excluded``)."""
        return [f for f in self.flights if f["epoch"] == self.epoch and not f.get("excluded")]

    def summary_of(self, f: dict) -> FlightSummary:
        """One of ``flights``' summary, read and checked once for the life of this object."""
        hit = self._checked.get(id(f))
        if hit is None or hit[0] is not f:
            hit = self._checked[id(f)] = (f, FlightSummary.from_dict(f["summary"], f"flight {f['name']}"))
        return hit[1]

    def summaries(self) -> list[FlightSummary]:
        return [self.summary_of(f) for f in self.active()]

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
        """A baseline from its JSON object, every field checked (``BaselineError`` naming the first bad one); a file
        of another version goes through ``READERS`` (``BaselineNewerError`` where newer than ``VERSION``)."""
        return READERS[file_version(d, origin)](d, origin)

    def save(self, path: str | Path) -> Path:
        return write_atomic(Path(path), self.to_text())

    def to_text(self) -> str:
        """The file's text: one line per field, per flight and per event (json's C encoder: a landing rewrites
        every flight)."""

        def one(x) -> str:
            return json.dumps(x, allow_nan=False)

        def lines(items: list) -> str:
            return "[\n" + ",\n".join(f"  {one(x)}" for x in items) + "\n ]" if items else "[]"

        d = self.to_dict()
        body = ",\n".join(f" {one(k)}: {lines(v) if k in ('flights', 'events') else one(v)}" for k, v in d.items())
        return "{\n" + body + "\n}\n"

    @classmethod
    def from_text(cls, text: str, origin: str) -> VehicleBaseline:
        try:
            d = json.loads(text)
        except (ValueError, RecursionError) as exc:  # JSONDecodeError is a ValueError
            raise BaselineError(f"{origin}: corrupt vehicle baseline (not JSON: {str(exc)[:200]})") from exc
        return cls.from_dict(d, origin)

    @classmethod
    def load(cls, path: str | Path) -> VehicleBaseline:
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise BaselineError(f"{path}: cannot read the vehicle baseline: {exc}") from exc
        return cls.from_text(text, str(path))


# -- reading a file, one version at a time -------------------------------------------------------------------------


def file_version(d, origin: str) -> int:
    """The version of a baseline's JSON object: one this propwatch reads (a key of ``READERS``), else raise."""
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise BaselineError(
            f"{origin}: not a propwatch vehicle baseline (format {d.get('format') if isinstance(d, dict) else None!r})"
        )
    version = d.get("version")
    if type(version) is not int or version < 1:
        raise BaselineError(f"{origin}: field version: {version!r} is not a baseline version")
    if version > VERSION:
        raise BaselineNewerError(f"{origin}: baseline version {version} is newer than this propwatch reads ({VERSION})")
    if version not in READERS:
        raise BaselineError(f"{origin}: baseline version {version} is no longer read (this propwatch reads {sorted(READERS)})")
    return version


class _Fields:
    """Typed access to a JSON object's fields; each failure names the field (``flights[2].epoch``)."""

    def __init__(self, origin: str) -> None:
        self.origin = origin

    def fail(self, where: str, why: str) -> BaselineError:
        return BaselineError(f"{self.origin}: field {where}: {why}")

    def get(self, d, key: str, where: str, kinds: tuple, optional: bool = False):
        if not isinstance(d, dict):
            raise self.fail(where.rpartition(".")[0] or where, f"not an object ({type(d).__name__})")
        if key not in d:
            if optional:
                return None
            raise self.fail(where, "missing")
        x = d[key]
        if optional and x is None:
            return None
        if not any(type(x) is k for k in kinds):  # bool is not an int here
            raise self.fail(where, f"{_short(x)} is not {' or '.join(k.__name__ for k in kinds)}")
        return x

    def date(self, d, key: str, where: str) -> str | None:
        x = self.get(d, key, where, (str,), optional=True)
        if x is not None:
            try:
                _dt.date.fromisoformat(x)
            except ValueError:
                raise self.fail(where, f"{_short(x)} is not a date (YYYY-MM-DD)") from None
        return x

    def epoch(self, d, where: str, last: int) -> int:
        e = self.get(d, "epoch", where, (int,))
        if not 0 <= e <= last:
            raise self.fail(where, f"{e} is not in [0, {last}] (the baseline's epoch)")
        return e


def _short(x) -> str:
    r = repr(x)
    return r if len(r) <= 60 else r[:57] + "..."


SOURCES = ("declared", "no fault")  # a flight the operator declared healthy; one that raised nothing in the daemon


def _read_v1(d: dict, origin: str) -> VehicleBaseline:
    f = _Fields(origin)
    v = f.get(d, "vehicle", "vehicle", (dict,))
    vid = f.get(v, "id", "vehicle.id", (str,), optional=True)
    id_source = f.get(v, "id_source", "vehicle.id_source", (str,), optional=True)
    names = f.get(v, "motor_names", "vehicle.motor_names", (list,))
    if len(names) != 4 or not all(type(x) is str for x in names) or len(set(names)) != 4:
        raise f.fail("vehicle.motor_names", f"{_short(names)} is not 4 distinct rotor names")
    basis = f.get(v, "basis", "vehicle.basis", (str,))
    if basis not in ("omega2", "command"):
        raise f.fail("vehicle.basis", f"{basis!r} is neither 'omega2' nor 'command'")
    cg = f.get(v, "cg_damage_separable", "vehicle.cg_damage_separable", (bool,), optional=True)
    epoch = f.get(d, "epoch", "epoch", (int,))
    if epoch < 0:
        raise f.fail("epoch", f"{epoch} is negative")
    flights = f.get(d, "flights", "flights", (list,))
    checked: dict = {}
    for i, fl in enumerate(flights):
        at = f"flights[{i}]"
        name = f.get(fl, "name", f"{at}.name", (str,))
        f.date(fl, "date", f"{at}.date")
        f.epoch(fl, f"{at}.epoch", epoch)
        source = f.get(fl, "source", f"{at}.source", (str,))
        if source not in SOURCES:
            raise f.fail(f"{at}.source", f"{source!r} is not one of {', '.join(SOURCES)}")
        f.get(fl, "excluded", f"{at}.excluded", (str,), optional=True)
        summ = f.get(fl, "summary", f"{at}.summary", (dict,))
        n = f.get(summ, "n", f"{at}.summary.n", (int,))
        if n < 1:
            raise f.fail(f"{at}.summary.n", f"{n} steps: a flight of a baseline was airborne")
        try:
            s = FlightSummary.from_dict(summ, f"{origin}: {at}.summary ({_short(name)})")
        except ConfigError as exc:
            raise BaselineError(str(exc)) from exc
        if s.basis != basis:
            raise f.fail(f"{at}.summary.basis", f"{s.basis!r}, the baseline's is {basis!r}")
        checked[id(fl)] = (fl, s)
    events = f.get(d, "events", "events", (list,))
    for i, ev in enumerate(events):
        at = f"events[{i}]"
        name = f.get(ev, "event", f"{at}.event", (str,))
        if name not in EVENTS:
            raise f.fail(f"{at}.event", f"{_short(name)} is not a known event")
        f.date(ev, "date", f"{at}.date")
        f.epoch(ev, f"{at}.epoch", epoch)
    return VehicleBaseline(vid, id_source, tuple(names), basis, epoch, list(flights), list(events), cg, checked)


# The one place a file's version is turned into a baseline: a reader per version this propwatch reads. A new version
# adds its reader here (an older one's reader may fill the new fields) and raises VERSION.
READERS = {1: _read_v1}


def is_vehicle_baseline(path: str | Path) -> bool:
    """Whether ``path`` holds this format (an older adapt folder's ``baseline.json`` does not)."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8")).get("format") == FORMAT
    except (OSError, ValueError, AttributeError):
        return True  # unreadable: let VehicleBaseline.load say why
