"""Per-signal fixed-point format tables and the checks every filter configuration runs.

A filter's fixed-point configuration is a frozen dataclass whose fields are the
:class:`dsp.fixed.FixedFormat` of each named signal (one table, no magic indices); the
kernels receive its fraction bits and limits as arrays indexed by the signal's position in
the table (:meth:`FormatTable.arrays`), and the same order names the saturation counters and
range logs of :class:`dsp.estimation.events.EventRegistry`.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
import math

import numpy as np

from ..fixed import FixedFormat

#: The widest exact intermediate the int64 kernels may form (sign included).
ACC_BITS = 63
#: Arithmetics a filter runs in besides fixed point.
FLOATS = ("float64", "float32")


def fmt(width: int, frac: int) -> FixedFormat:
    """A signed, half-up rounding, saturating format (the default of every table)."""
    return FixedFormat(width, frac, True, "half_up", "saturate")


class FormatTable:
    """Mixin for the frozen dataclasses that hold one format per signal."""

    @classmethod
    def signals(cls) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(cls))

    def validate(self) -> None:
        for name in self.signals():
            f = getattr(self, name)
            if not isinstance(f, FixedFormat):
                raise ValueError(f"format of signal {name!r} must be a dsp.fixed.FixedFormat, "
                                 f"not {f!r}")
            if not f.signed:
                raise ValueError(f"format of signal {name!r} must be signed, not {f}")
            if f.rounding not in ("floor", "half_up"):
                raise ValueError(f"format of signal {name!r} must round 'floor' or 'half_up', "
                                 f"not {f.rounding!r}")
            if f.overflow != "saturate":
                raise ValueError(f"format of signal {name!r} must saturate (a wrapped state "
                                 f"word is a divergence), not {f.overflow!r}")

    def arrays(self):
        """``(frac, lo, hi, half, width)`` int64 arrays in signal order."""
        fs = [getattr(self, n) for n in self.signals()]
        return (np.array([f.frac for f in fs], np.int64),
                np.array([f.min_int for f in fs], np.int64),
                np.array([f.max_int for f in fs], np.int64),
                np.array([1 if f.rounding == "half_up" else 0 for f in fs], np.int64),
                np.array([f.width for f in fs], np.int64))

    def fracs(self) -> dict:
        return {n: getattr(self, n).frac for n in self.signals()}

    def with_(self, **changes):
        """A copy with some signals' formats replaced (for word-length sweeps)."""
        return dataclasses.replace(self, **changes)


def need_bits(step: str, bits: int) -> None:
    """Raise if an exact intermediate of ``step`` needs more than :data:`ACC_BITS` bits."""
    if bits > ACC_BITS:
        raise ValueError(f"formats too wide for the int64 datapath: {step} needs {bits} bits "
                         f"(at most {ACC_BITS})")


def sum_bits(wa: int, wb: int, terms: int) -> int:
    """Bits of an exact signed sum of ``terms`` products of ``wa``- and ``wb``-bit words."""
    return wa + wb - 1 + max(1, math.ceil(math.log2(max(terms, 1)))) if terms > 1 else wa + wb - 1


def need_shift(step: str, shift: int, what: str) -> int:
    """An alignment shift must be >= 0 (no rounding where none is documented)."""
    if shift < 0:
        raise ValueError(f"formats inconsistent: {step} would drop {-shift} fraction bits of "
                         f"{what} (give it at most as many fraction bits as the accumulator)")
    return shift


