"""Linear Kalman filter: float64 against filterpy, float32 and fixed point bit for bit
against independent evaluations, fixed against float64 within the documented bound, bad
configurations and inputs."""
from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter as FpKalman

from dsp.estimation import KalmanFilter, KalmanFormats, LinearGaussianModel, white_jerk
from dsp.estimation.formats import fmt, to_fixed
from dsp.estimation.kalman import EVENTS, SIGNALS

from estimation_reference import F32Arith, IntArith, kf_step


def random_system(rng, n, m, p, steps=None):
    """A random stable-ish system with states of order 1."""
    def one():
        F = np.eye(n) + 0.2 * rng.standard_normal((n, n))
        F /= max(1.0, np.abs(np.linalg.eigvals(F)).max() / 0.98)
        G = 0.3 * rng.standard_normal((n, n))
        V = 0.5 * rng.standard_normal((m, m))
        return F, rng.standard_normal((m, n)), G @ G.T + 1e-3 * np.eye(n), V @ V.T + 0.2 * np.eye(m), \
            0.5 * rng.standard_normal((n, p))
    if steps is None:
        F, H, Q, R, B = one()
    else:
        F, H, Q, R, B = (np.stack(a) for a in zip(*[one() for _ in range(steps)]))
    return LinearGaussianModel(F, H, Q, R, B if p else None)


@pytest.mark.parametrize("seed,n,m,p,tv", [(1, 3, 1, 0, False), (2, 4, 2, 1, False),
                                           (3, 8, 3, 2, False), (4, 3, 2, 1, True)])
def test_float64_matches_filterpy(seed, n, m, p, tv):
    rng = np.random.default_rng(seed)
    T = 60
    model = random_system(rng, n, m, p, steps=T if tv else None)
    x0, P0 = rng.standard_normal(n), np.eye(n) * 2.0
    z = rng.standard_normal((T, m))
    u = rng.standard_normal((T, p)) if p else None
    ours = KalmanFilter(model, x0, P0).run(z, u, keep_P=True)
    fp = FpKalman(dim_x=n, dim_z=m, dim_u=p)
    fp.x, fp.P = x0[:, None].copy(), P0.copy()
    for k in range(T):
        F, H, Q, R, B = model.at(k)
        fp.predict(u=None if u is None else u[k][:, None], B=B if p else None, F=F, Q=Q)
        fp.update(z[k][:, None], R=R, H=H)
        np.testing.assert_allclose(ours.x[0, k], fp.x[:, 0], rtol=1e-12, atol=1e-12,
                                   err_msg=f"seed {seed} step {k}")
        np.testing.assert_allclose(ours.P[0, k], fp.P, rtol=1e-12, atol=1e-12,
                                   err_msg=f"seed {seed} step {k}")


def _fixed_table():
    return KalmanFormats()


@pytest.mark.parametrize("seed,n,m,p,tv", [(11, 3, 1, 1, False), (12, 4, 2, 0, True),
                                           (13, 2, 2, 1, False)])
def test_fixed_bit_exact_against_unbounded_integers(seed, n, m, p, tv):
    rng = np.random.default_rng(seed)
    T = 40
    model = random_system(rng, n, m, p, steps=T if tv else None)
    fm = _fixed_table()
    x0, P0 = rng.standard_normal(n), np.eye(n) * 2.0
    z = rng.standard_normal((T, m))
    z[7] = np.nan                      # implausible: predict only
    u = rng.standard_normal((T, p)) if p else None
    kf = KalmanFilter(model, x0, P0, fm)
    run = kf.run(z, u, keep_P=True)
    ar = IntArith(fm)
    q = lambda a, s: to_fixed(a, getattr(fm, s)).tolist()
    x, P = q(x0, "x"), q(P0, "P")
    for k in range(T):
        F, H, Q, R, B = model.at(k)
        zk = None if not np.all(np.isfinite(z[k])) else q(z[k], "z")
        uk = q(u[k], "u") if p else []
        x, P = kf_step(ar, x, P, zk, uk, q(F, "F"), q(B, "B"), q(H, "H"), q(Q, "Q"), q(R, "R"))
        np.testing.assert_array_equal(np.round(run.x[0, k] * 2.0 ** fm.x.frac).astype(np.int64), x,
                                      err_msg=f"seed {seed} step {k}")
        np.testing.assert_array_equal(np.round(run.P[0, k] * 2.0 ** fm.P.frac).astype(np.int64), P,
                                      err_msg=f"seed {seed} step {k}")
    np.testing.assert_array_equal(kf.x[0], x)
    np.testing.assert_array_equal(kf.P[0], P)
    assert run.events["implausible"] == 1
    assert {s: run.events[f"sat_{s}"] for s in SIGNALS} == ar.sat
    lo, hi = EVENTS.ranges(kf.ev, fm.fracs())["x"]      # the range log saw every stored x
    assert lo <= run.x.min() and hi >= run.x.max()


