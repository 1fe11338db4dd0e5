"""Reference decoding, coarse/fine combination and bearing over the whole circle."""
import numpy as np
import pytest

from cosim.tacan.signal import TacanSignalConfig, pulse_observations, pulse_schedule
from dsp.tacan.bearing import combine_coarse_fine, paper_eq17, wrap_deg
from dsp.tacan.decode import DecoderConfig, decode
from dsp.tacan.scoring import REF_AUX, REF_MAIN
from dsp.tacan.kalman_config import KalmanConfig
from dsp.tacan.bounds import crb_deg
from dsp.tacan.receiver import ReceiverConfig, bearing_stats, process_peaks


def test_combination_exact_for_every_bearing_with_coarse_error_below_20_degrees():
    theta = np.arange(0, 360, 0.05)
    rng = np.random.default_rng(0)
    coarse_err = rng.uniform(-19.5, 19.5, theta.size)
    coarse = np.radians(theta + coarse_err)
    fine9 = np.radians(9 * theta)
    got = np.degrees(combine_coarse_fine(coarse, fine9))
    np.testing.assert_allclose(wrap_deg(got - theta), 0, atol=1e-9)


def test_paper_eq17_slips_at_sector_edges_and_ours_does_not():
    theta = np.array([39.9, 80.05, 359.8])
    coarse = theta + np.array([0.3, -0.2, 0.5])  # small coarse errors across an edge
    fine135 = (9 * theta) % 360
    eq17 = paper_eq17(coarse, fine135)
    assert np.all(np.abs(wrap_deg(eq17 - theta)) > 30)  # whole-sector slips
    ours = np.degrees(combine_coarse_fine(np.radians(coarse), np.radians(fine135)))
    np.testing.assert_allclose(wrap_deg(ours - theta), 0, atol=1e-9)


def test_combination_weights_by_information():
    # Equal information: halfway between a resolved fine and a consistent coarse.
    got = np.degrees(combine_coarse_fine(np.radians(10.4), np.radians(90.0), 1.0, 1.0))
    assert got == pytest.approx(10.2)


@pytest.mark.parametrize("mode", ["X", "Y"])
def test_decoder_finds_every_reference(mode):
    cfg = TacanSignalConfig(mode=mode, duration_s=2.0, seed=9)
    t, _, mains, auxs = pulse_schedule(cfg)
    d = decode(t, mode)
    np.testing.assert_allclose(d.ref_times_s[d.ref_kinds == REF_MAIN], mains, atol=1e-12)
    np.testing.assert_allclose(d.ref_times_s[d.ref_kinds == REF_AUX], auxs, atol=1e-12)
    assert d.measurement_mask.all()


@pytest.mark.parametrize("mode", ["X", "Y"])
def test_decoder_robust_to_missing_and_extra_pulses(mode):
    cfg = TacanSignalConfig(mode=mode, duration_s=2.0, seed=10)
    t, _, mains, auxs = pulse_schedule(cfg)
    rng = np.random.default_rng(3)
    keep = rng.random(t.size) > 0.05                 # 5 % of pulses lost
    extra = rng.uniform(0, cfg.duration_s, 400)      # 200 false peaks per second
    tt = np.sort(np.concatenate([t[keep] + rng.normal(0, 0.1e-6, keep.sum()), extra]))
    d = decode(tt, mode)
    m = d.ref_times_s[d.ref_kinds == REF_MAIN]
    a = d.ref_times_s[d.ref_kinds == REF_AUX]
    # Found nearly all, and every one found is a real reference, timed to < 0.2 us.
    assert m.size >= 0.9 * mains.size and a.size >= 0.9 * auxs.size
    assert np.max(np.min(np.abs(m[:, None] - mains[None, :]), axis=1)) < 0.2e-6
    assert np.max(np.min(np.abs(a[:, None] - auxs[None, :]), axis=1)) < 0.2e-6


