"""Fixed-point unscented filter: bit for bit against Python integers (the AUKF patent's
parameters, augmented n = 10, a carrier-phase model with an I/Q measurement), against
float64 over many steps (stated bound, P PSD, no events), the counted Cholesky recovery after a P upset, and
the refusal of UT weights the formats cannot hold."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from dsp.estimation import NonlinearModel, UkfFormats, UnscentedKalmanFilter, sigma_weights
from dsp.estimation.formats import to_fixed
from dsp.estimation.ukf import psd_sqrt

from estimation_reference import IntArith, rnd_int, trig_int, ukf_step_int

# the AUKF patent's UT: epsilon (alpha) 1.027, kappa 0, beta 2; 4 states + 4 process + 2 measurement noises
UT = dict(alpha=1.027, beta=2.0, kappa=0.0)
F = np.array([[0.98, 0.1, 0.005, 0.0], [0, 0.95, 0.1, 0.005], [0, 0, 0.95, 0.1], [0, 0, 0, 0.95]])
Q = np.diag([1e-3, 1e-4, 1e-5, 1e-6])
R = np.eye(2) * 0.05          # I/Q noise per component: 10 dB SNR
MODEL = NonlinearModel.phase_iq(F, Q, R)
P0 = np.eye(4) * 0.01


def simulate(seed: int, T: int):
    rng = np.random.default_rng(seed)
    Lq = np.linalg.cholesky(Q)
    x = np.zeros(4)
    xs, z = np.empty((T, 4)), np.empty((T, 2))
    w = rng.standard_normal((T, 4)) @ Lq.T
    v = rng.standard_normal((T, 2)) * math.sqrt(0.05)
    for k in range(T):
        x = F @ x + w[k]
        xs[k] = x
        z[k] = (math.cos(x[0]) + v[k, 0], math.sin(x[0]) + v[k, 1])
    return xs, z


def test_aukf_patent_weights():
    wm, wc, c = sigma_weights(10, 1.027, 2.0, 0.0)
    np.testing.assert_allclose([wm[0], wc[0], wm[1]], [0.051889, 1.99716, 0.047406], atol=5e-6)


def _int_reference(fm, x0, P0_, zq, upset_at=None, upset=None, noise="augmented"):
    """The Python-integer filter over ``zq`` (None = implausible), ``upset(P)`` before step
    ``upset_at``."""
    A = IntArith(fm)
    n, m = 4, 2
    aug = noise == "augmented"
    L = n + (n + m if aug else 0)
    wm, wc, c = sigma_weights(L, **UT)
    wmq, wcq, cq = [int(v) for v in to_fixed(wm, fm.W)], [int(v) for v in to_fixed(wc, fm.W)], int(to_fixed(c, fm.W))
    Lq, Lr = (np.sqrt(c) * psd_sqrt(a) for a in (Q, R))
    Lq, Lr = to_fixed(Lq, fm.U).tolist(), to_fixed(Lr, fm.U).tolist()
    Qq, Rq = to_fixed(Q, fm.Pp).tolist(), to_fixed(R, fm.Pyy).tolist()
    Fq = to_fixed(F, fm.prm).tolist()
    amp = int(to_fixed(1.0, fm.prm))
    r = fm.fracs()
    half = 1

    def model_f(x, w):
        return [rnd_int((w[i] << (r["prm"])) + sum(Fq[i][j] * x[j] for j in range(n)), r["prm"], half)
                for i in range(n)]

    def model_h(x, v):
        out = []
        for k, fn in enumerate((math.cos, math.sin)):
            acc = amp * trig_int(fn, x[0], r["X"], r["Y"], half) + (v[k] << (r["prm"] + r["Y"] - r["X"]))
            out.append(rnd_int(acc, r["prm"], half))
        return out

    pfloor = (max(1, int(to_fixed(1e-12, fm.P))), max(1, int(to_fixed(1e-12, fm.Pp))))
    x, P = [int(v) for v in to_fixed(x0, fm.x)], to_fixed(P0_, fm.P).tolist()
    events = {"chol_fail": 0, "s_not_pd": 0, "implausible": 0}
    xs, Ps = [], []
    for k, zk in enumerate(zq):
        if k == upset_at:
            P = upset(P)
        x, P = ukf_step_int(A, x, P, zk, model_f, model_h, Qq, Rq, Lq, Lr, wmq, wcq, cq, pfloor, n, m,
                            aug, True, events)
        xs.append(list(x))
        Ps.append([list(row) for row in P])
    return np.array(xs), np.array(Ps), events, A.sat


def _flip_sign_bit(v, width):
    """A sign-bit upset of a two's-complement word held sign-extended."""
    return v ^ (-1 << (width - 1))


