"""Every key of ``propwatch diagnose --json`` is documented in docs/diagnose-json.md, and every
always-present documented key is really produced (the doc neither lags nor invents)."""

from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path

import pytest
from test_diagnose_fixtures import build_model, write_tlog

from monitor.diagnose.cli import main as diagnose
from monitor.diagnose.engine import describe_label, rotor_name, round_floats

DOC = Path(__file__).resolve().parents[1] / "docs" / "diagnose-json.md"


def documented() -> dict[str, bool]:
    """path -> optional, from the doc's table rows ``| `path` | type | meaning |``."""
    rows = re.findall(r"^\| `([^`]+)` \| [^|]+ \| (.*) \|$", DOC.read_text(), re.M)
    assert len(rows) > 20, "the key table in docs/diagnose-json.md was not found"
    return {path: meaning.startswith("optional") for path, meaning in rows}


def key_paths(obj, prefix: str = "") -> set[str]:
    paths = set()
    if isinstance(obj, dict):
        for k, v in obj.items():
            p = f"{prefix}.{k}" if prefix else k
            paths |= {p} | key_paths(v, p)
    elif isinstance(obj, list):
        for v in obj:
            if isinstance(v, dict):
                paths |= key_paths(v, prefix + "[]")
    return paths


def float_values(obj):
    if isinstance(obj, float):
        yield obj
    elif isinstance(obj, dict):
        for v in obj.values():
            yield from float_values(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from float_values(v)


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("schema")
    model = build_model(d / "fixture.onnx")
    far = build_model(d / "far.onnx", trained_rpm=2000.0)
    faulty = write_tlog(d / "f3.tlog", duration_s=12.0, faulty=3, seed=3)
    junk = d / "junk.bin"
    junk.write_bytes(b"\x00\x01garbage" * 100)
    # the vehicle's own history: three healthy flights learnt into a baseline (vehicle memory's keys)
    from monitor.logs import read_log
    from monitor.memory.learn import learn_baseline
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

    esc = load_vehicle(DEFAULT_VEHICLE).esc
    healthy = [write_tlog(d / f"h{i}.tlog", duration_s=12.0, seed=10 + i) for i in range(3)]
    learn_baseline([read_log(h, esc=esc) for h in healthy], [h.name for h in healthy], vehicle_id="fixture").save(d / "B.json")
    runs = {
        "verdict": [faulty, "--model", model],
        "refusal": [faulty, "--model", far],
        "several": [faulty, junk, "--model", model],
        "memory": [faulty, "--model", model, "--baseline", d / "B.json"],
        "memory_refused": [faulty, "--model", far, "--baseline", d / "B.json"],
    }
    out = {}
    for name, argv in runs.items():
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
            diagnose([str(a) for a in argv] + ["--json"])
        out[name] = json.loads(buf.getvalue())
    return out


def test_every_key_is_documented(outputs):
    doc = documented()
    seen = set().union(*(key_paths(o) for o in outputs.values()))
    # results[] holds one-log objects: document them once, at the top level.
    seen = {p.removeprefix("results[].") for p in seen}
    undocumented = sorted(seen - set(doc))
    assert not undocumented, f"add these keys to {DOC.name}: {undocumented}"
    never_produced = sorted(p for p, optional in doc.items() if not optional and p not in seen)
    assert not never_produced, f"documented in {DOC.name} but never produced: {never_produced}"


def test_check_catches_an_undocumented_key(outputs):
    extra = dict(outputs["verdict"], surprise={"inner": 1})
    assert {"surprise", "surprise.inner"} <= key_paths(extra) - set(documented())


def test_floats_are_rounded(outputs):
    for o in outputs.values():
        for x in float_values(o):
            assert x == round(x, 6)
    assert round_floats({"t": [239.70000000000002, 1], "p": (0.1234567891,)}) == {"t": [239.7, 1], "p": [0.123457]}


def test_one_numbering_in_json_and_text(outputs, capsys):
    v = outputs["verdict"]
    assert v["verdict"]["label"] == 4 and v["verdict"]["faulty_propellers"] == [3]  # PX4 rotor 3 alone
    assert v["verdict"]["faulty_names"] == ["3"]
    assert [p["propeller"] for p in v["propellers"]] == [p["px4_rotor"] for p in v["propellers"]] == [1, 2, 3, 4]
    # A vehicle with its own names (CrazyPAD: PX4 rotor order M1, M3, M4, M2) keeps the PX4 numbers.
    names = ["M1", "M3", "M4", "M2"]
    assert describe_label(3, names) == "label 3: M3 (PX4 rotor 2) faulty"
    assert describe_label(1, names) == "label 1: no faulty propeller"
    assert rotor_name("3", 3) == "propeller 3" and rotor_name("M2", 4) == "M2 (PX4 rotor 4)"


def test_a_log_the_network_refuses_is_still_judged_against_the_vehicles_history(outputs):
    """The comparison with the vehicle's own flights needs no classifier: outside the network's envelope (a model
    trained at 2000 RPM) the nominal verdict is none, and vehicle memory's stands in its place."""
    assert outputs["refusal"]["network"]["used"] is False and outputs["refusal"]["verdict"]["source"] == "first flight"
    judged = outputs["memory_refused"]
    assert judged["verdict"]["source"] == "vehicle memory" and judged["verdict"]["nominal"]["label"] >= 1
    assert judged["verdict"]["faulty_propellers"] == judged["baseline"]["faulty_propellers"]
