"""One-source operators for the estimation library: float64, float32 or fixed point by type.

The filters of :mod:`dsp.estimation` are written once in terms of the operators below and
numba compiles them three times, from the type of the state arrays: ``float64`` (the golden
filter), ``float32`` (a floating-point DSP: every operation rounds to float32, in the order
written) and ``int64`` (the fixed-point core: a value ``v`` with ``f`` fraction bits means
``v 2**-f``). This is the habit of :mod:`dsp.qops` (which the TACAN core uses and which stays
as it is); these operators add what a general filter needs: a rounding store, square root,
division, and the event/range layout of :class:`dsp.estimation.events.EventRegistry`
(no fixed slot count).

Fixed-point semantics (each is *one* rounding; checked bit for bit against Python's
unbounded integers in ``tests/dsp/estimation/test_ops.py``):

``store(acc, s, half, lo, hi, ev, i, base)``
    An exact sum of products ``acc`` (``s`` more fraction bits than the destination) shifted
    right by ``s`` with ``floor`` (``half=0``) or ``half_up`` (``half=1``) rounding, then
    saturated to ``[lo, hi]``: a clamp adds 1 to ``ev[i]``; the value before saturation is
    range-logged in ``ev[base + 2 i]`` (min) and ``ev[base + 2 i + 1]`` (max).
``sqrt_q(v, s, half, hi, ev, i, ineg, base)``
    ``sqrt(v 2**s)``, ``s >= 0``: floor or round-to-nearest integer square root, saturated to
    ``hi``. ``v < 0`` is counted in ``ev[ineg]`` and gives 0.
``div_q(n, d, s, half, lo, hi, ev, i, izero, base)``
    ``n 2**s / d`` floored or rounded half up, saturated; ``d <= 0`` is counted in
    ``ev[izero]`` and gives the saturation limit of the numerator's sign.

Floats: ``store`` is the identity, ``sqrt_q`` the square root (a negative or NaN argument
is still counted and gives 0, so a float state never becomes NaN), ``div_q`` the quotient
(``d <= 0`` counted, gives 0).

The callers guarantee that every exact intermediate fits 63 bits (checked from the formats
before a kernel runs, see :func:`dsp.estimation.formats.need_bits`).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import overload

from ..jit import njit_cached
from ..qops import fdiv, align  # noqa: F401  (align re-exported: exact left shift)

_OPTS = {"cache": True}


def _jit_only(*_):
    raise RuntimeError("dsp.estimation.ops operators are for numba kernels (call them inside @njit)")


def _is_int(t):
    return isinstance(t, types.Integer)


def _is_float(t):
    return isinstance(t, types.Float)


@njit(inline="always")
def _note(ev, j, v):
    if v < ev[j]:
        ev[j] = v
    if v > ev[j + 1]:
        ev[j + 1] = v


@njit(inline="always")
def _zero32():
    return np.float32(0.0)


@njit(inline="always")
def _zero64():
    return 0.0


def _zero(t):
    return _zero32 if t == types.float32 else _zero64


def store(acc, s, half, lo, hi, ev, i, base):
    """Round an exact accumulator into a format and saturate (identity for floats)."""
    _jit_only()


@overload(store, jit_options=_OPTS)
def _ol_store(acc, s, half, lo, hi, ev, i, base):
    if _is_int(acc):
        def impl(acc, s, half, lo, hi, ev, i, base):
            if s > 0:
                if half:
                    v = (acc + (np.int64(1) << (s - 1))) >> s
                else:
                    v = acc >> s
            else:
                v = acc << (-s)
            _note(ev, base + 2 * i, v)
            if v < lo:
                ev[i] += 1
                return lo
            if v > hi:
                ev[i] += 1
                return hi
            return v
        return impl
    if _is_float(acc):
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
    _jit_only()


@overload(sqrt_q, jit_options=_OPTS)
def _ol_sqrt_q(v, s, half, hi, ev, i, ineg, base):
    if _is_int(v):
        def impl(v, s, half, hi, ev, i, ineg, base):
            if v < 0:
                ev[ineg] += 1
                return v - v
            w = v << s
            r = isqrt(w)
            # round to nearest: (r + 1/2)^2 = r^2 + r + 1/4 < w  <=>  w - r^2 > r (no ties)
            if half and w - r * r > r:
                r += 1
            _note(ev, base + 2 * i, r)
            if r > hi:
                ev[i] += 1
                return hi
            return r
        return impl
    if _is_float(v):
        zero = _zero(v)

        def impl(v, s, half, hi, ev, i, ineg, base):
            if not v >= 0:  # negative or NaN
                ev[ineg] += 1
                return zero()
            return np.sqrt(v)
        return impl


def div_q(n, d, s, half, lo, hi, ev, i, izero, base):
    """``n 2**s / d``, one rounding, saturated; ``d <= 0`` counted."""
    _jit_only()


@overload(div_q, jit_options=_OPTS)
def _ol_div_q(n, d, s, half, lo, hi, ev, i, izero, base):
    if _is_int(n):
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
            _note(ev, base + 2 * i, q)
            if q < lo:
                ev[i] += 1
                return lo
            if q > hi:
                ev[i] += 1
                return hi
            return q
        return impl
    if _is_float(n):
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
    _jit_only()


@overload(flip, jit_options=_OPTS)
def _ol_flip(v, bit, width):
    if _is_int(v):
        def impl(v, bit, width):
            if bit == width - 1:
                return v ^ (np.int64(-1) << (width - 1))
            return v ^ (np.int64(1) << bit)
        return impl
    if _is_float(v):
        return lambda v, bit, width: v


# --- operators for model functions (the f and h of a fixed-point capable NonlinearModel) ---
# They round but do not saturate: the filter saturates (and counts) what a model returns.

def rnd(acc, s, half):
    """``acc`` with ``s`` fewer fraction bits: shift right with floor (``half=0``) or half-up
    rounding (``s < 0``: exact left shift); the identity for floats."""
    _jit_only()


@overload(rnd, jit_options=_OPTS)
def _ol_rnd(acc, s, half):
    if _is_int(acc):
        def impl(acc, s, half):
            if s > 0:
                if half:
                    return (acc + (np.int64(1) << (s - 1))) >> s
                return acc >> s
            return acc << (-s)
        return impl
    if _is_float(acc):
        return lambda acc, s, half: acc


def sin_q(v, fin, fout, half):
    """``sin`` of ``v`` (``fin`` fraction bits) into ``fout`` fraction bits, one rounding of
    the float64 value (a table/CORDIC of a real core must match it to the last bit; here the
    float64 libm value is the definition). Floats: ``np.sin``."""
    _jit_only()


def cos_q(v, fin, fout, half):
    """``cos``, as :func:`sin_q`."""
    _jit_only()


def _trig_overload(fn):
    def ol(v, fin, fout, half):
        if _is_int(v):
            def impl(v, fin, fout, half):
                t = fn(float(v) * 2.0 ** -float(fin)) * 2.0 ** float(fout)
                return np.int64(math.floor(t + 0.5)) if half else np.int64(math.floor(t))
            return impl
        if _is_float(v):
            return lambda v, fin, fout, half: fn(v)
    return ol


overload(sin_q, jit_options=_OPTS)(_trig_overload(np.sin))
overload(cos_q, jit_options=_OPTS)(_trig_overload(np.cos))
