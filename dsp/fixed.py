"""One typed fixed-point format shared by the HDL blocks, their bit-exact models and the DSP.

A value is stored as an integer ``v`` and means ``v * 2**-frac``. The format also carries
how a wider result is brought back into it: the rounding of dropped LSBs and what happens
on overflow. Every hot path works on vectorised ``int64`` numpy arrays; ``tests`` pin the
semantics against fxpmath.

Rounding modes (what happens to the LSBs dropped by a right shift):

``"floor"``      arithmetic shift right, the free choice in hardware (fxpmath ``floor``).
``"half_up"``    add half an LSB then floor: round half towards +inf (one adder in HDL).
``"half_even"``  convergent rounding, no DC bias (fxpmath ``around``).
``"zero"``       towards zero (fxpmath ``trunc``).

Overflow modes: ``"wrap"`` (two's complement, what a plain adder does) and ``"saturate"``.

Arithmetic kernels (:func:`add`, :func:`sub`, :func:`mul`, :func:`dot`, :func:`matmul`,
:func:`div`, :func:`quantize`, :func:`requantize`) take integer arrays together with their
formats, form the exact result in ``int64``, then round and overflow it once into the output
format, like a DSP's full-precision multiplier/accumulator followed by one store. They
broadcast over any leading batch dimensions. Pass ``log=Counters()`` (and a ``name=``) to
count overflow and division-by-zero events and log the range of each named signal, the way
Fixed-Point Designer's range logging does.

Every exact intermediate must fit in 63 signed bits (checked from the formats before any
work, ``ValueError`` otherwise): for :func:`mul` two signed operands need
``width_a + width_b <= 63`` (e.g. 32 x 31 or 24 x 24 bits). There is no split multiply:
a wider product would need 128-bit intermediates, which no DSP word length here needs.
Integer inputs are assumed to lie in their formats (every kernel output does).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

Rounding = Literal["floor", "half_up", "half_even", "zero"]
Overflow = Literal["wrap", "saturate"]
ROUNDINGS: tuple[str, ...] = ("floor", "half_up", "half_even", "zero")
OVERFLOWS: tuple[str, ...] = ("wrap", "saturate")

#: Largest word length the int64 kernels can hold with headroom for one product.
MAX_WIDTH = 62


def check_width(name: str, value, *, minimum: int = 1, maximum: int = MAX_WIDTH) -> int:
    """Validate an integer word length and return it.

    Raises ``ValueError`` stating the rule and repeating the bad value.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, not {value!r}")
    if not minimum <= int(value) <= maximum:
        raise ValueError(f"{name} must be an integer in [{minimum}, {maximum}], not {value}")
    return int(value)


def parity_bit(words) -> np.ndarray:
    """XOR of all bits of each word (int64 array in, 0/1 int64 array out): even parity is 0.
    The FIFO model appends it (:mod:`hdl.model.fifo`) and the DSP's receiver checks it
    (:mod:`dsp.tacan.fifo_rx`)."""
    v = np.asarray(words, dtype=np.int64).astype(np.uint64)
    for s in (32, 16, 8, 4, 2, 1):
        v = v ^ (v >> np.uint64(s))
    return (v & np.uint64(1)).astype(np.int64)


