"""CIC decimator: parameters, derived widths and the bit-exact numpy model.

An N-stage CIC decimator (Hogenauer 1981) is N integrators at the input rate, a decimation
by R, and N combs ``1 - z**-M`` at the output rate. Its DC gain is ``(R M)**N``, so the
full-precision register width is

    B_max = in_width + ceil(N log2(R M))          (Hogenauer eq. 11)

and every stage may wrap around in two's complement: the output is a linear combination of
integrator values with integer weights and a true value that fits ``B_max`` bits, so it
comes out exact modulo ``2**B_max`` and therefore exact.

Register pruning (``prune=True``) drops LSBs at each stage's input. Hogenauer's rule
(E. B. Hogenauer, "An economical class of digital filters for decimation and
interpolation", IEEE Trans. ASSP 29(2):155-162, Apr. 1981, eqs. 12-21) chooses the number
``B_j`` of LSBs discarded at the input of stage ``j = 1..2N`` so that each of the 2N
truncation noises, seen at the output, has at most ``1/(2N)`` of the variance of the output
rounding noise:

    F_j**2 = sum_k h_j(k)**2     (h_j: impulse response from the input of stage j to the
                                  output; j <= N at the input rate, j > N at the output rate)
    sigma_T**2 = 2**(2 B_out) / 12,   B_out = B_max - out_width (LSBs dropped at the output)
    B_j = floor(-log2 F_j + log2 sigma_T + log2(6/N) / 2)
        = floor(B_out - log2 F_j - log2(2N) / 2),   clipped to [0, B_out]

so the total pruning noise variance is at most the output rounding variance. Stage ``j``
keeps ``B_max + 1 - max(B_1..B_j)`` bits (the MSB never moves; LSBs already gone stay gone).
Two deliberate departures from the paper, both on the safe side:

* ``B_1 = 0``: truncating the input of the first integrator is the only pruning error that
  reaches the output with a DC gain ((R M)**N); every later stage's error path has a zero
  at DC. Keeping stage 1 whole makes the pruning noise zero-mean (Hogenauer's criterion is
  on variance only; a truncated stage 1 biases the output by up to a few LSBs).
* one guard MSB when anything is pruned: the truncation noise can push a full-scale result
  just outside ``B_max`` bits, which would wrap negative full scale to positive full scale;
  with the guard bit the excursion reaches the output stage and is saturated (or wrapped,
  per ``overflow``) and counted.

The model mirrors the hardware sample for sample: the integrators are ``cumsum`` with a wrap
to the stage width after each stage, the decimator keeps the inputs whose running count is
``R-1 (mod R)`` since reset (the R-th, 2R-th, ... sample), the combs are vector differences.
State (integrator values, decimation phase, comb delay lines, overflow count) is passed in
and out so long runs can be done in chunks with the same bits.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from dsp.fixed import OVERFLOWS, ROUNDINGS, FixedFormat, check_samples, check_width, \
    shift_right

__all__ = ["CicParams", "CicState", "cic_init_state", "cic_model", "cic_float_gain",
           "hogenauer_f2"]


def _poly_mul(a: list[int], b: list[int]) -> list[int]:
    out = [0] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        if x:
            for k, y in enumerate(b):
                out[i + k] += x * y
    return out


@functools.lru_cache(maxsize=256)
def _impulse_response(stages: int, rm: int) -> tuple[int, ...]:
    h = [1]
    for _ in range(stages):
        h = _poly_mul(h, [1] * rm)
    return tuple(h)


@functools.lru_cache(maxsize=256)
def hogenauer_f2(stages: int, rate: int, diff_delay: int) -> tuple[int, ...]:
    """Hogenauer's variance gains ``F_j**2`` for j = 1..2N (exact integers).

    ``F_j**2`` is the sum of squares of the impulse response from the input of stage ``j``
    to the CIC output: for an integrator stage (j <= N) at the input rate,
    ``(1 - z**-RM)**N / (1 - z**-1)**(N-j+1)``; for a comb stage (j > N) at the output rate,
    ``(1 - z**-M)**(2N+1-j)`` (its sum of squares does not depend on M).
    """
    n, rm = stages, rate * diff_delay
    box = [1] * rm
    f2 = []
    for j in range(1, n + 1):
        # (1 - z^-RM)^N / (1 - z^-1)^(N-j+1) = (sum_{k<RM} z^-k)^(N-j+1) (1 - z^-RM)^(j-1)
        h = [1]
        for _ in range(n - j + 1):
            h = _poly_mul(h, box)
        diff = [1] + [0] * (rm - 1) + [-1]
        for _ in range(j - 1):
            h = _poly_mul(h, diff)
        f2.append(sum(c * c for c in h))
    for j in range(n + 1, 2 * n + 1):
        m = 2 * n + 1 - j
        f2.append(math.comb(2 * m, m))  # sum_l C(m, l)^2
    return tuple(f2)


@dataclass(frozen=True)
class CicParams:
    """Parameters of a CIC decimator; every width and latency is derived here.

    Parameters
    ----------
    stages : int
        Number of integrator/comb pairs N (1..8).
    rate : int
        Decimation factor R (>= 2).
    diff_delay : int
        Differential delay M of the combs (1 or 2).
    in_width : int
        Input sample width in bits (signed, 2..62).
    channels : int
        1: real signed samples; 2: complex samples as ``StructLayout({"i", "q"})``.
    out_width : int, optional
        Output width in bits (default: the full width ``B_max``); the ``B_max - out_width``
        LSBs are dropped with ``rounding``.
    rounding : {"floor", "half_up", "half_even", "zero"}
        Rounding of the LSBs dropped at the output (see ``dsp.fixed``).
    overflow : {"saturate", "wrap"}
        What an output out of ``out_width`` range becomes (counted by the model). Only
        possible near full scale: a rounding carry (rounding other than floor), or pruning
        noise on a full-scale result.
    prune : bool
        Hogenauer register pruning (see the module docstring); needs ``out_width < B_max``
        to have any effect.
    """

    stages: int = 3
    rate: int = 4
    diff_delay: int = 1
    in_width: int = 18
    channels: int = 2
    out_width: int | None = None
    rounding: str = "floor"
    overflow: str = "saturate"
    prune: bool = False

    def __post_init__(self):
        def is_int(v):
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)
        if not is_int(self.stages) or not 1 <= self.stages <= 8:
            raise ValueError(f"CIC stages must be an integer in [1, 8], not {self.stages!r}")
        if not is_int(self.rate) or self.rate < 2:
            raise ValueError(f"CIC decimation must be an integer >= 2, not {self.rate!r}")
        if not is_int(self.diff_delay) or self.diff_delay not in (1, 2):
            raise ValueError(f"CIC differential delay must be 1 or 2, not {self.diff_delay!r}")
        check_width("CIC in_width", self.in_width, minimum=2)
        if not is_int(self.channels) or self.channels not in (1, 2):
            raise ValueError(f"CIC channels must be 1 (real) or 2 (complex), not {self.channels!r}")
        growth = ((self.rate * self.diff_delay) ** self.stages - 1).bit_length()
        full = int(self.in_width) + growth
        if full > 62:
            raise ValueError(f"CIC full register width in_width + ceil(N log2(R M)) must be "
                             f"<= 62, not {full}")
        if self.out_width is None:
            object.__setattr__(self, "out_width", full)
        if (not is_int(self.out_width) or not 2 <= self.out_width <= full):
            raise ValueError(f"CIC out_width must be an integer in [2, {full}] (the full "
                             f"width), not {self.out_width!r}")
        if self.rounding not in ROUNDINGS:
            raise ValueError(f"CIC rounding must be one of {ROUNDINGS}, not {self.rounding!r}")
        if self.overflow not in OVERFLOWS:
            raise ValueError(f"CIC overflow must be one of {OVERFLOWS}, not {self.overflow!r}")
        if not isinstance(self.prune, bool):
            raise ValueError(f"CIC prune must be a bool, not {self.prune!r}")
        for name in ("stages", "rate", "diff_delay", "in_width", "channels", "out_width"):
            object.__setattr__(self, name, int(getattr(self, name)))

    # -- derived widths ------------------------------------------------------------------
    @property
    def gain(self) -> int:
        """DC gain ``(R M)**N`` of the integer filter before the output shift."""
        return (self.rate * self.diff_delay) ** self.stages

    @property
    def full_width(self) -> int:
        """Hogenauer's B_max = in_width + ceil(N log2(R M)) (computed exactly in integers)."""
        return self.in_width + (self.gain - 1).bit_length()

    @property
    def out_shift(self) -> int:
        """LSBs dropped at the output, ``B_max - out_width`` (Hogenauer's B_{2N+1})."""
        return self.full_width - self.out_width

    @property
    def hogenauer_bits(self) -> tuple[int, ...]:
        """Hogenauer's B_j for j = 1..2N as his formula gives them (clipped to [0, B_out]),
        whether or not ``prune`` is set."""
        n, bo = self.stages, self.out_shift
        return tuple(min(max(math.floor(bo - 0.5 * math.log2(f2) - 0.5 * math.log2(2 * n)), 0), bo)
                     for f2 in hogenauer_f2(n, self.rate, self.diff_delay))

    @property
    def hogenauer_discard(self) -> tuple[int, ...]:
        """LSBs discarded at the input of each of the 2N stages: :attr:`hogenauer_bits` with
        ``B_1 = 0`` (see the module docstring) if ``prune``, else all 0."""
        if not self.prune:
            return (0,) * (2 * self.stages)
        return (0,) + self.hogenauer_bits[1:]

    @property
    def stage_lsbs(self) -> tuple[int, ...]:
        """Weight (log2, in input LSBs) of the LSB of each of the 2N stage registers:
        the running maximum of :attr:`hogenauer_discard`."""
        lsb, out = 0, []
        for b in self.hogenauer_discard:
            lsb = max(lsb, b)
            out.append(lsb)
        return tuple(out)

    @property
    def guard_bits(self) -> int:
        """Extra MSB kept in every stage when pruning discards bits: truncation noise can
        push a full-scale result just past ``B_max`` bits, which would otherwise wrap from
        negative to positive full scale; with the guard bit it is saturated at the output."""
        return 1 if any(self.hogenauer_discard) else 0

    @property
    def stage_widths(self) -> tuple[int, ...]:
        """Register width of each of the 2N stages (integrators first, then combs):
        ``B_max + guard_bits - stage_lsbs[j]``."""
        return tuple(self.full_width + self.guard_bits - b for b in self.stage_lsbs)

    @property
    def impulse_response(self) -> tuple[int, ...]:
        """The integer CIC as an FIR at the input rate: ``(sum_{k<RM} z**-k)**N``
        (length ``(R M - 1) N + 1``, sum ``(R M)**N``)."""
        return _impulse_response(self.stages, self.rate * self.diff_delay)

    @property
    def latency(self) -> int:
        """Cycles from the input transfer that completes a decimation group to the output
        transfer: N integrators + N combs + rounding + overflow registers."""
        return 2 * self.stages + 2

    @property
    def out_format(self) -> FixedFormat:
        """Output word format; ``frac`` counts LSBs relative to the input LSB (negative:
        the output LSB weighs ``2**out_shift`` input LSBs)."""
        return FixedFormat(self.out_width, -self.out_shift, True, self.rounding, self.overflow)

    @property
    def float_gain(self) -> float:
        """Output integer per input integer at DC: ``(R M)**N / 2**out_shift``. The golden
        float chain (``dsp.design.cic_taps``, DC gain 1) times this gives the output level."""
        return self.gain / 2.0 ** self.out_shift

    @property
    def sample_shape(self) -> tuple[int, ...]:
        """Trailing shape of model sample arrays: () for real, (2,) for complex (i, q)."""
        return () if self.channels == 1 else (2,)


