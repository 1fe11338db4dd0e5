"""Monopulse FPGA front end: parameters, register map, record layout and bit-exact model.

The hardware is :mod:`hdl.monopulse.frontend`; this module is its specification.

Chain (one ``sync`` clock = the ADC rate; 4 phase-coherent channels)::

    4 ADC ----------------------------------------------------+
    replica chip --(NCO latency)--+                            |
    NCO (shared) -> LO * (+-1) ----+-> 4 x DDC (external LO) -> 4 x CIC (-> 4 x FIR)
      -> 4 x complex correction k_i (registers) -> beams S, dA, dE, dd
      -> accumulate N snapshots -> normalise -> Im(d S*), |S|^2 -> CORDIC (both axes)
      -> u = u0 + 2 a / Dx, v = v0 + 2 a / Dy -> one record -> FIFO -> DSP

Per ADC sample (one per ``i.valid`` cycle)
------------------------------------------
The input word carries the four ADC codes and the replica bit of the sample's chip (0 = +1,
1 = -1). The shared NCO (:class:`hdl.nco.Nco`, word :attr:`MonopulseFrontendParams.nco_freq_word`,
fixed) gives ``(cos, sin)``; *replica wipe-off*: the LO is negated when the chip is -1 (the
NCO's table is symmetric, so the negation never overflows) and drives the four DDCs
(:class:`hdl.ddc.Ddc`, ``external_lo=True``). Despreading at the LO instead of after the
filter costs one negation for all four channels; with the default integrate-and-dump
(CIC N=1, R = fs / chip rate, chips constant over a decimation group) it equals
``sum_n z(n) c(n)`` exactly, so the matched filter of the golden chain
(:mod:`dsp.monopulse.golden`) is the accumulation that follows. Each DDC output goes through
a CIC decimator (:class:`hdl.cic.Cic`) and optionally a FIR decimator (:class:`hdl.fir.Fir`);
snapshot ``k`` is the ``k``-th decimator output since reset.

Per snapshot
------------
*Correction.* ``w_i = k_i z_i`` by a complex mixer (:class:`hdl.mixer.Mixer`,
``complex_input=True``, LO port ``cos = Re k_i``, ``sin = -Im k_i``); ``k_i`` is the channel's
coefficient register, ``(re + j im) / 2**(corr_coef_bits - 1)``, each part in
``[-(2**(b-1) - 1), 2**(b-1) - 1]`` (symmetric, so ``-im`` fits). The DSP writes the digital
steering ``exp(j phi_i0)`` times its calibration into it. Output scaled by
``2**-corr_headroom_bits`` of full scale, saturating.

*Beams* (RECEIVERS.md section 3 mapping)::

    S = w1 + w2 + w3 + w4,  dA = (w1 + w2) - (w3 + w4),  dE = (w1 + w3) - (w2 + w4),
    dd = (w1 + w4) - (w2 + w3)

``dd`` (the double difference) makes the four beams a Hadamard transform of the channels,
so the DSP can recover every channel's matched-filter output for calibration:
``S_1 = (S + dA + dE + dd) / 4`` etc.

*Matched filter.* Block ``b`` is snapshots ``[b N, (b + 1) N)``; its beams are summed
exactly in ``acc_width`` bits (never overflows).

Per block (the angle unit)
--------------------------
1. Normalise (block floating point, common to the six S/dA/dE values so the ratios are
   kept): ``L`` = the signed width of the largest of them, ``r = max(0, L - cordic_in_bits)``,
   each value ``>> r`` (floor).
2. ``x = Sr^2 + Si^2``, ``y_A = dAi Sr - dAr Si``, ``y_E = dEi Sr - dEr Si``
   (``y / x = Im(d / S)``, no division).
3. Vectoring CORDIC (:class:`dsp.cordic.CordicConfig`, ``width = 2 cordic_in_bits + 1``,
   ``cordic_iterations``, signed binary angle of ``angle_bits`` per turn; ``x >= 0`` so the
   pre-rotation never happens; ``x = y = 0`` gives 0): ``a = atan(Im(d / S))`` in turns.
4. Direction cosines: ``dphi = -2 a`` (rad ``= -4 pi a_turns``), ``u = u0 - dphi / (2 pi Dx)
   = u0 + 2 a_turns / Dx``: ``du = round_half_up(a k_x / 2**(angle_bits + k_frac - dc_frac_bits))``
   with the constant ``k_x = round(2 / Dx 2**k_frac)`` (``dc_coef_bits``), ``u = u0 + du`` in
   ``dc_frac_bits`` fraction bits (``dc_bits = dc_frac_bits + 3`` signed: never overflows).
   ``u0``, ``v0`` are the steering registers (the command the DSP sent to the beam control
   unit). Azimuth/elevation (``atan2``, ``arcsin``) stay on the DSP: the tracker works on
   direction cosines, so the board hands over what it tracks.

Registers (bus ``reg_we``, ``reg_addr``, ``reg_data``; double buffered)
---------------------------------------------------------------------
:data:`REG_COEF` + i (i = 0..3): channel ``i + 1``'s coefficient, ``re | im << corr_coef_bits``
(two's complement each); :data:`REG_U0`, :data:`REG_V0`: steering direction cosines
(two's complement, ``dc_frac_bits`` fraction bits, ``|u0| <= 1``). A write in cycle ``c``
lands in the shadow register from cycle ``c + 1``. At the *block boundary* of block ``b``,
the cycle its last snapshot enters the correction stage, the shadows become active for
block ``b + 1`` (a write in the boundary cycle itself waits for the next boundary); the
record of block ``b`` carries the ``u0, v0`` active during block ``b``. Reset: every
coefficient :attr:`MonopulseFrontendParams.unit_coef` (gain 1 - 2**-(b-1), phase 0),
``u0 = v0 = 0``.

Record (LSB first; :attr:`MonopulseFrontendParams.record`)
---------------------------------------------------------------
``block`` (``block_bits``, wraps), ``u``, ``v`` (``dc_bits`` signed), ``ang_a``, ``ang_e``
(``angle_bits`` signed: ``a`` of each axis, turns), ``shift`` (the normalisation ``r``),
``s_re, s_im, da_re, da_im, de_re, de_im, dd_re, dd_im`` (``acc_width`` signed: the
accumulated beams, before normalisation), split into ``record_words`` FIFO words of
``fifo_width`` bits (word 0 = the lowest bits). It enters the FIFO
:attr:`MonopulseFrontendParams.latency` cycles after the input cycle of the ADC sample
that completes the block's last snapshot.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dsp.cordic import CordicConfig
from dsp.fixed import ROUNDINGS, check_width, shift_right
from dsp.record_layout import RecordLayout
from hdl.model.cic import CicParams, cic_model
from hdl.model.ddc import DdcModel, DdcParams
from hdl.model.fifo import FifoParams, FifoState, fifo_model_events
from hdl.model.fir import FirParams, fir_model
from hdl.model.mixer import MixerModel, MixerParams
from hdl.model.nco import NcoModel, NcoParams, nco_freq_word

__all__ = ["MonopulseFrontendParams", "MonopulseFrontendModel", "MonopulseRecords",
           "REG_COEF", "REG_U0", "REG_V0", "REG_NAMES", "BEAMS", "pack_input", "coef_word",
           "dc_word", "hadamard_channels"]

#: Register addresses.
REG_COEF, REG_U0, REG_V0 = 0, 4, 5
#: Register names (the DSP's view, :class:`cosim.session.RegisterSession`) -> addresses.
REG_NAMES = {"coef1": REG_COEF, "coef2": REG_COEF + 1, "coef3": REG_COEF + 2,
             "coef4": REG_COEF + 3, "u0": REG_U0, "v0": REG_V0}
#: Accumulated beam fields of the record, in order.
BEAMS = ("s", "da", "de", "dd")
_ACC_FIELDS = tuple(f"{b}_{c}" for b in BEAMS for c in ("re", "im"))


def _num(name, v, *, positive=False):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(float(v)):
        raise ValueError(f"monopulse front end {name} must be a finite number, not {v!r}")
    if positive and not float(v) > 0:
        raise ValueError(f"monopulse front end {name} must be > 0, not {v!r}")
    return float(v)


def _rounding(name, v):
    if v not in ROUNDINGS:
        raise ValueError(f"monopulse front end {name} must be one of {ROUNDINGS}, not {v!r}")


@dataclass(frozen=True)
class MonopulseFrontendParams:
    """Rates, structure and every word length of the monopulse front end.

    Parameters
    ----------
    fs_hz, if_hz : float
        ADC (= clock) rate and IF (Hz); ``0 < if_hz < fs_hz / 2``. The NCO word is the IF's.
    snapshot_decimation : int
        ADC samples per snapshot (= fs / chip rate, 10); must equal ``cic_rate * fir_decim``.
    adc_bits : int
        Signed ADC word (2..16).
    nco_phase_bits, nco_table_bits, nco_amp_bits : int
        Shared NCO accumulator, table address and amplitude widths.
    mixer_out_bits, mixer_rounding
        DDC mixer output width (LSB ``2**-(out-1)`` FS; never saturates) and rounding.
    mixer_input_stages, corr_input_stages : int
        Register stages in front of the multipliers of each DDC mixer and of each channel
        correction (1..4, default 2: the shared NCO's LO reaches four channels' DSP blocks,
        and the snapshots reach four multipliers each; with one stage that wire and the
        multiplier were the critical path, 97.6 and 82.9 MHz). Latency only.
    cic_stages, cic_rate, cic_out_bits, cic_rounding
        CIC decimator (default N = 1, R = 10: the chip's integrate-and-dump, the golden
        chain's low-pass). ``cic_out_bits=None``: the full Hogenauer width.
    fir_taps : tuple of float or None
        Symmetric FIR after the CIC (None: no FIR; after an integrate-and-dump matched to a
        rectangular chip a snapshot-rate FIR only adds inter-chip interference, so the
        default has none). ``fir_decim``, ``fir_coef_bits``, ``fir_out_bits`` (None: natural),
        ``fir_rounding``.
    corr_coef_bits : int
        Correction coefficient width per part (2..18: one 18x18 multiplier).
    corr_out_bits, corr_headroom_bits, corr_rounding
        Corrected snapshot width, extra right shift, rounding (saturating).
    snapshots : int
        Snapshots per measurement N (>= 1; 8192).
    cordic_in_bits : int
        Width of the normalised beams entering the ratio (4..30).
    cordic_iterations : int
        CORDIC micro-rotations (4..32).
    angle_bits : int
        Binary angle bits per turn (8..40).
    spacing_x_wl, spacing_y_wl : float
        Subarray spacings Dx, Dy (wavelengths, >= 0.5).
    dc_frac_bits, dc_coef_bits : int
        Fraction bits of the direction cosines (8..40) and width of the ``2 / D`` constants
        (4..25).
    block_bits : int
        Record block counter width (1..32).
    fifo_width, fifo_depth, fifo_count_bits : int
        FIFO payload bits per word, depth (words), overflow-counter width.
    """

    fs_hz: float = 100e6
    if_hz: float = 20e6
    snapshot_decimation: int = 10
    adc_bits: int = 12
    nco_phase_bits: int = 32
    nco_table_bits: int = 10
    nco_amp_bits: int = 16
    mixer_out_bits: int = 16
    mixer_rounding: str = "half_even"
    mixer_input_stages: int = 2
    cic_stages: int = 1
    cic_rate: int = 10
    cic_out_bits: int | None = 18
    cic_rounding: str = "half_even"
    fir_taps: tuple | None = None
    fir_decim: int = 1
    fir_coef_bits: int = 18
    fir_out_bits: int | None = None
    fir_rounding: str = "half_even"
    corr_coef_bits: int = 18
    corr_out_bits: int = 18
    corr_headroom_bits: int = 1
    corr_rounding: str = "half_even"
    corr_input_stages: int = 2
    snapshots: int = 8192
    cordic_in_bits: int = 16
    cordic_iterations: int = 20
    angle_bits: int = 24
    spacing_x_wl: float = 4.0
    spacing_y_wl: float = 4.0
    dc_frac_bits: int = 22
    dc_coef_bits: int = 18
    block_bits: int = 16
    fifo_width: int = 48
    fifo_depth: int = 64
    fifo_count_bits: int = 16
    _blocks: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        fs = _num("fs_hz", self.fs_hz, positive=True)
        f_if = _num("if_hz", self.if_hz)
        if not 0 < f_if < fs / 2:
            raise ValueError(f"monopulse front end if_hz must lie in (0, fs_hz/2 = {fs / 2:g}) "
                             f"Hz, not {self.if_hz!r}")
        check_width("monopulse adc_bits", self.adc_bits, minimum=2, maximum=16)
        check_width("monopulse snapshot_decimation", self.snapshot_decimation, minimum=2,
                    maximum=4096)
        check_width("monopulse cic_stages", self.cic_stages, minimum=1, maximum=6)
        check_width("monopulse cic_rate", self.cic_rate, minimum=2, maximum=4096)
        check_width("monopulse fir_decim", self.fir_decim, minimum=1, maximum=64)
        if self.fir_taps is None and self.fir_decim != 1:
            raise ValueError(f"monopulse fir_decim must be 1 without a FIR (fir_taps=None), "
                             f"not {self.fir_decim!r}")
        if self.cic_rate * self.fir_decim != self.snapshot_decimation:
            raise ValueError(
                f"monopulse decimation cic_rate * fir_decim must equal snapshot_decimation "
                f"(ADC samples per snapshot), not {self.cic_rate} * {self.fir_decim} != "
                f"{self.snapshot_decimation}")
        for name in ("mixer_rounding", "cic_rounding", "fir_rounding", "corr_rounding"):
            _rounding(name, getattr(self, name))
        check_width("monopulse corr_coef_bits", self.corr_coef_bits, minimum=2, maximum=18)
        check_width("monopulse corr_out_bits", self.corr_out_bits, minimum=4, maximum=30)
        check_width("monopulse corr_headroom_bits", self.corr_headroom_bits, minimum=0,
                    maximum=8)
        n = self.snapshots
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= 1 << 24:
            raise ValueError(f"monopulse snapshots must be an integer in [1, 2**24], not {n!r}")
        check_width("monopulse cordic_in_bits", self.cordic_in_bits, minimum=4, maximum=30)
        check_width("monopulse cordic_iterations", self.cordic_iterations, minimum=4,
                    maximum=32)
        check_width("monopulse angle_bits", self.angle_bits, minimum=8, maximum=40)
        for name in ("spacing_x_wl", "spacing_y_wl"):
            d = _num(name, getattr(self, name), positive=True)
            if d < 0.5:
                raise ValueError(f"monopulse front end {name} must be >= 0.5 wavelengths, "
                                 f"not {getattr(self, name)!r}")
        check_width("monopulse dc_frac_bits", self.dc_frac_bits, minimum=8, maximum=40)
        check_width("monopulse dc_coef_bits", self.dc_coef_bits, minimum=4, maximum=25)
        check_width("monopulse block_bits", self.block_bits, minimum=1, maximum=32)
        check_width("monopulse fifo_width", self.fifo_width, minimum=8, maximum=60)
        check_width("monopulse fifo_count_bits", self.fifo_count_bits, minimum=1, maximum=32)

        b = self._blocks
        nco = NcoParams(phase_bits=self.nco_phase_bits, table_bits=self.nco_table_bits,
                        amp_bits=self.nco_amp_bits)
        mixer = MixerParams(in_width=self.adc_bits, lo_width=nco.amp_bits,
                            out_width=self.mixer_out_bits, rounding=self.mixer_rounding,
                            overflow="saturate", input_stages=self.mixer_input_stages)
        b["ddc"] = DdcParams(nco=nco, mixer=mixer)
        b["cic"] = CicParams(stages=self.cic_stages, rate=self.cic_rate, diff_delay=1,
                             in_width=mixer.out_width, channels=2, out_width=self.cic_out_bits,
                             rounding=self.cic_rounding, overflow="saturate")
        snap_w = b["cic"].out_width
        if self.fir_taps is not None:
            b["fir"] = FirParams(taps=tuple(self.fir_taps), coef_bits=self.fir_coef_bits,
                                 decimation=self.fir_decim, in_width=snap_w, channels=2,
                                 out_width=self.fir_out_bits, rounding=self.fir_rounding,
                                 overflow="saturate", input_spacing=self.cic_rate)
            snap_w = b["fir"].out_width
        else:
            b["fir"] = None
        if snap_w > 30:
            raise ValueError(f"monopulse snapshot width (decimator output) must be <= 30 bits, "
                             f"not {snap_w} (set cic_out_bits / fir_out_bits)")
        b["corr"] = MixerParams(in_width=snap_w, complex_input=True,
                                lo_width=self.corr_coef_bits, out_width=self.corr_out_bits,
                                rounding=self.corr_rounding, overflow="saturate",
                                headroom_bits=self.corr_headroom_bits,
                                input_stages=self.corr_input_stages)
        b["cordic"] = CordicConfig(width=2 * self.cordic_in_bits + 1,
                                   iterations=self.cordic_iterations,
                                   angle_bits=self.angle_bits, signed_angle=True)
        if b["cordic"].lut_bits > 62 or b["cordic"].datapath_bits > 62:
            raise ValueError("monopulse CORDIC datapath must fit 62 bits: reduce "
                             "cordic_in_bits or angle_bits")
        b["k"] = tuple(self._dc_coef(d) for d in (self.spacing_x_wl, self.spacing_y_wl))
        if min(s for _, s in b["k"]) < 0:
            raise ValueError(f"monopulse dc_frac_bits {self.dc_frac_bits} exceeds the angle "
                             f"and coefficient precision: use dc_frac_bits <= angle_bits + "
                             f"coefficient fraction bits")
        fp = self.fifo
        fp  # FifoParams validates width and depth
        need = self.corr.latency + 2 + self.latency_angle + self.record_words
        if self.snapshots * self.snapshot_decimation < need:
            raise ValueError(
                f"monopulse block too short: snapshots * snapshot_decimation = "
                f"{self.snapshots * self.snapshot_decimation} cycles must be >= {need} (the "
                f"angle unit and the FIFO's record write must finish before the next block)")

    def _dc_coef(self, d: float) -> tuple[int, int]:
        """``(k, shift)``: ``2 / d`` as ``k / 2**frac`` in ``dc_coef_bits``; ``shift`` =
        ``angle_bits + frac - dc_frac_bits`` dropped after ``a * k``."""
        c = 2.0 / d
        frac = self.dc_coef_bits - 1 - math.floor(math.log2(c))
        while round(c * 2 ** frac) > (1 << (self.dc_coef_bits - 1)) - 1:
            frac -= 1
        return int(round(c * 2 ** frac)), self.angle_bits + frac - self.dc_frac_bits

    # -- blocks --------------------------------------------------------------------------
    @property
    def ddc(self) -> DdcParams:
        return self._blocks["ddc"]

    @property
    def nco(self) -> NcoParams:
        return self._blocks["ddc"].nco

    @property
    def cic(self) -> CicParams:
        return self._blocks["cic"]

    @property
    def fir(self) -> FirParams | None:
        return self._blocks["fir"]

    @property
    def corr(self) -> MixerParams:
        """The correction multiplier (a complex :class:`~hdl.model.mixer.MixerParams`)."""
        return self._blocks["corr"]

    @property
    def cordic(self) -> CordicConfig:
        return self._blocks["cordic"]

    @property
    def dc_coefs(self) -> tuple[tuple[int, int], tuple[int, int]]:
        """``((k_x, shift_x), (k_y, shift_y))`` of the direction-cosine step."""
        return self._blocks["k"]

    # -- widths --------------------------------------------------------------------------
    @property
    def nco_freq_word(self) -> int:
        return nco_freq_word(self.if_hz, f_clk_hz=self.fs_hz, phase_bits=self.nco_phase_bits).word

    @property
    def snap_width(self) -> int:
        """Signed width of a decimated snapshot (correction input)."""
        return self.corr.in_width

    @property
    def beam_width(self) -> int:
        """Signed width of a beam: corrected snapshot + 2 (sum of four)."""
        return self.corr_out_bits + 2

    @property
    def acc_width(self) -> int:
        """Signed matched-filter accumulator width: ``beam_width + ceil(log2 N)``."""
        return self.beam_width + (self.snapshots - 1).bit_length()

    @property
    def shift_bits(self) -> int:
        """Width of the normalisation shift field (holds ``acc_width - cordic_in_bits``)."""
        return max(1, max(0, self.acc_width - self.cordic_in_bits).bit_length())

    @property
    def dc_bits(self) -> int:
        """Signed width of ``u``, ``v``, ``u0``, ``v0``: sign, 2 integer bits, fraction."""
        return self.dc_frac_bits + 3

    @property
    def coef_max(self) -> int:
        return (1 << (self.corr_coef_bits - 1)) - 1

    @property
    def unit_coef(self) -> int:
        """Reset value of every coefficient register (re = 2**(b-1) - 1, im = 0)."""
        return self.coef_max

    @property
    def reg_data_width(self) -> int:
        return max(2 * self.corr_coef_bits, self.dc_bits)

    @property
    def record(self) -> RecordLayout:
        """The record's fields, LSB first (module docstring)."""
        f = [("block", self.block_bits, False), ("u", self.dc_bits, True),
             ("v", self.dc_bits, True), ("ang_a", self.angle_bits, True),
             ("ang_e", self.angle_bits, True), ("shift", self.shift_bits, False)]
        return RecordLayout(tuple(f + [(n, self.acc_width, True) for n in _ACC_FIELDS]))

    @property
    def record_bits(self) -> int:
        return self.record.bits

    @property
    def record_words(self) -> int:
        return self.record.words(self.fifo_width)

    @property
    def fifo(self) -> FifoParams:
        return FifoParams(width=self.fifo_width, depth=self.fifo_depth,
                          count_width=self.fifo_count_bits, record_words=self.record_words)

    # -- latencies -------------------------------------------------------------------------
    @property
    def latency_pre(self) -> int:
        """Cycles from an ADC sample's input cycle to the cycle the snapshot it completes is
        at the correction input (DDC, CIC, FIR)."""
        f = self.fir
        return self.ddc.latency + self.cic.latency + (f.latency if f is not None else 0)

    @property
    def latency_angle(self) -> int:
        """Cycles from the accumulated beams (dump register valid) to the record: OR,
        thermometer, shift count, shift, products, sums, CORDIC load, iterations, angle
        rounding, ``a k`` product, ``u0 + du``."""
        return 10 + self.cordic_iterations

    @property
    def latency(self) -> int:
        """Cycles from the input cycle of the ADC sample completing a block's last snapshot
        to its record at the FIFO input: :attr:`latency_pre`, correction, beams, accumulator
        (dump register), :attr:`latency_angle`."""
        return self.latency_pre + self.corr.latency + 2 + self.latency_angle

    # -- registers -------------------------------------------------------------------------
    def check_write(self, reg: int, value: int) -> int:
        """A register write's value, refused if it does not fit (``ValueError`` naming it)."""
        v = int(value)
        if REG_COEF <= reg < REG_COEF + 4:
            if not 0 <= v < 1 << (2 * self.corr_coef_bits):
                raise ValueError(f"monopulse coefficient register {reg} takes "
                                 f"{2 * self.corr_coef_bits}-bit words (re | im << "
                                 f"{self.corr_coef_bits}), not {value!r}")
            b, m = self.corr_coef_bits, self.coef_max
            for part, name in ((v & ((1 << b) - 1), "re"), (v >> b, "im")):
                s = part - (1 << b) if part >> (b - 1) else part
                if s < -m:
                    raise ValueError(f"monopulse coefficient {name} part must be in "
                                     f"[-{m}, {m}] (symmetric), not {s}")
            return v
        if reg in (REG_U0, REG_V0):
            if not 0 <= v < 1 << self.dc_bits:
                raise ValueError(f"monopulse steering register {reg} takes {self.dc_bits}-bit "
                                 f"two's complement words, not {value!r}")
            s = v - (1 << self.dc_bits) if v >> (self.dc_bits - 1) else v
            if abs(s) > 1 << self.dc_frac_bits:
                raise ValueError(f"monopulse steering direction cosine must be in [-1, 1], "
                                 f"not {s / 2 ** self.dc_frac_bits!r}")
            return v
        raise ValueError(f"monopulse register must be one of {REG_COEF}..{REG_COEF + 3}, "
                         f"{REG_U0}, {REG_V0}, not {reg!r}")


# -- words ---------------------------------------------------------------------------------

def coef_word(k: complex, params: MonopulseFrontendParams) -> int:
    """Register word of the complex coefficient ``k`` (``|Re|, |Im| <= 1``): each part
    ``round(part * (2**(b-1) - 1))``, i.e. ``k (1 - 2**-(b-1))`` (a gain common to the four
    channels, which the ratios do not see)."""
    m = params.coef_max
    k = complex(k)
    re, im = (int(round(float(v) * m)) for v in (k.real, k.imag))
    if abs(re) > m or abs(im) > m:
        raise ValueError(f"monopulse coefficient parts must lie in [-{m}, {m}] / 2**"
                         f"{params.corr_coef_bits - 1}, not {k!r}")
    b = params.corr_coef_bits
    return (re & ((1 << b) - 1)) | ((im & ((1 << b) - 1)) << b)


def dc_word(u: float, params: MonopulseFrontendParams) -> int:
    """Register word of a steering direction cosine ``u`` in [-1, 1] (rounded)."""
    q = int(round(float(u) * (1 << params.dc_frac_bits)))
    if abs(q) > 1 << params.dc_frac_bits:
        raise ValueError(f"monopulse steering direction cosine must be in [-1, 1], not {u!r}")
    return q & ((1 << params.dc_bits) - 1)


def pack_input(x, chips, params: MonopulseFrontendParams) -> np.ndarray:
    """ADC codes (n, 4) and replica bits (n,) (0 = +1, 1 = -1) -> input payload words
    (``x0 | x1 << b | x2 << 2b | x3 << 3b | chip << 4b``)."""
    x = np.asarray(x)
    b = params.adc_bits
    if x.ndim != 2 or x.shape[1] != 4:
        raise ValueError(f"monopulse ADC samples must have shape (n, 4), not {x.shape}")
    c = np.asarray(chips).astype(np.int64).ravel()
    if c.size != x.shape[0] or (c.size and (c.min() < 0 or c.max() > 1)):
        raise ValueError("monopulse replica bits must be 0/1, one per sample")
    w = c << np.int64(4 * b)
    m = np.int64((1 << b) - 1)
    for i in range(4):
        w = w | ((x[:, i].astype(np.int64) & m) << np.int64(i * b))
    return w


def unpack_input(words, params: MonopulseFrontendParams) -> tuple[np.ndarray, np.ndarray]:
    w = np.asarray(words, np.int64)
    b = params.adc_bits
    x = np.stack([(w >> np.int64(i * b)) & np.int64((1 << b) - 1) for i in range(4)], axis=1)
    x = np.where(x >= 1 << (b - 1), x - (1 << b), x)
    return x, (w >> np.int64(4 * b)) & 1


def hadamard_channels(rec: dict) -> np.ndarray:
    """The four channels' accumulated (corrected) outputs from a record's beams:
    ``S_1 = (S + dA + dE + dd) / 4``, ``S_2 = (S + dA - dE - dd) / 4``,
    ``S_3 = (S - dA + dE - dd) / 4``, ``S_4 = (S - dA - dE + dd) / 4`` (complex, LSBs)."""
    b = {n: rec[f"{n}_re"] + 1j * rec[f"{n}_im"] for n in BEAMS}
    s, a, e, d = b["s"], b["da"], b["de"], b["dd"]
    return np.array([s + a + e + d, s + a - e - d, s - a + e - d, s - a - e + d]) / 4


# -- the angle unit ------------------------------------------------------------------------

def angle_unit(acc: np.ndarray, u0: np.ndarray, v0: np.ndarray,
               params: MonopulseFrontendParams) -> dict:
    """Bit-exact angle unit on accumulated beams ``acc`` (m, 8) int64 (the order of
    :data:`BEAMS`, re/im) with the blocks' steering words ``u0``, ``v0`` (signed ints).
    Returns the record fields ``u, v, ang_a, ang_e, shift`` as int64 arrays."""
    p = params
    acc = np.asarray(acc, np.int64).reshape(-1, 8)
    six = acc[:, :6]
    mag = np.bitwise_or.reduce(six ^ (six >> np.int64(63)), axis=1) if len(acc) else \
        np.zeros(0, np.int64)
    length = np.array([int(m).bit_length() + 1 for m in mag], np.int64)
    r = np.maximum(length - p.cordic_in_bits, 0)
    t = six >> r[:, None]
    sr, si, ar, ai, er, ei = (t[:, j] for j in range(6))
    x = sr * sr + si * si
    ya = ai * sr - ar * si
    ye = ei * sr - er * si
    cfg = p.cordic
    ang_a = cfg(ya, x).angle
    ang_e = cfg(ye, x).angle
    out = {"shift": r, "ang_a": ang_a, "ang_e": ang_e}
    for name, ang, base, (k, s) in (("u", ang_a, u0, p.dc_coefs[0]),
                                    ("v", ang_e, v0, p.dc_coefs[1])):
        out[name] = np.asarray(base, np.int64) + shift_right(ang * np.int64(k), s, "half_up")
    return out


def angle_error_bound(params: MonopulseFrontendParams, x_lsb) -> tuple[float, float]:
    """Bound on ``|u - u_exact|`` (and ``v``) from the angle unit alone, given the
    magnitude ``x_lsb`` of the CORDIC input vector (normalised LSBs squared): the CORDIC's
    angle bound (:meth:`dsp.cordic.CordicConfig.angle_error_bound`, in turns times
    ``2 / D``), the ``2 / D`` constant's quantisation, the half-up rounding of ``du``; the
    normalisation's floor (each of S, d within 1 LSB, at least ``2**(cordic_in_bits - 2)``
    for the largest) is the caller's term (:meth:`MonopulseFrontendModel` tests add it)."""
    p = params
    out = []
    for d, (k, s) in zip((p.spacing_x_wl, p.spacing_y_wl), p.dc_coefs):
        turns = float(p.cordic.angle_error_bound(x_lsb)) / (2 * math.pi)
        kf = s + p.dc_frac_bits - p.angle_bits
        coef = abs(k / 2.0 ** kf - 2 / d) * 0.25
        out.append(2 / d * turns + coef + 0.5 * 2.0 ** -p.dc_frac_bits)
    return out[0], out[1]


# -- the model ---------------------------------------------------------------------------

@dataclass
class MonopulseRecords:
    """Records a model step produced (before the FIFO)."""

    cycles: np.ndarray     #: FIFO input cycle of each record
    values: list           #: record values (Python ints)
    fields: dict           #: field name -> int64 array (one entry per record)
    overflows: int = 0     #: saturated correction outputs in this step


class MonopulseFrontendModel:
    """Bit-exact model of :class:`hdl.monopulse.frontend.MonopulseFrontEnd` before its FIFO,
    chunk by chunk.

    ``step(x, chips, writes, cycles=...)`` advances over consecutive ADC samples; the state
    (NCO, CIC/FIR registers, partial block, shadow/active registers, writes not yet applied)
    is carried, so a run split anywhere gives the same records. :meth:`run` adds the FIFO.
    """

    def __init__(self, params: MonopulseFrontendParams):
        if not isinstance(params, MonopulseFrontendParams):
            raise ValueError(f"MonopulseFrontendModel needs a MonopulseFrontendParams, not "
                             f"{params!r}")
        self.params = p = params
        self.nco = NcoModel(p.nco)
        self.ddc = DdcModel(p.ddc)
        self.corr = MixerModel(p.corr)
        self._nco_state = None
        self._cic_state = [None] * 4
        self._fir_state = [None] * 4
        unit = p.unit_coef
        self.shadow = {REG_COEF + i: unit for i in range(4)}
        self.shadow.update({REG_U0: 0, REG_V0: 0})
        self.active = dict(self.shadow)
        self._writes: list[tuple[int, int, int]] = []   # (cycle, reg, value), sorted
        self.n_samples = 0
        self.n_snapshots = 0
        self.next_cycle = 0
        self._acc = np.zeros(8, np.int64)
        self.fifo_state = FifoState()
        # Snapshots decimated but not yet at the correction input before the horizon (their
        # block boundary may still see a register write): (z, t_corr, k).
        self._pend = (np.zeros((0, 4, 2), np.int64), np.zeros(0, np.int64),
                      np.zeros(0, np.int64))

    # -- registers -------------------------------------------------------------------------
    def _latch(self, t_boundary: int) -> tuple[int, int]:
        """Apply the writes before ``t_boundary`` to the shadows, make them active; return
        the (u0, v0) words of the block that ends here."""
        while self._writes and self._writes[0][0] < t_boundary:
            _, reg, v = self._writes.pop(0)
            self.shadow[reg] = v
        u0v0 = (self.active[REG_U0], self.active[REG_V0])
        self.active = dict(self.shadow)
        return u0v0

    def _coefs(self) -> list[tuple[int, int]]:
        b = self.params.corr_coef_bits
        out = []
        for i in range(4):
            v = self.active[REG_COEF + i]
            re, im = v & ((1 << b) - 1), v >> b
            re = re - (1 << b) if re >> (b - 1) else re
            im = im - (1 << b) if im >> (b - 1) else im
            out.append((re, im))
        return out

    def _signed_dc(self, w: int) -> int:
        b = self.params.dc_bits
        return w - (1 << b) if w >> (b - 1) else w

    # -- stepping --------------------------------------------------------------------------
    def step(self, x, chips, writes=(), *, cycles=None, horizon=None) -> MonopulseRecords:
        """Advance over ADC samples ``x`` (n, 4) with replica bits ``chips`` (n,).

        ``writes``: register writes ``(cycle, reg, value)``; a write takes effect at the
        first block boundary in a later cycle (this or a later step). ``cycles``: input
        cycle of each sample (default one per cycle, continuing). ``horizon``: the snapshots
        reaching the correction stage before this cycle are processed (default: the cycle
        after the last sample); the others wait, since a write made later may still land
        before their block boundary (:meth:`advance` processes them).
        """
        p = self.params
        x = np.asarray(x)
        if x.ndim != 2 or x.shape[1] != 4:
            raise ValueError(f"monopulse ADC samples must have shape (n, 4), not {x.shape}")
        if x.size and x.dtype.kind not in "iu":
            raise ValueError(f"monopulse ADC samples must be integers, not dtype {x.dtype}")
        x = x.astype(np.int64)
        c = np.asarray(chips).astype(np.int64).ravel()
        if c.size != x.shape[0]:
            raise ValueError(f"monopulse replica needs one bit per sample ({x.shape[0]}), "
                             f"not {c.size}")
        if c.size and (c.min() < 0 or c.max() > 1):
            raise ValueError("monopulse replica bits must be 0 (+1) or 1 (-1)")
        n = x.shape[0]
        if cycles is None:
            scyc = np.arange(self.next_cycle, self.next_cycle + n, dtype=np.int64)
        else:
            scyc = np.asarray(cycles, np.int64).ravel()
            if scyc.size != n:
                raise ValueError(f"monopulse cycles must give one cycle per sample ({n})")
        new = [(int(cy), int(a), p.check_write(int(a), v)) for cy, a, v in writes]
        if new:
            self._writes = sorted(self._writes + new, key=lambda w: w[0])
        cos, sin, self._nco_state = self.nco.run(n, p.nco_freq_word, self._nco_state)
        sgn = 1 - 2 * c
        cos, sin = cos * sgn, sin * sgn
        snaps = []
        for ch in range(4):
            i, q = self.ddc.mix(x[:, ch], cos, sin)
            y, self._cic_state[ch] = cic_model(p.cic, np.stack([i, q], axis=1),
                                               self._cic_state[ch])
            if p.fir is not None:
                y, self._fir_state[ch] = fir_model(p.fir, y, self._fir_state[ch])
            snaps.append(y)
        z = np.stack(snaps, axis=1)                       # (m, 4, 2)
        m = z.shape[0]
        k = self.n_snapshots + np.arange(m, dtype=np.int64)
        # ADC sample (chunk index) completing each snapshot, and the cycles that follow.
        last = (k + 1) * p.snapshot_decimation - 1 - self.n_samples
        t_corr = scyc[last] + p.latency_pre if m else np.zeros(0, np.int64)
        self.n_samples += n
        self.n_snapshots += m
        if n:
            self.next_cycle = int(scyc[-1]) + 1
        pz, pt, pk = self._pend
        self._pend = (np.concatenate([pz, z]), np.concatenate([pt, t_corr]),
                      np.concatenate([pk, k]))
        return self.advance(self.next_cycle if horizon is None else horizon)

    def advance(self, horizon: int) -> MonopulseRecords:
        """Process the snapshots waiting for the correction stage with ``t_corr < horizon``
        (every register write before ``horizon`` must have been given)."""
        p = self.params
        pz, pt, pk = self._pend
        j = int(np.searchsorted(pt, horizon))
        z, t_corr, k = pz[:j], pt[:j], pk[:j]
        self._pend = (pz[j:], pt[j:], pk[j:])
        m = z.shape[0]
        k0 = int(k[0]) if m else 0
        N = p.snapshots
        blk = k // N
        w = np.empty((m, 4, 2), np.int64)
        out_cyc, u0s, v0s, accs, blocks = [], [], [], [], []
        over = 0
        # One coefficient set per block: loop over the blocks this chunk touches.
        start = 0
        while start < m:
            b = int(blk[start])
            stop = min(m, (b + 1) * N - k0)
            coefs = self._coefs()
            for ch, (re, im) in enumerate(coefs):
                zi, zq = z[start:stop, ch, 0], z[start:stop, ch, 1]
                pi, pq = self.corr.products((zi, zq), np.full(zi.shape, re), np.full(zi.shape, -im))
                fi, ni = p.corr.out_format.fit(shift_right(pi, p.corr.drop_bits, p.corr_rounding))
                fq, nq = p.corr.out_format.fit(shift_right(pq, p.corr.drop_bits, p.corr_rounding))
                w[start:stop, ch, 0], w[start:stop, ch, 1] = fi, fq
                over += int(ni) + int(nq)
            w1, w2, w3, w4 = (w[start:stop, j] for j in range(4))
            beams = np.concatenate([w1 + w2 + w3 + w4, (w1 + w2) - (w3 + w4),
                                    (w1 + w3) - (w2 + w4), (w1 + w4) - (w2 + w3)], axis=1)
            self._acc = self._acc + beams.sum(axis=0)
            if (b + 1) * N - k0 <= m:                    # the block ends in this chunk
                j = stop - 1
                u0, v0 = self._latch(int(t_corr[j]))
                u0s.append(self._signed_dc(u0))
                v0s.append(self._signed_dc(v0))
                accs.append(self._acc.copy())
                blocks.append(b)
                out_cyc.append(int(t_corr[j]) + p.corr.latency + 2 + p.latency_angle)
                self._acc = np.zeros(8, np.int64)
            start = stop
        acc = np.array(accs, np.int64).reshape(-1, 8)
        f = angle_unit(acc, np.array(u0s, np.int64), np.array(v0s, np.int64), p)
        f["block"] = np.array(blocks, np.int64) & ((1 << p.block_bits) - 1)
        for j, name in enumerate(_ACC_FIELDS):
            f[name] = acc[:, j]
        vals = [p.record.pack({k_: f[k_][r] for k_ in f}) for r in range(len(blocks))]
        return MonopulseRecords(np.array(out_cyc, np.int64), vals, f, over)

    def run(self, x, chips, writes=(), *, n_cycles: int, out_ready=None, cycles=None):
        """One step then the FIFO over ``n_cycles`` cycles from the model's FIFO state:
        returns ``(records, fifo_result)`` (records written at or after ``n_cycles`` are
        not offered)."""
        r = self.step(x, chips, writes, cycles=cycles, horizon=n_cycles)
        keep = r.cycles < n_cycles
        p = self.params
        words = np.array([p.record.to_words(v, p.fifo_width) for v, k in zip(r.values, keep) if k],
                         np.int64).reshape(-1, p.record_words)
        ready = np.ones(n_cycles, bool) if out_ready is None else np.asarray(out_ready, bool)
        if ready.size < n_cycles:
            ready = np.r_[ready[:n_cycles], np.ones(n_cycles - ready.size, bool)]
        res = fifo_model_events(r.cycles[keep], words, n_cycles - self.fifo_state.cycle,
                                ready[self.fifo_state.cycle:n_cycles], self.params.fifo,
                                state=self.fifo_state)
        self.fifo_state = res.state
        return r, res
