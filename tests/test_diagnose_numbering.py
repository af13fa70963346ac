"""One numbering: the diagnosis JSON keeps PX4 rotor order and labels; the vehicle's names stand beside them."""

from monitor.diagnose.cli import format_text
from monitor.diagnose.engine import Diagnosis


def _diag(names):
    p = [0.1, 0.9, 0.2, 0.3]  # PX4 rotor 2 faulty
    faulty_names = [names[1]]
    d = Diagnosis("x", {"label": 3, "faulty_propellers": [2], "faulty_names": faulty_names, "fault_probability": p}, 5, [])
    d.propellers = [
        {"propeller": i + 1, "px4_rotor": i + 1, "name": n, "fault_probability": p[i], "faulty": i == 1}
        for i, n in enumerate(names)
    ]
    d.label_probability = [0.0] * 16
    d.label_probability[2] = 1.0
    d.timeline = {"t_boot_s": [1.0], "fault_probability": [p], "label": [3]}
    return d


def test_crazypad_names_stand_beside_px4_numbers():
    d = _diag(["M1", "M3", "M4", "M2"])  # PX4 rotor 2 is Bitcraze M3
    out = d.to_json()
    assert out["verdict"] == {
        "label": 3,
        "faulty_propellers": [2],
        "faulty_names": ["M3"],
        "fault_probability": [0.1, 0.9, 0.2, 0.3],
    }
    assert [p["name"] for p in out["propellers"]] == ["M1", "M3", "M4", "M2"]
    assert [p["px4_rotor"] for p in out["propellers"]] == [1, 2, 3, 4]
    assert out["label_probability"][2] == 1.0 and out["timeline"]["label"] == [3]
    text = format_text(d)
    # The text names the vehicle's own rotor and where it sits (PX4 rotor 2 is rear-left); no label number.
    assert "Propeller M3 (rear-left) is damaged: replace it." in text and "label" not in text
    assert "M3 rear-left REPLACE" in text and "M2 rear-right ok" in text


def test_px4_names_are_not_repeated():
    text = format_text(_diag(["1", "2", "3", "4"]))
    assert "Propeller 2 (rear-left) is damaged: replace it." in text and "2 rear-left REPLACE" in text
