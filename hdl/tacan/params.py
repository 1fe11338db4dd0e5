"""TACAN FPGA front end: its parameters and word lengths (:class:`TacanFrontendParams`),
from which every block's parameters are built in one place so that each block's output
width is the next one's input width, and the amplitude error budget of the chain
(:func:`amp_error_terms`). The rates and structure are a
:class:`dsp.tacan.frontend.FrontendConfig`, shared with the golden float model. Why each
default word length is what it is: ``docs/explanation/tacan_frontend_design.md``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from dsp.fixed import ROUNDINGS, check_width
from dsp.record_layout import RecordLayout
from dsp.tacan.fifo_rx import peak_record
from dsp.tacan.frontend import FrontendConfig
from dsp.tacan.peak_params import PeakParams

from ..model.cic import CicParams
from ..model.ddc import DdcParams
from ..model.envelope import EnvelopeParams
from ..model.fifo import FifoParams
from ..model.fir import FirParams
from ..model.mixer import MixerParams
from ..model.nco import NcoParams, nco_freq_word

__all__ = ["TacanFrontendParams", "amp_error_terms"]


@dataclass(frozen=True)
class TacanFrontendParams:
    """Rates, structure and word lengths of the TACAN front end.

    Parameters
    ----------
    config : FrontendConfig
        Rates and structure shared with the golden model (fs, digital IF, CIC N/R/M, FIR
        length/decimation, pulse width, peak-search parameters, ``thr_min_fs``).
        ``config.peak`` gives the noise-floor/threshold/hold settings; its ``amp_width`` and
        ``thr_min`` are replaced by the envelope width and ``thr_min_fs`` in LSBs.
        ``config.pair_peak`` (optional) adds the pair search, built the same way
        (:attr:`pair_peak`), and the source bit of the FIFO payload.
    adc_bits : int
        ADC word (signed, 2..18).
    nco_phase_bits, nco_table_bits, nco_amp_bits, nco_dither_bits : int
        NCO accumulator, full-circle table address, signed amplitude, phase dither widths.
    mixer_out_bits, mixer_headroom_bits : int
        Mixer output width and extra right shift (output LSB ``2**-(out - 1 - headroom)`` FS).
    mixer_rounding : str
        Rounding of the mixer products (see :mod:`dsp.fixed`).
    cic_out_bits : int
        CIC output width (LSBs dropped from the full Hogenauer width).
    cic_rounding : str
    cic_prune : bool
        Hogenauer register pruning.
    fir_coef_bits : int
        FIR coefficient width.
    fir_out_shift_rel : int
        FIR output LSB relative to its input LSB, as a power of two: the FIR drops
        ``coef_frac - fir_out_shift_rel`` LSBs (1: one fraction bit more than the input).
    fir_out_bits : int
        FIR output width.
    fir_rounding : str
    fir_input_spacing : int, optional
        Multiplier sharing of the FIR (default ``config.cic_rate``: the CIC's guaranteed
        minimum spacing between its outputs; 1 = fully parallel).
    env_iterations : int
        CORDIC iterations.
    env_out_bits : int, optional
        Envelope output width (default: natural, ``fir_out_bits + 1``).
    env_rounding : str
    ts_bits : int
        Peak timestamp width (wraps).
    fifo_depth, fifo_count_bits : int
        FIFO depth (words) and overflow-counter width.
    fifo_parity : bool
        Even-parity bit on every FIFO word (checked by the DSP's FIFO receiver).
    check_headroom : bool
        Refuse word lengths where a legal input could overflow a stage (default True).
    """

    config: FrontendConfig = field(default_factory=FrontendConfig)
    adc_bits: int = 12
    nco_phase_bits: int = 32
    nco_table_bits: int = 10
    nco_amp_bits: int = 16
    nco_dither_bits: int = 0
    mixer_out_bits: int = 16
    mixer_headroom_bits: int = 0
    mixer_rounding: str = "half_even"
    cic_out_bits: int = 17
    cic_rounding: str = "half_even"
    cic_prune: bool = False
    fir_coef_bits: int = 18
    fir_out_shift_rel: int = 0
    fir_out_bits: int = 18
    fir_rounding: str = "half_up"
    fir_input_spacing: int | None = None
    env_iterations: int = 12
    env_out_bits: int | None = None
    env_rounding: str = "half_up"
    ts_bits: int = 32
    fifo_depth: int = 512
    fifo_count_bits: int = 16
    fifo_parity: bool = False
    check_headroom: bool = True
    _blocks: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        if not isinstance(self.config, FrontendConfig):
            raise ValueError(f"config must be a FrontendConfig, not {self.config!r}")
        check_width("ADC adc_bits", self.adc_bits, minimum=2, maximum=18)
        for name in ("mixer_rounding", "cic_rounding", "fir_rounding"):
            if getattr(self, name) not in ROUNDINGS:
                raise ValueError(f"{name} must be one of {ROUNDINGS}, not {getattr(self, name)!r}")
        if not isinstance(self.cic_prune, bool):
            raise ValueError(f"cic_prune must be a bool, not {self.cic_prune!r}")
        if isinstance(self.fir_out_shift_rel, bool) or not isinstance(self.fir_out_shift_rel, int) \
                or not 0 <= self.fir_out_shift_rel <= 8:
            raise ValueError(f"fir_out_shift_rel must be an integer in [0, 8], not "
                             f"{self.fir_out_shift_rel!r}")
        cfg = self.config
        if cfg.pair_peak is not None and cfg.decimation < 2:   # (FrontendConfig: cic_rate >= 2)
            raise ValueError(f"with pair_peak the total decimation must be >= 2 (the merge of "
                             f"the two searches holds a word for one cycle and needs each "
                             f"search's words 2 cycles apart), not {cfg.decimation}")
        if self.fir_input_spacing is None:
            object.__setattr__(self, "fir_input_spacing", cfg.cic_rate)
        if isinstance(self.fir_input_spacing, bool) or not isinstance(self.fir_input_spacing, int) \
                or not 1 <= self.fir_input_spacing <= cfg.cic_rate:
            raise ValueError(f"fir_input_spacing must be an integer in [1, cic_rate = "
                             f"{cfg.cic_rate}] (the CIC's output spacing), not "
                             f"{self.fir_input_spacing!r}")

        # Build every block once, in chain order; each takes the previous one's out width.
        b = self._blocks
        nco = NcoParams(phase_bits=self.nco_phase_bits, table_bits=self.nco_table_bits,
                        amp_bits=self.nco_amp_bits, dither_bits=self.nco_dither_bits)
        mixer = MixerParams(in_width=self.adc_bits, lo_width=nco.amp_bits,
                            out_width=self.mixer_out_bits, rounding=self.mixer_rounding,
                            overflow="saturate", headroom_bits=self.mixer_headroom_bits)
        b["ddc"] = DdcParams(nco=nco, mixer=mixer)
        b["cic"] = CicParams(stages=cfg.cic_stages, rate=cfg.cic_rate, diff_delay=cfg.cic_delay,
                             in_width=b["ddc"].out_width, channels=2, out_width=self.cic_out_bits,
                             rounding=self.cic_rounding, overflow="saturate", prune=self.cic_prune)
        probe = FirParams(taps=tuple(cfg.fir_taps), coef_bits=self.fir_coef_bits,
                          decimation=cfg.fir_decim, in_width=b["cic"].out_width, channels=2)
        out_shift = probe.coef_frac - self.fir_out_shift_rel
        if out_shift < 0:
            raise ValueError(f"fir_out_shift_rel must be <= the coefficient fraction bits "
                             f"{probe.coef_frac}, not {self.fir_out_shift_rel}")
        b["fir"] = FirParams(taps=probe.taps, coef_bits=self.fir_coef_bits,
                             decimation=cfg.fir_decim, in_width=b["cic"].out_width, channels=2,
                             out_shift=out_shift, out_width=self.fir_out_bits,
                             rounding=self.fir_rounding, overflow="saturate",
                             input_spacing=self.fir_input_spacing)
        b["envelope"] = EnvelopeParams(in_width=b["fir"].out_width, out_width=self.env_out_bits,
                                       iterations=self.env_iterations,
                                       rounding=self.env_rounding)
        env = b["envelope"]
        object.__setattr__(self, "env_out_bits", env.out_width)
        # thr_min_fs in envelope LSBs (scale of the chain up to the envelope).
        thr_min = int(round(cfg.thr_min_fs / self._scale_from(b)))
        # the algorithm's fields as configured; the widths, the timestamp step and the
        # floor of the threshold are the chain's
        searches = {"peak": cfg.peak}
        if cfg.pair_peak is not None:
            searches["pair_peak"] = cfg.pair_peak
        for name, search in searches.items():
            b[name] = replace(search, amp_width=env.out_width, ts_bits=self.ts_bits,
                              ts_step=cfg.decimation,
                              thr_min=min(thr_min, (1 << env.out_width) - 1))
        b["fifo"] = FifoParams(width=peak_record(env.out_width, self.ts_bits,
                                                 self.source_bits).bits,
                               depth=self.fifo_depth, count_width=self.fifo_count_bits,
                               parity=self.fifo_parity)
        if self.check_headroom:
            self._check_headroom()

    # -- headroom ----------------------------------------------------------------------------
    def headroom(self) -> dict[str, tuple[int, int]]:
        """Per stage: (largest magnitude any legal ADC input can produce, largest the output
        word holds), both in that stage's output LSBs (exact integers; the envelope's from
        its CORDIC bound)."""
        d, c, f, e = self.ddc, self.cic, self.fir, self.envelope
        mx = d.mixer
        full = 1 << (self.adc_bits - 1)
        prod = full * d.nco.peak
        drop = mx.drop_bits
        mix_max = (prod + (1 << (drop - 1))) >> drop if drop > 0 else prod << -drop
        # CIC: positive impulse response, gain/2**out_shift, plus a rounding carry.
        cic_max = -(-mix_max * c.gain // (1 << c.out_shift))
        taps = np.array(f.taps_int, dtype=object)
        fir_max = -(-cic_max * int(np.abs(taps).sum()) // (1 << f.out_shift))
        env_max = int(math.ceil(e.eff_gain * math.sqrt(2) * fir_max / 2.0 ** e.shift
                                + e.error_bound_lsb))
        return {
            "mixer": (mix_max, (1 << (mx.out_width - 1)) - 1),
            "cic": (cic_max, (1 << (c.out_width - 1)) - 1),
            "fir": (fir_max, (1 << (f.out_width - 1)) - 1),
            "envelope": (env_max, (1 << e.out_width) - 1),
        }

    def _check_headroom(self):
        for stage, (need, have) in self.headroom().items():
            if need > have:
                raise ValueError(
                    f"{stage} output can overflow: a full-scale ADC input reaches {need} LSB "
                    f"but {stage} words hold {have}; widen it, or pass check_headroom=False "
                    f"to study saturation")

    # -- blocks --------------------------------------------------------------------------------
    @property
    def ddc(self) -> DdcParams:
        return self._blocks["ddc"]

    @property
    def cic(self) -> CicParams:
        return self._blocks["cic"]

    @property
    def fir(self) -> FirParams:
        return self._blocks["fir"]

    @property
    def envelope(self) -> EnvelopeParams:
        return self._blocks["envelope"]

    @property
    def peak(self) -> PeakParams:
        return self._blocks["peak"]

    @property
    def pair_peak(self) -> PeakParams | None:
        """The pulse-pair search beside :attr:`peak` (``config.pair_peak``), None without."""
        return self._blocks.get("pair_peak")

    @property
    def source_bits(self) -> int:
        """Bits of the source field at the top of the FIFO payload: 1 with
        :attr:`pair_peak` (0 = :attr:`peak`, 1 = :attr:`pair_peak`), else 0."""
        return 0 if self.config.pair_peak is None else 1

    @property
    def record(self) -> RecordLayout:
        """The FIFO record (:func:`dsp.tacan.fifo_rx.peak_record`): ``amplitude``
        (envelope width), ``timestamp`` (``ts_bits``) and, with :attr:`pair_peak`,
        ``source``; one FIFO word (:attr:`fifo` is as wide)."""
        return peak_record(self.peak.amp_width, self.ts_bits, self.source_bits)

    @property
    def fifo(self) -> FifoParams:
        return self._blocks["fifo"]

    # -- derived ---------------------------------------------------------------------------------
    @property
    def nco_freq_word(self) -> int:
        """NCO word of the digital IF (rounded to nearest; the error is ``nco_freq_error_hz``)."""
        return nco_freq_word(self.config.if_hz, f_clk_hz=self.config.fs_hz,
                             phase_bits=self.nco_phase_bits).word

    @property
    def nco_freq_error_hz(self) -> float:
        return nco_freq_word(self.config.if_hz, f_clk_hz=self.config.fs_hz,
                             phase_bits=self.nco_phase_bits).error_hz

    @property
    def decimation(self) -> int:
        return self.config.decimation

    @property
    def chain_latency(self) -> int:
        """Cycles from the ADC transfer that completes an envelope sample to the envelope's
        output transfer of that sample (DDC, CIC, FIR, CORDIC)."""
        return self.ddc.latency + self.cic.latency + self.fir.latency + self.envelope.latency

    @property
    def peak_latency(self) -> int:
        """Cycles from the ADC transfer that completes a pulse's closing envelope sample
        (``peak.emit_delay`` samples later with the readout or the pair detection) to the
        peak search's output transfer (= the FIFO write)."""
        return self.chain_latency + self.peak.latency

    @property
    def pair_peak_latency(self) -> int | None:
        """:attr:`peak_latency` of the pair search (``pair_peak.emit_delay`` envelope samples
        after the pair's closing sample), None without it. Its FIFO write comes one cycle
        later when the pulse search writes in the same cycle (:func:`fifo_write_cycles`)."""
        return None if self.pair_peak is None else self.chain_latency + self.pair_peak.latency

    #: SyncFIFOBuffered: a word written into an empty queue is offered 2 cycles later.
    FIFO_LATENCY = 2

    @property
    def latency(self) -> int:
        """Cycles from the ADC transfer that completes a pulse's closing envelope sample to
        ``o.valid`` of its FIFO word (empty FIFO, DSP ready)."""
        return self.peak_latency + self.FIFO_LATENCY

    @staticmethod
    def _scale_from(b) -> float:
        d, c, f, e = b["ddc"], b["cic"], b["fir"], b["envelope"]
        mx = d.mixer
        lo_rel = d.nco.peak / 2.0 ** (d.nco.amp_bits - 1)
        # mixer integer per golden baseband unit: golden z = 2 x exp(-jwn) (x in FS).
        mix = lo_rel * 2.0 ** (mx.out_width - 1 - mx.headroom_bits) / 2.0
        return 1.0 / (mix * c.float_gain * f.float_gain * e.eff_gain / 2.0 ** e.shift)

    @property
    def scale_to_fs(self) -> float:
        """ADC full-scale units per envelope (amplitude) LSB: golden amplitude ~=
        ``scale_to_fs * amplitude`` (mixer scaling and NCO peak, CIC and FIR gains, CORDIC
        gain; the FIR's quantised taps stand for the golden float taps)."""
        return self._scale_from(self._blocks)

    @property
    def group_delay_samples(self) -> float:
        """Delay (ADC ticks) of a pulse peak to its hardware timestamp: subtract it from a
        timestamp to get the pulse time. The golden's delay less ``decimation - 1``: a
        hardware envelope sample ``n`` has timestamp ``n D`` but completes on ADC tick
        ``n D + D - 1`` (the D-th, 2D-th, ... input is kept)."""
        return self.config.group_delay_samples - (self.decimation - 1)

    @property
    def amp_bound_fs(self) -> float:
        """Bound on ``|model amplitude - golden amplitude|`` (FS) for the same envelope
        sampling phase, from the rounding steps of the chain (worst case over inputs) and the
        CORDIC bound; see :func:`amp_error_terms`."""
        return sum(amp_error_terms(self).values())


