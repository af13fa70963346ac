"""``propwatch simulate`` flies one vehicle's flights: a date per flight, a landing at the end of each, the board's
id with ``--vehicle-id``, damage that starts in the air with ``--onset`` and a stopped motor with ``--fault stopped``.
``write_flights`` is the same as a plain function."""

from __future__ import annotations

import json

import numpy as np
import pytest
from pymavlink import mavutil
from test_sim_io import read_tlog

from monitor.logs.identity import identify
from offline.sim.io_npz import read_npz
from offline.simulate import SimulateSpec, write_flights
from offline.simulate import main as simulate_main

DAY_S = 86_400


def test_flights_of_one_vehicle_carry_its_id_a_date_each_and_end_landed_then_disarmed(tmp_path, capsys):
    out = tmp_path / "quad3"
    assert simulate_main(["--out", str(out), "--flights", "3", "--duration-s", "4", "--propellers", "quadratic",
                          "--vehicle-id", "3"]) == 0  # fmt: skip
    stdout = capsys.readouterr().out
    assert "vehicle id: 5057000000000003" in stdout and "2024-06-03" in stdout, stdout
    idents = [identify(out / f"flight_{k:03d}.tlog", "tlog") for k in range(3)]
    assert {i.vehicle_id for i in idents} == {"5057000000000003"}
    starts_s = [i.utc_minus_boot_us / 1e6 for i in idents]
    assert np.allclose(np.diff(starts_s), DAY_S), starts_s  # one flight a day, in file order
    truth = json.loads((out / "sidecar.json").read_text())["flights"]
    assert [f["start_utc"][:10] for f in truth] == ["2024-06-01", "2024-06-02", "2024-06-03"]

    msgs = read_tlog(out / "flight_000.tlog")
    armed = [bool(m.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED) for m in msgs["HEARTBEAT"]]
    landed = [m.landed_state for m in msgs["EXTENDED_SYS_STATE"]]
    assert armed[0] and not armed[-1], armed  # armed in flight, disarmed at the end
    assert landed[0] == mavutil.mavlink.MAV_LANDED_STATE_IN_AIR and landed[-1] == mavutil.mavlink.MAV_LANDED_STATE_ON_GROUND
    first_ground = landed.index(mavutil.mavlink.MAV_LANDED_STATE_ON_GROUND)
    assert armed[first_ground], "the vehicle is on the ground before it disarms"


def test_without_vehicle_id_the_logs_carry_none(tmp_path):
    write_flights(tmp_path, SimulateSpec(duration_s=2.0, propellers="quadratic"))
    assert identify(tmp_path / "flight_000.tlog", "tlog").vehicle_id is None


def _thrust_per_omega2(log, rotor: int, mask):
    return float(np.median(log.thrust_n[0, mask, rotor - 1] / log.motor_omega_rad_s[0, mask, rotor - 1] ** 2))


def test_onset_damages_the_propeller_in_the_air_from_that_time_on(tmp_path):
    files = write_flights(
        tmp_path, SimulateSpec(label=4, fault="bent", onset_s=5.0, duration_s=10.0, propellers="quadratic", format="npz")
    )
    log, _ = read_npz(files[0])
    before, after = log.time_s < 4.9, log.time_s > 5.1
    for rotor in (1, 2, 4):  # healthy throughout
        assert _thrust_per_omega2(log, rotor, after) == pytest.approx(_thrust_per_omega2(log, rotor, before), rel=0.01)
    assert _thrust_per_omega2(log, 3, after) < 0.97 * _thrust_per_omega2(log, 3, before)
    assert _thrust_per_omega2(log, 3, before) == pytest.approx(_thrust_per_omega2(log, 1, before), rel=0.01)
    truth = json.loads(files[-1].read_text())["flights"][0]
    assert truth["onset_s"] == 5.0 and truth["faulty_propellers"] == [3]


def test_a_stopped_motor_has_its_output_at_the_minimum_from_the_onset_on(tmp_path, capsys):
    assert simulate_main(["--out", str(tmp_path), "--label", "4", "--fault", "stopped", "--onset", "3", "--duration-s",
                          "6", "--propellers", "quadratic"]) == 0  # fmt: skip
    assert "motor 3 stopped from 3 s" in capsys.readouterr().out
    msgs = read_tlog(tmp_path / "flight_000.tlog")
    t0_us = msgs["SERVO_OUTPUT_RAW"][0].time_usec - 20_000  # the first sample is one 50 Hz step after the start
    servo = [(m.time_usec - t0_us, (m.servo1_raw, m.servo2_raw, m.servo3_raw, m.servo4_raw)) for m in msgs["SERVO_OUTPUT_RAW"]]
    flight = [(t, pwm) for t, pwm in servo if t <= 6_000_000]  # before the landing tail
    before = [pwm for t, pwm in flight if t < 3_000_000]
    after = [pwm for t, pwm in flight if t >= 3_010_000]  # the next 200 Hz control step
    assert min(p[2] for p in before) > 1100  # motor 3 flew
    assert {p[2] for p in after} == {1000}  # then held at the ESC's minimum
    assert all(max(p[m] for p in after) > 1500 for m in (0, 1, 3))  # the others still fly (the controller may idle one)
    truth = json.loads((tmp_path / "sidecar.json").read_text())["flights"][0]
    assert truth["propeller_conditions"] == ["normal", "normal", "stopped", "normal"] and truth["onset_s"] == 3.0


@pytest.mark.parametrize(
    "args, says",
    [
        (["--onset", "5"], "--onset: label 1 damages nothing"),
        (["--label", "4", "--onset", "90"], "--onset: must be inside the flight"),
        (["--label", "4", "--fault", "stopped"], "--fault stopped: a vehicle with a stopped motor never takes off"),
        (["--vehicle-id", "0"], "--vehicle-id: must be 1.."),
    ],
)
def test_impossible_faults_are_refused_with_the_flag_named(tmp_path, capsys, args, says):
    from monitor.cli import main as propwatch

    assert propwatch(["simulate", "--out", str(tmp_path / "x"), "--duration-s", "20", *args]) == 2
    assert says in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_help_lists_the_labels_and_shows_no_markup(capsys):
    with pytest.raises(SystemExit):
        simulate_main(["--help"])
    text = capsys.readouterr().out
    assert " 4 3 " in text and "16 1+2+3+4" in text and " 1 healthy" in text
    assert "`" not in text and "offline." not in text and "monitor." not in text


def test_a_later_run_goes_on_with_the_vehicles_flights(tmp_path):
    write_flights(tmp_path, SimulateSpec(flights=2, duration_s=3.0, vehicle_id=4, propellers="quadratic"))
    files = write_flights(
        tmp_path, SimulateSpec(flights=1, label=3, duration_s=3.0, vehicle_id=4, first_flight=2, propellers="quadratic")
    )
    assert [f.name for f in files] == ["flight_002.tlog", "sidecar_002.json"]
    assert (tmp_path / "sidecar.json").is_file()  # the first run's truth stays
    idents = [identify(tmp_path / f"flight_{k:03d}.tlog", "tlog") for k in range(3)]
    assert np.allclose(np.diff([i.utc_minus_boot_us / 1e6 for i in idents]), DAY_S)
    later = json.loads(files[-1].read_text())["flights"][0]
    assert later["start_utc"][:10] == "2024-06-03" and later["faulty_propellers"] == [2]
    first = json.loads((tmp_path / "sidecar.json").read_text())["flights"][0]
    assert later["waypoints_ned_m"] != first["waypoints_ned_m"]  # its own route
