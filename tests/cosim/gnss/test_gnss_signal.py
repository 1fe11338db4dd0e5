"""GPS L1 C/A IF generator: validation, determinism, blocks, Doppler consistency, ADC, data."""
import math

import numpy as np
import pytest

from cosim.gnss import dynamics as dy
from cosim.gnss.signal import (CHIPS_PER_BIT, NOISE_CHUNK, GnssSignalConfig, GnssSignalGenerator,
                               SampleStream, generate)
from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH
from dsp.gnss.correlator import correlate


@pytest.mark.parametrize("kw,msg", [
    (dict(prn=0), r"PRN must be an integer in \[1, 32\], not 0"),
    (dict(prn=33), r"PRN must be an integer in \[1, 32\], not 33"),
    (dict(fs_hz=2.0e6), "sample rate must be >= the C/A main-lobe bandwidth 2.046 MHz, not 2 MS/s"),
    (dict(if_hz=7.5e6), r"IF must keep the C/A main lobe \(IF \+- 1.023 MHz\) inside the first "
                        r"Nyquist zone \(0, fs/2 = 8.192 MHz\), not IF = 7.5 MHz \(sampled as it is, "
                        r"without bandpass sampling\)"),
    (dict(if_hz=20.46e6), "inside the first Nyquist zone .* not IF = 20.46 MHz"),
    (dict(if_hz=16.368e6, bandpass=True), "must lie inside one Nyquist zone .* not straddle an edge "
                                          r"\(IF = 16.368 MHz\)"),
    (dict(cn0_dbhz=math.nan), r"--cn0-dbhz must be a finite number >= 10 dB-Hz and <= 70 dB-Hz, not nan"),
    (dict(cn0_dbhz=math.inf), r"--cn0-dbhz must be a finite number >= 10 dB-Hz and <= 70 dB-Hz, not inf"),
    (dict(cn0_dbhz=200.0), r"--cn0-dbhz must be a finite number >= 10 dB-Hz and <= 70 dB-Hz, not 200.0"),
    (dict(adc_bits=0), r"adc_bits must be an integer in \[1, 16\], not 0"),
    (dict(adc_bits=17), r"adc_bits must be an integer in \[1, 16\], not 17"),
    (dict(duration_s=0.0), "duration_s must be > 0, not 0.0"),
    (dict(duration_s=-1.0), "duration_s must be > 0, not -1.0"),
    (dict(code_phase_chips=1023.0), r"code_phase_chips must be in \[0, 1023\), not 1023.0"),
    (dict(oscillator="rubidium"), "oscillator must be None, an Oscillator or one of"),
    (dict(dynamics="aukf-patent"), "dynamics must be a PolynomialProfile, JerkProcess or CsvProfile, not str"),
])
def test_bad_config_is_refused_with_the_rule_and_the_value(kw, msg):
    with pytest.raises(ValueError, match=msg):
        GnssSignalConfig(**kw)


def test_bandpass_sampling_is_allowed_when_asked_and_folds():
    c = GnssSignalConfig(if_hz=20.46e6, bandpass=True, fs_hz=16.368e6)
    assert c.digital_if_hz == pytest.approx(4.092e6) and not c.spectrum_inverted
    c = GnssSignalConfig(if_hz=12.276e6, bandpass=True, fs_hz=16.368e6)
    assert c.digital_if_hz == pytest.approx(4.092e6) and c.spectrum_inverted
    c = GnssSignalConfig(if_hz=12.276e6, bandpass=True)            # 16.384 MS/s
    assert c.digital_if_hz == pytest.approx(4.108e6) and c.spectrum_inverted


def _cfg(**kw):
    base = dict(prn=5, duration_s=0.02, cn0_dbhz=45.0, dynamics=dy.JerkProcess(q=1e3),
                oscillator="tcxo", seed=11)
    base.update(kw)
    return GnssSignalConfig(**base)


def test_same_seed_same_bits_other_seed_other_bits():
    a, b = generate(_cfg()), generate(_cfg())
    np.testing.assert_array_equal(a.samples, b.samples)
    np.testing.assert_array_equal(a.truth.carrier_phase_cycles, b.truth.carrier_phase_cycles)
    c = generate(_cfg(seed=12))
    assert np.mean(a.samples != c.samples) > 0.3


@pytest.mark.parametrize("block", [10007, NOISE_CHUNK, 3 * NOISE_CHUNK + 1])
def test_blocks_concatenated_equal_one_shot(block):
    cfg = _cfg(adc_bits=3)
    g = GnssSignalGenerator(cfg)
    one = g.analog(0, cfg.n_samples)
    parts = [GnssSignalGenerator(cfg).analog(k, min(block, cfg.n_samples - k))
             for k in range(0, cfg.n_samples, block)]
    np.testing.assert_array_equal(np.concatenate(parts), one)
    codes, clip = g.quantise(one)
    bl = list(GnssSignalGenerator(cfg).blocks(block))
    np.testing.assert_array_equal(np.concatenate([c for c, _ in bl]), codes)
    assert sum(c for _, c in bl) == clip
    # Block k alone, out of order, needs nothing of the rest.
    k = 2
    np.testing.assert_array_equal(GnssSignalGenerator(cfg).block(k, block)[0],
                                  codes[k * block:(k + 1) * block])


