"""Diagnose on a log whose propeller was damaged mid-flight answers with the in-flight rule, not the whole-flight mean.

The behaviour test uses flights of the evaluation-only simulator (offline/evalsim: RotorPy dynamics, its own
controller and damage model), which nothing trains or selects on: a propeller on each of the four rotors in
turn, damaged 25-38 s into an 80 s flight. The whole-flight verdict called three of these four healthy and
the fourth the wrong rotor (the healthy half outvotes the damaged one); a tool that guesses a rotor passes
one in four. The rotor's effectiveness is read after the change, against the flight's own balance before it.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
from types import SimpleNamespace

import evalsim_flights
import numpy as np
import pytest
from test_diagnose_fixtures import build_model, write_tlog
from test_diagnose_json_schema import documented, key_paths

from monitor.diagnose.cli import main as diagnose
from monitor.diagnose.engine import Diagnosis, apply_in_flight_fault
from monitor.logs.raw import airborne_mask
from monitor.resample import US_PER_S
from monitor.vehicle import REPO_ROOT
from offline.sim.log import BOOT_OFFSET_US

SHIPPED = REPO_ROOT / "models" / "classifier.onnx"


def run(argv) -> tuple[int, dict, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = diagnose([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def _onset_specs() -> list:
    from offline.evalsim.sets import build_set

    return build_set("onset", flights=4, seed=0)  # as write_set flies it below


evalsim_flights.declare(__name__, "evalsim_onsets", _onset_specs)


@pytest.fixture(scope="module")
def evalsim_onsets(tmp_path_factory):
    pytest.importorskip("rotorpy")
    from offline.evalsim.score import load_set
    from offline.evalsim.sets import write_set

    with evalsim_flights.shared():
        folder = write_set("onset", tmp_path_factory.mktemp("onset"), flights=4, seed=0)
    _, truths = load_set(folder)
    return [(folder / t["file"], t) for t in truths]


@pytest.mark.slow
@pytest.mark.skipif(not SHIPPED.is_file(), reason="models/classifier.onnx not built")
def test_a_propeller_damaged_mid_flight_is_named_on_flights_of_the_other_simulator(evalsim_onsets):
    doc = documented()
    for path, truth in evalsim_onsets:
        assert len(truth["faulty_propellers"]) == 1  # the set's first four flights: rotors 1, 2, 3, 4 alone
        code, out, _ = run([path, "--json", "--vehicle", SHIPPED.with_name("vehicle.yaml")])  # the paper quad
        res = json.loads(out)
        v = res["verdict"]
        assert v["faulty_propellers"] == truth["faulty_propellers"], (path.name, v)
        assert v["source"] == "in-flight change" and "whole_flight" in v
        onset_boot_s = BOOT_OFFSET_US / US_PER_S + truth["fault_onset_s"]
        assert onset_boot_s < v["change_boot_s"] < onset_boot_s + 15.0  # after the damage, within 15 s of it
        assert res["decision"]["in_flight_fault"]["first_fault_boot_s"] == v["change_boot_s"]
        # the hypotheses are the rule's sets, the verdict's first; the truth is among them
        sets = [h["faulty_propellers"] for h in res["hypotheses"]]
        assert sets[0] == v["faulty_propellers"] and truth["faulty_propellers"] in sets
        p = [h["probability"] for h in res["hypotheses"]]
        assert p == sorted(p, reverse=True) and abs(sum(p) - 1.0) < 2e-3  # weighed among the rule's sets
        assert all(h["evidence"].startswith("in-flight change") for h in res["hypotheses"])
        assert code == (0 if len(sets) == 1 else 3)
        # the moment balance reads the windows after the change against the flight's own before it: the damaged
        # rotor's thrust within 2 points of the truth (the whole flight's balance fits neither half, read 2-60 %)
        rotor = truth["faulty_propellers"][0]
        assert abs(res["rotor_effectiveness"][rotor - 1] - truth["thrust_factor_at_hover"][rotor - 1]) <= 0.02, res
        assert all(abs(x - 1.0) <= 0.02 for i, x in enumerate(res["rotor_effectiveness"]) if i + 1 != rotor)
        assert res["rotor_effectiveness_basis"].startswith("windows after the in-flight change")
        undocumented = sorted(key_paths(res) - set(doc))
        assert not undocumented, f"add these keys to docs/diagnose-json.md: {undocumented}"
    # the text says where the answer comes from
    _, text, _ = run([evalsim_onsets[2][0], "--vehicle", SHIPPED.with_name("vehicle.yaml")])
    assert re.search(r"\(from \d+ s after take-off\)", text) and "evidence: In-flight monitor: fault on" in text, text
    assert "possible: " in text, text


def test_a_flight_without_a_fault_level_change_keeps_the_whole_flight_verdict(tmp_path):
    model = build_model(tmp_path / "toy.onnx")
    tlog = write_tlog(tmp_path / "f3.tlog", duration_s=12.0, faulty=3, seed=3)
    _, out, _ = run([tlog, "--model", model, "--json"])
    res = json.loads(out)
    assert res["decision"]["alerts"] == [] and "in_flight_fault" not in res["decision"]
    assert res["verdict"].get("source") != "in-flight change" and "whole_flight" not in res["verdict"]


def test_the_in_flight_answer_replaces_the_verdict_and_keeps_the_whole_flight_one():
    d = Diagnosis("x.tlog", {"label": 1, "faulty_propellers": [], "faulty_names": [], "confidence": "ambiguous"}, 50, [])
    d.propellers = [{"propeller": i, "faulty": False, "suspect": False} for i in range(1, 5)]
    d.hypotheses = [{"faulty_propellers": [], "probability": 0.6}, {"faulty_propellers": [4], "probability": 0.4}]
    d.decision = {"alerts": [], "final": {}}
    apply_in_flight_fault(d, ["1", "2", "3", "4"])
    assert d.verdict["faulty_propellers"] == [] and "source" not in d.verdict  # no change: nothing moves
    d.decision["in_flight_fault"] = {"first_fault_boot_s": 40.0, "last_fault_boot_s": 70.0, "hypothesis_sets": [[3], [3, 4]]}
    apply_in_flight_fault(d, ["1", "2", "3", "4"])
    v = d.verdict
    assert (v["label"], v["faulty_propellers"], v["confidence"], v["change_boot_s"]) == (4, [3], "ambiguous", 40.0)
    assert v["whole_flight"]["faulty_propellers"] == [] and v["whole_flight"]["hypotheses"][1]["faulty_propellers"] == [4]
    assert [p["suspect"] for p in d.propellers] == [False, False, True, False] and not any(p["faulty"] for p in d.propellers)


def test_the_fleet_report_shows_a_ranked_set_without_a_probability():
    from fleet.report import _probability

    assert _probability({"faulty_propellers": [3], "probability": 0.25}) == "0.250"
    assert _probability({"faulty_propellers": [3], "evidence": "in-flight change"}) == "in-flight change"


LOG171 = REPO_ROOT.parent / "shared" / "data" / "ardupilot_log171" / "log171.bin"


@pytest.mark.skipif(not (LOG171.is_file() and SHIPPED.is_file()), reason="real ArduPilot log or shipped model missing")
def test_a_log_unlike_the_rules_calibration_flights_keeps_the_whole_flight_verdict():
    # A real ArduCopter flight of another quad, attitude at 10 Hz, ending in a flip: the in-flight rule reaches fault
    # level on it (network and ω² shares of a vehicle it was not calibrated for), which must not become the verdict.
    _, out, _ = run([LOG171, "--json"])
    res = json.loads(out)
    assert res["verdict"].get("source") != "in-flight change" and "whole_flight" not in res["verdict"]
    if "in_flight_fault" in res["decision"]:
        # why it is not: the network's attitude at 9.9 Hz or, physics alone (no airframe declared), the flip
        reasons = ("9.9 Hz", "beyond 45 deg")
        assert any("in-flight rule reached fault level" in w and any(r in w for r in reasons) for w in res["warnings"]), res[
            "warnings"
        ]


def _fault_events(tmp_path, tlog):
    from test_decision_daemon import replay_shipped

    _, alerts = replay_shipped(tmp_path, tlog)
    return [a for a in alerts if a["level"] == "fault" and a.get("rotor_effectiveness") is not None]


@pytest.mark.slow
@pytest.mark.skipif(not SHIPPED.is_file(), reason="models/classifier.onnx not built")
def test_the_daemons_alert_reads_the_damaged_rotor_against_the_flights_own_start(tmp_path, evalsim_onsets, monkeypatch):
    """The alert's rotor effectiveness (the last 5 s) is read against this flight's own balance before the change:
    on an airframe with its own motor spread and CG offset (our simulator, airframe drawn from the register) the
    nominal-airframe reading put the loss on another rotor (rotor 4 losing 8 %: read 1.00, rotor 2 read 0.94).

    Without blade flapping: the moment balance's baseline is a constant, and this flight draws the register's
    largest trim (0.025 per m/s) in 3 m/s of wind, which moves the balance with airspeed by more than the loss
    (read 1.00 for rotor 4, truth 0.93; docs/ALERTS.md, known limits). The decision's share baseline follows
    airspeed (tests/test_share_line.py); the effectiveness reading does not yet."""
    import offline.sim.assumptions as assumptions
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
    from offline.alerts.flights import FlightSet, randomised_chunks
    from offline.sim.io_tlog import write_tlog as write_sim_tlog

    monkeypatch.setattr(assumptions, "REGISTER", assumptions.REGISTER.with_range("blade_flapping_trim_per_m_s", 0.0, 0.0))

    vehicle = load_vehicle(DEFAULT_VEHICLE)
    ch = next(randomised_chunks(vehicle, FlightSet("single", n_flights=1, physics="randomised", seed=211)))
    rotor = int(ch.cond[0].nonzero()[0][0]) + 1
    truth = ch.hover_thrust_factors(0, ch.flog.signals()["motor_rpm"][0], vehicle, 80.0)[rotor - 1]
    assert truth < 0.95  # a loss the reading must find
    ours = _fault_events(tmp_path / "ours", write_sim_tlog(tmp_path / "ours.tlog", ch.flog, 0))
    path, t = evalsim_onsets[2]  # the other simulator: rotor 3
    other = _fault_events(tmp_path / "evalsim", path)
    readings = []
    for events, r, factor in ((other, 3, t["thrust_factor_at_hover"][2]), (ours, rotor, truth)):
        assert events, "no fault alert"
        eff = events[-1]["rotor_effectiveness"]
        readings.append((r, factor, eff))
        assert all(abs(x - 1.0) <= 0.02 for i, x in enumerate(eff) if i + 1 != r), eff
    r, factor, eff = readings[0]
    assert abs(eff[r - 1] - factor) <= 0.02, readings
    r, factor, eff = readings[1]
    if abs(eff[r - 1] - factor) > 0.02:
        # Known limit: the share rule, now calibrated with the airspeed plane, faults 8.5 s after this
        # onset, in a 32-deg manoeuvre; the 5 s before it read rotor 4 at 0.987 +- 0.009 against a truth of 0.924
        # (the rule at 5ea08db faulted later and read 0.917). The reading does not skip manoeuvres.
        pytest.xfail(f"effectiveness read in a manoeuvre: {readings[1]}")


def test_a_vehicle_baseline_does_not_overrule_the_in_flight_answer():
    """A propeller damaged mid-flight: the in-flight rule found the change against the flight's own start; the whole
    flight against the vehicle's history, which mixes the healthy part before it in, names nothing, so the change
    stands (``monitor.diagnose.memory_adapter``); where the history does name a fault, that is the verdict."""
    from test_vehicle_memory import QUIRKY, baseline_of, damaged, table

    from monitor.diagnose.memory_adapter import judge_flight

    def change_verdict():
        d = Diagnosis("x.tlog", {"label": 1, "faulty_propellers": [], "faulty_names": [], "confidence": "ambiguous"}, 50, [])
        d.propellers = [{"propeller": i, "faulty": False, "suspect": False} for i in range(1, 5)]
        d.label_probability = [1.0 / 16] * 16
        d.decision = {"in_flight_fault": {"first_fault_boot_s": 40.0, "last_fault_boot_s": 70.0, "hypothesis_sets": [[3]]}}
        apply_in_flight_fault(d, ["1", "2", "3", "4"])
        return d

    b = baseline_of()
    d = change_verdict()
    out = judge_flight(d, table(QUIRKY, seed=77), b, None)
    assert d.verdict["faulty_propellers"] == [3] and d.verdict["source"] == "in-flight change"
    assert "in-flight rule's change stands" in out["note"]
    d = change_verdict()
    judge_flight(d, damaged(1, 0.10), b, None)
    assert d.verdict["faulty_propellers"] == [1] and d.verdict["source"] == "vehicle memory"


def test_a_throttle_dip_in_flight_is_not_a_landing():
    """A mean motor command under lift throttle for a fraction of a second between two airborne stretches (evalsim's
    controller on a fast descent: 1104 us for 0.2 s) is flight, not a landing that would reset the in-flight rule;
    a stop on the ground longer than a second still ends the flight."""
    rate_hz, n = 20.0, 1200
    grid = (np.arange(n) * 50_000).astype(np.int64)
    cmd = np.full((n, 4), 1400.0)
    cmd[:100] = cmd[-100:] = 1000.0  # on the ground before and after
    cmd[300:305] = 1104.0  # a 0.25 s dip in flight
    cmd[600:640] = 1000.0  # 2 s on the ground: landed and took off again
    raw = SimpleNamespace(cmd_unit="us", armed=None, landed=None, height_m=None, min_height_m=0.25, lift_cmd=None)
    mask = airborne_mask(raw, grid, cmd, rate_hz)
    assert mask[300:305].all() and mask[100:600].all()
    assert not mask[600:640].any() and mask[640:1100].all() and not mask[:100].any() and not mask[1100:].any()


@pytest.mark.slow
def test_without_the_network_the_shares_name_the_propeller_damaged_mid_flight(evalsim_onsets, tmp_path):
    """The same four flights with the network silent (a model trained on another airframe, around 2000 RPM): the
    rule replayed on the shares and the yaw balance alone names each damaged rotor after its onset, and never a
    healthy one. A tool that guesses a rotor passes one in four."""
    far = build_model(tmp_path / "far.onnx", trained_rpm=2000.0)
    for path, truth in evalsim_onsets:
        code, out, _ = run([path, "--model", far, "--json"])
        res = json.loads(out)
        v = res["verdict"]
        assert res["network"]["used"] is False and res["decision"]["network"] is False
        assert v["source"] == "in-flight change", (path.name, v, res["warnings"])
        # the damaged rotor first; beside it at most its same-spin pair, which the shares cannot always rule out
        assert v["faulty_propellers"] == truth["faulty_propellers"], (path.name, v, res["hypotheses"])
        rotor = truth["faulty_propellers"][0]
        pair = [1, 2] if rotor in (1, 2) else [3, 4]
        assert all(h["faulty_propellers"] in ([rotor], pair) for h in res["hypotheses"]), res["hypotheses"]
        onset_boot_s = BOOT_OFFSET_US / US_PER_S + truth["fault_onset_s"]
        assert onset_boot_s < v["change_boot_s"] < onset_boot_s + 15.0
        assert code == (0 if v["confidence"] == "confident" else 3)
