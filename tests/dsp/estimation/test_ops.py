"""The one-source operators: int64 forms bit for bit against Python's unbounded integers
(seeded random operands plus corners), float forms the plain operation, with the counted
events and range logs."""
from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from dsp.estimation.events import EventRegistry
from dsp.qops import div_q, flip, isqrt, sqrt_q, store

REG = EventRegistry(("a",), ("neg", "zero"))
NEG, ZERO, BASE = REG.index("neg"), REG.index("zero"), REG.base


@njit(cache=True)
def _store_all(acc, s, half, lo, hi, ev, out):
    for i in range(acc.shape[0]):
        out[i] = store(acc[i], s, half, lo, hi, ev, 0, BASE)


@njit(cache=True)
def _sqrt_all(v, s, half, hi, ev, out):
    for i in range(v.shape[0]):
        out[i] = sqrt_q(v[i], s, half, hi, ev, 0, NEG, BASE)


@njit(cache=True)
def _div_all(n, d, s, half, lo, hi, ev, out):
    for i in range(n.shape[0]):
        out[i] = div_q(n[i], d[i], s, half, lo, hi, ev, 0, ZERO, BASE)


@njit(cache=True)
def _flip_all(v, bit, width, out):
    for i in range(v.shape[0]):
        out[i] = flip(v[i], bit[i], width)


def _sat(v, lo, hi):
    return min(max(v, lo), hi), int(v < lo or v > hi)


@pytest.mark.parametrize("half", [0, 1])
@pytest.mark.parametrize("s", [0, 1, 7, 30])
def test_store_matches_unbounded_integers(half, s):
    rng = np.random.default_rng(100 + s + half)
    lo, hi = -(1 << 31), (1 << 31) - 1
    acc = rng.integers(-(1 << 61), 1 << 61, 4000, dtype=np.int64) >> rng.integers(0, 40, 4000)
    acc[:4] = [(1 << (s + 31)), -(1 << (s + 31)) - 1, (1 << s) >> 1, -((1 << s) >> 1)]
    ev = REG.new()
    out = np.empty_like(acc)
    _store_all(acc, s, half, lo, hi, ev, out)
    want, clamps = [], 0
    for a in acc.tolist():
        v = (a + ((1 << (s - 1)) if half and s else 0)) >> s
        w, c = _sat(v, lo, hi)
        want.append(w)
        clamps += c
    np.testing.assert_array_equal(out, want)
    assert ev[0] == clamps > 0
    pre = [(a + ((1 << (s - 1)) if half and s else 0)) >> s for a in acc.tolist()]
    assert (ev[BASE], ev[BASE + 1]) == (min(pre), max(pre))


@pytest.mark.parametrize("half", [0, 1])
@pytest.mark.parametrize("s", [0, 8, 24])
def test_sqrt_matches_unbounded_integers(half, s):
    rng = np.random.default_rng(200 + s + half)
    v = rng.integers(0, 1 << (61 - s), 4000, dtype=np.int64) >> rng.integers(0, 50, 4000)
    v[:5] = [0, 1, 2, 3, (1 << (61 - s)) - 1]
    v[5:8] = [-1, -5, -(1 << 40)]
    hi = (1 << 29) - 1
    ev = REG.new()
    out = np.empty_like(v)
    _sqrt_all(v, s, half, hi, ev, out)
    want, clamps = [], 0
    for x in v.tolist():
        if x < 0:
            want.append(0)
            continue
        w = x << s
        r = math.isqrt(w)
        if half and (r + 0.5) ** 2 < w:   # exact: no ties for integer w
            r += 1
        r2, c = _sat(r, -hi - 1, hi)
        want.append(r2)
        clamps += c
    np.testing.assert_array_equal(out, want)
    assert ev[NEG] == 3
    assert ev[0] == clamps


def test_isqrt_exact_near_squares():
    for r in [1, 2, 3, 1000, (1 << 31) - 1, 3037000499]:
        for d in (-1, 0, 1):
            w = r * r + d
            if 0 <= w < (1 << 62):
                assert isqrt(np.int64(w)) == math.isqrt(w)


@pytest.mark.parametrize("half", [0, 1])
@pytest.mark.parametrize("s", [0, 10, 24])
def test_div_matches_unbounded_integers(half, s):
    rng = np.random.default_rng(300 + s + half)
    n = rng.integers(-(1 << (60 - s)), 1 << (60 - s), 4000, dtype=np.int64) >> rng.integers(0, 30, 4000)
    d = rng.integers(1, 1 << 40, 4000, dtype=np.int64) >> rng.integers(0, 39, 4000)
    d[:3] = [0, -4, 0]
    lo, hi = -(1 << 35), (1 << 35) - 1
    ev = REG.new()
    out = np.empty_like(n)
    _div_all(n, d, s, half, lo, hi, ev, out)
    want, clamps = [], 0
    for a, b in zip(n.tolist(), d.tolist()):
        if b <= 0:
            want.append(hi if a >= 0 else lo)
            continue
        w = a << s
        q = w // b
        if half and 2 * (w - q * b) >= b:
            q += 1
        q2, c = _sat(q, lo, hi)
        want.append(q2)
        clamps += c
    np.testing.assert_array_equal(out, want)
    assert ev[ZERO] == int(np.count_nonzero(d <= 0)) >= 3
    assert ev[0] == clamps


def test_flip_is_a_bit_flip_of_the_word():
    width = 12
    v = np.array([5, -5, 2047, -2048, 0, 100], np.int64)
    bit = np.array([0, 11, 11, 11, 3, 6], np.int64)
    out = np.empty_like(v)
    _flip_all(v, bit, width, out)
    for x, b, y in zip(v.tolist(), bit.tolist(), out.tolist()):
        u = (x & ((1 << width) - 1)) ^ (1 << b)          # the stored 12-bit word, flipped
        assert y == (u - (1 << width) if u >> (width - 1) else u)


@pytest.mark.parametrize("dt", [np.float64, np.float32])
def test_float_forms_are_the_plain_operations(dt):
    ev = REG.new()
    v = np.array([4.0, 2.0, -1.0, np.nan], dt)
    out = np.empty_like(v)
    _sqrt_all(v, 0, 1, 0, ev, out)
    np.testing.assert_array_equal(out, np.array([2.0, np.sqrt(dt(2.0)), 0.0, 0.0], dt))
    assert ev[NEG] == 2
    n, d = np.array([1.0, 3.0, 1.0], dt), np.array([3.0, 0.0, -2.0], dt)
    out = np.empty_like(n)
    _div_all(n, d, 0, 1, 0, 0, ev, out)
    np.testing.assert_array_equal(out, np.array([dt(1.0) / dt(3.0), 0.0, 0.0], dt))
    assert ev[ZERO] == 2
    acc = np.array([1.5, -1e30], dt)
    out = np.empty_like(acc)
    _store_all(acc, 5, 1, 0, 0, ev, out)
    np.testing.assert_array_equal(out, acc)
    assert ev[0] == 0
