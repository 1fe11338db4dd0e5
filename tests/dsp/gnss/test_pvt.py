"""The PVT (dsp.gnss.pvt) on a nominal constellation: exact recovery, the covariance over
seeded Monte Carlo, agreement with gnss-lib-py's WLS and DOPs, the residual test and its
exclusion, no fix with too few satellites, and the atmosphere models."""
from __future__ import annotations

import numpy as np
import pymap3d
import pytest
from scipy.stats import binomtest, chi2

from dsp.gnss import observables as ob
from dsp.gnss import pvt
from dsp.gnss import ephemeris
from dsp.gnss.atmosphere import klobuchar_delay_m, saastamoinen_delay_m

LAT, LON, H = 48.15, 11.58, 520.0
AZ = np.array([10.0, 55.0, 100.0, 150.0, 200.0, 250.0, 300.0, 340.0])
EL = np.array([75.0, 20.0, 45.0, 15.0, 60.0, 30.0, 25.0, 40.0])
PRN = np.array([3, 7, 11, 14, 19, 22, 28, 31])
CN0 = np.array([48.0, 45.0, 47.0, 46.0, 48.0, 46.0, 45.0, 47.0])
B_M, DRIFT_MPS = 12_345.678, 37.5
V_ENU = (10.0, -3.0, 0.5)
ALPHA = [3.82e-8, 1.49e-8, -1.79e-7, 0.0]
BETA = [1.43e5, 0.0, -3.28e5, 1.13e5]
TOW = 345_600.0 + 13 * 3600.0          # local early afternoon at 11.6 E: the ionosphere is up


def scene(n=8):
    """Truth and exact measurements of the nominal constellation (first ``n`` satellites)."""
    pos, vel = ob.sky_geometry(LAT, LON, H, AZ[:n], EL[:n])
    r = np.array(pymap3d.geodetic2ecef(LAT, LON, H))
    v = np.array(pymap3d.enu2uvw(*V_ENU, LAT, LON))
    clk = np.linspace(-2e-4, 3e-4, n)
    drift = np.linspace(-2e-11, 1e-11, n)
    pr, tau = ob.predict_pseudoranges(r, B_M, pos, clk)
    rate = ob.predict_range_rates(r, v, DRIFT_MPS, pos, vel, drift, tau)
    return dict(prn=PRN[:n], pos=pos, vel=vel, clk=clk, drift=drift, pr=pr, tau=tau,
                dop=ob.doppler_from_rate(rate), r=r, v=v, cn0=CN0[:n])


def solve(s, pr=None, **kw):
    return pvt.solve(s["prn"], s["pos"], s["clk"], s["pr"] if pr is None else pr,
                     cn0_dbhz=s["cn0"], **kw)


def test_exact_measurements_give_the_truth_to_a_millimetre():
    s = scene()
    sol = solve(s, sat_vel_mps=s["vel"], sat_clock_drift=s["drift"], doppler_hz=s["dop"])
    assert sol.status is pvt.PvtStatus.FIX and sol.valid
    assert np.linalg.norm(sol.position_ecef_m - s["r"]) < 1e-3
    assert abs(sol.clock_bias_m - B_M) < 1e-3
    assert np.linalg.norm(sol.velocity_ecef_mps - s["v"]) < 1e-6
    assert abs(sol.clock_drift_mps - DRIFT_MPS) < 1e-6
    np.testing.assert_allclose(sol.velocity_enu_mps, V_ENU, atol=1e-6)
    assert (sol.lat_deg, sol.lon_deg) == pytest.approx((LAT, LON), abs=1e-10)
    assert sol.height_m == pytest.approx(H, abs=1e-3)
    np.testing.assert_allclose(sol.elevation_deg, EL, atol=1e-6)
    np.testing.assert_allclose(sol.azimuth_deg, AZ, atol=1e-6)
    assert sol.used_prns == tuple(PRN) and sol.excluded_prns == ()
    assert np.max(np.abs(sol.residuals_m)) < 1e-3 and 2 <= sol.iterations <= 20