def check_int(name: str, value, minimum: int) -> int:
    """Validate an integer count or cycle number (``>= minimum``) and return it.

    Raises ``ValueError`` ``"<name> must be an integer >= <minimum>, not <value>"``.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, not {value!r}")
    return int(value)


@dataclass(frozen=True)
class FixedFormat:
    """A two's-complement (or unsigned) fixed-point format.

    Parameters
    ----------
    width : int
        Total word length in bits, sign included (1..62).
    frac : int
        Fraction bits; the LSB weighs ``2**-frac``. May be negative or exceed ``width``.
    signed : bool
        Two's complement if True, unsigned otherwise.
    rounding : {"floor", "half_up", "half_even", "zero"}
        How LSBs dropped when converting into this format are rounded.
    overflow : {"wrap", "saturate"}
        What a value outside the range becomes.
    """

    width: int
    frac: int = 0
    signed: bool = True
    rounding: Rounding = "floor"
    overflow: Overflow = "wrap"

    def __post_init__(self):
        check_width("width", self.width, minimum=2 if self.signed else 1)
        if isinstance(self.frac, bool) or not isinstance(self.frac, (int, np.integer)):
            raise ValueError(f"frac must be an integer, not {self.frac!r}")
        if self.rounding not in ROUNDINGS:
            raise ValueError(f"rounding must be one of {ROUNDINGS}, not {self.rounding!r}")
        if self.overflow not in OVERFLOWS:
            raise ValueError(f"overflow must be one of {OVERFLOWS}, not {self.overflow!r}")

    # -- range ---------------------------------------------------------------------------
    @property
    def int_bits(self) -> int:
        """Integer bits, sign excluded (may be negative)."""
        return self.width - self.frac - (1 if self.signed else 0)

    @property
    def min_int(self) -> int:
        return -(1 << (self.width - 1)) if self.signed else 0

    @property
    def max_int(self) -> int:
        return (1 << (self.width - 1)) - 1 if self.signed else (1 << self.width) - 1

    @property
    def lsb(self) -> float:
        return 2.0 ** -self.frac

    @property
    def min_value(self) -> float:
        return self.min_int * self.lsb

    @property
    def max_value(self) -> float:
        return self.max_int * self.lsb

    def with_(self, **changes) -> "FixedFormat":
        """A copy with some fields changed (for sweeps)."""
        fields = dict(width=self.width, frac=self.frac, signed=self.signed,
                      rounding=self.rounding, overflow=self.overflow)
        fields.update(changes)
        return FixedFormat(**fields)

    def __str__(self) -> str:
        s = "s" if self.signed else "u"
        return f"{s}Q{self.int_bits}.{self.frac}({self.rounding},{self.overflow})"

    # -- conversions -----------------------------------------------------------------------
    def fit(self, v) -> tuple[np.ndarray, int]:
        """Apply the overflow mode to integers already at this format's scale.

        Returns the integers and how many were out of range.
        """
        v = np.asarray(v, dtype=np.int64)
        lo, hi = self.min_int, self.max_int
        over = (v < lo) | (v > hi)
        n = int(np.count_nonzero(over))
        if n == 0:
            return v, 0
        if self.overflow == "saturate":
            return np.clip(v, lo, hi), n
        span = np.int64(1) << np.int64(self.width)
        w = (v - lo) & (span - 1)
        return w + lo, n

    def quantize(self, x, *, log: "Counters | None" = None,
                 name: str = "quantize") -> tuple[np.ndarray, int]:
        """Float values to integers of this format: rounding, then the overflow mode.

        NaN input is refused with a ``ValueError`` (it has no integer meaning). With
        ``log``, the overflow count and the range of the rounded values go to ``log[name]``.
        """
        x = np.asarray(x, dtype=np.float64)
        if np.isnan(x).any():
            raise ValueError(f"cannot quantise NaN to {self}")
        scaled = np.ldexp(x, self.frac)
        r = _round_float(scaled, self.rounding)
        # Clamp before the int cast so +-inf and huge values count as overflow, not UB.
        big = float(1 << 62)
        r = np.clip(r, -big, big)
        v, n = self.fit(r.astype(np.int64))
        if log is not None:
            log.record(name, self, r, n)
        return v, n

    def to_float(self, v) -> np.ndarray:
        return np.ldexp(np.asarray(v, dtype=np.float64), -self.frac)

    def requantize(self, v, src_frac: int, *, log: "Counters | None" = None,
                   name: str = "requantize") -> tuple[np.ndarray, int]:
        """Integers scaled by ``2**-src_frac`` into this format (shift, round, overflow).

        With ``log``, the overflow count and the range before overflow go to ``log[name]``.
        """
        v = np.asarray(v, dtype=np.int64)
        shift = int(src_frac) - self.frac
        if shift > 0:
            v = shift_right(v, shift, self.rounding)
        elif shift < 0:
            v = v << np.int64(-shift)
        r, n = self.fit(v)
        if log is not None:
            log.record(name, self, v, n)
        return r, n


def _round_float(x: np.ndarray, mode: str) -> np.ndarray:
    if mode == "floor":
        return np.floor(x)
    if mode == "half_up":
        return np.floor(x + 0.5)
    if mode == "half_even":
        return np.rint(x)
    if mode == "zero":
        return np.trunc(x)
    raise ValueError(f"rounding must be one of {ROUNDINGS}, not {mode!r}")


def shift_right(v, shift: int, rounding: str = "floor") -> np.ndarray:
    """Arithmetic right shift of int64 values by ``shift`` bits with the given rounding.

    This is exactly what the HDL does when it drops LSBs (``"floor"``: take the upper bits;
    ``"half_up"``: add ``1 << (shift-1)`` first).
    """
    v = np.asarray(v, dtype=np.int64)
    if shift <= 0:
        return v << np.int64(-shift) if shift < 0 else v
    s = np.int64(shift)
    if rounding == "floor":
        return v >> s
    if rounding == "half_up":
        return (v + (np.int64(1) << (s - 1))) >> s
    if rounding == "zero":
        q = v >> s
        rem = v - (q << s)
        return q + ((v < 0) & (rem != 0))
    if rounding == "half_even":
        q = v >> s
        rem = v - (q << s)
        half = np.int64(1) << (s - 1)
        up = (rem > half) | ((rem == half) & ((q & 1) == 1))
        return q + up
    raise ValueError(f"rounding must be one of {ROUNDINGS}, not {rounding!r}")


def wrap(v, width: int, signed: bool = True) -> np.ndarray:
    """Two's-complement wraparound of int64 values to ``width`` bits."""
    v = np.asarray(v, dtype=np.int64)
    mask = (np.int64(1) << np.int64(width)) - 1
    v = v & mask
    if signed:
        v = np.where(v >= (np.int64(1) << np.int64(width - 1)), v - (mask + 1), v)
    return v


