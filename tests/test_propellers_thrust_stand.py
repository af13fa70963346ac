"""Thrust-stand loader and fits: real RCbenchmark exports, file quirks, bad files, load-cell round trip."""

from pathlib import Path

import numpy as np
import pytest

from monitor.errors import LogFormatError
from monitor.esc import RAD_S_PER_RPM
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.propellers.loadcell import LoadCellConfig, run_load_cell, write_tyto_csv
from offline.propellers.thrust_stand import (
    GRAVITY_M_S2,
    esc_curve_from_fit,
    fit_esc_to_rpm,
    fit_kf,
    fit_ktau,
    read_thrust_stand_csv,
)

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
STRAWSON = DATA / "thrust_strawson" / "rawdata"
DANTONIO = DATA / "thrust_rcbench1580_dantonio" / "datasets"
needs_strawson = pytest.mark.skipif(not STRAWSON.is_dir(), reason=f"real thrust-stand data absent: {STRAWSON}")
needs_dantonio = pytest.mark.skipif(not DANTONIO.is_dir(), reason=f"real thrust-stand data absent: {DANTONIO}")


@pytest.mark.realdata
@needs_strawson
def test_strawson_golden_first_row_and_units():
    run = read_thrust_stand_csv(STRAWSON / "a1_11.csv")
    # First row of the file: 1050 µs, 15.171654199725802 gf, 3421 RPM (electrical; optical column is 0).
    assert run.esc_us[0] == 1050
    assert run.thrust_n[0] == pytest.approx(15.171654199725802e-3 * GRAVITY_M_S2, rel=1e-12)
    assert run.rpm[0] == 3421
    assert run.torque_nm is None  # the 1520 has no torque cell
    assert run.voltage_v[0] == pytest.approx(11.091128183929616)
    assert run.time_s.size == 11


@pytest.mark.realdata
@needs_strawson
def test_strawson_all_sweeps_fit_well():
    files = sorted(STRAWSON.glob("*.csv"))
    assert len(files) == 208
    r2_rpm, r2_kf, kfs = [], [], []
    for f in files:
        run = read_thrust_stand_csv(f)
        assert np.all(np.diff(run.esc_us) > 0)  # a steps test
        r2_rpm.append(fit_esc_to_rpm(run).r2)
        kf = fit_kf(run)
        r2_kf.append(kf.r2)
        kfs.append(kf.coefficients[0])
    # Healthy 5-inch props follow kF·ω² closely; ESC -> RPM is close to quadratic.
    assert np.median(r2_kf) > 0.99
    assert np.median(r2_rpm) > 0.98
    assert 3e-7 < np.median(kfs) < 3e-6  # N/(rad/s)²: ~1 kgf at 30 000 RPM for a 5-inch prop


@pytest.mark.realdata
@needs_dantonio
def test_dantonio_torque_and_missing_rpm():
    run = read_thrust_stand_csv(DANTONIO / "StepsTest_2020-06-16_212137.csv")
    assert run.torque_nm is not None
    ktau, kf = fit_ktau(run), fit_kf(run)
    assert ktau.r2 > 0.95 and kf.r2 > 0.99
    # Torque to thrust ratio of a 2-inch prop: kτ/kF ~ a few mm (blade radius scale).
    assert 2e-3 < ktau.coefficients[0] / kf.coefficients[0] < 2e-2
    curve = esc_curve_from_fit(fit_esc_to_rpm(run), 1200.0, 1800.0)
    assert curve.cmd_to_rpm(1500.0) == pytest.approx(np.interp(1500.0, run.esc_us, run.rpm), rel=0.1)
    # 2023 exports: no RPM sensor (both speed columns 0) and a first timestamp after the second.
    no_rpm = read_thrust_stand_csv(DANTONIO / "StepsTest202306052008_2023-06-05_200852.csv")
    assert no_rpm.rpm is None
    with pytest.raises(LogFormatError, match="no RPM"):
        fit_kf(no_rpm)


def _write(tmp_path, header, rows, encoding="latin-1", newline="\r"):
    p = tmp_path / "sweep.csv"
    p.write_bytes(newline.join([header] + rows).encode(encoding) + newline.encode())
    return p