@pytest.mark.parametrize("mode", ["X", "Y"])
def test_decoder_scoring_kernel_equals_the_numpy_matching(mode):
    """The compiled hypothesis scorer (one walking pointer per template pulse) gives the
    numpy nearest-neighbour matching's scores exactly, also at ties and at the tolerance."""
    from dsp.tacan.standard import burst_offsets
    from dsp.tacan import scoring as sco
    rng = np.random.default_rng(4)
    cfg = TacanSignalConfig(mode=mode, duration_s=0.5, seed=12)
    t, _, _, _ = pulse_schedule(cfg)
    tol = DecoderConfig().tol_s
    for offs in (burst_offsets(mode, "main"), burst_offsets(mode, "aux")):
        tt = np.sort(np.concatenate([t + rng.normal(0, 0.5e-6, t.size),
                                     rng.uniform(0, 0.5, 300)]))
        starts = np.unique(np.round((tt[:, None] - offs[None, :4]).ravel(), 12))
        # Hypotheses whose targets sit exactly at the tolerance or midway between two peaks.
        edge = np.concatenate([tt[:50] - offs[3] + tol, tt[50:100] - offs[2] - tol,
                               (tt[100:150] + tt[101:151]) / 2 - offs[1],
                               [tt[0] - 1.0, tt[-1] + 1.0]])
        starts = np.unique(np.concatenate([starts, edge]))
        got = sco.burst_scores(tt, starts, offs, tol)
        want = sco.burst_scores_numpy(tt, starts, offs, tol)
        np.testing.assert_array_equal(got, want)
        assert want.max() == offs.size and (want == 0).any()
    # Dyadic times: distances of exactly tol (matched), tol + 1 LSB (not) and exact midpoints.
    q = 2.0 ** -20
    tt = np.sort(rng.choice(np.arange(4000), 900, replace=False)) * q
    offs = np.array([0.0, 7, 16, 40]) * q
    starts = np.unique(np.concatenate([tt - 2 * q, tt + 2 * q, tt - 3 * q, tt + 0.5 * q,
                                       tt - 40 * q]))
    got = sco.burst_scores(tt, starts, offs, 2 * q)
    np.testing.assert_array_equal(got, sco.burst_scores_numpy(tt, starts, offs, 2 * q))
    at_tol = sco.burst_scores(tt[:1], np.array([tt[0] - 2 * q, tt[0] - 3 * q]), offs[:1], 2 * q)
    assert at_tol.tolist() == [1, 0]


def test_decoder_refuses_nan_times():
    with pytest.raises(ValueError, match="peak times must be finite"):
        decode(np.array([0.0, np.nan, 1.0]))


def test_decoder_bad_config():
    with pytest.raises(ValueError, match=r"decoder min_fraction must be in \(0, 1\], not 1.5"):
        DecoderConfig(min_fraction=1.5)


@pytest.mark.parametrize("mode, snr", [("X", 10.0), ("X", 20.0), ("Y", 10.0)])
def test_no_sector_slip_at_any_bearing(mode, snr):
    """Every bearing 0..359 deg (1 deg steps), pulse-level fast path, one batch."""
    bearings = np.arange(360.0)
    cfg = TacanSignalConfig(mode=mode, snr_db=snr, duration_s=1.6, seed=21)
    t, amps, _ = pulse_observations(cfg, bearings)
    tr = process_peaks(t, amps, ReceiverConfig(mode=mode))
    st = bearing_stats(tr, bearings, 1.0)
    assert st["n"] > 50
    assert np.max(st["max_abs_error_deg"]) < 0.5   # a slip would be 40 deg
    assert tr.reinit.sum() == 0


def test_pulse_level_rmse_near_cramer_rao():
    """The DSP alone (ideal front end) is efficient: RMSE within 1.5x the bound for its memory."""
    bearings = np.array([0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0] * 4)
    cfg = TacanSignalConfig(snr_db=10.0, duration_s=4.0, seed=5)
    t, amps, _ = pulse_observations(cfg, bearings)
    kc = KalmanConfig()
    tr = process_peaks(t, amps, ReceiverConfig(kalman=kc))
    st = bearing_stats(tr, bearings, 1.0)
    rmse = np.sqrt(np.mean(st["rmse_deg"] ** 2))
    bound = crb_deg(cfg.matched_filter_rel_sigma(), 0.21, 0.21, kc.n_eff)
    assert 0.7 * bound < rmse < 1.5 * bound
    assert abs(np.mean(st["mean_error_deg"])) < 0.3 * bound  # no bias


def test_process_peaks_rejects_nan():
    with pytest.raises(ValueError, match="must be finite"):
        process_peaks(np.array([0.0, 1e-3]), np.array([1.0, np.nan]))


