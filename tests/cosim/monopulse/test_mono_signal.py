import math

import numpy as np
import pytest

from cosim.monopulse.array import ArrayConfig
from cosim.monopulse.signal import MonopulseSignalConfig, generate
from cosim.monopulse.trajectory import ConstantRate, Manoeuvre
from dsp.monopulse import golden


def small(**kw):
    """A short record at the default rates (N = 64 snapshots = 640 samples per block)."""
    base = dict(snapshots=64, trajectory=ConstantRate(0.32, 0.18, 0.5, -0.3), seed=11)
    base.update(kw)
    return MonopulseSignalConfig(**base)


def test_default_config_is_the_paper_scenario():
    c = MonopulseSignalConfig()
    assert (c.fs_hz, c.if_hz, c.chip_rate_hz, c.decimation) == (100e6, 20e6, 10e6, 10)
    assert c.snapshots == 8192 and c.snr_db == -8.0 and c.adc_bits == 12
    assert c.block_s == pytest.approx(819.2e-6)
    assert c.wavelength_m == pytest.approx(0.0299792458)
    # SNR over the ADC band = SNR 2 chip_rate / fs: -8 dB -> -15 dB; after N: 31.1 dB.
    snr_adc = 0.5 / c.sigma_w ** 2
    assert 10 * math.log10(snr_adc) == pytest.approx(-8 + 10 * math.log10(0.2), abs=1e-12)
    assert -8 + 10 * math.log10(8192) == pytest.approx(31.13, abs=0.01)


@pytest.mark.parametrize("kw, msg", [
    (dict(chip_rate_hz=3e7), "fs_hz / chip_rate_hz (the decimation) must be an integer >= 2, not 3.33"),
    (dict(chip_rate_hz=1e8), "fs_hz / chip_rate_hz (the decimation) must be an integer >= 2, not 1.0"),
    (dict(if_hz=45e6), "IF must keep the BPSK main lobe (IF +- chip rate 10 MHz) inside (0, fs/2 = 50 MHz), not IF = 45 MHz"),
    (dict(if_hz=21e6), "2 IF decimation / fs must be an integer"),
    (dict(snapshots=0), "snapshots must be an integer >= 1, not 0"),
    (dict(adc_bits=1), "adc_bits must be an integer in [2, 16] or None, not 1"),
    (dict(snr_db=float("nan")), "snr_db must be a finite number, not nan"),
    (dict(fs_hz=-1.0), "fs_hz must be > 0, not -1.0"),
])
def test_bad_config_is_refused(kw, msg):
    with pytest.raises(ValueError) as e:
        MonopulseSignalConfig(**kw)
    assert str(e.value).startswith(msg)


def test_blocks_concatenated_equal_one_shot_with_per_block_steering():
    c = small(array=ArrayConfig(gain_db=(0, 0.2, -0.1, 0.3), phase_deg=(0, 2, -1, 3)))
    steer = np.array([[0.3, 0.2], [0.31, 0.19], [0.33, 0.17]])
    whole = generate(c, steer, 0, 3)
    parts = [generate(c, steer[k], k, 1) for k in range(3)]
    np.testing.assert_array_equal(whole.samples, np.concatenate([p.samples for p in parts], 1))
    np.testing.assert_array_equal(whole.replica, np.concatenate([p.replica for p in parts]))
    np.testing.assert_array_equal(whole.clipped, sum(p.clipped for p in parts))
    np.testing.assert_array_equal(whole.az, np.concatenate([p.az for p in parts]))
    mid = generate(c, steer[1:], 1, 2)
    np.testing.assert_array_equal(mid.samples, whole.samples[:, c.samples_per_block:])
    # The steering acts per block: block 1 steered elsewhere changes block 1 only.
    other = generate(c, np.array([[0.3, 0.2], [0.25, 0.25], [0.33, 0.17]]), 0, 3)
    n = c.samples_per_block
    np.testing.assert_array_equal(other.samples[:, :n], whole.samples[:, :n])
    np.testing.assert_array_equal(other.samples[:, 2 * n:], whole.samples[:, 2 * n:])
    assert np.any(other.samples[:, n:2 * n] != whole.samples[:, n:2 * n])