def test_without_the_earth_rotation_the_position_is_tens_of_metres_off():
    """The Sagnac correction matters: the same data solved as if already in the reception
    frame land tens of metres away (why the solver rotates the satellites)."""
    s = scene()
    rot = pvt.rotate_z(s["pos"], pvt.OMEGA_E_DOT * s["tau"])
    wrong = solve(dict(s, pos=rot))
    assert 5.0 < np.linalg.norm(wrong.position_ecef_m - s["r"]) < 100.0


def test_the_pseudorange_rate_input_equals_the_doppler_input():
    s = scene()
    rate = -s["dop"] * ephemeris.L1_WAVELENGTH_M
    a = solve(s, sat_vel_mps=s["vel"], sat_clock_drift=s["drift"], doppler_hz=s["dop"])
    b = solve(s, sat_vel_mps=s["vel"], sat_clock_drift=s["drift"], pseudorange_rate_mps=rate)
    np.testing.assert_allclose(a.velocity_ecef_mps, b.velocity_ecef_mps, atol=1e-9)


def test_the_error_covariance_matches_the_weighted_geometry():
    """Seeded Monte Carlo: noise of the weight model's sigmas; the normalised errors
    ``dx^T (H^T W H) dx`` of (x, y, z, b) are chi-square with 4 degrees of freedom, and so is
    each component's squared normalised error with 1."""
    s = scene()
    sig = pvt.pseudorange_sigma_m(s["cn0"], EL)
    rng = np.random.default_rng(20261205)
    trials = 400
    nees, comp = np.empty(trials), np.empty((trials, 4))
    for k in range(trials):
        sol = solve(s, pr=s["pr"] + sig * rng.standard_normal(len(sig)))
        assert sol.valid
        dx = np.append(sol.position_ecef_m - s["r"], sol.clock_bias_m - B_M)
        nees[k] = dx @ np.linalg.solve(sol.covariance_m2, dx)
        comp[k] = dx / np.sqrt(np.diag(sol.covariance_m2))
    lo, hi = chi2.ppf([0.0005, 0.9995], 4 * trials)
    assert lo < nees.sum() < hi
    lo1, hi1 = chi2.ppf([0.0005, 0.9995], trials)
    for j in range(4):
        assert lo1 < np.sum(comp[:, j] ** 2) < hi1, j


def _gnss_lib_py_wls(s, pr_corr, weights):
    from gnss_lib_py.algorithms.snapshot import solve_wls
    from gnss_lib_py.navdata.navdata import NavData
    nd = NavData()
    n = len(pr_corr)
    nd["gps_millis"] = np.full(n, 1.3e12)
    nd["x_sv_m"], nd["y_sv_m"], nd["z_sv_m"] = s["pos"].T
    nd["corr_pr_m"] = pr_corr
    nd["weights"] = weights
    est = solve_wls(nd, weight_type="weights")
    return np.array([float(est[k]) for k in ("x_rx_wls_m", "y_rx_wls_m", "z_rx_wls_m",
                                              "b_rx_wls_m")])


@pytest.mark.parametrize("noise", [False, True])
def test_agrees_with_gnss_lib_py_to_a_millimetre(noise):
    """gnss-lib-py's ``solve_wls`` solves the same problem: satellite positions in the frame
    of transmission (it rotates them by ``w_E (P - b) / c``), pseudoranges corrected for the
    satellite clock, our final weights ``1 / sigma_i^2``."""
    s = scene()
    rng = np.random.default_rng(7)
    pr = s["pr"] + (pvt.pseudorange_sigma_m(s["cn0"], EL) * rng.standard_normal(8)
                    if noise else 0.0)
    ours = solve(s, pr=pr)
    theirs = _gnss_lib_py_wls(s, pr + pvt.C_LIGHT * s["clk"], 1.0 / ours.sigmas_m ** 2)
    assert np.linalg.norm(ours.position_ecef_m - theirs[:3]) < 1e-3
    assert abs(ours.clock_bias_m - theirs[3]) < 1e-3
    if not noise:
        assert np.linalg.norm(theirs[:3] - s["r"]) < 1e-3