def test_truth_code_doppler_is_carrier_doppler_over_1540():
    g = GnssSignalGenerator(_cfg(duration_s=0.5, oscillator=None, dynamics=dy.JerkProcess(q=1e5)))
    t = np.linspace(0.01, 0.49, 50)
    h = 1e-5
    a, b = g.truth_at(t - h), g.truth_at(t + h)
    f_car = (b["carrier_phase_cycles"] - a["carrier_phase_cycles"]) / (2 * h)
    f_code = (b["code_chips_total"] - a["code_chips_total"]) / (2 * h)
    tr = g.truth_at(t)
    np.testing.assert_allclose(f_car, tr["doppler_hz"], atol=1e-3)
    # The code's Doppler phase is the carrier's over 1540 (exactly; finite differences of the
    # unwrapped chip count would only see its rounding).
    np.testing.assert_allclose((tr["code_chips_total"] - CHIP_RATE_HZ * t) * 1540,
                               tr["carrier_phase_cycles"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(f_code - CHIP_RATE_HZ, tr["doppler_hz"] / 1540, atol=1e-5)
    d_rate = (g.truth_at(t + h)["doppler_hz"] - g.truth_at(t - h)["doppler_hz"]) / (2 * h)
    np.testing.assert_allclose(d_rate, tr["doppler_rate_hz_s"], rtol=1e-4)


def test_noise_free_signal_correlates_fully_with_the_true_replica():
    # Constant Doppler, 5 kHz: code Doppler 3.25 chip/s. With code NCO = chip rate + D/1540
    # the prompt stays at A M / 2; with the code Doppler left out it decays (0.65 chip in 0.2 s).
    D = 5000.0
    cfg = GnssSignalConfig(prn=9, cn0_dbhz=None, duration_s=0.2, dynamics=dy.from_doppler(D),
                           nav_data=False, adc_bits=16, carrier_phase_cycles=0.3)
    g = GnssSignalGenerator(cfg)
    good = correlate(SampleStream(g, adc=False), cfg.fs_hz, 9, cfg.digital_if_hz + D,
                     CHIP_RATE_HZ + D / 1540, carrier_phase_cycles=0.3, n_epochs=199)
    p = (good.ip + 1j * good.qp) / (good.n_samples / 2)
    assert np.min(np.abs(p)) > 0.995 and np.max(np.abs(np.angle(p))) < 2e-3
    bad = correlate(SampleStream(g, adc=False), cfg.fs_hz, 9, cfg.digital_if_hz + D,
                    CHIP_RATE_HZ, carrier_phase_cycles=0.3, n_epochs=199)
    assert np.abs(bad.ip[-1]) / (bad.n_samples[-1] / 2) < 0.5


def test_nav_bits_flip_on_code_epochs_and_modulate_the_prompt():
    cfg = GnssSignalConfig(prn=3, cn0_dbhz=None, duration_s=0.4, nav_data=True, adc_bits=16,
                           code_phase_chips=0.0, seed=4)
    g = GnssSignalGenerator(cfg)
    tr = g.epoch_truth()
    bits = tr.nav_bit
    assert set(np.unique(bits)) == {-1.0, 1.0}
    # Constant within each group of 20 code epochs (the record starts on a bit edge).
    assert np.all(bits.reshape(-1, 20) == bits.reshape(-1, 20)[:, :1])
    assert np.all(np.floor(tr.code_chips_total / CHIPS_PER_BIT) == np.arange(bits.size) // 20)
    out = correlate(SampleStream(g, adc=False), cfg.fs_hz, 3, cfg.digital_if_hz, CHIP_RATE_HZ,
                    n_epochs=399)
    np.testing.assert_array_equal(np.sign(out.ip), bits[:399])


def test_noise_variance_is_n0_times_half_the_sample_rate():
    cfg = GnssSignalConfig(cn0_dbhz=50.0, duration_s=0.02, adc_bits=16)
    g = GnssSignalGenerator(cfg)
    n0 = 0.5 / 10 ** 5.0
    assert cfg.noise_sigma ** 2 == pytest.approx(n0 * cfg.fs_hz / 2, rel=1e-12)
    x = g.analog(0, cfg.n_samples)
    # 327 360 samples: the variance is known to 0.25 % (1 sigma); the signal adds 0.5.
    assert np.var(x) == pytest.approx(cfg.noise_sigma ** 2 + 0.5, rel=0.01)


@pytest.mark.parametrize("bits", [1, 2, 3, 8, 16])
def test_adc_levels_agc_and_clipping_count(bits):
    cfg = GnssSignalConfig(cn0_dbhz=45.0, duration_s=0.01, adc_bits=bits)
    g = GnssSignalGenerator(cfg)
    x = g.analog(0, cfg.n_samples)
    codes, clip = g.quantise(x)
    assert codes.dtype == (np.int16 if bits <= 15 else np.int32)
    levels = np.unique(codes)
    assert np.all(levels % 2 != 0) and levels.min() >= -(2 ** bits - 1) and levels.max() <= 2 ** bits - 1
    if bits <= 3:
        assert levels.size == 2 ** bits
    full = 2 ** (bits - 1) * cfg.adc_step
    expect = 0 if bits == 1 else int(np.count_nonzero((x >= full) | (x < -full)))
    assert clip == expect
    if bits == 2:
        # Max's 2-bit step ~ 1 sigma: P(|x| >= 2 sigma) = 4.55 %.
        assert clip / x.size == pytest.approx(0.0455, abs=0.003)
    # Reconstruction: codes * Delta/2 tracks x within half a step where not clipped.
    ok = np.abs(x) < full
    if bits > 1:
        assert np.max(np.abs(codes[ok] * cfg.adc_step / 2 - x[ok])) <= cfg.adc_step / 2 + 1e-12


def test_oscillator_phase_enters_the_truth_and_the_signal():
    a = GnssSignalGenerator(_cfg(duration_s=0.2))
    b = GnssSignalGenerator(_cfg(duration_s=0.2, oscillator=None))
    ta, tb = a.epoch_truth(), b.epoch_truth()
    assert np.all(tb.osc_phase_cycles == 0) and np.std(ta.osc_phase_cycles) > 0
    np.testing.assert_allclose(ta.carrier_phase_cycles - ta.osc_phase_cycles,
                               tb.carrier_phase_cycles, atol=1e-9)
    np.testing.assert_array_equal(ta.code_chips_total, tb.code_chips_total)


def test_truth_per_epoch_layout():
    cfg = _cfg(duration_s=0.05, code_phase_chips=100.0)
    tr = generate(cfg).truth
    assert tr.t_s.size == 50 and tr.t_s[1] == pytest.approx(1e-3)
    assert np.all((tr.code_phase_chips >= 0) & (tr.code_phase_chips < CODE_LENGTH))
    assert tr.code_phase_chips[0] == 100.0
    assert tr.doppler_hz[0] == pytest.approx(5251.40, abs=0.01)


def test_inverted_spectrum_after_bandpass_sampling_correlates_with_the_mirrored_replica():
    # 12.276 MHz at 16.384 MS/s lands at 4.108 MHz inverted: Doppler and phase change sign.
    D = 2000.0
    cfg = GnssSignalConfig(prn=4, if_hz=12.276e6, bandpass=True, cn0_dbhz=None, duration_s=0.05,
                           dynamics=dy.from_doppler(D), nav_data=False, adc_bits=16,
                           carrier_phase_cycles=0.2)
    g = GnssSignalGenerator(cfg)
    kw = dict(n_epochs=49)
    good = correlate(SampleStream(g, adc=False), cfg.fs_hz, 4, cfg.digital_if_hz - D,
                     CHIP_RATE_HZ + D / 1540, carrier_phase_cycles=-0.2, **kw)
    p = (good.ip + 1j * good.qp) / (good.n_samples / 2)
    assert np.min(np.abs(p)) > 0.995 and np.max(np.abs(np.angle(p))) < 2e-3
    wrong = correlate(SampleStream(g, adc=False), cfg.fs_hz, 4, cfg.digital_if_hz + D,
                      CHIP_RATE_HZ + D / 1540, carrier_phase_cycles=0.2, **kw)
    assert np.max(np.abs(wrong.ip + 1j * wrong.qp) / (wrong.n_samples / 2)) < 0.05


def test_sample_stream_serves_the_record_and_counts_each_clip_once():
    cfg = GnssSignalConfig(cn0_dbhz=40.0, duration_s=0.03, adc_bits=2, seed=2)
    g = GnssSignalGenerator(cfg)
    codes, clip = g.samples(0, cfg.n_samples)
    s = SampleStream(g, block_samples=50_000)
    parts, n = [], 0
    for m in [16368] * 29 + [cfg.n_samples - 29 * 16368]:
        parts.append(s(n, m).copy())
        n += m
    np.testing.assert_array_equal(np.concatenate(parts), codes)
    assert s.n_clipped == clip
    assert GnssSignalConfig(signal_present=False).adc_step < GnssSignalConfig().adc_step