def test_seeds_and_streams():
    a = generate(small(), (0.3, 0.2), 0, 2)
    b = generate(small(seed=12), (0.3, 0.2), 0, 2)
    assert np.mean(a.samples == b.samples) < 0.2
    assert np.mean(a.replica == b.replica) < 0.7
    assert np.mean(a.replica[0] == a.replica[1]) < 0.7   # each block its own chips
    assert set(np.unique(a.replica)) == {-1, 1}
    assert a.samples.dtype == np.int16


def test_truth_is_returned_at_block_centres():
    c = small(trajectory=Manoeuvre(0.3, 0.2, 0.1, 0.0, segments=((0.0, 1.0, 2.0, 1.0),)))
    r = generate(c, (0.3, 0.2), 2, 3)
    t = (np.arange(2, 5) + 0.5) * c.block_s
    u, v = c.trajectory(t)
    np.testing.assert_allclose(r.t_s, t)
    np.testing.assert_allclose(r.u, u)
    np.testing.assert_allclose(r.az, np.arctan2(v, u))
    np.testing.assert_allclose(r.el, np.arcsin(np.hypot(u, v)))
    assert r.snap_u.shape == (3, 64)
    assert np.all(np.diff(r.snap_u.ravel()) > 0)


def test_steering_outside_the_visible_region_is_refused():
    with pytest.raises(ValueError, match="steering direction must lie in the visible region"):
        generate(small(), (0.8, 0.7), 0, 1)
    with pytest.raises(ValueError, match="steering must be .* shape \\(2, 2\\), not shape \\(3, 2\\)"):
        generate(small(), np.zeros((3, 2)), 0, 2)


def test_snr_in_the_snapshot_band_is_as_defined():
    """Noise at the DDC output has variance A^2 / SNR, the on-boresight signal power A^2."""
    c = small(snapshots=8192, snr_db=-8.0, adc_bits=None, array=ArrayConfig(phase_bits=None),
              trajectory=ConstantRate(0.3, 0.2))
    noisy = generate(c, (0.3, 0.2), 0, 1)
    clean = generate(small(snapshots=8192, snr_db=None, adc_bits=None,
                           array=ArrayConfig(phase_bits=None), trajectory=ConstantRate(0.3, 0.2)),
                     (0.3, 0.2), 0, 1)
    z_n = golden.ddc(noisy.samples - clean.samples, c.if_hz, c.fs_hz, c.decimation)
    z_s = golden.ddc(clean.samples, c.if_hz, c.fs_hz, c.decimation)
    np.testing.assert_allclose(np.abs(z_s), 1.0, atol=1e-12)
    snr_db = 10 * np.log10(1.0 / np.mean(np.abs(z_n) ** 2))
    assert snr_db == pytest.approx(-8.0, abs=0.1)  # 4 x 8192 snapshots: 1 sigma = 0.024 dB
    # circular: I and Q equal power, uncorrelated
    assert np.var(z_n.real) / np.var(z_n.imag) == pytest.approx(1.0, abs=0.05)
    assert abs(np.mean(z_n.real * z_n.imag)) / np.var(z_n.real) < 0.03


def test_adc_clipping_is_counted():
    r = generate(small(adc_full_scale_sigma=1.0, adc_bits=8), (0.3, 0.2), 0, 8)
    n = r.samples.shape[1]
    # Gaussian-dominated input clipped at 1 sigma: 31.7 % of samples (1 sigma of the count 0.46 %).
    assert np.all(np.abs(r.clipped / n - 0.317) < 0.02)
    assert r.samples.max() == 127 and r.samples.min() == -128
    assert np.all(generate(small(adc_full_scale_sigma=6.0), (0.3, 0.2), 0, 2).clipped == 0)


def test_one_default_block():
    """The monopulse paper's block: 8192 snapshots = 81920 samples per ADC, 12-bit codes, no clipping
    expected at 4 sigma full scale beyond a handful (P = 6e-5 per sample)."""
    c = MonopulseSignalConfig()
    r = generate(c, (0.3, 0.2), 0, 1)
    assert r.samples.shape == (4, 81920) and r.replica.shape == (1, 8192)
    assert np.all(r.clipped < 25)
    assert np.abs(r.samples).max() <= 2048