@pytest.mark.parametrize("noise", ["augmented", "additive"])
def test_fixed_bit_exact_against_python_integers_with_an_upset(noise):
    fm = UkfFormats()
    _, z = simulate(3, 90)
    z[17] = np.nan                                   # an implausible measurement: predict only
    ukf = UnscentedKalmanFilter(MODEL, np.zeros(4), P0, arithmetic=fm, noise=noise, **UT)
    first = ukf.run(z[:40], keep_P=True)
    w = fm.P.width
    # an upset of the stored covariance: the sign bit of the P[0, 0] word (P indefinite)
    ukf.P[0, 0, 0] = _flip_sign_bit(int(ukf.P[0, 0, 0]), w)
    second = ukf.run(z[40:], keep_P=True)

    def upset(P):
        P[0][0] = _flip_sign_bit(P[0][0], w)
        return P

    zq = [None if not np.all(np.isfinite(zk)) else [int(v) for v in to_fixed(zk, fm.z)] for zk in z]
    xs, Ps, events, sat = _int_reference(fm, np.zeros(4), P0, zq, upset_at=40, upset=upset, noise=noise)
    got_x = np.concatenate([first.x[0], second.x[0]]) * 2.0 ** fm.x.frac
    got_P = np.concatenate([first.P[0], second.P[0]]) * 2.0 ** fm.P.frac
    np.testing.assert_array_equal(got_x.astype(np.int64), xs)
    np.testing.assert_array_equal(got_P.astype(np.int64), Ps)
    assert second.events["chol_fail"] == events["chol_fail"] == 1
    assert second.events["implausible"] == events["implausible"] == 1
    assert second.events["s_not_pd"] == 0
    for s, v in sat.items():
        assert second.events[f"sat_{s}"] == v, s
    # recovered: the covariance is positive definite again after the upset
    assert np.linalg.eigvalsh(second.P[0, 1:]).min() > 0


def _fixed_vs_float(T: int, seed: int = 11):
    xs, z = simulate(seed, T)
    kw = dict(noise="augmented", **UT)
    f64 = UnscentedKalmanFilter(MODEL, np.zeros(4), P0, **kw).run(z, keep_P=True)
    fx = UnscentedKalmanFilter(MODEL, np.zeros(4), P0, arithmetic=UkfFormats(), **kw).run(z, keep_P=True)
    dx = np.abs(fx.x[0] - f64.x[0]).max(axis=0)
    dP = np.abs(fx.P[0] - f64.P[0]).max()
    rmse = np.sqrt(np.mean((f64.x[0] - xs) ** 2, axis=0))
    eig = np.linalg.eigvalsh(fx.P[0]).min()
    return dx, dP, rmse, eig, fx.events


# measured (seed 11, 1e5 steps: ``_fixed_vs_float(100_000)``, 36 s, as the slow test runs it):
# max |x_fixed - x_f64| = [3.56e-5, 1.28e-5, 7.2e-6, 2.2e-6], max |P_fixed - P_f64| = 1.07e-6,
# smallest eigenvalue of P_fixed 9.4e-6, no event; float64 RMSE of theta 0.079 rad. Stated
# bounds (1.5-2.5x the measurement):
BOUND_X = np.array([6e-5, 2.5e-5, 1.5e-5, 5e-6])
BOUND_P = 2.5e-6


def _check_fixed_vs_float(T):
    dx, dP, rmse, eig, events = _fixed_vs_float(T)
    assert np.all(dx < BOUND_X), (dx, BOUND_X)
    assert dP < BOUND_P, dP
    assert rmse[0] < 0.1
    assert eig > 0
    assert not any(events.values()), {k: v for k, v in events.items() if v}


