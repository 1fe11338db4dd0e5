"""TACAN IF signal generator: schedule, codes, modulation, noise, ADC, bad input."""
import math

import numpy as np
import pytest

from cosim.tacan.signal import (KIND_AUX, KIND_IDENT, KIND_MAIN, KIND_RANDOM, Multipath, TacanSignalConfig, envelope_gain, generate, noise_enbw_hz, pulse_observations, pulse_schedule)
from dsp.tacan.standard import burst_offsets
from dsp.sampling import fold_frequency


@pytest.mark.parametrize("mode", ["X", "Y"])
def test_counts_per_second(mode):
    cfg = TacanSignalConfig(mode=mode, duration_s=2.0, seed=3)
    t, k, mains, auxs = pulse_schedule(cfg)
    # The whole record is covered by reference groups (first main ref at 5 ms).
    assert mains.size == 30 and auxs.size == 240
    n_main_pulses = {"X": 24, "Y": 13}[mode]
    n_aux_pulses = {"X": 12, "Y": 13}[mode]
    assert np.count_nonzero(k == KIND_MAIN) == 30 * n_main_pulses
    assert np.count_nonzero(k == KIND_AUX) == 240 * n_aux_pulses
    # Constant duty cycle: 3600 pulse pairs = 7200 pulses per second (+-1 pair).
    assert abs(t.size - 2 * 3600 * 2.0) <= 2
    assert np.all(np.diff(t) >= 0)


def test_reference_timing_and_aux_left_out_at_main():
    cfg = TacanSignalConfig(duration_s=1.0)
    _, _, mains, auxs = pulse_schedule(cfg)
    np.testing.assert_allclose(np.diff(mains), 1 / 15, atol=1e-12)
    d = (auxs[:, None] - mains[None, :]) * 135
    k = np.round(d).astype(int)
    near = np.abs(d - k) < 1e-6
    ks = k[near]
    assert set(ks[(ks >= 1) & (ks <= 8)]) == set(range(1, 9))
    assert not np.any(ks == 0)  # the ninth auxiliary burst falls on the main one: left out


@pytest.mark.parametrize("mode", ["X", "Y"])
def test_codes_and_spacings(mode):
    cfg = TacanSignalConfig(mode=mode, duration_s=1.0, seed=7)
    t, k, mains, auxs = pulse_schedule(cfg)
    for starts, kind, name in ((mains, KIND_MAIN, "main"), (auxs, KIND_AUX, "aux")):
        offs = burst_offsets(mode, name)
        got = t[k == kind].reshape(starts.size, offs.size) - starts[:, None]
        np.testing.assert_allclose(got, np.broadcast_to(offs, got.shape), atol=1e-12)
    # Documented codes (MIL-STD-291C), in microseconds.
    us = lambda a: np.round(np.asarray(a) * 1e6, 6)
    if mode == "X":
        assert list(us(burst_offsets("X", "main"))[:4]) == [0, 12, 30, 42]
        assert list(us(burst_offsets("X", "aux"))) == list(range(0, 144, 12))
    else:
        assert list(us(burst_offsets("Y", "main"))) == list(range(0, 390, 30))
        assert list(us(burst_offsets("Y", "aux"))) == list(range(0, 195, 15))
    # Random pulses come in pairs at 12 us (X) or 30 us (Y), starts >= dead time apart.
    r = t[k == KIND_RANDOM]
    first, second = r[0::2], r[1::2]
    np.testing.assert_allclose(second - first, {"X": 12e-6, "Y": 30e-6}[mode], atol=1e-12)
    assert np.min(np.diff(first)) >= cfg.min_pair_gap_s - 1e-12


def test_no_random_pulse_inside_a_reference_group():
    cfg = TacanSignalConfig(duration_s=2.0, seed=11)
    t, k, mains, auxs = pulse_schedule(cfg)
    r = t[k == KIND_RANDOM]
    for starts, span in ((mains, burst_offsets("X", "main")[-1]), (auxs, burst_offsets("X", "aux")[-1])):
        lo = starts - cfg.ref_guard_s
        hi = starts + span + cfg.ref_guard_s
        inside = (r[:, None] >= lo[None, :]) & (r[:, None] <= hi[None, :])
        assert not inside.any()


