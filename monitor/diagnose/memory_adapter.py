"""Diagnose's adapter of vehicle memory (``monitor.memory``): a diagnosed flight judged against its vehicle's own
healthy history.

``judge_flight`` is the one place a log's ``Diagnosis`` meets a ``VehicleBaseline``: ``propwatch diagnose
--baseline`` and ``fleet ingest`` both call it, so both give the same verdict on the same log against the same
history. The vehicle's normal needs no classifier: a log the network's envelope refuses still gets the comparison.
Where the baseline is ready, its judgement is the verdict (``verdict.source`` "vehicle memory"); what the nominal
comparison said stays in ``verdict.nominal``.
"""

from __future__ import annotations

from pathlib import Path

from monitor.diagnose.engine import Diagnosis
from monitor.diagnose.physics_first import boot_s
from monitor.labels import LABEL_TABLE
from monitor.memory.baseline import MIN_FLIGHTS, VehicleBaseline
from monitor.memory.summary import FlightSummary, Mark, accumulate
from monitor.memory.through_time import judge_through_time


def log_vehicle_id(path: str | Path, fmt: str | None) -> str | None:
    """The vehicle id the log carries (``monitor.logs.identity``), None where it carries none or cannot say."""
    from monitor.logs import detect_format
    from monitor.logs.identity import identify

    try:
        return identify(Path(path), fmt or detect_format(Path(path))).vehicle_id
    except Exception:  # noqa: BLE001 - a log readable for shares without a readable id is still judged
        return None


def log_date(path: str | Path, fmt: str | None, table) -> str | None:
    """The log's take-off date (UTC, ``YYYY-MM-DD``) from its own clock, None where it carries none."""
    from monitor.logs import detect_format
    from monitor.logs.identity import identify, plausible_utc
    from monitor.memory.learn import flight_date

    try:
        offset = identify(Path(path), fmt or detect_format(Path(path))).utc_minus_boot_us
    except Exception:  # noqa: BLE001 - a log without a readable clock is still judged, its date unknown
        return None
    air = table.airborne.nonzero()[0]
    if offset is None or not len(air):
        return None
    start = int(table.timestamp_us[air[0]]) + int(offset)
    return flight_date(start) if plausible_utc(start) else None


def ties(baseline: VehicleBaseline, s: FlightSummary, vehicle_id: str | None, date: str | None) -> list[str]:
    """What ties a log to the baseline it is judged against, where something does not: a log without a vehicle id,
    one of the baseline's own flights, a flight older than the baseline's newest."""
    out = []
    if vehicle_id is None:
        who = f"vehicle {baseline.vehicle_id}" if baseline.vehicle_id else "a vehicle the baseline does not name either"
        out.append(f"this log carries no vehicle id: nothing ties it to {who}")
    own = next((f for f in baseline.flights if f.get("summary") == s.to_dict()), None)
    if own is not None:
        out.append(f"this log is one of the baseline's own flights ({own['name']}): compared with itself")
    dates = [f["date"] for f in baseline.active() if f.get("date")]
    if own is None and date is not None and dates and date < max(dates):
        out.append(f"this flight ({date}) is older than the baseline's newest flight ({max(dates)})")
    return out


def judge_flight(d: Diagnosis, table, baseline: VehicleBaseline, vehicle_id: str | None, date: str | None = None) -> dict:
    """The ``baseline`` object of the diagnose JSON; replaces ``d``'s verdict by the vehicle-memory verdict where the
    baseline judged the flight (``with_memory``). ``vehicle_id`` and ``date`` are the log's own (None: it carries
    none); where they do not tie the log to the baseline, its ``caveats`` say so. Raises ``BaselineError`` where
    the log is another vehicle's (identity or rotors)."""
    acc = accumulate(table)
    s = acc.summary
    baseline.check_vehicle(vehicle_id, table.motor_names, s.basis, str(table.source or "log"))
    out = judgement(d.to_json(), s, baseline, marks=acc.marks, boot_s_of_row=boot_clock(table))
    if caveats := ties(baseline, s, vehicle_id, date):
        out["caveats"] = caveats
    res = with_memory(d.to_json(), out)
    d.verdict, d.reason, d.propellers = res["verdict"], res["reason"], res["propellers"]
    d.hypotheses, d.hypothesis_rule = res["hypotheses"], res["hypothesis_rule"]
    return out


def boot_clock(table):
    """A table row's boot-clock seconds (the last row's for a row past the end)."""
    t_s = boot_s(table)
    return lambda row: float(t_s[min(int(row), len(t_s) - 1)])


