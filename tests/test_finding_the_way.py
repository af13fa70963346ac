"""Messages that tell a new user what to do next ("finding the way")."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from monitor.cli import main as propwatch
from monitor.errors import LogFormatError
from monitor.logs import detect_format
from monitor.logs.csvlog import load_formats
from monitor.resources import shipped
from monitor.vehicle import vehicles_for_cmd_unit

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
CRAZYPAD_CUT = DATA / "crazypad" / "motor" / "cut_propeller_M3_4mm_4mm_39mm" / "E8_log00.csv.gz"


def test_empty_file_is_called_empty(tmp_path):
    empty = tmp_path / "flight.tlog"
    empty.write_bytes(b"")
    with pytest.raises(LogFormatError, match="empty file"):
        detect_format(empty)


def test_csv_without_format_lists_the_format_names(tmp_path, capsys):
    csv = tmp_path / "x.csv"
    csv.write_text("a,b\n1,2\n")
    assert propwatch(["diagnose", str(csv)]) == 2
    err = capsys.readouterr().err
    for name in load_formats():
        assert name in err
    assert "crazypad" in err


def test_the_crazyflie_is_the_shipped_vehicle_for_cf16_commands():
    assert vehicles_for_cmd_unit("cf16") == [shipped("crazyflie.yaml")]
    assert vehicles_for_cmd_unit("no-such-unit") == []


@pytest.mark.realdata
@pytest.mark.skipif(not CRAZYPAD_CUT.is_file(), reason=f"CrazyPAD data not found at {CRAZYPAD_CUT}")
def test_crazypad_without_vehicle_suggests_it(capsys):
    # The paper quad's model takes PWM microseconds: it is silent, the shares of the raw outputs judge the flight,
    # and the next step says to diagnose again with the Crazyflie's own vehicle file.
    assert propwatch(["diagnose", str(CRAZYPAD_CUT), "--format", "crazypad", "--json"]) == 3
    out = json.loads(capsys.readouterr().out)
    assert out["network"]["used"] is False and "--vehicle models/crazyflie.yaml" in out["network"]["why_not"]
    assert "--vehicle models/crazyflie.yaml" in out["summary"]["next_step"]


def test_report_says_where_it_wrote(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from test_diagnose_fixtures import build_model, write_tlog

    log = write_tlog(tmp_path / "f.tlog", duration_s=10.0, faulty=2, seed=1)
    model = build_model(tmp_path / "m.onnx")
    propwatch(["diagnose", str(log), "--model", str(model), "--report", str(tmp_path / "rep"), "--json"])
    captured = capsys.readouterr()
    json.loads(captured.out)  # stdout stays pure JSON
    assert f"report: {tmp_path / 'rep' / 'f.tlog.html'} and {tmp_path / 'rep' / 'f.tlog.png'}" in captured.err
