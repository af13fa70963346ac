"""propwatch baseline: a vehicle's healthy normal from its own flights.

    propwatch baseline learn LOG... --out B.json [--vehicle-id ID] [--format F] [--vehicle YAML] [--json]
    propwatch baseline show B.json [--json]
    propwatch baseline note B.json --event props-replaced|motor-replaced|... [--date YYYY-MM-DD]
    propwatch baseline reset --state-dir DIR --vehicle KEY

learn reads flights the operator declares healthy (at least 3, of one vehicle: the logs' own ids, or
--vehicle-id for logs without one) and writes B.json; diagnose LOG --baseline B.json then judges a flight
against it. Learning into an existing baseline file of the same vehicle adds the flights and keeps its notes and
history; a file that is not a baseline is never overwritten. note records maintenance; an event that changes the
airframe restarts the normal. reset moves a daemon's baseline of one vehicle aside (dated, beside it) so that its
history starts again from the next flight: the daemon never replaces a baseline it cannot read, so this is the
way on from one. A learn --out or note on a baseline in a state dir (DIR/vehicles/KEY/baseline.json) writes under
the state dir's write lock, as the daemon does; learn there never replaces a baseline (reset it first).
Exit 2 with one line naming the file and the reason on bad input; nothing is written then.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import sys
from pathlib import Path

from monitor.errors import PropwatchError
from monitor.memory.baseline import EVENTS, MIN_FLIGHTS, BaselineError, VehicleBaseline
from monitor.memory.store import StateDir, state_dir_of

LOG_NAMES = {"tlog": "a MAVLink telemetry log", "ulog": "a PX4 ULog", "dataflash": "an ArduPilot DataFlash log"}


def flight_log_kind(path: Path) -> str | None:
    """What kind of flight log ``path`` is (its first bytes, or a CSV log's name), None where it is none."""
    from monitor.errors import LogFormatError
    from monitor.logs import detect_format

    try:
        return LOG_NAMES.get(detect_format(path), "a flight log")
    except LogFormatError:
        return "a CSV flight log" if ".csv" in "".join(path.suffixes).lower() else None


def load_baseline(path: Path) -> VehicleBaseline:
    """``path``'s baseline; a flight log given in its place is named as one."""
    if path.is_file() and (kind := flight_log_kind(path)) is not None:
        raise BaselineError(f"{path} is a flight log, not a baseline ({kind}): give the B.json that baseline learn wrote")
    return VehicleBaseline.load(path)


def learn_into(out: Path, learnt: VehicleBaseline) -> tuple[VehicleBaseline, VehicleBaseline | None]:
    """The baseline to write at ``out``, and the one ``out`` held (None where it did not exist): ``learnt``, or
    ``out``'s own baseline of the same vehicle with the flights it lacks added to its current normal, its notes and
    history kept. Raises ``BaselineError``, writing nothing, where ``out`` is not a baseline or another vehicle's."""
    if not out.exists():
        return learnt, None
    if out.is_file() and (kind := flight_log_kind(out)) is not None:
        raise BaselineError(f"--out {out} is a flight log ({kind}), not a baseline: nothing overwritten; give a new file name")
    try:
        old = VehicleBaseline.load(out)
    except BaselineError as exc:
        raise BaselineError(
            f"--out {out} exists and is not a baseline ({exc}): nothing overwritten; give a new file name"
        ) from exc
    kept = VehicleBaseline.from_dict(old.to_dict(), str(out))
    old.check_vehicle(learnt.vehicle_id, learnt.motor_names, learnt.basis, f"--out {out}")
    if old.vehicle_id is None:
        old.vehicle_id, old.id_source = learnt.vehicle_id, learnt.id_source
    if old.cg_damage_separable is None:
        old.cg_damage_separable = learnt.cg_damage_separable
    known = {(f["name"], f["date"]) for f in old.active()}
    old.flights += [{**f, "epoch": old.epoch} for f in learnt.flights if (f["name"], f["date"]) not in known]
    return old, kept


def _date(text: str) -> str:
    try:
        return _dt.date.fromisoformat(text).isoformat()
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"not a date (YYYY-MM-DD): {text!r}") from exc


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="propwatch baseline", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = p.add_subparsers(dest="cmd", required=True)
    lp = sub.add_parser("learn", help=f"learn B.json from at least {MIN_FLIGHTS} healthy flights of one vehicle")
    lp.add_argument("logs", nargs="+", metavar="LOG")
    lp.add_argument("--out", required=True, type=Path, help="the baseline file to write (B.json)")
    lp.add_argument("--vehicle-id", default=None, help="the vehicle's id, for logs that carry none")
    lp.add_argument("--format", dest="fmt", default=None, help="log format (as diagnose --format)")
    lp.add_argument("--vehicle", default=None, help="vehicle YAML whose ESC curve converts commands to RPM (as diagnose)")
    lp.add_argument("--json", action="store_true", help="print the summary as JSON")
    sp = sub.add_parser("show", help="what a baseline holds")
    sp.add_argument("baseline", type=Path)
    sp.add_argument("--json", action="store_true")
    np_ = sub.add_parser("note", help="record a maintenance event")
    np_.add_argument("baseline", type=Path)
    np_.add_argument("--event", required=True, help=f"one of: {', '.join(EVENTS)}")
    np_.add_argument("--date", type=_date, default=None, help="the event's date (default today, UTC)")
    rp = sub.add_parser("reset", help="move a vehicle's baseline in a daemon's state dir aside (dated) and start afresh")
    rp.add_argument("--state-dir", required=True, type=Path, help="the daemon's state dir (its --state-dir)")
    rp.add_argument("--vehicle", required=True, help="the vehicle key, as under DIR/vehicles/ (uid-... or sysid-N)")
    return p.parse_args(argv)


