"""Line-of-sight dynamics: the jerk model's exact discretisation, the profiles' continuity."""
import math

import numpy as np
import pytest
from scipy.linalg import expm

from cosim.gnss import dynamics as dy
from dsp.gnss.ephemeris import L1_WAVELENGTH_M
from cosim.gnss.dynamics import CsvProfile, JerkProcess, PolynomialProfile
from dsp.gnss.jerk import jerk_phi, jerk_q


def _q_alpha0(q, T):
    # The jerk model's discrete process noise, alpha -> 0.
    return q * np.array([[T**7 / 252, T**6 / 72, T**5 / 30, T**4 / 24],
                         [T**6 / 72, T**5 / 20, T**4 / 8, T**3 / 6],
                         [T**5 / 30, T**4 / 8, T**3 / 3, T**2 / 2],
                         [T**4 / 24, T**3 / 6, T**2 / 2, T]])


def _van_loan(alpha, q, T):
    """Independent formulation: Van Loan's block-matrix exponential."""
    A = np.zeros((4, 4))
    A[0, 1] = A[1, 2] = A[2, 3] = 1.0
    A[3, 3] = -alpha
    B = np.array([[0.0], [0], [0], [1]])
    M = np.zeros((8, 8))
    M[:4, :4] = -A
    M[:4, 4:] = q * B @ B.T
    M[4:, 4:] = A.T
    E = expm(M * T)
    phi = E[4:, 4:].T
    return phi, phi @ E[:4, 4:]


@pytest.mark.parametrize("T", [1e-3, 1e-2])
def test_jerk_q_alpha_zero_matches_the_polynomial_form(T):
    np.testing.assert_allclose(jerk_q(0.0, 5.0, T), _q_alpha0(5.0, T), rtol=1e-13, atol=0)
    # A tiny alpha differs from the limit by O(alpha T) relative, nothing more (no cancellation).
    np.testing.assert_allclose(jerk_q(1e-9, 5.0, T), _q_alpha0(5.0, T), rtol=3e-9 * T, atol=0)


