"""Pulse-peak search, bit-exact model: == the per-sample reference loop, chunked == one run,
compiled == numpy, the float variant, the fractional floor, the censored floor, bad input,
and the parameter checks."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dsp.tacan.peak_params import PeakParams, PeakState
from hdl.tacan.peak_model import peak_search
from dsp.tacan.peak import peak_search_float, peak_search_numpy

from _peak_util import SMALL, as_tuples, realistic_envelope, reference_loop  # tests/hdl, on sys.path: conftest.py


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
    assert as_tuples(ref) == reference_loop(e, p)


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
    got = np.array(as_tuples(r))
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


# -- censored noise floor ------------------------------------------------------------------
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