def test_fixed_saturation_counted_like_the_reference():
    """A too-narrow x format clamps; the kernel counts exactly the reference's clamps."""
    rng = np.random.default_rng(21)
    model = random_system(rng, 3, 1, 0)
    fm = KalmanFormats(x=fmt(21, 20))   # +-1
    x0 = np.array([0.5, -0.5, 0.5])
    z = 3.0 * np.sign(rng.standard_normal((50, 1)))
    kf = KalmanFilter(model, x0, np.eye(3) * 2.0, fm)
    run = kf.run(z)
    ar = IntArith(fm)
    q = lambda a, s: to_fixed(a, getattr(fm, s)).tolist()
    x, P = q(x0, "x"), q(np.eye(3) * 2.0, "P")
    F, H, Q, R, B = model.at(0)
    for k in range(50):
        x, P = kf_step(ar, x, P, q(z[k], "z"), [], q(F, "F"), q(B, "B"), q(H, "H"), q(Q, "Q"), q(R, "R"))
    np.testing.assert_array_equal(kf.x[0], x)
    assert ar.sat["x"] > 0
    assert run.events["sat_x"] == ar.sat["x"]


@pytest.mark.parametrize("seed,n,m,p", [(31, 3, 1, 1), (32, 4, 2, 1)])
def test_float32_bit_exact_against_numpy_float32(seed, n, m, p):
    rng = np.random.default_rng(seed)
    T = 50
    model = random_system(rng, n, m, p)
    x0, P0 = rng.standard_normal(n), np.eye(n) * 2.0
    z = rng.standard_normal((T, m))
    u = rng.standard_normal((T, p))
    run = KalmanFilter(model, x0, P0, "float32").run(z, u, keep_P=True)
    f32 = lambda a: [[np.float32(v) for v in row] for row in np.atleast_2d(a)]
    F, H, Q, R, B = (f32(a) for a in model.at(0))
    x, P = [np.float32(v) for v in x0], f32(P0)
    ar = F32Arith()
    for k in range(T):
        x, P = kf_step(ar, x, P, [np.float32(v) for v in z[k]], [np.float32(v) for v in u[k]],
                       F, B, H, Q, R)
        assert all(type(v) is np.float32 for v in x)
        np.testing.assert_array_equal(run.x[0, k], np.array(x, np.float32), err_msg=f"step {k}")
        np.testing.assert_array_equal(run.P[0, k], np.array(P, np.float32), err_msg=f"step {k}")


def test_batched_trials_equal_single_runs():
    rng = np.random.default_rng(41)
    model = random_system(rng, 3, 1, 0)
    z = rng.standard_normal((4, 30, 1))
    for arith in ("float64", KalmanFormats()):
        batch = KalmanFilter(model, np.zeros(3), np.eye(3), arith, trials=4).run(z)
        for b in range(4):
            one = KalmanFilter(model, np.zeros(3), np.eye(3), arith).run(z[b])
            np.testing.assert_array_equal(batch.x[b], one.x[0])


def test_runs_carry_state_across_calls():
    rng = np.random.default_rng(42)
    model = random_system(rng, 3, 2, 0, steps=40)
    z = rng.standard_normal((40, 2))
    whole = KalmanFilter(model, np.zeros(3), np.eye(3), KalmanFormats()).run(z).x
    kf = KalmanFilter(model, np.zeros(3), np.eye(3), KalmanFormats())
    parts = np.concatenate([kf.run(z[:15]).x, kf.run(z[15:]).x], axis=1)
    np.testing.assert_array_equal(whole, parts)
    with pytest.raises(ValueError, match="the time-varying model covers 40 steps, not 41"):
        kf.run(z[:1])


