"""The LNAV message (IS-GPS-200 20.3): parity of Table 20-XIV, field positions of Figure
20-1, encode -> decode bit-exact for every ephemeris of the real RINEX files, frame sync at
either polarity, and decoding under seeded random bit errors."""
import itertools
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cosim.gnss.rinex_nav import read_rinex_nav
from dsp.gnss import lnav as L
from dsp.gnss.ephemeris import KlobucharParameters, UtcParameters
from dsp.gnss.lnav_decode import decode_lnav, hard_bits

DATA = Path(__file__).resolve().parents[2] / "data" / "gnss"
UTC = UtcParameters(A0=-0.931322574615e-09, A1=-0.444089209850e-14, tot=405504.0, WNt=1865 % 256,
                    dtLS=17, WNLSF=1865 % 256, DN=7, dtLSF=17)   # brdc2800.15n's header values


@pytest.fixture(scope="module")
def navs():
    return read_rinex_nav(DATA / "brdc2800.15n"), \
        read_rinex_nav(DATA / "ZIM200CHE_R_20201390000_01D_GN.rnx")


def _frame_start(e):
    """A frame start (multiple of 30 s) 10 minutes before toe, in toe's week."""
    return float(max(0.0, (e.toe - 600.0) // 30 * 30))


# --- parity -------------------------------------------------------------------------------

def test_parity_table_as_32_bit_masks():
    # Table 20-XIV as masks over [D29*, D30*, d1..d24, 6 spare bits]: the constants of
    # open-source receivers (e.g. RTKLIB's decode_word), an independent transcription.
    masks = []
    for star, taps in L.PARITY_TAPS:
        m = 1 << (31 if star == 29 else 30)
        for i in taps:
            m |= 1 << (30 - i)
        masks.append(m)
    assert masks == [0xBB1F3480, 0x5D8F9A40, 0xAEC7CD00, 0x5763E680, 0x6BB1F340, 0x8B7A89C0]


def test_every_single_bit_error_fails_parity():
    rng = np.random.default_rng(1)
    for _ in range(300):
        d24, prev = int(rng.integers(1 << 24)), int(rng.integers(1 << 30))
        w = L.encode_word(d24, prev)
        assert L.check_word(w, prev) == d24
        for k in range(30):                      # a flipped bit of the word
            assert L.check_word(w ^ (1 << k), prev) is None
        for k in range(2):                       # a flipped D29* or D30*
            assert L.check_word(w, prev ^ (1 << k)) is None


def test_every_error_of_up_to_three_bits_fails_parity():
    # Over the 32-bit window (D29*, D30*, D1..D30) the code's minimum distance is 4.
    rng = np.random.default_rng(5)
    for _ in range(4):
        d24, prev = int(rng.integers(1 << 24)), int(rng.integers(1 << 30))
        w = L.encode_word(d24, prev)
        for k in (2, 3):
            for pos in itertools.combinations(range(32), k):
                ww, pp = w, prev
                for b in pos:
                    if b < 30:
                        ww ^= 1 << b
                    else:
                        pp ^= 1 << (b - 30)
                assert L.check_word(ww, pp) is None, pos


def test_data_complemented_after_d30_and_t_bits_zero_d29_d30():
    rng = np.random.default_rng(2)
    for _ in range(200):
        d24 = int(rng.integers(1 << 24))
        w0, w1 = L.encode_word(d24, 0b00), L.encode_word(d24, 0b01)
        assert w1 >> 6 == (w0 >> 6) ^ 0xFFFFFF
        w = L.encode_word_solved(d24 >> 2, int(rng.integers(1 << 30)))
        assert w & 0b11 == 0


# --- field positions (Figure 20-1) ---------------------------------------------------------

def _data_bits(bits, sf, word):
    """Source data bits d1..d24 of word ``word`` (1..10) of subframe ``sf`` (0-based index)."""
    i = sf * 300 + (word - 1) * 30
    prev = bits[i - 1] if i else 0
    return bits[i:i + 24] ^ prev


def _uint(b):
    return int("".join(map(str, b)), 2)


def test_field_positions(navs):
    e = navs[0].ephemerides[0]
    bits = L.encode_frames(e, navs[0].iono, e.week, 259200.0 - 600.0, 1, utc=UTC)
    for sf in range(5):
        assert _uint(bits[sf * 300: sf * 300 + 8]) == 0b10001011               # preamble
        how = _data_bits(bits, sf, 2)
        assert _uint(how[:17]) == (259200 - 600) // 6 + sf + 1                 # next TOW count
        assert _uint(how[19:22]) == sf + 1                                     # subframe ID
    w3 = _data_bits(bits, 0, 3)
    assert _uint(w3[:10]) == 1865 % 1024 and _uint(w3[12:16]) == e.ura_index
    assert _uint(w3[22:24]) == e.IODC >> 8 and _uint(_data_bits(bits, 0, 8)[:8]) == e.IODC & 255
    assert _uint(_data_bits(bits, 0, 8)[8:24]) * 16 == e.toc
    assert _uint(_data_bits(bits, 1, 3)[:8]) == e.IODE
    assert _uint(_data_bits(bits, 1, 10)[:16]) * 16 == e.toe
    sqrt_a = _uint(np.r_[_data_bits(bits, 1, 8)[16:], _data_bits(bits, 1, 9)])
    assert sqrt_a * 2.0 ** -19 == pytest.approx(e.sqrtA, abs=2.0 ** -20)
    assert _uint(_data_bits(bits, 2, 10)[:8]) == e.IODE
    p18 = _data_bits(bits, 3, 3)
    assert _uint(p18[:2]) == 1 and _uint(p18[2:8]) == 56                       # data ID, page 18
    assert _uint(_data_bits(bits, 4, 3)[2:8]) == 51                            # page 25


# --- round trip --------------------------------------------------------------------------

def test_round_trip_every_ephemeris_of_the_files(navs):
    n = 0
    for nav in navs:
        for e in nav.ephemerides:
            bits = L.encode_frames(e, nav.iono, e.week, _frame_start(e), 1, utc=UTC)
            r = decode_lnav(bits, e.prn, reference_week=e.week + 300)
            assert r.withheld is None and r.parity_failures == ()
            assert r.ephemeris == e.quantised()
            assert r.iono == nav.iono.quantised() and r.utc == UTC.quantised()
            assert r.sv_health == (0,) * 24
            n += 1
    assert n == 422


def test_quantised_is_idempotent_and_close(navs):
    for e in navs[0].ephemerides[:40]:
        q = e.quantised()
        assert q.quantised() == q
        assert abs(q.M0 - e.M0) <= 2.0 ** -32 * 3.1415926535898
        assert abs(q.sqrtA - e.sqrtA) <= 2.0 ** -20


@pytest.mark.parametrize("inverted", [False, True])
@pytest.mark.parametrize("soft", [False, True])
def test_sync_at_any_offset_and_polarity(navs, inverted, soft):
    rng = np.random.default_rng(3 + inverted + 2 * soft)
    e = navs[1].ephemerides[1]
    bits = L.encode_frames(e, navs[1].iono, e.week, _frame_start(e), 2, sv_health=range(24))
    cut = int(rng.integers(1, 300))
    x = bits[cut:] ^ np.uint8(inverted)
    if soft:
        x = (1.0 - 2.0 * x) * rng.uniform(0.2, 3.0, x.size)     # BPSK with varying amplitude
    r = decode_lnav(x, e.prn, reference_week=2048)
    assert r.sync_bit == 300 - cut and r.inverted == inverted
    assert r.ephemeris == e.quantised() and r.sv_health == tuple(range(24))
    assert len(r.subframes) == 9 and r.parity_failures == ()


def test_utc_absent_is_sent_as_zeros(navs):
    e = navs[1].ephemerides[0]
    r = decode_lnav(L.encode_frames(e, navs[1].iono, e.week, _frame_start(e), 1), 5,
                    reference_week=2106)
    assert r.utc == UtcParameters(0.0, 0.0, 0.0, 0, 0, 0, 0, 0)


def test_week_resolution_and_crossover(navs):
    e = replace(navs[1].ephemerides[0], toe=0.0, toc=0.0)   # toe at the start of week 2106
    # sent from the last 90 s of week 2105 on, across the week's end
    bits = L.encode_frames(e, navs[1].iono, 2105, 604800.0 - 90.0, 4)
    for ref in (2106 - 511, 2106, 2106 + 500):
        r = decode_lnav(bits, 5, reference_week=ref)
        assert r.ephemeris == e.quantised() and r.ephemeris.week == 2106
    tows = [sf.tow_start for sf in r.subframes]
    assert tows[:5] == [604710.0, 604716.0, 604722.0, 604728.0, 604734.0]
    assert tows[15:] == [0.0, 6.0, 12.0, 18.0, 24.0]


# --- errors ------------------------------------------------------------------------------

def _corrupt_word(bits, sf_index, word):
    out = bits.copy()
    out[sf_index * 300 + (word - 1) * 30 + 5] ^= 1
    return out


def test_a_failed_word_is_reported_and_its_subframe_replaced(navs):
    e = navs[0].ephemerides[10]
    bits = L.encode_frames(e, navs[0].iono, e.week, _frame_start(e), 2)
    bad = _corrupt_word(bits, 1, 5)                  # subframe 2 of frame 1, word 5 (M0)
    r = decode_lnav(bad, e.prn, reference_week=e.week)
    assert [(f.bit_index, f.subframe_id, f.word) for f in r.parity_failures] == \
        [(300 + 4 * 30, 2, 5)]
    assert r.rejected_subframes == 1 and r.ephemeris == e.quantised()
    only_one = decode_lnav(bad[:1500], e.prn, reference_week=e.week)
    assert only_one.ephemeris is None and only_one.withheld == "no parity-clean subframe 2"


def test_never_a_mixed_data_set(navs):
    e = navs[0].ephemerides[10]
    e2 = replace(e, IODE=(e.IODE + 1) % 256, IODC=(e.IODC + 1) % 1024, M0=e.M0 + 0.01)
    t0 = _frame_start(e)
    bits = np.r_[L.encode_frames(e, navs[0].iono, e.week, t0, 1),
                 L.encode_frames(e2, navs[0].iono, e.week, t0 + 30, 1, prev_bits=(0, 0))]
    r = decode_lnav(_corrupt_word(bits, 6, 4), e.prn, reference_week=e.week)  # e2's subframe 2
    assert r.ephemeris == e.quantised()           # e2's 1 and 3 with e's 2 do not mix
    r = decode_lnav(bits, e.prn, reference_week=e.week)
    assert r.ephemeris == e2.quantised()


def test_random_bit_errors_never_use_a_failed_word(navs):
    # Seeded bit errors at several rates: the decoder never returns a wrong ephemeris
    # (either the transmitted one or none), every word with an odd number of errors in
    # its 32-bit parity window is reported, and no reported-clean word differs from the
    # transmitted one at these rates.
    e = navs[0].ephemerides[100]
    truth = e.quantised()
    bits = L.encode_frames(e, navs[0].iono, e.week, _frame_start(e), 2)
    counts = {}
    for ber in (1e-3, 3e-3, 1e-2, 3e-2):
        rng = np.random.default_rng(int(ber * 1e5))
        ok = withheld = missed_single = undetected = no_sync = 0
        for _ in range(60):
            flips = (rng.random(bits.size) < ber).astype(np.uint8)
            r = decode_lnav(bits ^ flips, e.prn, reference_week=e.week)
            if r.ephemeris is None:
                withheld += 1
            else:
                assert r.ephemeris == truth
                ok += 1
            if r.sync_bit is None:
                no_sync += 1
                continue
            failed = {f.bit_index for f in r.parity_failures}
            for i in range(r.sync_bit, bits.size - 29, 30):
                window = flips[max(i - 2, 0):i + 30]
                if window.sum() % 2 == 1 and i not in failed:
                    missed_single += 1
            for sf in r.subframes:
                for w in range(10):
                    i = sf.bit_index + 30 * w
                    # the code's distance is 4: an undetected pattern has 4 errors or more
                    assert not flips[i:i + 30].any() or flips[max(i - 2, 0):i + 30].sum() >= 4
                    undetected += int(flips[i:i + 30].any())
        assert missed_single == 0 and undetected == 0
        counts[ber] = (ok, withheld, no_sync)
    print("LNAV decode under bit errors (decoded, withheld, of which no sync; 60 two-frame "
          "streams):", counts)
    assert counts[1e-3][0] >= 50 and counts[3e-2][1] >= 50


def test_bad_input_is_named(navs):
    e = navs[1].ephemerides[0]
    with pytest.raises(ValueError, match=r"tow = 15.0 is not a frame start"):
        L.encode_frames(e, navs[1].iono, e.week, 15.0)
    with pytest.raises(ValueError, match=r"LNAV G05: af0 = 0.01 is outside the 22-bit LNAV "
                                         r"field"):
        L.encode_frames(replace(e, af0=0.01), navs[1].iono, e.week, 0.0)
    with pytest.raises(ValueError, match=r"LNAV ionosphere: beta0 = 10000000.0 is outside"):
        L.encode_frames(e, KlobucharParameters((0, 0, 0, 0), (1e7, 0, 0, 0)), e.week, 0.0)
    with pytest.raises(ValueError, match=r"symbols\[2\] = 0.0: a soft value must be finite"):
        hard_bits(np.array([1.0, -1.0, 0.0]))
    with pytest.raises(ValueError, match=r"reference_week = -1 is not a GPS week"):
        decode_lnav(np.ones(10), 5, reference_week=-1)
    assert np.array_equal(hard_bits(np.array([1, -1, -1])), [0, 1, 1])
    r = decode_lnav(np.random.default_rng(4).integers(0, 2, 3000), 5, reference_week=2106)
    assert r.sync_bit is None and r.ephemeris is None and r.withheld == "no frame sync"
