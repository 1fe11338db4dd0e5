"""Pulse-peak search: Amaranth sim == bit-exact model, model == per-sample reference, corners;
the exported Verilog (Verilator) == Amaranth simulation == model."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from amaranth.hdl import Fragment, Shape, unsigned

from cosim.pysim import run_stream, unpack_fields
from dsp.tacan.peak import peak_search_float, peak_search_numpy
from dsp.tacan.peak_params import PeakParams, PeakState
from hdl.tacan.peak_model import peak_search
from hdl.tacan.peak import PeakSearch

from _util import (WithClear, accepted_cycles, assert_lints_clean, assert_same_stream,
                   needs_verilator, verilator_sim)


# -- helpers -------------------------------------------------------------------------------
def realistic_envelope(rng, n, *, noise=200.0, width=10.0, min_gap=21, max_gap=150,
                       amp_range=(2.0, 20.0), amp_width=19, pair_offset=0, single=0.0):
    """Rayleigh noise (mean ``noise``) plus Gaussian pulses (FWHM ``width`` samples) at
    random spacing > 20 samples with amplitudes 2..20 times the noise mean.

    ``pair_offset = D``: each pulse gets a partner ``D`` samples later (its own random
    amplitude, so either pulse of a pair may be the larger), except a fraction ``single``
    of them, left alone."""
    mean_to_sigma = 1.0 / np.sqrt(np.pi / 2)
    e = rng.rayleigh(noise * mean_to_sigma, n)
    centres = np.cumsum(rng.integers(min_gap, max_gap, n // min_gap + 1))
    centres = centres[centres < n]
    amps = rng.uniform(*amp_range, centres.size) * noise
    if pair_offset:
        paired = rng.random(centres.size) >= single
        second = centres[paired] + pair_offset
        centres = np.concatenate((centres, second))
        amps = np.concatenate((amps, rng.uniform(*amp_range, second.size) * noise))
    sigma = width / (2 * np.sqrt(2 * np.log(2)))
    k = np.arange(-4 * int(sigma + 1), 4 * int(sigma + 1) + 1)
    shape = np.exp(-0.5 * (k / sigma) ** 2)
    for c, a in zip(centres, amps):
        idx = c + k
        ok = (idx >= 0) & (idx < n)
        e[idx[ok]] += a * shape[ok]
    return np.minimum(np.round(e), (1 << amp_width) - 1).astype(np.int64)


def reference_loop(e, p, *, is_float=False, thr_min=None):
    """Straight per-sample transcription of the algorithm (independent of the model)."""
    L = p.block_len
    out = []
    nu, bsum = 0, 0
    F = 0                 # floor_frac: the floor with smooth_log2 fraction bits
    is_open, pmax, nmax, below, length = False, 0, 0, 0, 0
    tm = p.thr_min if thr_min is None else thr_min
    for n, x in enumerate(e):
        x = float(x) if is_float else int(x)
        b = n // L
        if b == 0:
            T = float("inf")
            bsum += x
        elif is_float:
            T = max(tm, nu * p.thr_mult / 2 ** p.thr_frac)
            clip = nu * 2 ** p.clip_log2
            bsum += x if x <= clip else (nu if p.clip_to_floor else clip)
        else:
            T = max(p.thr_min, (nu * p.thr_mult) >> p.thr_frac)
            clip = nu << p.clip_log2
            bsum += x if x <= clip else (nu if p.clip_to_floor else clip)
        if (n + 1) % L == 0:
            if is_float:
                m = bsum / L
                nu = m if b == 0 else nu + (m - nu) / 2 ** p.smooth_log2
            else:
                m = bsum >> p.block_log2
                if p.floor_frac:
                    F = m * 2 ** p.smooth_log2 if b == 0 else F - F // 2 ** p.smooth_log2 + m
                    nu = F // 2 ** p.smooth_log2
                else:
                    nu = m if b == 0 else nu + ((m - nu) >> p.smooth_log2)
            bsum = 0
        if not is_open:
            if x >= T:
                is_open, pmax, nmax, below, length = True, x, n, 0, 1
        else:
            if x > pmax:
                pmax, nmax = x, n
            below = 0 if x >= T else below + 1
            length += 1
            if below == p.hold or length == p.max_len:
                out.append((pmax, nmax, n))
                is_open = False
    return out


def _as_tuples(r):
    return list(zip(r.amplitude.tolist(), r.index.tolist(), r.end_index.tolist()))


def _run_sim(p, e, in_valid=None, dut=None, **kw):
    res = run_stream(dut if dut is not None else PeakSearch(p), e, in_valid=in_valid,
                     flush_cycles=p.latency + 2, **kw)
    f = unpack_fields(res.words, p.out_layout)
    return res, f["amplitude"], f["timestamp"]


def _check_sim(p, e, in_valid=None):
    res = run_stream(PeakSearch(p), e, in_valid=in_valid, flush_cycles=p.latency + 2)
    f = unpack_fields(res.words, p.out_layout)
    ref, _ = peak_search(e, p)
    np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
    np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
    if p.partner_offset:
        np.testing.assert_array_equal(f["partner"], ref.partner)
        np.testing.assert_array_equal(f["partner_late"], ref.partner_late)
    # Emitted params.latency cycles after the input transfer of the closing sample (of the
    # sample emit_delay later with the pair-partner readout or the pair detection).
    in_cycles = np.arange(e.size) if in_valid is None else np.flatnonzero(in_valid)[:e.size]
    np.testing.assert_array_equal(res.cycles,
                                  in_cycles[ref.end_index + p.emit_delay] + p.latency)
    return ref


SMALL = PeakParams(block_log2=5, hold=3, max_len=24)


# -- simulation == model -------------------------------------------------------------------
@pytest.mark.slow
def test_sim_matches_model_realistic_1e5():
    p = PeakParams()
    rng = np.random.default_rng(201)
    e = realistic_envelope(rng, 100_000)
    e[60_000:60_700] = 2500  # a continuous carrier (max_len cuts)
    ref = _check_sim(p, e)
    assert ref.amplitude.size > 1000


def test_sim_matches_model_realistic_quick():
    p = PeakParams(block_log2=8)
    rng = np.random.default_rng(200)
    e = realistic_envelope(rng, 15_000)
    e[9_000:9_300] = 2500
    ref = _check_sim(p, e)
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
    ref = _check_sim(p, e)
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
    _check_sim(SMALL, e, valid)
    # Bursty valid too: long gaps, then back to back.
    valid = np.repeat(rng.random(900) < 0.5, 10)
    _check_sim(SMALL, e, valid)


def test_gaps_in_valid_with_floor_frac():
    rng = np.random.default_rng(206)
    e = realistic_envelope(rng, 3000)
    for p in (replace(SMALL, smooth_log2=5, floor_frac=True),
              PeakParams(block_log2=2, hold=1, max_len=2, smooth_log2=3, floor_frac=True)):
        _check_sim(p, e, rng.random(9000) < 0.35)
        _check_sim(p, e, np.repeat(rng.random(900) < 0.5, 10))


def test_gaps_in_valid_with_partner_readout():
    rng = np.random.default_rng(213)
    e = realistic_envelope(rng, 3000)
    p = PeakParams(block_log2=5, hold=3, max_len=24, partner_offset=12)
    ref = _check_sim(p, e, rng.random(9000) < 0.35)
    _check_sim(p, e, np.repeat(rng.random(900) < 0.5, 10))
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
    ref = _check_sim(p, e)
    assert _as_tuples(ref) == reference_loop(e, p)
    assert ref.index[0] == 2 * L + 1 and ref.end_index[0] >= 2 * L


def test_tie_first_occurrence_wins():
    p = SMALL
    L = p.block_len
    e = np.full(3 * L, 50, dtype=np.int64)
    e[L + 5:L + 12] = [300, 700, 700, 700, 650, 700, 200]
    ref = _check_sim(p, e)
    assert ref.amplitude.tolist() == [700]
    assert ref.index.tolist() == [L + 6]
    assert ref.timestamp.tolist() == [(L + 6) * p.ts_step]


def test_max_len_cut_on_carrier():
    p = SMALL
    L = p.block_len
    e = np.full(8 * L, 60, dtype=np.int64)
    start = 2 * L + 3
    e[start:start + 3 * p.max_len + 5] = 1000
    ref = _check_sim(p, e)
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
    _, amp, ts = _run_sim(p, np.concatenate((e1, e2)), valid, dut=dut,
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


# -- pulse-pair detection ------------------------------------------------------------------
def pair_sum(e, D):
    """``s[n] = e[n] + e[n - D]`` (``e`` = 0 before the first sample)."""
    e = np.asarray(e)
    return e + np.concatenate((np.zeros(D, e.dtype), e))[:e.size]


def pair_reference(e, p, *, is_float=False, thr_min=None):
    """Brute-force pair detection, independent of the model: :func:`reference_loop` on the
    pair sum with ``p.search_params``, then per pulse: emitted once sample ``end + D`` is in;
    kept iff ``8 s[n_max] >= pair_keep * max(s[n_max - D], s[n_max + D])`` (0 before the
    start); amplitude ``s >> 1`` (float: ``s / 2``). Returns the kept and the dropped pulses as
    ``(amplitude, n_max, end)``."""
    D = p.pair_offset
    s = pair_sum(np.asarray(e, np.float64 if is_float else np.int64), D)
    kept, dropped = [], []
    for pmax, nmax, end in reference_loop(s, p.search_params, is_float=is_float, thr_min=thr_min):
        if end + D >= len(s):
            continue                      # not emitted yet: its sample end + D has not arrived
        assert pmax == s[nmax]
        behind = s[nmax - D] if nmax >= D else 0
        ahead = s[nmax + D]
        amp = pmax / 2 if is_float else int(pmax) >> 1
        (kept if 8 * pmax >= p.pair_keep * max(behind, ahead) else dropped).append(
            (amp, nmax, end))
    return kept, dropped


def pair_envelope(rng, n, D, **kw):
    """:func:`realistic_envelope` with pulse pairs ``D`` apart (a quarter of them single
    pulses), spaced so that most pairs stand apart and some overlap; a carrier (max_len
    cuts) and a stretch at the top of the input range."""
    aw = kw.pop("amp_width", 19)
    e = realistic_envelope(rng, n, pair_offset=D, single=0.25, min_gap=21 + D,
                           max_gap=150 + 2 * D, amp_width=aw, **kw)
    e[n // 3:n // 3 + 500] = min(4000, (1 << aw) - 1)
    e[n // 2:n // 2 + 50] = (1 << aw) - 1
    return e


#: TACAN X mode at 5 MHz envelope samples (12 us = 60 samples), the censored floor.
TACAN_X_PAIR = PeakParams(pair_offset=60, clip_to_floor=True, smooth_log2=10, thr_mult=46)

PAIR_SETS = [TACAN_X_PAIR,
             PeakParams(pair_offset=1, block_log2=3, hold=2, max_len=7),
             PeakParams(pair_offset=7, block_log2=5, hold=3, max_len=24),
             PeakParams(pair_offset=150, block_log2=6, clip_log2=0, thr_mult=40),
             PeakParams(pair_offset=300, block_log2=4, max_len=20, ts_bits=10, amp_width=14),
             replace(TACAN_X_PAIR, floor_frac=True),
             PeakParams(pair_offset=7, block_log2=5, hold=3, max_len=24, smooth_log2=5,
                        floor_frac=True)]


@pytest.mark.parametrize("k", range(len(PAIR_SETS)))
def test_pair_model_matches_reference(k):
    """Compiled model == numpy model == the brute-force reference (pulses, timestamps,
    thresholds, state); the side-lobe rule both drops and keeps pulses here."""
    p = PAIR_SETS[k]
    e = pair_envelope(np.random.default_rng(270 + k), 30_000, p.pair_offset, amp_width=p.amp_width)
    r, st = peak_search(e, p)
    rn, st_n = peak_search_numpy(e, p)
    for name in ("amplitude", "timestamp", "index", "end_index", "thresholds"):
        np.testing.assert_array_equal(getattr(r, name), getattr(rn, name), err_msg=name)
    assert st == st_n
    kept, dropped = pair_reference(e, p)
    assert _as_tuples(r) == kept
    np.testing.assert_array_equal(r.timestamp, (r.index * p.ts_step) & ((1 << p.ts_bits) - 1))
    assert r.amplitude.max() < 1 << p.amp_width
    assert len(kept) > 50 and len(dropped) > 10, (len(kept), len(dropped))


@pytest.mark.parametrize("k", range(len(PAIR_SETS)))
def test_pair_model_chunked_equals_one_run(k):
    """Chunked runs (cuts inside pulses, within D of each other, 1-sample and empty chunks)
    == one run, for the compiled and the numpy model, whose states agree after every chunk."""
    p = PAIR_SETS[k]
    D = p.pair_offset
    rng = np.random.default_rng(280 + k)
    e = pair_envelope(rng, 30_000, D, amp_width=p.amp_width)
    whole, st_whole = peak_search(e, p)
    cuts = np.unique(np.clip(np.concatenate((
        whole.index[::5] + 1, whole.index[2::7] + D, rng.integers(0, e.size, 30),
        [0, 1, 1, 2, D - 1, D, D + 1, 2 * D + 3, 10_000, 10_001, 10_000 + D])), 0, e.size))
    st_a = st_b = None
    parts = []
    prev = 0
    for c in list(cuts) + [e.size, e.size]:
        ra, st_a = peak_search(e[prev:c], p, st_a)
        rb, st_b = peak_search_numpy(e[prev:c], p, st_b)
        for name in ("amplitude", "timestamp", "index", "end_index"):
            np.testing.assert_array_equal(getattr(ra, name), getattr(rb, name))
        assert st_a == st_b
        parts.append(ra)
        prev = c
    for name in ("amplitude", "timestamp", "index", "end_index"):
        np.testing.assert_array_equal(np.concatenate([getattr(r, name) for r in parts]),
                                      getattr(whole, name), err_msg=name)
    assert st_a == st_whole


@pytest.mark.parametrize("k", range(len(PAIR_SETS)))
def test_pair_float_variant_matches_reference(k):
    p = PAIR_SETS[k]
    rng = np.random.default_rng(290 + k)
    e = pair_envelope(rng, 10_000, p.pair_offset) * 1e-3 + rng.random(10_000) * 1e-4
    r, _ = peak_search_float(e, p, thr_min=0.03)
    kept, dropped = pair_reference(e, p, is_float=True, thr_min=0.03)
    got = np.array(_as_tuples(r))
    exp = np.array(kept)
    assert got.shape == exp.shape and len(kept) > 10 and len(dropped) > 0
    np.testing.assert_allclose(got, exp, rtol=0, atol=1e-12)
    r1, st = peak_search_float(e[:4321], p, thr_min=0.03)
    r2, _ = peak_search_float(e[4321:], p, st, thr_min=0.03)
    np.testing.assert_array_equal(np.concatenate((r1.index, r2.index)), r.index)
    np.testing.assert_array_equal(np.concatenate((r1.amplitude, r2.amplitude)), r.amplitude)


@pytest.mark.parametrize("D, kw", [(1, dict(block_log2=3, hold=2, max_len=7)),
                                   (7, dict(block_log2=5, hold=3, max_len=24)),
                                   (45, dict(block_log2=5, hold=3, max_len=24, clip_to_floor=True,
                                             smooth_log2=10, thr_mult=46)),
                                   (45, dict(block_log2=5, hold=3, max_len=24, clip_to_floor=True,
                                             smooth_log2=6, thr_mult=46, floor_frac=True)),
                                   (1, dict(block_log2=3, hold=2, max_len=7, smooth_log2=4,
                                            floor_frac=True))])
def test_sim_matches_model_pair_detection(D, kw):
    """Amaranth sim == model on pulse pairs D apart (small blocks: the first L samples only
    feed the floor), with pulses dropped and kept by the side-lobe rule."""
    p = PeakParams(pair_offset=D, **kw)
    e = pair_envelope(np.random.default_rng(300 + D), 6000, D)
    ref = _check_sim(p, e)
    kept, dropped = pair_reference(e, p)
    assert _as_tuples(ref) == kept
    assert len(kept) > 30 and len(dropped) > 5, (len(kept), len(dropped))


def test_pair_side_lobes_and_ties():
    """Noise-free floor, D = 10, pair_keep 6. A single pulse at c gives two equal sums,
    s[c] = s[c + D] (a train of one pulse): both kept. A pair 700/900: its side lobes at c1
    (800 against 1600 ahead) and c2 + D (1000 against 1600 behind) go, the pair's sum at c2
    stays. A pair 900/400 at c3, c4: the side lobe at c3 (1000 against 1300 ahead, 8 * 1000
    >= 6 * 1300) is kept (the one at c4 + D, 500, is under the threshold, 600). The simulation emits the same."""
    D = 10
    p = PeakParams(block_log2=5, hold=3, max_len=24, pair_offset=D)
    L = p.block_len
    e = np.full(5 * L, 100, dtype=np.int64)
    c = 2 * L + 6
    e[c - 1:c + 2] = [400, 900, 400]
    c1, c2 = 3 * L + 6, 3 * L + 6 + D
    e[c1 - 1:c1 + 2] = [400, 700, 400]
    e[c2 - 1:c2 + 2] = [400, 900, 400]
    c3, c4 = 4 * L + 6, 4 * L + 6 + D
    e[c3 - 1:c3 + 2] = [400, 900, 400]
    e[c4 - 1:c4 + 2] = [300, 400, 300]
    ref = _check_sim(p, e)
    assert ref.index.tolist() == [c, c + D, c2, c3, c4]
    assert ref.amplitude.tolist() == [(900 + 100) >> 1, (100 + 900) >> 1, (900 + 700) >> 1,
                                      (900 + 100) >> 1, (400 + 900) >> 1]
    kept, dropped = pair_reference(e, p)
    assert _as_tuples(ref) == kept
    assert [d[1] for d in dropped] == [c1, c2 + D]


def test_gaps_in_valid_with_pair_detection():
    rng = np.random.default_rng(310)
    p = PeakParams(block_log2=5, hold=3, max_len=24, pair_offset=12)
    e = pair_envelope(rng, 3000, p.pair_offset)
    ref = _check_sim(p, e, rng.random(9000) < 0.35)
    _check_sim(p, e, np.repeat(rng.random(900) < 0.5, 10))
    kept, dropped = pair_reference(e, p)
    assert ref.amplitude.size > 10 and len(dropped) > 0


@pytest.mark.parametrize("D", [5, 40])
def test_reset_mid_run_with_pair_detection(D):
    """After a clear the memory's old words are not e[n - D]: 0 until D new samples are in
    (the memory itself is not reset). Stale words would lift the first block's floor (a
    quiet block: threshold 96 instead of 27 with D = 5, 465 instead of 16 with D = 40) and,
    with D = 40 > L, the pulse at 33 (block 1) would sum with one, 3150 > 3025 at 73: the
    pulse at 33 would be kept instead of its later side lobe."""
    p = PeakParams(block_log2=5, hold=3, max_len=24, pair_offset=D)
    rng = np.random.default_rng(315)
    e1 = pair_envelope(rng, 700, D)
    e1[-40 - 2 * D:] = 150  # no pulse open when the clear comes; these stay in the memory
    e2 = realistic_envelope(rng, 900)
    e2[:32] = 5
    e2[33:36] = 3000
    e2[36:36 + 2 * D] = 25
    ref1, st1 = peak_search(e1, p)
    assert not st1.open
    ref2, _ = peak_search(e2, p)
    # what a sum stage that forgot the clear would give (stale e[n - D]): different pulses
    stale, _ = peak_search(e2, p, PeakState(pair_hist=tuple(e1[-D:].tolist())))
    assert not (np.array_equal(stale.amplitude, ref2.amplitude)
                and np.array_equal(stale.index, ref2.index))
    valid = np.concatenate((np.ones(e1.size, bool), np.zeros(30, bool)))
    c = e1.size + 15
    dut = WithClear(PeakSearch(p))
    _, amp, ts = _run_sim(p, np.concatenate((e1, e2)), valid, dut=dut,
                          writes=[(c, dut.clear, 1), (c + 1, dut.clear, 0)])
    np.testing.assert_array_equal(amp, np.concatenate((ref1.amplitude, ref2.amplitude)))
    np.testing.assert_array_equal(ts, np.concatenate((ref1.timestamp, ref2.timestamp)))


def test_pair_detection_ports():
    """The pair detection's output is amplitude (amp_width) + timestamp, as out_layout."""
    p = PeakParams(pair_offset=60, amp_width=17, ts_bits=20)
    dut = PeakSearch(p)
    assert [(k, Shape.cast(v).width) for k, v in dut.out_layout.members.items()] \
        == [(k, w) for k, w, _ in p.out_layout] == [("amplitude", 17), ("timestamp", 20)]
    assert dut.i.payload.shape() == unsigned(17)
    assert p.latency == 11 and p.emit_delay == 60
    Fragment.get(dut, None)   # elaborates


