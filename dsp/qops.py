"""Quantisation operators for numba kernels written once and compiled for float or fixed point.

This is our form of Fixed-Point Designer's *data-type override*: a DSP kernel is written
once, in terms of the operators below, and numba compiles it per data type of its state
arrays -- ``int64`` (the fixed-point core: every operator quantises: shifts with rounding,
saturates and counts, exact wide products, integer division), ``float64`` (the golden
kernel: every operator is the plain real-valued operation; shifts and saturations vanish)
and ``float32`` (a floating-point DSP: every operation rounds to float32, in the order
written). The compiled kernels therefore differ *only* where quantisation happens. The TACAN
Kalman core (:mod:`dsp.tacan.kalman_kernel`) and the estimation library
(:mod:`dsp.estimation`) are both written with them.

The fixed-point value of an ``int64`` ``v`` with ``f`` fraction bits is ``v * 2**-f``; the
float form carries the real value itself. Operators that re-scale (``rs``, ``align``, the
products) take the shift in bits and ignore it for floats. Each is an ordinary Python
function (raising if called outside numba) with a numba ``@overload`` choosing the
implementation from the type of its first value argument.

Events and range log: the saturating operators count a clamp in ``ev[i]`` and record, in
integer mode, the smallest and the largest value they were asked to store *before*
saturation (what Fixed-Point Designer's min/max logging shows) in ``ev[base + 2 i]`` and
``ev[base + 2 i + 1]``. The TACAN core's operators use the fixed layout ``base =``
:data:`RANGE_BASE` with :data:`RANGE_SLOTS` slots (:func:`new_event_array`); the estimation
library's (``store``, ``sqrt_q``, ``div_q``) take ``base`` from
:class:`dsp.estimation.events.EventRegistry` (no fixed slot count).

Integer semantics (what the hardware does; each is *one* rounding, checked bit for bit
against unbounded Python integers in ``tests/dsp/test_qops.py``,
``tests/dsp/tacan/test_tacan_kalman_fixed.py`` and ``tests/dsp/estimation/test_ops.py``):

``rs(v, s, half)``
    ``v / 2**s`` rounded ``floor`` (``half=0``) or ``half_up`` (``half=1``); ``s <= 0``
    shifts left.
``sat(v, lo, hi, ev, i)``
    clamp to ``[lo, hi]``; a clamp adds 1 to ``ev[i]``.
``store(acc, s, half, lo, hi, ev, i, base)``
    An exact sum of products ``acc`` (``s`` more fraction bits than the destination) shifted
    right by ``s`` with ``floor`` or ``half_up`` rounding, then saturated to ``[lo, hi]``.
``mac2(a1, b1, a2, b2, s, k, half)``
    ``(a1 b1 + a2 b2) / 2**s`` exactly rounded, for wide ``a`` whose products with ``b`` do
    not fit 63 bits: each ``a`` is split at ``k`` bits (``k <= s``) and the rounding of the
    full sum is reassembled exactly (in hardware: a DSP-slice cascade).
``div_norm(num, Sn, nb, f, half, lo, hi, ev, i)``
    ``num / S * 2**f`` rounded and saturated, where ``S`` was normalised by :func:`snorm`
    to ``Sn = S / 2**nb`` (``Sn`` < 2**29): long division in two exact integer steps.
``sqrt_q(v, s, half, hi, ev, i, ineg, base)``
    ``sqrt(v 2**s)``, ``s >= 0``: floor or round-to-nearest integer square root, saturated to
    ``hi``. ``v < 0`` is counted in ``ev[ineg]`` and gives 0.
``div_q(n, d, s, half, lo, hi, ev, i, izero, base)``
    ``n 2**s / d`` floored or rounded half up, saturated; ``d <= 0`` is counted in
    ``ev[izero]`` and gives the saturation limit of the numerator's sign.
``sin_q(v, fin, fout, half)``, ``cos_q``
    One rounding of the float64 value (for the model functions of a nonlinear filter: they
    round but do not saturate; the filter saturates what a model returns).

Floats: ``store`` is the identity, ``sqrt_q`` the square root (a negative or NaN argument
is still counted and gives 0, so a float state never becomes NaN), ``div_q`` the quotient
(``d <= 0`` counted, gives 0). The callers guarantee that every exact intermediate fits 63
bits (the estimation library checks it from the formats before a kernel runs,
:func:`dsp.estimation.formats.need_bits`).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import overload

from dsp.jit import njit_cached

#: numba options of every operator's ``@overload`` (the compiled forms are cached).
OVERLOAD_OPTS = {"cache": True}
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
def _note(ev, j, v):
    """Range log: the extremes of the values stored through event slot ``j`` (min at ``j``,
    max at ``j + 1``)."""
    if v < ev[j]:
        ev[j] = v
    if v > ev[j + 1]:
        ev[j + 1] = v


@njit(inline="always")
def _shift(v, s, half):
    """``v / 2**s`` rounded ``floor`` (``half`` false) or ``half_up``; ``s <= 0`` shifts
    left (the integer form of :func:`rs`)."""
    if s <= 0:
        return v << (-s)
    if half:
        return (v + (np.int64(1) << (s - 1))) >> s
    return v >> s


@njit(inline="always")
def _log_clamp(v, lo, hi, ev, i, j):
    """Log ``v`` in range slot ``j`` (:func:`_note`), then clamp it to ``[lo, hi]``, a clamp
    counted in ``ev[i]``: the store step of every saturating operator."""
    _note(ev, j, v)
    if v < lo:
        ev[i] += 1
        return lo
    if v > hi:
        ev[i] += 1
        return hi
    return v


@njit(inline="always")
def _log_cap(v, hi, ev, i, j):
    """:func:`_log_clamp` for a result that cannot be negative (only ``hi`` applies)."""
    _note(ev, j, v)
    if v > hi:
        ev[i] += 1
        return hi
    return v


def jit_only(*_):
    """The Python body of an operator: operators exist only inside numba kernels."""
    raise RuntimeError("dsp.qops operators are for numba kernels (call them inside @njit)")


def is_int(t):
    """Whether numba type ``t`` selects an operator's fixed-point form."""
    return isinstance(t, types.Integer)


