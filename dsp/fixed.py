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

Arithmetic lives with the cores that use it: the one-source numba operators of
:mod:`dsp.qops` (TACAN core) and :mod:`dsp.qops` (estimation library), which count
saturations and log ranges per signal (:class:`dsp.estimation.events.EventRegistry`). The
array kernels this module once had (``add`` ... ``div``, ``Counters``, ``SignalStats``) had
no production caller and were removed.
"""
from __future__ import annotations

from dataclasses import dataclass
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

    def quantize(self, x) -> tuple[np.ndarray, int]:
        """Float values to integers of this format: rounding, then the overflow mode.
        Returns the integers and how many were out of range.

        NaN input is refused with a ``ValueError`` (it has no integer meaning).
        """
        x = np.asarray(x, dtype=np.float64)
        if np.isnan(x).any():
            raise ValueError(f"cannot quantise NaN to {self}")
        scaled = np.ldexp(x, self.frac)
        r = _round_float(scaled, self.rounding)
        # Clamp before the int cast so +-inf and huge values count as overflow, not UB.
        big = float(1 << 62)
        r = np.clip(r, -big, big)
        return self.fit(r.astype(np.int64))

    def to_float(self, v) -> np.ndarray:
        return np.ldexp(np.asarray(v, dtype=np.float64), -self.frac)

    def requantize(self, v, src_frac: int) -> tuple[np.ndarray, int]:
        """Integers scaled by ``2**-src_frac`` into this format (shift, round, overflow).
        Returns the integers and how many were out of range."""
        v = np.asarray(v, dtype=np.int64)
        shift = int(src_frac) - self.frac
        if shift > 0:
            v = shift_right(v, shift, self.rounding)
        elif shift < 0:
            v = v << np.int64(-shift)
        return self.fit(v)


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


def check_samples(what: str, x, width: int, sample_shape: tuple = (),
                  shape_note: str = "") -> np.ndarray:
    """Input samples of a block: integers of shape ``(n, *sample_shape)`` that fit in
    ``width`` signed bits, as int64; else a ``ValueError`` naming ``what`` (the block's
    input; ``shape_note`` follows the shape wanted, e.g. ``" for channels=2"``)."""
    x = np.asarray(x)
    if x.dtype.kind not in "iu":
        raise ValueError(f"{what} must be integers, not dtype {x.dtype}")
    x = x.astype(np.int64, copy=False)
    if x.ndim < 1 or x.shape[1:] != tuple(sample_shape):
        raise ValueError(f"{what} must have shape (n, *{sample_shape}){shape_note}, not "
                         f"{x.shape}")
    if x.size:
        lo, hi = -(1 << (width - 1)), (1 << (width - 1)) - 1
        xmin, xmax = x.min(), x.max()
        if xmin < lo or xmax > hi:
            raise ValueError(f"{what} must fit in {width} signed bits [{lo}, {hi}], not "
                             f"range [{xmin}, {xmax}]")
    return x
