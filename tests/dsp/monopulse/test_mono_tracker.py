"""Monopulse angle tracker: Kalata == Kalman (C3), adaptive vs fixed gains (C4), the search
walk (C6), fixed point against float, calibration, bad input."""
from __future__ import annotations

import re

import numpy as np
import pytest

from dsp.estimation import steady_state_gains, white_acceleration
from dsp.monopulse.angles import crb_uv
from dsp.monopulse.tracker import (MONOPULSE_FORMATS, AngleTracker, SearchCapture, TrackerConfig,
                                   calibration_from_measurement, search_centres, search_pattern)

T = 8192 / 10e6                                        # one 8192-snapshot block at 10 Mchip/s
SIGMA_V = float(np.sqrt(crb_uv(10 ** -0.8, 8192, 4.0, 4.0)[0]))   # -8 dB per subarray


@pytest.mark.parametrize("sigma_a", [0.5, 2.0, 50.0, 2000.0])
def test_c3_kalata_gains_equal_steady_state_kalman_gain(sigma_a):
    tr = AngleTracker(TrackerConfig(mode="fixed", sigma_a=sigma_a), T, SIGMA_V)
    K = steady_state_gains(white_acceleration(T, sigma_a ** 2, SIGMA_V ** 2))
    np.testing.assert_allclose([tr.alpha, tr.beta / T], K, rtol=1e-9)


def _ramp(t, t0, t1):
    tin = np.clip(t - t0, 0, t1 - t0)
    return 0.5 * tin ** 2 + (t1 - t0) * np.maximum(t - t1, 0)


def _scenario(seed, trials=24, blocks=700, accel=40.0, start=300, stop=420):
    """u: +accel over the first half of blocks start..stop, -accel over the second (the rate
    comes back: a jink of 0.036 in u)."""
    rng = np.random.default_rng(seed)
    t = np.arange(blocks) * T
    t0, t1, tm = start * T, stop * T, (start + stop) / 2 * T
    u = 0.3 + 0.02 * t + accel * (_ramp(t, t0, tm) - _ramp(t, tm, t1))
    v = 0.2 - 0.015 * t
    zu = u + SIGMA_V * rng.standard_normal((trials, blocks))
    zv = v + SIGMA_V * rng.standard_normal((trials, blocks))
    return u, v, zu, zv


def _track(cfg, zu, zv, arithmetic="float64"):
    tr = AngleTracker(cfg, T, SIGMA_V, arithmetic=arithmetic, trials=zu.shape[0],
                      u0=zu[:, 0], v0=zv[:, 0])
    out = np.empty((2,) + zu.shape)
    pred = np.empty((2,) + zu.shape)
    for k in range(zu.shape[1]):
        out[0, :, k], out[1, :, k] = tr.update(zu[:, k], zv[:, k])
        pred[0, :, k], pred[1, :, k] = tr.command()
    return out, pred, tr


def test_c4_adaptive_lags_less_in_a_manoeuvre_and_is_quieter_when_quiet():
    u, v, zu, zv = _scenario(seed=41)
    low = TrackerConfig(mode="fixed", sigma_a=2.0)
    high = TrackerConfig(mode="fixed", sigma_a=2000.0)
    ada = TrackerConfig(mode="adaptive", sigma_a=2.0)
    err = {n: _track(c, zu, zv)[0][0] - u for n, c in (("low", low), ("high", high), ("ada", ada))}
    man = slice(310, 460)            # inside and just after the manoeuvre (300..420)
    quiet = slice(150, 300)          # settled, before it
    after = slice(500, 700)          # quiet again after it
    lag = {n: np.mean(np.abs(e[:, man])) for n, e in err.items()}
    rms = {n: np.sqrt(np.mean(e[:, quiet] ** 2)) for n, e in err.items()}
    rms2 = {n: np.sqrt(np.mean(e[:, after] ** 2)) for n, e in err.items()}
    assert lag["ada"] < 0.5 * lag["low"], (lag, rms)
    assert rms["ada"] < 0.9 * rms["high"], (lag, rms)
    assert rms["low"] < rms["high"] and lag["high"] < lag["low"], (lag, rms)   # a real trade-off
    # and the adaptive filter does not stay agile when quiet (the fixed 4 sigma_v^2 floor did:
    # 5.8e-4 before and 6.7e-4 after the manoeuvre, near the high-index filter; measured now
    # 1.5e-4 and 1.9e-4, the low-index filter's 1.6e-4 and 3.1e-4)
    assert rms["ada"] < 1.2 * rms["low"] and rms2["ada"] < 1.2 * rms2["low"], (rms, rms2)
    assert rms2["ada"] < 0.5 * rms2["high"], rms2


