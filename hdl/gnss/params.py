"""GPS L1 C/A tracking channel: its parameters and word lengths (:class:`GnssChannelParams`),
register map (:attr:`GnssChannelParams.registers`), record layout (:attr:`GnssChannelParams.record`) and the
register words (:func:`code_freq_word`, :meth:`GnssChannelParams.carr_word`). What each
register and field means is specified with the model, :mod:`hdl.gnss.model`.

The default frequency plan (:data:`DEFAULT_FS_HZ`, :data:`DEFAULT_IF_HZ`) is the one home of
the rate every GNSS default, study and benchmark uses; :func:`code_phase_step_chips` is the
code-phase resolution a rate gives a signal without code Doppler.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import NamedTuple

import numpy as np

from dsp.fixed import check_width
from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, PRN_MAX, PRN_MIN, check_prn
from dsp.record_layout import RecordLayout
from dsp.register_map import Register, RegisterMap
from hdl.model.fifo import FifoParams
from hdl.model.mixer import MixerParams
from hdl.model.nco import NcoParams, nco_freq_word

#: Default ADC sample rate = channel clock (S/s): 16384 samples per 1 ms code period (a
#: power of two: radix-2 FFTs for the acquisition), 16.0156 samples per chip. Not a whole
#: number of samples per chip: 16384 and 1023 have no common factor, so over a code period
#: the samples fall at every 1/16384 chip of the chip edges and the code loop resolves the
#: code phase (a rate of k samples per chip, such as 16.368 MS/s = 16 x 1.023 MHz, puts
#: every sample at the same k offsets within a chip: a dead zone of 1/k chip,
#: :func:`code_phase_step_chips`).
DEFAULT_FS_HZ = 16.384e6
#: Default IF (Hz): the SiGe SE4110L front end's 4.1304 MHz. Commensurate with neither the
#: chip rate nor the sample rate: an IF of 4 x 1.023 MHz (4.092 MHz) puts the carrier at the
#: same phase on every chip edge, and the real mixer's double-frequency product then biases
#: the early-minus-late discriminator by up to 0.015 chip (measured at 16.384 MS/s, 0.02 at
#: 20 MS/s) where the edges fall; an IF of exactly fs / 4 repeats four carrier phases, so a
#: zero Doppler pins the ADC's and the LO's quantisation to the carrier.
DEFAULT_IF_HZ = 4.1304e6
#: Register addresses (per channel; an array adds ``4 * channel``).
REG_CARR_FREQ, REG_CODE_FREQ, REG_PRN, REG_SLEW = range(4)
#: Signal bandwidth of C/A (main lobe, null to null), Hz: the lowest sample rate accepted.
CA_BANDWIDTH_HZ = 2 * CHIP_RATE_HZ
#: The channel's input kinds (:attr:`GnssChannelParams.input`).
INPUTS = ("real", "complex")
#: What an ADC word stands for (:class:`GnssChannelParams` ``adc_levels``).
ADC_LEVELS = ("twos", "odd")
#: Record fields before ``channel``.
ACC_FIELDS = ("ie", "qe", "ip", "qp", "il", "ql")


def _number(name, v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(float(v)):
        raise ValueError(f"GNSS channel {name} must be a finite number, not {v!r}")
    return float(v)


class CodeWord(NamedTuple):
    word: int          #: code NCO frequency word
    actual_hz: float   #: chipping rate it gives, chip/s
    error_hz: float    #: actual - requested


def code_freq_word(chip_rate_hz: float, *, fs_hz: float, code_phase_bits: int) -> CodeWord:
    """Code NCO word for ``chip_rate_hz`` (nominal 1.023e6 plus code Doppler) at ``fs_hz``,
    rounded to nearest; at most one chip per sample."""
    check_width("GNSS code_phase_bits", code_phase_bits, minimum=8, maximum=32)
    r = _number("chip_rate_hz", chip_rate_hz)
    fs = _number("fs_hz", fs_hz)
    if not 0 < r < fs:
        raise ValueError(f"code chip rate must be in (0, fs_hz = {fs!r}) (at most one chip "
                         f"per sample), not {chip_rate_hz!r}")
    n = round(Fraction(r) / Fraction(fs) * (1 << code_phase_bits))
    if n >= 1 << code_phase_bits:
        raise ValueError(f"code chip rate {chip_rate_hz!r} rounds to one chip per sample")
    actual = float(Fraction(n) * Fraction(fs) / (1 << code_phase_bits))
    return CodeWord(int(n), actual, actual - r)


def code_phase_step_chips(fs_hz: float) -> float:
    """The finest code-phase step (chips) the correlations resolve for a signal whose code
    keeps a fixed phase to the sample clock (no code Doppler): with ``fs_hz / 1.023 MHz =
    p / q`` in lowest terms (the rate to the mHz), the samples fall at only ``p`` offsets
    within a chip, so the early-minus-late discriminator is a staircase of ``1 / p`` chip
    steps and the code loop stops where it enters a step: a dead zone of ``1 / p`` chip. 16.368
    MS/s (16 x 1.023 MHz) gives 1/16 chip (18 m), the default 16.384 MS/s 1/16384 chip."""
    fs = _number("fs_hz", fs_hz)
    if fs <= 0:
        raise ValueError(f"fs_hz must be > 0, not {fs_hz!r}")
    ratio = Fraction(round(fs * 1000), round(CHIP_RATE_HZ * 1000))
    return 1.0 / ratio.numerator


def dump_epochs_for(dump_s: float) -> int:
    """Code periods in a dump of ``dump_s`` seconds; ``ValueError`` unless it is a whole
    number (>= 1) of 1 ms code periods."""
    t = _number("dump length", dump_s)
    k = round(t / 1e-3)
    if k < 1 or abs(t - k * 1e-3) > 1e-12:
        raise ValueError(f"dump length must be a whole number (>= 1) of 1 ms code periods, "
                         f"not {dump_s!r} s")
    return int(k)


@dataclass(frozen=True)
class GnssChannelParams:
    """Parameters of one tracking channel (:class:`hdl.gnss.channel.GnssChannel`).

    Parameters
    ----------
    fs_hz : float
        ADC sample rate = clock rate, Hz (>= 2.046 MHz, the C/A main-lobe bandwidth);
        default :data:`DEFAULT_FS_HZ`.
    if_hz : float
        Nominal IF, Hz: the reset carrier word. Real input: in the first Nyquist zone
        ``[0, fs_hz / 2)``; complex input: in ``(-fs_hz / 2, fs_hz / 2)`` (0: zero IF).
    adc_bits : int
        Signed ADC word (1..16), per component for a complex input; 1 bit means sign
        samples +-1.
    adc_levels : {"twos", "odd"}
        What an ADC word ``q`` stands for: ``"twos"``, the two's-complement value ``q``;
        ``"odd"``, the odd level ``2 q + 1`` (a sign/magnitude front end's +-1, +-3, ...:
        symmetric, no DC), one bit wider into the mixer. A 1-bit word is always odd
        (+-1). A two's-complement reading of odd levels carries a DC of -1/2 LSB, which a
        complex low IF puts next to the carrier.
    input : {"real", "complex"}
        ``"real"``: one real ADC stream at ``if_hz``, real carrier wipe-off. ``"complex"``:
        two ADC streams I and Q (the input payload ``{"i", "q"}``, I at the LSB: see
        :meth:`pack_samples`), the signal ``I + jQ`` at the complex IF ``if_hz`` (0 for
        zero-IF baseband), complex wipe-off ``(I + jQ) exp(-j phi)``. Both use one
        carrier-word sign convention: a signal at ``+f`` (real: ``cos 2 pi f t``; complex:
        ``exp(+j 2 pi f t)``) is wiped off by the word of ``+f``, so a positive Doppler
        is tracked with ``carr_word(if_hz + doppler)``. A front end whose spectrum is
        inverted delivers ``I - jQ``: its Q sign is turned before the channel (as
        :class:`cosim.gnss.files.SampleFile` reads it), after which the Doppler sign is the
        ordinary one.
    carr_phase_bits, carr_table_bits, lo_bits : int
        Carrier NCO accumulator (8..32), sine-table address (4..12) and LO amplitude bits
        (2..16).
    code_phase_bits : int
        Code NCO accumulator (8..32).
    el_spacing_samples : int
        Early-minus-late spacing in samples, even, 2..128 (prompt is in the middle).
    dump_epochs : int
        Code periods per dump, 1..64 (must be whole: see :func:`dump_epochs_for`).
    slew_bits : int
        Width of the slew register (samples of code hold), 1..24.
    epoch_bits : int
        Width of the record's epoch counter, 1..32.
    max_code_doppler_hz : float
        Largest code-rate decrease below 1.023 Mcps the accumulator widths allow for, Hz.
    prn : int
        PRN at reset, 1..32.
    fifo_width, fifo_depth : int
        FIFO payload bits per word and depth in words.
    record_words : int, optional
        FIFO words per record; default the fewest that hold the record.
    channel_bits : int
        Width of a ``channel`` field appended to the record (0 for a single channel; set
        by :class:`GnssChannelArray`).
    """

    fs_hz: float = DEFAULT_FS_HZ
    if_hz: float = DEFAULT_IF_HZ
    adc_bits: int = 2
    carr_phase_bits: int = 32
    carr_table_bits: int = 8
    lo_bits: int = 4
    code_phase_bits: int = 32
    el_spacing_samples: int = 8
    dump_epochs: int = 1
    slew_bits: int = 16
    epoch_bits: int = 16
    max_code_doppler_hz: float = 100.0
    prn: int = 1
    fifo_width: int = 51
    fifo_depth: int = 512
    record_words: int | None = None
    channel_bits: int = 0
    input: str = "real"
    adc_levels: str = "twos"

    def __post_init__(self):
        if not isinstance(self.adc_levels, str) or self.adc_levels not in ADC_LEVELS:
            raise ValueError(f"GNSS adc_levels must be one of {', '.join(ADC_LEVELS)} (the "
                             f"word q as q, or as the odd level 2q+1), not {self.adc_levels!r}")
        if not isinstance(self.input, str) or self.input not in INPUTS:
            raise ValueError(f"GNSS channel input must be one of {', '.join(INPUTS)} (one real "
                             f"ADC stream, or I and Q), not {self.input!r}")
        fs = _number("fs_hz", self.fs_hz)
        if fs < CA_BANDWIDTH_HZ:
            raise ValueError(f"GNSS sample rate fs_hz must be >= the C/A signal bandwidth "
                             f"{CA_BANDWIDTH_HZ:g} Hz, not {self.fs_hz!r}")
        f_if = _number("if_hz", self.if_hz)
        if self.input == "complex":
            if not -fs / 2 < f_if < fs / 2:
                raise ValueError(f"GNSS IF of a complex input must lie in (-fs_hz/2, fs_hz/2) = "
                                 f"({-fs / 2:g}, {fs / 2:g}) Hz, not {self.if_hz!r}")
        elif not 0 <= f_if < fs / 2:
            raise ValueError(f"GNSS IF must lie in the first Nyquist zone [0, fs_hz/2 = "
                             f"{fs / 2:g}) Hz, not {self.if_hz!r}")
        check_width("GNSS adc_bits", self.adc_bits, minimum=1, maximum=16)
        check_width("GNSS carr_phase_bits", self.carr_phase_bits, minimum=8, maximum=32)
        check_width("GNSS carr_table_bits", self.carr_table_bits, minimum=4,
                    maximum=min(12, self.carr_phase_bits))
        check_width("GNSS lo_bits", self.lo_bits, minimum=2, maximum=16)
        check_width("GNSS code_phase_bits", self.code_phase_bits, minimum=8, maximum=32)
        s = self.el_spacing_samples
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or not 2 <= s <= 128 \
                or s % 2:
            raise ValueError(f"GNSS el_spacing_samples (early-minus-late, samples) must be an "
                             f"even integer in [2, 128], not {s!r}")
        k = self.dump_epochs
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
            if isinstance(k, (float, np.floating)) and float(k).is_integer():
                raise ValueError(f"GNSS dump_epochs must be an int, not {k!r}")
            raise ValueError(f"GNSS dump length must be a whole number of code periods "
                             f"(dump_epochs an integer in [1, 64]), not {k!r}")
        check_width("GNSS dump_epochs", k, minimum=1, maximum=64)
        check_width("GNSS slew_bits", self.slew_bits, minimum=1, maximum=24)
        check_width("GNSS epoch_bits", self.epoch_bits, minimum=1, maximum=32)
        cd = _number("max_code_doppler_hz", self.max_code_doppler_hz)
        if not 0 <= cd < CHIP_RATE_HZ / 2:
            raise ValueError(f"GNSS max_code_doppler_hz must be in [0, {CHIP_RATE_HZ / 2:g}), "
                             f"not {self.max_code_doppler_hz!r}")
        check_prn(self.prn)
        if fs / CHIP_RATE_HZ * CODE_LENGTH < 4 * s:
            raise ValueError(f"GNSS el_spacing_samples must be below a quarter code period, "
                             f"not {s}")
        check_width("GNSS channel_bits", self.channel_bits, minimum=0, maximum=8)
        # A record wider than the FIFO's record is refused here, FIFO limits by FifoParams.
        rw = self.record_words
        if rw is not None:
            check_width("GNSS record_words", rw, minimum=1, maximum=64)
            if rw * self.fifo_width < self.record_bits:
                raise ValueError(
                    f"GNSS record of {self.record_bits} bits is wider than the FIFO record "
                    f"(record_words * fifo_width = {rw} * {self.fifo_width} = "
                    f"{rw * self.fifo_width} bits)")
        self.fifo  # validates width and depth (FifoParams' own messages)

    # -- derived ---------------------------------------------------------------------------
    @property
    def half_spacing(self) -> int:
        """``d``: prompt is ``d`` samples behind early, late ``2 d``."""
        return self.el_spacing_samples // 2

    @property
    def nco(self) -> NcoParams:
        return NcoParams(phase_bits=self.carr_phase_bits, table_bits=self.carr_table_bits,
                         amp_bits=self.lo_bits, dither_bits=0, phase_port=True)

    @property
    def complex_input(self) -> bool:
        """Two ADC streams I and Q (``input == "complex"``)."""
        return self.input == "complex"

    @property
    def mixer_in_width(self) -> int:
        """Signed width of an ADC component into the mixer: ``adc_bits``, one more for odd
        levels (:attr:`odd_levels`)."""
        return self.adc_bits + 1 if self.odd_levels else self.adc_bits

    @property
    def odd_levels(self) -> bool:
        """True when a word ``q`` enters the mixer as ``2 q + 1`` (``adc_levels="odd"`` or
        a 1-bit ADC)."""
        return self.adc_levels == "odd" or self.adc_bits == 1

    @property
    def mixer(self) -> MixerParams:
        """Full-precision mixer: ``drop_bits == 0``, nothing rounded, and wide enough that
        nothing overflows.

        Bound: with ``a = mixer_in_width``, ``b = lo_bits``, an ADC component ``|x| <=
        2**(a-1)`` and the NCO's symmetric peak ``|cos|, |sin| <= A = 2**(b-1) - 1``:

        * real, ``I = x cos``, ``Q = -x sin``: ``|I|, |Q| <= 2**(a-1) A < 2**(a+b-2)``, so
          ``out_width = a + b - 1``;
        * complex, ``I = xi cos + xq sin``, ``Q = xq cos - xi sin`` (a sum of two
          products): ``|I|, |Q| <= 2**(a-1) (|cos| + |sin|) <= 2**a A < 2**(a+b-1)``, so
          ``out_width = a + b`` (one bit more; ``headroom_bits = 1`` keeps
          ``drop_bits = 0``: the output is the exact sum).

        Either way ``|I|, |Q| < 2**(iq_width - 1)`` per sample, which :attr:`acc_width`
        builds on.

        Two input stages (:attr:`MixerParams.input_stages`): the second, each channel's own
        registers beside its DSP blocks, takes the route from the NCO and the ADC delay line
        (shared by every channel of an array) off the multiplier path, the 12-channel
        array's critical path with one stage.
        """
        a, b = self.mixer_in_width, self.lo_bits
        if self.complex_input:
            return MixerParams(in_width=a, complex_input=True, lo_width=b, out_width=a + b,
                               rounding="floor", overflow="wrap", headroom_bits=1,
                               input_stages=2)
        return MixerParams(in_width=a, complex_input=False, lo_width=b, out_width=a + b - 1,
                           rounding="floor", overflow="wrap", input_stages=2)

    @property
    def iq_width(self) -> int:
        """Signed width of the wiped-off ``I``, ``Q`` of one sample (:attr:`mixer`)."""
        return self.mixer.out_width

    @property
    def input_width(self) -> int:
        """Bits of the input payload: ``adc_bits`` (real) or ``2 * adc_bits`` (I, Q)."""
        return self.adc_bits * (2 if self.complex_input else 1)

    def check_samples(self, samples) -> np.ndarray:
        """``samples`` as int64 ADC words, checked: real, a 1-D array; complex, an ``(n, 2)``
        array of ``(I, Q)`` pairs; every word signed ``adc_bits``. ``ValueError`` naming
        what is wrong otherwise."""
        x = np.asarray(samples)
        if x.dtype.kind not in "iu" and not (x.size == 0 and x.dtype.kind == "f"):
            raise ValueError(f"GNSS samples must be integers, not dtype {x.dtype}")
        x = x.astype(np.int64)
        if self.complex_input:
            if x.ndim != 2 or x.shape[1] != 2:
                if x.size == 0 and x.ndim == 1:
                    x = x.reshape(0, 2)
                else:
                    raise ValueError(f"GNSS samples of a complex-input channel must be an "
                                     f"(n, 2) array of (I, Q) pairs, not shape {x.shape}")
        elif x.ndim != 1:
            raise ValueError(f"GNSS samples of a real-input channel must be a 1-D array, not "
                             f"shape {x.shape} (input='complex' takes (n, 2) I/Q pairs)")
        lo, hi = -(1 << (self.adc_bits - 1)), (1 << (self.adc_bits - 1)) - 1
        if x.size and (x.min() < lo or x.max() > hi):
            raise ValueError(f"GNSS samples must be signed {self.adc_bits}-bit in [{lo}, {hi}]")
        return x

    def pack_samples(self, samples) -> np.ndarray:
        """The input port's payload words of ``samples`` (checked as by
        :meth:`check_samples`): real, the ADC words; complex, ``I`` in the low ``adc_bits``
        and ``Q`` above (two's complement each), as ``int64``."""
        x = self.check_samples(samples)
        if not self.complex_input:
            return x
        m = (1 << self.adc_bits) - 1
        return (x[:, 0] & m) | ((x[:, 1] & m) << self.adc_bits)

    def unpack_samples(self, words) -> np.ndarray:
        """Inverse of :meth:`pack_samples`: payload words to ADC samples (real: 1-D;
        complex: ``(n, 2)``)."""
        w = np.asarray(words)
        if w.dtype.kind not in "iu" and not (w.size == 0 and w.dtype.kind == "f"):
            raise ValueError(f"GNSS input words must be integers, not dtype {w.dtype}")
        w = w.astype(np.int64).ravel()
        b = self.adc_bits
        if not self.complex_input:
            return self.check_samples(w)
        if w.size and (w.min() < 0 or w.max() >= 1 << (2 * b)):
            raise ValueError(f"GNSS I/Q input words are unsigned {2 * b}-bit (I, Q packed), "
                             f"found {int(w[(w < 0) | (w >= 1 << (2 * b))][0])}")
        s = np.int64(1 << (b - 1))
        m = np.int64((1 << b) - 1)
        i, q = w & m, (w >> np.int64(b)) & m
        return np.stack([(i ^ s) - s, (q ^ s) - s], axis=-1)

    @property
    def max_dump_samples(self) -> int:
        """Longest dump the accumulators are sized for: ``dump_epochs`` code periods at the
        slowest chipping rate plus the longest slew."""
        per = math.ceil(CODE_LENGTH * self.fs_hz / (CHIP_RATE_HZ - self.max_code_doppler_hz))
        return self.dump_epochs * per + (1 << self.slew_bits) - 1

    @property
    def acc_width(self) -> int:
        """Signed accumulator width: ``|I| < 2**(iq_width-1)`` per sample, so
        ``iq_width + ceil(log2(max_dump_samples))`` holds any dump."""
        return self.iq_width + (self.max_dump_samples - 1).bit_length()

    @property
    def reg_data_width(self) -> int:
        """Bus data width: the widest register."""
        return max(r.width for r in self.registers.registers)

    @property
    def record(self) -> RecordLayout:
        """The record's fields, LSB first: the six accumulators, ``epoch``, ``carr_phase``,
        ``code_phase`` and, in an array, ``channel``."""
        f = [(n, self.acc_width, True) for n in ACC_FIELDS]
        f += [("epoch", self.epoch_bits, False), ("carr_phase", self.carr_phase_bits, False),
              ("code_phase", self.code_phase_bits, False)]
        if self.channel_bits:
            f.append(("channel", self.channel_bits, False))
        return RecordLayout(tuple(f))

    @property
    def record_bits(self) -> int:
        return self.record.bits

    @property
    def fifo(self) -> FifoParams:
        rw = self.record_words or -(-self.record_bits // self.fifo_width)
        return FifoParams(width=self.fifo_width, depth=self.fifo_depth, record_words=rw)

    @property
    def latency(self) -> int:
        """Cycles from the input cycle of a dump's first sample to its record at the FIFO
        input: carrier NCO, mixer, replica-product register, accumulator/record register."""
        return self.nco.latency + self.mixer.latency + 2

    # -- register values -------------------------------------------------------------------
    def carr_word(self, f_hz: float) -> int:
        return nco_freq_word(f_hz, f_clk_hz=self.fs_hz, phase_bits=self.carr_phase_bits).word

    def code_word(self, chip_rate_hz: float = CHIP_RATE_HZ) -> int:
        return code_freq_word(chip_rate_hz, fs_hz=self.fs_hz,
                              code_phase_bits=self.code_phase_bits).word

    @property
    def registers(self) -> RegisterMap:
        """The register map (per channel; an array adds ``4 * channel``): ``carr_freq``,
        ``code_freq`` (the NCO words), ``prn`` (1-32, 6 bits) and ``slew``."""
        return RegisterMap("GNSS", (
            Register("carr_freq", REG_CARR_FREQ, self.carr_phase_bits),
            Register("code_freq", REG_CODE_FREQ, self.code_phase_bits),
            Register("prn", REG_PRN, 6, minimum=PRN_MIN, maximum=PRN_MAX),
            Register("slew", REG_SLEW, self.slew_bits)))