# -- fixed against float64 over a long run ----------------------------------------------
#: The documented bound (README, "Estimation library"): on the 3-state white-jerk loop
#: below with the default KalmanFormats, every state of the fixed core stays within
#: BOUND_SIGMA posterior standard deviations of the float64 filter's, and every covariance
#: element within BOUND_P relative (to the diagonal scale), with P positive definite.
BOUND_SIGMA = 1e-3
BOUND_P = 1e-3


def _jerk_run(T, seed):
    model = white_jerk(T_s=1e-2, q=4.0, r=0.05)
    rng = np.random.default_rng(seed)
    t = np.arange(T) * 1e-2
    z = np.sin(0.3 * t)[:, None] * 3.0 + rng.normal(0, np.sqrt(0.05), (T, 1))
    out = {}
    for arith in ("float64", KalmanFormats()):
        kf = KalmanFilter(model, [0.0, 0.0, 0.0], np.eye(3) * 4.0, arith)
        out["fixed" if arith != "float64" else "float"] = kf.run(z, keep_P=True)
    return out


def _check_bound(out):
    fl, fx = out["float"], out["fixed"]
    sig = np.sqrt(np.einsum("btii->bti", fl.P))
    assert np.max(np.abs(fx.x - fl.x) / sig) < BOUND_SIGMA
    scale = np.sqrt(np.einsum("btii->bti", fl.P))
    rel = np.abs(fx.P - fl.P) / (scale[..., :, None] * scale[..., None, :])
    assert np.max(rel) < BOUND_P
    assert np.linalg.eigvalsh(fx.P[0]).min() > 0
    assert np.array_equal(fx.P, np.swapaxes(fx.P, -1, -2))
    assert not any(v for k, v in fx.events.items())


def test_fixed_within_bound_of_float_1e5_steps():
    _check_bound(_jerk_run(100_000, 52))


# -- upsets, bad input, bad configuration ------------------------------------------------
def test_state_upset_is_injected_counted_and_recovers():
    rng = np.random.default_rng(61)
    model = white_jerk(1e-2, 4.0, 0.05)
    z = rng.normal(0, 0.2, (600, 1))
    clean = KalmanFilter(model, np.zeros(3), np.eye(3), KalmanFormats()).run(z)
    kf = KalmanFilter(model, np.zeros(3), np.eye(3), KalmanFormats())
    hit = kf.run(z, upsets=[[100, 0, 0, 0, 28]])   # x[0] bit 28 at step 100: +-16
    assert hit.events["upsets"] == 1
    np.testing.assert_array_equal(hit.x[0, :100], clean.x[0, :100])
    jump = abs(hit.x[0, 100, 0] - clean.x[0, 100, 0])
    assert jump > 1.0
    assert abs(hit.x[0, -1, 0] - clean.x[0, -1, 0]) < 1e-2 * jump   # the filter forgets it
    with pytest.raises(ValueError, match=r"upset \(step, trial, target, element, bit\) out of range: \[0, 0, 0, 3, 1\]"):
        kf.run(z[:2], upsets=[[0, 0, 0, 3, 1]])
    with pytest.raises(ValueError, match="upsets flip bits of fixed-point state words"):
        KalmanFilter(model, np.zeros(3), np.eye(3)).run(z[:2], upsets=[[0, 0, 0, 0, 1]])


def test_sign_bit_upset_flips_the_word():
    model = white_jerk(1e-2, 4.0, 0.05)
    kf = KalmanFilter(model, [1.0, 0, 0], np.eye(3), KalmanFormats(), z_limit=1e-9)
    run = kf.run(np.full(1, 5.0), upsets=[[0, 0, 0, 0, 31]])   # implausible z: predict only
    assert run.x[0, 0, 0] == pytest.approx(1.0 - 128.0, abs=1e-6)


