"""The alert-rule card table is written from an alert evaluation's JSON, and refuses anything else by name."""

import json

import pytest

from monitor.errors import LogFormatError
from offline.alerts.card import COLUMNS, card_table, load_result, main
from offline.classifier.card_tables import load_tables

ROW = {
    "healthy_flights": 480,
    "healthy_hours": 10.007,
    "false_alarms": 0,
    "false_alarms_per_hour": 0.0,
    "false_alarms_per_hour_upper95": 0.299,
    "suspect_false_alarms_per_hour": 0.2,
    "single_onsets": 50,
    "single_detected": 1.0,
    "single_onsets_all": 150,
    "single_detected_all": 0.9067,
    "latency_median_s": 4.15,
    "latency_p95_s": 5.63,
    "wrong_propeller_alerts": 9,
    "wrong_propeller_suspects": 14,
    "alerts_before_onset": 1,
    "pair_onsets": 50,
    "pair_alert_overlaps_truth": 0.72,
    "pair_alert_contains_truth": 0.6,
    "set_alerts": 47,
}


def _result() -> dict:
    px4 = {**ROW, "single_detected": 0.0, "latency_median_s": None, "latency_p95_s": None}
    return {
        "rows": {"ours": {"decision": ROW, "PX4 metric": px4}},
        "thresholds": {"suspect": {"physics": 7.8}, "fault": {"physics": 10.8}, "source": "calibrated"},
        "cpu_s": 12.5,
        "healthy_hours": {"ours": {"flights": 480, "flown_h": 10.667, "classified_h": 10.007, "asked_classified_h": 10.0}},
        "manifest": {"kind": "alert-evaluation"},
    }


def test_card_table_rows_carry_the_evaluations_figures(tmp_path):
    path = tmp_path / "alerts.json"
    path.write_text(json.dumps(_result()))
    tables = tmp_path / "tables.json"
    assert main([str(path), "--tables", str(tables)]) == 0
    (table,) = load_tables(tables)
    assert table.key == "alert-rules" and table.columns == COLUMNS
    decision = dict(zip(COLUMNS, table.rows[0], strict=True))
    assert decision["false alarms / h (95 % upper)"] == "0.0 (0.299)"
    assert decision["single >= 8 % detected"] == "100.0 %"
    assert decision["median / p95 latency"] == "4.15 s / 5.63 s"
    assert decision["wrong-propeller alerts (suspect)"] == "9 (14)"
    assert decision["pairs: alert or its set contains truth"] == "60 % of 50"
    px4 = dict(zip(COLUMNS, table.rows[1], strict=True))
    assert px4["single >= 8 % detected"] == "0.0 %" and px4["median / p95 latency"] == "- / -"
    assert "10.007 h classified" in table.note


def test_anything_but_an_alert_evaluation_is_refused_by_name(tmp_path):
    other = tmp_path / "generalisation.json"
    other.write_text(json.dumps({"evalsim": {}, "ours": []}))
    with pytest.raises(LogFormatError, match="generalisation.json.*alert-evaluation"):
        load_result(other)
    broken = tmp_path / "alerts.json"
    broken.write_text("{not json")
    with pytest.raises(LogFormatError, match="alerts.json"):
        load_result(broken)
    partial = {**_result()}
    del partial["rows"]
    broken.write_text(json.dumps(partial))
    with pytest.raises(LogFormatError, match="'rows'"):
        load_result(broken)
    tables = tmp_path / "tables.json"
    assert main([str(other), "--tables", str(tables)]) == 2
    assert not tables.exists()  # nothing half-written


def test_card_table_note_names_the_thresholds_and_sources():
    t = card_table(_result(), "out/alerts/alerts.json")
    assert "calibrated" in t.note and "out/alerts/alerts.json" in t.produced_by