def is_float(t):
    """Whether numba type ``t`` selects an operator's float form."""
    return isinstance(t, types.Float)


@njit(inline="always")
def _zero32():
    return np.float32(0.0)


@njit(inline="always")
def _zero64():
    return 0.0


def _zero(t):
    return _zero32 if t == types.float32 else _zero64


# -- re-scaling ------------------------------------------------------------------------------
def rs(v, s, half):
    """Right shift by ``s`` bits with ``floor``/``half_up`` rounding (identity for floats)."""
    jit_only()


@overload(rs, jit_options=OVERLOAD_OPTS)
def _ol_rs(v, s, half):
    if is_int(v):
        return lambda v, s, half: _shift(v, s, half)
    if is_float(v):
        return lambda v, s, half: v


def align(v, s):
    """Move ``v`` to ``s`` more fraction bits (``s >= 0``; identity for floats)."""
    jit_only()


@overload(align, jit_options=OVERLOAD_OPTS)
def _ol_align(v, s):
    if is_int(v):
        return lambda v, s: v << s
    if is_float(v):
        return lambda v, s: v


def lut_index(v, s):
    """Index of ``v`` in a table of step ``2**s`` in ``v``'s units: ``floor(v / 2**s)``
    (integers: an arithmetic shift)."""
    jit_only()


@overload(lut_index, jit_options=OVERLOAD_OPTS)
def _ol_lut_index(v, s):
    if is_int(v):
        def impl(v, s):
            return v >> s if s >= 0 else v << (-s)
        return impl
    if is_float(v):
        return lambda v, s: np.int64(math.floor(v * 2.0 ** (-s)))


def sat(v, lo, hi, ev, i):
    """Saturate to ``[lo, hi]`` counting clamps in ``ev[i]`` (identity for floats)."""
    jit_only()


@overload(sat, jit_options=OVERLOAD_OPTS)
def _ol_sat(v, lo, hi, ev, i):
    if is_int(v):
        return lambda v, lo, hi, ev, i: _log_clamp(v, lo, hi, ev, i, RANGE_BASE + 2 * i)
    if is_float(v):
        return lambda v, lo, hi, ev, i: v


def floor_one(v, ev, i):
    """A variance that must stay positive: below 1 LSB it is raised to 1 LSB and counted
    (identity for floats)."""
    jit_only()


@overload(floor_one, jit_options=OVERLOAD_OPTS)
def _ol_floor_one(v, ev, i):
    if is_int(v):
        def impl(v, ev, i):
            if v < 1:
                ev[i] += 1
                return v - v + 1
            return v
        return impl
    if is_float(v):
        return lambda v, ev, i: v


def store(acc, s, half, lo, hi, ev, i, base):
    """Round an exact accumulator into a format and saturate (identity for floats)."""
    jit_only()