@pytest.mark.parametrize("arith", ["float64", "float32", KalmanFormats()])
def test_nan_and_out_of_range_input_counted_never_nan_state(arith):
    rng = np.random.default_rng(71)
    model = random_system(rng, 3, 2, 1)
    z = rng.standard_normal((100, 2))
    z[5, 0], z[9, 1], z[20] = np.nan, np.inf, 1e6
    u = rng.standard_normal((100, 1))
    u[3] = np.nan
    run = KalmanFilter(model, np.zeros(3), np.eye(3), arith, z_limit=100.0).run(z, u, keep_P=True)
    assert run.events["implausible"] == 3
    assert run.events["bad_u"] == 1
    assert np.all(np.isfinite(run.x)) and np.all(np.isfinite(run.P))


@pytest.mark.parametrize("kwargs,msg", [
    (dict(F=np.ones((2, 3))), "F must be square (n x n), not 2 x 3"),
    (dict(F=np.eye(9), H=np.ones((1, 9)), Q=np.eye(9)), "the state dimension must be 1..8, not 9"),
    (dict(H=np.ones((1, 3))), "H must have n = 2 columns, not 3"),
    (dict(Q=np.array([[1.0, 0.0], [0.0, -1.0]])), "Q must be positive semi-definite, not a matrix with eigenvalue -1"),
    (dict(Q=np.array([[1.0, 0.5], [0.0, 1.0]])), "Q must be symmetric"),
    (dict(R=np.zeros((1, 1))), "R must be positive definite, not a matrix with eigenvalue 0"),
    (dict(R=np.eye(2)), "R must be 1 x 1, not 2 x 2"),
    (dict(F=np.full((2, 2), np.nan)), "F must be finite"),
])
def test_bad_model_errors(kwargs, msg):
    args = dict(F=np.eye(2), H=np.ones((1, 2)), Q=np.eye(2), R=np.eye(1))
    args.update(kwargs)
    with pytest.raises(ValueError, match=__import__("re").escape(msg)):
        LinearGaussianModel(**args)


def test_bad_filter_configuration_errors():
    model = white_jerk(1e-2, 4.0, 0.05)
    with pytest.raises(ValueError, match=r"P0 must be positive semi-definite, not a matrix with eigenvalue -2"):
        KalmanFilter(model, np.zeros(3), np.diag([1.0, -2.0, 1.0]))
    with pytest.raises(ValueError, match=r"format too narrow for x0: sQ7.24\(half_up,saturate\) holds "
                                         r"\[-128, 128\], not max \|x0\| = 300"):
        KalmanFilter(model, [300.0, 0, 0], np.eye(3), KalmanFormats())
    with pytest.raises(ValueError, match=r"format too narrow for P0: .* not max \|P0\| = 100"):
        KalmanFilter(model, np.zeros(3), np.eye(3) * 100, KalmanFormats())
    with pytest.raises(ValueError, match=r"formats too wide for the int64 datapath: F P needs 71 bits \(at most 63\)"):
        KalmanFilter(model, np.zeros(3), np.eye(3), KalmanFormats(P=fmt(46, 30)))
    with pytest.raises(ValueError, match=r"formats inconsistent: M F\^T \+ Q would drop 2 fraction bits of Q"):
        KalmanFilter(model, np.zeros(3), np.eye(3), KalmanFormats(Q=fmt(40, 48)))
    with pytest.raises(ValueError, match="arithmetic must be 'float64', 'float32' or a format table, not 'float16'"):
        KalmanFilter(model, np.zeros(3), np.eye(3), "float16")
    with pytest.raises(ValueError, match="format of signal 'x' must saturate"):
        KalmanFormats(x=fmt(32, 24).with_(overflow="wrap"))
    with pytest.raises(ValueError, match="trials must be an integer >= 1, not 0"):
        KalmanFilter(model, np.zeros(3), np.eye(3), trials=0)
    with pytest.raises(ValueError, match=r"z must have shape \(T, 1\) or \(1, T, 1\), not \(5, 2\)"):
        KalmanFilter(model, np.zeros(3), np.eye(3)).run(np.zeros((5, 2)))


def test_event_registry_layout():
    ev = EVENTS.new((2,))
    assert ev.shape == (2, len(SIGNALS) + 5 + 2 * len(SIGNALS))
    assert EVENTS.index("sat_x") == SIGNALS.index("x")
    assert EVENTS.ranges(ev)["x"] is None
    with pytest.raises(KeyError, match="no event 'nope'"):
        EVENTS.index("nope")
