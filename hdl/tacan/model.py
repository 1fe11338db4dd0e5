"""TACAN FPGA front end (top level): parameters, word lengths and the bit-exact model.

Chain (one ``sync`` clock, the ADC rate)::

    ADC (12 b) -> DDC (NCO + real mixer) -> CIC (N=3, R=4, M=1) -> FIR (33 taps, matched,
    CIC-compensating) -> envelope (CORDIC |z|) -> pulse-peak search -> FIFO -> DSP

:class:`TacanFrontendParams` holds the rates/structure (a :class:`dsp.tacan.frontend.FrontendConfig`,
shared with the golden float model) plus every word length, and builds each block's
parameters in one place so that each block's output width is the next one's input width.

Word lengths (defaults) and why
-------------------------------
Units: "FS" is ADC full scale (code ``2**(adc_bits-1)``); the golden model's amplitudes are
the carrier amplitude in FS (its mixer multiplies by ``2 exp(-jwn)``).

* **ADC 12 b** (the scenario's converter).
* **NCO**: 32-bit phase (frequency error ~2 mHz at 3 MHz), 10-bit table address (phase error
  <= pi/1024 rad, zero-mean with the bin-centre table), 16-bit amplitude (table rounding
  1.5e-5 relative): the 12 x 16 product fits one 18x18 multiplier. The LO phase error
  changes a narrowband pulse's *magnitude* only to second order (a rotation to first order).
* **Mixer 16 b, headroom 0, half_even**: output LSB ``2**-15`` FS (16x finer than the ADC
  LSB, so its rounding adds < 0.4% to the ADC quantisation noise power). The product is
  shifted by 11 bits and ``|x * lo| <= 2**11 * (2**15 - 1)``, so the output is at most
  ``2**15 - 1`` LSB: it never saturates, not even at (-full scale) x (-peak). Convergent
  rounding has no DC bias (a floor would put a ~1e-5 FS offset on I and Q).
* **CIC 17 b out** (full width 22, 5 LSBs dropped, half_even, no pruning): LSB ``2**-16`` FS;
  the impulse response is positive with gain 64/32, so ``|out| <= 2 * (2**15 - 1) < 2**16``;
  17 bits make the FIR's pre-adder 18 bits, i.e. one 18x18 multiplier per tap.
* **FIR**: 18-bit coefficients (the 18x18 multiplier; quantisation error of the pulse
  response ~1e-5 relative), output LSB = input LSB (``2**-16`` FS), 18 b out: every tap is
  positive with sum 1.212, so ``|out| <= 1.212 * 2**16 < 2**17`` (no overflow for any
  input). The multipliers
  are time-shared over ``input_spacing = cic_rate`` cycles (the CIC cannot deliver faster).
* **Envelope 18 b in, 19 b out** (CORDIC, 12 iterations, half_up, no gain compensation):
  ``1.647 * sqrt(2) * 2**17 < 2**19``; error <= :attr:`~hdl.model.envelope.EnvelopeParams.error_bound_lsb`
  (1.4 LSB = 2.5e-5 FS). 12 iterations leave an angle residual of atan(2**-11), i.e. a
  relative error <= 2**-23 (0.02 LSB at full scale); more iterations would only add
  truncation error (each one < 1 guard LSB) and pipeline stages.
* **Peak search** 19-bit amplitude, 32-bit timestamp (wraps after 214 s at 20 MHz; the model
  also returns it unwrapped), threshold floor ``thr_min`` = the golden's ``thr_min_fs`` in
  envelope LSBs.
* **FIFO** 51-bit payload (amplitude | timestamp << 19; 52 with both searches, the source
  bit on top) + 2-bit tag, 512 deep (one DP16KD block pair), 16-bit overflow counter.

Model
-----
:class:`TacanFrontendModel` chains the block models (vectorised, chunkable with a
:class:`TacanFrontendState`), or composes the blocks' compiled single-threaded kernels
(:class:`hdl.model.ddc.DdcCicKernel`, :class:`hdl.model.fir.FirKernel`,
:func:`hdl.model.envelope.envelope_model`; :meth:`TacanFrontendModel.envelope`, the default
when the word lengths allow);
:meth:`TacanFrontendModel.fifo_output` adds the FIFO cycle model for a given DSP ``ready``
pattern.

Both searches (``config.pair_peak``)
------------------------------------
A second :class:`~hdl.tacan.peak.PeakSearch` (the pulse-pair detection,
:attr:`TacanFrontendParams.pair_peak`, built as :attr:`~TacanFrontendParams.peak` is: envelope
width, ``ts_bits``, the decimation as timestamp step, the same threshold floor) runs on the
same envelope stream. Both write into the one FIFO, whose payload grows by a **source bit**
at the top::

    payload = amplitude | timestamp << amp_width | source << (amp_width + ts_bits)

(source 0 = the single-pulse search, 1 = the pair search; a 52-bit payload by default).
Merge rule (:func:`fifo_write_cycles`, the HDL's ``TacanFrontEnd._merge``): the pulse search
has priority; a pair word emitted in the same cycle as a pulse word waits in a one-word hold
register and is written the next cycle. Each search emits at most one word per envelope
sample, i.e. at least ``decimation`` cycles apart, and ``decimation >= 2`` (checked), so that
next cycle has no pulse word and no new pair word: one register suffices, nothing is lost.
The pair search's latency is 8 (9 with the pair checks) against the pulse search's 6, and
envelope samples are at least ``decimation`` cycles apart, so the two can only meet when the
decimation is at most that difference: never with the default decimation 4, at decimation 2
they do. Resources: a second search (its pair-sum memory of ``pair_offset`` words, the inner
search's ``2 pair_offset``-word partner line, with the pair checks an envelope history of
``pair_check_depth`` (512) words), the hold register and one FIFO bit more;
``results/synth_tacan.json`` is the single search's (not re-synthesised).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from dsp.fixed import OVERFLOWS, ROUNDINGS, check_width
from dsp.jit import njit_cached
from dsp.tacan.frontend import FrontendConfig, Peaks
from dsp.tacan.standard import SOURCE_PAIR

from ..model.cic import CicParams, CicState, cic_model
from ..model.ddc import DdcCicKernel, DdcModel, DdcParams
from ..model.envelope import EnvelopeParams, envelope_model
from ..model.fifo import FifoParams, fifo_model
from ..model.fir import FirKernel, FirParams, FirState, fir_model
from ..model.mixer import MixerParams
from ..model.nco import NcoParams, NcoState, nco_freq_word
from dsp.tacan.peak_params import PeakParams, PeakState
from .peak_model import peak_search

__all__ = ["TacanFrontendParams", "TacanFrontendState", "TacanFrontendModel", "FrontendPeaks", "amp_error_terms",
           "FifoRun", "fifo_write_cycles"]


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
        b["fifo"] = FifoParams(width=env.out_width + self.ts_bits + self.source_bits,
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


# -- model ------------------------------------------------------------------------------------

def _check_changes(freq_changes, phase_bits: int):
    """Validated ``freq`` writes as (index, word) int64 arrays (None: no writes)."""
    if freq_changes is None or isinstance(freq_changes, tuple) and len(freq_changes) == 2 \
            and isinstance(freq_changes[0], np.ndarray):
        return freq_changes
    pairs = list(freq_changes)
    if any(len(c) != 2 for c in pairs):
        raise ValueError("freq_changes must be (index, word) pairs")
    idx = np.array([int(c[0]) for c in pairs], dtype=np.int64)
    val = np.array([int(c[1]) for c in pairs], dtype=np.int64)
    if idx.size and (np.any(np.diff(idx) <= 0) or idx[0] < 0):
        raise ValueError(f"freq_changes indices must be >= 0 and strictly increasing, not "
                         f"{idx.tolist()[:8]}")
    if val.size and (val.min() < 0 or val.max() >= 1 << phase_bits):
        raise ValueError(f"freq words must lie in [0, 2**{phase_bits})")
    return idx, val


def _changes_in(changes, start: int, stop: int):
    """The changes with ``start <= index < stop``, indices made relative to ``start``."""
    if changes is None:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    idx, val = changes
    a, b = np.searchsorted(idx, [start, stop])
    return np.ascontiguousarray(idx[a:b] - start), np.ascontiguousarray(val[a:b])


@dataclass
class TacanFrontendState:
    """Model state between chunks (``None`` = just after reset)."""

    nco: NcoState | None = None
    cic: object = None         #: CicState (block path) or (integrators, combs) arrays (fast)
    fir: object = None         #: FirState (block path) or (2, taps-1) history array (fast)
    peak: PeakState | None = None
    pair_peak: PeakState | None = None   #: the pair search's (``config.pair_peak``)
    n_adc: int = 0            #: ADC samples consumed
    pending: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    #: ADC samples left over (fewer than one decimation group: the CIC/FIR consume whole
    #: groups per chunk so that the integer models' chunks line up).
    freq: int | None = None   #: NCO word in force at the next sample (None: the model's)
    #: Pair-search peaks held back by ``run(..., final=False)`` (a pulse of the next call may
    #: be written before them; see :meth:`TacanFrontendModel.run`).
    held: "FrontendPeaks | None" = None


@dataclass
class FrontendPeaks:
    """Peaks as the hardware reports them (before the FIFO).

    amplitudes : int64 envelope LSBs (the peak's, with the pair-partner readout the
    partner's envelope, with the pair detection the pair's mean, as the FIFO word carries
    it); timestamps : int64 ADC ticks, unwrapped (``timestamps mod 2**ts_bits`` is the
    hardware field); index / end_index : envelope sample of the peak / whose arrival emits
    the pulse (the closing sample, ``PeakParams.emit_delay`` later with the readout or the
    pair detection); source : with two searches (``config.pair_peak``) the search of each
    peak, int8 :data:`~dsp.tacan.standard.SOURCE_PULSE` / ``SOURCE_PAIR`` (None: one search).
    """

    amplitudes: np.ndarray
    timestamps: np.ndarray
    index: np.ndarray
    end_index: np.ndarray
    source: np.ndarray | None = None

    def __len__(self):
        return len(self.amplitudes)

    def take(self, idx) -> "FrontendPeaks":
        """The peaks at ``idx`` (indices or a mask), in that order."""
        return FrontendPeaks(self.amplitudes[idx], self.timestamps[idx], self.index[idx],
                             self.end_index[idx], None if self.source is None else self.source[idx])

    @staticmethod
    def concat(parts) -> "FrontendPeaks":
        """The peaks of ``parts`` one after the other (all with a source, or none)."""
        parts = list(parts)
        cat = [np.concatenate([getattr(q, f) for q in parts])
               for f in ("amplitudes", "timestamps", "index", "end_index")]
        src = None if parts[0].source is None else np.concatenate([q.source for q in parts])
        return FrontendPeaks(*cat, source=src)


def fifo_write_cycles(emit_cycles, source=None, *, last_pulse: int = -1) -> np.ndarray:
    """The merge of the two searches into the one FIFO input
    (:class:`~hdl.tacan.frontend.TacanFrontEnd` with ``config.pair_peak``): the cycle each
    peak is written to the FIFO, from the cycle it leaves its search (``emit_cycles``) and
    its ``source``.

    The pulse search has priority: a pulse word is written in the cycle it is emitted; a pair
    word too, unless a pulse word is emitted in the same cycle, then it waits in a one-word
    hold register and is written the next cycle. Each search emits at most one word per
    envelope sample, i.e. at least ``decimation >= 2`` cycles apart, so that cycle has no
    pulse word and the register is free again before the next pair word: one register
    suffices and no word is lost or reordered within its search.

    ``source`` None (one search): the emit cycles. ``last_pulse``: the emit cycle of the
    last pulse word written before these (a caller that hands the FIFO the words of one
    stretch of cycles at a time, keeping the later ones).
    """
    c = np.asarray(emit_cycles, dtype=np.int64)
    if source is None:
        return c.copy()
    pair = np.asarray(source) == SOURCE_PAIR
    pulses = np.r_[c[~pair], np.int64(last_pulse)]
    w = c + (pair & np.isin(c, pulses))
    if np.unique(w).size != w.size:
        raise RuntimeError("two FIFO writes in one cycle: each search's words must be >= 2 "
                           "cycles apart (decimation >= 2, one word per envelope sample)")
    return w


@dataclass
class FifoRun:
    """FIFO output predicted for a ready pattern: packed words and their cycles, the
    ``overflow_count`` port per cycle, and which peaks were dropped."""

    words: np.ndarray
    cycles: np.ndarray
    overflow_count: np.ndarray
    dropped: np.ndarray


class TacanFrontendModel:
    """Bit-exact model of :class:`hdl.tacan.frontend.TacanFrontEnd`.

    Parameters
    ----------
    params : TacanFrontendParams
    freq_word : int, optional
        NCO word held on the ``freq`` port (default: the IF word).
    fast : bool, optional
        Use the compiled fused path when the parameters allow it (default), or force the
        chained block models (``False``); both give the same bits.
    """

    CHUNK = 1 << 18   # ADC samples per internal step (cache-sized temporaries)

    def __init__(self, params: TacanFrontendParams | None = None, *, freq_word: int | None = None,
                 fast: bool | None = None, log_ranges: bool = False):
        self.params = params if params is not None else TacanFrontendParams()
        self.log_ranges = bool(log_ranges)
        #: Range log (``log_ranges=True``): signal -> [min, max] in LSBs over every call.
        self.range_log: dict[str, list[int]] = {}
        self.freq_word = self.params.nco_freq_word if freq_word is None else int(freq_word)
        self.ddc = DdcModel(self.params.ddc)
        self._fast = self._fast_ok() if fast is None else bool(fast and self._fast_ok())
        p = self.params
        if self._fast:
            self._ddc_cic = DdcCicKernel(p.ddc, p.cic)
            self._fir = FirKernel(p.fir)

    @property
    def fast(self) -> bool:
        """Whether :meth:`envelope` takes the compiled fast path (see there)."""
        return self._fast

    def _fast_ok(self) -> bool:
        p = self.params
        # Exact when nothing saturates (check_headroom) or wraps (no pruning: the CIC sum is
        # exact) and the FIR's float64 accumulation holds integers below 2**53.
        return (p.check_headroom and DdcCicKernel.exact(p.ddc, p.cic)
                and FirKernel.exact(p.fir))

    def envelope(self, adc_codes, state: TacanFrontendState | None = None, *,
                 freq_changes=None) -> tuple[np.ndarray, TacanFrontendState]:
        """Envelope samples (envelope LSBs) of the next ADC codes, and the new state
        (the peak searches' states are carried unchanged).

        ``freq_changes``: ``(index, word)`` pairs, the ``freq`` port taking ``word`` from the
        ADC sample ``index`` on (counted from reset, strictly increasing); the pairs outside
        the samples processed by this call are ignored (see :meth:`run`).

        Two implementations with the same bits: the block models chained
        (``fast=False``), and compiled numba kernels used when the parameters allow it
        (:attr:`fast`), single-threaded: NCO, mixer and CIC fused in one pass over the ADC
        samples in int64 (integrators and combs as the hardware, wrapping mod 2**64, which
        is exact because the unpruned CIC's result fits its full width), the FIR at the
        CIC rate accumulating in float64 (every product and partial sum is an integer below
        ``2**50``, so exact in any order), then the envelope CORDIC. Every rounding is the
        integer ``shift_right`` of :mod:`dsp.fixed`. The tests check the two paths against
        each other and the HDL against both.
        """
        p = self.params
        st = TacanFrontendState() if state is None else state
        x = np.asarray(adc_codes)
        if x.dtype.kind not in "iu":
            raise ValueError(f"ADC codes must be integers, not dtype {x.dtype}")
        if len(st.pending):
            x = np.concatenate([st.pending.astype(x.dtype), x])
        r = p.cic.rate * p.fir.decimation
        usable = len(x) - len(x) % r
        rest = x[usable:].astype(np.int64)
        x = x[:usable]
        fw0 = self.freq_word if st.freq is None else st.freq
        ch_idx, ch_val = _changes_in(freq_changes, st.n_adc, st.n_adc + usable)
        fw_end = int(ch_val[-1]) if ch_val.size else fw0
        if self.log_ranges and x.size:
            self._note("adc", x)
        if self._fast:
            e, nco, cic, fir = self._fast_chain(x, st, fw0, ch_idx, ch_val)
        else:
            fw = fw0
            if ch_idx.size:
                fw = np.full(usable, fw0, dtype=np.int64)
                for k, v in zip(ch_idx, ch_val):
                    fw[k:] = v
            i, q, nco = self.ddc.run(x.astype(np.int64), fw, st.nco)
            c, cic = cic_model(p.cic, np.stack([i, q], axis=-1), st.cic)
            f, fir = fir_model(p.fir, c, st.fir)
            e = envelope_model(f[:, 0], f[:, 1], p.envelope)
            if self.log_ranges and x.size:
                self._note("mixer", np.r_[i.min(), i.max(), q.min(), q.max()])
                self._note("cic", c)
                self._note("fir", f)
        if self.log_ranges and x.size:
            self._note("envelope", e)
        return e, replace(st, nco=nco, cic=cic, fir=fir, n_adc=st.n_adc + usable,
                          pending=rest, freq=fw_end)

    def _note(self, name: str, v) -> None:
        v = np.asarray(v)
        if v.size == 0:
            return
        lo, hi = int(v.min()), int(v.max())
        r = self.range_log.get(name)
        self.range_log[name] = [lo, hi] if r is None else [min(r[0], lo), max(r[1], hi)]

    def ranges(self) -> dict:
        """The range log (``log_ranges=True``) against each signal's word: ``{name: {"min",
        "max", "lo", "hi", "bits", "headroom_bits"}}`` in LSBs; ``headroom_bits`` = unused
        MSBs, ``log2(full scale / max |v|)`` (negative means it would have overflowed,
        which the parameter checks rule out for the default structure)."""
        p = self.params
        words = {"adc": p.adc_bits, "mixer": p.ddc.mixer.out_width, "cic": p.cic.out_width,
                 "fir": p.fir.out_width, "envelope": p.envelope.out_width}
        out = {}
        for name, (lo, hi) in self.range_log.items():
            b = words[name]
            signed = name != "envelope"
            top = (1 << (b - 1)) if signed else (1 << b)
            peak = max(abs(lo), abs(hi), 1)
            out[name] = {"min": lo, "max": hi, "bits": b,
                         "lo": -top if signed else 0, "hi": top - 1,
                         "headroom_bits": math.log2(top / peak)}
        return out

    def _fast_chain(self, x, st: TacanFrontendState, fw0: int, ch_idx, ch_val):
        """Compiled kernels: NCO + mixer + CIC fused (integer, sample by sample), the FIR
        (float64 accumulation, exact), the envelope CORDIC; states are copied, not
        modified."""
        p = self.params
        nco_p, cic = p.ddc.nco, p.cic
        if x.dtype.kind == "u" and x.size and int(x.max()) >= 1 << (p.adc_bits - 1):
            raise ValueError(f"ADC codes must be signed {p.adc_bits}-bit integers")
        x = np.ascontiguousarray(x, dtype=np.int64)   # one kernel signature
        pmask = (1 << nco_p.phase_bits) - 1
        acc0 = 0 if st.nco is None else int(st.nco.acc) & pmask
        fw = int(fw0) & pmask
        if st.cic is None:
            integ = np.zeros((2, cic.stages), np.int64)
            combs = np.zeros((2, cic.stages, cic.diff_delay), np.int64)
        else:
            integ, combs = (a.copy() for a in st.cic)
        L = len(p.fir.taps_int)
        hist = np.zeros((2, L - 1), np.int64) if st.fir is None else st.fir.copy()
        big = np.iinfo(np.int64).max
        mrng = np.array([big, -big, big, -big], np.int64)
        ci, cq, ph = self._ddc_cic.run(x, acc0, fw, integ, combs, ch_idx, ch_val, mrng)
        count = len(ci)
        nco = NcoState(acc=ph, lfsr=int(nco_p.dither_seed) if st.nco is None else st.nco.lfsr)
        nf = count // p.fir.decimation
        fi = self._fir.run(ci, hist[0])
        fq = self._fir.run(cq, hist[1])
        if self.log_ranges and count:
            self._note("mixer", mrng)
            self._note("cic", np.r_[ci.min(), ci.max(), cq.min(), cq.max()])
            if nf:
                self._note("fir", np.r_[fi.min(), fi.max(), fq.min(), fq.max()])
        # In range by construction (check_headroom: the FIR output never saturates).
        e = envelope_model(fi, fq, p.envelope, check=False)
        return e, nco, (integ, combs), hist

    def run(self, adc_codes, state: TacanFrontendState | None = None, *, freq_changes=None,
            final: bool = True) -> tuple[FrontendPeaks, TacanFrontendState]:
        """Peaks of the next ADC codes (valid samples only; gaps in valid do not change the
        values), vectorised, in internal chunks of :attr:`CHUNK`.

        Parameters
        ----------
        adc_codes : array of int
        state : TacanFrontendState, optional
        freq_changes : sequence of (index, word), optional
            Writes of the ``freq`` port (DSP -> FPGA control path): the NCO steps with
            ``word`` from ADC sample ``index`` on (valid samples counted from reset, as
            the state's ``n_adc``; ``index`` strictly increasing). A run split into several
            calls passes the same list to each: a call applies the changes that fall in its
            samples, the state carries the word in force, changes before the call's first
            sample (``state.n_adc``) were applied by the earlier calls.
        final : bool
            Two searches only (``config.pair_peak``): the record ends with this call. With
            ``False`` the pair peaks that a pulse peak of the next call could precede in the
            FIFO are held in the state and come out of the next call (only possible when
            the decimation is <= the pair search's extra latency, 2 or 3 cycles: see below),
            so that the calls' outputs put together equal one call's.

        Returns
        -------
        peaks : FrontendPeaks
            ``amplitudes`` (envelope LSBs) and ``timestamps`` (unwrapped int64 ADC ticks);
            with two searches both searches' peaks with their ``source``, in the order the
            FIFO is written (:func:`fifo_write_cycles`) when the ADC samples arrive on
            consecutive cycles. The order does not depend on gaps in ``valid`` when the
            decimation exceeds ``pair_peak.latency - peak.latency`` (2, 3 with the pair
            checks; the decimation is 4 by default): a pulse word comes first exactly when
            its emitting envelope sample is not later than the pair word's. Otherwise
            :meth:`peak_cycles` gives the cycles for a ``valid`` pattern and
            :meth:`fifo_output` writes in that order.
        state : TacanFrontendState
            Pass it to the next call: the result of several calls equals one long call.
        """
        p = self.params
        x = np.asarray(adc_codes)
        st = TacanFrontendState() if state is None else state
        changes = _check_changes(freq_changes, self.params.nco_phase_bits)
        searches = [("peak", p.peak)] + ([("pair_peak", p.pair_peak)] if p.pair_peak else [])
        found = {name: [] for name, _ in searches}
        for c0 in range(0, max(len(x), 1), self.CHUNK):
            e, st = self.envelope(x[c0:c0 + self.CHUNK], st, freq_changes=changes)
            for name, search in searches:
                res, pk = peak_search(e, search, getattr(st, name))
                setattr(st, name, pk)
                found[name].append(res)
        parts = []
        for k, (name, search) in enumerate(searches):
            res = found[name]
            index = np.concatenate([r.index for r in res]).astype(np.int64)
            amps = [r.partner if search.partner_offset else r.amplitude for r in res]
            parts.append(FrontendPeaks(
                amplitudes=np.concatenate(amps).astype(np.int64),
                timestamps=index * np.int64(search.ts_step), index=index,
                end_index=np.concatenate([r.end_index for r in res]).astype(np.int64)
                + search.emit_delay,
                source=np.full(index.size, k, np.int8) if p.pair_peak else None))
        if p.pair_peak is None:
            return parts[0], st
        if st.held is not None:
            parts.append(st.held)
        peaks = FrontendPeaks.concat(parts)
        emit = self.emit_cycles(peaks)
        peaks = peaks.take(np.argsort(fifo_write_cycles(emit, peaks.source), kind="stable"))
        st = replace(st, held=None)
        if not final:
            # a pulse of a later call leaves the search at this emit cycle or later
            # (the next envelope sample, closing a pulse); pair words from there on wait
            first = (st.peak.n + 1) * np.int64(p.decimation) - 1 + p.peak_latency
            late = self.emit_cycles(peaks) >= first
            if late.any():
                st.held, peaks = peaks.take(late), peaks.take(~late)
        return peaks, st

    # -- conversions --------------------------------------------------------------------------
    def peaks_to_fs(self, peaks: FrontendPeaks) -> Peaks:
        """The golden model's units: amplitudes in ADC full scale, timestamps in the golden's
        convention (the ADC tick that completes the envelope sample: ``ts + D - 1``); the
        ``source`` is carried."""
        p = self.params
        return Peaks(timestamps=peaks.timestamps + (p.decimation - 1),
                     amplitudes=peaks.amplitudes * p.scale_to_fs, fs_hz=p.config.fs_hz,
                     source=None if peaks.source is None else peaks.source.copy())

    def _check_source(self, peaks: FrontendPeaks) -> None:
        if (peaks.source is None) != (self.params.pair_peak is None):
            raise ValueError("peaks must carry a source exactly when the front end has two "
                             "searches (config.pair_peak)")

    def words(self, peaks: FrontendPeaks) -> np.ndarray:
        """Packed FIFO input payloads ``amplitude | (timestamp mod 2**ts_bits) << amp_width``,
        with two searches ``| source << (amp_width + ts_bits)``."""
        self._check_source(peaks)
        p = self.params.peak
        ts = peaks.timestamps & np.int64((1 << p.ts_bits) - 1)
        w = peaks.amplitudes | (ts << np.int64(p.amp_width))
        if peaks.source is not None:
            w = w | (peaks.source.astype(np.int64) << np.int64(p.amp_width + p.ts_bits))
        return w

    def unpack(self, fifo_words) -> dict[str, np.ndarray]:
        """Split FIFO output words into ``amplitude``, ``timestamp`` (wrapped), ``tag`` and,
        with two searches, ``source`` (the payload's top bit; in a marker word it is part
        of the drop count)."""
        p = self.params
        w = np.asarray(fifo_words, dtype=np.int64)
        aw, tb, sb = p.peak.amp_width, p.peak.ts_bits, p.source_bits
        out = {"amplitude": w & np.int64((1 << aw) - 1),
               "timestamp": (w >> np.int64(aw)) & np.int64((1 << tb) - 1),
               "tag": (w >> np.int64(aw + tb + sb)) & np.int64(3)}
        if sb:
            out["source"] = (w >> np.int64(aw + tb)) & np.int64(1)
        return out

    def emit_cycles(self, peaks: FrontendPeaks, in_valid=None, *, adc_cycles=None) -> np.ndarray:
        """Clock cycle (from reset, as :func:`cosim.pysim.run_stream` counts) at which each
        peak leaves its search: the cycle of the ADC transfer that completes its emitting
        envelope sample (``end_index``) plus that search's latency
        (:attr:`~TacanFrontendParams.peak_latency`, ``pair_peak_latency``), for ADC samples
        offered with ``in_valid`` (per cycle; every cycle after the pattern ends, as
        ``run_stream``), or mapped to their cycles by ``adc_cycles(adc_index) -> cycle``
        (valid ADC samples counted from reset). Default: one sample per cycle from reset."""
        p = self.params
        adc_idx = (peaks.end_index + 1) * np.int64(p.decimation) - 1
        if adc_cycles is not None:
            acc = np.asarray(adc_cycles(adc_idx), np.int64)
        elif in_valid is not None:
            v = np.flatnonzero(np.asarray(in_valid, dtype=bool))
            n_pat = len(np.asarray(in_valid))
            acc = np.where(adc_idx < len(v), v[np.minimum(adc_idx, max(len(v) - 1, 0))]
                           if len(v) else 0, n_pat + adc_idx - len(v))
        else:
            acc = adc_idx
        if peaks.source is None:
            return acc + np.int64(p.peak_latency)
        self._check_source(peaks)
        return acc + np.where(peaks.source == SOURCE_PAIR, np.int64(p.pair_peak_latency),
                              np.int64(p.peak_latency))

    def peak_cycles(self, peaks: FrontendPeaks, in_valid=None) -> np.ndarray:
        """Clock cycle at which each peak is written to the FIFO: :meth:`emit_cycles`, with
        two searches merged by :func:`fifo_write_cycles`. The peaks must be all of a record
        from reset (the merge looks at every pulse word)."""
        return fifo_write_cycles(self.emit_cycles(peaks, in_valid), peaks.source)

    def fifo_output(self, peaks: FrontendPeaks, n_cycles: int, *, in_valid=None,
                    out_ready=None) -> FifoRun:
        """What the FIFO hands the DSP in ``n_cycles`` cycles from reset, given the DSP's
        ``ready`` per cycle (default always; after the pattern ends: ready). ``dropped``:
        per peak written within ``n_cycles`` (in the order of ``peaks``), whether the FIFO
        dropped it."""
        p = self.params
        cyc = self.peak_cycles(peaks, in_valid)
        order = np.argsort(cyc, kind="stable")        # the FIFO's write order
        order = order[cyc[order] < n_cycles]
        w_valid = np.zeros(n_cycles, dtype=bool)
        w_valid[cyc[order]] = True
        rdy = np.ones(n_cycles, dtype=bool)
        if out_ready is not None:
            r = np.asarray(out_ready, dtype=bool)[:n_cycles]
            rdy[:len(r)] = r
        res = fifo_model(self.words(peaks)[order], w_valid, rdy, p.fifo)
        dropped = np.zeros(len(peaks), dtype=bool)
        dropped[order] = res.dropped
        return FifoRun(words=res.words, cycles=res.cycles,
                       overflow_count=res.overflow_count, dropped=dropped[cyc < n_cycles])