def test_identity_keeps_duty_cycle():
    cfg = TacanSignalConfig(duration_s=1.0, identity=True)
    t, k, _, _ = pulse_schedule(cfg)
    ident = t[k == KIND_IDENT]
    assert ident.size > 0
    # Identity pairs are 1/1350 s apart while keyed.
    starts = ident[0::2]
    assert np.median(np.diff(starts)) == pytest.approx(1 / 1350, rel=1e-9)
    assert abs(t.size - 7200) <= 2


@pytest.mark.parametrize("bearing", [0.0, 37.0, 90.0, 200.5, 359.0])
def test_bearing_and_depth_recovered_from_noiseless_envelope(bearing):
    cfg = TacanSignalConfig(bearing_deg=bearing, mod_15=0.3, mod_135=0.07, duration_s=0.5)
    t, _, mains, _ = pulse_schedule(cfg)
    amp = envelope_gain(t, cfg, mains[0])
    tm = t - mains[0]
    w1, w2 = 2 * np.pi * 15 * tm, 2 * np.pi * 135 * tm
    M = np.column_stack([np.ones_like(tm), np.sin(w1), np.cos(w1), np.sin(w2), np.cos(w2)])
    c, *_ = np.linalg.lstsq(M, amp, rcond=None)
    # A sin(w - th) = A cos th sin w - A sin th cos w
    assert math.hypot(c[1], c[2]) == pytest.approx(0.3, abs=1e-9)
    assert math.hypot(c[3], c[4]) == pytest.approx(0.07, abs=1e-9)
    th1 = math.degrees(math.atan2(-c[2], c[1])) % 360
    th9 = math.degrees(math.atan2(-c[4], c[3])) % 360
    assert abs((th1 - bearing + 180) % 360 - 180) < 1e-7
    assert abs((th9 - 9 * bearing + 180) % 360 - 180) < 1e-6


def test_references_sit_in_the_trough_at_90_degrees():
    cfg = TacanSignalConfig(bearing_deg=90.0)
    _, _, mains, auxs = pulse_schedule(cfg)
    # Main references: both components at their minimum.
    np.testing.assert_allclose(envelope_gain(mains, cfg, mains[0]), 1 - 0.21 - 0.21, atol=1e-9)
    # Auxiliary references: the 135 Hz component at its minimum.
    only135 = cfg.replace(mod_15=0.0)
    np.testing.assert_allclose(envelope_gain(auxs, only135, mains[0]), 1 - 0.21, atol=1e-9)


def test_bandpass_sampling_folds_63_mhz_to_3_mhz():
    cfg = TacanSignalConfig()
    assert cfg.digital_if_hz == pytest.approx(3e6)
    assert not cfg.spectrum_inverted
    assert fold_frequency(73e6, 20e6) == (pytest.approx(7e6), True)
    assert fold_frequency(67e6, 20e6) == (pytest.approx(7e6), False)


def test_noise_level_matches_snr_definition():
    cfg = TacanSignalConfig(snr_db=10.0, duration_s=0.2, seed=2)
    s = generate(cfg)
    tr = s.truth
    x = s.samples.astype(float) / 2 ** (cfg.adc_bits - 1)
    # Samples far from any pulse (direct or not): noise only.
    n = np.arange(x.size) / cfg.fs_hz
    j = np.searchsorted(tr.pulse_times_s, n)
    d = np.minimum(np.abs(n - tr.pulse_times_s[np.clip(j, 0, tr.pulse_times_s.size - 1)]),
                   np.abs(n - tr.pulse_times_s[np.clip(j - 1, 0, tr.pulse_times_s.size - 1)]))
    quiet = x[d > 15e-6]
    # Noise power in 2 MHz = peak pulse power / SNR; the filter's ENBW is a bit over 2 MHz.
    expect = (tr.amplitude ** 2 / 2) / 10.0 * noise_enbw_hz(cfg) / cfg.noise_bw_hz
    assert quiet.var() == pytest.approx(expect, rel=0.03)
    assert tr.noise_rms ** 2 == pytest.approx(expect, rel=1e-9)


