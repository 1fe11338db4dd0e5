"""Golden correlator: against an independent numpy formulation, epoch boundaries, replicas."""
import numpy as np
import pytest

from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, ca_code_levels
from dsp.gnss.correlator import GoldenCorrelator, correlate

FS = 16.368e6


def _reference(x, fs, prn, d, f_car, f_code, ph0, cp0):
    """Sample by sample from the definition, one epoch after another, in plain numpy."""
    code = ca_code_levels(prn).astype(float)
    out, n, ph, cp = [], 0, ph0, cp0
    for fc, fk in zip(f_car, f_code):
        dp = fk / fs
        M = int(np.ceil((CODE_LENGTH - cp) / dp))
        if n + M > x.size:
            break
        m = np.arange(M)
        z = x[n:n + M] * np.exp(-2j * np.pi * (ph + fc / fs * m))
        p = cp + dp * m
        row = [np.sum(z * code[np.floor(p + o).astype(int) % CODE_LENGTH]) for o in (d / 2, 0, -d / 2)]
        out.append(row + [n, M])
        n += M
        ph = (ph + fc / fs * M) % 1.0
        cp = cp + dp * M - CODE_LENGTH
    return out


def test_matches_independent_formulation_with_changing_frequencies():
    rng = np.random.default_rng(42)
    x = rng.standard_normal(int(FS * 0.006))
    f_car = 4.092e6 + rng.uniform(-5e3, 5e3, 6)
    f_code = CHIP_RATE_HZ + rng.uniform(-3, 3, 6) + np.array([0, 0, 500, 0, -500, 0])
    ref = _reference(x, FS, 13, 0.3, f_car, f_code, 0.37, 700.25)
    out = correlate(x, FS, 13, f_car, f_code, spacing_chips=0.3, carrier_phase_cycles=0.37,
                    code_phase_chips=700.25, n_epochs=6)
    assert len(ref) == len(out.ip) >= 5
    iq = out.iq()
    for k, r in enumerate(ref):
        np.testing.assert_allclose(iq[k], r[:3], rtol=1e-9, atol=1e-9 * np.sqrt(r[4]))
        assert (out.n_start[k], out.n_samples[k]) == (r[3], r[4])


def test_epoch_lengths_and_double_buffered_frequencies():
    c = GoldenCorrelator(FS, 1, carrier_freq_hz=4.092e6, code_freq_hz=CHIP_RATE_HZ)
    assert c.samples_needed() == 16368
    d0 = c.integrate(np.zeros(16368))
    c.set_frequencies(4.1e6, CHIP_RATE_HZ * 1.01)  # written after the dump: next epoch
    assert c.samples_needed() == int(np.ceil(1023 / (CHIP_RATE_HZ * 1.01 / FS)))
    d1 = c.integrate(np.zeros(c.samples_needed()))
    assert (d0.code_freq_hz, d1.code_freq_hz) == (CHIP_RATE_HZ, CHIP_RATE_HZ * 1.01)
    assert d1.n_start == d0.n_start + d0.n_samples
    assert d1.code_phase_start == d0.code_phase_dump and d1.carrier_phase_start == d0.carrier_phase_dump
    with pytest.raises(ValueError, match=r"this epoch needs \d+ samples, not \(10,\)"):
        c.integrate(np.zeros(10))


def test_early_prompt_late_sample_the_triangle():
    # Zero Doppler, a signal code phase 0.25 chip (4 samples) ahead of the prompt replica:
    # E = R(0), P = R(0.25), L = R(0.5) exactly (16 samples per chip), R the code's own
    # rectangular-chip autocorrelation: 1 - tau (1 - R1), R1 its one-chip value (63/1023).
    code = ca_code_levels(21).astype(float)
    r1 = code @ np.roll(code, 1) / 1023
    n = np.arange(int(FS * 0.003))
    chips = n * CHIP_RATE_HZ / FS + 0.25
    x = code[np.floor(chips).astype(int) % 1023] * np.cos(2 * np.pi * 0.25 * n)
    out = correlate(x, FS, 21, 4.092e6, CHIP_RATE_HZ, spacing_chips=0.5, n_epochs=2)
    half_m = out.n_samples / 2
    np.testing.assert_allclose(out.ie / half_m, 1.0, atol=1e-9)
    assert r1 == pytest.approx(63 / 1023)
    np.testing.assert_allclose(out.ip / half_m, 1 - 0.25 * (1 - r1), atol=1e-9)
    np.testing.assert_allclose(out.il / half_m, 1 - 0.5 * (1 - r1), atol=1e-9)
    np.testing.assert_allclose([out.qe, out.qp, out.ql], 0.0, atol=1e-6 * half_m.max())


@pytest.mark.parametrize("kw,msg", [
    (dict(spacing_chips=0.0), r"spacing_chips must be in \(0, 2\], not 0.0"),
    (dict(spacing_chips=2.5), r"spacing_chips must be in \(0, 2\], not 2.5"),
    (dict(code_phase_chips=1023.0), r"code_phase_chips must be in \[0, 1023\), not 1023.0"),
    (dict(prn=40), r"PRN must be an integer in \[1, 32\], not 40"),
    (dict(code_freq_hz=0.0), r"code_freq_hz must be in \(0, fs\), not 0.0"),
    (dict(carrier_freq_hz=float("nan")), "carrier_freq_hz must be a finite number, not nan"),
])
def test_bad_parameters(kw, msg):
    args = dict(fs_hz=FS, prn=1)
    args.update(kw)
    with pytest.raises(ValueError, match=msg):
        GoldenCorrelator(**args)