def test_fixed_within_bound_of_float64_short():
    _check_fixed_vs_float(5_000)


@pytest.mark.slow
def test_fixed_within_bound_of_float64_1e5_steps():
    _check_fixed_vs_float(100_000)


@pytest.mark.parametrize("kwargs,fm,msg", [
    (dict(alpha=1e-3), UkfFormats(),
     "UT weights not representable in fixed point: |Wm0| = 999999 beyond the range of the W format"),
    (dict(alpha=0.3), UkfFormats(),
     "UT weights not representable in fixed point: sum |Wm| = 21.2222 > 8 (rounding errors amplified by it); "
     "alpha >= 0.4"),
    (dict(alpha=1.027), UkfFormats().with_(W=UkfFormats().W.__class__(24, 22, True, "half_up", "saturate")),
     "UT weights not representable in fixed point: |c = L + lambda| = 10.5473 beyond the range of the W format"),
    (dict(alpha=1.027), UkfFormats().with_(W=UkfFormats().W.__class__(14, 8, True, "half_up", "saturate")),
     "UT weights not representable in fixed point: Wm0 = 0.0518892 quantised to 0.0507812 in sQ5.8(half_up,saturate): "
     "relative error 0.0214 > 2^-12; no alpha in (0, 10] would do; widen the W format"),
])
def test_weights_the_formats_cannot_hold_are_refused(kwargs, fm, msg):
    args = dict(noise="augmented", arithmetic=fm, beta=2.0, kappa=0.0)
    args.update(kwargs)
    with pytest.raises(ValueError, match=re.escape(msg)):
        UnscentedKalmanFilter(MODEL, np.zeros(4), P0, **args)


def test_refusal_names_the_alpha_needed():
    with pytest.raises(ValueError, match=r"alpha >= (\S+) would do \(L = 10, beta = 2, kappa = 0\)") as ei:
        UnscentedKalmanFilter(MODEL, np.zeros(4), P0, alpha=1e-3, beta=2.0, noise="augmented",
                              arithmetic=UkfFormats())
    need = float(re.search(r"alpha >= (\S+) would", str(ei.value)).group(1))
    UnscentedKalmanFilter(MODEL, np.zeros(4), P0, alpha=need * 1.01, beta=2.0, noise="augmented",
                          arithmetic=UkfFormats())
    with pytest.raises(ValueError, match="UT weights not representable"):
        UnscentedKalmanFilter(MODEL, np.zeros(4), P0, alpha=need * 0.98, beta=2.0, noise="augmented",
                              arithmetic=UkfFormats())


def test_kernel_instanced_per_model_and_cached_across_processes():
    """The model functions are bound into one kernel per model (distinct names, so distinct
    cache entries), and a fresh process loads that kernel from numba's cache instead of
    compiling it again (~13-20 s before)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    from dsp.estimation import ukf as U

    k_iq = U._kernel_for(MODEL.f, MODEL.h)
    lin = NonlinearModel.linear(F, np.ones((2, 4)), Q, R)
    k_lin = U._kernel_for(lin.f, lin.h)
    assert k_iq is U._kernel_for(MODEL.f, MODEL.h)
    assert k_iq is not k_lin and k_iq.py_func.__name__ != k_lin.py_func.__name__
    UnscentedKalmanFilter(MODEL, np.zeros(4), P0, noise="augmented", **UT).run(np.ones((3, 2)))
    code = ("import numpy as np, sys; sys.path.insert(0, 'tests/dsp/estimation');"
            "from test_ukf_fixed import MODEL, P0, UT; from dsp.estimation import ukf as U;"
            "U.UnscentedKalmanFilter(MODEL, np.zeros(4), P0, noise='augmented', **UT).run(np.ones((3, 2)));"
            "s = U._kernel_for(MODEL.f, MODEL.h).stats;"
            "print(sum(s.cache_hits.values()), sum(s.cache_misses.values()))")
    root = Path(__file__).resolve().parents[3]
    env = dict(os.environ, PYTHONPATH=str(root))
    out = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    hits, misses = map(int, out.stdout.split()[-2:])
    assert hits >= 1 and misses == 0, out.stdout