@overload(store, jit_options=OVERLOAD_OPTS)
def _ol_store(acc, s, half, lo, hi, ev, i, base):
    if is_int(acc):
        def impl(acc, s, half, lo, hi, ev, i, base):
            return _log_clamp(_shift(acc, s, half), lo, hi, ev, i, base + 2 * i)
        return impl
    if is_float(acc):
        return lambda acc, s, half, lo, hi, ev, i, base: acc


@njit_cached
def isqrt(w):
    """``floor(sqrt(w))`` for ``0 <= w < 2**62``, exactly."""
    r = np.int64(math.sqrt(float(w)))
    while r * r > w:
        r -= 1
    while (r + 1) * (r + 1) <= w:
        r += 1
    return r


def sqrt_q(v, s, half, hi, ev, i, ineg, base):
    """Square root, one rounding; a negative argument is counted and gives 0."""
    jit_only()


@overload(sqrt_q, jit_options=OVERLOAD_OPTS)
def _ol_sqrt_q(v, s, half, hi, ev, i, ineg, base):
    if is_int(v):
        def impl(v, s, half, hi, ev, i, ineg, base):
            if v < 0:
                ev[ineg] += 1
                return v - v
            w = v << s
            r = isqrt(w)
            # round to nearest: (r + 1/2)^2 = r^2 + r + 1/4 < w  <=>  w - r^2 > r (no ties)
            if half and w - r * r > r:
                r += 1
            return _log_cap(r, hi, ev, i, base + 2 * i)
        return impl
    if is_float(v):
        zero = _zero(v)

        def impl(v, s, half, hi, ev, i, ineg, base):
            if not v >= 0:  # negative or NaN
                ev[ineg] += 1
                return zero()
            return np.sqrt(v)
        return impl


def div_q(n, d, s, half, lo, hi, ev, i, izero, base):
    """``n 2**s / d``, one rounding, saturated; ``d <= 0`` counted."""
    jit_only()


@overload(div_q, jit_options=OVERLOAD_OPTS)
def _ol_div_q(n, d, s, half, lo, hi, ev, i, izero, base):
    if is_int(n):
        def impl(n, d, s, half, lo, hi, ev, i, izero, base):
            if d <= 0:
                ev[izero] += 1
                return hi if n >= 0 else lo
            w = n << s
            q = fdiv(w, d)
            if half:
                rem = w - q * d
                if 2 * rem >= d:
                    q += 1
            return _log_clamp(q, lo, hi, ev, i, base + 2 * i)
        return impl
    if is_float(n):
        zero = _zero(n)

        def impl(n, d, s, half, lo, hi, ev, i, izero, base):
            if not d > 0:
                ev[izero] += 1
                return zero()
            return n / d
        return impl


def flip(v, bit, width):
    """Flip ``bit`` of a ``width``-bit two's-complement word held sign-extended in int64
    (a state-word upset; flipping the sign bit flips the extension with it). Floats: the
    identity (upsets are refused for float filters before a kernel runs)."""
    jit_only()


@overload(flip, jit_options=OVERLOAD_OPTS)
def _ol_flip(v, bit, width):
    if is_int(v):
        def impl(v, bit, width):
            if bit == width - 1:
                return v ^ (np.int64(-1) << (width - 1))
            return v ^ (np.int64(1) << bit)
        return impl
    if is_float(v):
        return lambda v, bit, width: v


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
    jit_only()


@overload(mac2, jit_options=OVERLOAD_OPTS)
def _ol_mac2(a1, b1, a2, b2, s, k, half):
    if is_int(a1):
        split = _split

        def impl(a1, b1, a2, b2, s, k, half):
            q1, l1 = split(a1, b1, s, k)
            q2, l2 = split(a2, b2, s, k)
            v = l1 + l2
            if half:
                v += np.int64(1) << (s - 1)
            return q1 + q2 + (v >> s)
        return impl
    if is_float(a1):
        return lambda a1, b1, a2, b2, s, k, half: a1 * b1 + a2 * b2


def mulw(a, b, s, k, half):
    """``a b / 2**s`` exactly rounded for a wide ``a`` (``mac2`` with one product)."""
    jit_only()


@overload(mulw, jit_options=OVERLOAD_OPTS)
def _ol_mulw(a, b, s, k, half):
    if is_int(a):
        split = _split

        def impl(a, b, s, k, half):
            q, lo = split(a, b, s, k)
            if half:
                lo += np.int64(1) << (s - 1)
            return q + (lo >> s)
        return impl
    if is_float(a):
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
    jit_only()