# ---------------------------------------------------------------------------------------
# Range logging and events
# ---------------------------------------------------------------------------------------
@dataclass
class SignalStats:
    """What one named signal has seen (Fixed-Point Designer-style range log).

    ``min``/``max`` are real values (``int * 2**-frac``) of the results *before* the
    overflow mode was applied, i.e. the range the format would have needed.
    """

    samples: int = 0
    overflows: int = 0
    div_by_zero: int = 0
    min: float = math.inf
    max: float = -math.inf

    def int_bits_needed(self, signed: bool = True) -> int:
        """Integer bits (sign excluded) that would have held every logged value."""
        if self.samples == 0 or self.max < self.min:
            return 0
        hi = max(self.max, 0.0)
        lo = min(self.min, 0.0)
        need = 0
        while hi >= 2.0 ** need or (signed and lo < -(2.0 ** need)):
            need += 1
        if not signed and lo < 0:
            raise ValueError(f"an unsigned format cannot hold the logged minimum {self.min}")
        return need

    def as_dict(self) -> dict:
        return dict(samples=self.samples, overflows=self.overflows,
                    div_by_zero=self.div_by_zero,
                    min=None if self.samples == 0 else self.min,
                    max=None if self.samples == 0 else self.max)


@dataclass
class Counters:
    """Overflow/division-by-zero events and ranges per named signal, plus free event counts.

    Pass one instance as ``log=`` to the kernels; each call adds to ``signals[name]``.
    ``events`` holds counts of anything else (e.g. ``"kalman_reinit"``) via :meth:`count`.
    """

    signals: dict[str, SignalStats] = field(default_factory=dict)
    events: dict[str, int] = field(default_factory=dict)

    def __getitem__(self, name: str) -> SignalStats:
        return self.signals[name]

    def __contains__(self, name: str) -> bool:
        return name in self.signals

    def record(self, name: str, fmt: FixedFormat, exact, overflows: int,
               div_by_zero: int = 0, samples: int | None = None) -> None:
        """Add one result: ``exact`` are its values at ``fmt``'s scale before overflow.

        ``samples`` (default: ``exact.size + div_by_zero``) is how many values it stands for.
        """
        s = self.signals.get(name)
        if s is None:
            s = self.signals[name] = SignalStats()
        exact = np.asarray(exact)
        s.samples += int(exact.size + div_by_zero) if samples is None else int(samples)
        s.overflows += int(overflows)
        s.div_by_zero += int(div_by_zero)
        if exact.size:
            s.min = min(s.min, math.ldexp(float(exact.min()), -fmt.frac))
            s.max = max(s.max, math.ldexp(float(exact.max()), -fmt.frac))

    def count(self, event: str, n: int = 1) -> None:
        """Count a non-arithmetic event (re-initialisation, rejected input, ...)."""
        self.events[event] = self.events.get(event, 0) + int(n)

    @property
    def overflows(self) -> int:
        """Overflow events over all signals."""
        return sum(s.overflows for s in self.signals.values())

    @property
    def div_by_zero(self) -> int:
        return sum(s.div_by_zero for s in self.signals.values())

    def reset(self) -> None:
        self.signals.clear()
        self.events.clear()

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return dict(signals={k: v.as_dict() for k, v in self.signals.items()},
                    events=dict(self.events), overflows=self.overflows,
                    div_by_zero=self.div_by_zero)


