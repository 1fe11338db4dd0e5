"""Symmetric FIR decimator / CIC droop compensator: parameters, widths and bit-exact model.

The filter is type I (odd length L, ``h[k] == h[L-1-k]``) with real float taps quantised to
``coef_bits`` signed integers ``taps_int = round(h * 2**coef_frac)``; ``coef_frac`` is the
largest power-of-two scale that keeps every tap in range, so the biggest tap uses as much
of the coefficient word as a power-of-two scale allows. The hardware pre-adds the symmetric
input pairs (one multiplier per distinct non-zero tap, or ``ceil(U / input_spacing)`` of them
time-shared when the input cadence allows), sums the products exactly in an ``acc_width``
accumulator, drops ``out_shift`` LSBs with ``rounding`` and applies ``overflow`` to
``out_width`` bits. The architecture changes the latency only, never the values.

Output meaning: ``y_int ~= float_gain * sum_k taps_quantised[k] * x_int[n-k]`` with
``float_gain = 2**(coef_frac - out_shift)`` (1 by default: output LSB = input LSB);
:func:`fir_float_reference` gives that float value for the golden-chain comparisons.

Decimation by D keeps the outputs for the D-th, 2D-th, ... input since reset (the same
convention as the CIC). The model runs on the valid samples only and passes its state
(last L-1 inputs, decimation phase, overflow count) in and out for chunked runs.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from dsp.fixed import OVERFLOWS, ROUNDINGS, FixedFormat, check_samples, check_width, \
    shift_right
from dsp.jit import njit_cached

from .rounding import rnd, round_consts

__all__ = ["FirParams", "FirState", "fir_init_state", "fir_model", "fir_float_reference",
           "default_fir_taps", "dsp_limbs"]


@functools.lru_cache(maxsize=None)
def default_fir_taps() -> tuple[float, ...]:
    """The TACAN pulse-matched, CIC-compensating FIR: ``design_pulse_fir(fs_in_hz=20e6,
    cic_stages=3, cic_rate=4, numtaps=33)`` (DC gain ~1.21)."""
    from dsp.design import design_pulse_fir
    return tuple(float(t) for t in design_pulse_fir(fs_in_hz=20e6, cic_stages=3, cic_rate=4,
                                                     numtaps=33))


def _is_int(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool)


@dataclass(frozen=True)
class FirParams:
    """Parameters of the symmetric FIR decimator; every width and latency is derived here.

    Parameters
    ----------
    taps : sequence of float, optional
        Symmetric taps, odd length >= 3 (default: :func:`default_fir_taps`).
    coef_bits : int
        Signed coefficient width in bits (2..32).
    decimation : int
        Output one sample per ``decimation`` inputs (>= 1).
    in_width : int
        Input sample width in bits, signed (default 24: the TACAN CIC's full width).
    channels : int
        1: real samples; 2: complex samples as ``StructLayout({"i", "q"})``.
    out_shift : int, optional
        LSBs dropped from the accumulator (default ``coef_frac``: output LSB = input LSB).
    out_width : int, optional
        Output width in bits (default: ``acc_width - out_shift``, which cannot overflow
        except by a rounding carry).
    rounding : {"floor", "half_up", "half_even", "zero"}
        Rounding of the dropped LSBs.
    overflow : {"saturate", "wrap"}
        What an output out of ``out_width`` range becomes (counted by the model).
    input_spacing : int
        Guaranteed minimum number of cycles between input samples (1: any cadence, one
        sample per cycle). With S >= 2 the hardware time-shares its multipliers: each does
        S taps per sample, ``ceil(U / S)`` per channel for U distinct non-zero taps (after
        the TACAN CIC with R = 4, S = 4). Inputs closer together than S set the sticky
        ``overrun`` output and corrupt outputs; the output values do not depend on S.
    """

    taps: tuple | None = None
    coef_bits: int = 18
    decimation: int = 1
    in_width: int = 24
    channels: int = 2
    out_shift: int | None = None
    out_width: int | None = None
    rounding: str = "half_up"
    overflow: str = "saturate"
    input_spacing: int = 1
    _taps_int: tuple = field(default=(), init=False, repr=False, compare=False)
    _coef_frac: int = field(default=0, init=False, repr=False, compare=False)

    def __post_init__(self):
        taps = default_fir_taps() if self.taps is None else self.taps
        try:
            h = np.asarray(taps, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"FIR taps must be a sequence of real numbers, not {taps!r}") from None
        if h.ndim != 1 or len(h) < 3 or len(h) % 2 == 0:
            raise ValueError(f"FIR numtaps must be an odd integer >= 3 (type I), not "
                             f"{len(h) if h.ndim == 1 else h.shape}")
        if not np.all(np.isfinite(h)):
            raise ValueError("FIR taps must be finite, not containing NaN/inf")
        scale = np.max(np.abs(h))
        if scale == 0:
            raise ValueError("FIR taps must not be all zero")
        asym = float(np.max(np.abs(h - h[::-1])))
        if asym > 1e-9 * scale:
            raise ValueError(f"FIR taps must be symmetric (h[k] == h[L-1-k], type I), not "
                             f"asymmetric by {asym:.3g}")
        object.__setattr__(self, "taps", tuple(float(t) for t in h))
        if not _is_int(self.coef_bits) or not 2 <= self.coef_bits <= 32:
            raise ValueError(f"FIR coef_bits must be an integer in [2, 32], not {self.coef_bits!r}")
        if not _is_int(self.decimation) or self.decimation < 1:
            raise ValueError(f"FIR decimation must be an integer >= 1, not {self.decimation!r}")
        check_width("FIR in_width", self.in_width, minimum=2)
        if not _is_int(self.channels) or self.channels not in (1, 2):
            raise ValueError(f"FIR channels must be 1 (real) or 2 (complex), not {self.channels!r}")
        if self.rounding not in ROUNDINGS:
            raise ValueError(f"FIR rounding must be one of {ROUNDINGS}, not {self.rounding!r}")
        if self.overflow not in OVERFLOWS:
            raise ValueError(f"FIR overflow must be one of {OVERFLOWS}, not {self.overflow!r}")
        if not _is_int(self.input_spacing) or self.input_spacing < 1:
            raise ValueError(f"FIR input_spacing must be an integer >= 1 (cycles), not "
                             f"{self.input_spacing!r}")
        # Coefficients: quantise the first half (incl. the centre) and mirror, so the integer
        # taps are exactly symmetric whatever the float rounding did.
        half = h[: len(h) // 2 + 1]
        lim = (1 << (self.coef_bits - 1)) - 1
        frac = self.coef_bits - 1 - math.floor(math.log2(scale))
        while True:
            q = np.round(np.ldexp(half, frac))
            if np.max(np.abs(q)) <= lim:
                break
            frac -= 1
        q = q.astype(np.int64)
        if not q.any():
            raise ValueError("FIR taps quantise to all zeros")
        full = np.concatenate([q, q[-2::-1]])
        object.__setattr__(self, "_taps_int", tuple(int(v) for v in full))
        object.__setattr__(self, "_coef_frac", int(frac))
        if self.acc_width > 62:
            raise ValueError(f"FIR accumulator width must be <= 62 bits, not {self.acc_width} "
                             f"(reduce in_width or coef_bits)")
        if self.out_shift is None:
            object.__setattr__(self, "out_shift", self._coef_frac)
        if not _is_int(self.out_shift) or not 0 <= self.out_shift <= self.acc_width - 2:
            raise ValueError(f"FIR out_shift must be an integer in [0, {self.acc_width - 2}], "
                             f"not {self.out_shift!r}")
        if self.out_width is None:
            object.__setattr__(self, "out_width", self.acc_width - self.out_shift)
        if not _is_int(self.out_width) or not 2 <= self.out_width <= 62:
            raise ValueError(f"FIR out_width must be an integer in [2, 62], not {self.out_width!r}")
        for name in ("coef_bits", "decimation", "in_width", "channels", "out_shift", "out_width",
                     "input_spacing"):
            object.__setattr__(self, name, int(getattr(self, name)))

    # -- coefficients ----------------------------------------------------------------------
    @property
    def numtaps(self) -> int:
        return len(self.taps)

    @property
    def coef_frac(self) -> int:
        """Fraction bits of the integer taps: ``taps_int ~= taps * 2**coef_frac``."""
        return self._coef_frac

    @property
    def taps_int(self) -> tuple[int, ...]:
        """The quantised integer taps (exactly symmetric, ``coef_bits`` signed)."""
        return self._taps_int

    @property
    def taps_quantised(self) -> np.ndarray:
        """The float taps the hardware implements: ``taps_int / 2**coef_frac``."""
        return np.ldexp(np.array(self._taps_int, dtype=np.float64), -self._coef_frac)

    @property
    def unique_taps(self) -> tuple[int, ...]:
        """``taps_int[0 .. L//2]``: one multiplier each (per channel) unless zero."""
        return self._taps_int[: self.numtaps // 2 + 1]

    # -- widths ------------------------------------------------------------------------------
    @property
    def preadd_width(self) -> int:
        """Width of the symmetric pre-adder outputs (multiplier data input)."""
        return self.in_width + 1

    @property
    def acc_bounds(self) -> tuple[int, int]:
        """Exact (min, max) of the accumulator over all inputs in ``in_width`` bits."""
        h = np.array(self._taps_int, dtype=object)
        pos, neg = int(h[h > 0].sum()), int(-h[h < 0].sum())
        lo, hi = -(1 << (self.in_width - 1)), (1 << (self.in_width - 1)) - 1
        return lo * pos - hi * neg, hi * pos - lo * neg

    @property
    def acc_width(self) -> int:
        """Signed width holding every accumulator value (products summed exactly)."""
        lo, hi = self.acc_bounds
        return max((-lo - 1).bit_length(), hi.bit_length()) + 1

    @property
    def nonzero_taps(self) -> tuple[int, ...]:
        """Indices ``t <= L//2`` of the distinct non-zero taps (one product each)."""
        return tuple(t for t, c in enumerate(self.unique_taps) if c != 0)

    @property
    def mux_factor(self) -> int:
        """Taps per multiplier per sample: ``min(input_spacing, U)`` (1: fully parallel)."""
        return min(self.input_spacing, len(self.nonzero_taps))

    @property
    def multipliers_per_channel(self) -> int:
        """Multipliers per channel: ``ceil(U / mux_factor)`` for U distinct non-zero taps."""
        return -(-len(self.nonzero_taps) // self.mux_factor)

    @property
    def multipliers(self) -> int:
        """Logical multipliers (one per distinct non-zero tap, or shared): per channel x
        channels. Each is built from :attr:`dsp_pieces_per_multiplier` 18x18 pieces."""
        return self.multipliers_per_channel * self.channels

    @property
    def data_limbs(self) -> tuple[tuple[int, int, bool], ...]:
        """How the pre-adder output is split for 18x18 multipliers: ``(lsb, width, signed)``."""
        return dsp_limbs(self.preadd_width)

    @property
    def coef_limbs(self) -> tuple[tuple[int, int, bool], ...]:
        """How a coefficient is split for 18x18 multipliers: ``(lsb, width, signed)``."""
        return dsp_limbs(self.coef_bits)

    def tap_coef_limbs(self, t: int) -> tuple[tuple[int, int, int], ...]:
        """Non-zero limbs ``(lsb, width, value)`` of the constant tap ``unique_taps[t]``."""
        c = self.unique_taps[t]
        out = []
        for lsb, width, signed in self.coef_limbs:
            v = (c >> lsb) & ((1 << width) - 1)
            if signed and v >> (width - 1):
                v -= 1 << width
            if v:
                out.append((lsb, width, v))
        return tuple(out)

    @property
    def dsp_pieces_per_channel(self) -> int:
        """18x18 products per channel (= ECP5 MULT18X18D blocks), the adder tree's leaves.
        Parallel: data limbs x non-zero coefficient limbs per tap; shared: data limbs x
        coefficient limbs per multiplier."""
        nd = len(self.data_limbs)
        if self.mux_factor == 1:
            return sum(nd * len(self.tap_coef_limbs(t)) for t in self.nonzero_taps)
        return self.multipliers_per_channel * nd * len(self.coef_limbs)

    @property
    def dsp_blocks(self) -> int:
        """18x18 multiplier blocks in all (ECP5 MULT18X18D), all channels."""
        return self.dsp_pieces_per_channel * self.channels

    @property
    def tree_levels(self) -> int:
        """Registered levels of the pairwise adder tree over the 18x18 products (or their
        accumulators)."""
        return max(0, (self.dsp_pieces_per_channel - 1).bit_length())

    @property
    def latency(self) -> int:
        """Cycles from an input transfer to the output transfer it produces.

        Fully parallel: delay line, pre-add, multiplier input, multiplier output, routing
        register, tree levels, rounding, overflow (``7 + tree_levels``). Time-shared
        (``mux_factor`` T >= 2): the same with T phases and an accumulator
        (``8 + (T - 1) + tree_levels``).
        """
        t = self.mux_factor
        return 7 + self.tree_levels + (t if t > 1 else 0)

    @property
    def out_format(self) -> FixedFormat:
        """Output format; ``frac`` is relative to the input LSB."""
        return FixedFormat(self.out_width, self._coef_frac - self.out_shift, True,
                           self.rounding, self.overflow)

    @property
    def float_gain(self) -> float:
        """``y_int ~= float_gain * (taps_quantised filter of x_int)``: 2**(coef_frac - out_shift)."""
        return 2.0 ** (self._coef_frac - self.out_shift)

    @property
    def dc_gain(self) -> float:
        """Output integers per input integer at DC: ``sum(taps_int) / 2**out_shift``."""
        return sum(self._taps_int) / 2.0 ** self.out_shift

    @property
    def sample_shape(self) -> tuple[int, ...]:
        """Trailing shape of model sample arrays: () for real, (2,) for complex (i, q)."""
        return () if self.channels == 1 else (2,)


def dsp_limbs(width: int, dsp: int = 18) -> tuple[tuple[int, int, bool], ...]:
    """Split a signed ``width``-bit operand into limbs that fit a ``dsp``-bit signed
    multiplier input: ``(lsb, width, signed)``, low limbs unsigned of ``dsp - 1`` bits,
    the top limb signed."""
    if width <= dsp:
        return ((0, width, True),)
    out, lsb = [], 0
    while width - lsb > dsp:
        out.append((lsb, dsp - 1, False))
        lsb += dsp - 1
    out.append((lsb, width - lsb, True))
    return tuple(out)


@dataclass
class FirState:
    """Model state between chunks (``fir_init_state``: just after reset)."""

    hist: np.ndarray           # (L-1, *sample_shape) last inputs, oldest first
    phase: int = 0             # valid inputs since reset, mod D
    overflows: int = 0         # output words saturated/wrapped so far
    n_in: int = 0


def fir_init_state(params: FirParams) -> FirState:
    return FirState(hist=np.zeros((params.numtaps - 1, *params.sample_shape), np.int64))


def _check_input(params: FirParams, x) -> np.ndarray:
    return check_samples("FIR input", x, params.in_width, params.sample_shape,
                         f" for channels={params.channels}")


def _accumulate(p: FirParams, x: np.ndarray, st: FirState):
    """Exact accumulator values at the kept outputs, and the new history."""
    L, d = p.numtaps, p.decimation
    xp = np.concatenate([st.hist, x], axis=0)
    hist = xp[len(xp) - (L - 1):].copy()
    first = (d - 1 - st.phase) % d
    count = len(range(first, len(x), d))
    acc = np.zeros((count, *p.sample_shape), np.int64)
    if not count:
        return acc, hist
    # Output for input k (chunk index) is sum_t h[t] xp[k + L-1 - t]; kept k = first + q d.
    # Split into D contiguous phases once so every tap reads a contiguous slice.
    frames = -(-len(xp) // d)
    if d == 1:
        phases = [xp]
    else:
        padded = np.zeros((frames * d, *p.sample_shape), np.int64)
        padded[:len(xp)] = xp
        padded = padded.reshape(frames, d, *p.sample_shape)
        phases = [np.ascontiguousarray(padded[:, b]) for b in range(d)]

    def tap(t):
        f0, b = divmod(first + L - 1 - t, d)
        return phases[b][f0:f0 + count]

    tmp = np.empty_like(acc)
    half = L // 2
    for t, c in enumerate(p.unique_taps):
        if c == 0:
            continue
        if t == half:
            np.multiply(tap(t), np.int64(c), out=tmp)
        else:
            np.add(tap(t), tap(L - 1 - t), out=tmp)     # the hardware's pre-adder
            tmp *= np.int64(c)
        acc += tmp
    return acc, hist


def fir_model(params: FirParams, x, state: FirState | None = None
              ) -> tuple[np.ndarray, FirState]:
    """Bit-exact symmetric FIR decimator.

    Parameters
    ----------
    params : FirParams
    x : array of int, shape (n,) for channels=1 or (n, 2) for channels=2 (columns i, q)
        Input samples (the valid ones only), ``in_width`` signed bits.
    state : FirState, optional
        From a previous call (default: just after reset). Not modified.

    Returns
    -------
    y : ndarray of int64, shape (m, *sample_shape)
        One output per ``decimation`` inputs, ``out_width`` signed bits.
    state : FirState
        ``state.overflows`` counts the outputs saturated/wrapped so far.
    """
    p = params
    x = _check_input(p, x)
    st = fir_init_state(p) if state is None else state
    acc, hist = _accumulate(p, x, st)
    y = shift_right(acc, p.out_shift, p.rounding)
    y, nover = p.out_format.fit(y)
    return y, FirState(hist=hist, phase=(st.phase + len(x)) % p.decimation,
                       overflows=st.overflows + nover, n_in=st.n_in + len(x))


def fir_float_reference(params: FirParams, x, *, quantised_taps: bool = True) -> np.ndarray:
    """Float64 equivalent of :func:`fir_model` from reset, in output LSBs, no rounding.

    ``float_gain * sum_k h[k] x[n-k]`` at the kept outputs, with ``h`` the quantised taps
    (default) or the design's float taps. The golden float chain compares its levels with
    this; ``fir_model``'s output differs from it by the rounding only (unless it overflowed).
    """
    p = params
    x = np.asarray(x, dtype=np.float64)
    h = p.taps_quantised if quantised_taps else np.asarray(p.taps)
    pad = np.zeros((p.numtaps - 1, *x.shape[1:]))
    xp = np.concatenate([pad, x], axis=0)
    y = np.stack([np.convolve(xp[:, c] if x.ndim > 1 else xp, h, mode="valid")
                  for c in range(x.shape[1] if x.ndim > 1 else 1)], axis=-1)
    if x.ndim == 1:
        y = y[:, 0]
    return p.float_gain * y[p.decimation - 1::p.decimation]


# -- compiled fast path ---------------------------------------------------------------------

class FirKernel:
    """Compiled FIR of one channel (:func:`fir_kernel`): the same bits as :func:`fir_model`
    when its output cannot saturate (the caller's headroom check) and the accumulator fits
    float64's exact integers (:meth:`exact`). The history (last ``L-1`` inputs) is the
    caller's int64 array, updated in place."""

    def __init__(self, params: FirParams):
        self.params = params
        self.h = np.array(params.taps_int, dtype=np.float64)
        self.sym = bool(np.array_equal(self.h, self.h[::-1]))
        self.rc = round_consts(params.out_shift, params.rounding)

    @staticmethod
    def exact(params: FirParams) -> bool:
        """Every product and partial sum an integer below ``2**53`` (with margin)."""
        return params.acc_width <= 50

    def run(self, z, hist) -> np.ndarray:
        """Outputs of the input chunk ``z`` (int64) after ``hist``."""
        out = np.empty(len(z) // self.params.decimation, np.int64)
        fir_kernel(z, hist, self.h, self.sym, self.params.decimation, self.rc, out)
        return out


@njit_cached(nogil=True)
def fir_kernel(z, hist, h, sym, down, rc, out):
    """FIR ``sum_t h[t] z[k - t]`` at ``k = down-1, 2 down-1, ...`` of the chunk, preceded
    by ``hist`` (the last ``L-1`` inputs, updated in place), rounded (``rc``: see
    :func:`hdl.model.rounding.round_consts`); ``sym``: the taps are symmetric (one product per pair).
    Accumulates in float64: every product and partial sum is an integer below 2**53, so
    the sums are exact in any order. Blocks of outputs stay in L1; the tap loop is outer
    so the inner loop vectorises."""
    L = h.shape[0]
    K = z.shape[0]
    buf = np.empty(L - 1 + K, dtype=np.float64)
    for t in range(L - 1):
        buf[t] = hist[t]
    for k in range(K):
        buf[L - 1 + k] = z[k]
    count = K // down
    blk = 512
    acc = np.empty(blk, dtype=np.float64)
    for j0 in range(0, count, blk):
        nb = min(blk, count - j0)
        sp = (nb - 1) * down + 1   # input span of nb outputs
        for j in range(nb):
            acc[j] = 0.0
        # Slices: indices from range() are known non-negative, so numba's negative-index
        # wraparound folds away and the loops vectorise; several taps per pass over acc.
        top = j0 * down + down - 1 + L - 1
        if sym:
            # h[t] == h[L-1-t]: one product per tap pair (as the hardware's pre-adder)
            t = 0
            while t + 2 <= L // 2:
                h0, h1 = h[t], h[t + 1]
                s0 = buf[top - t:top - t + sp]
                s1 = buf[top - t - 1:top - t - 1 + sp]
                r0 = buf[top - (L - 1 - t):top - (L - 1 - t) + sp]
                r1 = buf[top - (L - 2 - t):top - (L - 2 - t) + sp]
                if down == 1:
                    for j in range(nb):
                        acc[j] += h0 * (s0[j] + r0[j]) + h1 * (s1[j] + r1[j])
                else:
                    for j in range(nb):
                        jj = j * down
                        acc[j] += h0 * (s0[jj] + r0[jj]) + h1 * (s1[jj] + r1[jj])
                t += 2
            while t < L // 2:
                h0 = h[t]
                s0 = buf[top - t:top - t + sp]
                r0 = buf[top - (L - 1 - t):top - (L - 1 - t) + sp]
                for j in range(nb):
                    acc[j] += h0 * (s0[j * down] + r0[j * down])
                t += 1
            t = L  # the middle tap of an odd length remains
            if L % 2:
                h0 = h[L // 2]
                s0 = buf[top - L // 2:top - L // 2 + sp]
                for j in range(nb):
                    acc[j] += h0 * s0[j * down]
        else:
            t = 0
        while t + 4 <= L:
            h0, h1, h2, h3 = h[t], h[t + 1], h[t + 2], h[t + 3]
            s0 = buf[top - t:top - t + sp]
            s1 = buf[top - t - 1:top - t - 1 + sp]
            s2 = buf[top - t - 2:top - t - 2 + sp]
            s3 = buf[top - t - 3:top - t - 3 + sp]
            if down == 1:
                for j in range(nb):
                    acc[j] += (h0 * s0[j] + h1 * s1[j]) + (h2 * s2[j] + h3 * s3[j])
            else:
                for j in range(nb):
                    jj = j * down
                    acc[j] += (h0 * s0[jj] + h1 * s1[jj]) + (h2 * s2[jj] + h3 * s3[jj])
            t += 4
        while t < L:
            ht = h[t]
            s0 = buf[top - t:top - t + sp]
            for j in range(nb):
                acc[j] += ht * s0[j * down]
            t += 1
        for j in range(nb):
            out[j0 + j] = rnd(np.int64(acc[j]), rc)
    for t in range(L - 1):
        hist[t] = np.int64(buf[K + t])
