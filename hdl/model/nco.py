"""NCO parameters, frequency-word conversion and the bit-exact numpy model.

The NCO is a ``phase_bits`` phase accumulator driving a quarter-wave sine table.

Phase and table addressing
--------------------------
Output sample ``n`` (counted from reset, one per step request) has the phase word

    p[n] = (acc[n] + phase_offset[n] + dither[n] * 2**(phase_bits - table_bits - dither_bits))
           mod 2**phase_bits,          acc[0] = 0,  acc[n+1] = acc[n] + freq[n],

where ``freq[n]`` and ``phase_offset[n]`` are the port values in the cycle of step ``n``
and ``dither[n]`` is a signed ``dither_bits`` word (0 when off). The table address is the
top ``table_bits`` bits, ``a = p >> (phase_bits - table_bits)`` (plain truncation: no
adder). The table stores the angle at the *centre* of each address bin,

    theta(a) = 2*pi*(a + 1/2) / 2**table_bits,

and this half-LSB offset is the documented choice: (1) truncation followed by bin-centre
evaluation is round-to-nearest of the phase, so the phase error is in (-1/2, 1/2] LSB with
zero mean (no constant -1/2 LSB rotation as with a plain truncating LUT); (2) the sampled
angles avoid 0 and pi/2, so the quarter table ``S[k] = round(peak*sin(2*pi*(k+1/2)/2**T))``,
``k = 0 .. 2**(T-2)-1`` is exactly mirror-symmetric: ``cos(theta_k) = S[~k]`` (bitwise NOT of
the ``T-2`` address bits). No entry is duplicated or special-cased and negation never
overflows, because every stored value lies in ``[0, peak]`` with ``peak = 2**(amp_bits-1)-1``.

With ``q`` the top two address bits and ``k`` the rest::

    q | sin        cos
    0 | +S[k]      +S[~k]
    1 | +S[~k]     -S[k]
    2 | -S[k]      -S[~k]
    3 | -S[~k]     +S[k]

Dither
------
``dither_bits`` > 0 adds a signed (two's complement, hence almost zero-mean) pseudo-random
word whose MSB sits just below the table address LSB, before truncation. The bits come from
a 63-bit Fibonacci LFSR with characteristic polynomial x^63 + x + 1 (primitive, period
2**63 - 1): the bit stream obeys ``s[m+63] = s[m] ^ s[m+1]`` and ``s[0:63]`` is the seed
(bit ``j`` of ``dither_seed`` is ``s[j]``). Sample ``n`` takes the bits
``s[n*D : n*D + D]`` (first bit is the LSB) and the register then advances ``D`` steps.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import NamedTuple

import numpy as np

from dsp.fixed import check_width

#: LFSR length of the dither generator (x^63 + x + 1).
LFSR_BITS = 63
#: Default dither seed: any nonzero 63-bit value; this one has balanced ones and zeros so
#: the first samples already look random (a sparse seed warms up slowly on a trinomial).
DEFAULT_DITHER_SEED = 0x2545F4914F6CDD1D

_MASK64 = (1 << 64) - 1


@dataclass(frozen=True)
class NcoParams:
    """Parameters of the LUT NCO.

    Parameters
    ----------
    phase_bits : int
        Phase accumulator width in bits (3..62); frequency resolution
        ``f_clk / 2**phase_bits`` Hz per step-rate Hz.
    table_bits : int
        Address bits of the full circle (3..20, <= phase_bits); the ROM holds
        ``2**(table_bits - 2)`` entries of ``amp_bits - 1`` bits.
    amp_bits : int
        Signed output width in bits (2..32); peak amplitude ``2**(amp_bits-1) - 1``.
    dither_bits : int
        Width of the signed phase dither added below the table LSB (0 = off); at most
        ``min(62, phase_bits - table_bits)``.
    dither_seed : int
        Nonzero 63-bit initial state of the dither LFSR.
    phase_port : bool
        Whether the component has a run-time phase offset input ``phase``.
    """

    phase_bits: int = 32
    table_bits: int = 10
    amp_bits: int = 16
    dither_bits: int = 0
    dither_seed: int = DEFAULT_DITHER_SEED
    phase_port: bool = False

    def __post_init__(self):
        check_width("NCO phase_bits", self.phase_bits, minimum=3, maximum=62)
        check_width("NCO table_bits", self.table_bits, minimum=3, maximum=20)
        check_width("NCO amp_bits", self.amp_bits, minimum=2, maximum=32)
        if self.table_bits > self.phase_bits:
            raise ValueError(
                "NCO LUT larger than the phase width: table_bits must be <= phase_bits, "
                f"not table_bits={self.table_bits} > phase_bits={self.phase_bits}")
        max_dither = min(LFSR_BITS - 1, self.phase_bits - self.table_bits)
        if (isinstance(self.dither_bits, bool) or not isinstance(self.dither_bits, (int, np.integer))
                or not 0 <= self.dither_bits <= max_dither):
            raise ValueError(
                "NCO dither_bits must be an integer in [0, min(62, phase_bits - table_bits)] "
                f"= [0, {max_dither}], not {self.dither_bits!r}")
        if (isinstance(self.dither_seed, bool) or not isinstance(self.dither_seed, (int, np.integer))
                or not 0 < self.dither_seed < (1 << LFSR_BITS)):
            raise ValueError(
                f"NCO dither_seed must be a nonzero {LFSR_BITS}-bit integer, not {self.dither_seed!r}")
        if not isinstance(self.phase_port, bool):
            raise ValueError(f"NCO phase_port must be a bool, not {self.phase_port!r}")

    # -- derived -------------------------------------------------------------------------
    @property
    def freq_width(self) -> int:
        """Width of the ``freq`` (and ``phase``) port: ``phase_bits``."""
        return self.phase_bits

    @property
    def quarter_bits(self) -> int:
        """Address bits of the stored quarter-wave table."""
        return self.table_bits - 2

    @property
    def rom_depth(self) -> int:
        return 1 << (self.table_bits - 2)

    @property
    def rom_width(self) -> int:
        """Stored entries are non-negative, so the sign bit is not stored."""
        return self.amp_bits - 1

    @property
    def peak(self) -> int:
        return (1 << (self.amp_bits - 1)) - 1

    @property
    def trunc_bits(self) -> int:
        """Phase LSBs dropped when addressing the table."""
        return self.phase_bits - self.table_bits

    @property
    def dither_shift(self) -> int:
        """Left shift that puts the dither MSB just below the table LSB."""
        return self.phase_bits - self.table_bits - self.dither_bits

    @property
    def latency(self) -> int:
        """Cycles from an accepted step to its ``o.valid`` (accumulate/offset, dither add,
        ROM read, ROM data register, sign)."""
        return 5


class FreqWord(NamedTuple):
    """A frequency word and the error it introduces."""

    word: int          #: unsigned port value (two's complement for negative frequencies)
    actual_hz: float   #: frequency the word really produces, Hz (signed)
    error_hz: float    #: actual_hz - requested, Hz
    error_ppm: float   #: error relative to the requested frequency, ppm (0 for 0 Hz)


def nco_freq_word(f_hz: float, *, f_clk_hz: float, phase_bits: int) -> FreqWord:
    """The NCO frequency word for ``f_hz`` at step rate ``f_clk_hz``, rounded to nearest.

    Parameters
    ----------
    f_hz : float
        Wanted frequency in Hz, ``|f_hz| < f_clk_hz / 2``; negative means a clockwise
        phasor (the word is its two's complement).
    f_clk_hz : float
        Rate of the NCO steps in Hz (the ADC sample rate in the DDC), > 0.
    phase_bits : int
        Phase accumulator width.

    Raises
    ------
    ValueError
        Non-finite inputs, a non-positive clock, or a frequency at or beyond Nyquist
        (also when rounding reaches the Nyquist word ``2**(phase_bits-1)``).
    """
    phase_bits = check_width("NCO phase_bits", phase_bits, minimum=3, maximum=62)
    for name, v in (("f_hz", f_hz), ("f_clk_hz", f_clk_hz)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or not math.isfinite(float(v)):
            raise ValueError(f"NCO {name} must be a finite number, not {v!r}")
    if not f_clk_hz > 0:
        raise ValueError(f"NCO f_clk_hz must be > 0, not {f_clk_hz!r}")
    if abs(f_hz) >= f_clk_hz / 2:
        raise ValueError(
            f"NCO frequency word out of range: |f_hz| must be < f_clk_hz/2 = {f_clk_hz / 2!r}, "
            f"not {f_hz!r}")
    exact = Fraction(float(f_hz)) / Fraction(float(f_clk_hz)) * (1 << phase_bits)
    n = round(exact)  # Fraction rounds half to even, exactly
    if abs(n) >= 1 << (phase_bits - 1):
        raise ValueError(
            f"NCO frequency word out of range: {f_hz!r} Hz rounds to the Nyquist word at "
            f"phase_bits={phase_bits}")
    actual = float(Fraction(n) * Fraction(float(f_clk_hz)) / (1 << phase_bits))
    err = actual - float(f_hz)
    ppm = 0.0 if f_hz == 0 else err / float(f_hz) * 1e6
    return FreqWord(n % (1 << phase_bits), actual, err, ppm)


# -- LFSR ------------------------------------------------------------------------------------

def lfsr_bits(seed: int, n: int) -> np.ndarray:
    """The first ``n`` bits of the dither LFSR stream (uint8), ``s[0:63]`` being ``seed``.

    Vectorised with the Frobenius identity: if x^63 + x + 1 annihilates the stream, so does
    its 2**j-th power, i.e. ``s[m] = s[m - 63*2**j] ^ s[m - 62*2**j]``, which fills
    ``62*2**j`` new bits per numpy operation.
    """
    total = max(int(n), LFSR_BITS)
    s = np.empty(total, dtype=np.uint8)
    s[:LFSR_BITS] = (int(seed) >> np.arange(LFSR_BITS, dtype=np.uint64).astype(np.int64)) & 1
    m = LFSR_BITS
    while m < total:
        j = (m // LFSR_BITS).bit_length() - 1
        far, near = LFSR_BITS << j, (LFSR_BITS - 1) << j
        block = min(near, total - m)
        np.bitwise_xor(s[m - far:m - far + block], s[m - near:m - near + block],
                       out=s[m:m + block])
        m += block
    return s[:n]


def _pack_state(bits: np.ndarray) -> int:
    return int(np.dot(bits.astype(np.uint64), np.uint64(1) << np.arange(len(bits), dtype=np.uint64)))


# -- model -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class NcoState:
    """Everything the NCO carries from one sample to the next."""

    acc: int   #: phase accumulator (phase of the next sample before offset and dither)
    lfsr: int  #: dither LFSR register (bit j = the next-but-j stream bit)


def nco_quarter_table(params: NcoParams) -> np.ndarray:
    """The stored ROM: ``round(peak * sin(2*pi*(k + 1/2) / 2**table_bits))`` (int64)."""
    k = np.arange(params.rom_depth, dtype=np.float64)
    theta = 2 * np.pi * (k + 0.5) / (1 << params.table_bits)
    # floor(x + 0.5) = round half up; no value here sits on a tie in practice.
    return np.floor(params.peak * np.sin(theta) + 0.5).astype(np.int64)


def nco_full_tables(params: NcoParams) -> tuple[np.ndarray, np.ndarray]:
    """(cos, sin) for every ``table_bits`` address, unfolded from the quarter table exactly
    as the hardware folds it (see the module docstring)."""
    s = nco_quarter_table(params)
    a = np.arange(1 << params.table_bits, dtype=np.int64)
    qb = params.quarter_bits
    k = a & ((1 << qb) - 1)
    q = a >> qb
    odd = (q & 1).astype(bool)
    nk = k ^ ((1 << qb) - 1)
    sin_mag = np.where(odd, s[nk], s[k])
    cos_mag = np.where(odd, s[k], s[nk])
    sin_neg = (q >> 1).astype(bool)
    cos_neg = ((q >> 1) ^ (q & 1)).astype(bool)
    return np.where(cos_neg, -cos_mag, cos_mag), np.where(sin_neg, -sin_mag, sin_mag)


class NcoModel:
    """Bit-exact model of :class:`hdl.nco.Nco` (values per step; timing is the latency).

    Parameters
    ----------
    params : NcoParams
    """

    def __init__(self, params: NcoParams):
        self.params = params
        self.cos_table, self.sin_table = nco_full_tables(params)

    def initial_state(self) -> NcoState:
        """The state after reset."""
        return NcoState(acc=0, lfsr=int(self.params.dither_seed))

    def dither(self, n: int, state: NcoState | None = None) -> tuple[np.ndarray, int]:
        """Signed dither words of the next ``n`` steps and the LFSR state after them."""
        p = self.params
        st = self.initial_state() if state is None else state
        d = p.dither_bits
        if d == 0:
            return np.zeros(n, dtype=np.int64), st.lfsr
        bits = lfsr_bits(st.lfsr, n * d + LFSR_BITS)
        wt = np.int16 if d <= 15 else np.int32 if d <= 31 else np.int64  # less memory traffic
        words = np.zeros(n, dtype=wt)
        for j in range(d - 1):
            words |= bits[j:n * d:d].astype(wt) << wt(j)
        words -= bits[d - 1:n * d:d].astype(wt) << wt(d - 1)  # sign bit
        words = words.astype(np.int64)
        return words, _pack_state(bits[n * d:])

    def addresses(self, n: int, freq_word, state: NcoState | None = None, *,
                  phase_offset=0) -> tuple[np.ndarray, NcoState]:
        """Table addresses of the next ``n`` steps and the state after them.

        Parameters
        ----------
        n : int
            Number of steps.
        freq_word : int or array of int, shape (n,)
            Frequency word of each step (taken mod ``2**phase_bits``; negative values
            are two's complement).
        state : NcoState, optional
            State before the first step (default: after reset).
        phase_offset : int or array of int, shape (n,)
            ``phase`` port value at each step (mod ``2**phase_bits``).
        """
        p = self.params
        st = self.initial_state() if state is None else state
        n = int(n)
        pmask = np.uint64((1 << p.phase_bits) - 1)
        fw = np.asarray(freq_word)
        if fw.ndim == 0:
            f = np.uint64(int(fw) & _MASK64)
            steps = np.arange(n, dtype=np.uint64)
            steps *= f
            acc_after = (int(st.acc) + n * int(f)) & int(pmask)
            ph = steps
        else:
            if fw.shape != (n,):
                raise ValueError(f"freq_word must be a scalar or have shape ({n},), not {fw.shape}")
            f = fw.astype(np.int64).astype(np.uint64)  # two's complement mod 2**64
            ph = np.empty(n, dtype=np.uint64)
            if n:
                ph[0] = 0
                np.cumsum(f[:-1], out=ph[1:])
            acc_after = (int(st.acc) + int(np.sum(f, dtype=np.uint64))) & int(pmask)
        ph += np.uint64(int(st.acc) & int(pmask))
        po = np.asarray(phase_offset)
        if po.ndim != 0 or int(po) != 0:
            if not p.phase_port:
                raise ValueError("phase_offset needs NcoParams(phase_port=True)")
            ph += po.astype(np.int64).astype(np.uint64) if po.ndim else np.uint64(int(po) & _MASK64)
        lfsr = st.lfsr
        if p.dither_bits:
            d, lfsr = self.dither(n, st)
            ph += (d << np.int64(p.dither_shift)).astype(np.uint64)
        ph &= pmask
        ph >>= np.uint64(p.trunc_bits)
        return ph.astype(np.int64), NcoState(acc=acc_after, lfsr=lfsr)

    def run(self, n: int, freq_word, state: NcoState | None = None, *,
            phase_offset=0) -> tuple[np.ndarray, np.ndarray, NcoState]:
        """(cos, sin, state) of the next ``n`` steps; arguments as :meth:`addresses`."""
        a, st = self.addresses(n, freq_word, state, phase_offset=phase_offset)
        return self.cos_table[a], self.sin_table[a], st