def cic_float_gain(params: CicParams) -> float:
    """Float-equivalent DC gain: output integers = input integers x this (+ rounding)."""
    return params.float_gain


@dataclass
class CicState:
    """Model state between chunks (``cic_init_state``: just after reset).

    Only the fields of the method in use are meaningful: ``hist`` for the direct method,
    ``integ``/``combs`` for the stage one.
    """

    integ: np.ndarray          # (N, *sample_shape) integrator values (stage units)
    combs: np.ndarray          # (N, M, *sample_shape) comb delay lines, newest first
    hist: np.ndarray           # (L-1, *sample_shape) last inputs, oldest first
    phase: int = 0             # valid inputs since reset, mod R
    overflows: int = 0         # output words saturated/wrapped so far
    n_in: int = 0              # input samples consumed so far
    method: str = ""           # the method that produced this state


def cic_init_state(params: CicParams) -> CicState:
    """The state just after reset."""
    s = params.sample_shape
    return CicState(integ=np.zeros((params.stages, *s), np.int64),
                    combs=np.zeros((params.stages, params.diff_delay, *s), np.int64),
                    hist=np.zeros((len(params.impulse_response) - 1, *s), np.int64))


def _check_input(params: CicParams, x) -> np.ndarray:
    return check_samples("CIC input", x, params.in_width, params.sample_shape,
                         f" for channels={params.channels}")


