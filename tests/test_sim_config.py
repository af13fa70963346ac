"""Bad configs fail loudly, naming the key."""

from __future__ import annotations

import dataclasses

import pytest
import yaml

from monitor.config import from_mapping, load_dataclass
from monitor.errors import ConfigError
from monitor.vehicle import CALIBRATION_TERMS, DEFAULT_VEHICLE, load_vehicle
from offline.sim.controller import ControllerConfig
from offline.sim.simulator import SimConfig


@pytest.mark.parametrize(
    "kw,key",
    [
        ({"physics_rate_hz": 200, "control_rate_hz": 100, "position_rate_hz": 50}, "physics_rate_hz"),
        ({"control_rate_hz": 300}, "control_rate_hz"),
        ({"position_rate_hz": 30}, "position_rate_hz"),
        ({"log_rate_hz": 30}, "log_rate_hz"),
        ({"log_rate_hz": 0}, "log_rate_hz"),
        ({"duration_s": -1.0}, "duration_s"),
        ({"duration_s": 1.01}, "duration_s"),
        ({"gyro_noise_std_rad_s": -0.1}, "gyro_noise_std_rad_s"),
    ],
)
def test_sim_config_names_the_bad_key(kw, key):
    with pytest.raises(ConfigError, match=key):
        SimConfig(**kw)


def test_controller_config_names_the_bad_key():
    with pytest.raises(ConfigError, match="mc_rollrate_p"):
        ControllerConfig(mc_rollrate_p=-0.1)
    with pytest.raises(ConfigError, match="mpc_tiltmax_air_deg"):
        ControllerConfig(mpc_tiltmax_air_deg=95.0)


def test_sim_config_from_yaml(tmp_path):
    p = tmp_path / "sim.yaml"
    p.write_text("physics_rate_hz: 800\ncontrol_rate_hz: 400\ncontroller: {mc_roll_p: 5.0}\n")
    cfg, _ = load_dataclass(SimConfig, p)
    assert cfg.physics_rate_hz == 800 and cfg.controller.mc_roll_p == 5.0 and cfg.log_rate_hz == 20
    p.write_text("physics_rate_hz: 800\nphysics_rate: 1\n")
    with pytest.raises(ConfigError, match="physics_rate"):
        load_dataclass(SimConfig, p)
    p.write_text("controller: {mc_roll_pp: 5.0}\n")
    with pytest.raises(ConfigError, match="mc_roll_pp"):
        load_dataclass(SimConfig, p)
    p.write_text("physics_rate_hz: 300\n")
    with pytest.raises(ConfigError, match=f"{p}.*(control_rate_hz|log_rate_hz)"):
        load_dataclass(SimConfig, p)


def edited_vehicle(tmp_path, edit):
    data = yaml.safe_load(DEFAULT_VEHICLE.read_text())
    edit(data)
    p = tmp_path / "vehicle.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


def test_vehicle_yaml_errors_name_the_key(tmp_path):
    def negative_mass(d):
        d["mass_kg"]["value"] = -1.5

    def missing_kf(d):
        del d["kf_n_per_rad_s2"]

    def unknown(d):
        d["mass_lb"] = {"value": 3.3, "source": "x"}

    for edit, key in ((negative_mass, "mass_kg"), (missing_kf, "kf_n_per_rad_s2"), (unknown, "mass_lb")):
        with pytest.raises(ConfigError, match=key):
            load_vehicle(edited_vehicle(tmp_path, edit))


def test_every_vehicle_value_cites_a_source():
    from monitor.vehicle import load_vehicle_with_sources

    loaded = load_vehicle_with_sources(DEFAULT_VEHICLE)
    names = [f.name for f in dataclasses.fields(loaded.config)]
    required = [n for n in names if n not in CALIBRATION_TERMS]
    for n in required:
        assert any(k == n or k.startswith(n + ".") for k in loaded.sources), n


def test_sim_config_round_trips_through_a_mapping():
    from monitor.config import to_mapping

    cfg = SimConfig(physics_rate_hz=800, control_rate_hz=400)
    back, _ = from_mapping(SimConfig, to_mapping(cfg))
    assert back == cfg


def test_simulate_rejects_bad_inputs_by_name():
    import numpy as np

    from offline.sim.propeller import QuadraticPropeller
    from offline.sim.simulator import simulate

    v = load_vehicle(DEFAULT_VEHICLE)
    prop = QuadraticPropeller.for_vehicle(v)
    sim = SimConfig(duration_s=0.1)
    with pytest.raises(ConfigError, match="waypoints_ned_m"):
        simulate(v, np.zeros((2, 3)), prop, sim)
    with pytest.raises(ConfigError, match="payload_kg"):
        simulate(v, np.zeros((2, 1, 3)), prop, sim, payload_kg=[0.1, -0.2])
    with pytest.raises(ConfigError, match="seed"):
        simulate(v, np.zeros((2, 1, 3)), prop, sim, seed=[1, 2, 3])


def test_missions_are_deterministic_inside_the_box_and_distinct():
    import numpy as np

    from offline.sim.mission import DEFAULT_BOX_NED_M, random_waypoints, waypoint_set

    a, b = waypoint_set("A"), waypoint_set("B")
    assert a.shape == b.shape == (5, 3)
    np.testing.assert_array_equal(a, waypoint_set("A"))
    assert np.linalg.norm(a - b, axis=1).min() > 1.0
    w = random_waypoints(50, 5, seed=3)
    box = np.array(DEFAULT_BOX_NED_M)
    assert np.all(w >= box[:, 0]) and np.all(w <= box[:, 1])
    np.testing.assert_array_equal(random_waypoints(10, 5, seed=3), w[:10])  # more flights extend, never reshuffle
    assert not np.array_equal(random_waypoints(10, 5, seed=4), w[:10])
    with pytest.raises(ConfigError, match="waypoint set"):
        waypoint_set("C")
