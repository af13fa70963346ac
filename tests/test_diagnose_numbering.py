"""Diagnosis JSON in the vehicle's own propeller numbers (CrazyPAD's M1..M4), PX4 order otherwise."""

from monitor.diagnose.engine import Diagnosis, vehicle_numbers


def _diag(names):
    p = [0.1, 0.9, 0.2, 0.3]  # PX4 rotor 2 faulty
    d = Diagnosis("x", {"label": 3, "faulty_propellers": [2], "fault_probability": p}, 5, [])
    d.propellers = [{"propeller": i + 1, "name": n, "fault_probability": p[i], "faulty": i == 1} for i, n in enumerate(names)]
    d.label_probability = [0.0] * 16
    d.label_probability[2] = 1.0
    d.timeline = {"t_boot_s": [1.0], "fault_probability": [p], "label": [3]}
    return d


def test_crazypad_numbering_is_used_in_the_verdict():
    out = _diag(["M1", "M3", "M4", "M2"]).to_json()  # PX4 rotor 2 is Bitcraze M3
    assert out["verdict"] == {"label": 4, "faulty_propellers": [3], "fault_probability": [0.1, 0.3, 0.9, 0.2]}
    assert [p["name"] for p in out["propellers"]] == ["M1", "M2", "M3", "M4"]
    assert out["label_probability"][3] == 1.0 and sum(out["label_probability"]) == 1.0
    assert out["timeline"]["label"] == [4] and out["timeline"]["fault_probability"] == [[0.1, 0.3, 0.9, 0.2]]


def test_px4_numbering_is_left_alone():
    out = _diag(["1", "2", "3", "4"]).to_json()
    assert out["verdict"]["faulty_propellers"] == [2] and out["verdict"]["label"] == 3
    assert "propeller_numbering" not in out
    assert vehicle_numbers(["A", "B", "C", "D"]) is None
