"""The evaluation-only ``strangers_*`` sets (offline/evalsim/strangers.py): airframes in the promised ranges, physics
that flies them sanely, damage and a stopped motor where truth says, flights that depend only on (set, seed, i); and
the scoring harness's reading of a verdict (bench/strangers.py)."""

import math

import numpy as np
import pytest

pytest.importorskip("rotorpy")

import evalsim_flights  # noqa: E402

from monitor.esc import RPM_PER_RAD_S  # noqa: E402
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle  # noqa: E402
from offline.evalsim.catalog import build_set  # noqa: E402
from offline.evalsim.names import STRANGER_SETS, STRANGERS_DEV_SEED, STRANGERS_EVAL_SEED  # noqa: E402
from offline.evalsim.strangers import STRANGER_CLASSES, nominal_airframe, saturated_fraction, uid_of  # noqa: E402

DURATION_S = 6.0
SEED = STRANGERS_DEV_SEED


def _specs():
    """Flight 0-4 of strangers_healthy (one per class) and flight 0 of every other set (micro-6in, rotor 1)."""
    specs = build_set("strangers_healthy", 5, seed=SEED, duration_s=DURATION_S)
    return specs + [build_set(n, 1, seed=SEED, duration_s=DURATION_S)[0] for n in STRANGER_SETS[1:]]


evalsim_flights.declare(__name__, "flights", _specs)


@pytest.fixture(scope="module")
def flights():
    specs = _specs()
    return {s.name: (s, log) for s, log in zip(specs, evalsim_flights.simulate_flights(specs), strict=True)}


def test_classes_span_the_promised_sizes_and_hover_speeds():
    nominal_hover = load_vehicle(DEFAULT_VEHICLE).hover_omega_rad_s
    masses = [c.mass_kg for c in STRANGER_CLASSES]
    arms = [c.arm_m for c in STRANGER_CLASSES]
    ratios = [c.hover_omega_rad_s / nominal_hover for c in STRANGER_CLASSES]
    assert len(STRANGER_CLASSES) >= 4
    assert 0.5 <= min(masses) and max(masses) <= 3.0 and max(masses) / min(masses) > 4
    assert 0.10 <= min(arms) <= 0.12 and 0.28 <= max(arms) <= 0.30
    assert 0.6 <= min(ratios) <= 0.7 and 1.25 <= max(ratios) <= 1.4
    for c in STRANGER_CLASSES:
        af = nominal_airframe(c)
        assert c.prop_diameter_m < c.arm_m * math.sqrt(2)  # neighbouring propellers clear each other
        # hover thrust equals weight; the ESC's top command gives omega_max, its bottom omega_min
        assert 4 * af.kf_n_per_rad_s2 * af.hover_omega_rad_s**2 == pytest.approx(c.mass_kg * 9.81)
        assert af.esc.cmd_to_rpm(af.esc.cmd_max) == pytest.approx(af.omega_max_rad_s * RPM_PER_RAD_S)
        assert af.esc.cmd_to_rpm(af.esc.cmd_min) == pytest.approx(af.omega_min_rad_s * RPM_PER_RAD_S)
        # inertia grows with mass and arm; drag torque per thrust with the propeller
        assert af.inertia_diag_kg_m2[0] == pytest.approx(0.0123 * c.mass_kg / 1.5 * (c.arm_m / 0.16) ** 2)


def test_healthy_flights_hover_at_their_class_speed_and_commands_map_to_rpm(flights):
    nominal_hover = load_vehicle(DEFAULT_VEHICLE).hover_omega_rad_s
    for k, c in enumerate(STRANGER_CLASSES):
        spec, log = flights[f"strangers_healthy_{k:04d}"]
        af = spec.airframe
        assert 0.0 <= af.payload_kg / af.mass_kg <= 0.25
        rpm = np.median(log.motor_omega_rad_s[0]) * RPM_PER_RAD_S
        loaded = c.hover_omega_rad_s * math.sqrt(1 + af.payload_kg / af.mass_kg) * RPM_PER_RAD_S
        assert rpm == pytest.approx(loaded, rel=0.06)  # flying around, motors ±4-8 % apart
        assert 0.6 <= rpm / (nominal_hover * RPM_PER_RAD_S) <= 1.4 * math.sqrt(1.25)
        # the ESC command the log shows maps (class ESC curve) to the speed reached, within the motor spread and sag
        commanded = np.median(spec.nominal.esc.cmd_to_rpm(log.pwm_us[0]), axis=0)
        reached = np.median(log.motor_omega_rad_s[0], axis=0) * RPM_PER_RAD_S
        assert np.all(np.abs(reached / commanded - 1) < 0.06)
        assert np.all(np.isfinite(log.pos_ned_m[0])) and np.abs(np.degrees(log.roll_rad[0])).max() < 35
        assert saturated_fraction(log, spec.nominal.esc) < 0.05