def _gauss_pulse(e, c, amp, half_width=9.5):
    """Add a TACAN-like pulse (the golden envelope's shape: 19 samples at half amplitude)."""
    k = np.arange(-45, 46)
    e[c + k] += np.round(amp * np.exp(-np.log(2) * (k / half_width) ** 2)).astype(np.int64)


#: D = 60 (12 us at 5 MHz), the pair checks on; a noise-free floor of 100.
PAIR_CHECKED = PeakParams(block_log2=8, hold=5, max_len=128, clip_to_floor=True, pair_offset=60,
                          pair_balance=4, pair_spread=8)


def _other_mode_envelope():
    """Floor 100; a single pulse at c1 (a Y-mode reference pulse), two pulses 75 samples (15
    us, the Y auxiliary burst) apart at c2, c2 + 75, an X pair 60 apart at c3, c3 + 60, and
    one 62 apart (D + 2) at c4, c4 + 62."""
    L = PAIR_CHECKED.block_len
    e = np.full(12 * L, 100, dtype=np.int64)
    c1, c2, c3, c4 = 2 * L, 4 * L, 6 * L, 8 * L
    _gauss_pulse(e, c1, 3000)
    _gauss_pulse(e, c2, 3000)
    _gauss_pulse(e, c2 + 75, 3000)
    _gauss_pulse(e, c3, 3000)
    _gauss_pulse(e, c3 + 60, 2500)
    _gauss_pulse(e, c4, 2000)
    _gauss_pulse(e, c4 + 62, 3000)
    return e, (c1, c2, c3, c4)


