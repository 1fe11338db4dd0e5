"""The snapshot-level fast path against the IF path (generator -> golden DDC / matched filter)."""
import time

import numpy as np
import pytest

from cosim.monopulse import fastpath
from cosim.monopulse.array import ArrayConfig
from cosim.monopulse.signal import MonopulseSignalConfig, generate
from cosim.monopulse.trajectory import ConstantRate, Manoeuvre
from dsp.monopulse import angles, golden

MISMATCH = ArrayConfig(phase_bits=4, gain_db=(0.0, 0.3, -0.2, 0.1), phase_deg=(0.0, 3.0, -2.0, 1.0))


def if_outputs(cfg, steering, first_block, n_blocks):
    rec = generate(cfg, steering, first_block, n_blocks)
    k = cfg.array.steering_correction(rec.steering[:, 0], rec.steering[:, 1])
    return golden.golden_chain(rec.samples, rec.scale, rec.replica, k, cfg.if_hz, cfg.fs_hz,
                               cfg.decimation, first_block * cfg.samples_per_block), rec


@pytest.mark.parametrize("mode", ["digital", "elements"])
def test_noise_free_fast_path_equals_the_if_path(mode):
    """No noise, no ADC: the fast path's mean is the IF chain's output to rounding, for a
    manoeuvring target, channel mismatch, quantised shifters and per-block steering."""
    arr = ArrayConfig(phase_bits=4, gain_db=MISMATCH.gain_db, phase_deg=MISMATCH.phase_deg,
                      subarray_steering=mode)
    cfg = MonopulseSignalConfig(array=arr, snapshots=256, snr_db=None, adc_bits=None,
                                trajectory=Manoeuvre(0.3, 0.2, 2.0, -1.0,
                                                     segments=((0.0, 1.0, 300.0, 200.0),)))
    steer = np.array([[0.3, 0.2], [0.305, 0.198], [0.31, 0.195], [0.3, 0.21]])
    s_if, _ = if_outputs(cfg, steer, 3, 4)
    s_fp = fastpath.matched_filter_outputs(cfg, steer, trials=2, first_block=3, n_blocks=4)
    assert s_fp.shape == (2, 4, 4)
    np.testing.assert_allclose(s_fp[1], s_if, atol=1e-12)
    np.testing.assert_allclose(s_fp[0], s_if, atol=1e-12)


def _statistics(n_blocks, snapshots, seed):
    cfg = MonopulseSignalConfig(array=MISMATCH, snapshots=snapshots, snr_db=-8.0, adc_bits=12,
                                trajectory=ConstantRate(0.36, 0.17), seed=seed)
    steer = (0.3, 0.22)
    t0 = time.perf_counter()
    s_if, rec = if_outputs(cfg, steer, 0, n_blocks)
    t_if = time.perf_counter() - t0
    m_fp = 20 * n_blocks
    t0 = time.perf_counter()
    s_fp = fastpath.matched_filter_outputs(cfg, steer, trials=m_fp)[:, 0]
    t_fp = time.perf_counter() - t0
    mu = fastpath.mean_outputs(cfg, steer)[0][0]
    var = fastpath.noise_variance(cfg)  # |k_i| = 1
    print(f"seed {seed}: IF {n_blocks} blocks x {snapshots} snapshots in {t_if:.2f} s, "
          f"fast path {m_fp} trials in {t_fp:.3f} s, ADC clipped {rec.clipped}")
    return cfg, steer, s_if, s_fp, mu, var