def test_dops_of_the_regular_tetrahedron():
    """Zenith plus three at asin(-1/3) 120 deg apart: G^T G = diag(4/3, 4/3, 4/3, 4)."""
    el = [90.0, np.rad2deg(np.arcsin(-1 / 3))] + [np.rad2deg(np.arcsin(-1 / 3))] * 2
    d = pvt.dop_enu(el, [0.0, 0.0, 120.0, 240.0])
    assert (d.gdop, d.pdop, d.hdop, d.vdop, d.tdop) == pytest.approx(
        (np.sqrt(2.5), 1.5, np.sqrt(1.5), np.sqrt(0.75), 0.5), abs=1e-12)


def test_dops_agree_with_gnss_lib_py():
    from gnss_lib_py.navdata.navdata import NavData
    from gnss_lib_py.utils.dop import get_dop
    s = scene()
    sol = solve(s)
    nd = NavData()
    nd["gps_millis"] = np.zeros(8)
    nd["el_sv_deg"], nd["az_sv_deg"] = sol.elevation_deg, sol.azimuth_deg
    ref = get_dop(nd, GDOP=True, PDOP=True, HDOP=True, VDOP=True, TDOP=True)
    for name in ("gdop", "pdop", "hdop", "vdop", "tdop"):
        assert getattr(sol.dop, name) == pytest.approx(float(ref[name.upper()]), rel=1e-10)


@pytest.mark.parametrize("bad", range(8))
def test_a_100_m_fault_is_detected_and_the_right_satellite_excluded(bad):
    s = scene()
    sig = pvt.pseudorange_sigma_m(s["cn0"], EL)
    rng = np.random.default_rng(100 + bad)
    pr = s["pr"] + sig * rng.standard_normal(8)
    pr[bad] += 100.0
    sol = solve(s, pr=pr)
    assert sol.status is pvt.PvtStatus.FIX_EXCLUDED and sol.valid
    assert sol.excluded_prns == (int(PRN[bad]),)
    assert int(PRN[bad]) not in sol.used_prns and len(sol.used_prns) == 7
    assert f"PRN {PRN[bad]} excluded" in sol.message
    assert sol.test_statistic <= sol.test_threshold
    assert np.linalg.norm(sol.position_ecef_m - s["r"]) < 6 * np.sqrt(
        np.trace(sol.covariance_m2[:3, :3]))


def test_the_false_alarm_rate_is_the_stated_one():
    """Over seeded fault-free trials the test fires at its p_fa (binomial, 0.1 % two-sided),
    and at the default p_fa = 1e-5 it never fires in 300 trials."""
    s = scene()
    sig = pvt.pseudorange_sigma_m(s["cn0"], EL)
    rng = np.random.default_rng(99)
    cfg = pvt.PvtConfig(p_false_alarm=0.05)
    trials, alarms, default_alarms = 600, 0, 0
    for k in range(trials):
        pr = s["pr"] + sig * rng.standard_normal(8)
        alarms += solve(s, pr=pr, config=cfg).excluded_prns != ()
        if k < 300:
            sol = solve(s, pr=pr)
            default_alarms += sol.status is not pvt.PvtStatus.FIX
    assert binomtest(alarms, trials, 0.05).pvalue > 1e-3
    assert default_alarms == 0


def test_a_fault_with_five_satellites_is_detected_not_excluded():
    s = scene(5)
    pr = s["pr"].copy()
    pr[2] += 300.0
    sol = solve(s, pr=pr)
    assert sol.status is pvt.PvtStatus.FAULT_DETECTED and not sol.valid
    assert sol.excluded_prns == () and "none to exclude" in sol.message