def test_pair_checks_reject_single_pulses_and_other_spacings():
    """Without the checks the pair sum takes a single pulse for two pairs (c1, c1 + D: equal
    sums, the side-lobe rule keeps both) and two pulses 15 us apart for a 12-us pair (both
    halves on a flank: s ~ 1.3 A at the middle). ``pair_balance`` (both halves >= s/4) drops the
    single pulse, ``pair_spread`` (w = 8: the sum at spacing D through the pair's centre not
    below those at D +- 16) the 15-us pair; the 12-us pairs (60 and 62 apart) stay. Compiled
    model == numpy model; the float variant keeps the same pairs."""
    e, (c1, c2, c3, c4) = _other_mode_envelope()
    D = PAIR_CHECKED.pair_offset
    plain = replace(PAIR_CHECKED, pair_balance=0, pair_spread=0)
    r0, _ = peak_search(e, plain)
    assert {c1, c1 + D} <= set(r0.index.tolist())
    assert any(c2 + D <= i <= c2 + 75 for i in r0.index.tolist())
    for kw, gone in [(dict(pair_spread=0), "single"), (dict(pair_balance=0), "15us"), ({}, "")]:
        p = replace(PAIR_CHECKED, **kw)
        r, st = peak_search(e, p)
        rn, st_n = peak_search_numpy(e, p)
        for name in ("amplitude", "timestamp", "index", "end_index", "thresholds"):
            np.testing.assert_array_equal(getattr(r, name), getattr(rn, name), err_msg=name)
        assert st == st_n
        got = r.index.tolist()
        single = [i for i in got if c1 - 5 <= i <= c1 + D + 5]
        y_aux = [i for i in got if c2 + D - 5 <= i <= c2 + 80]
        assert (single == []) == ("single" in gone or gone == ""), (kw, got)
        assert (y_aux == []) == ("15us" in gone or gone == ""), (kw, got)
        if not kw:  # both checks: only the X pairs, reported at their second pulse
            assert len(got) == 2 and abs(got[0] - (c3 + D)) <= 1 and abs(got[1] - (c4 + 61)) <= 1, got
            np.testing.assert_array_equal(r.amplitude, (e[got] + e[np.array(got) - D]) >> 1)
            rf, _ = peak_search_float(e.astype(np.float64), p)
            np.testing.assert_array_equal(rf.index, r.index)
            np.testing.assert_array_equal(rf.amplitude, (e[got] + e[np.array(got) - D]) / 2)


