"""Monopulse FPGA front end: its parameters and word lengths
(:class:`MonopulseFrontendParams`, every block's parameters built in one place), register
map (:attr:`MonopulseFrontendParams.registers`), record layout (:attr:`MonopulseFrontendParams.record`) and the
register and input word codecs (:func:`coef_word`, :func:`dc_word`, :func:`pack_input`,
:func:`unpack_input`). What each register, field and word means is specified with the
model, :mod:`hdl.monopulse.model`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dsp.cordic import CordicConfig
from dsp.fixed import ROUNDINGS, check_width
from dsp.record_layout import RecordLayout
from dsp.register_map import Register, RegisterMap
from hdl.model.cic import CicParams
from hdl.model.ddc import DdcParams
from hdl.model.fifo import FifoParams
from hdl.model.fir import FirParams
from hdl.model.mixer import MixerParams
from hdl.model.nco import NcoParams, nco_freq_word

__all__ = ["MonopulseFrontendParams", "REG_COEF", "REG_U0", "REG_V0", "BEAMS",
           "ACC_FIELDS", "coef_word", "dc_word", "pack_input", "unpack_input"]

#: Register addresses.
REG_COEF, REG_U0, REG_V0 = 0, 4, 5
#: Accumulated beams of the record, in order, and their fields (re, im).
BEAMS = ("s", "da", "de", "dd")
ACC_FIELDS = tuple(f"{b}_{c}" for b in BEAMS for c in ("re", "im"))


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
        """Bus data width: the widest register."""
        return max(r.width for r in self.registers.registers)

    @property
    def record(self) -> RecordLayout:
        """The record's fields, LSB first (module docstring)."""
        f = [("block", self.block_bits, False), ("u", self.dc_bits, True),
             ("v", self.dc_bits, True), ("ang_a", self.angle_bits, True),
             ("ang_e", self.angle_bits, True), ("shift", self.shift_bits, False)]
        return RecordLayout(tuple(f + [(n, self.acc_width, True) for n in ACC_FIELDS]))

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
    @property
    def registers(self) -> RegisterMap:
        """The register map: ``coef1``..``coef4`` at ``REG_COEF + i`` (``re | im <<
        corr_coef_bits``, each part symmetric, ``|part| <= coef_max``), ``u0`` and ``v0``
        (``dc_bits`` two's complement, ``|u| <= 1``, i.e. ``2**dc_frac_bits``)."""
        b, m, d = self.corr_coef_bits, self.coef_max, 1 << self.dc_frac_bits
        coefs = tuple(Register(f"coef{i + 1}", REG_COEF + i, 2 * b, True, -m, m, 2)
                      for i in range(4))
        return RegisterMap("monopulse", coefs + (
            Register("u0", REG_U0, self.dc_bits, True, -d, d),
            Register("v0", REG_V0, self.dc_bits, True, -d, d)))


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