def test_burst_density_weighting_removes_most_of_the_distortion_bias():
    """A memoryless amplitude nonlinearity (here a cube, noise-free) makes harmonics the
    5-state model does not carry; with the clustered reference pulses they leak into the
    bearing as a bias. De-weighting the bursts (uniform effective density) cuts it >= 3x."""
    bearings = np.array([0.0, 90.0, 180.0, 270.0])
    cfg = TacanSignalConfig(snr_db=None, duration_s=2.0, seed=1)
    t, _, truth = pulse_observations(cfg, bearings, rel_sigma=0.0)
    amps = truth ** 3
    err = {}
    for dw in (False, True):
        tr = process_peaks(t, amps, ReceiverConfig(density_weighting=dw))
        err[dw] = np.abs(bearing_stats(tr, bearings, 1.0)["mean_error_deg"])
    assert np.max(err[False]) > 0.1
    assert np.max(err[True]) < np.max(err[False]) / 3


def test_burst_weights_only_touch_burst_pulses():
    from dsp.tacan.decode import decode
    from dsp.tacan.receiver import burst_r_mult
    cfg = TacanSignalConfig(duration_s=0.5, seed=2)
    t, kinds, _, _ = pulse_schedule(cfg)
    r = burst_r_mult(t, decode(t, "X"), "X")
    assert np.all(r[kinds == 0] == 1.0)
    # A burst's pulses together weigh what its pulse-free window would have held: 12-24
    # pulses standing for the few random ones (5400/s) of a 0.3-0.6 ms window.
    assert np.all((r[kinds != 0] > 0.5) & (r[kinds != 0] < 30))
    assert np.median(r[kinds != 0]) > 1.5


# ---------------------------------------------------------------------------------------
# Fixed point: binary angles, integer combination, bearing from the integer Kalman state
# ---------------------------------------------------------------------------------------
from fractions import Fraction  # noqa: E402

from dsp.fixed import FixedFormat  # noqa: E402
from dsp.tacan.bearing import (ANGLE_BITS, PHASE_BITS, bangle_to_deg, bangle_to_rad,  # noqa: E402
                               bearing_from_state, combine_coarse_fine_fixed, deg_to_bangle,
                               freq_word, information_weights, phase_advance, rad_to_bangle,
                               reduce_bangle, reference_advances, state_cordic, wrap_pi,
                               weight_fraction)

LSB_DEG = 360.0 / 2 ** ANGLE_BITS
X_FMT = FixedFormat(36, 28, True, "half_up", "saturate")   # the core's state format


def _lsb_err(fixed_bangle, ref_rad, bits=ANGLE_BITS):
    """Signed difference in LSBs between a binary angle and an angle in radians."""
    return wrap_pi(bangle_to_rad(fixed_bangle, bits) - ref_rad) / (2 * np.pi) * 2 ** bits


