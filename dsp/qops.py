"""Quantisation operators for numba kernels that run in float or fixed point by data type.

This is our form of Fixed-Point Designer's *data-type override*: a DSP kernel is written
once, in terms of the operators below, and numba compiles it twice -- once for ``int64``
arrays (every operator quantises: shifts with rounding, saturates and counts, exact wide
products, integer division) and once for ``float64`` arrays (every operator is the plain
real-valued operation: shifts and saturations vanish, products and quotients are exact up
to float64). The two compiled kernels therefore differ *only* where quantisation happens.

The fixed-point value of an ``int64`` ``v`` with ``f`` fraction bits is ``v * 2**-f``; the
float form carries the real value itself. Operators that re-scale (``rs``, ``align``, the
products) take the shift in bits and ignore it for floats. Each is an ordinary Python
function (raising if called outside numba) with a numba ``@overload`` choosing the
implementation from the type of its first value argument.

Integer semantics (what the hardware does; checked bit for bit against unbounded Python
integers in ``tests/dsp/test_tacan_kalman.py``):

``rs(v, s, half)``
    ``v / 2**s`` rounded ``floor`` (``half=0``) or ``half_up`` (``half=1``); ``s <= 0``
    shifts left.
``sat(v, lo, hi, ev, i)``
    clamp to ``[lo, hi]``; a clamp adds 1 to ``ev[i]``.
``mac2(a1, b1, a2, b2, s, k, half)``
    ``(a1 b1 + a2 b2) / 2**s`` exactly rounded, for wide ``a`` whose products with ``b`` do
    not fit 63 bits: each ``a`` is split at ``k`` bits (``k <= s``) and the rounding of the
    full sum is reassembled exactly (in hardware: a DSP-slice cascade).
``div_norm(num, Sn, nb, f, half, lo, hi, ev, i)``
    ``num / S * 2**f`` rounded and saturated, where ``S`` was normalised by :func:`snorm`
    to ``Sn = S / 2**nb`` (``Sn`` < 2**29): long division in two exact integer steps.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import overload

from dsp.jit import njit_cached

_OPTS = {"cache": True}
#: Bits of the normalised divisor (see :func:`snorm`).
S_BITS = 28
#: Range log: the saturating operators also record, in integer mode, the smallest and the
#: largest value they were asked to store *before* saturation (what Fixed-Point Designer's
#: min/max logging shows), in ``ev[RANGE_BASE + 2 i]`` and ``ev[RANGE_BASE + 2 i + 1]`` for
#: the event index ``i`` (``0 <= i < RANGE_SLOTS``). The event array must have
#: ``RANGE_BASE + 2 RANGE_SLOTS`` entries, the min slots starting at the int64 maximum and the
#: max slots at the int64 minimum (:func:`new_event_array`).
RANGE_BASE = 16
RANGE_SLOTS = 8


def new_event_array(shape_prefix) -> np.ndarray:
    """An event/range array for the operators below: counts 0, range slots empty."""
    ev = np.zeros(tuple(shape_prefix) + (RANGE_BASE + 2 * RANGE_SLOTS,), np.int64)
    ev[..., RANGE_BASE::2] = np.iinfo(np.int64).max
    ev[..., RANGE_BASE + 1::2] = np.iinfo(np.int64).min
    return ev


@njit(inline="always")
def _note(ev, i, v):
    j = RANGE_BASE + 2 * i
    if v < ev[j]:
        ev[j] = v
    if v > ev[j + 1]:
        ev[j + 1] = v


def _jit_only(*_):
    raise RuntimeError("dsp.qops operators are for numba kernels (call them inside @njit)")


def _is_int(t):
    return isinstance(t, types.Integer)


def _is_float(t):
    return isinstance(t, types.Float)


# -- re-scaling ------------------------------------------------------------------------------
def rs(v, s, half):
    """Right shift by ``s`` bits with ``floor``/``half_up`` rounding (identity for floats)."""
    _jit_only()


@overload(rs, jit_options=_OPTS)
def _ol_rs(v, s, half):
    if _is_int(v):
        def impl(v, s, half):
            if s <= 0:
                return v << (-s)
            if half:
                return (v + (np.int64(1) << (s - 1))) >> s
            return v >> s
        return impl
    if _is_float(v):
        return lambda v, s, half: v


def align(v, s):
    """Move ``v`` to ``s`` more fraction bits (``s >= 0``; identity for floats)."""
    _jit_only()


@overload(align, jit_options=_OPTS)
def _ol_align(v, s):
    if _is_int(v):
        return lambda v, s: v << s
    if _is_float(v):
        return lambda v, s: v


def lut_index(v, s):
    """Index of ``v`` in a table of step ``2**s`` in ``v``'s units: ``floor(v / 2**s)``
    (integers: an arithmetic shift)."""
    _jit_only()


@overload(lut_index, jit_options=_OPTS)
def _ol_lut_index(v, s):
    if _is_int(v):
        def impl(v, s):
            return v >> s if s >= 0 else v << (-s)
        return impl
    if _is_float(v):
        return lambda v, s: np.int64(math.floor(v * 2.0 ** (-s)))


def sat(v, lo, hi, ev, i):
    """Saturate to ``[lo, hi]`` counting clamps in ``ev[i]`` (identity for floats)."""
    _jit_only()


@overload(sat, jit_options=_OPTS)
def _ol_sat(v, lo, hi, ev, i):
    if _is_int(v):
        def impl(v, lo, hi, ev, i):
            _note(ev, i, v)
            if v < lo:
                ev[i] += 1
                return lo
            if v > hi:
                ev[i] += 1
                return hi
            return v
        return impl
    if _is_float(v):
        return lambda v, lo, hi, ev, i: v


def floor_one(v, ev, i):
    """A variance that must stay positive: below 1 LSB it is raised to 1 LSB and counted
    (identity for floats)."""
    _jit_only()


@overload(floor_one, jit_options=_OPTS)
def _ol_floor_one(v, ev, i):
    if _is_int(v):
        def impl(v, ev, i):
            if v < 1:
                ev[i] += 1
                return v - v + 1
            return v
        return impl
    if _is_float(v):
        return lambda v, ev, i: v


# -- products --------------------------------------------------------------------------------
@njit_cached
def _split(a, b, s, k):
    """``(Q, low)`` with ``a b = Q 2**s + low`` exactly (``k <= s``)."""
    ah = a >> k
    al = a - (ah << k)
    p = ah * b
    q = p >> (s - k)
    rem = p - (q << (s - k))
    return q, (rem << k) + al * b


def mac2(a1, b1, a2, b2, s, k, half):
    """``(a1 b1 + a2 b2) / 2**s`` exactly rounded for a wide ``a`` (split at ``k`` bits)."""
    _jit_only()


@overload(mac2, jit_options=_OPTS)
def _ol_mac2(a1, b1, a2, b2, s, k, half):
    if _is_int(a1):
        split = _split

        def impl(a1, b1, a2, b2, s, k, half):
            q1, l1 = split(a1, b1, s, k)
            q2, l2 = split(a2, b2, s, k)
            v = l1 + l2
            if half:
                v += np.int64(1) << (s - 1)
            return q1 + q2 + (v >> s)
        return impl
    if _is_float(a1):
        return lambda a1, b1, a2, b2, s, k, half: a1 * b1 + a2 * b2


def mulw(a, b, s, k, half):
    """``a b / 2**s`` exactly rounded for a wide ``a`` (``mac2`` with one product)."""
    _jit_only()


@overload(mulw, jit_options=_OPTS)
def _ol_mulw(a, b, s, k, half):
    if _is_int(a):
        split = _split

        def impl(a, b, s, k, half):
            q, lo = split(a, b, s, k)
            if half:
                lo += np.int64(1) << (s - 1)
            return q + (lo >> s)
        return impl
    if _is_float(a):
        return lambda a, b, s, k, half: a * b


# -- division --------------------------------------------------------------------------------
@njit_cached
def fdiv(n, d):
    """``n // d`` (floor) for int64 ``n`` and ``0 < d < 2**53``, exactly, via one float
    division and a remainder correction (a hardware integer divide is ~4x slower here)."""
    q = np.int64(math.floor(float(n) / float(d)))
    r = n - q * d
    while r < 0:
        q -= 1
        r += d
    while r >= d:
        q += 1
        r -= d
    return q


@njit_cached
def _bitlen(v):
    """Bits of ``v > 0`` (``int.bit_length``)."""
    m, e = math.frexp(float(v))
    if e > 0 and (v >> (e - 1)) == 0:
        e -= 1
    elif e < 63 and (v >> e) != 0:
        e += 1
    return e


def snorm(S):
    """``(Sn, nb)``: a positive divisor scaled to ``S_BITS`` bits, ``Sn = S / 2**nb``
    (rounded half-up); floats: ``(S, 0)``."""
    _jit_only()


@overload(snorm, jit_options=_OPTS)
def _ol_snorm(S):
    if _is_int(S):
        def impl(S):
            nb = _bitlen(S) - S_BITS
            if nb > 0:
                return (S + (np.int64(1) << (nb - 1))) >> nb, nb
            return S << (-nb), nb
        return impl
    if _is_float(S):
        return lambda S: (S, 0)


def div_norm(num, Sn, nb, f, half, lo, hi, ev, i):
    """``num / S`` at ``f`` more fraction bits than ``num`` has over ``S``, saturated."""
    _jit_only()


@overload(div_norm, jit_options=_OPTS)
def _ol_div_norm(num, Sn, nb, f, half, lo, hi, ev, i):
    if _is_int(num):
        def impl(num, Sn, nb, f, half, lo, hi, ev, i):
            if nb > 0:
                n = (num + (np.int64(1) << (nb - 1))) >> nb
            else:
                n = num << (-nb)
            q1 = fdiv(n, Sn)
            rem = n - q1 * Sn
            if q1 >= (np.int64(1) << (61 - f)) or q1 < -(np.int64(1) << (61 - f)):
                q = hi + 1 if q1 > 0 else lo - 1
            else:
                nn = rem << f
                if half:
                    nn += Sn >> 1
                q = (q1 << f) + fdiv(nn, Sn)
            _note(ev, i, q)
            if q < lo:
                ev[i] += 1
                return lo
            if q > hi:
                ev[i] += 1
                return hi
            return q
        return impl
    if _is_float(num):
        return lambda num, Sn, nb, f, half, lo, hi, ev, i: num / Sn


def div_square(v, Sn, nb, t, half, hi, ev, i):
    """``v**2 / S`` re-scaled by ``2**t`` (before the ``nb`` normalisation), saturated to
    ``hi`` (non-negative result)."""
    _jit_only()


@overload(div_square, jit_options=_OPTS)
def _ol_div_square(v, Sn, nb, t, half, hi, ev, i):
    if _is_int(v):
        def impl(v, Sn, nb, t, half, hi, ev, i):
            tt = t - nb
            v2 = v * v
            if tt >= 0:
                q1 = fdiv(v2, Sn)
                rem = v2 - q1 * Sn
                if tt > 61 or (q1 >> max(61 - tt, 0)) != 0:
                    e = hi + 1
                else:
                    num = rem << tt
                    if half:
                        num += Sn >> 1
                    e = (q1 << tt) + fdiv(num, Sn)
            else:
                den = Sn << (-tt)
                e = fdiv(v2 + ((den >> 1) if half else 0), den)
            _note(ev, i, e)
            if e > hi:
                ev[i] += 1
                return hi
            return e
        return impl
    if _is_float(v):
        return lambda v, Sn, nb, t, half, hi, ev, i: v * v / Sn


def ewma(r, acc, m, half, lo, hi, ev, i):
    """``r + (acc - r) / m`` (``m`` a positive integer), rounded and saturated."""
    _jit_only()


@overload(ewma, jit_options=_OPTS)
def _ol_ewma(r, acc, m, half, lo, hi, ev, i):
    if _is_int(r):
        def impl(r, acc, m, half, lo, hi, ev, i):
            d = acc - r
            if half:
                d += m // 2
            v = r + fdiv(d, m)
            _note(ev, i, v)
            if v < lo:
                ev[i] += 1
                return lo
            if v > hi:
                ev[i] += 1
                return hi
            return v
        return impl
    if _is_float(r):
        return lambda r, acc, m, half, lo, hi, ev, i: r + (acc - r) / m


def scale_sat(g, r, f, hi):
    """``g r / 2**f`` (``g >= 0`` a constant with ``f`` fraction bits), floored, capped at
    ``hi`` without overflowing; floats: ``g r``."""
    _jit_only()


@overload(scale_sat, jit_options=_OPTS)
def _ol_scale_sat(g, r, f, hi):
    if _is_int(r):
        def impl(g, r, f, hi):
            if r > ((np.int64(1) << 62) - 1) // g:
                return hi
            v = (g * r) >> f
            return hi if v > hi else v
        return impl
    if _is_float(r):
        return lambda g, r, f, hi: g * r


# -- time -> phase, sin/cos ------------------------------------------------------------------
#: Phase accumulator width (bits) and sine ROM size (log2 entries, full circle).
PHASE_BITS = 40
LUT_BITS = 10
TRIG_FRAC = 30
SIN_LUT = np.round(np.sin(2 * np.pi * np.arange(1 << LUT_BITS) / (1 << LUT_BITS))
                   * (1 << TRIG_FRAC)).astype(np.int64)
_TWO_PI_30 = int(round(2 * math.pi * (1 << 30)))


def sincos_dt(lut, dt, fw, cs_frac, half):
    """``(sin, cos)`` of the phase advance over ``dt``.

    Integers: ``dt`` in ticks, ``fw`` the ``PHASE_BITS`` frequency word; phase ``dt fw mod
    2**40`` from a ``2**LUT_BITS``-entry full-circle sine ROM (``TRIG_FRAC`` fraction
    bits) plus a 3rd-order Taylor correction of the residual angle (< 1e-12), rounded once
    to ``cs_frac`` fraction bits. Floats: ``dt`` in seconds, ``fw = 2 pi f``.
    """
    _jit_only()


@overload(sincos_dt, jit_options=_OPTS)
def _ol_sincos_dt(lut, dt, fw, cs_frac, half):
    if _is_int(dt):
        def impl(lut, dt, fw, cs_frac, half):
            phase = (dt * fw) & ((np.int64(1) << PHASE_BITS) - 1)
            sh = PHASE_BITS - LUT_BITS
            idx = phase >> sh
            d = phase - (idx << sh)
            s0 = lut[idx]
            c0 = lut[(idx + (1 << (LUT_BITS - 2))) & ((1 << LUT_BITS) - 1)]
            # residual angle at 30 fraction bits (d >> 8 keeps the product in 63 bits)
            dl = ((d >> 8) * _TWO_PI_30 + (np.int64(1) << (PHASE_BITS - 9))) >> (PHASE_BITS - 8)
            d2 = (dl * dl + (np.int64(1) << (TRIG_FRAC - 1))) >> TRIG_FRAC
            d3 = (d2 * dl + (np.int64(1) << (TRIG_FRAC - 1))) >> TRIG_FRAC
            cd = (np.int64(1) << TRIG_FRAC) - (d2 >> 1)
            sd = dl - d3 // 6
            sh2 = 2 * TRIG_FRAC - cs_frac
            rnd = (np.int64(1) << (sh2 - 1)) if half else np.int64(0)
            sn = (s0 * cd + c0 * sd + rnd) >> sh2
            cn = (c0 * cd - s0 * sd + rnd) >> sh2
            return sn, cn
        return impl
    if _is_float(dt):
        def impl(lut, dt, fw, cs_frac, half):
            a = fw * dt
            return math.sin(a), math.cos(a)
        return impl


def rate_dt(q, dt, extra, half):
    """Process noise ``q dt``: integers ``q`` per tick at ``extra`` more fraction bits
    (``q dt`` capped below 2**61 before the shift); floats ``q`` per second."""
    _jit_only()


@overload(rate_dt, jit_options=_OPTS)
def _ol_rate_dt(q, dt, extra, half):
    if _is_int(dt):
        def impl(q, dt, extra, half):
            lim = (np.int64(1) << 61) // max(q, np.int64(1))
            dq = dt if dt <= lim else lim
            v = q * dq
            if half:
                v += np.int64(1) << (extra - 1)
            return v >> extra
        return impl
    if _is_float(dt):
        return lambda q, dt, extra, half: q * dt