def test_latin1_cr_and_kgf(tmp_path):
    header = "Time (s),ESC signal (µs),Thrust (kgf),Torque (N·m),Motor Electrical Speed (RPM),Motor Optical Speed (RPM)"
    p = _write(tmp_path, header, ["0,1100,0.1,0.01,3000,0", "0.5,1500,0.4,0.04,6000,0", "1.0,1900,0.9,0.09,9000,0"])
    assert b"\xb5" in p.read_bytes() and b"\n" not in p.read_bytes()
    run = read_thrust_stand_csv(p)
    np.testing.assert_allclose(run.thrust_n, np.array([0.1, 0.4, 0.9]) * GRAVITY_M_S2)
    np.testing.assert_allclose(run.torque_nm, [0.01, 0.04, 0.09])
    np.testing.assert_array_equal(run.rpm, [3000, 6000, 9000])
    # Thrust exactly k·ω² is recovered with R² = 1.
    w = run.rpm * RAD_S_PER_RPM
    p2 = _write(
        tmp_path,
        "Time (s),ESC signal (us),Thrust (N),Motor Optical Speed (RPM)",
        [f"{i},{1100 + 100 * i},{float(2e-6 * wi**2)!r},{r}" for i, (wi, r) in enumerate(zip(w, run.rpm))],
        "utf-8",
        "\n",
    )
    fit = fit_kf(read_thrust_stand_csv(p2))
    assert fit.coefficients[0] == pytest.approx(2e-6, rel=1e-9) and fit.r2 == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("header", "rows", "column"),
    [
        ("Time (s),ESC signal (µs),Motor Optical Speed (RPM)", ["0,1100,3000", "1,1200,4000"], "Thrust"),
        ("Time (s),ESC signal (µs),Thrust (stone),Motor Optical Speed (RPM)", ["0,1100,1,3000", "1,1200,2,4000"], "Thrust"),
        ("Time (s),ESC signal (µs),Thrust (gf),Torque (kN·m)", ["0,1100,1,0.1", "1,1200,2,0.2"], "Torque"),
        ("Time (s),ESC signal (µs),Thrust (gf)", ["0,1100,1", "2,1200,2", "1,1300,3"], "Time"),
        ("Time (s),ESC signal (µs),Thrust (gf)", ["0,1100,1", "1,abc,2"], "ESC signal"),
    ],
)
def test_bad_files_name_file_and_column(tmp_path, header, rows, column):
    p = _write(tmp_path, header, rows, "utf-8", "\n")
    with pytest.raises(LogFormatError) as exc:
        read_thrust_stand_csv(p)
    assert str(p) in str(exc.value) and repr(column) in str(exc.value)


def test_virtual_load_cell_round_trip_and_kf(tmp_path):
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    run = run_load_cell(vehicle, "normal", LoadCellConfig(duration_s=60.0, seed=4))
    back = read_thrust_stand_csv(write_tyto_csv(run, tmp_path / "virtual.csv"))
    np.testing.assert_allclose(back.thrust_n, run.thrust_n, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(back.torque_nm, run.torque_nm, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(back.esc_us, run.esc_us)
    # The fits recover the vehicle the load cell was built around.
    assert fit_kf(back).coefficients[0] == pytest.approx(vehicle.kf_n_per_rad_s2, rel=0.005)
    assert fit_ktau(back).coefficients[0] == pytest.approx(vehicle.ktau_nm_per_rad_s2, rel=0.005)
    a, b, c = fit_esc_to_rpm(back).coefficients
    esc = vehicle.esc
    assert fit_esc_to_rpm(back).r2 > 0.99
    assert np.polyval([a, b, c], 1500.0) == pytest.approx(esc.cmd_to_rpm(1500.0), rel=0.03)


@pytest.mark.realdata
@needs_dantonio
def test_load_cell_noise_defaults_not_below_a_real_stand():
    """The virtual stand is no quieter than a real RCbenchmark 1580 ramp sampled every ~25 ms."""
    from offline.propellers.thrust_stand import noise_at_rest

    run = read_thrust_stand_csv(DANTONIO / "StepsTest20230615_2023-06-15_174003.csv")
    assert np.mean(np.diff(run.time_s)) == pytest.approx(0.025, abs=0.003)  # the paper's sample period
    thrust_std_n, torque_std_nm = noise_at_rest(run)
    assert 0 < thrust_std_n <= LoadCellConfig().thrust_noise_n
    assert 0 < torque_std_nm <= LoadCellConfig().torque_noise_nm