def test_damaged_rotor_makes_less_thrust_from_takeoff_and_after_onset(flights):
    spec, log = flights["strangers_takeoff_0000"]
    rotor = spec.faulty_propellers[0] - 1
    assert spec.airframe.damage.thrust_loss_at_hover[rotor] >= 0.10
    factor = log.thrust_n[0] / (spec.airframe.kf_n_per_rad_s2 * log.motor_omega_rad_s[0] ** 2)
    assert np.all(np.median(factor, axis=0)[rotor] < 0.92)
    assert np.median(np.delete(factor, rotor, axis=1)) == pytest.approx(1.0)

    spec, log = flights["strangers_onset_0000"]
    rotor, onset = spec.faulty_propellers[0] - 1, spec.airframe.damage.onset_time_s
    assert spec.airframe.damage.thrust_loss_at_hover[rotor] >= 0.06 and 0 < onset < DURATION_S
    factor = log.thrust_n[0, :, rotor] / (spec.airframe.kf_n_per_rad_s2 * log.motor_omega_rad_s[0, :, rotor] ** 2)
    assert np.median(factor[log.time_s < onset]) == pytest.approx(1.0)
    assert np.median(factor[log.time_s > onset + 0.1]) < 0.95


def test_truth_puts_onset_and_stop_on_the_boot_clock(flights):
    from offline.evalsim.strangers import stranger_truth

    t = {n: stranger_truth(n.rsplit("_", 1)[0], SEED, 0, *flights[n], "f.tlog", 1) for n in flights if n.endswith("_0000")}
    assert t["strangers_takeoff_0000"]["fault_onset_boot_s"] is None  # damaged from take-off
    onset = flights["strangers_onset_0000"][0].airframe.damage.onset_time_s
    assert t["strangers_onset_0000"]["fault_onset_boot_s"] == pytest.approx(5.0 + onset)  # the log's boot offset
    stop = flights["strangers_stopped_0000"][0].airframe.motor_stop_time_s
    assert t["strangers_stopped_0000"]["stop_boot_s"] == pytest.approx(5.0 + stop)
    assert t["strangers_stopped_0000"]["stopped_motor"] == 1 and t["strangers_healthy_0000"]["stopped_motor"] == 0
    assert all(np.isfinite(x["first_10s_median_rpm"]) for x in t.values())


def test_stopped_motor_output_sits_at_minimum_after_its_time(flights):
    spec, log = flights["strangers_stopped_0000"]
    rotor, t_stop = spec.airframe.motor_stop_rotor, spec.airframe.motor_stop_time_s
    esc = spec.nominal.esc
    pwm = log.pwm_us[0, :, rotor - 1]
    assert np.all(pwm[log.time_s >= t_stop] == esc.cmd_min)
    assert np.all(pwm[log.time_s < t_stop] > esc.cmd_min + 50)
    assert log.time_s[-1] == pytest.approx(t_stop + 2.0, abs=0.1)  # STOP_TAIL_S after the stop
    late = log.time_s > t_stop + 0.5
    assert np.median(log.motor_omega_rad_s[0, late, rotor - 1]) < 1.5 * spec.airframe.omega_min_rad_s


def test_sets_are_deterministic_extend_and_memory_shares_its_airframe():
    for name in STRANGER_SETS:
        a = build_set(name, 13, seed=SEED, duration_s=20.0)
        assert a == build_set(name, 13, seed=SEED, duration_s=20.0)
        assert build_set(name, 14, seed=SEED, duration_s=20.0)[:13] == a
        assert a != build_set(name, 13, seed=STRANGERS_EVAL_SEED, duration_s=20.0)
    mem = build_set("strangers_memory", 13, seed=SEED, duration_s=20.0)
    assert len({s.airframe_id for s in mem[:12]}) == 1 and mem[12].airframe_id != mem[0].airframe_id
    assert {s.airframe.payload_kg for s in mem[:3]} == {0.0} and max(s.airframe.payload_kg for s in mem[3:12]) > 0
    assert len({uid_of("strangers_memory", SEED, s) for s in mem}) == 2
    healthy = build_set("strangers_healthy", 20, seed=SEED, duration_s=20.0)
    assert len({uid_of("strangers_healthy", SEED, s) for s in healthy}) == 20
    assert sum(s.nuisance == "hard" for s in healthy) == 5


def test_harness_reads_named_sets_timed_alarms_and_confident_wrong():
    from bench.strangers import confident_wrong, motor_alarms, named_set, propeller_alarms

    damaged = {"summary": {"state": "damaged", "confidence": "confident", "replace": [2], "sets": [[2]], "inspect": []}}
    unsure = {"summary": {"state": "inspect", "confidence": "ambiguous", "replace": [], "sets": [[], [3]], "inspect": [3]}}
    assert named_set(damaged) == (2,) and named_set(unsure) == ()
    assert confident_wrong(damaged, (3,)) and not confident_wrong(damaged, (2,)) and confident_wrong(damaged, ())
    healthy = {"summary": {"state": "healthy", "confidence": "confident", "sets": [[]]}}
    assert confident_wrong(healthy, (1,)) and not confident_wrong(healthy, ())
    j = {
        "verdict": {"source": "in-flight change", "change_boot_s": 40.0, "faulty_propellers": [1]},
        "decision": {"alerts": [{"t_boot_s": 38.0, "level": "suspect", "propellers": [1]}]},
        "motor_events": [{"boot_s": 50.0, "motors": [4], "text": "MOTOR 4 STOPPED"}],  # a key a later version may add
    }
    assert [(e["t"], e["rotors"]) for e in propeller_alarms(j)] == [(40.0, (1,))]
    assert [(e["t"], e["rotors"]) for e in motor_alarms(j)] == [(50.0, (4,))]