def _check(n_blocks, snapshots, seed):
    cfg, steer, s_if, s_fp, mu, var = _statistics(n_blocks, snapshots, seed)
    m = n_blocks
    tol = 5 / np.sqrt(m)  # 5 sigma of a sample (co)variance of m circular Gaussians
    # Means: the IF mean is the fast path's deterministic part (4 sigma of the mean).
    err = np.abs(s_if.mean(0) - mu) / np.sqrt(var / m)
    print("mean error / sigma:", np.round(err, 2))
    assert np.all(err < 4)
    # Covariance: diagonal = predicted noise variance, off-diagonal and pseudo-covariance 0.
    d = s_if - s_if.mean(0)
    cov = d.T @ d.conj() / (m - 1)
    pcov = d.T @ d / (m - 1)
    norm = np.sqrt(np.outer(var, var))
    rel = np.abs(cov - np.diag(var)) / norm
    print("covariance error / predicted:", np.round(rel.max(), 4), "pseudo:",
          np.round((np.abs(pcov) / norm).max(), 4), "tol", round(tol, 4))
    assert rel.max() < tol
    assert (np.abs(pcov) / norm).max() < tol
    # The fast path's own sample covariance agrees too (it draws what it says).
    dfp = s_fp - s_fp.mean(0)
    cfp = dfp.T @ dfp.conj() / (len(s_fp) - 1)
    assert (np.abs(cfp - np.diag(var)) / norm).max() < 5 / np.sqrt(len(s_fp))
    # Monopulse ratios and the measured direction cosines: variance within 10 %.
    out = {}
    for name, s in (("if", s_if), ("fp", s_fp)):
        ss, da, de = golden.beams(s)
        u, v = angles.direction_cosines(s, *steer, cfg.array.dx_wl, cfg.array.dy_wl)
        out[name] = np.array([np.var(np.imag(da / ss)), np.var(np.imag(de / ss)),
                              np.var(u), np.var(v)])
    ratio = out["if"] / out["fp"]
    print("variance IF / fast path (Im dA/S, Im dE/S, u, v):", np.round(ratio, 4))
    assert np.all(np.abs(ratio - 1) < 0.10)


def test_fast_path_statistics_match_the_if_path():
    """2000 IF blocks of 256 snapshots at -8 dB (16 dB after the matched filter), 12-bit ADC,
    channel mismatch, 4-bit shifters, target off the steering; fast path 40000 trials."""
    _check(2000, 256, seed=5)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [6, 7])
def test_fast_path_statistics_match_the_if_path_long(seed):
    _check(8000, 256, seed=seed)


def test_fast_path_trials_are_independent_and_seeded():
    cfg = MonopulseSignalConfig(snapshots=64, trajectory=ConstantRate(0.3, 0.2))
    a = fastpath.matched_filter_outputs(cfg, (0.3, 0.2), trials=3, n_blocks=2)
    b = fastpath.matched_filter_outputs(cfg, (0.3, 0.2), trials=3, n_blocks=2)
    np.testing.assert_array_equal(a, b)
    c = fastpath.matched_filter_outputs(cfg, (0.3, 0.2), trials=3, n_blocks=2, seed=99)
    assert np.all(a != c)
    assert np.all(a[0] != a[1]) and np.all(a[:, 0] != a[:, 1])
    with pytest.raises(ValueError, match="trials must be an integer >= 1, not 0"):
        fastpath.matched_filter_outputs(cfg, (0.3, 0.2), trials=0)


def test_calibration_removes_the_mismatch_bias():
    """Noise-free: channel mismatch biases the angle; a correction k_i = g_1 / g_i removes it."""
    u0, v0, u, v = 0.3, 0.2, 0.34, 0.17
    cfg = MonopulseSignalConfig(array=MISMATCH, snapshots=1, snr_db=None, adc_bits=None,
                                trajectory=ConstantRate(u, v))
    g = MISMATCH.channel_gains
    raw = fastpath.matched_filter_outputs(cfg, (u0, v0))[0, 0]
    cal = fastpath.matched_filter_outputs(cfg, (u0, v0), calibration=g[0] / g)[0, 0]
    ur, vr = angles.direction_cosines(raw, u0, v0, 4.0, 4.0)
    uc, vc = angles.direction_cosines(cal, u0, v0, 4.0, 4.0)
    assert abs(ur - u) > 1e-3 and abs(vr - v) > 1e-3    # a few degrees: ~mrad-level bias
    assert abs(uc - u) < 1e-12 and abs(vc - v) < 1e-12
