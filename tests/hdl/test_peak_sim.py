"""Pulse-peak search, Amaranth simulation == bit-exact model: realistic envelopes, parameter
variants, gaps in valid, pulses across block boundaries, ties, max_len cuts, reset mid-run
and the pair-partner readout."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cosim.backends.pysim import run_stream, unpack_fields
from dsp.tacan.peak_params import PeakParams
from hdl.tacan.peak_model import peak_search
from dsp.tacan.peak import peak_search_float, peak_search_numpy
from hdl.tacan.peak import PeakSearch

from _util import WithClear
from _peak_util import SMALL, as_tuples, check_sim, realistic_envelope, reference_loop, run_sim  # tests/hdl, on sys.path: conftest.py


# -- simulation == model -------------------------------------------------------------------
@pytest.mark.slow
def test_sim_matches_model_realistic_1e5():
    p = PeakParams()
    rng = np.random.default_rng(201)
    e = realistic_envelope(rng, 100_000)
    e[60_000:60_700] = 2500  # a continuous carrier (max_len cuts)
    ref = check_sim(p, e)
    assert ref.amplitude.size > 1000


def test_sim_matches_model_realistic_quick():
    p = PeakParams(block_log2=8)
    rng = np.random.default_rng(200)
    e = realistic_envelope(rng, 15_000)
    e[9_000:9_300] = 2500
    ref = check_sim(p, e)
    assert ref.amplitude.size > 100


@pytest.mark.parametrize("kw", [
    dict(block_log2=2, hold=1, max_len=2),
    dict(block_log2=3, hold=2, max_len=7, ts_bits=8, ts_step=5),   # timestamp wraps
    dict(block_log2=6, smooth_log2=0, clip_log2=0, thr_mult=5, thr_frac=0),
    dict(block_log2=4, smooth_log2=5, clip_log2=3, thr_min=900, amp_width=12),
    dict(block_log2=5, smooth_log2=3, clip_to_floor=True, thr_mult=52),  # censored floor
    dict(block_log2=5, hold=3, max_len=24, partner_offset=7),            # pair partner
    dict(block_log2=3, hold=2, max_len=7, partner_offset=1),
    dict(block_log2=5, hold=3, max_len=24, pair_offset=7),               # pair detection
    dict(block_log2=3, hold=2, max_len=7, pair_offset=1),
    dict(block_log2=4, smooth_log2=5, clip_log2=3, thr_min=900, amp_width=12, pair_offset=20),
    # the floor with fraction bits (floor_frac)
    dict(block_log2=2, hold=1, max_len=2, floor_frac=True),
    dict(block_log2=6, smooth_log2=0, clip_log2=0, thr_mult=5, thr_frac=0, floor_frac=True),
    dict(block_log2=4, smooth_log2=5, clip_log2=3, thr_min=900, amp_width=12, floor_frac=True),
    dict(block_log2=5, smooth_log2=3, clip_to_floor=True, thr_mult=52, floor_frac=True),
    dict(block_log2=3, smooth_log2=16, hold=2, max_len=7, floor_frac=True),
    dict(block_log2=5, hold=3, max_len=24, smooth_log2=6, pair_offset=7, floor_frac=True),
    dict(block_log2=4, smooth_log2=5, clip_log2=3, thr_min=900, amp_width=12, pair_offset=20,
         floor_frac=True),
])
def test_sim_matches_model_variants(kw):
    p = PeakParams(**kw)
    rng = np.random.default_rng(202)
    e = realistic_envelope(rng, 8000, amp_width=p.amp_width)
    e[3000:3300] = min(3000, (1 << p.amp_width) - 1)
    ref = check_sim(p, e)
    if p.floor_frac and p.smooth_log2:   # the option changes the floor here
        plain, _ = peak_search(e, replace(p, floor_frac=False))
        assert not np.array_equal(ref.thresholds, plain.thresholds)


def test_hdl_needs_two_bits_of_block():
    """The HDL defers a block's first two samples (the new floor is not in place for them):
    block_log2 = 1 is the model's only, refused with the reason."""
    for p in (PeakParams(block_log2=1, hold=1, max_len=2),
              PeakParams(block_log2=1, hold=1, max_len=2, pair_offset=3)):
        with pytest.raises(ValueError, match=r"PeakSearch needs peak block_log2 >= 2 .*not 1"):
            PeakSearch(p)
    peak_search(np.arange(50), PeakParams(block_log2=1, hold=1, max_len=2))   # the model runs


def test_gaps_in_valid():
    rng = np.random.default_rng(203)
    e = realistic_envelope(rng, 3000)
    valid = rng.random(9000) < 0.35
    check_sim(SMALL, e, valid)
    # Bursty valid too: long gaps, then back to back.
    valid = np.repeat(rng.random(900) < 0.5, 10)
    check_sim(SMALL, e, valid)