def judgement(
    result: dict,
    s: FlightSummary,
    baseline: VehicleBaseline,
    compared_note: str = "",
    marks: list[Mark] | None = None,
    boot_s_of_row=None,
) -> dict:
    """The ``baseline`` object of the diagnose JSON for the flight whose nominal diagnosis is ``result`` (a
    ``--json`` object) and whose rotor shares are ``s``, against ``baseline``: what it was compared with, and the
    judgement (``monitor.memory.through_time``: the whole flight, and its ends from each of ``marks``) or a
    ``note`` saying why the verdict stays the nominal one. ``compared_note`` is added to ``compared_with_text``.
    ``propwatch diagnose --baseline`` and the fleet both judge here."""
    out = {"compared_with": baseline.compared_with(), "compared_with_text": baseline.compared_with_text() + compared_note}
    if not baseline.ready:
        out["note"] = f"no vehicle baseline yet ({len(baseline.active())} of {MIN_FLIGHTS} flights): not compared"
        return out
    if s.n == 0:
        out["note"] = "no airborne step past take-off to compare"
        return out
    v = judge_through_time(baseline.normal(), s, marks or [], boot_s_of_row)
    if baseline.cg_damage_separable is False and v["faulty_propellers"]:
        v = as_imbalance(v)
    out.update(v)
    if (result.get("verdict") or {}).get("source") == "motor output":
        out["note"] = "a stopped or saturated motor stands: the vehicle's history judges propellers, not motors"
        return out
    if _in_flight_change(result) and not v["faulty_propellers"]:
        # A propeller damaged mid-flight: the in-flight rule compared the flight with its own start and found the
        # change; the whole flight's shares mix the healthy part before it in, so its answer stands.
        out["note"] = "the in-flight rule's change stands: the whole flight against the vehicle's history did not name it"
    elif _in_flight_change(result) and v["confidence"] != "confident":
        # The in-flight rule compared the flight with its own start: the same load, the same CG. Against the
        # history, another load's CG moves the shares too; where that leaves the history unsure, the change stands.
        out["note"] = "the in-flight rule's change stands: the vehicle's history is not sure which propeller (another load)"
    return out


def with_memory(result: dict, judged: dict | None) -> dict:
    """``result`` (a diagnose ``--json`` object, its nominal diagnosis) with its ``baseline`` object ``judged``
    (``judgement``): where that judged the flight (a label and no note), the verdict, propellers and hypotheses are
    the vehicle memory's and the nominal verdict stays in ``verdict.nominal``. Every rendering of a flight compared
    with its vehicle's history (text, JSON, PNG, the fleet's row and site) renders this."""
    out = dict(result)
    out["baseline"] = judged
    if not judged or "label" not in judged or "note" in judged:
        return out
    motor_names = [p.get("name") or str(p["propeller"]) for p in result.get("propellers") or []] or ["1", "2", "3", "4"]
    out.update(_applied(result, judged, motor_names, judged["compared_with_text"]))
    return out


def as_imbalance(v: dict) -> dict:
    """A propeller verdict on an airframe whose flights were measured not to tell a CG offset from damage: the rotors
    that work harder are an imbalance near them, both causes named, no propeller called faulty (never confident)."""
    rotors = sorted({k for h in v["hypotheses"] for k in h["faulty_propellers"]})
    where = "+".join(map(str, rotors))
    return v | {
        "label": 1,
        "faulty_propellers": [],
        "suspect_propellers": rotors,
        "imbalance_rotors": rotors,
        "confidence": "ambiguous",
        "hypotheses": [{"faulty_propellers": h["faulty_propellers"], "statistic": h["statistic"]} for h in v["hypotheses"]]
        + [
            {
                "faulty_propellers": [],
                "statistic": v["fault_statistic"],
                "cause": f"CG offset toward rotor {where}, propellers intact",
            }
        ],
        "rule": v["rule"] + "; a CG offset and damage look alike on this airframe: an imbalance, no propeller named",
    }


def _in_flight_change(result: dict) -> bool:
    return (result.get("verdict") or {}).get("source") == "in-flight change"


def _applied(result: dict, v: dict, motor_names, compared: str) -> dict:
    """The keys of ``result`` the vehicle memory's judgement ``v`` replaces."""
    nominal = result.get("verdict")
    label = v["label"]
    suspect = set(v.get("suspect_propellers", [])) | {k for h in v["hypotheses"] for k in h["faulty_propellers"]}
    propellers = []
    for p in result.get("propellers") or []:
        bad = p["propeller"] in LABEL_TABLE[label]
        faulty = bad and v["confidence"] == "confident"
        propellers.append({**p, "faulty": faulty, "suspect": not faulty and p["propeller"] in suspect})
    return {
        "verdict": {
            "label": label,
            "faulty_propellers": list(LABEL_TABLE[label]),
            "faulty_names": [motor_names[i - 1] for i in LABEL_TABLE[label]],
            "confidence": v["confidence"],
            "source": "vehicle memory",
            "compared_with": compared,
            "fault_probability": None if nominal is None else nominal.get("fault_probability"),
            "nominal": None
            if nominal is None
            else {k: nominal[k] for k in ("label", "faulty_propellers", "confidence") if k in nominal},
        }
        | {k: v[k] for k in ("imbalance_rotors", "imbalance_why") if k in v},
        "reason": None,
        "propellers": propellers,
        "hypotheses": [
            {
                "faulty_propellers": h["faulty_propellers"],
                "statistic": h["statistic"],
                "cause": h.get("cause")
                or (
                    "as this vehicle's healthy flights"
                    if not h["faulty_propellers"]
                    else "damaged propeller " + "+".join(map(str, h["faulty_propellers"]))
                ),
            }
            for h in v["hypotheses"]
        ],
        "hypothesis_rule": None,
    }
