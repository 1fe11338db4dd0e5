"""Pulse-peak search with pulse-pair detection (``pair_offset``): model == per-sample reference
(integer and float, chunked), Amaranth simulation == model, side lobes and ties, gaps in
valid, reset mid-run, ports, and the pair checks (balance, spread) in the model."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from amaranth.hdl import Fragment, Shape, unsigned

from dsp.tacan.peak_params import PeakParams, PeakState
from hdl.tacan.peak_model import peak_search
from dsp.tacan.peak import peak_search_float, peak_search_numpy
from hdl.tacan.peak import PeakSearch

from _util import WithClear
from _peak_util import (PAIR_CHECKED, TACAN_X_PAIR, as_tuples, check_sim, pair_envelope, pair_sum,
                        realistic_envelope, reference_loop, run_sim)


# -- pulse-pair detection ------------------------------------------------------------------
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
    assert as_tuples(r) == kept
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
    got = np.array(as_tuples(r))
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
    ref = check_sim(p, e)
    kept, dropped = pair_reference(e, p)
    assert as_tuples(ref) == kept
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
    ref = check_sim(p, e)
    assert ref.index.tolist() == [c, c + D, c2, c3, c4]
    assert ref.amplitude.tolist() == [(900 + 100) >> 1, (100 + 900) >> 1, (900 + 700) >> 1,
                                      (900 + 100) >> 1, (400 + 900) >> 1]
    kept, dropped = pair_reference(e, p)
    assert as_tuples(ref) == kept
    assert [d[1] for d in dropped] == [c1, c2 + D]


def test_gaps_in_valid_with_pair_detection():
    rng = np.random.default_rng(310)
    p = PeakParams(block_log2=5, hold=3, max_len=24, pair_offset=12)
    e = pair_envelope(rng, 3000, p.pair_offset)
    ref = check_sim(p, e, rng.random(9000) < 0.35)
    check_sim(p, e, np.repeat(rng.random(900) < 0.5, 10))
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
    _, amp, ts = run_sim(p, np.concatenate((e1, e2)), valid, dut=dut,
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