def test_c4_fixed_floor_stays_agile_when_quiet():
    """The previous adaptive form (fixed floor 4 sigma_v^2, alpha free to fall at once) keeps
    a high alpha in the quiet windows: the reason for the gain-scaled floor and the relax."""
    u, v, zu, zv = _scenario(seed=41)
    old = TrackerConfig(mode="adaptive", floor_scaling="fixed", noise_floor=4.0, alpha_relax=0)
    low = TrackerConfig(mode="fixed", sigma_a=2.0)
    e_old = _track(old, zu, zv)[0][0] - u
    e_low = _track(low, zu, zv)[0][0] - u
    q = slice(150, 300)
    assert np.sqrt(np.mean(e_old[:, q] ** 2)) > 2 * np.sqrt(np.mean(e_low[:, q] ** 2))


def test_literal_eq36_never_leaves_alpha_min():
    u, v, zu, zv = _scenario(seed=5, trials=4)
    _, _, tr = _track(TrackerConfig(mode="adaptive", eq36="literal"), zu, zv)
    np.testing.assert_allclose(tr.coefficients[:, 0], 0.05, rtol=0, atol=1e-12)
    _, _, tr = _track(TrackerConfig(mode="adaptive"), zu[:, :400], zv[:, :400])
    assert np.mean(tr.coefficients[:, 0]) > 0.2       # the repaired form reacts at block 400


# Fixed against float (MONOPULSE_FORMATS), fixed gains: z rounds to 2^-23 (half an LSB of
# 2^-22); the filter's DC gain is 1 and the prediction adds lead x rate; the coefficient words
# round to 2^-23 too. Stated bound: 8 LSB of z (1.9e-6, 0.24 % of sigma_v) on the filtered and
# predicted direction. Adaptive gains: the alpha of a step is a threshold decision (innovation
# power above the floor or not), so a one-LSB difference can flip it and the two runs then
# follow different (equally good) gain sequences: no per-sample bound exists; the bound
# stated is on the figure of merit: tracking RMS within 10 % of the float run's.
FIXED_BOUND = 8 * 2.0 ** -22


def test_fixed_point_tracks_float_within_bound_fixed_gains():
    u, v, zu, zv = _scenario(seed=7, trials=8)
    cfg = TrackerConfig(mode="fixed")
    of, pf, _ = _track(cfg, zu, zv)
    oq, pq, tq = _track(cfg, zu, zv, MONOPULSE_FORMATS)
    assert np.max(np.abs(oq - of)) < FIXED_BOUND
    assert np.max(np.abs(pq - pf)) < FIXED_BOUND
    assert np.max(np.abs(oq - of)) > 0                # it is a different arithmetic
    assert not any(v for k, v in tq.counts().items() if k.startswith("sat"))


def test_fixed_point_adaptive_tracking_rms_within_10_percent_of_float():
    u, v, zu, zv = _scenario(seed=7, trials=16)
    cfg = TrackerConfig(mode="adaptive")
    of, _, _ = _track(cfg, zu, zv)
    oq, _, tq = _track(cfg, zu, zv, MONOPULSE_FORMATS)
    truth = np.stack([np.broadcast_to(u, zu.shape), np.broadcast_to(v, zv.shape)])
    rf = np.sqrt(np.mean((of - truth)[:, :, 100:] ** 2))
    rq = np.sqrt(np.mean((oq - truth)[:, :, 100:] ** 2))
    assert abs(rq / rf - 1) < 0.10, (rf, rq)
    w = cfg.window - 1                # before the window fills: the start gains, as fixed
    np.testing.assert_allclose(oq[:, :, :w], of[:, :, :w], atol=FIXED_BOUND, rtol=0)
    assert not any(v for k, v in tq.counts().items() if k.startswith("sat"))