@pytest.mark.parametrize("p", [PAIR_CHECKED,
                               replace(TACAN_X_PAIR, pair_balance=6, pair_spread=5),
                               replace(TACAN_X_PAIR, pair_balance=4, pair_spread=8,
                                       floor_frac=True),
                               PeakParams(pair_offset=7, block_log2=5, hold=3, max_len=24,
                                          pair_balance=8, pair_spread=7)])
def test_pair_checks_chunked_equals_one_run(p):
    """With the pair checks (an envelope history of 2 D + max_len + w samples across chunks):
    chunked == one run, compiled == numpy after every chunk; the checks drop pairs here."""
    D = p.pair_offset
    rng = np.random.default_rng(320 + D)
    e = pair_envelope(rng, 30_000, D, amp_width=p.amp_width)
    e[:3000] = np.maximum(e[:3000], _other_mode_envelope()[0][:3000])
    whole, st_whole = peak_search(e, p)
    plain, _ = peak_search(e, replace(p, pair_balance=0, pair_spread=0))
    assert 10 < whole.index.size < plain.index.size
    cuts = np.unique(np.clip(np.concatenate((
        whole.index[::5] + 1, whole.index[2::7] + D, rng.integers(0, e.size, 30),
        [0, 1, 1, 2, D - 1, D, D + 1, 2 * D + 3, 10_000, 10_001, 10_000 + D])), 0, e.size))
    st_a = st_b = None
    parts = []
    prev = 0
    for c in list(cuts) + [e.size, e.size]:
        ra, st_a = peak_search(e[prev:c], p, st_a)
        rb, st_b = peak_search_numpy(e[prev:c], p, st_b)
        for name in ("amplitude", "timestamp", "index", "end_index"):
            np.testing.assert_array_equal(getattr(ra, name), getattr(rb, name))
        assert st_a == st_b
        parts.append(ra)
        prev = c
    for name in ("amplitude", "timestamp", "index", "end_index"):
        np.testing.assert_array_equal(np.concatenate([getattr(r, name) for r in parts]),
                                      getattr(whole, name), err_msg=name)
    assert st_a == st_whole


# -- pair checks in the HDL ----------------------------------------------------------------
def checked_envelope(rng, n, D, other=None, width=10.0, **kw):
    """:func:`pair_envelope` (pairs ``D`` apart, a quarter single pulses) with, at the
    sample-wise max, a sparser stream of pairs ``other`` apart (default ``1.25 D``: the 15-us
    pairs of the other TACAN mode at ``D`` = 12 us), a third of them single pulses; pulses
    ``width`` samples at half amplitude (TACAN at 5 MHz: 19)."""
    other = other or int(round(1.25 * D))
    e = pair_envelope(rng, n, D, width=width, **kw)
    e2 = realistic_envelope(rng, n, pair_offset=other, single=0.33, min_gap=60 + other,
                            max_gap=300 + 3 * other, amp_width=kw.get("amp_width", 19),
                            width=width)
    return np.maximum(e, e2)