def _wrap(v: np.ndarray, width: int) -> np.ndarray:
    # Two's-complement wrap, cheaper than dsp.fixed.wrap's np.where.
    half = np.int64(1) << np.int64(width - 1)
    return ((v + half) & ((half << np.int64(1)) - np.int64(1))) - half


def cic_model(params: CicParams, x, state: CicState | None = None, *,
              method: str = "auto") -> tuple[np.ndarray, CicState]:
    """Bit-exact CIC decimator.

    Parameters
    ----------
    params : CicParams
    x : array of int, shape (n,) for channels=1 or (n, 2) for channels=2 (columns i, q)
        Input samples (only the valid ones: gaps in valid do not change the output values).
    state : CicState, optional
        From a previous call with the same params and method (default: just after reset).
        Not modified.
    method : {"auto", "direct", "stages"}
        ``"stages"`` runs the integrators (``cumsum``) and combs as the hardware does.
        ``"direct"`` computes the decimated outputs as the equivalent FIR
        (:attr:`CicParams.impulse_response`) on a polyphase split, about 2x faster; it is
        exact only without pruning (the hardware result is the exact sum mod 2**B_max and
        fits B_max bits). ``"auto"``: direct unless pruning discards bits. The tests run
        both against each other and against the HDL.

    Returns
    -------
    y : ndarray of int64, shape (m, *sample_shape)
        Output samples (``out_width`` bits, signed), one per R inputs.
    state : CicState
        State after the last input; ``state.overflows`` counts saturated/wrapped outputs.
    """
    p = params
    if method not in ("auto", "direct", "stages"):
        raise ValueError(f"CIC model method must be auto, direct or stages, not {method!r}")
    pruned = p.guard_bits > 0
    if method == "auto":
        method = "stages" if pruned else "direct"
    if method == "direct" and pruned:
        raise ValueError("CIC model method 'direct' is exact only without pruning; "
                         f"use 'stages' (params discard {p.hogenauer_discard})")
    x = _check_input(p, x)
    st = cic_init_state(p) if state is None else state
    if st.method and st.method != method:
        raise ValueError(f"CIC state comes from method {st.method!r}, not {method!r}")
    r = p.rate
    first = (r - 1 - st.phase) % r     # keep inputs whose count since reset is R-1 mod R
    if method == "direct":
        v, hist = _direct(p, x, st, first)
        integ, combs = st.integ, st.combs
        lsb_out = 0
    else:
        v, integ, combs = _stages(p, x, st, first)
        hist = st.hist
        lsb_out = p.stage_lsbs[-1]
    y = shift_right(v, p.out_shift - lsb_out, p.rounding)
    y, nover = p.out_format.fit(y)
    new = CicState(integ=integ, combs=combs, hist=hist, phase=(st.phase + len(x)) % r,
                   overflows=st.overflows + nover, n_in=st.n_in + len(x), method=method)
    return y, new


