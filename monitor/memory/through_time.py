"""A flight judged through time against its vehicle's normal: a change in the air that the flight's mean dilutes.

A propeller damaged in the air stays damaged to the landing, so the flight from the change to its end deviates from
the normal while the whole flight's mean mixes in the healthy part before it. Each ``Mark`` (the sums at the end of
a 2-s block, ``monitor.memory.summary``) starts a candidate: the flight from it to the end (``FlightSummary.minus``),
at least ``MIN_SUFFIX_S`` long, judged as a whole flight is (``monitor.memory.judge``, the load rival included). The
largest statistic of the candidates is the scan's. It overrules the whole flight only where the whole did not reach
the fault level and the scan reaches ``thresholds.SCAN_FAULT_STATISTIC``, measured like the fault level on healthy
later flights of our own simulator (the maximum of many nested looks is larger than one look's); a confident
"healthy" also needs the scan below ``thresholds.SCAN_SUSPECT_STATISTIC``.

The scan is post-flight (``propwatch diagnose --baseline``, the fleet, and the daemon at landing before it learns a
flight): its ``from_boot_s`` is where the end that deviates most begins, found with the whole flight in hand, never
when the change was first seen. Once inside a change, every end deviates alike (the flight-to-flight spread
dominates the wander of a mean of 10 s or more), so it marks a time within the change, not its start.
"""

from __future__ import annotations

from monitor.errors import ConfigError
from monitor.memory import thresholds as th
from monitor.memory.judge import judge
from monitor.memory.normal import Normal
from monitor.memory.summary import FlightSummary, Mark

# The shortest end of a flight judged on its own: five 2-s blocks, enough for the within-flight wander term of
# ``Normal.deviation_cov``. Chosen, not measured.
MIN_SUFFIX_S = 10.0
# At most this many candidates (evenly thinned marks) per flight: bounds the cost of a long flight (each look is one
# ``judge``, under a millisecond) and the record the fleet keeps per flight. Chosen, not measured.
MAX_LOOKS = 64


def thin(marks: list[Mark], whole: FlightSummary) -> list[Mark]:
    """The marks that leave at least ``MIN_SUFFIX_S`` to the end and are not the flight's start, at most
    ``MAX_LOOKS`` of them, evenly spaced."""
    keep = [m for m in marks if m.summary.n > 0 and (whole.n - m.summary.n) >= MIN_SUFFIX_S * whole.rate_hz]
    step = -(-len(keep) // MAX_LOOKS) if keep else 1
    return keep[::step]


def scan(normal: Normal, whole: FlightSummary, looks: list[Mark]) -> tuple[Mark, dict] | None:
    """The end of the flight from one of ``looks`` (``thin``'s marks) with the largest statistic, and its judgement;
    None where there is none."""
    best = None
    for m in looks:
        v = judge(normal, whole.minus(m.summary))
        if best is None or v["fault_statistic"] > best[1]["fault_statistic"]:
            best = (m, v)
    return best


def judge_through_time(normal: Normal, whole: FlightSummary, marks: list[Mark], boot_s_of_row=None) -> dict:
    """``judge`` of the whole flight, with its ``through_time`` object, replaced by the judgement of the flight's end
    where the scan found a change the whole flight's mean diluted. ``boot_s_of_row`` maps a mark's row to the log's
    boot-clock seconds (None: rows are reported as they are)."""
    v = judge(normal, whole)
    looks = thin(marks, whole)
    best = scan(normal, whole, looks)
    if best is None:
        return v | {"through_time": None}
    m, u = best
    part = whole.minus(m.summary)
    info = {
        "statistic": float(u["fault_statistic"]),
        "from_row": m.row,
        "from_boot_s": None if boot_s_of_row is None else float(boot_s_of_row(m.row)),
        "seconds": part.seconds,
        "looks": len(looks),
        "fault": th.SCAN_FAULT_STATISTIC,
        "suspect": th.SCAN_SUSPECT_STATISTIC,
    }
    where = f"{info['from_boot_s']:.0f} s" if info["from_boot_s"] is not None else f"row {m.row}"
    if v["fault_statistic"] < th.FAULT_STATISTIC and u["fault_statistic"] >= th.SCAN_FAULT_STATISTIC:
        whole_flight = {k: v[k] for k in ("label", "faulty_propellers", "confidence", "fault_statistic")}
        return u | {
            "through_time": info | {"overrules": True, "whole_flight": whole_flight},
            "rule": f"the last {part.seconds:.0f} s (from {where}) against this vehicle's normal: statistic "
            f"{u['fault_statistic']:.1f} >= {th.SCAN_FAULT_STATISTIC:g} (the whole flight's {v['fault_statistic']:.1f} "
            f"mixes in the part before); " + u["rule"],
        }
    out = v | {"through_time": info | {"overrules": False}}
    if v["label"] == 1 and v["confidence"] == "confident" and u["fault_statistic"] >= th.SCAN_SUSPECT_STATISTIC:
        out |= {
            "confidence": "ambiguous",
            "rule": v["rule"] + f"; but the last {part.seconds:.0f} s (from {where}) reach statistic "
            f"{u['fault_statistic']:.1f} >= {th.SCAN_SUSPECT_STATISTIC:g}: not sure",
        }
    return out


def marks_to_json(marks: list[Mark], whole: FlightSummary, boot_s_of_row) -> list[dict]:
    """The marks the scan looks from (``thin``), each with its boot-clock seconds: what the fleet keeps per flight."""
    return [{"row": m.row, "boot_s": float(boot_s_of_row(m.row)), "summary": m.summary.to_dict()} for m in thin(marks, whole)]


def marks_from_json(items: list, origin: str) -> tuple[list[Mark], dict[int, float]]:
    """``marks_to_json``'s list read back (every summary checked as a stored one is): the marks and {row: boot s}."""
    try:
        marks = [Mark(int(x["row"]), FlightSummary.from_dict(x["summary"], f"{origin}: mark {i}")) for i, x in enumerate(items)]
        boot = {int(x["row"]): float(x["boot_s"]) for x in items}
    except (KeyError, TypeError, ValueError) as exc:
        raise ConfigError(f"{origin}: malformed through-time marks: {exc!r}") from exc
    return marks, boot
