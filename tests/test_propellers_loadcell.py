"""Virtual load cell: the paper's sweep, the documented fault signatures measured back, seeding."""

import numpy as np
import pytest

from monitor.errors import ConfigError
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.propellers.loadcell import LoadCellConfig, run_load_cell
from offline.sim.faults import SIGNATURES

VEHICLE = load_vehicle(DEFAULT_VEHICLE)
CFG = LoadCellConfig(duration_s=120.0, seed=7)
RUNS = {c: run_load_cell(VEHICLE, c, CFG) for c in ("normal", "bent", "cracked")}


def _ratio(run, lo, hi):
    """Median measured / kF·ω² (thrust) and / kτ·ω² (torque) for lo <= s < hi."""
    s, y = run.normalised(VEHICLE)
    m = (s >= lo) & (s < hi)
    return np.median(y[m, 0] / s[m] ** 2), np.median(y[m, 1] / s[m] ** 2)


def test_sweep_is_the_papers_experiment():
    run = RUNS["normal"]
    assert np.allclose(np.diff(run.time_s), 0.025)
    assert run.esc_us.min() == pytest.approx(1000.0, abs=1.0) and run.esc_us.max() == pytest.approx(2000.0, abs=1.0)
    assert len(run.time_s) == 120 / 0.025
    # Full five minutes by default, as in the paper.
    assert LoadCellConfig().duration_s == 300.0
    # The measured RPM lags the commanded one (first-order motor) but spans the ESC curve.
    assert run.rpm.max() == pytest.approx(VEHICLE.esc.cmd_to_rpm(2000.0), rel=0.01)


@pytest.mark.parametrize("condition", ["normal", "bent", "cracked"])
def test_measured_signature_matches_the_fault_model(condition):
    sig = SIGNATURES[condition]
    for lo, hi in ((0.3, 0.4), (0.85, 0.95)):
        t, q = _ratio(RUNS[condition], lo, hi)
        s_mid = np.sqrt((lo**2 + hi**2) / 2)
        assert t == pytest.approx(sig.thrust_factor(s_mid), abs=0.01)
        assert q == pytest.approx(sig.torque_factor(s_mid), abs=0.01)


def test_faults_differ_as_argued():
    bent_lo, bent_hi = _ratio(RUNS["bent"], 0.3, 0.4)[0], _ratio(RUNS["bent"], 0.85, 0.95)[0]
    assert bent_lo - bent_hi > 0.02  # the bent blade flexes further under load
    crack_lo, crack_hi = _ratio(RUNS["cracked"], 0.3, 0.4)[0], _ratio(RUNS["cracked"], 0.85, 0.95)[0]
    assert bent_lo < 0.93 and crack_lo > 0.95  # bent loses thrust at once, a crack is closed at low speed
    assert crack_lo - crack_hi > 0.08  # and opens with RPM
    assert _ratio(RUNS["bent"], 0.5, 0.9)[1] > _ratio(RUNS["cracked"], 0.5, 0.9)[1] > 1.0  # more drag torque

    # Flutter makes the cracked sweep noisier at speed than the normal one.
    def scatter(run):
        s, y = run.normalised(VEHICLE)
        m = s > 0.8
        r = y[m, 0] / s[m] ** 2
        return np.std(np.diff(r))

    assert scatter(RUNS["cracked"]) > 2 * scatter(RUNS["normal"])


def test_seeded():
    a = run_load_cell(VEHICLE, "cracked", LoadCellConfig(duration_s=20.0, seed=1))
    b = run_load_cell(VEHICLE, "cracked", LoadCellConfig(duration_s=20.0, seed=1))
    c = run_load_cell(VEHICLE, "cracked", LoadCellConfig(duration_s=20.0, seed=2))
    np.testing.assert_array_equal(a.thrust_n, b.thrust_n)
    assert not np.array_equal(a.thrust_n, c.thrust_n)


def test_bad_config():
    with pytest.raises(ConfigError, match="internal_rate_hz"):
        LoadCellConfig(internal_rate_hz=1999.0)
    with pytest.raises(ConfigError, match="condition"):
        run_load_cell(VEHICLE, "chipped")
