import numpy as np
import pytest

from dsp.gnss.ephemeris import L1_WAVELENGTH_M
from cosim.ins.ins_error import InsAiding, InsErrors
from cosim.ins.trajectory import G_MPS2, Scenario, PaperTrajectory, los_kinematics


def test_seed_profile_figures():
    tr = PaperTrajectory()
    t = np.arange(0, 150, 1e-3)
    s, v, a, j = tr.kinematics(t)
    assert v.max() == pytest.approx(8300.0, rel=1e-12)
    assert a.max() / G_MPS2 == pytest.approx(50.0, rel=1e-12)
    assert np.abs(j).max() / G_MPS2 == pytest.approx(5.0, rel=1e-12)
    assert tr.hold_s == pytest.approx(6.927, abs=1e-3)
    assert v[-1] == pytest.approx(8300.0, rel=1e-12) and v[0] == 0.0
    # s, v, a are integrals of each other (trapezoid)
    np.testing.assert_allclose(np.cumsum((v[1:] + v[:-1]) / 2e3)[-1], s[-1] - s[0], rtol=1e-9)


def _derivative_check(sc, t, h=1e-3):
    f = sc.doppler_hz
    num = (f(t - 2 * h) - 8 * f(t - h) + 8 * f(t + h) - f(t + 2 * h)) / (12 * h)
    return num, sc.truth_at(t)["doppler_rate_hz_s"]


def test_b4_doppler_rate_formula_vs_numerical_derivative():
    sc = Scenario()
    knots = np.array([k for seg in sc.traj.jerk_segments() for k in seg])
    t = np.linspace(0.05, 149.9, 3001)
    t = t[np.min(np.abs(t[:, None] - knots[None]), axis=1) > 0.01]   # the stencil sees no knot
    num, ana = _derivative_check(sc, t)
    rel = np.abs(num - ana) / np.abs(ana)
    assert rel.max() <= 1e-6, f"max relative error {rel.max():.3g}"


def test_b4_acceleration_only_formula_fails_the_same_check():
    # The INS paper's formula as reconstructed keeps only (As - Au).e: ~0.6 % short at 8300 m/s
    sc = Scenario()
    t = np.array([100.0])
    Ru, Vu, Au = sc.user(t)
    Rs, Vs, As = sc.satellite(t)
    d = Rs - Ru
    e = d / np.linalg.norm(d, axis=0)
    acc_only = -np.sum((As - Au) * e, axis=0) / L1_WAVELENGTH_M
    num, _ = _derivative_check(sc, t)
    assert np.abs(acc_only - num) / np.abs(num) > 1e-3


def test_los_kinematics_against_finite_difference_of_range():
    sc = Scenario()
    t, h = np.array([20.0, 80.0]), 1e-4
    rho, rd, rdd = sc.los(t)
    rp, rm = sc.los(t + h)[0], sc.los(t - h)[0]
    np.testing.assert_allclose((rp - rm) / (2 * h), rd, rtol=1e-7)


def test_csv_trajectory_and_non_monotonic_time(tmp_path):
    good = tmp_path / "ok.csv"
    t = np.linspace(0, 10, 50)
    np.savetxt(good, np.c_[t, 3.0 * t ** 2], delimiter=",")
    k = PaperTrajectory(duration_s=10, csv_path=str(good)).kinematics(np.array([5.0]))
    assert k[1, 0] == pytest.approx(30.0, rel=1e-9) and k[2, 0] == pytest.approx(6.0, rel=1e-9)
    bad = tmp_path / "bad.csv"
    tt = t.copy()
    tt[7] = tt[5]
    np.savetxt(bad, np.c_[tt, t], delimiter=",")
    with pytest.raises(ValueError, match=r"line 8, column 1: time must increase strictly; .* does "
                                         r"not follow .* \(line 7\)"):
        PaperTrajectory(duration_s=10, csv_path=str(bad))


@pytest.mark.parametrize("kw, msg", [
    ({"duration_s": -1.0}, "duration_s must be a finite number > 0"),
    ({"jerk_g_s": 0.0}, "jerk_g_s must be a finite number > 0"),
    ({"v_max_mps": 1000.0}, "v_max_mps must be >= the two ramps"),
    ({"duration_s": 20.0}, "duration_s must cover the manoeuvre"),
])
def test_trajectory_bad_input(kw, msg):
    with pytest.raises(ValueError, match=msg):
        PaperTrajectory(**kw)


def test_ins_aiding_errors():
    sc = Scenario(PaperTrajectory(duration_s=40.0))
    none = InsAiding(sc, InsErrors(0, 0, 0, 0), n_epochs=40000)
    np.testing.assert_array_equal(none.rate, none.true_rate)
    # accelerometer bias alone: a constant acceleration error -> rate error b.e / lambda at t~0
    b = InsAiding(sc, InsErrors(0, 1.0, 0, 0, signs=(1.0, 0.0, 0.0)), n_epochs=40000)
    err = b.rate - b.true_rate
    assert abs(err[0]) <= 1e-3 * G_MPS2 / L1_WAVELENGTH_M + 1e-9
    assert abs(err[0]) > 0.2 * 1e-3 * G_MPS2 / L1_WAVELENGTH_M
    # gyro drift: the misalignment grows, so the error during the 50 g hold grows in time
    g = InsAiding(sc, InsErrors(10.0, 0, 0, 0), n_epochs=40000)
    eg = np.abs(g.rate - g.true_rate)
    assert eg[int(16.5e3)] > 3 * eg[int(6e3)]
    with pytest.raises(ValueError, match="gyro_drift_deg_h must be a finite number >= 0"):
        InsErrors(gyro_drift_deg_h=-1.0)
    with pytest.raises(ValueError, match="T_s must be a finite number > 0 s"):
        InsAiding(sc, T_s=0.0)