def test_closed_loop_lead_and_reset():
    cfg = TrackerConfig(mode="fixed", latency_blocks=2)
    tr = AngleTracker(cfg, T, SIGMA_V, trials=2, u0=0.1, v0=0.2)
    for k in range(400):
        tr.update(0.1 + 0.05 * k * T, 0.2)
    uf, _, du, _ = tr.state()
    np.testing.assert_allclose(du, 0.05, rtol=1e-3)
    np.testing.assert_allclose(tr.command()[0], uf + 3 * T * du, rtol=1e-12)
    tr.reset(np.array([True, False]), -0.3, 0.4)
    u, v, du, dv = tr.state()
    assert (u[0], v[0], du[0], dv[0]) == (-0.3, 0.4, 0.0, 0.0) and u[1] == uf[1]


def test_c6_search_walks_5_then_9x5_then_reinitialises():
    sc = SearchCapture((0.2, -0.1), (0.125, 0.125))
    pos = np.array([sc.next_position() for _ in range(51)])
    pat = search_pattern(0.125, 0.125)
    np.testing.assert_allclose(pos[:5], [0.2, -0.1] + pat, atol=1e-15)
    cen = search_centres(0.25, 0.25)
    assert len(np.unique(cen, axis=0)) == 9
    for j, c in enumerate(cen):
        np.testing.assert_allclose(pos[5 + 5 * j:10 + 5 * j], [0.2, -0.1] + c + pat, atol=1e-15)
    assert sc.cycles == 1 and sc.index == 1
    np.testing.assert_allclose(pos[50], pos[0])
    assert sc.confirmed((0.2, -0.1), (0.21, -0.12), True)
    assert not sc.confirmed((0.2, -0.1), (0.27, -0.1), True)
    assert not sc.confirmed((0.2, -0.1), (0.2, -0.1), False)


def test_calibration_equalises_channels():
    rng = np.random.default_rng(3)
    g = 10 ** (rng.uniform(-0.3, 0.3, 4) / 20) * np.exp(1j * np.deg2rad(rng.uniform(-4, 4, 4)))
    c = calibration_from_measurement(np.broadcast_to(0.7 * np.exp(0.3j) * g, (3, 4)))
    np.testing.assert_allclose(c * g, g[0], rtol=1e-12)


@pytest.mark.parametrize("kw,msg", [
    (dict(mode="kalman"), "tracker mode must be one of adaptive, fixed, not 'kalman'"),
    (dict(eq36="x"), "eq36 must be one of repaired, literal, not 'x'"),
    (dict(sigma_a=0.0), "sigma_a must be a finite number > 0, not 0.0"),
    (dict(window=1), "window must be an integer in [2, 64], not 1"),
    (dict(latency_blocks=-1), "latency_blocks must be an integer >= 0, not -1"),
    (dict(alpha_min=0.5, alpha_max=0.4), "alpha limits must satisfy 0 < alpha_min < alpha_max < 1"),
])
def test_bad_config_is_refused(kw, msg):
    with pytest.raises(ValueError, match=re.escape(msg)):
        TrackerConfig(**kw)


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match=re.escape("sigma_v must be a finite number > 0, not nan")):
        AngleTracker(TrackerConfig(), T, float("nan"))
    with pytest.raises(ValueError, match=re.escape("s_cal must be finite and non-zero in every channel")):
        calibration_from_measurement(np.array([1, 1j, 0, 1]))
    with pytest.raises(ValueError, match=re.escape("s_cal must have shape (..., 4), not (3,)")):
        calibration_from_measurement(np.ones(3))
    with pytest.raises(ValueError, match=re.escape("search step must be a finite number > 0, not 0.0")):
        SearchCapture((0, 0), (0.0, 0.1))