def _assert_checks_bite(p, e):
    """Each check on in ``p`` drops some of the peaks the side-lobe rule keeps and keeps
    others (so the tests below can fail)."""
    plain, _ = peak_search(e, replace(p, pair_balance=0, pair_spread=0))
    got, _ = peak_search(e, p)
    for name in ("pair_balance", "pair_spread"):
        if getattr(p, name):
            only = replace(p, **{"pair_balance": 0, "pair_spread": 0, name: getattr(p, name)})
            r, _ = peak_search(e, only)
            assert 5 <= r.index.size <= plain.index.size - 2, (name, r.index.size,
                                                                plain.index.size)
    assert got.index.size >= 5
    return got


PAIR_CHECK_SETS = [
    PeakParams(pair_offset=7, block_log2=5, hold=3, max_len=24, pair_balance=6),
    PeakParams(pair_offset=7, block_log2=5, hold=3, max_len=24, pair_spread=3),
    PeakParams(pair_offset=7, block_log2=5, hold=3, max_len=24, pair_balance=7, pair_spread=2),
    # max_len such that pair_history + inner latency = 64, the history's depth: exactly
    PeakParams(pair_offset=7, block_log2=5, hold=3, max_len=39, pair_balance=6, pair_spread=3),
    replace(PAIR_CHECKED, pair_balance=4, pair_spread=8),
    PeakParams(pair_offset=7, block_log2=5, hold=3, max_len=24, pair_balance=6, pair_spread=3,
               smooth_log2=6, floor_frac=True),
]


@pytest.mark.parametrize("k", range(len(PAIR_CHECK_SETS)))
def test_sim_matches_model_pair_checks(k):
    """Amaranth sim == model with the pair checks (balance alone, spread alone, both; D = 7
    and TACAN-like D = 60) on pairs D apart, single pulses and pairs 1.25 D apart: amplitude,
    timestamp and emission cycle (latency + 1: the history's registered read)."""
    p = PAIR_CHECK_SETS[k]
    D = p.pair_offset
    e = checked_envelope(np.random.default_rng(330 + k), 6000 if D < 20 else 8000, D,
                         width=10.0 if D < 20 else 19.0)
    assert p.latency == PeakParams(pair_offset=D).latency + 1
    ref = _check_sim(p, e)
    _assert_checks_bite(p, e)
    assert ref.index.size > 5


def test_pair_check_history_depth():
    """The history holds pair_history + the inner latency samples rounded up to a power of
    two (here exactly: 2 * 7 + 39 + 3 + 8 = 64)."""
    assert PAIR_CHECK_SETS[3].pair_check_depth == 64
    assert PAIR_CHECK_SETS[3].pair_history + PAIR_CHECK_SETS[3].search_params.latency == 64
    assert replace(TACAN_X_PAIR, pair_balance=4, pair_spread=8).pair_check_depth == 512


@pytest.mark.parametrize("max_len", [39, 40])
def test_pair_check_history_worst_case(max_len):
    """The oldest tap of the worst case: a max_len cut whose max is its first sample c, valid
    on every cycle. Its tap e[c - D - w] (0) is read when the samples up to c + max_len - 1 +
    D + inner latency (8) are in (with max_len 39 that is c + 53, the history full at 64 =
    depth words from c - 10); a spike at c + 54 written over it would make
    e[c + w] + e[c - D - w] 6400 > s[c] = 5000 and drop the pair c - D, c (max_len 40: the
    need is 65 words, the depth 128)."""
    p = replace(PAIR_CHECK_SETS[3], max_len=max_len)
    D, w = p.pair_offset, p.pair_spread
    assert (p.pair_history + p.search_params.latency, p.pair_check_depth) \
        == ((64, 64) if max_len == 39 else (65, 128))
    c = 4 * p.block_len + 10
    e = np.full(c + 200, 50, dtype=np.int64)
    e[c - D - w] = 0
    e[c - D] = 2000
    e[c] = 3000
    e[c + 1:c + 45] = 1400
    e[c + D] = 0                      # s[c + D] = 3000 < s[c]
    e[c + 54] = 5000                  # the sample that would overwrite e[c - D - w]
    ref = _check_sim(p, e)
    i = ref.index.tolist().index(c)
    assert ref.end_index[i] == c + max_len - 1 and ref.amplitude[i] == 5000 >> 1
    plain, _ = peak_search(e, replace(p, pair_spread=0))
    assert plain.index.tolist() == ref.index.tolist()
    # (checked by hand: a history one word short of the need, 64 with max_len 40, fails here)


def test_gaps_in_valid_with_pair_checks():
    rng = np.random.default_rng(340)
    p = PeakParams(block_log2=5, hold=3, max_len=24, pair_offset=12, pair_balance=6,
                   pair_spread=3)
    e = checked_envelope(rng, 3000, p.pair_offset, width=14.0)
    _check_sim(p, e, rng.random(9000) < 0.35)
    _check_sim(p, e, np.repeat(rng.random(900) < 0.5, 10))
    _assert_checks_bite(p, e)


@pytest.mark.parametrize("kw, early_kept", [(dict(pair_balance=4), False),
                                            (dict(pair_spread=8), True),
                                            (dict(pair_balance=4, pair_spread=8), False)])
def test_reset_mid_run_with_pair_checks(kw, early_kept):
    """Early peaks (D = 40 > L = 32) whose taps fall before the first sample since reset read
    e = 0 there, after power-up and after a clear (the history is not reset: its words are
    stale, 1500). The peak at 36 (s = e[36] = 2000): balance drops it (min(e[36], e[-4]) = 0;
    stale 1500 would keep it), spread keeps it (e[44] + e[-12] = 600; stale: 2100 > 2000)."""
    D = 40
    p = PeakParams(block_log2=5, hold=3, max_len=24, pair_offset=D, **kw)
    rng = np.random.default_rng(345)
    e1 = pair_envelope(rng, 1400, D)
    e1[-700:] = 1500      # a pulse (max_len cuts), then the floor catches up: closed
    e2 = realistic_envelope(rng, 900)
    e2[:120] = 5
    e2[35:38] = [1000, 2000, 1000]
    e2[38:46] = 600
    ref1, st1 = peak_search(e1, p)
    assert not st1.open and ref1.end_index[-1] < e1.size - 200
    ref2, _ = peak_search(e2, p)
    assert (36 in ref2.index.tolist()) == early_kept
    _check_sim(p, e2)     # from power-up
    valid = np.concatenate((np.ones(e1.size, bool), np.zeros(30, bool)))
    c = e1.size + 15
    dut = WithClear(PeakSearch(p))
    _, amp, ts = _run_sim(p, np.concatenate((e1, e2)), valid, dut=dut,
                          writes=[(c, dut.clear, 1), (c + 1, dut.clear, 0)])
    np.testing.assert_array_equal(amp, np.concatenate((ref1.amplitude, ref2.amplitude)))
    np.testing.assert_array_equal(ts, np.concatenate((ref1.timestamp, ref2.timestamp)))


def test_pair_checks_ports():
    p = replace(TACAN_X_PAIR, pair_balance=4, pair_spread=8)
    dut = PeakSearch(p)
    assert [(k, w) for k, w, _ in p.out_layout] == [("amplitude", 19), ("timestamp", 32)]
    assert p.latency == 12 and p.emit_delay == 60
    Fragment.get(dut, None)   # elaborates


