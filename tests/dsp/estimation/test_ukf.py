"""Unscented Kalman filter: against filterpy on a nonlinear model, equal to the Kalman
filter on linear models (additive and augmented noise), float32 bit for bit against numpy
float32, Cholesky recovery, bad input and configuration."""
from __future__ import annotations

import re

import numpy as np
import pytest
from filterpy.kalman import MerweScaledSigmaPoints
from filterpy.kalman import UnscentedKalmanFilter as FpUKF
from numba import njit

from dsp.estimation import (KalmanFilter, LinearGaussianModel, NonlinearModel,
                            UnscentedKalmanFilter, sigma_weights)

from estimation_reference import ukf_step_f32


@njit(cache=True)
def f_pendulum(x, w, prm, q, out):
    out[0] = x[0] + prm[0, 0] * x[1] + w[0]
    out[1] = x[1] - prm[0, 0] * np.sin(x[0]) + w[1]


@njit(cache=True)
def h_pendulum(x, v, prm, q, out):
    out[0] = np.sin(x[0]) + v[0]
    out[1] = x[0] * x[1] + v[1]


def _random_linear(rng, n, m):
    F = np.eye(n) + 0.2 * rng.standard_normal((n, n))
    F /= max(1.0, np.abs(np.linalg.eigvals(F)).max() / 0.98)
    G, V = 0.3 * rng.standard_normal((n, n)), 0.5 * rng.standard_normal((m, m))
    return F, rng.standard_normal((m, n)), G @ G.T + 1e-3 * np.eye(n), V @ V.T + 0.2 * np.eye(m)


@pytest.mark.parametrize("alpha,beta,kappa", [(0.5, 2.0, 0.0), (1.0, 2.0, 1.0), (0.8, 0.0, -1.0)])
def test_float64_matches_filterpy_on_a_nonlinear_model(alpha, beta, kappa):
    dt = 0.05
    Q, R = np.diag([1e-4, 4e-4]), np.diag([0.01, 0.02])
    model = NonlinearModel(f_pendulum, h_pendulum, Q, R, prm_f=[[dt]])
    rng = np.random.default_rng(7)
    z = rng.normal(0, 0.1, (60, 2)) + np.array([0.5, 0.1])
    ours = UnscentedKalmanFilter(model, [0.3, 0.0], np.eye(2) * 0.5, alpha=alpha, beta=beta,
                                 kappa=kappa).run(z, keep_P=True)
    pts = MerweScaledSigmaPoints(2, alpha=alpha, beta=beta, kappa=kappa)
    fx = lambda x, dt_: np.array([x[0] + dt_ * x[1], x[1] - dt_ * np.sin(x[0])])
    hx = lambda x: np.array([np.sin(x[0]), x[0] * x[1]])
    fp = FpUKF(dim_x=2, dim_z=2, dt=dt, hx=hx, fx=fx, points=pts)
    fp.x, fp.P, fp.Q, fp.R = np.array([0.3, 0.0]), np.eye(2) * 0.5, Q, R
    for k in range(len(z)):
        fp.predict()
        fp.update(z[k])
        np.testing.assert_allclose(ours.x[0, k], fp.x, rtol=1e-12, atol=1e-12, err_msg=f"step {k}")
        np.testing.assert_allclose(ours.P[0, k], fp.P, rtol=1e-12, atol=1e-12, err_msg=f"step {k}")


@pytest.mark.parametrize("noise", ["additive", "augmented"])
@pytest.mark.parametrize("seed,n,m,alpha,beta,kappa", [(1, 3, 1, 1.0, 0.0, 0.0), (2, 4, 2, 1.0, 2.0, 1.0),
                                                       (3, 4, 2, 0.7, 2.0, 0.0)])
