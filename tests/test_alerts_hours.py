"""The evaluation's healthy hours are classified hours: how many flights the evaluation flies to reach them."""

import hashlib
import json
import math

import numpy as np
import pytest

from offline.alerts.evaluate import classified_s, healthy_flight_count, healthy_sets, set_key
from offline.alerts.flights import ALERT_FLIGHT_FIELDS, AlertFlight, FlightSet, heading_velocity
from offline.sim.assumptions import REGISTER


def _flight(samples: int, window: int, rate_hz: float) -> AlertFlight:
    """A flight as ``_classify`` builds it: one window output per sample from the first full window on."""
    z = np.zeros(samples)
    return AlertFlight(
        "f",
        rate_hz,
        window,
        np.zeros((samples - window + 1, 4)),
        np.zeros((samples, 4)),
        z,
        z,
        z,
        z,
        np.zeros((samples, 3)),
        (),
        math.inf,
    )


@pytest.mark.parametrize("short", [0, 1])
def test_classified_seconds_are_what_the_evaluation_counts(short):
    samples = 80 * 20 - short
    assert classified_s(80.0, 20.0, 100, short) == pytest.approx(_flight(samples, 100, 20.0).hours * 3600.0)
    assert classified_s(80.0, 20.0, 100, short) == pytest.approx(75.05 - 0.05 * short)


def test_flight_count_is_the_fewest_that_reach_the_classified_hours():
    for hours in (0.05, 1.0, 4.69, 9.3813, 10.0, 12.5):
        for per_s in (75.05, 75.0, 80.0):
            n = healthy_flight_count(hours, per_s)
            assert n * per_s >= hours * 3600.0 - 1e-6
            assert (n - 1) * per_s < hours * 3600.0
    assert healthy_flight_count(10.0, 75.05) == 480  # 450 flights were 9.38 classified hours
    assert healthy_flight_count(10.0, 75.0) == 480  # exactly 10 h: no extra flight from rounding


def test_a_flight_shorter_than_one_window_is_an_error():
    with pytest.raises(ValueError, match="fewer than one 100-sample window"):
        classified_s(4.0, 20.0, 100)


def test_the_flown_hours_set_stays_and_the_extra_flights_are_appended():
    sets = healthy_sets(10.0, 75.05, seed=200, pickup_fraction=0.25, physics="randomised")
    assert [(s.n_flights, s.first_flight, s.seed) for s in sets] == [(450, 0, 200), (30, 450, 200)]
    # The first set is the one earlier runs drew: its key is the key it had before first_flight existed, with what
    # its flights hold (ALERT_FLIGHT_FIELDS: flights cached without the heading velocity are simulated again) and
    # the register's ranges that drew them (a new assumption, e.g. blade flapping, draws new flights).
    old = {**FlightSet("healthy", 450, seed=200, pickup_fraction=0.25, physics="randomised").__dict__, "model": "m"}
    del old["first_flight"]
    register = hashlib.sha256(json.dumps(REGISTER.to_mapping(), sort_keys=True).encode()).hexdigest()[:16]
    assert set_key(sets[0], "m") == {**old, "fields": ALERT_FLIGHT_FIELDS, "register": register}
    wider = REGISTER.with_range("blade_flapping_trim_per_m_s", 0.0, 0.05)
    assert hashlib.sha256(json.dumps(wider.to_mapping(), sort_keys=True).encode()).hexdigest()[:16] != register
    assert set_key(sets[1], "m")["first_flight"] == 450
    digest = [hashlib.sha256(json.dumps(set_key(s, "m"), sort_keys=True).encode()).hexdigest() for s in sets]
    assert digest[0] != digest[1]
    # No second set when the flown-hours count already reaches the classified hours.
    assert [s.n_flights for s in healthy_sets(1.0, 80.0, seed=200)] == [45]


def test_an_appended_set_draws_from_its_own_stream():
    base, extra = FlightSet("healthy", 450, seed=200), FlightSet("healthy", 30, seed=200, first_flight=450)
    assert np.array_equal(base.rng().random(5), np.random.default_rng([200, 13]).random(5))  # the stream as before
    assert not np.array_equal(base.rng().random(5), extra.rng().random(5))


def test_heading_velocity_is_ned_velocity_turned_by_the_yaw():
    # Flying east (NED v_e = 5 m/s) with the nose east (yaw 90 deg): 5 m/s forward; nose north: 5 m/s to the right.
    v = np.array([[0.0, 5.0, -1.0], [0.0, 5.0, 0.0], [3.0, 4.0, 0.0]])
    yaw = np.array([np.pi / 2, 0.0, np.arctan2(4.0, 3.0)])
    np.testing.assert_allclose(heading_velocity(v, yaw), [[5.0, 0.0], [0.0, 5.0], [5.0, 0.0]], atol=1e-12)
    assert heading_velocity(None, yaw) is None
