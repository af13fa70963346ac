"""Flights declared healthy (or that raised nothing) into a ``VehicleBaseline``.

``learn_baseline(tables, files, vehicle_id=...)`` is the one entry point for flight tables already read (``propwatch
adapt`` calls it on its healthy flights); ``learn_from_logs`` reads logs first (``propwatch baseline learn``), takes
the vehicle's identity and each flight's date from the logs themselves, and orders the flights by date.

A flight given as healthy must look like the others: each is judged against the normal of the rest, and one that
the rest would call FAULTY is refused, naming its rotor(s) (``HealthyOutlierError``).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.flight import FlightTable
from monitor.memory import thresholds as th
from monitor.memory.baseline import MIN_FLIGHTS, BaselineError, VehicleBaseline
from monitor.memory.judge import judge, statistics
from monitor.memory.normal import FlightStack
from monitor.memory.summary import FlightSummary, summarize
from monitor.resample import US_PER_S


class HealthyOutlierError(BaselineError):
    """A flight declared healthy whose rotor lies beyond the other flights' spread."""


@dataclass(frozen=True)
class LoggedFlight:
    name: str
    table: FlightTable
    summary: FlightSummary
    vehicle_id: str | None
    id_source: str | None
    date: str | None  # YYYY-MM-DD of take-off, UTC, where the log carries a clock
    start_utc_us: int | None
    path: str = ""  # as given; named instead of ``name`` where two logs share a file name


def flight_date(utc_us: int | None) -> str | None:
    if utc_us is None:
        return None
    return _dt.datetime.fromtimestamp(utc_us / US_PER_S, tz=_dt.timezone.utc).date().isoformat()


def read_flight(path: str | Path, fmt: str | None, esc, rate_hz: float = 20.0) -> LoggedFlight:
    """One log: its table, share summary, vehicle identity and take-off date (``monitor.logs.identity``)."""
    from monitor.logs import detect_format, read_raw, to_flight_table
    from monitor.logs.identity import identify, plausible_utc

    path = Path(path)
    raw = read_raw(path, fmt, extras=False)
    table = to_flight_table(raw, esc=esc, rate_hz=rate_hz)
    try:
        ident = identify(path, fmt or detect_format(path))
    except Exception:  # noqa: BLE001 - identity is optional evidence; a log readable for shares still counts
        ident = None
    start = None
    if ident is not None and ident.utc_minus_boot_us is not None and len(table):
        air = table.airborne.nonzero()[0]
        t0 = int(table.timestamp_us[air[0] if len(air) else 0])
        start = t0 + int(ident.utc_minus_boot_us)
        start = start if plausible_utc(start) else None
    return LoggedFlight(
        name=path.name,
        table=table,
        summary=summarize(table),
        vehicle_id=None if ident is None else ident.vehicle_id,
        id_source=None if ident is None else ident.vehicle_id_source,
        date=flight_date(start),
        start_utc_us=start,
        path=str(path),
    )


def distinct_names(flights: list[LoggedFlight]) -> list[str]:
    """Each flight's file name, or its path where another flight has the same file name."""
    seen = [f.name for f in flights]
    return [f.path or f.name if seen.count(f.name) > 1 else f.name for f in flights]


def outliers(summaries: list[FlightSummary], prior_cov=None):
    """Each flight the others call FAULTY (judged against the normal of the rest, ``prior_cov`` its prior), in
    order: (index, verdict). None below ``MIN_FLIGHTS`` flights."""
    if len(summaries) < MIN_FLIGHTS:
        return
    stack = FlightStack.of(summaries)  # each leave-one-out normal one vectorised pass: linear in flights, not quadratic
    for i, s in enumerate(summaries):
        keep = np.ones(len(summaries), dtype=bool)
        keep[i] = False
        normal = stack.normal(keep, prior_cov)
        # judge's fault statistic alone first (the largest hypothesis statistic); the whole verdict only past it
        stats, _, _ = statistics(normal.deviation(s), normal.deviation_cov(s))
        if max(stats.values()) >= th.FAULT_STATISTIC:  # a load off centre that explains it is no excuse here
            yield i, judge(normal, s)


def _rotors(v: dict, motor_names=("1", "2", "3", "4")) -> str:
    """The hypotheses' rotors by the vehicle's own names (PX4 numbers 1..4 index ``motor_names``)."""
    sets = [h["faulty_propellers"] for h in v["hypotheses"] if h["faulty_propellers"]]
    return " or ".join("+".join(motor_names[p - 1] for p in s) for s in sets)