# ---------------------------------------------------------------------------------------
# Vectorised int64 kernels
# ---------------------------------------------------------------------------------------
#: Exact intermediates stay in [-2**62, 2**62) so that a rounding add cannot leave int64.
_LIMIT = 1 << 62


def _bits(lo: int, hi: int) -> int:
    """Signed word length holding [lo, hi]."""
    def one(v):
        return (v.bit_length() if v >= 0 else (-v - 1).bit_length()) + 1
    return max(one(lo), one(hi))


def _check_span(lo: int, hi: int, what: str) -> None:
    if lo < -_LIMIT or hi >= _LIMIT:
        raise ValueError(
            f"{what} needs {_bits(lo, hi)} bits, more than the 63 the int64 kernels hold; "
            f"use narrower operands")


@functools.lru_cache(maxsize=1024)
def _check_left(lo: int, hi: int, shift: int, out: FixedFormat) -> None:
    _check_span(lo << shift, hi << shift, f"result scaled to {out}")


# The static range checks depend on the formats only: cached, so that batch-1 calls pay
# for them once.
@functools.lru_cache(maxsize=1024)
def _sum_range(fa: FixedFormat, fb: FixedFormat, sign: int) -> tuple[int, int, int, int, int]:
    frac = max(fa.frac, fb.frac)
    sa, sb = frac - fa.frac, frac - fb.frac
    if sign > 0:
        lo, hi = (fa.min_int << sa) + (fb.min_int << sb), (fa.max_int << sa) + (fb.max_int << sb)
        _check_span(lo, hi, f"sum of {fa} and {fb}")
    else:
        lo, hi = (fa.min_int << sa) - (fb.max_int << sb), (fa.max_int << sa) - (fb.min_int << sb)
        _check_span(lo, hi, f"difference of {fa} and {fb}")
    return frac, sa, sb, lo, hi


def _fmt(f, what: str) -> FixedFormat:
    if not isinstance(f, FixedFormat):
        raise ValueError(f"{what} must be a FixedFormat, not {f!r}")
    return f


def _ints(x, what: str) -> np.ndarray:
    x = np.asarray(x)
    if x.dtype.kind not in "iu":
        raise ValueError(f"{what} must be an integer array (use quantize() for real values), "
                         f"not dtype {x.dtype}")
    return x.astype(np.int64, copy=False)


def _to_out(v: np.ndarray, frac: int, lo: int, hi: int, out: FixedFormat,
            log: Counters | None, name: str) -> np.ndarray:
    """Round exact ``v`` (scale ``2**-frac``, static range [lo, hi]) into ``out``."""
    shift = frac - out.frac
    if shift > 0:
        v = shift_right(v, shift, out.rounding)
    elif shift < 0:
        _check_left(lo, hi, -shift, out)
        v = v << np.int64(-shift)
    r, n = out.fit(v)
    if log is not None:
        log.record(name, out, v, n)
    return r


def quantize(x, out: FixedFormat, *, log: Counters | None = None,
             name: str = "quantize") -> np.ndarray:
    """Real values to integers of ``out`` (see :meth:`FixedFormat.quantize`); NaN refused."""
    return _fmt(out, "out").quantize(x, log=log, name=name)[0]


def requantize(v, fv: FixedFormat, out: FixedFormat, *, log: Counters | None = None,
               name: str = "requantize") -> np.ndarray:
    """Integers of format ``fv`` into ``out``: shift, round per ``out``, overflow per ``out``."""
    fv = _fmt(fv, "fv")
    _fmt(out, "out")
    return _to_out(_ints(v, "v"), fv.frac, fv.min_int, fv.max_int, out, log, name)