def test_gaps_in_valid_ignore_the_idle_payload():
    """A payload without valid is not a sample: the top of the input range on those cycles
    changes nothing (the plain search's input register takes the payload on every cycle)."""
    rng = np.random.default_rng(216)
    e = realistic_envelope(rng, 3000)
    for p in (SMALL, replace(SMALL, smooth_log2=5, floor_frac=True),
              replace(SMALL, partner_offset=12), replace(SMALL, pair_offset=7)):
        check_sim(p, e, rng.random(9000) < 0.35, idle_payload=(1 << p.amp_width) - 1)


def test_gaps_in_valid_with_floor_frac():
    rng = np.random.default_rng(206)
    e = realistic_envelope(rng, 3000)
    for p in (replace(SMALL, smooth_log2=5, floor_frac=True),
              PeakParams(block_log2=2, hold=1, max_len=2, smooth_log2=3, floor_frac=True)):
        check_sim(p, e, rng.random(9000) < 0.35)
        check_sim(p, e, np.repeat(rng.random(900) < 0.5, 10))


def test_gaps_in_valid_with_partner_readout():
    rng = np.random.default_rng(213)
    e = realistic_envelope(rng, 3000)
    p = PeakParams(block_log2=5, hold=3, max_len=24, partner_offset=12)
    ref = check_sim(p, e, rng.random(9000) < 0.35)
    check_sim(p, e, np.repeat(rng.random(900) < 0.5, 10))
    assert ref.partner_late.any() and not ref.partner_late.all()


def test_pulse_spanning_block_boundary():
    p = SMALL
    L = p.block_len
    e = np.full(4 * L, 100, dtype=np.int64)
    # Block 2 gets a higher floor (threshold) than block 1; the pulse straddles the
    # boundary, peaks after it and its tail is below block 2's threshold but above block 1's.
    e[L:2 * L] = 100
    e[2 * L - 4:2 * L] = [400, 500, 600, 700]
    e[2 * L:2 * L + 6] = [800, 900, 650, 320, 310, 305]
    ref = check_sim(p, e)
    assert as_tuples(ref) == reference_loop(e, p)
    assert ref.index[0] == 2 * L + 1 and ref.end_index[0] >= 2 * L


