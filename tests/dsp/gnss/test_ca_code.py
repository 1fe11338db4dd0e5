"""The 32 C/A codes against IS-GPS-200 Table 3-Ia and the Gold-code properties."""
import numpy as np
import pytest

from dsp.gnss import ca_code as ca


@pytest.mark.parametrize("prn", range(1, 33))
def test_first_10_chips_match_is_gps_200(prn):
    assert ca.first_10_chips_octal(ca.ca_code(prn)) == ca.FIRST_10_CHIPS_OCTAL[prn]


@pytest.mark.parametrize("prn", range(1, 33))
def test_phase_selector_equals_g2_delay(prn):
    # Two columns of the table agree: the tap pair's XOR is G2 delayed by the stated chips.
    g2 = ca.lfsr_sequence(ca.G2_FEEDBACK, n=2 * ca.CODE_LENGTH)
    d = ca.G2_DELAY_CHIPS[prn]
    np.testing.assert_array_equal(ca.g2i(prn), g2[ca.CODE_LENGTH - d:2 * ca.CODE_LENGTH - d])


def test_period_balance_and_gold_correlation():
    g1 = ca.lfsr_sequence(ca.G1_FEEDBACK, n=2 * ca.CODE_LENGTH)
    np.testing.assert_array_equal(g1[:1023], g1[1023:])     # period 1023 (maximal length)
    codes = np.array([ca.ca_code_levels(p) for p in range(1, 33)], dtype=np.int64)
    # Balanced: 512 ones and 511 zeros (sum of levels -1).
    np.testing.assert_array_equal(codes.sum(axis=1), -1)
    spec = np.fft.fft(codes, axis=1)
    allowed = {-65, -1, 63}
    for a in range(32):
        for b in range(a, 32):
            # Every cyclic shift: circular correlation via FFT (exact after rounding).
            r = np.rint(np.fft.ifft(spec[a] * np.conj(spec[b])).real).astype(np.int64)
            if a == b:
                assert r[0] == 1023
                r = r[1:]
            assert set(np.unique(r)) <= allowed, (a + 1, b + 1, set(np.unique(r)))


def test_bad_prn_message():
    for bad in (0, 33, -1, 1.5, True):
        with pytest.raises(ValueError, match=r"PRN must be an integer in \[1, 32\], not "):
            ca.ca_code(bad)