@pytest.mark.parametrize("n", [0, 1, 3])
def test_fewer_than_four_satellites_give_no_fix(n):
    s = scene(max(n, 1))
    sol = pvt.solve(s["prn"][:n], s["pos"][:n], s["clk"][:n], s["pr"][:n])
    assert sol.status is pvt.PvtStatus.NO_FIX_TOO_FEW and not sol.valid
    assert np.all(np.isnan(sol.position_ecef_m)) and np.isnan(sol.lat_deg)
    assert f"{n} usable satellites" in sol.message


def test_four_satellites_fix_without_a_check_and_nan_rows_are_unusable():
    s = scene(5)
    pr = s["pr"].copy()
    pr[1] = np.nan
    sol = solve(s, pr=pr)
    assert sol.status is pvt.PvtStatus.FIX_UNCHECKED and sol.unusable_prns == (int(PRN[1]),)
    assert np.linalg.norm(sol.position_ecef_m - s["r"]) < 1e-3 and np.isnan(sol.test_statistic)
    pr[2] = np.nan
    assert solve(s, pr=pr).status is pvt.PvtStatus.NO_FIX_TOO_FEW


def test_satellites_below_the_mask_are_not_used():
    s = scene()
    sol = solve(s, config=pvt.PvtConfig(elevation_mask_deg=18.0))
    assert sol.unusable_prns == (int(PRN[3]),)
    assert np.linalg.norm(sol.position_ecef_m - s["r"]) < 1e-3 and "mask" in sol.message


def test_coplanar_satellites_give_no_fix():
    s = scene()
    sol = pvt.solve(s["prn"], np.tile(s["pos"][0], (8, 1)), s["clk"], s["pr"])
    assert sol.status is pvt.PvtStatus.NO_FIX_GEOMETRY and np.all(np.isnan(sol.position_ecef_m))


def test_bad_input_raises():
    s = scene()
    with pytest.raises(ValueError, match="shape"):
        pvt.solve(s["prn"], s["pos"][:7], s["clk"], s["pr"])
    with pytest.raises(ValueError, match="distinct"):
        pvt.solve(np.ones(8, dtype=int), s["pos"], s["clk"], s["pr"])
    with pytest.raises(ValueError, match="together"):
        pvt.solve(s["prn"], s["pos"], s["clk"], s["pr"], iono_alpha=ALPHA)
    with pytest.raises(ValueError, match="gps_tow_s"):
        pvt.solve(s["prn"], s["pos"], s["clk"], s["pr"], iono_alpha=ALPHA, iono_beta=BETA)
    with pytest.raises(ValueError, match="sat_vel_mps"):
        pvt.solve(s["prn"], s["pos"], s["clk"], s["pr"], doppler_hz=s["dop"])


def test_atmosphere_corrections_remove_the_generated_delays():
    """Measurements delayed by the same models (as the generator does) are solved exactly
    when the PVT applies them, and are metres off when it does not."""
    s = scene()
    delay = klobuchar_delay_m(LAT, LON, EL, AZ, TOW, ALPHA, BETA) + \
        saastamoinen_delay_m(LAT, H, EL)
    pr = s["pr"] + delay
    sol = solve(s, pr=pr, gps_week=2400, gps_tow_s=TOW, iono_alpha=ALPHA, iono_beta=BETA,
                troposphere=True)
    assert sol.corrections == ("klobuchar", "saastamoinen")
    assert np.linalg.norm(sol.position_ecef_m - s["r"]) < 1e-3
    assert sol.gps_tow_s == pytest.approx(TOW - B_M / pvt.C_LIGHT, abs=1e-9)
    raw = solve(s, pr=pr)
    assert np.linalg.norm(raw.position_ecef_m - s["r"]) > 1.0


def test_klobuchar_night_floor_and_obliquity():
    """At night (|x| >= 1.57) the delay is F * 5 ns; at zenith F = 1 + 16 * 0.03^3."""
    night = 345_600.0 + 2 * 3600.0 - LON / 15 * 3600.0   # 02:00 local
    d = klobuchar_delay_m(LAT, LON, 90.0, 0.0, night, ALPHA, BETA)
    assert d == pytest.approx(pvt.C_LIGHT * 5e-9 * (1 + 16 * 0.03 ** 3), rel=1e-12)
    with pytest.raises(ValueError):
        klobuchar_delay_m(LAT, LON, -1.0, 0.0, night, ALPHA, BETA)