@pytest.mark.parametrize("thr_mult, thr_frac, thr_min", [(48, 4, 16), (91, 5, 50), (5, 0, 33)])
def test_threshold_at_the_thr_min_boundary(thr_mult, thr_frac, thr_min):
    """The HDL takes ``thr_min`` when ``nu < ceil((thr_min << thr_frac) / thr_mult)`` (a
    registered flag beside the partial products); floors ``c - 2 .. c + 1`` around that
    bound, each followed by a block of probes between the thresholds on either side of it."""
    p = PeakParams(block_log2=5, smooth_log2=0, clip_log2=8, hold=1, max_len=2,
                   thr_mult=thr_mult, thr_frac=thr_frac, thr_min=thr_min)
    L = p.block_len
    c = -(-(thr_min << thr_frac) // thr_mult)
    probes = list(range((((c - 1) * thr_mult) >> thr_frac) - 1, ((c * thr_mult) >> thr_frac) + 2))
    assert 2 * len(probes) < L and ((c - 1) * thr_mult) >> thr_frac < thr_min
    blocks, expected = [], 0
    for v in (c, c - 2, c - 1, c, c + 1, c - 1, c):
        assert v < thr_min            # the floor's own block stays below its threshold
        probe = np.full(L, v)
        probe[1:2 * len(probes):2] = probes
        blocks += [np.full(L, v), probe]
        expected += sum(x >= p.threshold(v) for x in probes)
    e = np.concatenate(blocks).astype(np.int64)
    ref = check_sim(p, e)
    assert as_tuples(ref) == reference_loop(e, p)
    assert ref.amplitude.size == expected


def test_tie_first_occurrence_wins():
    p = SMALL
    L = p.block_len
    e = np.full(3 * L, 50, dtype=np.int64)
    e[L + 5:L + 12] = [300, 700, 700, 700, 650, 700, 200]
    ref = check_sim(p, e)
    assert ref.amplitude.tolist() == [700]
    assert ref.index.tolist() == [L + 6]
    assert ref.timestamp.tolist() == [(L + 6) * p.ts_step]


def test_max_len_cut_on_carrier():
    p = SMALL
    L = p.block_len
    e = np.full(8 * L, 60, dtype=np.int64)
    start = 2 * L + 3
    e[start:start + 3 * p.max_len + 5] = 1000
    ref = check_sim(p, e)
    # Cut every max_len samples; the cutting sample is consumed, the next one reopens.
    starts = start + np.arange(3) * p.max_len
    np.testing.assert_array_equal(ref.index[:3], starts)
    np.testing.assert_array_equal(ref.end_index[:3], starts + p.max_len - 1)
    assert ref.amplitude.size == 4


def test_reset_mid_run():
    p = SMALL
    rng = np.random.default_rng(204)
    e1 = realistic_envelope(rng, 700)
    e1[-40:] = 10  # quiet end: no pulse open when the clear comes
    e2 = realistic_envelope(rng, 900)
    ref1, st1 = peak_search(e1, p)
    assert not st1.open
    ref2, _ = peak_search(e2, p)
    valid = np.concatenate((np.ones(e1.size, bool), np.zeros(30, bool)))
    c = e1.size + 15
    dut = WithClear(PeakSearch(p))
    _, amp, ts = run_sim(p, np.concatenate((e1, e2)), valid, dut=dut,
                          writes=[(c, dut.clear, 1), (c + 1, dut.clear, 0)])
    np.testing.assert_array_equal(amp, np.concatenate((ref1.amplitude, ref2.amplitude)))
    np.testing.assert_array_equal(ts, np.concatenate((ref1.timestamp, ref2.timestamp)))


@pytest.mark.parametrize("D", [5, 40])
def test_reset_mid_run_with_partner_readout(D):
    """After a clear the delay line's old words are not behind values: 0 until 2D new
    samples are in (the memory itself is not reset)."""
    p = PeakParams(block_log2=5, hold=3, max_len=24, partner_offset=D)
    rng = np.random.default_rng(214)
    e1 = realistic_envelope(rng, 700)
    e1[-40 - 2 * D:] = 150  # no pulse open when the clear comes; these stay in the memory
    e2 = realistic_envelope(rng, 900)
    e2[33:36] = 3000        # a pulse in the first block after the clear, whose behind
    e2[36:36 + 2 * D] = 5   # value (D = 40: before the clear) must read 0, not 150
    ref1, st1 = peak_search(e1, p)
    assert not st1.open
    ref2, _ = peak_search(e2, p)
    valid = np.concatenate((np.ones(e1.size, bool), np.zeros(30, bool)))
    c = e1.size + 15
    dut = WithClear(PeakSearch(p))
    res = run_stream(dut, np.concatenate((e1, e2)), in_valid=valid, flush_cycles=p.latency + 2,
                     writes=[(c, dut.clear, 1), (c + 1, dut.clear, 0)])
    f = unpack_fields(res.words, p.out_layout)
    for k in ("amplitude", "timestamp", "partner", "partner_late"):
        np.testing.assert_array_equal(f[k], np.concatenate((getattr(ref1, k), getattr(ref2, k))))


@pytest.mark.parametrize("D, kw", [(60, {}), (3, dict(block_log2=3, hold=2, max_len=7)),
                                   (150, dict(block_log2=6, clip_to_floor=True))])
def test_partner_readout_model(D, kw):
    """The pulses are those of the search without the readout (less the ones whose sample
    D later has not arrived); partner = max(e[n_max + D], e[n_max - D]) (0 before the
    start); the compiled and the numpy models agree, in one run and in chunks."""
    p = PeakParams(partner_offset=D, **kw)
    e = realistic_envelope(np.random.default_rng(215), 30_000)
    e[9000:9500] = 4000
    r, _ = peak_search(e, p)
    plain, _ = peak_search(e, PeakParams(**kw))
    done = plain.end_index + D < e.size
    np.testing.assert_array_equal(r.amplitude, plain.amplitude[done])
    np.testing.assert_array_equal(r.index, plain.index[done])
    ahead = np.concatenate([e, np.zeros(D, e.dtype)])[r.index + D]
    behind = np.concatenate([np.zeros(D, e.dtype), e])[r.index]
    np.testing.assert_array_equal(r.partner, np.maximum(ahead, behind))
    np.testing.assert_array_equal(r.partner_late, ahead >= behind)
    cuts = np.sort(np.random.default_rng(216).integers(0, e.size, 40))
    for fn in (peak_search, peak_search_numpy):
        st, parts = None, []
        for c0, c1 in zip(np.r_[0, cuts], np.r_[cuts, e.size]):
            rr, st = fn(e[c0:c1], p, st)
            parts.append(rr)
        for k in ("amplitude", "index", "end_index", "partner", "partner_late"):
            np.testing.assert_array_equal(np.concatenate([getattr(x, k) for x in parts]),
                                          getattr(r, k), err_msg=f"{fn.__name__} {k}")
    f, _ = peak_search_float(e.astype(np.float64), p)
    assert f.partner.size and np.all(f.partner >= 0)
