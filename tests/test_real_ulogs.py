"""The three real PX4 ULogs in ../shared/data/px4_ulog get the answers its README expects.

- sample.ulg: a real quadrotor on the bench, never armed: no airborne flight.
- sample_log_small.ulg: a real VTOL (MAV_TYPE 22): refused by name, not a quad-X multicopter.
- sample_px4_events.ulg: a short healthy SITL quadrotor flight: no false fault.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from monitor.diagnose.cli import main as diagnose
from monitor.logs import read_log

ULOGS = Path(__file__).resolve().parents[2] / "shared" / "data" / "px4_ulog"
PAPER_QUAD = Path(__file__).resolve().parents[1] / "models" / "vehicle.yaml"

pytestmark = [
    pytest.mark.realdata,
    pytest.mark.skipif(not (ULOGS / "sample.ulg").is_file(), reason=f"real PX4 ULogs not found at {ULOGS} (../shared/data)"),
]


def _diagnose(capsys, name: str, *extra) -> tuple[int, dict]:
    code = diagnose([str(ULOGS / name), "--json", *map(str, extra)])
    return code, json.loads(capsys.readouterr().out)


def test_bench_log_never_armed_has_no_airborne_flight(capsys):
    code, out = _diagnose(capsys, "sample.ulg")
    assert code == 1 and out["verdict"] is None
    assert out["reason"].startswith("no airborne flight found")
    assert out["airborne_segments"] == []
    assert read_log(ULOGS / "sample.ulg").extras["vehicle_type"] == "MAV_TYPE_QUADROTOR (2)"


def test_vtol_is_refused_by_name(capsys):
    code, out = _diagnose(capsys, "sample_log_small.ulg")
    assert code == 1 and out["verdict"] is None and out["windows"] == 0
    assert out["reason"].startswith("not a quad-X multicopter") and "(22)" in out["reason"]


def test_sitl_flight_gets_no_false_fault(capsys):
    # Nothing declares PX4's SITL quad to be the network's airframe: physics alone, no propeller named.
    code, out = _diagnose(capsys, "sample_px4_events.ulg")
    assert code == 3 and out["network"]["used"] is False and out["network"]["why_not"].startswith("the network knows")
    assert out["verdict"]["source"] == "first flight" and out["verdict"]["faulty_propellers"] == []
    assert out["summary"]["state"] == "healthy" and out["summary"]["propellers"] == []
    # Declared as the paper's quad, the network speaks too.
    code, out = _diagnose(capsys, "sample_px4_events.ulg", "--vehicle", PAPER_QUAD)
    # Healthy is the verdict; 3 when the conformal set keeps a same-spin pair beside it (physics cannot exclude
    # one from 11 s of 10 Hz outputs): never a propeller marked FAULTY.
    assert code in (0, 3) and out["verdict"]["label"] == 1 and out["verdict"]["faulty_propellers"] == []
    assert out["hypotheses"][0]["faulty_propellers"] == [] and not any(p["faulty"] for p in out["propellers"])
    assert out["windows"] >= 1 and len(out["airborne_segments"]) == 1
    assert max(out["verdict"]["fault_probability"]) < 0.5
    assert any("motor_cmd logged at 10.0 Hz" in w for w in out["warnings"])  # outputs below 20 Hz, said