def fits(what: str, values, f: FixedFormat) -> None:
    """Raise ``formats too narrow`` if any value lies outside ``f``'s range."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return
    big = float(np.max(np.abs(v)))
    if not (np.all(v <= f.max_value) and np.all(v >= f.min_value)):
        raise ValueError(f"format too narrow for {what}: {f} holds [{f.min_value:g}, "
                         f"{f.max_value:g}], not max |{what}| = {big:g}")


def to_fixed(values, f: FixedFormat) -> np.ndarray:
    """Round floats into ``f`` (its rounding); the caller has checked the range."""
    v = np.ldexp(np.asarray(values, dtype=np.float64), f.frac)
    v = np.floor(v + 0.5) if f.rounding == "half_up" else np.floor(v)
    return v.astype(np.int64)


def arithmetic_name(arith) -> str:
    """``"float64"``, ``"float32"`` or ``"fixed"``; anything else is refused."""
    if isinstance(arith, str):
        if arith in FLOATS:
            return arith
        raise ValueError(f"arithmetic must be 'float64', 'float32' or a format table, not {arith!r}")
    if isinstance(arith, FormatTable):
        return "fixed"
    raise ValueError(f"arithmetic must be 'float64', 'float32' or a format table, not {arith!r}")


@dataclass(frozen=True)
class Arithmetic:
    """The arithmetic a filter runs in, resolved once from its ``arithmetic`` argument: the
    kind (``"float64"``, ``"float32"`` or ``"fixed"``), the state dtype, the format table
    (fixed point only) and the kernels' per-signal ``(frac, lo, hi, half, width)`` arrays
    (zeros for floats), with the conversions between physical values and the filter's
    words that every filter makes."""

    kind: str
    dtype: type
    formats: FormatTable | None
    arrays: tuple

    @classmethod
    def of(cls, arithmetic, table: type, what: str) -> "Arithmetic":
        """Resolve ``arithmetic`` (``"float64"``, ``"float32"`` or an instance of the format
        table class ``table``) for the filter named ``what``."""
        kind = arithmetic_name(arithmetic)
        if kind == "fixed":
            if not isinstance(arithmetic, table):
                raise ValueError(f"the fixed-point {what} takes a {table.__name__} table, "
                                 f"not {arithmetic!r}")
            return cls(kind, np.int64, arithmetic, arithmetic.arrays())
        zz = np.zeros(len(table.signals()), np.int64)
        return cls(kind, np.float64 if kind == "float64" else np.float32, None, (zz,) * 5)

    @property
    def fixed(self) -> bool:
        return self.kind == "fixed"

    def words(self, values, signal: str, what: str | None = None) -> np.ndarray:
        """Physical ``values`` as the filter's words of ``signal``: fixed point, rounded into
        its format (first checked to fit when ``what`` names them); floats, cast to the
        dtype."""
        if self.fixed:
            f = getattr(self.formats, signal)
            if what is not None:
                fits(what, values, f)
            return to_fixed(values, f)
        return np.ascontiguousarray(np.asarray(values), dtype=self.dtype)

    def physical(self, words, signal: str) -> np.ndarray:
        """The filter's words of ``signal`` in physical units (float64)."""
        if self.fixed:
            return words * 2.0 ** -getattr(self.formats, signal).frac
        return words.astype(np.float64)

    def limit(self, limit: float | None, signal: str = "z") -> float | None:
        """The plausibility limit on ``|signal|``: ``limit`` (None: none), in fixed point
        also the format's symmetric range."""
        if not self.fixed:
            return limit
        f = getattr(self.formats, signal)
        flim = min(f.max_value, -f.min_value)
        return flim if limit is None else min(limit, flim)

    def measurements(self, z, m: int, trials: int, z_limit: float | None):
        """A batch of measurements for ``trials`` filters of ``m`` measurements: ``z`` of
        shape ``(T, m)`` or ``(trials, T, m)`` (``(T,)`` for ``m = 1``) -> ``(zc, ok, T)``:
        ``zc`` ``(trials, T, m)`` float64 with the implausible vectors zeroed, ``ok`` which
        are plausible (finite, within :meth:`limit` of ``z_limit``), ``T`` the steps."""
        z = np.asarray(z, dtype=np.float64)
        shape = z.shape
        if z.ndim == 1 and m == 1:
            z = z[:, None]
        if z.ndim == 2:
            z = np.broadcast_to(z, (trials,) + z.shape)
        if z.ndim != 3 or z.shape[0] != trials or z.shape[2] != m:
            raise ValueError(f"z must have shape (T, {m}) or ({trials}, T, {m}), not {shape}")
        ok = np.all(np.isfinite(z), axis=2)
        lim = self.limit(z_limit, "z")
        if lim is not None:
            ok &= np.all(np.abs(np.where(np.isfinite(z), z, 0.0)) <= lim, axis=2)
        return np.where(ok[..., None], z, 0.0), ok, z.shape[1]