def check_outliers(names: list[str], summaries: list[FlightSummary], motor_names=("1", "2", "3", "4")) -> None:
    """Raise naming the flight and rotor(s), by the vehicle's own rotor names, where a declared-healthy flight is
    FAULTY against the others."""
    found = next(outliers(summaries), None)
    if found is not None:
        i, v = found
        raise HealthyOutlierError(
            f"{names[i]}: given as healthy, but against the other {len(summaries) - 1} flights rotor {_rotors(v, motor_names)} lies "
            f"beyond their spread (statistic {v['fault_statistic']:.1f} >= {v['thresholds']['fault']:g}); "
            "inspect that propeller, or leave the flight out"
        )


def set_aside_outliers(b: VehicleBaseline) -> list[str]:
    """Flights that raised nothing before the vehicle had a normal may still carry damage nobody could see: once
    there are ``MIN_FLIGHTS``, the one the others call FAULTY (the largest statistic against the rest) is set aside
    (``excluded``, with why), and again until none is. Returns the names set aside."""
    out = []
    while True:
        act = b.active()
        found = max(
            outliers([b.summary_of(f) for f in act]),
            key=lambda iv: iv[1]["fault_statistic"],
            default=None,
        )
        if found is None:
            break
        i, v = found
        act[i]["excluded"] = (
            f"unlike the other {len(act) - 1} flights: rotor {_rotors(v, b.motor_names)} (statistic {v['fault_statistic']:.1f})"
        )
        out.append(act[i]["name"])
    return out


def learn_baseline(
    tables: list[FlightTable],
    files: list[str],
    vehicle_id: str | None = None,
    id_source: str | None = None,
    dates: list[str | None] | None = None,
    source: str = "declared",
    cg_damage_separable: bool | None = None,
    check_healthy: bool = True,
) -> VehicleBaseline:
    """The baseline of flights declared healthy, in the order given. Raises ``BaselineError`` (fewer than
    ``MIN_FLIGHTS`` flights with airborne steps, mixed airframes) or, with ``check_healthy``, ``HealthyOutlierError``.
    ``cg_damage_separable``: ``VehicleBaseline``'s (False where CG and damage were measured alike)."""
    summaries = [summarize(t) for t in tables]
    b = _build(
        files,
        summaries,
        [t.motor_names for t in tables],
        vehicle_id,
        id_source,
        dates or [None] * len(tables),
        source,
        check_healthy,
    )
    b.cg_damage_separable = cg_damage_separable
    return b


def _build(names, summaries, motor_names, vehicle_id, id_source, dates, source, check_healthy=True) -> VehicleBaseline:
    flown = [i for i, s in enumerate(summaries) if s.n > 0]
    if len(flown) < MIN_FLIGHTS:
        empty = [names[i] for i in range(len(names)) if i not in flown]
        why = f" ({', '.join(empty)} never airborne long enough)" if empty else ""
        raise BaselineError(f"a baseline needs at least {MIN_FLIGHTS} flights with airborne steps, got {len(flown)}{why}")
    if len({tuple(motor_names[i]) for i in flown}) != 1 or len({summaries[i].basis for i in flown}) != 1:
        raise BaselineError("the flights mix airframes (rotor names or share basis differ): give one vehicle's flights")
    if check_healthy:
        check_outliers([names[i] for i in flown], [summaries[i] for i in flown], tuple(motor_names[flown[0]]))
    b = VehicleBaseline(vehicle_id, id_source, tuple(motor_names[flown[0]]), summaries[flown[0]].basis)
    for i in flown:
        b.add(names[i], dates[i], summaries[i], source)
    return b


def learn_from_logs(flights: list[LoggedFlight], vehicle_id: str | None = None) -> VehicleBaseline:
    """``propwatch baseline learn``: one vehicle's flights (by the logs' ids, or ``vehicle_id`` for logs without)."""
    flights = [dataclasses.replace(f, name=n) for f, n in zip(flights, distinct_names(flights), strict=True)]
    ids = {f.vehicle_id for f in flights if f.vehicle_id is not None}
    if len(ids) > 1:
        raise BaselineError(f"the logs are of {len(ids)} vehicles ({', '.join(sorted(ids))}): learn one vehicle at a time")
    missing = [f.name for f in flights if f.vehicle_id is None]
    if vehicle_id is None:
        if missing:
            raise BaselineError(f"{', '.join(missing)}: no vehicle identity in the log: give --vehicle-id")
        vehicle_id = ids.pop()
    elif ids and vehicle_id not in ids:
        raise BaselineError(f"--vehicle-id {vehicle_id}, but the logs say vehicle {ids.pop()}")
    order = sorted(range(len(flights)), key=lambda i: (flights[i].start_utc_us is None, flights[i].start_utc_us or 0, i))
    fl = [flights[i] for i in order]
    src = next((f.id_source for f in fl if f.id_source), "--vehicle-id")
    return _build(
        [f.name for f in fl],
        [f.summary for f in fl],
        [f.table.motor_names for f in fl],
        vehicle_id,
        src,
        [f.date for f in fl],
        "declared",
    )