def test_same_seed_same_bits_and_seed_matters():
    cfg = TacanSignalConfig(duration_s=0.06, seed=5)
    a, b = generate(cfg), generate(cfg)
    np.testing.assert_array_equal(a.samples, b.samples)
    c = generate(cfg.replace(seed=6))
    assert not np.array_equal(a.samples, c.samples)


def test_adc_clipping_is_counted():
    s = generate(TacanSignalConfig(duration_s=0.05, amplitude=1.5, snr_db=None))
    assert s.truth.n_clipped > 0
    assert s.samples.max() == 2047 and s.samples.min() == -2048
    q = generate(TacanSignalConfig(duration_s=0.05, snr_db=None))
    assert q.truth.n_clipped == 0


def test_multipath_echo_changes_the_signal():
    base = TacanSignalConfig(duration_s=0.05, snr_db=None, amplitude=0.3)
    a = generate(base).samples
    b = generate(base.replace(multipath=Multipath(delay_s=3e-6, rel_amplitude=0.4))).samples
    assert not np.array_equal(a, b)


def test_pulse_observations_share_timeline():
    cfg = TacanSignalConfig(duration_s=0.5, snr_db=20)
    t, amps, truth = pulse_observations(cfg, [0.0, 90.0, 180.0])
    assert amps.shape == (3, t.size) == truth.shape
    resid = amps - truth
    assert resid.std() == pytest.approx(cfg.matched_filter_rel_sigma(), rel=0.05)


@pytest.mark.parametrize("changes, message", [
    (dict(fs_hz=2e6), r"sample rate 2 MS/s is too low for the IF"),
    (dict(fs_hz=0.0), r"fs_hz must be > 0, not 0.0"),
    (dict(adc_bits=0), r"adc_bits must be an integer in \[1, 24\], not 0"),
    (dict(adc_bits=-3), r"adc_bits must be an integer in \[1, 24\], not -3"),
    (dict(mod_15=1.2), r"modulation depths must satisfy 0 <= A, B and A \+ B < 1"),
    (dict(mod_135=-0.1), r"modulation depths must satisfy"),
    (dict(mod_15=0.6, mod_135=0.5), r"A \+ B < 1 .*A=0.6, B=0.5"),
    (dict(bearing_deg=float("nan")), r"bearing_deg must be a finite number, not nan"),
    (dict(duration_s=0.0), r"duration_s must be > 0, not 0.0"),
    (dict(duration_s=-1.0), r"duration_s must be > 0, not -1.0"),
    (dict(mode="Z"), r"mode must be 'X' or 'Y', not 'Z'"),
    (dict(pulse_width_s=0.0), r"pulse_width_s must be > 0"),
    (dict(snr_db=float("inf")), r"snr_db must be a finite number"),
    (dict(pairs_per_s=30000.0), r"pairs_per_s=30000 does not fit"),
])
def test_bad_input_clear_errors(changes, message):
    with pytest.raises(ValueError, match=message):
        cfg = TacanSignalConfig(**changes)
        pulse_schedule(cfg)


def test_bad_multipath():
    with pytest.raises(ValueError, match=r"multipath rel_amplitude must be in \[0, 1\), not 1.5"):
        Multipath(rel_amplitude=1.5)


def test_adc_variants_equal_separate_generation():
    from dataclasses import replace

    from cosim.tacan.signal import generate_adc_variants
    cfg = TacanSignalConfig(duration_s=0.01, snr_db=10, seed=3)
    v = generate_adc_variants(cfg, [4, 12, 8])
    for b in (4, 8, 12):
        ref = generate(replace(cfg, adc_bits=b))
        np.testing.assert_array_equal(v[b].samples, ref.samples)
        assert v[b].truth.n_clipped == ref.truth.n_clipped
        assert v[b].truth.config.adc_bits == b
    with pytest.raises(ValueError, match="adc_bits must be integers in 1..24"):
        generate_adc_variants(cfg, [0])
