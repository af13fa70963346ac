"""The fleet's adapter of vehicle memory (``monitor.memory``): each flight of the store judged against its vehicle's
healthy flights before it.

After the workers have written their rows (each with its flight's share summary), ``judge_store`` walks every
vehicle's flights in order of the logs' own clocks. A flight is compared with the vehicle's flights before it that
raised nothing (no FAULTY, not suspect) once there are ``MIN_FLIGHTS`` of them: the same ``VehicleBaseline`` and
the same ``judgement`` and ``with_memory`` (``monitor.diagnose.memory_adapter``) as ``propwatch diagnose LOG
--baseline B.json`` with B learnt from those flights, so both give the same verdict, and the site renders it. Flights that raised nothing before a normal existed are checked against each other once there are
enough, and one the others call FAULTY is set aside (``monitor.memory.learn.set_aside_outliers``). A log without a clock of its own is judged against the baseline as it stands (every timed flight)
and never becomes history. A flight judged before keeps its verdict unless ``rediagnose``: a log older than flights
already judged changes them only then.
"""

from __future__ import annotations

import json

from monitor.diagnose.memory_adapter import judgement, with_memory
from monitor.memory.baseline import VehicleBaseline
from monitor.memory.learn import set_aside_outliers
from monitor.memory.summary import FlightSummary
from monitor.memory.through_time import marks_from_json

_COLS = (
    "log_hash, vehicle_id, start_time_utc, time_known, status, memory_summary, memory, verdict_label, confidence, "
    "propeller_names, path, diagnosis"
)


def _raised_nothing(label, confidence, memory, diagnosis) -> bool:
    """Whether a flight may become history: against a ready baseline, judged healthy (not even suspect); before
    one, no in-flight alert and no confident fault from the nominal comparison (the daemon's rule)."""
    if memory is not None and "label" in json.loads(memory):
        return label == 1 and confidence != "suspect"
    alerts = ((json.loads(diagnosis) if diagnosis else {}).get("decision") or {}).get("alerts") or []
    return not alerts and not (label not in (1, None) and confidence == "confident")


def judge_store(con, rediagnose: bool = False) -> int:
    """Judge every unjudged flight (every flight with ``rediagnose``); returns how many rows changed."""
    rows = con.execute(f"SELECT {_COLS} FROM flights WHERE vehicle_id IS NOT NULL AND memory_summary IS NOT NULL").fetchall()
    by: dict[str, list[tuple]] = {}
    for r in rows:
        by.setdefault(r[1], []).append(r)
    updates = []
    for vid, fl in by.items():
        timed = sorted((r for r in fl if r[3]), key=lambda r: (r[2], r[10]))
        untimed = sorted((r for r in fl if not r[3]), key=lambda r: r[10])
        history = VehicleBaseline(vid, None, tuple(fl[0][9]), json.loads(fl[0][5])["basis"])
        for r in timed + untimed:
            log_hash, _, start, time_known, status, summ, memory, label, conf, names, path, diagnosis = r
            trace = json.loads(summ)
            summary = FlightSummary.from_dict(trace, path)
            if memory is None or rediagnose:
                marks = marks_from_json(trace.get("marks") or [], path)
                upd = _judge_row(history, summary, time_known, json.loads(diagnosis) if diagnosis else {}, marks)
                updates.append((log_hash, upd))
                label, conf, memory = upd.get("verdict_label", label), upd.get("confidence", conf), upd["memory"]
                status = upd.get("status", status)
            if (
                time_known
                and status == "ok"
                and _raised_nothing(label, conf, memory, diagnosis)
                and summary.basis == history.basis
            ):
                history.add(log_hash, start.date().isoformat() if start is not None else None, summary, "no fault")
                set_aside_outliers(history)  # the history changed: check it once, not before every flight judged
    if updates:
        con.execute("BEGIN TRANSACTION")
        for h, upd in updates:
            cols = ", ".join(f"{k} = ?" for k in upd)
            con.execute(f"UPDATE flights SET {cols} WHERE log_hash = ?", [*upd.values(), h])
        con.execute("COMMIT")
    return len(updates)


def _judge_row(b: VehicleBaseline, summary: FlightSummary, time_known, diagnosis: dict, marks) -> dict:
    """The row's memory columns, and where the history judged the flight its verdict columns: ``judgement`` and
    ``with_memory``, as ``propwatch diagnose --baseline`` with ``b``."""
    cw = b.compared_with()
    upd = {
        "baseline_flights": cw["flights"],
        "compared_with_first": cw["first"],
        "compared_with_last": cw["last"],
        "compared_with_logs": [f["name"] for f in b.active()],
    }
    if b.ready and summary.basis != b.basis:
        upd["memory"] = json.dumps({"note": "another share basis"})
        return upd
    note = "" if time_known else "; time unknown: judged against the baseline at ingest"
    judged = judgement(diagnosis, summary, b, note, marks=marks[0], boot_s_of_row=marks[1].get)
    upd["memory"] = json.dumps(judged, allow_nan=False)
    v = with_memory(diagnosis, judged)["verdict"]
    if v is not None and v.get("source") == "vehicle memory":
        upd.update(
            verdict_label=int(v["label"]),
            faulty_propellers=list(v["faulty_propellers"]),
            confidence=v["confidence"],
            status="ok",
        )
    return upd