# -- model ---------------------------------------------------------------------------------
PARAM_SETS = [PeakParams(), SMALL, PeakParams(block_log2=3, hold=2, max_len=7),
              PeakParams(block_log2=2, hold=1, max_len=2, smooth_log2=0),
              PeakParams(block_log2=4, max_len=20, clip_log2=0),
              PeakParams(block_log2=6, smooth_log2=4, clip_to_floor=True, thr_mult=52),
              # the floor with fraction bits
              PeakParams(block_log2=6, smooth_log2=4, clip_to_floor=True, thr_mult=52,
                         floor_frac=True),
              PeakParams(block_log2=3, hold=2, max_len=7, smooth_log2=9, floor_frac=True),
              PeakParams(block_log2=2, hold=1, max_len=2, smooth_log2=0, floor_frac=True)]


@pytest.mark.parametrize("k", range(len(PARAM_SETS)))
def test_model_matches_reference_loop(k):
    p = PARAM_SETS[k]
    rng = np.random.default_rng(205 + k)
    e = realistic_envelope(rng, 20_000)
    e[9000:9500] = 4000
    ref, _ = peak_search(e, p)
    assert _as_tuples(ref) == reference_loop(e, p)


@pytest.mark.parametrize("k", range(len(PARAM_SETS)))
def test_model_chunked_equals_one_run(k):
    p = PARAM_SETS[k]
    rng = np.random.default_rng(215 + k)
    e = realistic_envelope(rng, 20_000)
    e[9000:9500] = 4000
    whole, st_whole = peak_search(e, p)
    # Cut inside pulses (open at the end of a chunk), at random points, and 1-sample chunks.
    cuts = np.concatenate((whole.index[::7] + 1, rng.integers(0, e.size, 40),
                           np.arange(9200, 9210)))
    cuts = np.unique(np.clip(cuts, 0, e.size))
    st = None
    parts = []
    prev = 0
    for c in list(cuts) + [e.size]:
        r, st = peak_search(e[prev:c], p, st)
        parts.append(r)
        prev = c
    for name in ("amplitude", "timestamp", "index", "end_index"):
        np.testing.assert_array_equal(np.concatenate([getattr(r, name) for r in parts]),
                                      getattr(whole, name))
    assert st == st_whole


@pytest.mark.parametrize("k", range(len(PARAM_SETS)))
def test_compiled_model_equals_numpy_model(k):
    """The compiled per-sample search == the vectorised numpy one: pulses, thresholds and
    the state after every chunk (cuts inside pulses, 1-sample and empty chunks, a carrier
    longer than max_len, values at the top of the range)."""
    p = PARAM_SETS[k]
    rng = np.random.default_rng(245 + k)
    e = realistic_envelope(rng, 30_000)
    e[9000:9500] = 4000
    e[12_000:12_050] = (1 << p.amp_width) - 1
    whole, st_whole = peak_search(e, p)
    ref, st_ref = peak_search_numpy(e, p)
    assert whole.amplitude.size > 50
    for name in ("amplitude", "timestamp", "index", "end_index", "thresholds"):
        np.testing.assert_array_equal(getattr(whole, name), getattr(ref, name))
        assert getattr(whole, name).dtype == np.int64
    assert st_whole == st_ref
    cuts = np.unique(np.concatenate((whole.index[::5] + 1, whole.index[3::11] + 3,
                                     rng.integers(0, e.size, 30), [0, 1, 1, 2, 9200, 9201])))
    st_a = st_b = None
    prev = 0
    for c in list(cuts) + [e.size, e.size]:
        ra, st_a = peak_search(e[prev:c], p, st_a)
        rb, st_b = peak_search_numpy(e[prev:c], p, st_b)
        for name in ("amplitude", "timestamp", "index", "end_index", "thresholds"):
            np.testing.assert_array_equal(getattr(ra, name), getattr(rb, name))
        assert st_a == st_b
        prev = c
    assert st_a == st_whole


def test_state_is_not_modified():
    st = PeakState()
    peak_search(np.full(100, 5), SMALL, st)
    assert st == PeakState()


@pytest.mark.parametrize("k", range(len(PARAM_SETS)))
def test_float_variant_matches_reference_loop(k):
    p = PARAM_SETS[k]
    rng = np.random.default_rng(225 + k)
    e = realistic_envelope(rng, 10_000) * 1e-3 + rng.random(10_000) * 1e-4
    r, _ = peak_search_float(e, p, thr_min=0.03)
    got = np.array(_as_tuples(r))
    exp = np.array(reference_loop(e, p, is_float=True, thr_min=0.03))
    assert got.shape == exp.shape
    np.testing.assert_allclose(got, exp, rtol=0, atol=1e-12)
    # Chunked float run gives the same result.
    r1, st = peak_search_float(e[:4321], p, thr_min=0.03)
    r2, _ = peak_search_float(e[4321:], p, st, thr_min=0.03)
    np.testing.assert_array_equal(np.concatenate((r1.index, r2.index)), r.index)


def test_float_variant_close_to_integer():
    """On a strong-pulse envelope both variants find the same pulses at the same peaks."""
    p = PeakParams()
    rng = np.random.default_rng(235)
    e = realistic_envelope(rng, 50_000, amp_range=(6.0, 20.0))
    ri, _ = peak_search(e, p)
    rf, _ = peak_search_float(e.astype(np.float64), p)
    np.testing.assert_array_equal(rf.index, ri.index)
    np.testing.assert_array_equal(rf.amplitude, ri.amplitude)


def test_floor_frac_equilibrium_on_a_constant_input():
    """The floor's truncation bias: from block 0 at 1000, a constant m = 3000 with
    smooth_log2 = 10. Without fraction bits nu stops where m - nu < 2**10 (nu += (m - nu)
    >> 10 adds nothing): 1977, 2**10 - 1 below m; with floor_frac it reaches m (F = m << 10
    and the fraction bits). Both models; the threshold follows nu."""
    e = np.concatenate([np.full(2, 1000), np.full(2 * 12_000, 3000)])
    for frac, want in ((False, 3000 - (2 ** 10 - 1)), (True, 3000)):
        p = PeakParams(block_log2=1, smooth_log2=10, clip_log2=2, floor_frac=frac)
        for fn in (peak_search, peak_search_numpy):
            r, st = fn(e, p)
            assert st.nu == want, (fn.__name__, frac, st.nu)
            assert st.nuf == (3000 << 10 if frac else 0)
            assert r.thresholds[-1] == p.threshold(want)
    # from above both reach m (a negative difference always subtracts)
    e = np.concatenate([np.full(2, 5000), np.full(2 * 12_000, 3000)])
    for frac in (False, True):
        _, st = peak_search(e, PeakParams(block_log2=1, smooth_log2=10, floor_frac=frac))
        assert st.nu == 3000