def add(a, fa: FixedFormat, b, fb: FixedFormat, out: FixedFormat, *,
        log: Counters | None = None, name: str = "add") -> np.ndarray:
    """``a + b`` formed exactly (binary points aligned), then rounded/overflowed into ``out``.

    Parameters
    ----------
    a, b : array_like of int
        Stored integers of formats ``fa``/``fb``; broadcast against each other.
    out : FixedFormat
        Result format; its rounding and overflow modes apply.
    log, name : Counters, str
        Where to count overflows and log the range of the result.

    Returns
    -------
    numpy.ndarray of int64, the broadcast shape of ``a`` and ``b``.
    """
    fa, fb, out = _fmt(fa, "fa"), _fmt(fb, "fb"), _fmt(out, "out")
    frac, sa, sb, lo, hi = _sum_range(fa, fb, 1)
    a, b = _ints(a, "a"), _ints(b, "b")
    v = (a << np.int64(sa) if sa else a) + (b << np.int64(sb) if sb else b)
    return _to_out(v, frac, lo, hi, out, log, name)


def sub(a, fa: FixedFormat, b, fb: FixedFormat, out: FixedFormat, *,
        log: Counters | None = None, name: str = "sub") -> np.ndarray:
    """``a - b``, exact then rounded/overflowed into ``out`` (as :func:`add`)."""
    fa, fb, out = _fmt(fa, "fa"), _fmt(fb, "fb"), _fmt(out, "out")
    frac, sa, sb, lo, hi = _sum_range(fa, fb, -1)
    a, b = _ints(a, "a"), _ints(b, "b")
    v = (a << np.int64(sa) if sa else a) - (b << np.int64(sb) if sb else b)
    return _to_out(v, frac, lo, hi, out, log, name)


@functools.lru_cache(maxsize=1024)
def _product_range(fa: FixedFormat, fb: FixedFormat) -> tuple[int, int]:
    c = [x * y for x in (fa.min_int, fa.max_int) for y in (fb.min_int, fb.max_int)]
    lo, hi = min(c), max(c)
    _check_span(lo, hi, f"product of {fa} and {fb}")
    return lo, hi


def mul(a, fa: FixedFormat, b, fb: FixedFormat, out: FixedFormat, *,
        log: Counters | None = None, name: str = "mul") -> np.ndarray:
    """``a * b``: exact product (``fa.frac + fb.frac`` fraction bits), one rounding into ``out``.

    Raises ``ValueError`` from the formats alone if the exact product could need more
    than 63 bits (two signed operands: ``fa.width + fb.width <= 63``).
    """
    fa, fb, out = _fmt(fa, "fa"), _fmt(fb, "fb"), _fmt(out, "out")
    lo, hi = _product_range(fa, fb)
    v = _ints(a, "a") * _ints(b, "b")
    return _to_out(v, fa.frac + fb.frac, lo, hi, out, log, name)


def dot(a, fa: FixedFormat, b, fb: FixedFormat, out: FixedFormat, *,
        acc_width: int | None = 40, acc_overflow: Overflow = "wrap",
        log: Counters | None = None, name: str = "dot") -> np.ndarray:
    """Multiply-accumulate over the last axis: ``(..., n) x (..., n) -> (...)``.

    Each product is exact; they are added in order into an accumulator of ``acc_width``
    bits (signed, at the product's scale, like a DSP's 40-bit accumulator with guard
    bits) whose overflow mode is ``acc_overflow``; then one rounding into ``out``.

    Parameters
    ----------
    acc_width : int or None
        Accumulator word length (2..62). ``None``: an exact accumulator (checked to fit
        63 bits for this ``n``).
    acc_overflow : {"wrap", "saturate"}
        What the accumulator does on overflow (counted in ``log[name + ".acc"]``). Wrap
        is two's complement, so intermediate overflows that cancel leave the right sum.
    """
    fa, fb, out = _fmt(fa, "fa"), _fmt(fb, "fb"), _fmt(out, "out")
    plo, phi = _product_range(fa, fb)
    p = _ints(a, "a") * _ints(b, "b")
    if p.ndim == 0:
        raise ValueError("dot needs arrays with at least one axis to contract")
    n = p.shape[-1]
    pfrac = fa.frac + fb.frac
    if acc_width is None:
        lo, hi = plo * n, phi * n
        _check_span(lo, hi, f"exact sum of {n} products of {fa} and {fb}")
        acc = p.sum(axis=-1)
    else:
        accf = FixedFormat(check_width("acc_width", acc_width, minimum=2), pfrac, True,
                           "floor", acc_overflow)
        lo, hi = accf.min_int, accf.max_int
        acc = np.zeros(p.shape[:-1], dtype=np.int64)
        nover = 0
        amin = amax = None
        for k in range(n):
            acc = acc + p[..., k]
            if log is not None and acc.size:
                lo_k, hi_k = acc.min(), acc.max()
                amin = lo_k if amin is None else min(amin, lo_k)
                amax = hi_k if amax is None else max(amax, hi_k)
            acc, nk = accf.fit(acc)
            nover += nk
        if log is not None:
            ext = np.array([amin, amax] if amin is not None else [], dtype=np.int64)
            log.record(name + ".acc", accf, ext, nover, samples=acc.size)
    return _to_out(acc, pfrac, lo, hi, out, log, name)


