"""Reference decoding, coarse/fine combination and bearing over the whole circle."""
import numpy as np
import pytest

from cosim.tacan_signal import TacanSignalConfig, pulse_observations, pulse_schedule
from dsp.tacan.bearing import combine_coarse_fine, seed_eq17, wrap_deg
from dsp.tacan.decode import REF_AUX, REF_MAIN, DecoderConfig, decode
from dsp.tacan.kalman import KalmanConfig
from dsp.tacan.receiver import ReceiverConfig, bearing_stats, crb_deg, process_peaks


def test_combination_exact_for_every_bearing_with_coarse_error_below_20_degrees():
    theta = np.arange(0, 360, 0.05)
    rng = np.random.default_rng(0)
    coarse_err = rng.uniform(-19.5, 19.5, theta.size)
    coarse = np.radians(theta + coarse_err)
    fine9 = np.radians(9 * theta)
    got = np.degrees(combine_coarse_fine(coarse, fine9))
    np.testing.assert_allclose(wrap_deg(got - theta), 0, atol=1e-9)


def test_seed_eq17_slips_at_sector_edges_and_ours_does_not():
    theta = np.array([39.9, 80.05, 359.8])
    coarse = theta + np.array([0.3, -0.2, 0.5])  # small coarse errors across an edge
    fine135 = (9 * theta) % 360
    eq17 = seed_eq17(coarse, fine135)
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