def describe(b: VehicleBaseline) -> dict:
    """The summary ``show`` and ``learn`` print: vehicle, flights, normal, spread, events."""
    out = {
        "vehicle_id": b.vehicle_id,
        "id_source": b.id_source,
        "basis": b.basis,
        "motor_names": list(b.motor_names),
        "compared_with": b.compared_with(),
        "ready": b.ready,
        "flights_needed": MIN_FLIGHTS,
        "flights": [{"name": f["name"], "date": f["date"], "source": f["source"]} for f in b.active()],
        "history_flights": len(b.flights),
        "events": b.events,
    }
    if b.ready:
        n = b.normal()
        out["normal_share"] = [round(float(x), 5) for x in n.intercept]
        out["spread_share"] = [round(float(x), 5) for x in n.cov.diagonal() ** 0.5]
        out["tilt_slopes_share_per_rad"] = [[round(float(x), 4) for x in row] for row in n.slopes]
    return out


def text(b: VehicleBaseline, d: dict) -> str:
    lines = [f"vehicle {d['vehicle_id']} ({d['id_source']}), rotors {', '.join(d['motor_names'])}, {d['basis']} shares"]
    if d["ready"]:
        lines.append(b.compared_with_text())
        names = d["motor_names"]
        lines.append(f"  each rotor's {d['basis']} share, in % of the rotors' mean:")
        lines.append(
            "    normal:                  " + ", ".join(f"{m} {100 * x:.2f} %" for m, x in zip(names, d["normal_share"]))
        )
        lines.append(
            "    flight-to-flight spread: " + ", ".join(f"{m} {100 * x:.2f} %" for m, x in zip(names, d["spread_share"]))
        )
    else:
        lines.append(f"no vehicle baseline yet ({len(d['flights'])} of {MIN_FLIGHTS} flights)")
    for f in d["flights"]:
        lines.append(f"  flight {f['name']} ({f['date'] or 'time unknown'}, {f['source']})")
    for e in d["events"]:
        lines.append(f"  event {e['event']} ({e['date'] or 'date unknown'})")
    return "\n".join(lines)


def _write(path: Path, change, plain_old: bool) -> VehicleBaseline:
    """Apply ``change`` (the baseline there, or None -> the baseline to write) to ``path``: read, changed and written
    under the state dir's write lock where ``path`` is a baseline in one; else as a plain file, read first only with
    ``plain_old``."""
    in_state = state_dir_of(path)
    if in_state is None:
        b = change(VehicleBaseline.load(path) if plain_old else None)
        b.save(path)
        return b
    root, key = in_state
    with StateDir.open(root, create=False) as sd:
        return sd.update(key, change)


def _learnt(new: VehicleBaseline, path: Path):
    def change(old):
        if old is not None:
            raise BaselineError(
                f"{path} already holds this vehicle's history ({len(old.flights)} flights): "
                "`propwatch baseline reset` moves it aside first"
            )
        return new

    return change


def _noted(path: Path, event: str, date: str):
    def change(b):
        if b is None:
            raise BaselineError(f"{path}: no vehicle baseline there")
        b.note(event, date)
        return b

    return change


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        if args.cmd == "learn":
            from monitor.memory.learn import learn_from_logs, read_flight
            from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

            esc = load_vehicle(args.vehicle or DEFAULT_VEHICLE).esc
            flights = [read_flight(p, args.fmt, esc) for p in args.logs]
            learnt = learn_from_logs(flights, args.vehicle_id)
            before = None
            if state_dir_of(args.out) is not None:
                b = _write(args.out, _learnt(learnt, args.out), plain_old=False)
            else:
                b, before = learn_into(args.out, learnt)
                b.save(args.out)
            if before is not None and not args.json:
                print(
                    f"{args.out}: learnt into the baseline it held: {len(b.flights) - len(before.flights)} flights added, "
                    f"its {len(before.flights)} earlier flights and {len(before.events)} "
                    f"note{'' if len(before.events) == 1 else 's'} kept"
                )
        elif args.cmd == "show":
            b = load_baseline(args.baseline)
        elif args.cmd == "note":
            load_baseline(args.baseline)  # a flight log given as the baseline is named as one
            date = args.date or _dt.datetime.now(_dt.timezone.utc).date().isoformat()
            _write(args.baseline, _noted(args.baseline, args.event, date), plain_old=True)
            restarts = EVENTS.get(args.event)  # note() refused an unknown event above
            print(f"{args.baseline}: {args.event} recorded" + ("; the normal restarts from the next flight" if restarts else ""))
            return 0
        else:
            with StateDir.open(args.state_dir, create=False) as sd:
                moved = sd.reset(args.vehicle)
            print(f"vehicle {args.vehicle}: baseline moved aside to {moved}; its history starts again from the next flight")
            return 0
    except (PropwatchError, OSError) as exc:  # BaselineError, StateDirError, disk full: one line, nothing written
        print(f"propwatch baseline: error: {exc}", file=sys.stderr)
        return 2
    d = describe(b)
    if getattr(args, "json", False):
        json.dump(d, sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(text(b, d))
    return 0


if __name__ == "__main__":
    sys.exit(main())