def amp_error_terms(p: TacanFrontendParams) -> dict[str, float]:
    """Worst-case amplitude error (FS) contributed by each rounding step; the magnitude of a
    complex error ``(ei, eq)`` with ``|ei|, |eq| <= b`` is at most ``sqrt(2) b``.

    * mixer rounding: 1/2 LSB per sample (half_even), through CIC (DC gain 1, positive) and
      FIR (sum|h|);
    * CIC output rounding: 1/2 CIC LSB through the FIR;
    * FIR output rounding (+ coefficient quantisation is not a rounding of the signal: the
      golden comparison uses the design taps, so the difference of the tap sets times the
      largest input is counted too);
    * envelope: :attr:`EnvelopeParams.error_bound_lsb`.

    * NCO: the table rounds the LO amplitude by <= 1/2 LSB of its peak (relative
      ``1/(2 peak)``, first order, times the largest amplitude 1 FS); the table's phase
      error ``|d| <= pi/2**table_bits`` only rotates a narrowband pulse to first order
      (zero-mean pattern, filtered by the positive CIC/FIR), changing its magnitude by
      ``<= d**2/2`` relative.
    """
    fs = p.scale_to_fs   # FS per envelope LSB
    e = p.envelope
    env_per_fir = e.eff_gain / 2.0 ** e.shift    # envelope LSB per FIR LSB
    fir_lsb = fs * env_per_fir                   # FS per FIR LSB
    cic_lsb = fir_lsb * p.fir.float_gain
    mix_lsb = cic_lsb * p.cic.float_gain
    h = np.asarray(p.fir.taps_quantised)
    dh = float(np.abs(h - np.asarray(p.fir.taps)).sum())
    s2 = math.sqrt(2.0)
    half = {"floor": 1.0, "zero": 1.0, "half_up": 0.5, "half_even": 0.5}
    return {
        "mixer": s2 * half[p.ddc.mixer.rounding] * mix_lsb * np.abs(h).sum(),
        "cic": s2 * half[p.cic.rounding] * (cic_lsb if p.cic.out_shift else 0.0) * np.abs(h).sum(),
        "fir_coef": dh * 1.0,   # |x| <= 1 FS (golden units: carrier amplitude <= 1)
        "fir": s2 * half[p.fir.rounding] * fir_lsb,
        "envelope": e.error_bound_lsb * fs,
        "nco": 1.0 / (2 * p.ddc.nco.peak) + (math.pi / 2 ** p.ddc.nco.table_bits) ** 2 / 2,
    }
