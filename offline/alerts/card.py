"""The alert-rule table of the classifier card, from an alert evaluation's ``alerts.json``.

    python -m offline.alerts.card out/alerts/alerts.json      # then `make card-text`

The card shows the rules side by side: rule x false alarms per hour x detection x median/p95
latency x wrong-propeller alerts, with the old window rule and PX4's vibration metric as rows. The table is
written by code from the evaluation's own JSON (``offline.alerts.evaluate`` writes it), never by hand.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from monitor.errors import LogFormatError
from monitor.vehicle import REPO_ROOT
from offline.classifier.card_tables import TABLES_FILE, CardTable, upsert_table

COLUMNS = (
    "simulator",
    "rule",
    "healthy flights (h)",
    "false alarms / h (95 % upper)",
    "suspect / h",
    "single onsets >= 8 %",
    "single >= 8 % detected",
    "median / p95 latency",
    "all singles detected",
    "wrong-propeller alerts (suspect)",
    "alerts before onset",
    "pairs: alert overlaps truth",
    "pairs: alert or its set contains truth",
    "pairs alerted: of those, contains truth",
    "pairs, each >= 5 %: contains truth (same-spin / adjacent, all losses)",
    "set alerts after onset",
)


def _f(v, unit: str = "") -> str:
    return "-" if v is None else f"{v}{unit}"


def _pct(v, of=None, digits: int = 0) -> str:
    if v is None:
        return "-"
    return f"{100 * v:.{digits}f} %" + (f" of {of}" if of is not None else "")


def row_cells(sim: str, name: str, v: dict) -> tuple[str, ...]:
    """One rule's row, every cell as text (``alerts.md`` and the card print the same cells)."""
    return (
        sim,
        name,
        f"{v['healthy_flights']} ({v['healthy_hours']})",
        f"{v['false_alarms_per_hour']} ({v['false_alarms_per_hour_upper95']})",
        f"{v['suspect_false_alarms_per_hour']}",
        f"{v['single_onsets']}",
        _pct(v["single_detected"], digits=1),
        f"{_f(v['latency_median_s'], ' s')} / {_f(v['latency_p95_s'], ' s')}",
        _pct(v.get("single_detected_all"), v.get("single_onsets_all"), digits=1),
        f"{v['wrong_propeller_alerts']} ({v.get('wrong_propeller_suspects', '-')})",
        f"{v['alerts_before_onset']}",
        _pct(v["pair_alert_overlaps_truth"], v["pair_onsets"]),
        _pct(v.get("pair_alert_contains_truth"), v["pair_onsets"]),
        _pct(v.get("pair_contains_truth_of_alerted"), v.get("pair_alerted")),
        f"{_pct(v.get('pair_contains_truth_each_5pct'), v.get('pair_onsets_each_5pct'))} "
        f"({_pct(v.get('pair_contains_truth_same_spin'), v.get('pair_onsets_same_spin'))} / "
        f"{_pct(v.get('pair_contains_truth_adjacent'), v.get('pair_onsets_adjacent'))})",
        f"{v.get('set_alerts', '-')}",
    )


def rows(result: dict) -> list[tuple[str, ...]]:
    return [row_cells(sim, name, v) for sim, by in result["rows"].items() for name, v in by.items()]


def hours_line(result: dict) -> str:
    return (
        "Healthy hours (classified: from each flight's first full classifier window, the hours the rates are per): "
        + "; ".join(
            f"{sim}: {h['flights']} flights, {h['flown_h']} h flown, {h['classified_h']} h classified (asked: {h['asked_classified_h']} h)"
            for sim, h in result["healthy_hours"].items()
        )
    )


def card_table(result: dict, source: str) -> CardTable:
    th = result["thresholds"]
    note = (
        "What the daemon and `diagnose` alert on (monitor/decision/rule.py, docs/ALERTS.md): sequential tests with thresholds "
        f"from stated false-alarm rates (suspect {th['suspect']}, fault {th['fault']}; {th['source']}), replayed over "
        "healthy flights and in-flight onsets of both simulators. *ours*: this project's simulator, every flight's physics "
        "drawn from the register; *evalsim*: the evaluation-only simulator, never used to calibrate. "
        "A false alarm is a FAULT-level alert on a healthy flight; suspect (NOTICE) alerts are counted apart. "
        "The window rule `P >= 0.9 for 20 windows` (the daemon's rule before the decision layer) and PX4's "
        "vibration imbalance metric are rows. "
        + (hours_line(result) + ". " if "healthy_hours" in result else "")
        + f"CPU {result['cpu_s']} s. Per-flight notes: models/decision-evaluation.md."
    )
    return CardTable(
        key="alert-rules",
        title="Alert decisions on both simulators",
        note=note,
        columns=COLUMNS,
        rows=tuple(rows(result)),
        produced_by=f"propwatch evaluate alerts ... --out DIR; python -m offline.alerts.card {source}",
    )


def load_result(path: Path) -> dict:
    try:
        result = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise LogFormatError(f"{path}: not a readable alert evaluation JSON ({exc})") from exc
    if not isinstance(result, dict) or result.get("manifest", {}).get("kind") != "alert-evaluation":
        raise LogFormatError(f"{path}: manifest.kind is not 'alert-evaluation': not written by offline.alerts.evaluate")
    for key in ("rows", "thresholds", "cpu_s"):
        if key not in result:
            raise LogFormatError(f"{path}: no {key!r}: not a complete alert evaluation")
    return result


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("alerts_json", type=Path, help="alerts.json written by offline.alerts.evaluate")
    p.add_argument(
        "--tables", type=Path, default=REPO_ROOT / "models" / TABLES_FILE, help="card tables file (default: the shipped card's)"
    )
    a = p.parse_args(argv)
    try:
        table = card_table(load_result(a.alerts_json), str(a.alerts_json))
    except LogFormatError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    upsert_table(a.tables, table)
    print(f"card table 'alert-rules' ({len(table.rows)} rows) written to {a.tables}; run `make card-text`")
    return 0


if __name__ == "__main__":
    sys.exit(main())
