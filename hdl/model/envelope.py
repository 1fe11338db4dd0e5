"""Envelope (magnitude) of complex samples by pipelined CORDIC vectoring: parameters and model.

Algorithm (what the HDL does, bit for bit)
------------------------------------------
1. Fold into the first quadrant: ``x0 = |i| << guard``, ``y0 = |q| << guard`` (a reflection
   keeps the magnitude; the angle is then in [0, 90] deg, inside CORDIC's ~99.9 deg range).
2. ``iterations`` micro-rotations, k = 0 .. N-1, with arithmetic (floor) shifts::

       if y >= 0:  x, y = x + (y >> k), y - (x >> k)
       else:       x, y = x - (y >> k), y + (x >> k)

   ``x`` ends as ``gain * |z| * 2**guard`` (plus rounding error), with
   ``gain = prod_k sqrt(1 + 2**-2k)`` (:attr:`EnvelopeParams.gain`, -> 1.646760258 for many
   iterations).
3. Optional gain compensation (``compensate=True``): ``x * comp_const`` with
   ``comp_const = round(2**comp_bits / gain)``, one registered multiplier.
4. Drop ``guard + shift (+ comp_bits)`` LSBs with the chosen rounding and saturate to
   ``out_width`` unsigned bits.

Output scaling: ``mag_out ~= eff_gain * |z| / 2**shift`` with ``|z|`` in input LSBs,
``eff_gain = gain`` (not compensated, the default) or ``gain * comp_const / 2**comp_bits``
(compensated, ~1). :attr:`EnvelopeParams.shift` is derived from ``out_width``: by default the
output is one bit wider than the input (uncompensated; ``gain * sqrt(2) < 4``) and
``shift = 0``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dsp.fixed import check_width, shift_right
from dsp.jit import njit_cached

from .rounding import round_consts

ENVELOPE_ROUNDINGS = ("floor", "half_up")


@dataclass(frozen=True)
class EnvelopeParams:
    """Parameters of :class:`hdl.envelope.Envelope`.

    Parameters
    ----------
    in_width : int
        Width of the signed ``i`` and ``q`` input fields (bits, 2..30).
    out_width : int, optional
        Width of the unsigned magnitude (bits). Default: ``in_width + 1`` without
        compensation, ``in_width`` with it, i.e. full range and ``shift = 0``.
    iterations : int
        CORDIC micro-rotations (1..32); the angle residual after N of them is
        ``atan(2**-(N-1))``.
    guard_bits : int, optional
        Extra LSBs carried through the iterations to keep the truncation error of the
        shifts below the output LSB. Default ``ceil(log2(iterations)) + 1``.
    compensate : bool
        Multiply by ``1/gain`` (one multiplier) so the output is ``~|z|``. Default False.
    comp_bits : int
        Fraction bits of the compensation constant (1..24).
    rounding : {"floor", "half_up"}
        Rounding of the LSBs dropped at the output.
    """

    in_width: int = 18
    out_width: int | None = None
    iterations: int = 16
    guard_bits: int | None = None
    compensate: bool = False
    comp_bits: int = 17
    rounding: str = "floor"

    def __post_init__(self):
        check_width("envelope in_width", self.in_width, minimum=2, maximum=30)
        check_width("CORDIC iterations", self.iterations, minimum=1, maximum=32)
        if self.guard_bits is None:
            object.__setattr__(self, "guard_bits", math.ceil(math.log2(self.iterations)) + 1)
        check_width("CORDIC guard_bits", self.guard_bits, minimum=0, maximum=16)
        if not isinstance(self.compensate, bool):
            raise ValueError(f"compensate must be a bool, not {self.compensate!r}")
        check_width("compensation comp_bits", self.comp_bits, minimum=1, maximum=24)
        if self.rounding not in ENVELOPE_ROUNDINGS:
            raise ValueError(f"envelope rounding must be one of {ENVELOPE_ROUNDINGS}, "
                             f"not {self.rounding!r}")
        if self.out_width is None:
            object.__setattr__(self, "out_width", self.natural_width)
        check_width("envelope out_width", self.out_width, minimum=1, maximum=40)
        if self.shift < -self.guard_bits:
            raise ValueError(f"envelope out_width must be <= natural width + guard_bits = "
                             f"{self.natural_width + self.guard_bits}, not {self.out_width}")
        if self.work_width > 48:
            raise ValueError(f"CORDIC working width in_width + guard_bits + 2 must be <= 48, "
                             f"not {self.work_width}")

    # -- derived ---------------------------------------------------------------------------
    @property
    def gain(self) -> float:
        """Exact CORDIC gain for this iteration count, ``prod sqrt(1 + 2**-2k)``."""
        return float(np.prod(np.sqrt(1.0 + 2.0 ** (-2.0 * np.arange(self.iterations)))))

    @property
    def comp_const(self) -> int:
        """Compensation multiplier ``round(2**comp_bits / gain)`` (unsigned)."""
        return int(round(2.0 ** self.comp_bits / self.gain))

    @property
    def eff_gain(self) -> float:
        """Overall gain from ``|z|`` to the output before the ``2**-shift``."""
        if self.compensate:
            return self.gain * self.comp_const / 2.0 ** self.comp_bits
        return self.gain

    @property
    def natural_width(self) -> int:
        """Unsigned width that holds ``eff_gain * max|z|`` at ``shift = 0``.

        ``max|z| = sqrt(2) * 2**(in_width-1)``; ``gain*sqrt(2) = 2.33 < 4`` needs one bit
        more than ``in_width``; compensated ``~1.414 < 2`` needs ``in_width``.
        """
        return self.in_width if self.compensate else self.in_width + 1

    @property
    def shift(self) -> int:
        """``mag_out ~= eff_gain * |z| / 2**shift`` (negative: extra fraction bits)."""
        return self.natural_width - self.out_width

    @property
    def work_width(self) -> int:
        """Signed width of the x/y registers: ``|z| * gain * 2**guard < 2**(in_width+1+guard)``."""
        return self.in_width + self.guard_bits + 2

    @property
    def total_shift(self) -> int:
        """LSBs dropped from the final ``x`` (or from the compensated product)."""
        return self.guard_bits + self.shift + (self.comp_bits if self.compensate else 0)

    @property
    def latency(self) -> int:
        """Cycles from an input transfer to its output transfer."""
        return 1 + self.iterations + 1 + (2 if self.compensate else 0)

    @property
    def max_out(self) -> int:
        return (1 << self.out_width) - 1

    @property
    def error_bound_lsb(self) -> float:
        """Bound on ``|mag_out - eff_gain*|z|/2**shift|`` in output LSBs.

        * each floor shift in an iteration errs by < 1 guard LSB in x and in y; the error
          vector is then rotated and scaled by the remaining iterations (norm <=
          the remaining gain <= ``gain``), so the accumulated error is below
          ``sqrt(2) * gain * N`` guard LSBs;
        * the angle residual ``a <= atan(2**-(N-1))`` leaves ``x = G|z|cos(a)``, a relative
          error ``1 - cos(a) <= 2**-(2N-1)``;
        * the compensation constant's rounding adds ``<= 0.5 * 2**-comp_bits`` relative
          (already in ``eff_gain``) and the product truncation < 1 LSB of the product;
        * the output rounding adds 1 LSB (floor) or 0.5 LSB (half_up).
        """
        scale_out = 2.0 ** -(self.guard_bits + self.shift)  # guard LSB -> output LSB
        c = self.eff_gain / self.gain  # compensation scales the CORDIC error too
        cordic = math.sqrt(2.0) * self.gain * self.iterations * scale_out * c
        max_mag = math.sqrt(2.0) * 2.0 ** (self.in_width - 1)
        angle = self.eff_gain * max_mag * 2.0 ** (-(2 * self.iterations - 1)) / 2.0 ** self.shift
        prod = 2.0 ** -(self.guard_bits + self.shift) if self.compensate else 0.0
        rnd = 1.0 if self.rounding == "floor" else 0.5
        return cordic + angle + prod + rnd


@njit_cached(nogil=True)
def _cordic_kernel(i, q, out, guard, iterations, mult, total_shift, bias, max_out):
    """The arithmetic of :func:`envelope_model_numpy` in int64, on blocks of samples (the
    loops over a block vectorise): the CORDIC, ``x * mult`` (the compensation constant, or
    1), ``(x + bias) >> total_shift`` (``bias``: 0 floor, half an LSB half_up), saturation
    at ``max_out``."""
    n = i.shape[0]
    blk = 256
    x = np.empty(blk, dtype=np.int64)
    y = np.empty(blk, dtype=np.int64)
    for a in range(0, n, blk):
        nb = min(blk, n - a)
        ib = i[a:a + nb]
        qb = q[a:a + nb]
        ob = out[a:a + nb]
        for j in range(nb):
            x[j] = abs(np.int64(ib[j])) << guard
            y[j] = abs(np.int64(qb[j])) << guard
        for k in range(iterations):
            for j in range(nb):
                xv = x[j]
                yv = y[j]
                # sgn = -1 where y < 0, else 0; (v ^ sgn) - sgn negates v where y < 0
                sgn = yv >> 63
                t = ((yv >> k) ^ sgn) - sgn
                xs = ((xv >> k) ^ sgn) - sgn
                x[j] = xv + t
                y[j] = yv - xs
        for j in range(nb):
            ob[j] = min((x[j] * mult + bias) >> total_shift, max_out)


def envelope_model(i, q, params: EnvelopeParams, *, check: bool = True) -> np.ndarray:
    """Bit-exact magnitude of ``i + jq`` (int arrays, same shape) as the HDL computes it.

    Compiled (numba) loop over cache-sized blocks of samples, the same arithmetic as
    :func:`envelope_model_numpy` (the reference it is tested against). The model is
    stateless: the pipeline only delays (latency :attr:`EnvelopeParams.latency`).
    ``check=False`` skips the input range check (for callers whose inputs are in range by
    construction).
    """
    p = params
    i = np.asarray(i)
    q = np.asarray(q)
    if i.shape != q.shape:
        raise ValueError(f"envelope i and q must have the same shape, not {i.shape} and {q.shape}")
    if i.dtype.kind not in "iu" or q.dtype.kind not in "iu":
        i = i.astype(np.int64)
        q = q.astype(np.int64)
    lo, hi = -(1 << (p.in_width - 1)), (1 << (p.in_width - 1)) - 1
    if check and i.size and (i.min() < lo or i.max() > hi or q.min() < lo or q.max() > hi):
        raise ValueError(f"envelope input must fit signed {p.in_width} bits "
                         f"[{lo}, {hi}]")
    shape = i.shape
    i = np.ascontiguousarray(i.ravel(), dtype=np.int64)
    q = np.ascontiguousarray(q.ravel(), dtype=np.int64)
    out = np.empty(i.size, dtype=np.int64)
    ts = p.total_shift   # >= 0 (shift >= -guard_bits)
    bias = round_consts(ts, p.rounding)[2]   # floor: 0, half_up: half an output LSB
    _cordic_kernel(i, q, out, p.guard_bits, p.iterations, p.comp_const if p.compensate else 1,
                   ts, bias, p.max_out)
    return out.reshape(shape)


def envelope_model_numpy(i, q, params: EnvelopeParams) -> np.ndarray:
    """Bit-exact magnitude of ``i + jq`` (int arrays, same shape) as the HDL computes it.

    numpy reference of :func:`envelope_model` (same bits, ~5x slower): vectorised over
    samples; loops over the ``iterations`` only, on cache-sized blocks, in int32 when the
    working width allows. The model is stateless: the pipeline only delays
    (latency :attr:`EnvelopeParams.latency`).
    """
    p = params
    i = np.asarray(i, dtype=np.int64)
    q = np.asarray(q, dtype=np.int64)
    if i.shape != q.shape:
        raise ValueError(f"envelope i and q must have the same shape, not {i.shape} and {q.shape}")
    lo, hi = -(1 << (p.in_width - 1)), (1 << (p.in_width - 1)) - 1
    if i.size and (i.min() < lo or i.max() > hi or q.min() < lo or q.max() > hi):
        raise ValueError(f"envelope input must fit signed {p.in_width} bits "
                         f"[{lo}, {hi}]")
    shape = i.shape
    i, q = i.ravel(), q.ravel()
    dt = np.int32 if p.work_width <= 31 else np.int64
    out = np.empty(i.size, dtype=np.int64)
    block = 1 << 14
    for a in range(0, i.size, block):
        x = np.abs(i[a:a + block]).astype(dt) << dt(p.guard_bits)
        y = np.abs(q[a:a + block]).astype(dt) << dt(p.guard_bits)
        t = np.empty_like(x)
        sgn = np.empty_like(x)
        sbits = dt(8 * np.dtype(dt).itemsize - 1)
        for k in range(p.iterations):
            kk = dt(k)
            # sgn = -1 where y < 0, else 0; (v ^ sgn) - sgn negates v where y < 0.
            np.right_shift(y, sbits, out=sgn)
            np.right_shift(y, kk, out=t)
            t ^= sgn
            t -= sgn
            xs = x >> kk
            x += t
            xs ^= sgn
            xs -= sgn
            y -= xs
        xv = x.astype(np.int64)
        if p.compensate:
            xv *= np.int64(p.comp_const)
        out[a:a + block] = shift_right(xv, p.total_shift, p.rounding)
    return np.minimum(out, np.int64(p.max_out)).reshape(shape)