@overload(snorm, jit_options=OVERLOAD_OPTS)
def _ol_snorm(S):
    if is_int(S):
        def impl(S):
            nb = _bitlen(S) - S_BITS
            return _shift(S, nb, True), nb
        return impl
    if is_float(S):
        return lambda S: (S, 0)


def div_norm(num, Sn, nb, f, half, lo, hi, ev, i):
    """``num / S`` at ``f`` more fraction bits than ``num`` has over ``S``, saturated."""
    jit_only()


@overload(div_norm, jit_options=OVERLOAD_OPTS)
def _ol_div_norm(num, Sn, nb, f, half, lo, hi, ev, i):
    if is_int(num):
        def impl(num, Sn, nb, f, half, lo, hi, ev, i):
            n = _shift(num, nb, True)
            q1 = fdiv(n, Sn)
            rem = n - q1 * Sn
            if q1 >= (np.int64(1) << (61 - f)) or q1 < -(np.int64(1) << (61 - f)):
                q = hi + 1 if q1 > 0 else lo - 1
            else:
                nn = rem << f
                if half:
                    nn += Sn >> 1
                q = (q1 << f) + fdiv(nn, Sn)
            return _log_clamp(q, lo, hi, ev, i, RANGE_BASE + 2 * i)
        return impl
    if is_float(num):
        return lambda num, Sn, nb, f, half, lo, hi, ev, i: num / Sn


def div_square(v, Sn, nb, t, half, hi, ev, i):
    """``v**2 / S`` re-scaled by ``2**t`` (before the ``nb`` normalisation), saturated to
    ``hi`` (non-negative result)."""
    jit_only()


@overload(div_square, jit_options=OVERLOAD_OPTS)
def _ol_div_square(v, Sn, nb, t, half, hi, ev, i):
    if is_int(v):
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
            return _log_cap(e, hi, ev, i, RANGE_BASE + 2 * i)
        return impl
    if is_float(v):
        return lambda v, Sn, nb, t, half, hi, ev, i: v * v / Sn


def ewma(r, acc, m, half, lo, hi, ev, i):
    """``r + (acc - r) / m`` (``m`` a positive integer), rounded and saturated."""
    jit_only()


@overload(ewma, jit_options=OVERLOAD_OPTS)
def _ol_ewma(r, acc, m, half, lo, hi, ev, i):
    if is_int(r):
        def impl(r, acc, m, half, lo, hi, ev, i):
            d = acc - r
            if half:
                d += m // 2
            v = r + fdiv(d, m)
            return _log_clamp(v, lo, hi, ev, i, RANGE_BASE + 2 * i)
        return impl
    if is_float(r):
        return lambda r, acc, m, half, lo, hi, ev, i: r + (acc - r) / m


def scale_sat(g, r, f, hi):
    """``g r / 2**f`` (``g >= 0`` a constant with ``f`` fraction bits), floored, capped at
    ``hi`` without overflowing; floats: ``g r``."""
    jit_only()


@overload(scale_sat, jit_options=OVERLOAD_OPTS)
def _ol_scale_sat(g, r, f, hi):
    if is_int(r):
        def impl(g, r, f, hi):
            if r > ((np.int64(1) << 62) - 1) // g:
                return hi
            v = (g * r) >> f
            return hi if v > hi else v
        return impl
    if is_float(r):
        return lambda g, r, f, hi: g * r


# -- trigonometry for model functions (round, do not saturate) -------------------------
def sin_q(v, fin, fout, half):
    """``sin`` of ``v`` (``fin`` fraction bits) into ``fout`` fraction bits, one rounding of
    the float64 value (a table/CORDIC of a real core must match it to the last bit; here the
    float64 libm value is the definition). Floats: ``np.sin``."""
    jit_only()


def cos_q(v, fin, fout, half):
    """``cos``, as :func:`sin_q`."""
    jit_only()


def _trig_overload(fn):
    def ol(v, fin, fout, half):
        if is_int(v):
            def impl(v, fin, fout, half):
                t = fn(float(v) * 2.0 ** -float(fin)) * 2.0 ** float(fout)
                return np.int64(math.floor(t + 0.5)) if half else np.int64(math.floor(t))
            return impl
        if is_float(v):
            return lambda v, fin, fout, half: fn(v)
    return ol


overload(sin_q, jit_options=OVERLOAD_OPTS)(_trig_overload(np.sin))
overload(cos_q, jit_options=OVERLOAD_OPTS)(_trig_overload(np.cos))