@pytest.mark.parametrize("alpha,T", [(0.7, 1.0), (3.0, 0.5), (0.1, 0.2), (50.0, 0.01)])
def test_jerk_phi_q_match_van_loan(alpha, T):
    phi, Q = _van_loan(alpha, 2.0, T)
    np.testing.assert_allclose(jerk_phi(alpha, T), phi, rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(jerk_q(alpha, 2.0, T), Q, rtol=1e-9, atol=0)


def test_jerk_process_stationary_jerk_variance():
    # q = 2 alpha sigma_j^2: the jerk state's stationary variance is sigma_j^2.
    alpha, sigma_j = 20.0, 3.0
    p = JerkProcess(x0=(0, 0, 0, 0), alpha_per_s=alpha, q=JerkProcess.q_from_sigma(alpha, sigma_j))
    X = p.states(60.0, np.random.default_rng(3))
    w2 = X[2000:, 3]
    # ~60 s / (1/alpha) * 2 = 2400 independent looks: 3 % relative std of the variance.
    assert abs(np.var(w2) / sigma_j**2 - 1) < 0.1


def test_hermite_trajectory_is_exact_for_deterministic_jerk_and_continuous():
    x0 = (0.3, 32995.519, 323.356, 40.0)
    traj = JerkProcess(x0=x0, alpha_per_s=0.0, q=0.0).realise(0.05, np.random.default_rng(0))
    t = np.linspace(0, 0.05, 1237)
    th = x0[0] + x0[1] * t + x0[2] * t**2 / 2 + x0[3] * t**3 / 6
    k = L1_WAVELENGTH_M / (2 * np.pi)
    ev = traj.evaluate(t)
    np.testing.assert_allclose(traj.delta_range_m(t), -(th - th[0]) * k, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ev[1], -(x0[1] + x0[2] * t + x0[3] * t**2 / 2) * k, rtol=1e-10)
    np.testing.assert_allclose(ev[2], -(x0[2] + x0[3] * t) * k, rtol=1e-8)
    # With noise: phase, frequency and rate continuous across grid points.
    traj = JerkProcess(q=1e4).realise(0.02, np.random.default_rng(1))
    tk = np.arange(1, 20) * 1e-3
    lo, hi = traj.theta(tk - 1e-12), traj.theta(tk + 1e-12)
    np.testing.assert_allclose(lo[:3], hi[:3], rtol=1e-7, atol=1e-9)  # float round-off of the quintic


def test_aukf_patent_initial_doppler():
    traj = dy.aukf_patent_dynamics(q=0.0).realise(1.0)
    ev = traj.evaluate(np.array([0.0]))
    assert -ev[1, 0] / L1_WAVELENGTH_M == pytest.approx(32995.519 / (2 * np.pi), rel=1e-12)
    assert -ev[2, 0] / L1_WAVELENGTH_M == pytest.approx(323.356 / (2 * np.pi), rel=1e-12)
    assert 32995.519 / (2 * np.pi) == pytest.approx(5251.40, abs=0.01)


def test_polynomial_segments_and_steps():
    p = PolynomialProfile(range_m=2e7, range_rate_mps=-100.0, range_accel_mps2=1.0,
                          jerk_segments=((1.0, -49.0), (2.0, 0.0)), accel_steps=((3.0, 5.0),))
    tr = p.realise(4.0)
    e = tr.evaluate(np.array([0.5, 1.5, 2.5, 2.999999999, 3.000000001, 3.5]))
    assert e[3].tolist() == [0.0, -49.0, 0.0, 0.0, 0.0, 0.0]
    # accel: 1 until 1 s, 1 - 49 (t-1) to 2 s = -48, step +5 at 3 s.
    np.testing.assert_allclose(e[2], [1.0, 1 - 24.5, -48.0, -48.0, -43.0, -43.0], atol=1e-6)
    # velocity continuous, closed form at 2.5 s: -100 + 1*1 + (1*1 - 49/2) - 48*0.5
    assert e[1, 2] == pytest.approx(-100 + 1 + 1 - 24.5 - 24.0, abs=1e-9)
    t = np.sort(np.random.default_rng(0).uniform(0, 4, 5000))
    np.testing.assert_allclose(tr.delta_range_m(t), tr.delta_range_m(t[::-1])[::-1], atol=1e-9)
    np.testing.assert_allclose(tr.delta_range_m(t), tr.evaluate(t)[0] - 2e7, atol=1e-7)


def test_csv_profile_reproduces_a_cubic(tmp_path):
    t = np.linspace(0, 5, 51)
    r = 2e7 - 800 * t + 3 * t**2 + 0.5 * t**3
    f = tmp_path / "los.csv"
    f.write_text("# test\ntime_s,range_m\n" + "\n".join(f"{float(a)!r},{float(b)!r}" for a, b in zip(t, r)))
    tr = CsvProfile(path=str(f)).realise(4.0)
    tt = np.array([0.0, 1.234, 3.9])
    e = tr.evaluate(tt)
    np.testing.assert_allclose(e[1], -800 + 6 * tt + 1.5 * tt**2, rtol=1e-9)
    np.testing.assert_allclose(e[3], 3.0, rtol=1e-4)  # 2e7 m ranges: 4e-9 m rounding / (0.1 s)^3
    np.testing.assert_allclose(tr.delta_range_m(tt), -800 * tt + 3 * tt**2 + 0.5 * tt**3, atol=1e-6)


@pytest.mark.parametrize("kw,msg", [
    (dict(t_s=(0, 1, 1, 2), range_m=(1, 2, 3, 4)), "strictly increasing, not 1.0 then 1.0"),
    (dict(t_s=(1, 2, 3, 4), range_m=(1, 2, 3, 4)), "must start at t <= 0 s, not 1.0"),
    (dict(t_s=(0, 1), range_m=(1, 2)), ">= 4 rows"),
    (dict(path="/nonexistent/los.csv"), "range table '/nonexistent/los.csv' is not a file"),
])
def test_csv_profile_errors(kw, msg):
    with pytest.raises(ValueError, match=msg):
        CsvProfile(**kw)


def test_csv_table_must_cover_the_record():
    with pytest.raises(ValueError, match="ends at 3.0 s, before the record's end 5.0 s"):
        CsvProfile(t_s=(0, 1, 2, 3), range_m=(1, 2, 3, 4)).realise(5.0)


@pytest.mark.parametrize("kw,msg", [
    (dict(alpha_per_s=-1.0), "alpha_per_s must be >= 0, not -1.0"),
    (dict(q=-1.0), r"q \(process-noise intensity, rad\^2/s\^7\) must be >= 0, not -1.0"),
    (dict(q=math.nan), "q must be a finite number, not nan"),
    (dict(x0=(0, 1)), "x0 must have 4 entries"),
])
def test_jerk_process_errors(kw, msg):
    with pytest.raises(ValueError, match=msg):
        JerkProcess(**kw)
