"""The airframe check: a flight whose moment balance no damage on the vehicle file's airframe explains
silences the network and is judged by physics alone, and says so; a nominal flight, and a large real fault, are
not flagged.

Judged on flights of the evaluation-only simulator (``offline/evalsim``: RotorPy dynamics, its own controller),
written to .tlog and read back through ``propwatch diagnose`` as a user's would. The check's threshold is the
shipped rule's (``models/classifier.sets.json``), calibrated on our own simulator only.
"""

from __future__ import annotations

import json

import evalsim_flights
import numpy as np
import pytest

pytest.importorskip("rotorpy")

from monitor.decision.effectiveness import SET_PRIOR  # noqa: E402
from monitor.decision.hypotheses import load_rule  # noqa: E402
from monitor.diagnose import cli  # noqa: E402
from monitor.diagnose.physics import airframe_log_bayes_factor  # noqa: E402
from monitor.resources import shipped  # noqa: E402
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle  # noqa: E402

V = load_vehicle(DEFAULT_VEHICLE)
ROUTE = ((8.0, 4.0, -9.0), (-6.0, 8.0, -11.0), (0.0, 0.0, -10.0), (5.0, -5.0, -10.0), (0.0, 0.0, -10.0))


def test_bayes_factor_is_the_log_ratio_of_the_two_evidences_by_hand():
    ll = np.zeros(16)
    assert airframe_log_bayes_factor(ll, ll) == 0.0
    assert airframe_log_bayes_factor(ll, ll + 2.0) == pytest.approx(2.0)  # every set 2 nats likelier
    # only the healthy set explains the flight under the nominal airframe, only {1} under the unmeasured one
    a, b = np.full(16, -50.0), np.full(16, -50.0)
    a[0], b[1] = 0.0, 0.0
    assert airframe_log_bayes_factor(a, b) == pytest.approx(np.log(SET_PRIOR[1] / SET_PRIOR[0]), abs=1e-3)


def _specs() -> list:
    from offline.evalsim.airframe import Airframe, Damage
    from offline.evalsim.environment import Wind
    from offline.evalsim.flight import FlightSpec

    def spec(name, seed, **af_kw):
        return FlightSpec(name, Airframe.from_vehicle(V, **af_kw), ROUTE, 30.0, seed, wind=Wind())

    return [
        spec("nominal", 1),
        spec("cg_2cm", 2, cg_offset_frd_m=(0.02, 0.0, 0.0)),
        spec("rotor3_20pct", 3, damage=Damage(thrust_loss_at_hover=(0.0, 0.0, 0.20, 0.0))),
    ]


evalsim_flights.declare(__name__, "diagnosed", _specs)


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    from offline.sim.io_tlog import write_tlog

    specs = _specs()
    d = tmp_path_factory.mktemp("airframe-check")
    out = {}
    for s, log in zip(specs, evalsim_flights.simulate_flights(specs), strict=True):
        path = write_tlog(d / f"{s.name}.tlog", log, 0)
        out[s.name] = path
    return out


def _run(path, capsys):
    rc = cli.main([str(path), "--json", "--vehicle", str(shipped("vehicle.yaml"))])  # the paper quad, declared
    return rc, json.loads(capsys.readouterr().out)


def test_the_shipped_rule_carries_a_check_calibrated_on_our_simulator():
    rule = load_rule(shipped("classifier.onnx"))
    assert rule.airframe_log_bayes_factor_max is not None and rule.unmeasured_threshold is not None
    assert rule.unmeasured_calibration_flights >= 100


def test_a_cg_offset_is_flagged_and_never_called_a_confident_fault(diagnosed, capsys):
    """The balance says the airframe is not its file's: the network (and the file's balance) go silent, physics
    alone judges, never confidently."""
    rc, d = _run(diagnosed["cg_2cm"], capsys)
    assert d["network"]["used"] is False and "balance of forces does not fit" in d["network"]["why_not"]
    assert "propwatch adapt" in d["network"]["why_not"] and d["rotor_effectiveness"] is None
    assert d["verdict"]["confidence"] != "confident" and rc == 3
    assert d["verdict"]["source"] == "first flight"


def test_a_nominal_flight_and_a_large_real_fault_are_not_flagged(diagnosed, capsys):
    rc, d = _run(diagnosed["nominal"], capsys)
    assert d["hypothesis_rule"]["airframe"] == "as its file says"
    assert d["verdict"]["faulty_propellers"] == []
    rc, d = _run(diagnosed["rotor3_20pct"], capsys)
    assert d["hypothesis_rule"]["airframe"] == "as its file says", d["hypothesis_rule"]
    assert d["verdict"]["faulty_propellers"] == [3]