@pytest.mark.parametrize("block_log2", [6, 8])
def test_floor_frac_follows_the_float_floor_on_noise(block_log2):
    """Rayleigh noise (mean 4000), censored floor smoothed over 2**10 blocks (the pair
    detector's): the integer threshold without fraction bits settles far below the float
    variant's (-36 % at 64-sample blocks, -13 % at 256); with floor_frac within 0.1 %. The
    float variant ignores floor_frac."""
    rng = np.random.default_rng(262)
    n = 1 << 21
    e = np.rint(rng.rayleigh(4000 / np.sqrt(np.pi / 2), n)).astype(np.int64)
    tail = slice(n // 2, None)
    p = PeakParams(block_log2=block_log2, smooth_log2=10, clip_to_floor=True, thr_mult=46)
    f, _ = peak_search_float(e.astype(np.float64), p)
    f2, _ = peak_search_float(e.astype(np.float64), replace(p, floor_frac=True))
    np.testing.assert_array_equal(f.thresholds, f2.thresholds)
    rel = {}
    for frac in (False, True):
        r, _ = peak_search(e, replace(p, floor_frac=frac))
        rel[frac] = r.thresholds[tail].mean() / f.thresholds[tail].mean() - 1
    assert rel[False] < -0.10, rel
    assert abs(rel[True]) < 1e-3, rel


def test_model_rejects_bad_input():
    with pytest.raises(ValueError, match="unsigned 19-bit"):
        peak_search(np.array([-1]), PeakParams())
    with pytest.raises(ValueError, match="NaN"):
        peak_search_float(np.array([np.nan]), PeakParams())


# -- parameters ----------------------------------------------------------------------------
@pytest.mark.parametrize("kw, msg", [
    (dict(amp_width=0), r"peak amp_width must be an integer in \[1, 40\], not 0"),
    (dict(ts_bits=0), r"peak ts_bits must be an integer in \[1, 62\], not 0"),
    (dict(ts_step=0), r"peak ts_step must be an integer in \[1, \d+\], not 0"),
    (dict(block_log2=0), r"peak block_log2 must be an integer in \[1, 20\], not 0"),
    (dict(hold=0), r"peak hold must be an integer in \[1, 65536\], not 0"),
    (dict(hold=5, max_len=5), r"peak max_len must be an integer > hold \(5\) and <= 2\*\*20, "
                              r"not 5"),
    (dict(thr_mult=0), r"peak thr_mult must be an integer in \[1, 1048575\], not 0"),
    (dict(thr_min=-1), r"peak thr_min must be an integer in \[0, 524287\], not -1"),
    (dict(smooth_log2=2.0), r"peak smooth_log2 must be an integer in \[0, 16\], not 2.0"),
    (dict(clip_to_floor=1), r"peak clip_to_floor must be True or False, not 1"),
    (dict(floor_frac=1), r"peak floor_frac must be True or False, not 1"),
    (dict(partner_offset=-1), r"peak partner_offset must be an integer in \[0, 4096\], not -1"),
    (dict(pair_offset=-1), r"peak pair_offset must be an integer in \[0, 4096\], not -1"),
    (dict(pair_offset=4097), r"peak pair_offset must be an integer in \[0, 4096\], not 4097"),
    (dict(pair_offset=1.0), r"peak pair_offset must be an integer in \[0, 4096\], not 1.0"),
    (dict(pair_keep=0), r"peak pair_keep must be an integer in \[1, 8\], not 0"),
    (dict(pair_keep=9), r"peak pair_keep must be an integer in \[1, 8\], not 9"),
    (dict(pair_balance=9), r"peak pair_balance must be an integer in \[0, 8\], not 9"),
    (dict(pair_spread=-1), r"peak pair_spread must be an integer in \[0, 64\], not -1"),
    (dict(pair_spread=65), r"peak pair_spread must be an integer in \[0, 64\], not 65"),
    (dict(pair_offset=5, pair_spread=6), r"peak pair_spread \(6\) must not exceed pair_offset \(5\)"),
    (dict(pair_offset=60, pair_balance=4, ts_step=3), r"peak pair checks \(pair_balance, "
     r"pair_spread\) need ts_step a power of two and ts_bits - log2\(ts_step\) >= 8 \(the "
     r"HDL reads the peak's index mod 256 from its timestamp\), not ts_step 3, ts_bits 32"),
    (dict(pair_offset=60, pair_spread=8, ts_bits=9, ts_step=2), r"need ts_step a power of "
     r"two and ts_bits - log2\(ts_step\) >= 9 .* not ts_step 2, ts_bits 9"),
    (dict(pair_offset=60, partner_offset=60), r"peak pair_offset and partner_offset exclude "
                                              r"each other \(the pair detection reads its "
                                              r"partners itself\)"),
])
def test_bad_params(kw, msg):
    with pytest.raises(ValueError, match=msg):
        PeakParams(**kw)


@pytest.mark.verilator
def test_verilog_lints_clean():
    """Waived: cosim.verilog.LINT_WAIVERS (UNUSEDSIGNAL, DECLFILENAME, WIDTH)."""
    assert_lints_clean(PeakSearch(PeakParams()), "peak_search")


#: Compiled with Verilator: the default (TACAN) configuration.
VL_PARAMS = PeakParams()


@pytest.fixture(scope="module")
def vl_peak():
    dut = PeakSearch(VL_PARAMS)
    return dut, verilator_sim(dut, "peak_search_vl")


def _vl_stimulus(rng, n, p_valid):
    """Realistic envelope with a continuous carrier (max_len cuts); random gaps in valid."""
    e = realistic_envelope(rng, n)
    e[n // 2:n // 2 + 700] = 2500
    return e, rng.random(int(n / p_valid) + 100) < p_valid


@needs_verilator
def test_verilator_matches_pysim(vl_peak):
    dut, sim = vl_peak
    p = VL_PARAMS
    e, valid = _vl_stimulus(np.random.default_rng(240), 5000, 0.6)
    kw = dict(in_valid=valid, flush_cycles=p.latency + 2)
    want = run_stream(dut, e, **kw)
    got = sim.run(e, **kw)
    assert_same_stream(got, want, "verilator vs pysim")
    assert len(got.words) > 20


@needs_verilator
def test_verilator_matches_model_long(vl_peak):
    _, sim = vl_peak
    p = VL_PARAMS
    e, valid = _vl_stimulus(np.random.default_rng(241), 1_000_000, 0.7)
    res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
    f = unpack_fields(res.words, p.out_layout)
    ref, _ = peak_search(e, p)
    assert ref.amplitude.size > 10_000
    np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
    np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
    np.testing.assert_array_equal(res.cycles,
                                  accepted_cycles(e.size, valid)[ref.end_index] + p.latency)


#: The censored noise floor (``clip_to_floor``) compiled with Verilator as well.
VL_CENSORED = PeakParams(clip_to_floor=True, thr_mult=52)


@needs_verilator
def test_verilator_matches_model_censored_floor():
    sim = verilator_sim(PeakSearch(VL_CENSORED), "peak_search_censored_vl")
    p = VL_CENSORED
    e, valid = _vl_stimulus(np.random.default_rng(242), 200_000, 0.7)
    res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
    f = unpack_fields(res.words, p.out_layout)
    ref, _ = peak_search(e, p)
    plain, _ = peak_search(e, PeakParams(thr_mult=52))
    assert ref.amplitude.size > 1000
    # the option changes the floor (else this test would not test it)
    assert not np.array_equal(ref.thresholds, plain.thresholds)
    np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
    np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
    np.testing.assert_array_equal(res.cycles,
                                  accepted_cycles(e.size, valid)[ref.end_index] + p.latency)


def test_censored_floor_is_not_lifted_by_a_burst_of_pulses():
    """A dense burst of strong pulses lifts the clipped-mean floor (its samples count as
    2 nu) and so the threshold after it; the censored mean counts them as nu and stays."""
    rng = np.random.default_rng(260)
    n, L = 60_000, 1 << 8
    e = np.rint(rng.rayleigh(200.0, n)).astype(np.int64)
    burst = slice(30_000, 30_000 + L)
    e[burst][::2] = 5000                       # every other sample of one block: pulses
    after = slice(30_000 + L, 30_000 + 2 * L)  # the block after the burst
    quiet = slice(20_000, 30_000)
    rise = {}
    for to_floor in (False, True):
        p = PeakParams(block_log2=8, clip_to_floor=to_floor)
        res, _ = peak_search(e, p)
        rise[to_floor] = res.thresholds[after].mean() / res.thresholds[quiet].mean() - 1
    assert rise[False] > 0.08                  # clipped: the burst lifts the threshold ...
    assert abs(rise[True]) < 0.3 * rise[False]  # ... censored: much less


#: The pair-partner readout (TACAN X mode: 12 us of 5 MHz envelope samples) with Verilator.
VL_PARTNER = PeakParams(partner_offset=60)


@needs_verilator
def test_verilator_matches_model_partner_readout():
    sim = verilator_sim(PeakSearch(VL_PARTNER), "peak_search_partner_vl")
    p = VL_PARTNER
    e, valid = _vl_stimulus(np.random.default_rng(243), 200_000, 0.7)
    res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
    f = unpack_fields(res.words, p.out_layout)
    ref, _ = peak_search(e, p)
    assert ref.amplitude.size > 1000
    for k in ("amplitude", "timestamp", "partner", "partner_late"):
        np.testing.assert_array_equal(f[k], getattr(ref, k))
    np.testing.assert_array_equal(res.cycles, accepted_cycles(e.size, valid)[
        ref.end_index + p.partner_offset] + p.latency)


@pytest.mark.verilator
@pytest.mark.parametrize("D", [60, 1])
def test_verilog_lints_clean_pair_detection(D):
    """The pair detection (TACAN X mode; and D = 1, a one-word memory)."""
    p = TACAN_X_PAIR if D == 60 else PeakParams(pair_offset=1)
    assert_lints_clean(PeakSearch(p), f"peak_search_pair{D}")


#: The pulse-pair detection (TACAN X mode: 12 us of 5 MHz envelope samples, censored floor)
#: with Verilator.
VL_PAIR = TACAN_X_PAIR


@needs_verilator
def test_verilator_matches_model_pair_detection():
    sim = verilator_sim(PeakSearch(VL_PAIR), "peak_search_pair_vl")
    p = VL_PAIR
    rng = np.random.default_rng(320)
    n = 200_000
    e = pair_envelope(rng, n, p.pair_offset)
    valid = rng.random(int(n / 0.7) + 100) < 0.7
    res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
    f = unpack_fields(res.words, p.out_layout)
    ref, _ = peak_search(e, p)
    inner, _ = peak_search(pair_sum(e, p.pair_offset), p.search_params)
    # the side-lobe rule drops many of the search's pulses and keeps most pairs
    assert ref.amplitude.size > 1000 and inner.amplitude.size - ref.amplitude.size > 500
    np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
    np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
    np.testing.assert_array_equal(res.cycles, accepted_cycles(e.size, valid)[
        ref.end_index + p.emit_delay] + p.latency)



@pytest.mark.verilator
def test_verilog_lints_clean_pair_checks():
    """The pair checks (TACAN X mode, balance 4, spread 8; and D = 1, spread 1)."""
    assert_lints_clean(PeakSearch(replace(TACAN_X_PAIR, pair_balance=4, pair_spread=8)),
                       "peak_search_pair_checks")
    assert_lints_clean(PeakSearch(PeakParams(pair_offset=1, pair_balance=8, pair_spread=1)),
                       "peak_search_pair_checks1")


#: The pair checks (balance 4, spread 8) on the TACAN X-mode pair detection with Verilator.
VL_PAIR_CHECKED = PeakParams(pair_offset=60, clip_to_floor=True, smooth_log2=10, thr_mult=46,
                             pair_balance=4, pair_spread=8)


@needs_verilator
def test_verilator_matches_model_pair_checks():
    """2e5 samples: pairs 60 apart, single pulses and 15-us-like pairs 75 apart; gaps."""
    sim = verilator_sim(PeakSearch(VL_PAIR_CHECKED), "peak_search_pair_checks_vl")
    p = VL_PAIR_CHECKED
    rng = np.random.default_rng(350)
    n = 200_000
    e = checked_envelope(rng, n, p.pair_offset, other=75, width=19.0)
    valid = rng.random(int(n / 0.7) + 100) < 0.7
    res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
    f = unpack_fields(res.words, p.out_layout)
    ref = _assert_checks_bite(p, e)
    assert ref.amplitude.size > 500
    np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
    np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
    np.testing.assert_array_equal(res.cycles, accepted_cycles(e.size, valid)[
        ref.end_index + p.emit_delay] + p.latency)


#: The floor with fraction bits (floor_frac) on the TACAN X-mode pair detection with its pair
#: checks (dsp.tacan.frontend.PAIR_DETECTOR) with Verilator.
VL_PAIR_FRAC = replace(VL_PAIR_CHECKED, floor_frac=True)


@pytest.mark.verilator
def test_verilog_lints_clean_floor_frac():
    assert_lints_clean(PeakSearch(VL_PAIR_FRAC), "peak_search_pair_frac")
    assert_lints_clean(PeakSearch(PeakParams(floor_frac=True)), "peak_search_frac")


@needs_verilator
def test_verilator_matches_model_floor_frac():
    """2e5 samples, gaps in valid: the pair detection with floor_frac, and the single-pulse
    search with floor_frac (smooth_log2 6: the fraction bits move the floor within the run)."""
    rng = np.random.default_rng(352)
    n = 200_000
    for name, p, e in (
            ("peak_search_pair_frac_vl", VL_PAIR_FRAC,
             checked_envelope(rng, n, VL_PAIR_FRAC.pair_offset, other=75, width=19.0)),
            ("peak_search_frac_vl", PeakParams(smooth_log2=6, floor_frac=True),
             _vl_stimulus(rng, n, 0.7)[0])):
        sim = verilator_sim(PeakSearch(p), name)
        valid = rng.random(int(n / 0.7) + 100) < 0.7
        res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
        f = unpack_fields(res.words, p.out_layout)
        ref, _ = peak_search(e, p)
        plain, _ = peak_search(e, replace(p, floor_frac=False))
        assert ref.amplitude.size > 500
        assert not np.array_equal(ref.thresholds, plain.thresholds)
        np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
        np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
        np.testing.assert_array_equal(res.cycles, accepted_cycles(e.size, valid)[
            ref.end_index + p.emit_delay] + p.latency)