def _direct(p: CicParams, x: np.ndarray, st: CicState, first: int):
    h = p.impulse_response
    taps, r = len(h), p.rate
    xp = np.concatenate([st.hist, x], axis=0)
    hist = xp[len(xp) - (taps - 1):].copy()
    count = len(range(first, len(x), r))
    v = np.zeros((count, *p.sample_shape), np.int64)
    if count:
        # Polyphase: split the padded input into R contiguous phases once; each tap is then
        # a contiguous slice of one phase (strided reads cost about 3x more).
        frames = -(-len(xp) // r)
        padded = np.zeros((frames * r, *p.sample_shape), np.int64)
        padded[:len(xp)] = xp
        padded = padded.reshape(frames, r, *p.sample_shape)
        phases = [np.ascontiguousarray(padded[:, b]) for b in range(r)]
        tmp = np.empty_like(v)
        base = first + taps - 1
        for t, c in enumerate(h):
            f0, b = divmod(base - t, r)
            # int64 wraps mod 2**64; the true sum fits B_max bits, so the wrap is exact.
            np.multiply(phases[b][f0:f0 + count], np.int64(c), out=tmp)
            v += tmp
    return _wrap(v, p.full_width), hist


def _stages(p: CicParams, x: np.ndarray, st: CicState, first: int):
    n, r, m = p.stages, p.rate, p.diff_delay
    lsbs = (0,) + p.stage_lsbs
    widths = p.stage_widths
    integ = st.integ.copy()
    # int64 arithmetic wraps mod 2**64, which is exact mod 2**W for every W <= 62, so a
    # stage's wrap can wait until a shift needs the true (wrapped) value, or the end.
    v = x
    for j in range(n):
        sh = lsbs[j + 1] - lsbs[j]
        if sh:
            v = _wrap(v, widths[j - 1]) >> np.int64(sh) if j else v >> np.int64(sh)
        if not len(v):
            continue
        if v is x:
            v = x.copy()
        # Seed the first sample with the state rather than adding it to every sample:
        # a broadcast add over a trailing axis of length 2 is ~20x slower than cumsum.
        v[0] += integ[j]
        np.cumsum(v, axis=0, out=v)
        integ[j] = _wrap(v[-1], widths[j])
    v = v[first::r]
    combs = st.combs.copy()
    for j in range(n):
        k = n + j
        sh = lsbs[k + 1] - lsbs[k]
        if sh:
            v = _wrap(v, widths[k - 1]) >> np.int64(sh)
        hist = np.concatenate([combs[j][::-1], v], axis=0)   # oldest first
        combs[j] = _wrap(hist[::-1][:m], widths[k])
        v = v - hist[:len(v)]
    return _wrap(v, widths[-1]), integ, combs
