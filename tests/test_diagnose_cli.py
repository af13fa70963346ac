"""``propwatch diagnose``: verdicts on synthetic faulty logs, JSON contract, reports,
refusals outside the model's envelope, errors, and the real logs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_diagnose_fixtures import HOVER_PWM_US, build_model, write_tlog

from monitor.cli import main as propwatch
from monitor.diagnose.cli import main as diagnose
from monitor.esc import PAPER_ESC

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
LOG171 = DATA / "ardupilot_log171" / "log171.bin"
CRAZYPAD_HEALTHY = DATA / "crazypad" / "motor" / "normal_flight" / "E8_log00.csv.gz"


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return build_model(tmp_path_factory.mktemp("model") / "fixture.onnx")


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("logs")
    # A damaged rotor's output 120 us above the others': enough for its share to stand out beyond healthy airframes
    # (monitor.diagnose.shares), so physics and the toy network agree and a confident verdict may be given.
    return {k: write_tlog(d / f"f{k}.tlog", duration_s=25.0, faulty=k or None, seed=k, excess_pwm=120.0) for k in range(5)}


def run(capsys, *argv) -> tuple[int, dict]:
    code = diagnose([str(a) for a in argv])
    out = capsys.readouterr().out
    return code, json.loads(out) if "--json" in argv else out


@pytest.mark.parametrize("faulty", [0, 1, 2, 3, 4])
def test_verdict_names_the_faulty_propeller(capsys, model, logs, faulty):
    code, res = run(capsys, logs[faulty], "--model", model, "--json")
    # 3 = a verdict that is not confident (the fixture model is not always sure); the label is still named
    assert code == (0 if res["verdict"]["confidence"] == "confident" else 3), res["verdict"]
    v = res["verdict"]
    assert v["label"] == faulty + 1  # label 1 = no fault, 2..5 = propeller 1..4 alone
    assert v["faulty_propellers"] == ([faulty] if faulty else [])
    p = v["fault_probability"]
    assert len(p) == 4 and all(0.0 <= x <= 1.0 for x in p)
    if faulty:
        assert p[faulty - 1] == max(p) and p[faulty - 1] > 0.5
    # One airborne segment (IN_AIR 2..23 s); a 100-step window every 20 steps inside it.
    (seg,) = res["airborne_segments"]
    assert 400 <= seg["steps"] <= 420 and res["windows"] == (seg["steps"] - 100) // 20 + 1
    assert len(res["timeline"]["t_boot_s"]) == res["windows"] == len(res["timeline"]["fault_probability"])
    assert res["warnings"] == [] and res["hop_steps"] == 20


def test_every_named_feature_is_fed_from_the_log(capsys, logs, tmp_path):
    # A model may ask for any feature of monitor.features (derived ones such as the shipped model's
    # yaw_moment_krpm2 and collective_krpm2 included): diagnose must find the signals each needs.
    from monitor.features import FEATURES, PAPER_FEATURES

    names = PAPER_FEATURES + tuple(n for n in FEATURES if n not in PAPER_FEATURES)
    code, res = run(capsys, logs[3], "--model", build_model(tmp_path / "all.onnx", features=names), "--json")
    assert code == 0 and res["verdict"]["faulty_propellers"] == [3], res


def test_text_output_and_hop(capsys, model, logs):
    code, out = run(capsys, logs[2], "--model", model)
    assert code == 0 and "Propeller 2 (rear-left) is damaged: replace it." in out and "2 rear-left REPLACE" in out
    assert "label" not in out and "s after take-off" in out
    _, every = run(capsys, logs[2], "--model", model, "--json", "--hop", "1")
    _, sparse = run(capsys, logs[2], "--model", model, "--json", "--hop", "7")
    t_every, t_sparse = every["timeline"]["t_boot_s"], sparse["timeline"]["t_boot_s"]
    assert set(t_sparse) <= set(t_every) and abs(len(t_every) / 7 - len(t_sparse)) <= 1
    assert np.allclose(np.diff(t_sparse), 7 / 20.0)  # one window every 7 steps of the 20 Hz grid


def test_several_logs_one_result_each_and_errors_do_not_stop_the_rest(capsys, model, logs, tmp_path):
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01garbage" * 100)
    code, res = run(capsys, logs[1], junk, logs[4], "--model", model, "--json")
    assert code == 2  # one log could not be read
    r = res["results"]
    assert [x["log"] for x in r] == [str(logs[1]), str(junk), str(logs[4])]
    assert r[0]["verdict"]["label"] == 2 and r[2]["verdict"]["label"] == 5
    assert "unknown log format" in r[1]["error"]


def test_report_writes_png_and_html(capsys, model, logs, tmp_path):
    pytest.importorskip("matplotlib")
    out = tmp_path / "report"
    code, _ = run(capsys, logs[3], "--model", model, "--report", out)
    assert code == 0
    html = (out / "f3.tlog.html").read_text()
    png = out / "f3.tlog.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    assert "Propeller 3 (front-left) is damaged: replace it." in html and "f3.tlog.png" in html and "Airborne" in html


def test_outside_envelope_is_not_classified_but_judged_by_physics(capsys, logs, tmp_path):
    # A model trained around 2000 RPM must not classify a vehicle hovering near 7100 RPM (1500 µs): the network is
    # silent, and the flight is judged by its shares alone (never a confident verdict on a first flight).
    far = build_model(tmp_path / "far.onnx", trained_rpm=2000.0)
    code, res = run(capsys, logs[1], "--model", far, "--json")
    assert code == 3 and res["windows"] == 0 and res["reason"] is None
    assert res["network"]["used"] is False and "outside the model's envelope" in res["network"]["why_not"]
    assert res["verdict"]["source"] == "first flight" and res["verdict"]["confidence"] != "confident"
    assert any(w.startswith("physics only: this airframe is not the one the network was trained on") for w in res["warnings"])
    assert res["envelope"]["trained_mean_rpm"] == 2000.0 and res["envelope"]["rpm_ratio"] > 3
    assert res["envelope"]["rpm_z"] > 4
    # Moderately off (x1.2, about 1.2 training std): beyond the envelope's warning bound, so silent too.
    near = build_model(tmp_path / "near.onnx", trained_rpm=float(PAPER_ESC.cmd_to_rpm(HOVER_PWM_US)) / 1.2)
    code, res = run(capsys, logs[0], "--model", near, "--json")
    assert code == 3 and res["verdict"]["label"] == 1 and res["network"]["used"] is False
    assert "outside the model's envelope" in res["network"]["why_not"]


def test_errors_exit_non_zero_through_propwatch(capsys, model, tmp_path):
    assert propwatch(["diagnose", str(tmp_path / "missing.tlog"), "--model", str(model)]) == 2
    assert "No such file" in capsys.readouterr().err
    csv = tmp_path / "x.csv"
    csv.write_text("a,b\n1,2\n")
    assert propwatch(["diagnose", str(csv), "--model", str(model)]) == 2
    assert "--format" in capsys.readouterr().err
    assert propwatch(["diagnose", str(csv), "--model", str(tmp_path / "none.onnx")]) == 2
    assert "model file not found" in capsys.readouterr().err


@pytest.mark.realdata
@pytest.mark.skipif(not LOG171.is_file(), reason=f"real ArduPilot log not found at {LOG171}")
def test_log171_gets_a_verdict_or_a_reason(capsys, model):
    code, res = run(capsys, LOG171, "--model", model, "--json")
    assert code in (0, 1, 3)
    assert (res["verdict"] is not None) != (res["reason"] is not None)
    assert any("9.9 Hz" in w for w in res["warnings"])  # ATT/RATE at 10 Hz, below the 20 Hz grid
    assert any("beyond 45 deg" in w for w in res["warnings"])  # the flip at the end
    if res["verdict"] is not None:
        assert res["windows"] > 100


@pytest.mark.realdata
@pytest.mark.skipif(not CRAZYPAD_HEALTHY.is_file(), reason=f"CrazyPAD data not found at {CRAZYPAD_HEALTHY}")
def test_crazypad_with_a_px4_model_is_outside_the_envelope(capsys, model, tmp_path):
    code, res = run(capsys, CRAZYPAD_HEALTHY, "--format", "crazypad", "--model", model, "--json")
    # The network is silent (its ESC curve takes another unit); the shares of the raw outputs still judge the flight.
    assert code == 3 and res["network"]["used"] is False and res["shares"]["basis"] == "command"
    assert "outside the model's envelope" in res["network"]["why_not"] and "'cf16'" in res["network"]["why_not"]
    assert res["verdict"]["source"] == "first flight" and res["verdict"]["faulty_propellers"] == []
    assert any("'cf16'" in w for w in res["warnings"])
    # With a Crazyflie ESC curve the RPM is known, but pitch and body rates are not logged in this config.
    cf = build_model(
        tmp_path / "cf.onnx",
        esc={
            "a_rpm_per_cmd2": 0.0,
            "b_rpm_per_cmd": 0.2685,
            "c_rpm": 4070.3,
            "cmd_min": 0.0,
            "cmd_max": 65535.0,
            "cmd_unit": "cf16",
        },
        trained_rpm=15000.0,
    )
    code, res = run(capsys, CRAZYPAD_HEALTHY, "--format", "crazypad", "--model", cf, "--json")
    assert code == 3 and "pitch_rad unknown during flight" in res["network"]["why_not"]
    assert res["verdict"]["source"] == "first flight" and res["shares"]["basis"] == "omega2"


def test_reports_of_same_named_logs_do_not_overwrite(capsys, model, tmp_path):
    pytest.importorskip("matplotlib")
    a = write_tlog((tmp_path / "a").mkdir() or tmp_path / "a" / "E8_log00.tlog", duration_s=12.0, faulty=1)
    b = write_tlog((tmp_path / "b").mkdir() or tmp_path / "b" / "E8_log00.tlog", duration_s=12.0, faulty=4)
    out = tmp_path / "report"
    for _ in range(2):  # a second run overwrites its own reports, never the other log's
        run(capsys, a, b, "--model", model, "--report", out)
    pages = sorted(p.name for p in out.glob("*.html"))
    assert pages == ["E8_log00.tlog-2.html", "E8_log00.tlog.html"]
    assert str(a) in (out / "E8_log00.tlog.html").read_text() and str(b) in (out / "E8_log00.tlog-2.html").read_text()


def test_a_verdict_below_the_stated_probability_is_not_faulty_and_exits_3(capsys, model, logs, monkeypatch):
    import monitor.diagnose.engine as engine
    from monitor.decision.config import DecisionConfig

    code, res = run(capsys, logs[2], "--model", model, "--json")
    assert code == 0 and res["verdict"]["confidence"] == "confident"
    sure = res["verdict"]["label_probability_of_verdict"]
    # The same log, with FAULTY required above what this verdict reaches: no confident verdict.
    monkeypatch.setattr(engine, "DecisionConfig", lambda: DecisionConfig(faulty_probability=min(0.99999, sure + 1e-4)))
    code, res = run(capsys, logs[2], "--model", model, "--json")
    v = res["verdict"]
    assert code == 3 and v["confidence"] in ("suspect", "uncertain") and v["faulty_propellers"] == [2]
    assert v["label_probability_of_verdict"] == sure and 0.0 <= v["agreeing_windows"] <= 1.0
    assert not any(p["faulty"] for p in res["propellers"])
    code, out = run(capsys, logs[2], "--model", model)
    assert code == 3 and "REPLACE" not in out and "Propeller 2 (rear-left) may be damaged (not sure)" in out


def test_a_conformal_rule_beside_the_model_gives_the_hypothesis_set(capsys, model, logs, tmp_path):
    import shutil

    from monitor.decision.hypotheses import rule_path

    ruled = tmp_path / "ruled.onnx"
    shutil.copy(model, ruled)

    def with_threshold(thr):
        rule = {"rule": {"score": "classifier x moment balance", "threshold": thr, "coverage": 0.95, "calibration_flights": 160}}
        rule_path(ruled).write_text(json.dumps(rule))
        return run(capsys, logs[2], "--model", ruled, "--json")

    # A threshold only the best set reaches: one hypothesis, confident, FAULTY.
    code, res = with_threshold(0.999999)
    assert [h["faulty_propellers"] for h in res["hypotheses"]] == [res["verdict"]["faulty_propellers"]]
    assert res["hypothesis_rule"]["threshold"] == 0.999999 and res["hypothesis_rule"]["calibration_flights"] == 160
    assert code == 0 and res["verdict"]["confidence"] == "confident"
    assert [p["px4_rotor"] for p in res["propellers"] if p["faulty"]] == res["verdict"]["faulty_propellers"]
    # A threshold every set reaches: all 16 are possible, so nothing is called FAULTY and the exit code says so.
    code, res = with_threshold(1e-300)
    assert len(res["hypotheses"]) == 16 and res["verdict"]["confidence"] == "ambiguous" and code == 3
    p = [h["probability"] for h in res["hypotheses"]]
    assert p == sorted(p, reverse=True) and res["verdict"]["faulty_propellers"] == res["hypotheses"][0]["faulty_propellers"]
    assert not any(x["faulty"] for x in res["propellers"])
    code, out = run(capsys, logs[2], "--model", ruled)
    assert code == 3 and "Not sure: 16 possible damage patterns" in out and "why not sure:" in out and "REPLACE" not in out
    rule_path(ruled).write_text("{")  # a damaged rule is an error naming the file, not a silent fallback
    assert diagnose([str(logs[2]), "--model", str(ruled), "--json"]) == 2
    assert "ruled.sets.json" in capsys.readouterr().err


def test_with_a_set_rule_the_fault_probability_is_the_verdicts_own_score(capsys, model, logs, tmp_path):
    # A rule beside the model fuses and reweighs the network's label probabilities (here: a sparsity prior,
    # 0.1 per damaged propeller); the verdict is that score's best set, and its per-propeller probabilities must
    # be the same score's marginals, not the network's, or a verdict could name a propeller the probabilities
    # call unlikely. The network's own mean stays, under its own key.
    import shutil

    from monitor.decision.hypotheses import flight_score, rule_path
    from monitor.labels import LABEL_TABLE

    _, plain = run(capsys, logs[2], "--model", model, "--json")
    assert "network_fault_probability" not in plain["verdict"]
    ruled = tmp_path / "ruled.onnx"
    shutil.copy(model, ruled)
    rule = {"score": "classifier", "threshold": 0.05, "coverage": 0.95, "calibration_flights": 160}
    rule_path(ruled).write_text(json.dumps({"rule": {**rule, "sparsity_prior": 0.1}}))
    _, res = run(capsys, logs[2], "--model", ruled, "--json")
    v = res["verdict"]
    np.testing.assert_allclose(v["network_fault_probability"], plain["verdict"]["fault_probability"], atol=1e-9)
    scores = flight_score(np.asarray(res["label_probability"]), None, "classifier", 0.1)
    by_hand = [sum(scores[k - 1] for k in LABEL_TABLE if rotor in LABEL_TABLE[k]) for rotor in (1, 2, 3, 4)]
    np.testing.assert_allclose(v["fault_probability"], by_hand, atol=1e-6)
    assert [p["fault_probability"] for p in res["propellers"]] == v["fault_probability"]
    best = res["hypotheses"][0]
    assert v["faulty_propellers"] == best["faulty_propellers"]
    for rotor in best["faulty_propellers"]:  # every named propeller is at least as likely as the set naming it
        assert v["fault_probability"][rotor - 1] >= best["probability"] - 1e-4
    # The prior moved probability off the network's: a score that merely copied it would fail here.
    assert not np.allclose(v["fault_probability"], v["network_fault_probability"], atol=1e-3)
