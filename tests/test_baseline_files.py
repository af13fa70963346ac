"""``propwatch baseline`` respects the files it is given: it never overwrites a file that is not a baseline, learning
into a baseline keeps its notes and history, a flight log given as a baseline is named as one, and two logs with one
file name are told apart by their paths."""

from __future__ import annotations

import json
import re
import shutil

import pytest

from monitor.memory.cli import main as baseline
from offline.simulate import SimulateSpec, write_flights


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    """Four healthy 20 s flights of simulated vehicle 5, one a day."""
    out = tmp_path_factory.mktemp("quad5")
    files = write_flights(out, SimulateSpec(flights=4, duration_s=20.0, vehicle_id=5, propellers="quadratic"))
    return [str(f) for f in files[:-1]]


def test_learn_never_overwrites_a_flight_log_or_another_file(flights, tmp_path, capsys):
    log = tmp_path / "flight.tlog"
    shutil.copy(flights[3], log)
    before = log.read_bytes()
    assert baseline(["learn", *flights[:3], "--out", str(log)]) == 2
    err = capsys.readouterr().err
    assert f"--out {log} is a flight log (a MAVLink telemetry log), not a baseline: nothing overwritten" in err, err
    assert log.read_bytes() == before
    notes = tmp_path / "notes.json"
    notes.write_text('{"format": "my-notes"}\n')
    assert baseline(["learn", *flights[:3], "--out", str(notes)]) == 2
    assert f"--out {notes} exists and is not a baseline" in capsys.readouterr().err
    assert notes.read_text() == '{"format": "my-notes"}\n'


def test_learning_into_a_baseline_keeps_its_notes_and_history(flights, tmp_path, capsys):
    b = tmp_path / "quad5.json"
    assert baseline(["learn", *flights[:3], "--out", str(b)]) == 0
    assert baseline(["note", str(b), "--event", "props-replaced", "--date", "2024-06-03"]) == 0
    capsys.readouterr()
    assert baseline(["learn", *flights[1:], "--out", str(b)]) == 0
    out = capsys.readouterr().out
    assert "learnt into the baseline it held: 3 flights added, its 3 earlier flights and 1 note kept" in out, out
    d = json.loads(b.read_text())
    assert [e["event"] for e in d["events"]] == ["props-replaced"]
    assert len(d["flights"]) == 6 and {f["epoch"] for f in d["flights"]} == {0, 1}  # history, then the new normal
    assert baseline(["learn", *flights[1:], "--out", str(b)]) == 0  # the same flights again add nothing
    assert len(json.loads(b.read_text())["flights"]) == 6


def test_show_on_a_flight_log_says_so(flights, capsys):
    assert baseline(["show", flights[0]]) == 2
    err = capsys.readouterr().err
    assert f"{flights[0]} is a flight log, not a baseline" in err and "codec" not in err, err


def test_show_gives_shares_in_percent_named_by_rotor(flights, tmp_path, capsys):
    b = tmp_path / "B.json"
    assert baseline(["learn", *flights[:3], "--out", str(b)]) == 0
    capsys.readouterr()
    assert baseline(["show", str(b)]) == 0
    text = capsys.readouterr().out
    normal = next(line for line in text.splitlines() if line.strip().startswith("normal:"))
    shares = re.findall(r"(\S+) ([0-9.]+) %", normal)
    assert [name for name, _ in shares] == ["1", "2", "3", "4"], text
    assert all(float(x) == pytest.approx(100.0, abs=5.0) for _, x in shares), text  # near the rotors' mean, in percent


def test_logs_with_one_file_name_are_named_by_their_paths(tmp_path, capsys):
    for run in ("a", "b", "c"):
        write_flights(tmp_path / run, SimulateSpec(duration_s=20.0, propellers="quadratic"))  # no vehicle id
    logs = [str(tmp_path / run / "flight_000.tlog") for run in ("a", "b", "c")]
    assert baseline(["learn", *logs, "--out", str(tmp_path / "B.json")]) == 2
    err = capsys.readouterr().err
    assert all(p in err for p in logs) and "no vehicle identity in the log: give --vehicle-id" in err, err


def _diagnose_text(capsys, log, b) -> str:
    from monitor.cli import main as propwatch

    propwatch(["diagnose", str(log), "--baseline", str(b)])
    return capsys.readouterr().out


def test_diagnose_says_when_nothing_ties_the_log_to_the_baseline(flights, tmp_path, capsys):
    b = tmp_path / "B.json"
    assert baseline(["learn", *flights[1:], "--out", str(b)]) == 0  # flights of 2024-06-02 to 06-04
    capsys.readouterr()
    text = _diagnose_text(capsys, flights[1], b)
    assert "(but this log is one of the baseline's own flights (flight_001.tlog): compared with itself)" in text.replace(
        "\n    ", " "
    ), text
    text = _diagnose_text(capsys, flights[0], b).replace("\n    ", " ")
    assert "(but this flight (2024-06-01) is older than the baseline's newest flight (2024-06-04))" in text, text
    anon = write_flights(tmp_path / "anon", SimulateSpec(duration_s=20.0, first_flight=5, propellers="quadratic"))[0]
    text = _diagnose_text(capsys, anon, b).replace("\n    ", " ")
    assert "(but this log carries no vehicle id: nothing ties it to vehicle 5057000000000005)" in text, text
    from monitor.cli import main as propwatch

    propwatch(["diagnose", str(anon), "--baseline", str(b), "--json"])
    assert json.loads(capsys.readouterr().out)["baseline"]["caveats"] == [
        "this log carries no vehicle id: nothing ties it to vehicle 5057000000000005"
    ]
    text = _diagnose_text(capsys, write_flights(tmp_path / "later", SimulateSpec(duration_s=20.0, vehicle_id=5,
                                                 first_flight=4, propellers="quadratic"))[0], b)  # fmt: skip
    assert "(but" not in text and "caveat" not in text, text  # a later flight of the vehicle: nothing to say
