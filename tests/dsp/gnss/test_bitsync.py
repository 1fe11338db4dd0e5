"""Bit synchronisation (histogram method) and frame synchronisation on prompt sequences built
from encoded LNAV frames: the edge found at any offset, either polarity, the message decoded
to the ephemeris sent; noise alone, a short stream and a stream without transitions refused
with their status."""
import numpy as np
import pytest

from dsp.gnss.bitsync import CODES_PER_BIT, bit_sync, nav_bits
from dsp.gnss.nominal_orbits import nominal_constellation
from dsp.gnss.ephemeris import KlobucharParameters
from dsp.gnss.lnav import encode_frames
from dsp.gnss.lnav_decode import decode_lnav

WEEK, TOE = 2300, 345_600.0
EPH = nominal_constellation(WEEK, TOE)[4]
IONO = KlobucharParameters((1e-8, 0.0, -6e-8, 0.0), (9e4, 0.0, -2e5, 0.0))


def prompts(offset: int, cn0_dbhz: float, seed: int, n_frames: int = 1, sign: float = 1.0):
    """1 ms in-phase prompts of one frame (30 s) of ``EPH`` starting ``offset`` code periods
    into the first bit (amplitude for the C/N0 at unit noise: I = A d + n, A^2 = 2 C/N0 T)."""
    bits = encode_frames(EPH, IONO, WEEK, TOE + 30.0, n_frames)
    d = np.repeat(1.0 - 2.0 * bits, CODES_PER_BIT)[offset:]
    a = np.sqrt(2 * 10 ** (cn0_dbhz / 10) * 1e-3)
    rng = np.random.default_rng(seed)
    return sign * a * d + rng.standard_normal(d.size), bits


@pytest.mark.parametrize("offset", [0, 7, 19])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_edge_bits_and_message_of_a_noisy_frame(offset, sign):
    ip, bits = prompts(offset, 35.0, seed=offset + 3, n_frames=2, sign=sign)
    bs = bit_sync(ip)
    assert bs.ok and bs.edge == (CODES_PER_BIT - offset) % CODES_PER_BIT, bs
    assert bs.histogram[bs.edge] == bs.histogram.max()
    sums, first = nav_bits(ip, bs.edge)
    assert np.all(first == bs.edge + CODES_PER_BIT * np.arange(sums.size))
    skip = 1 if offset else 0                       # a partial first bit is not a bit
    sent = bits[skip:skip + sums.size]
    got = (sums < 0).astype(np.uint8) ^ np.uint8(sign < 0)
    assert np.mean(got != sent) < 1e-3
    res = decode_lnav(sums, EPH.prn, reference_week=WEEK)
    assert res.inverted == (sign < 0)
    assert res.ephemeris is not None
    assert res.ephemeris == EPH.quantised()
    assert res.subframes[0].tow_start == TOE + 30.0 + 6.0 * (res.subframes[0].subframe_id - 1)


def test_noise_alone_is_not_synchronised():
    rng = np.random.default_rng(11)
    for _ in range(20):
        bs = bit_sync(rng.standard_normal(6000))
        assert not bs.ok and bs.edge is None and bs.status == "ambiguous", bs


def test_short_and_transition_free_streams_are_refused_with_their_reason():
    assert bit_sync(np.ones(39)).status == "too-short"
    bs = bit_sync(np.ones(4000))
    assert bs.status == "too-few-changes" and bs.edge is None
    ip, _ = prompts(0, 45.0, seed=2)
    assert bit_sync(ip[:100]).status == "too-few-changes"          # 5 bits: too few changes


def test_low_cn0_still_synchronises_on_enough_bits_and_parity_guards_the_words():
    ip, _ = prompts(5, 27.0, seed=9, n_frames=2)     # 60 s
    bs = bit_sync(ip)
    assert bs.ok and bs.edge == 15
    sums, _ = nav_bits(ip, bs.edge)
    res = decode_lnav(sums, EPH.prn, reference_week=WEEK)
    # every subframe the decoder used passed parity on all its words
    bad = {(f.bit_index - res.sync_bit) // 300 for f in res.parity_failures}
    assert all((s.bit_index - res.sync_bit) // 300 not in bad for s in res.subframes)


@pytest.mark.parametrize("bad", [np.zeros((3, 40)), np.array([1.0, np.nan] * 30), "x"])
def test_malformed_prompts_raise(bad):
    with pytest.raises((ValueError, TypeError)):
        bit_sync(bad)


def test_bad_parameters_raise():
    with pytest.raises(ValueError, match="edge"):
        nav_bits(np.ones(100), 20)
    with pytest.raises(ValueError, match="min_changes"):
        bit_sync(np.ones(100), min_changes=0)
    with pytest.raises(ValueError, match="dominance"):
        bit_sync(np.ones(100), dominance=0.5)
