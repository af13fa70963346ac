"""CrazyPAD real flights: manifest and split, reader mapping, hover physics, calibration gain.

Reads ../shared/data/crazypad; every test skips with the reason when it is absent.
"""

from __future__ import annotations

import csv
import gzip

import numpy as np
import pytest

from monitor.vehicle import REPO_ROOT, load_vehicle
from offline.crazypad.data import DEFAULT_ROOT, cut_total_mm, load_manifest, select
from offline.crazypad.vehicle import hover_cmd

pytestmark = [
    pytest.mark.realdata,
    pytest.mark.skipif(
        not (DEFAULT_ROOT / "manifest.csv").is_file(),
        reason=f"CrazyPAD data not found at {DEFAULT_ROOT} (../shared/data/crazypad)",
    ),
]


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle(REPO_ROOT / "models" / "crazyflie.yaml")


@pytest.fixture(scope="module")
def flights():
    return load_manifest()


@pytest.mark.parametrize(
    "name, mm",
    [
        ("cut_propeller_M3_0.5mm_46.5mm", 0.5),
        ("cut_propeller_M3_1mm", 1.0),
        ("cut_propeller_M3_3mm", 3.0),
        ("cut_propeller_M3_1mm_0.5mm_45.5mm", 1.5),
        ("cut_propeller_M3_4mm_4mm_39mm", 8.0),
        ("cut_m3_2mm_2mm", 4.0),
    ],
)
def test_cut_depth_from_folder_names(name, mm):
    assert cut_total_mm(name) == pytest.approx(mm)


def test_split_is_fixed_and_disjoint(flights):
    assert len(flights) == 260
    motor = select(flights)
    cal, hold = select(flights, role="calibration"), select(flights, role="holdout")
    assert all(f.fault_kind == "healthy" for f in cal + hold)
    assert {f.file for f in cal}.isdisjoint({f.file for f in hold})
    assert {f.airframe for f in cal} == {f.airframe for f in hold} == {"E8", "E9"}
    assert len(cal) + len(hold) == sum(f.fault_kind == "healthy" for f in motor)
    # Nothing that is not healthy is ever fitted.
    assert all(f.role == "evaluation" for f in flights if f.fault_kind != "healthy")


def test_reader_maps_bitcraze_motors_onto_px4_order(flights, vehicle):
    from offline.crazypad.real import read_flight

    f = select(flights, role="calibration")[0]
    tab = read_flight(f, vehicle)
    assert tab.motor_names == ("M1", "M3", "M4", "M2")
    # Golden check against the raw columns: the first airborne grid instant holds some CSV row exactly.
    with gzip.open(DEFAULT_ROOT / f.file, "rt", newline="") as fh:
        rows = list(csv.DictReader(fh))
    raw = np.array([[float(r[f"motor.m{k}"]) for k in (1, 3, 4, 2)] for r in rows])
    i = int(np.flatnonzero(tab.airborne)[0])
    assert np.any(np.all(raw == tab.motor_cmd[i], axis=1))
    assert not np.any(np.all(raw == tab.motor_cmd[i][[0, 3, 1, 2]], axis=1))  # the Bitcraze order would not match


def test_hover_command_lies_in_the_real_airborne_range(flights, vehicle):
    from offline.crazypad.real import summarise

    means = [summarise(f, vehicle).mean_cmd for f in select(flights, role="calibration")]
    assert min(means) < hover_cmd(vehicle) < max(means)


def test_calibration_names_a_cause_and_helps_held_out_flights(flights, vehicle):
    from offline.calibrate.fit import calibrate_steady
    from offline.crazypad.real import summarise

    for af in ("E8", "E9"):
        fit = [summarise(f, vehicle) for f in select(flights, role="calibration", airframe=af)]
        held = [summarise(f, vehicle) for f in select(flights, role="holdout", airframe=af)]
        cal = calibrate_steady(
            af, vehicle, np.array([s.motor_cmd_mean for s in fit]), np.array([s.motor_cmd_mean for s in held]), [], []
        )
        # The static spread is a yaw-pair pattern (M1, M3 high): a CG offset cannot make it.
        assert cal.cause == "motor_efficiency"
        assert cal.calibrated_holdout_rms_cmd < 0.5 * cal.nominal_holdout_rms_cmd
        ranks = [r.name for r in cal.ranking]
        assert ranks.index("motor_efficiency") < ranks.index("cg_offset")


def test_calibrated_vehicle_file_round_trips(flights, vehicle, tmp_path):
    from monitor.vehicle import load_vehicle_with_sources
    from offline.calibrate.fit import calibrate_steady
    from offline.crazypad.experiment import write_vehicle
    from offline.crazypad.real import summarise

    fit = np.array([summarise(f, vehicle).motor_cmd_mean for f in select(flights, role="calibration", airframe="E9")])
    cal = calibrate_steady("E9", vehicle, fit, fit, [], [])
    nominal = load_vehicle_with_sources(REPO_ROOT / "models" / "crazyflie.yaml")
    back = load_vehicle_with_sources(write_vehicle(cal, nominal.sources, tmp_path / "e9.yaml"))
    assert back.config == cal.calibrated
    assert "steady-state calibration" in back.sources["motor_efficiency"]
    assert back.provenance["config"]["cause"] == "motor_efficiency"