def test_ukf_on_a_linear_model_equals_the_kalman_filter(noise, seed, n, m, alpha, beta, kappa):
    rng = np.random.default_rng(seed)
    F, H, Q, R = _random_linear(rng, n, m)
    z = rng.standard_normal((80, m))
    x0, P0 = rng.standard_normal(n), np.eye(n) * 2.0
    kf = KalmanFilter(LinearGaussianModel(F, H, Q, R), x0, P0).run(z, keep_P=True)
    uk = UnscentedKalmanFilter(NonlinearModel.linear(F, H, Q, R), x0, P0, alpha=alpha, beta=beta,
                               kappa=kappa, noise=noise).run(z, keep_P=True)
    np.testing.assert_allclose(uk.x, kf.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(uk.P, kf.P, rtol=1e-12, atol=1e-12)


def test_float32_bit_exact_against_numpy_float32():
    rng = np.random.default_rng(5)
    n, m = 3, 2
    F, H, Q, R = _random_linear(rng, n, m)
    z = rng.standard_normal((40, m))
    alpha, beta, kappa = 0.9, 2.0, 0.0
    run = UnscentedKalmanFilter(NonlinearModel.linear(F, H, Q, R), np.zeros(n), np.eye(n),
                                alpha=alpha, beta=beta, kappa=kappa, arithmetic="float32").run(z, keep_P=True)
    f32 = lambda a: [[np.float32(v) for v in row] for row in np.atleast_2d(a)]
    wm, wc, c = sigma_weights(n, alpha, beta, kappa)
    wm, wc, c = [np.float32(v) for v in wm], [np.float32(v) for v in wc], np.float32(c)
    x, P = [np.float32(0)] * n, f32(np.eye(n))
    for k in range(len(z)):
        x, P = ukf_step_f32(x, P, [np.float32(v) for v in z[k]], f32(F), f32(H), f32(Q), f32(R), wm, wc, c)
        assert all(type(v) is np.float32 for v in x)
        np.testing.assert_array_equal(run.x[0, k], np.array(x, np.float32), err_msg=f"step {k}")
        np.testing.assert_array_equal(run.P[0, k], np.array(P, np.float32), err_msg=f"step {k}")


def test_cholesky_failure_is_counted_and_recovered():
    rng = np.random.default_rng(9)
    F, H, Q, R = _random_linear(rng, 3, 1)
    ukf = UnscentedKalmanFilter(NonlinearModel.linear(F, H, Q, R), np.zeros(3), np.eye(3))
    ukf.P[0] = np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, -1.0]])  # a corrupted P
    run = ukf.run(rng.standard_normal((20, 1)), keep_P=True)
    assert run.events["chol_fail"] == 1
    assert np.all(np.isfinite(run.x)) and np.linalg.eigvalsh(run.P[0, -1]).min() > 0


@pytest.mark.parametrize("arith", ["float64", "float32"])
def test_nan_input_counted_never_nan_state_and_batches(arith):
    rng = np.random.default_rng(10)
    F, H, Q, R = _random_linear(rng, 4, 2)
    z = rng.standard_normal((3, 50, 2))
    z[0, 3, 1], z[2, 8, 0], z[1, 9] = np.nan, np.inf, 1e9
    model = NonlinearModel.linear(F, H, Q, R)
    run = UnscentedKalmanFilter(model, np.zeros(4), np.eye(4), arithmetic=arith, trials=3,
                                z_limit=1e3).run(z)
    assert run.events["implausible"] == 3
    assert np.all(np.isfinite(run.x))
    one = UnscentedKalmanFilter(model, np.zeros(4), np.eye(4), arithmetic=arith, z_limit=1e3).run(z[1])
    np.testing.assert_array_equal(run.x[1], one.x[0])


@pytest.mark.parametrize("kwargs,msg", [
    (dict(alpha=0.0), "alpha must be in (0, 10], not 0.0"),
    (dict(beta=-1.0), "beta must be >= 0, not -1.0"),
    (dict(kappa=-5.0), "kappa must make L + kappa > 0 (L = 2), not -5.0"),
    (dict(noise="multiplicative"), "noise must be 'additive' or 'augmented', not 'multiplicative'"),
    (dict(arithmetic="float16"), "arithmetic must be 'float64', 'float32' or a format table, not 'float16'"),
    (dict(P0=np.array([[1.0, 0.0], [0.0, -3.0]])), "P0 must be positive semi-definite, not a matrix with eigenvalue -3"),
])
def test_bad_configuration_errors(kwargs, msg):
    model = NonlinearModel(f_pendulum, h_pendulum, np.eye(2) * 1e-3, np.eye(2) * 0.01, prm_f=[[0.1]])
    args = dict(model=model, x0=np.zeros(2), P0=np.eye(2))
    args.update(kwargs)
    with pytest.raises(ValueError, match=re.escape(msg)):
        UnscentedKalmanFilter(**args)
    with pytest.raises(ValueError, match=re.escape("Q must be square (n x n), not (2, 3)")):
        NonlinearModel(f_pendulum, h_pendulum, np.ones((2, 3)), np.eye(2))