def _random_combination_inputs(n, seed):
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0, 360, n)
    coarse = deg_to_bangle(theta + rng.uniform(-19, 19, n))
    fine9 = deg_to_bangle(9 * theta + rng.normal(0, 0.5, n))
    # weights over many decades, zeros included, up to the 2**62 limit
    wc = np.floor(2.0 ** rng.uniform(0, 61.9, n)).astype(np.int64)
    wf = np.floor(2.0 ** rng.uniform(0, 61.9, n)).astype(np.int64)
    wc[: n // 50] = 0
    wf[n // 50: n // 25] = 0
    wc[n // 25: n // 20] = wf[n // 25: n // 20] = 0
    return theta, coarse, fine9, wc, wf


def test_fixed_combination_matches_float_within_documented_bound():
    """Documented bound: <= 1/2 + 1/9 LSB (0.62 LSB = 5.2e-8 deg) at 32 bits."""
    _, coarse, fine9, wc, wf = _random_combination_inputs(200_000, seed=1)
    got = combine_coarse_fine_fixed(coarse, fine9, wc, wf)
    ref = combine_coarse_fine(bangle_to_rad(coarse), bangle_to_rad(fine9),
                              wc.astype(np.float64), wf.astype(np.float64))
    err = _lsb_err(got, ref)
    assert np.abs(err).max() <= 0.5 + 1 / 9 + 1e-3
    assert np.abs(err).max() * LSB_DEG < 1e-7
    assert got.dtype == np.int64 and got.min() >= 0 and got.max() < 2 ** ANGLE_BITS
    # small integer weights (no normalisation) take the same path
    rng = np.random.default_rng(2)
    wc, wf = rng.integers(0, 50, coarse.size), rng.integers(0, 50, coarse.size)
    got = combine_coarse_fine_fixed(coarse, fine9, wc, wf)
    ref = combine_coarse_fine(bangle_to_rad(coarse), bangle_to_rad(fine9), wc, wf)
    assert np.abs(_lsb_err(got, ref)).max() <= 0.5 + 1 / 9 + 1e-3


def test_fixed_combination_against_exact_rationals():
    """The integer result is the exact rational combination rounded, within 0.62 LSB."""
    _, coarse, fine9, wc, wf = _random_combination_inputs(3000, seed=3)
    got = combine_coarse_fine_fixed(coarse, fine9, wc, wf)
    B = 2 ** ANGLE_BITS
    for c, f9, a, b, g in zip(coarse.tolist(), fine9.tolist(), wc.tolist(), wf.tolist(),
                              got.tolist()):
        cands = [Fraction(f9 + i * B, 9) for i in range(9)]
        fine = min(cands, key=lambda v: abs((c - v + B / 2) % B - B / 2))
        d = (c - fine + Fraction(B, 2)) % B - Fraction(B, 2)
        exact = fine + (Fraction(a, a + b) * d if a + b else 0)
        e = (g - exact + Fraction(B, 2)) % B - Fraction(B, 2)
        assert abs(e) <= Fraction(1, 2) + Fraction(1, 9), (c, f9, a, b)


def test_fixed_fine_only_and_no_sector_slip():
    """Without weights: the nearest candidate, rounded (<= 4/9 LSB), at every bearing and
    with coarse errors up to 19.5 deg, including across the 0/360 wrap and sector edges."""
    theta = np.concatenate([np.arange(0, 360, 0.05), 40.0 * np.arange(9) + 1e-7,
                            40.0 * np.arange(9) - 1e-7 + 360, [359.9999999]])
    rng = np.random.default_rng(0)
    coarse = deg_to_bangle(theta + rng.uniform(-19.5, 19.5, theta.size))
    fine9 = deg_to_bangle(9 * theta)
    got = combine_coarse_fine_fixed(coarse, fine9)
    assert np.abs(wrap_deg(bangle_to_deg(got) - theta)).max() < 1.5 * LSB_DEG
    ref = combine_coarse_fine(bangle_to_rad(coarse), bangle_to_rad(fine9))
    assert np.abs(_lsb_err(got, ref)).max() <= 4 / 9 + 1e-6


def test_fixed_combination_weights():
    c, f9 = deg_to_bangle(10.4), deg_to_bangle(90.0)
    half = combine_coarse_fine_fixed(c, f9, 1, 1)          # as the float test: halfway
    assert abs(bangle_to_deg(half) - 10.2) < LSB_DEG
    assert combine_coarse_fine_fixed(c, f9, 0, 5) == combine_coarse_fine_fixed(c, f9)
    assert combine_coarse_fine_fixed(c, f9, 0, 0) == combine_coarse_fine_fixed(c, f9)
    # coarse only: exactly the coarse angle (wf = 0), any coarse
    cc = np.arange(0, 2 ** 32, 2 ** 32 // 997, dtype=np.int64)
    np.testing.assert_array_equal(combine_coarse_fine_fixed(cc, 12345, 7, 0), cc)
    # natural wrap: angles outside [0, 2**32) are taken mod one turn
    assert combine_coarse_fine_fixed(c + 2 ** 32, f9 - 2 ** 33, 3, 1) == \
        combine_coarse_fine_fixed(c, f9, 3, 1)
    # other word lengths
    for bits in (8, 16, 24, 40):
        got = combine_coarse_fine_fixed(deg_to_bangle(10.4, bits), deg_to_bangle(90.0, bits),
                                        1, 1, angle_bits=bits)
        assert abs(wrap_deg(bangle_to_deg(got, bits) - 10.2)) < 2 * 360 / 2 ** bits


def test_weight_fraction_is_exactly_rounded():
    rng = np.random.default_rng(4)
    wc = np.floor(2.0 ** rng.uniform(0, 61.9, 3000)).astype(np.int64)
    wf = np.floor(2.0 ** rng.uniform(0, 61.9, 3000)).astype(np.int64)
    got = weight_fraction(wc, wf, 30)
    for a, b, g in zip(wc.tolist(), wf.tolist(), got.tolist()):
        s = max(0, max(a, b).bit_length() - 60)            # the documented normalisation
        a2, b2 = a >> s, b >> s
        assert g == (2 * a2 * 2 ** 30 + (a2 + b2)) // (2 * (a2 + b2))
    np.testing.assert_array_equal(weight_fraction([0, 5, 0, 2 ** 62 - 1], [0, 0, 5, 2 ** 62 - 1],
                                                  30), [0, 2 ** 30, 0, 2 ** 29])


def test_information_weights():
    wc, wf = information_weights(np.array([3, 0, 2 ** 40]), np.array([2, 0, 2 ** 36]))
    np.testing.assert_array_equal(wc[:2], [9, 0])
    np.testing.assert_array_equal(wf[:2], [324, 0])
    # normalised: max(2**40, 9 * 2**36) has 41 bits -> common shift 11; ratio kept
    assert wc[2] == (2 ** 29) ** 2 and wf[2] == (9 * 2 ** 25) ** 2
    assert wc.max() < 2 ** 61 and wf.max() < 2 ** 61
    with pytest.raises(ValueError, match="magnitudes must be non-negative"):
        information_weights([-1], [1])


def test_binary_angle_conversions():
    assert deg_to_bangle(90.0) == 2 ** 30 and deg_to_bangle(-90.0) == 3 * 2 ** 30
    assert deg_to_bangle(360.0) == 0 and deg_to_bangle(359.99999999999) == 0
    assert bangle_to_deg(2 ** 31) == 180.0 and bangle_to_deg(-2 ** 30) == 270.0
    assert deg_to_bangle(45.0, 8) == 32 and bangle_to_deg(32, 8) == 45.0
    x = np.random.default_rng(5).uniform(-720, 720, 1000)
    np.testing.assert_allclose(wrap_deg(bangle_to_deg(deg_to_bangle(x)) - x), 0,
                               atol=0.5 * LSB_DEG + 1e-12)
    r = np.radians(x)
    np.testing.assert_allclose(wrap_pi(bangle_to_rad(rad_to_bangle(r)) - r), 0,
                               atol=0.5 * 2 * np.pi / 2 ** 32 + 1e-12)
    assert reduce_bangle(2 ** 40 - 2 ** 7, 40, 32) == 0           # rounds up, wraps
    assert reduce_bangle(2 ** 7 - 1, 40, 32) == 0 and reduce_bangle(2 ** 7, 40, 32) == 1
    assert reduce_bangle(5, 8, 12) == 80
    with pytest.raises(ValueError, match="must be finite"):
        deg_to_bangle(np.nan)
    with pytest.raises(ValueError, match=r"angle_bits must be an integer in \[1, 62\], not 63"):
        bangle_to_deg(1, 63)
    with pytest.raises(ValueError, match="a must be integers"):
        bangle_to_deg(1.5)


def test_phase_words_match_the_kalman_core():
    from dsp.tacan.kalman_config import KalmanFixedConfig

    cfg = KalmanFixedConfig()
    fw15, fw135 = (int(v) for v in cfg.value_consts()[:2])
    assert freq_word(15.0, cfg.tick_hz) == fw15 and freq_word(135.0, cfg.tick_hz) == fw135
    rng = np.random.default_rng(6)
    dt = np.concatenate([rng.integers(-2 ** 62, 2 ** 62, 500), [0, 1, -1, 2 ** 63 - 1]])
    got = phase_advance(dt, fw135)
    np.testing.assert_array_equal(got, [(int(d) * fw135) % 2 ** 40 for d in dt])
    a15, a135 = reference_advances(np.array([123456, 10 ** 7]), np.array([789, 2 ** 40 + 3]), 20e6)
    np.testing.assert_array_equal(a15, [reduce_bangle((d * fw15) % 2 ** 40, 40, 32)
                                        for d in (123456, 10 ** 7)])
    np.testing.assert_array_equal(a135, [reduce_bangle((d * fw135) % 2 ** 40, 40, 32)
                                         for d in (789, 2 ** 40 + 3)])
    # 1/15 s after the main reference the 15 Hz phase is back at 0 (within the word's error)
    a, _ = reference_advances(20_000_000 // 15 + 0, 0, 20e6)
    assert min(int(a), 2 ** 32 - int(a)) < 2 ** 32 * 1e-6
    with pytest.raises(ValueError, match="need 0 <= f_hz < tick_hz"):
        freq_word(-1.0, 20e6)
    with pytest.raises(ValueError, match=r"word must be an integer in \[0, 2\*\*40\)"):
        phase_advance([1], 2 ** 40)


def _random_states(n, seed, lo=2.0 ** -8, hi=2.0):
    rng = np.random.default_rng(seed)
    m1 = 2.0 ** rng.uniform(np.log2(lo), np.log2(hi), n)
    m2 = 2.0 ** rng.uniform(np.log2(lo), np.log2(hi), n)
    a, b = rng.uniform(0, 2 * np.pi, (2, n))
    xf = np.stack([m1 * np.sin(a), m1 * np.cos(a), m2 * np.sin(b), m2 * np.cos(b),
                   rng.uniform(-1, 1, n)], axis=-1)
    x = X_FMT.quantize(xf)[0]
    adv15, adv135 = rng.integers(0, 2 ** 40, (2, n))
    return x, adv15, adv135


def _float_path(x, adv15, adv135):
    """What process_peaks does with the float readout of the same integer state."""
    xq = X_FMT.to_float(x)
    alpha, beta = np.arctan2(xq[..., 0], xq[..., 1]), np.arctan2(xq[..., 2], xq[..., 3])
    m1, m2 = np.hypot(xq[..., 0], xq[..., 1]), np.hypot(xq[..., 2], xq[..., 3])
    coarse = 2 * np.pi * adv15 / 2.0 ** 40 - alpha
    fine9 = 2 * np.pi * adv135 / 2.0 ** 40 - beta
    return combine_coarse_fine(coarse, fine9, m1 * m1, 81.0 * m2 * m2), coarse, m1, m2


def test_bearing_from_state_matches_float_path():
    """Documented bound: <= 2.1 LSB (1.8e-7 deg) for magnitudes >= 2**20 state LSB."""
    x, adv15, adv135 = _random_states(100_000, seed=8)
    out = bearing_from_state(x, X_FMT, adv15, adv135)
    ref, coarse, m1, m2 = _float_path(x, adv15, adv135)
    err = _lsb_err(out.bearing, ref)
    assert np.abs(err).max() <= 2.1
    assert np.abs(err).max() * LSB_DEG < 2e-7
    assert np.abs(_lsb_err(out.coarse, coarse)).max() <= 0.78 + 0.5
    assert out.valid.all()
    np.testing.assert_allclose(X_FMT.to_float(out.m1), m1, rtol=1e-6, atol=2 ** -28)
    np.testing.assert_allclose(X_FMT.to_float(out.m2), m2, rtol=1e-6, atol=2 ** -28)
    assert state_cordic(36).angle_error_bound(2 ** 20) < 0.78 * 2 * np.pi / 2 ** 32


def test_bearing_from_state_shapes_and_broadcast():
    x, adv15, adv135 = _random_states(12, seed=9)
    out = bearing_from_state(x.reshape(3, 4, 5), X_FMT, adv15[0], adv135[0])
    assert out.bearing.shape == (3, 4) and out.valid.shape == (3, 4)
    flat = bearing_from_state(x, X_FMT, np.full(12, adv15[0]), np.full(12, adv135[0]))
    np.testing.assert_array_equal(out.bearing.ravel(), flat.bearing)
    np.testing.assert_array_equal(out.coarse.ravel(), flat.coarse)
    again = bearing_from_state(x, X_FMT, np.full(12, adv15[0]), np.full(12, adv135[0]))
    np.testing.assert_array_equal(again.bearing, flat.bearing)        # deterministic


def test_zero_state_gives_timing_only_bearing_flagged_invalid():
    adv15 = np.array([0, 2 ** 39, 12345678901])
    adv135 = np.array([0, 2 ** 38, 98765432109])
    out = bearing_from_state(np.zeros((3, 5), np.int64), X_FMT, adv15, adv135)
    assert not out.valid.any()
    np.testing.assert_array_equal(out.m1, 0)
    np.testing.assert_array_equal(out.m2, 0)
    c, f9 = reduce_bangle(adv15, 40), reduce_bangle(adv135, 40)
    np.testing.assert_array_equal(out.coarse, c)
    np.testing.assert_array_equal(out.bearing, combine_coarse_fine_fixed(c, f9))
    # one component missing: still flagged; with m2 = 0 the bearing is the coarse one
    x = np.zeros((1, 5), np.int64)
    x[0, 0] = 2 ** 26
    only15 = bearing_from_state(x, X_FMT, adv15[2], adv135[2])
    assert not only15.valid[0] and only15.bearing[0] == only15.coarse[0]
    assert bearing_from_state(x, X_FMT, 0, 0, min_magnitude=2 ** 27).valid.sum() == 0


def test_bearing_from_fixed_kalman_state_on_tacan_pulses():
    """End to end with the integer core: run the fixed filter on pulse ticks, take its
    state and the tick differences to the latest main and latest reference: the integer
    bearing is the true one (20 dB) and within 2.1 LSB of the float readout."""
    from cosim.tacan.signal import TacanSignalConfig, pulse_observations, pulse_schedule
    from dsp.tacan.kalman import EnvelopeKalman
    from dsp.tacan.kalman_config import KalmanFixedConfig

    cfg = TacanSignalConfig(duration_s=1.0, snr_db=20, seed=4)
    bears = np.array([0.0, 39.99, 123.4, 200.0, 359.9])
    t, amps, _ = pulse_observations(cfg, bears)
    _, _, mains, auxs = pulse_schedule(cfg)
    kcfg = KalmanFixedConfig()
    ticks = np.round(t * kcfg.tick_hz).astype(np.int64)
    kf = EnvelopeKalman(kcfg, batch=bears.size)
    kf.run(np.diff(ticks, prepend=ticks[0]), amps)
    t_last = int(ticks[-1])
    refs = np.round(np.concatenate([mains, auxs]) * kcfg.tick_hz).astype(np.int64)
    t_main = int(np.round(mains * kcfg.tick_hz).astype(np.int64)[mains <= t[-1]].max())
    t_ref = int(refs[refs <= t_last].max())
    fw15, fw135 = (int(v) for v in kcfg.value_consts()[:2])
    adv15 = phase_advance(t_last - t_main, fw15)
    adv135 = phase_advance(t_last - t_ref, fw135)
    out = bearing_from_state(kf.x, kcfg.x, adv15, adv135)
    assert out.valid.all()
    assert np.abs(wrap_deg(bangle_to_deg(out.bearing) - bears)).max() < 0.2
    ref, _, _, _ = _float_path(kf.x, adv15, adv135)
    assert np.abs(_lsb_err(out.bearing, ref)).max() <= 2.1
    # the same with the helper that forms the advances from the tick differences
    a15, a135 = reference_advances(t_last - t_main, t_last - t_ref, kcfg.tick_hz)
    again = bearing_from_state(kf.x, kcfg.x, a15, a135, adv_bits=ANGLE_BITS)
    np.testing.assert_array_equal(again.bearing, out.bearing)


@pytest.mark.parametrize("call, msg", [
    (lambda: combine_coarse_fine_fixed(1.5, 2), r"coarse must be integers"),
    (lambda: combine_coarse_fine_fixed(1, 2, -1, 3),
     r"w_coarse must be integers in \[0, 2\*\*62\)"),
    (lambda: combine_coarse_fine_fixed(1, 2, 1, 2 ** 62),
     r"w_fine must be integers in \[0, 2\*\*62\)"),
    (lambda: combine_coarse_fine_fixed(1, 2, angle_bits=41),
     r"angle_bits must be an integer in \[8, 40\], not 41"),
    (lambda: bearing_from_state(np.zeros((2, 4), np.int64), X_FMT, 0, 0),
     r"x must have shape \(\.\.\., 5\), not \(2, 4\)"),
    (lambda: bearing_from_state(np.full((1, 5), 2 ** 35), X_FMT, 0, 0),
     r"x does not fit its format"),
    (lambda: bearing_from_state(np.zeros((1, 5)), X_FMT, 0, 0), r"x must be integers"),
    (lambda: bearing_from_state(np.zeros((1, 5), np.int64), FixedFormat(36, 28, False), 0, 0),
     r"x_fmt must be a signed FixedFormat"),
    (lambda: bearing_from_state(np.zeros((1, 5), np.int64), X_FMT, 0, 0, min_magnitude=0),
     r"min_magnitude must be an integer >= 1, not 0"),
    (lambda: bearing_from_state(np.zeros((1, 5), np.int64), X_FMT, 0.5, 0),
     r"a must be integers"),
])
def test_fixed_bearing_bad_input(call, msg):
    with pytest.raises(ValueError, match=msg):
        call()
