"""Alpha-beta(-gamma): Kalata against the steady-state Kalman gain, float64 against a
direct formulation and against the Kalman filter, fixed and float32 bit for bit, errors."""
from __future__ import annotations

import re

import numpy as np
import pytest

from dsp.estimation import (AlphaBetaFilter, AlphaBetaFormats, KalmanFilter, kalata,
                            steady_state_gains, tracking_index, white_acceleration)
from dsp.estimation.formats import fmt, to_fixed

from estimation_reference import AlphaBetaRef, F32Arith, IntArith


@pytest.mark.parametrize("T_s,sigma_w,sigma_v", [(1e-3, 5.0, 0.01), (0.01, 2.0, 0.1),
                                                 (0.1, 1.0, 1.0), (1.0, 3.0, 0.5), (0.5, 0.01, 2.0)])
def test_kalata_equals_steady_state_kalman_gain(T_s, sigma_w, sigma_v):
    alpha, beta = kalata(tracking_index(T_s, sigma_w, sigma_v))
    K = steady_state_gains(white_acceleration(T_s, sigma_w ** 2, sigma_v ** 2))
    np.testing.assert_allclose([alpha, beta / T_s], K, rtol=1e-9)


def _track(T, T_s, seed, sigma_v=0.1):
    rng = np.random.default_rng(seed)
    t = np.arange(T) * T_s
    acc = np.where(t > t[T // 2], 4.0, 0.0)          # a manoeuvre half way
    truth = 0.5 * t + 0.5 * acc * (t - t[T // 2]) ** 2
    return truth + rng.normal(0, sigma_v, T)


@pytest.mark.parametrize("gamma", [None, 0.02])
def test_float64_matches_direct_formulation(gamma):
    T_s, alpha, beta = 0.01, 0.3, 0.05
    z = _track(500, T_s, 1)
    run = AlphaBetaFilter(T_s, alpha, beta, gamma, x0=[0.1, 0.2] + ([0.0] if gamma else [])).run(z)
    if gamma is None:
        F, K, x = np.array([[1, T_s], [0, 1]]), np.array([alpha, beta / T_s]), np.array([0.1, 0.2])
    else:
        F = np.array([[1, T_s, T_s ** 2 / 2], [0, 1, T_s], [0, 0, 1]])
        K, x = np.array([alpha, beta / T_s, gamma / (2 * T_s ** 2)]), np.array([0.1, 0.2, 0.0])
    # compared in the per-sample units the tracker computes in (x, T v, T^2 a / 2): there a
    # rounding of 1e-16 relative to the position is 1e-16 relative, not 1e-16 T^-2
    u = np.array([1.0, T_s, T_s ** 2 / 2])[:len(x)]
    for k in range(len(z)):
        x = F @ x
        x = x + K * (z[k] - x[0])
        np.testing.assert_allclose(run.x[0, k] * u, x * u, rtol=1e-12, atol=1e-12 * np.abs(x * u).max(),
                                   err_msg=f"step {k}")


def test_kalata_tracker_equals_steady_state_kalman_filter():
    T_s, sw, sv = 0.01, 2.0, 0.1
    model = white_acceleration(T_s, sw ** 2, sv ** 2)
    K = steady_state_gains(model)
    F, H, Q, R, _ = model.at(0)
    # the Kalman filter started at its steady-state posterior covariance has the constant gain K
    Pp = np.eye(2)
    for _ in range(20000):
        Pp = F @ (Pp - np.outer(Pp @ H[0], H[0] @ Pp) / (H[0] @ Pp @ H[0] + R[0, 0])) @ F.T + Q
    P_post = (np.eye(2) - np.outer(K, H[0])) @ Pp
    z = _track(2000, T_s, 2, sv)
    kf = KalmanFilter(model, [0.0, 0.0], P_post).run(z)
    ab = AlphaBetaFilter(T_s, *kalata(tracking_index(T_s, sw, sv))).run(z)
    np.testing.assert_allclose(ab.x[0], kf.x[0], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("gamma,adaptive", [(None, False), (0.02, False), (None, True)])
def test_fixed_bit_exact_against_unbounded_integers(gamma, adaptive):
    T_s, sv = 0.01, 0.1
    z = _track(800, T_s, 3, sv)
    z[10] = np.nan
    fm = AlphaBetaFormats()
    f = AlphaBetaFilter(T_s, 0.3, 0.05, gamma, adaptive=adaptive, sigma_v=sv, window=4,
                        arithmetic=fm)
    run = f.run(z)
    ar = IntArith(fm)
    q = lambda v, s: int(to_fixed(v, getattr(fm, s)))
    c = [q(0.3, "c"), q(0.05, "c"), q((gamma or 0.0) / 4, "c")]
    ref = AlphaBetaRef(ar, [0] * f.n, c, (q(4 * sv ** 2, "s"), q(0.05, "c"), q(0.95, "c"), 1 << fm.c.frac, 4,
                                          q(sv / 2, "l"), 4 << fm.l.frac), 4, adaptive)
    for k in range(len(z)):
        ref.step(None if np.isnan(z[k]) else q(z[k], "z"))
        assert f.x.shape == (1, f.n)
    np.testing.assert_array_equal(f.x[0], ref.x)
    np.testing.assert_array_equal(f.c[0, :2], ref.c[:2])
    assert run.events["implausible"] == 1
    assert {s: run.events[f"sat_{s}"] for s in fm.signals()} == ar.sat


@pytest.mark.parametrize("adaptive", [False, True])
def test_float32_bit_exact_against_numpy_float32(adaptive):
    T_s, sv = 0.01, 0.1
    z = _track(600, T_s, 4, sv)
    f = AlphaBetaFilter(T_s, 0.3, 0.05, adaptive=adaptive, sigma_v=sv, arithmetic="float32")
    run = f.run(z)
    f32 = np.float32
    ref = AlphaBetaRef(F32Arith(), [f32(0), f32(0)], [f32(0.3), f32(0.05), f32(0)],
                       (f32(4 * sv ** 2), f32(0.05), f32(0.95), f32(1), f32(4), f32(sv / 2), f32(4)), 4, adaptive)
    unit = np.array([1.0, 1.0 / T_s])
    for k in range(len(z)):
        ref.step(f32(z[k]))
        np.testing.assert_array_equal(run.x[0, k], np.array(ref.x, np.float32).astype(float) * unit)


@pytest.mark.parametrize("arith", ["float64", "float32", AlphaBetaFormats()])
def test_adaptive_alpha_follows_the_innovation_level(arith):
    """Directed: innovations far above sigma_v drive alpha to alpha_max (beta its Kalata
    pair); a noise-free straight track (innovations 0, no power above the noise floor)
    drives it to alpha_min, never a NaN."""
    T_s, sv = 0.01, 0.1
    z = np.concatenate([np.zeros(50), np.full(8, 5.0), 5.0 + 0.0 * np.arange(200)])
    f = AlphaBetaFilter(T_s, 0.2, 0.02, adaptive=True, sigma_v=sv, window=4, arithmetic=arith)
    run = f.run(np.zeros(50))
    assert run.coefficients[0, -1, 0] == pytest.approx(0.05, abs=1e-6)
    run = f.run(np.full(4, 5.0))
    a, b = run.coefficients[0, -1]
    assert a == pytest.approx(0.95, abs=1e-6)
    assert b == pytest.approx(2 * (1 - np.sqrt(1 - 0.95)) ** 2, abs=1e-5)
    assert np.all(np.isfinite(run.x))


def test_batched_trials_and_bad_input():
    T_s = 0.01
    z = np.stack([_track(300, T_s, s) for s in range(3)])
    z[1, 5], z[2, 7] = np.nan, 1e9
    for arith in ("float64", "float32", AlphaBetaFormats()):
        run = AlphaBetaFilter(T_s, 0.3, 0.05, arithmetic=arith, trials=3, z_limit=1e3).run(z)
        assert run.events["implausible"] == 2
        assert np.all(np.isfinite(run.x))
        one = AlphaBetaFilter(T_s, 0.3, 0.05, arithmetic=arith).run(z[0])
        np.testing.assert_array_equal(run.x[0], one.x[0])


@pytest.mark.parametrize("kwargs,msg", [
    (dict(alpha=1.2), "alpha must be in (0, 1), not 1.2"),
    (dict(alpha=0.0), "alpha must be in (0, 1), not 0.0"),
    (dict(beta=3.5), "beta must be in (0, 4 - 2 alpha) = (0, 3.4), not 3.5"),
    (dict(gamma=5.0), "gamma must be in (0, 4 alpha beta / (2 - alpha)) = (0, 0.0352941), not 5.0"),
    (dict(T_s=0.0), "T_s must be a finite number > 0, not 0.0"),
    (dict(adaptive=True), "sigma_v must be a finite number > 0 in adaptive mode, not None"),
    (dict(adaptive=True, sigma_v=0.1, window=1), "window must be an integer in [2, 64], not 1"),
    (dict(adaptive=True, sigma_v=0.1, gamma=0.01), "the adaptive mode is for the alpha-beta tracker"),
    (dict(x0=[1e6, 0.0], arithmetic=AlphaBetaFormats()), "format too narrow for x0 (per-sample units)"),
])
def test_bad_configuration_errors(kwargs, msg):
    args = dict(T_s=0.01, alpha=0.3, beta=0.05)
    args.update(kwargs)
    with pytest.raises(ValueError, match=re.escape(msg)):
        AlphaBetaFilter(**args)
    with pytest.raises(ValueError, match=re.escape("the tracking index must be a finite number > 0, not -1")):
        kalata(-1)


def test_fixed_state_upset_injected_counted_and_forgotten():
    T_s = 0.01
    z = _track(400, T_s, 8)
    clean = AlphaBetaFilter(T_s, 0.3, 0.05, arithmetic=AlphaBetaFormats()).run(z)
    f = AlphaBetaFilter(T_s, 0.3, 0.05, arithmetic=AlphaBetaFormats())
    hit = f.run(z[:100])
    hit2 = f.run(z[100:], upsets=[[150, 0, 0, 31]])      # position word bit 31 (+-8) at step 150
    x = np.concatenate([hit.x, hit2.x], axis=1)
    assert hit2.events["upsets"] == 1
    np.testing.assert_array_equal(x[0, :150], clean.x[0, :150])
    jump = abs(x[0, 150, 0] - clean.x[0, 150, 0])
    assert jump > 1.0
    assert abs(x[0, -1, 0] - clean.x[0, -1, 0]) < 1e-3 * jump
    with pytest.raises(ValueError, match=re.escape("upset (step, trial, element, bit) out of range: [0, 0, 2, 1]")):
        f.run(z[:2], upsets=[[0, 0, 2, 1]])
    with pytest.raises(ValueError, match="upsets flip bits of fixed-point state words"):
        AlphaBetaFilter(T_s, 0.3, 0.05).run(z[:2], upsets=[[0, 0, 0, 1]])


def manoeuvre_mc(trials=200, window=5, noise_floor=4.0, accel=1.0, arithmetic="float64", seed=2026,
                 scale=1.0, runs=False):
    """Seeded Monte Carlo in per-sample units (T_s = 1, sigma_v = 1): a constant-velocity
    track (1 per sample), a manoeuvre of ``accel`` per sample^2 over samples 100-129, then
    constant velocity again, 300 samples. The adaptive tracker against the best of 40 fixed
    Kalata trackers (lambda 1e-3..30) on the same noise; RMSE of position after sample 10.
    ``scale`` multiplies positions and noise (sigma_v = scale; lambda does not change)."""
    T, seg = 300, (100, 130)
    a = np.zeros(T)
    a[seg[0]:seg[1]] = accel
    v = 1.0 + np.cumsum(a)
    x = np.cumsum(v) - v[0]
    x = x * scale
    z = x + scale * np.random.default_rng(seed).standard_normal((trials, T))
    x0 = [0.0, scale]
    rmse = lambda run: float(np.sqrt(np.mean((run.x[:, 10:, 0] - x[10:]) ** 2))) / scale
    fixed = {}
    for lam in (np.geomspace(1e-3, 30, 40) if not runs else [0.741]):
        al, be = kalata(float(lam))
        fixed[float(lam)] = rmse(AlphaBetaFilter(1.0, al, be, trials=trials, x0=x0, arithmetic=arithmetic).run(z))
    best = min(fixed, key=fixed.get)
    ad = AlphaBetaFilter(1.0, 0.1, 2 * (1 - np.sqrt(0.9)) ** 2, adaptive=True, sigma_v=scale, window=window,
                         noise_floor=noise_floor, alpha_min=0.1, alpha_max=0.95, trials=trials, x0=x0,
                         arithmetic=arithmetic)
    run = ad.run(z)
    al = run.coefficients[:, :, 0]
    return {"rmse_adaptive": rmse(run), "rmse_fixed": fixed[best], "best_lambda": best,
            "best_alpha": kalata(best)[0], "alpha_before": float(al[:, 50:100].mean()),
            "alpha_during": float(al[:, 100:130].mean()), "alpha_after": float(al[:, 200:].mean()),
            "events": run.events, "z": z, "run": run, "filter": ad}


def test_adaptive_alpha_rises_in_a_manoeuvre_and_beats_the_best_fixed_gain():
    """200 seeded trials (see :func:`manoeuvre_mc`; window 5, noise floor 4 sigma_v^2):
    alpha rises during the manoeuvre and falls after it, and the adaptive tracker's RMSE
    over the whole track is below the best of 40 fixed Kalata trackers on the same noise.
    Measured: adaptive 0.756 sigma_v, best fixed (lambda 0.74, alpha 0.70) 0.817; mean alpha
    0.13 before, 0.75 during, 0.21 after. Windows 4 / 3 give 0.788 / 0.855 (3 loses) and the
    decision's floor 1 loses (0.94): ``manoeuvre_mc(window=..., noise_floor=...)``."""
    r = manoeuvre_mc()
    assert r["alpha_during"] > 4 * r["alpha_before"]
    assert r["alpha_after"] < r["alpha_during"] / 2
    assert r["rmse_adaptive"] < 0.95 * r["rmse_fixed"], (r["rmse_adaptive"], r["rmse_fixed"])
    assert not any(r["events"].values())


def test_seed_noise_floor_1_keeps_alpha_high_without_a_manoeuvre():
    """The decision's floor (tau = 1) with 5 innovations: chi-square spread alone gives
    alpha ~0.8 in quiet segments and the tracker loses to the best fixed gain (documented
    in the module; the default floor is 4)."""
    r = manoeuvre_mc(noise_floor=1.0)
    assert r["alpha_before"] > 0.7
    assert r["rmse_adaptive"] > r["rmse_fixed"]


def test_adaptive_fixed_point_on_the_manoeuvre_bit_exact_and_close_to_float():
    """The same Monte Carlo in fixed point (positions scaled by 0.01 to fit the z format):
    4 trials bit for bit against Python integers, and the RMSE over 200 trials within 1 %
    of float64 with the same alpha profile."""
    fm = AlphaBetaFormats()
    r = manoeuvre_mc(arithmetic=fm, scale=0.01, runs=True)
    rf = manoeuvre_mc(scale=0.01, runs=True)
    assert abs(r["rmse_adaptive"] - rf["rmse_adaptive"]) < 0.01 * rf["rmse_adaptive"]
    assert abs(r["alpha_during"] - rf["alpha_during"]) < 0.01
    assert not any(r["events"].values()), {k: v for k, v in r["events"].items() if v}
    q = lambda v, s: int(to_fixed(v, getattr(fm, s)))
    z, run = r["z"], r["run"]
    for b in range(4):
        ar = IntArith(fm)
        c = [q(0.1, "c"), q(2 * (1 - np.sqrt(0.9)) ** 2, "c"), 0]
        ref = AlphaBetaRef(ar, [0, q(0.01, "x")], c, (q(4 * 0.01 ** 2, "s"), q(0.1, "c"), q(0.95, "c"),
                                                      1 << fm.c.frac, 5, q(0.01 / 2, "l"), 4 << fm.l.frac),
                           5, True)
        for k in range(z.shape[1]):
            ref.step(q(z[b, k], "z"))
            got = np.round(run.x[b, k] * np.array([1.0, 1.0]) * 2.0 ** fm.x.frac).astype(np.int64)
            assert got.tolist() == ref.x, (b, k)
            assert int(round(run.coefficients[b, k, 0] * 2.0 ** fm.c.frac)) == ref.c[0]


@pytest.mark.parametrize("fm", [AlphaBetaFormats(), AlphaBetaFormats(s=fmt(48, 32))])
def test_gain_scaled_floor_and_relax_bit_exact_against_unbounded_integers(fm):
    """``floor_scaling="gain"`` (floor / (1 - alpha), the denominator's low bits dropped when
    the shifted floor would pass 62 bits: the second format) and ``alpha_relax``, against the
    step-by-step reference; alpha does move (not stuck at a limit)."""
    T_s, sv = 0.01, 0.1
    z = _track(800, T_s, 3, sv)
    z[300:340] += np.linspace(0, 3, 40)          # a manoeuvre: alpha rises, then relaxes
    f = AlphaBetaFilter(T_s, 0.3, 0.05, adaptive=True, sigma_v=sv, window=4, arithmetic=fm,
                        floor_scaling="gain", alpha_relax=1.1, noise_floor=6.0)
    run = f.run(z)
    ar = IntArith(fm)
    q = lambda v, s: int(to_fixed(v, getattr(fm, s)))
    ref = AlphaBetaRef(ar, [0, 0], [q(0.3, "c"), q(0.05, "c"), 0],
                       (q(6 * sv ** 2, "s"), q(0.05, "c"), q(0.95, "c"), 1 << fm.c.frac, 4,
                        q(sv / 2, "l"), 4 << fm.l.frac), 4, True, scale=True,
                       relax=q(1.1, "c"), kd=fm.floor_drop_bits())
    alphas = []
    for k in range(len(z)):
        ref.step(q(z[k], "z"))
        alphas.append(ref.c[0])
    np.testing.assert_array_equal(f.x[0], ref.x)
    np.testing.assert_array_equal(f.c[0, :2], ref.c[:2])
    a = run.coefficients[0, :, 0]
    assert a.max() > 0.5 and a[-1] < 0.1
    # relaxing: 1 - alpha grows by at most 1.1 (+ rounding) a step
    assert np.all((1 - a[1:]) <= 1.1 * (1 - a[:-1]) + 1e-6)
    assert {s: run.events[f"sat_{s}"] for s in fm.signals()} == ar.sat
    assert (fm.floor_drop_bits() > 0) == (fm.s.width == 48)


def test_gain_scaled_floor_and_relax_float32_bit_exact():
    T_s, sv = 0.01, 0.1
    z = _track(600, T_s, 4, sv)
    z[300:340] += np.linspace(0, 3, 40)
    f = AlphaBetaFilter(T_s, 0.3, 0.05, adaptive=True, sigma_v=sv, arithmetic="float32",
                        floor_scaling="gain", alpha_relax=1.1, noise_floor=6.0)
    run = f.run(z)
    f32 = np.float32
    ref = AlphaBetaRef(F32Arith(), [f32(0), f32(0)], [f32(0.3), f32(0.05), f32(0)],
                       (f32(6 * sv ** 2), f32(0.05), f32(0.95), f32(1), f32(4), f32(sv / 2),
                        f32(4)), 4, True, scale=True, relax=f32(1.1))
    unit = np.array([1.0, 1.0 / T_s])
    for k in range(len(z)):
        ref.step(f32(z[k]))
        np.testing.assert_array_equal(run.x[0, k], np.array(ref.x, np.float32).astype(float) * unit)


@pytest.mark.parametrize("kw,msg", [
    (dict(floor_scaling="innovation"), "floor_scaling must be one of fixed, gain, not 'innovation'"),
    (dict(alpha_relax=1.0), "alpha_relax must be 0 (no limit) or in (1, 2), not 1.0"),
    (dict(alpha_relax=-0.5), "alpha_relax must be 0 (no limit) or in (1, 2), not -0.5"),
])
def test_adaptive_options_bad_input(kw, msg):
    with pytest.raises(ValueError, match=re.escape(msg)):
        AlphaBetaFilter(0.01, 0.3, 0.05, adaptive=True, sigma_v=0.1, **kw)
