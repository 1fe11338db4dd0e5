"""Pulse-peak search, the pair checks (``pair_balance``, ``pair_spread``) in the HDL: Amaranth
simulation == model, the depth of the check history, gaps in valid, reset mid-run, ports."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from amaranth.hdl import Fragment

from dsp.tacan.peak_params import PeakParams
from hdl.tacan.peak_model import peak_search
from hdl.tacan.peak import PeakSearch

from _util import WithClear
from _peak_util import (PAIR_CHECKED, TACAN_X_PAIR, assert_checks_bite, check_sim,
                        checked_envelope, pair_envelope, realistic_envelope, run_sim)


# -- pair checks in the HDL ----------------------------------------------------------------
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
    ref = check_sim(p, e)
    assert_checks_bite(p, e)
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
    ref = check_sim(p, e)
    i = ref.index.tolist().index(c)
    assert ref.end_index[i] == c + max_len - 1 and ref.amplitude[i] == 5000 >> 1
    plain, _ = peak_search(e, replace(p, pair_spread=0))
    assert plain.index.tolist() == ref.index.tolist()


def test_gaps_in_valid_with_pair_checks():
    rng = np.random.default_rng(340)
    p = PeakParams(block_log2=5, hold=3, max_len=24, pair_offset=12, pair_balance=6,
                   pair_spread=3)
    e = checked_envelope(rng, 3000, p.pair_offset, width=14.0)
    check_sim(p, e, rng.random(9000) < 0.35)
    check_sim(p, e, np.repeat(rng.random(900) < 0.5, 10))
    assert_checks_bite(p, e)


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
    check_sim(p, e2)     # from power-up
    valid = np.concatenate((np.ones(e1.size, bool), np.zeros(30, bool)))
    c = e1.size + 15
    dut = WithClear(PeakSearch(p))
    _, amp, ts = run_sim(p, np.concatenate((e1, e2)), valid, dut=dut,
                          writes=[(c, dut.clear, 1), (c + 1, dut.clear, 0)])
    np.testing.assert_array_equal(amp, np.concatenate((ref1.amplitude, ref2.amplitude)))
    np.testing.assert_array_equal(ts, np.concatenate((ref1.timestamp, ref2.timestamp)))


def test_pair_checks_ports():
    p = replace(TACAN_X_PAIR, pair_balance=4, pair_spread=8)
    dut = PeakSearch(p)
    assert [(k, w) for k, w, _ in p.out_layout] == [("amplitude", 19), ("timestamp", 32)]
    assert p.latency == 12 and p.emit_delay == 60
    Fragment.get(dut, None)   # elaborates