def matmul(a, fa: FixedFormat, b, fb: FixedFormat, out: FixedFormat, *,
           acc_width: int | None = 40, acc_overflow: Overflow = "wrap",
           log: Counters | None = None, name: str = "matmul") -> np.ndarray:
    """``(..., m, n) @ (..., n, p) -> (..., m, p)``, each element a :func:`dot`."""
    a, b = _ints(a, "a"), _ints(b, "b")
    if a.ndim < 2 or b.ndim < 2 or a.shape[-1] != b.shape[-2]:
        raise ValueError(f"matmul needs (..., m, n) and (..., n, p) arrays, "
                         f"not shapes {a.shape} and {b.shape}")
    return dot(a[..., :, None, :], fa, np.swapaxes(b, -1, -2)[..., None, :, :], fb, out,
               acc_width=acc_width, acc_overflow=acc_overflow, log=log, name=name)


@functools.lru_cache(maxsize=1024)
def _div_shifts(fa: FixedFormat, fb: FixedFormat, out: FixedFormat) -> tuple[int, int]:
    s = out.frac + fb.frac - fa.frac  # quotient integer = (a * 2**s) / b
    sn, sd = max(s, 0), max(-s, 0)
    _check_span(fa.min_int << sn, fa.max_int << sn, f"dividend {fa} scaled to {out}")
    _check_span(fb.min_int << sd, fb.max_int << sd, f"divisor {fb} scaled to {out}")
    return sn, sd


def div(a, fa: FixedFormat, b, fb: FixedFormat, out: FixedFormat, *,
        log: Counters | None = None, name: str = "div") -> np.ndarray:
    """``a / b`` into ``out``, the exact quotient rounded once per ``out.rounding``.

    Division by zero never raises and never gives NaN: the result is ``out``'s largest
    value (numerator >= 0) or its smallest (numerator < 0), and it is counted in
    ``log[name].div_by_zero`` (not as an overflow).
    """
    fa, fb, out = _fmt(fa, "fa"), _fmt(fb, "fb"), _fmt(out, "out")
    sn, sd = _div_shifts(fa, fb, out)
    a, b = np.broadcast_arrays(_ints(a, "a"), _ints(b, "b"))
    num = a << np.int64(sn) if sn else a
    den = b << np.int64(sd) if sd else b
    zero = den == 0
    neg = den < 0
    num = np.where(neg, -num, num)
    den = np.where(neg, -den, den)
    nzero = int(np.count_nonzero(zero))
    if nzero:
        den = np.where(zero, 1, den)
    q = num // den
    r = num - q * den  # 0 <= r < den
    mode = out.rounding
    if mode == "zero":
        q = q + ((r != 0) & (num < 0))
    elif mode == "half_up":
        q = q + (2 * r >= den)
    elif mode == "half_even":
        q = q + ((2 * r > den) | ((2 * r == den) & ((q & 1) == 1)))
    if nzero:
        q = np.where(zero, 0, q)
    res, nover = out.fit(q)
    if nzero:
        res = np.where(zero, np.where(a < 0, out.min_int, out.max_int), res)
    if log is not None:
        log.record(name, out, q[~zero] if nzero else q, nover, nzero)
    return res