def test_klobuchar_agrees_with_gnss_lib_py():
    """gnss-lib-py implements the model in radians (Misra & Enge) with rounded constants,
    and its obliquity factor ``1 + 0.516 (1.6755 - E)^3`` puts 1.6755 where the standard's
    ``0.53 pi`` is 1.6650 (a 1.3 % larger factor at 20 degrees); the vertical delays (each
    divided by its own obliquity factor) agree to 0.1 %."""
    from gnss_lib_py.navdata.navdata import NavData
    from gnss_lib_py.utils.gnss_models import _calculate_iono_delay
    from gnss_lib_py.utils.time_conversions import tow_to_gps_millis
    s = scene()
    sv = NavData()
    sv["x_sv_m"], sv["y_sv_m"], sv["z_sv_m"] = pvt.rotate_z(
        s["pos"], pvt.OMEGA_E_DOT * s["tau"]).T
    sv["vx_sv_mps"] = sv["vy_sv_mps"] = sv["vz_sv_mps"] = np.zeros(8)
    millis = tow_to_gps_millis(2400, TOW)
    ref = _calculate_iono_delay(millis, {"gps": np.array([ALPHA, BETA])}, s["r"],
                                sv_posvel=sv)
    ours = klobuchar_delay_m(LAT, LON, EL, AZ, TOW, ALPHA, BETA)
    assert np.all(ours > 1.0)
    el_r = np.deg2rad(EL)
    f_ours = 1 + 16 * (0.53 - EL / 180) ** 3
    f_theirs = 1 + 0.516 * (1.6755 - el_r) ** 3
    # observed: 0.07 %
    np.testing.assert_allclose(ours / f_ours, np.ravel(ref) / f_theirs, rtol=0.001)


def test_saastamoinen_zenith_delay_and_range():
    """Sea-level zenith delay of the standard atmosphere: 2.3 m dry + wet, the textbook
    figure; 1/cos z growth; out-of-range heights raise."""
    z = saastamoinen_delay_m(45.0, 0.0, 90.0)
    assert 2.3 < z < 2.5
    assert saastamoinen_delay_m(45.0, 0.0, 30.0) == pytest.approx(2 * z, rel=1e-12)
    with pytest.raises(ValueError, match="range"):
        saastamoinen_delay_m(45.0, 50_000.0, 45.0)
    with pytest.raises(ValueError, match="elevation"):
        saastamoinen_delay_m(45.0, 0.0, 1.0)


def test_no_convergence_gives_no_fix():
    sol = solve(scene(), config=pvt.PvtConfig(max_iterations=2))
    assert sol.status is pvt.PvtStatus.NO_FIX_DIVERGED and not sol.valid
    assert np.all(np.isnan(sol.position_ecef_m)) and sol.iterations == 2


def test_the_velocity_error_covariance_matches_the_weighted_geometry():
    """Range-rate noise proportional to the pseudorange sigmas (k sigma_i, the same relative
    weights): the velocity and drift errors have covariance k^2 (H^T W H)^-1 (seeded)."""
    s = scene()
    sig = pvt.pseudorange_sigma_m(s["cn0"], EL)
    k = 0.01
    rate = -s["dop"] * ephemeris.L1_WAVELENGTH_M
    rng = np.random.default_rng(4242)
    trials, nees = 300, 0.0
    for _ in range(trials):
        sol = solve(s, sat_vel_mps=s["vel"], sat_clock_drift=s["drift"],
                    pseudorange_rate_mps=rate + k * sig * rng.standard_normal(8))
        dv = np.append(sol.velocity_ecef_mps - s["v"], sol.clock_drift_mps - DRIFT_MPS)
        nees += dv @ np.linalg.solve(k ** 2 * sol.covariance_m2, dv)
    lo, hi = chi2.ppf([0.0005, 0.9995], 4 * trials)
    assert lo < nees < hi
