"""Integer CORDIC in vectoring mode: ``atan2`` and magnitude with integers only.

What a DSP or FPGA does to turn a (sin, cos) pair into a phase and an amplitude. Inputs are
signed integers of ``width`` bits; the angle comes out as a *binary angle*: an integer where
``2**angle_bits`` is one full turn (natural wrap of a ``angle_bits``-bit register), unsigned
in ``[0, 2**angle_bits)`` or, with ``signed_angle=True``, in
``[-2**(angle_bits-1), 2**(angle_bits-1))``; the angle is ``atan2(y, x)``, counter-clockwise
from the +x axis, as :func:`numpy.arctan2`. Everything is vectorised over numpy ``int64``
arrays: the only Python loop is over the iterations.

Algorithm (bit-exact description; :func:`cordic_atan2_reference` is the same with Python
integers, one element at a time)
-----------------------------------------------------------------------------------------
1. Zero detect: ``x == y == 0`` gives angle 0 and magnitude 0 (no exception; a vector
   without a direction has no angle -- callers that care flag it from the magnitude).
2. Quadrant pre-rotation by 180 degrees: if ``x < 0``, ``(x, y) <- (-x, -y)`` and the angle
   accumulator starts at half a turn, else at 0. The vector is then in the right half
   plane (|angle| <= 90 deg), inside the +-99.9 deg convergence range of the iterations.
   ``-(-2**(width-1))`` needs one more bit, which the datapath has.
3. Scale by the guard bits: ``x <<= guard_bits``, ``y <<= guard_bits``.
4. For ``i = 0 .. iterations-1``: ``d = +1 if y < 0 else -1``;
   ``x, y = x - d (y >> i), y + d (x >> i)`` (arithmetic shifts, i.e. floor, as the
   hardware drops the LSBs) and ``z -= d * LUT[i]`` with
   ``LUT[i] = round(atan(2**-i) / 2 pi * 2**lut_bits)`` (the accumulator ``z`` counts
   ``2**-lut_bits`` turn).
5. Angle: ``z`` rounded half-up to ``angle_bits`` and wrapped (mod ``2**angle_bits``).
   Magnitude: ``x`` (which is ``K_n |v| 2**guard_bits``, ``K_n = prod_i sqrt(1 + 2**-2i)``,
   about 1.6468) times the quantised constant ``gain_word = round(2**gain_frac / K_n)``,
   one half-up rounding by ``2**(gain_frac + guard_bits)`` -- an exactly rounded product
   formed with a split multiply so that it fits int64 -- or, with
   ``compensate_gain=False``, ``x`` rounded to the input scale (magnitude times ``K_n``,
   reported as :attr:`CordicConfig.gain`).

Word lengths: the datapath ``x``/``y`` registers hold ``width + 2 + guard_bits`` signed
bits (1 bit for the pre-rotation of ``-2**(width-1)``, 1 for the growth ``K_n sqrt 2 <
2.33``); they must fit 62 bits. The split gain multiply needs ``2 gain_frac + guard_bits
+ 1 <= 62``.

Error bounds (checked by ``tests/dsp/test_cordic.py`` on random vectors over the full
circle and on the edge cases)
-------------------------------------------------------------------------------------------
With ``n = iterations``, ``r = |(x, y)|`` in input LSBs and ``g = guard_bits``, the angle
error (vs the exact ``atan2``) is at most (:meth:`CordicConfig.angle_error_bound`)::

    atan(2**-(n-1))                  residual rotation after the last iteration
  + n / 2 * 2**-lut_bits turn        rounding of the n LUT entries
  + 2 sqrt(2) n / (r 2**g) rad       floor of the shifted operands (<= 1 LSB per register
                                      per iteration, at most K_n times the input scale)
  + 1/2 * 2**-angle_bits turn        the final rounding

The residual term dominates unless ``n >= angle_bits + 2``; the default ``lut_bits =
angle_bits + ceil(log2 n) + 1`` makes the LUT term < 1/4 output LSB. The magnitude error
(:meth:`CordicConfig.magnitude_error_bound`, in input LSBs) is at most
``r (1 - cos atan(2**-(n-1)))`` (the residual angle) ``+ 2 sqrt(2) n 2**-g`` (datapath)
``+ r K_n 2**-(gain_frac+1)`` (gain constant) ``+ 2**-(magnitude_frac+1)`` (final
rounding).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

#: Largest number of iterations accepted: beyond ~60 every shift is 0/-1 and every LUT
#: entry below the 62-bit accumulator's LSB, so more only costs time.
MAX_ITERATIONS = 60
#: Largest angle / accumulator resolution (bits per turn) an int64 holds with headroom.
MAX_ANGLE_BITS = 62
#: The datapath registers (``width + 2 + guard_bits``) must fit this many bits.
MAX_DATAPATH_BITS = 62


class CordicResult(NamedTuple):
    """Output of :func:`cordic_atan2`."""

    angle: np.ndarray       #: binary angle of atan2(y, x), int64
    magnitude: np.ndarray   #: |(x, y)| at the input scale (gain compensated or not), int64


def _check_int(name: str, value, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, not {value!r}")
    if not lo <= int(value) <= hi:
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], not {value}")
    return int(value)


@dataclass(frozen=True)
class CordicConfig:
    """Word lengths of the vectoring CORDIC (see the module doc for the algorithm).

    Parameters
    ----------
    width : int
        Input word length (signed, two's complement), 2..60 -- and
        ``width + 2 + guard_bits <= 62``.
    iterations : int
        Micro-rotations, 1..60. The angle error from them is ``atan(2**-(iterations-1))``
        rad: ``angle_bits + 2`` makes it < 1/4 output LSB.
    angle_bits : int
        Bits per full turn of the output binary angle, 1..62.
    guard_bits : int, optional
        Fraction bits appended to the datapath (default ``ceil(log2 iterations) + 2``,
        limited to what fits 62 bits).
    lut_bits : int, optional
        Bits per turn of the arctangent LUT and the angle accumulator, ``angle_bits``..62
        (default ``angle_bits + ceil(log2 iterations) + 1``, at most 62).
    gain_frac : int, optional
        Fraction bits of the gain-compensation constant ``round(2**gain_frac / K_n)``,
        1..``(61 - guard_bits) // 2`` (the default, at most 32).
    compensate_gain : bool
        Multiply the magnitude by the constant (True) or return ``K_n |v|`` (False; the
        gain is :attr:`gain`).
    magnitude_frac : int
        Fraction bits kept in the magnitude output, 0..``guard_bits`` (default 0: the
        magnitude at the input scale). The output is then ``|v| * 2**magnitude_frac``.
    signed_angle : bool
        Output angles in ``[-2**(angle_bits-1), 2**(angle_bits-1))`` instead of
        ``[0, 2**angle_bits)``.
    """

    width: int
    iterations: int = 24
    angle_bits: int = 32
    guard_bits: int | None = None
    lut_bits: int | None = None
    gain_frac: int | None = None
    compensate_gain: bool = True
    signed_angle: bool = False
    magnitude_frac: int = 0

    def __post_init__(self):
        w = _check_int("width", self.width, 2, MAX_DATAPATH_BITS - 2)
        n = _check_int("iterations", self.iterations, 1, MAX_ITERATIONS)
        a = _check_int("angle_bits", self.angle_bits, 1, MAX_ANGLE_BITS)
        log_n = max(1, math.ceil(math.log2(n))) if n > 1 else 1
        room = MAX_DATAPATH_BITS - 2 - w
        if self.guard_bits is None:
            object.__setattr__(self, "guard_bits", min(log_n + 2, room))
        else:
            g = _check_int("guard_bits", self.guard_bits, 0, MAX_DATAPATH_BITS)
            if w + 2 + g > MAX_DATAPATH_BITS:
                raise ValueError(
                    f"width + 2 + guard_bits must be <= {MAX_DATAPATH_BITS} (the datapath "
                    f"registers), not {w} + 2 + {g} = {w + 2 + g}")
        g = self.guard_bits
        if self.lut_bits is None:
            object.__setattr__(self, "lut_bits", min(a + log_n + 1, MAX_ANGLE_BITS))
        else:
            _check_int("lut_bits", self.lut_bits, a, MAX_ANGLE_BITS)
        gmax = (MAX_DATAPATH_BITS - 1 - g) // 2
        if self.gain_frac is None:
            object.__setattr__(self, "gain_frac", min(gmax, 32))
        else:
            _check_int("gain_frac", self.gain_frac, 1, gmax)
        _check_int("magnitude_frac", self.magnitude_frac, 0, g)
        if not isinstance(self.compensate_gain, bool):
            raise ValueError(f"compensate_gain must be a bool, not {self.compensate_gain!r}")
        if not isinstance(self.signed_angle, bool):
            raise ValueError(f"signed_angle must be a bool, not {self.signed_angle!r}")

    # -- constants ------------------------------------------------------------------------
    @property
    def datapath_bits(self) -> int:
        """Signed word length of the x/y registers."""
        return self.width + 2 + self.guard_bits

    @property
    def lut(self) -> tuple[int, ...]:
        """``round(atan(2**-i) / 2 pi * 2**lut_bits)`` for each iteration (Python ints)."""
        return _lut(self.iterations, self.lut_bits)

    @property
    def gain(self) -> float:
        """CORDIC gain ``K_n = prod sqrt(1 + 2**-2i)`` of ``iterations`` micro-rotations."""
        return math.prod(math.sqrt(1.0 + 4.0 ** -i) for i in range(self.iterations))

    @property
    def gain_word(self) -> int:
        """The quantised compensation constant ``round(2**gain_frac / K_n)``."""
        return int(round(2.0 ** self.gain_frac / self.gain))

    # -- error bounds ---------------------------------------------------------------------
    def angle_error_bound(self, r) -> np.ndarray:
        """Bound on ``|angle - atan2(y, x)|`` in radians for input magnitude ``r`` (LSBs).

        See the module doc for the four terms. ``r = 0`` gives ``inf`` (no direction).
        """
        r = np.asarray(r, dtype=np.float64)
        n, g = self.iterations, self.guard_bits
        fixed = (math.atan(2.0 ** -(n - 1)) + 2 * math.pi * (
            n / 2 * 2.0 ** -self.lut_bits + 0.5 * 2.0 ** -self.angle_bits))
        with np.errstate(divide="ignore"):
            return fixed + 2 * math.sqrt(2) * n * 2.0 ** -g / r

    def magnitude_error_bound(self, r) -> np.ndarray:
        """Bound on ``|magnitude - r|`` in input LSBs (gain compensated) for magnitude ``r``.

        With ``compensate_gain=False`` it bounds ``|magnitude - K_n r|`` instead; with
        ``magnitude_frac`` the magnitude is first divided by ``2**magnitude_frac``.
        """
        r = np.asarray(r, dtype=np.float64)
        n, g = self.iterations, self.guard_bits
        k = self.gain
        res = r * (1.0 - math.cos(math.atan(2.0 ** -(n - 1))))
        path = 2 * math.sqrt(2) * n * 2.0 ** -g
        rnd = 0.5 * 2.0 ** -self.magnitude_frac
        if self.compensate_gain:
            return res + path + r * k * 2.0 ** -(self.gain_frac + 1) + rnd
        return k * (res + path) + rnd

    # -- evaluation -----------------------------------------------------------------------
    def __call__(self, y, x) -> CordicResult:
        """Vectorised CORDIC; see :func:`cordic_atan2`."""
        y, x = _inputs(y, x, self.width)
        n, g = self.iterations, self.guard_bits
        zero = (x == 0) & (y == 0)
        neg = x < 0
        half = np.int64(1) << np.int64(self.lut_bits - 1)
        z = np.where(neg, half, np.int64(0))
        xs = np.where(neg, -x, x) << np.int64(g)
        ys = np.where(neg, -y, y) << np.int64(g)
        for i, atan_i in enumerate(self.lut):
            s = np.int64(i)
            dx = ys >> s
            dy = xs >> s
            up = ys < 0               # d = +1: rotate counter-clockwise
            xs, ys = (np.where(up, xs - dx, xs + dx), np.where(up, ys + dy, ys - dy))
            z = np.where(up, z - np.int64(atan_i), z + np.int64(atan_i))
        angle = _round_angle(z, self.lut_bits, self.angle_bits, self.signed_angle)
        mag = self._magnitude(xs)
        return CordicResult(np.where(zero, np.int64(0), angle), np.where(zero, np.int64(0), mag))

    def _magnitude(self, xs: np.ndarray) -> np.ndarray:
        g = self.guard_bits - self.magnitude_frac
        if not self.compensate_gain:
            return _rshift_half_up(xs, g)
        # round(xs * c / 2**s), s = gain_frac + g, exactly: xs = hi 2**s + lo, 0 <= lo < 2**s
        # -> hi c + round(lo c / 2**s); lo c < 2**(2 gain_frac + guard_bits) fits (checked).
        s = np.int64(self.gain_frac + g)
        c = np.int64(self.gain_word)
        hi = xs >> s
        lo = xs & ((np.int64(1) << s) - 1)
        return hi * c + ((lo * c + (np.int64(1) << (s - 1))) >> s)

    def reference(self, y: int, x: int) -> tuple[int, int]:
        """The same algorithm on one pair of Python integers (bit-accurate reference)."""
        return cordic_atan2_reference(int(y), int(x), self)


@functools.lru_cache(maxsize=64)
def _lut(n: int, lut_bits: int) -> tuple[int, ...]:
    # float64 atan(2**-i) / 2 pi is off by ~2**-53 relative: hundreds of LSB at 62 bits.
    # The entries are computed exactly (integer series) instead.
    return tuple(_atan_pow2_turns(i, lut_bits) for i in range(n))


def _atan_pow2_turns(i: int, bits: int) -> int:
    """``round(atan(2**-i) / (2 pi) * 2**bits)`` exactly, with Python integer arithmetic.

    Fixed point with ``bits + 40`` fraction bits: ``atan(t) = sum (-1)^k t^(2k+1)/(2k+1)``
    for ``t = 2**-i <= 1`` (for ``i = 0``: ``atan 1 = pi / 4``), ``pi`` from Machin's formula.
    """
    p = bits + 40
    one = 1 << p

    def atan_inv(m: int) -> int:   # atan(1/m) * 2**p, m >= 2
        total, term, k, m2 = 0, one // m, 0, m * m
        while term:
            total += term // (2 * k + 1) if k % 2 == 0 else -(term // (2 * k + 1))
            term //= m2
            k += 1
        return total

    pi = 4 * (4 * atan_inv(5) - atan_inv(239))
    if i == 0:
        a = pi // 4
    else:
        a = atan_inv(1 << i)
    # a / (2 pi) * 2**bits, rounded half up
    num = a << bits
    den = 2 * pi
    return (2 * num + den) // (2 * den)


def _inputs(y, x, width: int) -> tuple[np.ndarray, np.ndarray]:
    y, x = np.asarray(y), np.asarray(x)
    for name, v in (("y", y), ("x", x)):
        if v.dtype.kind not in "iu":
            raise ValueError(f"{name} must be an integer array, not dtype {v.dtype}")
    y, x = np.broadcast_arrays(y.astype(np.int64), x.astype(np.int64))
    lo, hi = -(1 << (width - 1)), (1 << (width - 1)) - 1
    for name, v in (("y", y), ("x", x)):
        if v.size and (v.min() < lo or v.max() > hi):
            bad = int(np.count_nonzero((v < lo) | (v > hi)))
            raise ValueError(f"{bad} value(s) of {name} do not fit {width} signed bits "
                             f"[{lo}, {hi}]")
    return y, x


def _rshift_half_up(v: np.ndarray, s: int) -> np.ndarray:
    if s <= 0:
        return v
    return (v + (np.int64(1) << np.int64(s - 1))) >> np.int64(s)


def _round_angle(z: np.ndarray, lut_bits: int, angle_bits: int, signed: bool) -> np.ndarray:
    a = _rshift_half_up(z, lut_bits - angle_bits)
    a = a & ((np.int64(1) << np.int64(angle_bits)) - 1)
    if signed:
        a = np.where(a >= (np.int64(1) << np.int64(angle_bits - 1)),
                     a - (np.int64(1) << np.int64(angle_bits)), a)
    return a


@functools.lru_cache(maxsize=128)
def _config(**kw) -> CordicConfig:
    return CordicConfig(**kw)


def cordic_atan2(y, x, *, width: int, iterations: int = 24, angle_bits: int = 32,
                 guard_bits: int | None = None, lut_bits: int | None = None,
                 gain_frac: int | None = None, compensate_gain: bool = True,
                 signed_angle: bool = False, magnitude_frac: int = 0) -> CordicResult:
    """Angle and magnitude of integer vectors ``(x, y)`` by a vectoring CORDIC.

    Parameters
    ----------
    y, x : array_like of int
        Components, signed integers that fit ``width`` bits; broadcast together.
    width, iterations, angle_bits, guard_bits, lut_bits, gain_frac, compensate_gain, \
signed_angle, magnitude_frac
        Word lengths and options, see :class:`CordicConfig` (validated, ``ValueError``).

    Returns
    -------
    CordicResult
        ``angle``: int64 binary angle of ``atan2(y, x)`` (``2**angle_bits`` per turn);
        ``magnitude``: int64 ``|(x, y)| * 2**magnitude_frac``, rounded (times
        :attr:`CordicConfig.gain` if ``compensate_gain`` is False). ``x = y = 0`` gives
        ``(0, 0)``.

    Raises
    ------
    ValueError
        Bad word lengths, non-integer input, or input outside ``width`` bits.

    Examples
    --------
    >>> a, m = cordic_atan2(np.array([300]), np.array([-400]), width=12, iterations=20,
    ...                     angle_bits=16)
    >>> round(float(a[0]) / 2**16 * 360, 2), int(m[0])
    (143.13, 500)
    """
    cfg = _config(width=width, iterations=iterations, angle_bits=angle_bits,
                  guard_bits=guard_bits, lut_bits=lut_bits, gain_frac=gain_frac,
                  compensate_gain=compensate_gain, signed_angle=signed_angle,
                  magnitude_frac=magnitude_frac)
    return cfg(y, x)


def cordic_atan2_reference(y: int, x: int, cfg: CordicConfig) -> tuple[int, int]:
    """Scalar bit-accurate reference of :func:`cordic_atan2` with Python integers.

    A line-by-line transcription of the algorithm in the module doc (no numpy), used by the
    tests to pin the vectorised implementation. Returns ``(angle, magnitude)``.
    """
    if isinstance(y, bool) or isinstance(x, bool) or not (
            isinstance(y, int) and isinstance(x, int)):
        raise ValueError(f"x and y must be Python ints, not {x!r}, {y!r}")
    lo, hi = -(1 << (cfg.width - 1)), (1 << (cfg.width - 1)) - 1
    if not (lo <= x <= hi and lo <= y <= hi):
        raise ValueError(f"x={x}, y={y} do not fit {cfg.width} signed bits")
    if x == 0 and y == 0:
        return 0, 0
    z = 0
    if x < 0:
        x, y, z = -x, -y, 1 << (cfg.lut_bits - 1)
    x <<= cfg.guard_bits
    y <<= cfg.guard_bits
    for i, atan_i in enumerate(cfg.lut):
        if y < 0:
            x, y, z = x - (y >> i), y + (x >> i), z - atan_i
        else:
            x, y, z = x + (y >> i), y - (x >> i), z + atan_i
    s = cfg.lut_bits - cfg.angle_bits
    a = ((z + (1 << (s - 1))) >> s if s > 0 else z) % (1 << cfg.angle_bits)
    if cfg.signed_angle and a >= 1 << (cfg.angle_bits - 1):
        a -= 1 << cfg.angle_bits
    g = cfg.guard_bits - cfg.magnitude_frac
    if cfg.compensate_gain:
        s = cfg.gain_frac + g
        m = (x * cfg.gain_word + (1 << (s - 1))) >> s
    else:
        m = (x + (1 << (g - 1))) >> g if g > 0 else x
    return a, m
