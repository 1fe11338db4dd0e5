"""What one end-to-end TACAN run is: :class:`TacanRunConfig` (the scenario, the front-end
backend, the link, the DSP and the scoring), every field checked when it is built, and the
configurations it derives (front end, HDL parameters, receiver).

The run itself is :func:`cosim.tacan.run.run_tacan`; the front-end backends are
:mod:`cosim.tacan.frontends`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from dsp.tacan.frontend import (BOTH_PAIR_SEARCH, DETECTORS, NOISE_FLOORS, PAIR_DETECTOR,
                                FrontendConfig, pair_detector, pair_spacing_samples)
from dsp.tacan.kalman_config import KalmanConfig, KalmanFixedConfig
from dsp.tacan.peakbias import BOTH_PEAK_BIAS, PAIR_PEAK_BIAS
from dsp.tacan.receiver import ReceiverConfig
from dsp.tacan.decode import DecoderConfig
from ..core.control import ControlPath
from ..core.link import DspServiceConfig
from .signal import TacanSignalConfig

BACKENDS = ("golden", "model", "pysim", "verilator", "icarus")
DSP_MODES = ("float", "fixed")


@dataclass(frozen=True)
class TacanRunConfig:
    """A whole run: the scenario, the front end, the link, the DSP and how it is scored.

    Parameters
    ----------
    signal : TacanSignalConfig
    backend : str
        One of :data:`BACKENDS`.
    dsp : str
        ``"float"`` (golden arithmetic) or ``"fixed"`` (the fixed-point core, formats
        ``fixed``).
    kalman : KalmanConfig
        The filter (memory, gate, ...), shared by both arithmetics; the receiver runs it
        with its ``tick_hz`` replaced by the signal's ``fs_hz``, the clock of the FPGA
        timestamps.
    fixed : KalmanFixedConfig, optional
        Word lengths of the fixed-point core (default formats; its ``kalman`` is replaced
        by that filter).
    settle_s : float, optional
        Bearings before this time are not scored (default 2 x the filter memory).
    frontend_changes : tuple of (name, value)
        Overrides of :class:`dsp.tacan.frontend.FrontendConfig` (rates, structure).
    hdl_changes : tuple of (name, value)
        Overrides of :class:`hdl.tacan.params.TacanFrontendParams` (word lengths).
    service : DspServiceConfig
        How the DSP reads the FIFO (HDL backends).
    control_writes : tuple of (cycle, register, value)
        Register writes the DSP issues towards the FPGA (through a :class:`ControlPath`
        with ``control_latency_cycles``); registers: ``"freq"`` (NCO word).
    control_latency_cycles : int
    compare : str, optional
        ``"golden"``: also run the golden chain and report ``vs_golden_rms_deg``.
    require_bearing : bool
        Raise if no bearing is produced after settling (default). Short cycle-accurate
        runs set it False and compare bits instead.
    trace : str, optional
        Waveform file of the cycle-accurate front end (``pysim``: VCD; ``verilator``: FST
        if it ends in ``.fst``, else VCD); put it under ``build/``.
    trace_window : (start, stop), optional
        Cycles to dump (Verilator; the Amaranth VCD writer records the whole run).
    recheck : str, optional
        With the ``model`` backend: also run the first ``recheck_samples`` ADC samples
        cycle-accurately (``"auto"``, ``"verilator"``, ``"pysim"``) and report whether the
        FIFO words are the same bits (:func:`recheck_cycle_accurate`).
    """

    signal: TacanSignalConfig = field(default_factory=TacanSignalConfig)
    backend: str = field(default="golden", metadata={
        "help": "front end: float golden model (no FIFO), bit-exact HDL model, Amaranth "
                "simulation (~3k cycles/s: records of a few 0.01 s) or Verilator",
        "choices": BACKENDS, "case": "lower"})
    dsp: str = field(default="float", metadata={"help": "arithmetic of the bearing DSP core",
                                                "choices": DSP_MODES, "case": "lower"})
    kalman: KalmanConfig = field(default_factory=KalmanConfig)
    fixed: KalmanFixedConfig | None = None
    settle_s: float | None = field(default=None, metadata={
        "help": "bearings before this time (s) are not scored (default 2 x --memory-s)"})
    noise_floor: str = field(default="clipped", metadata={
        "help": "pulse detector's noise floor: clipped mean (default) or censored mean "
                "(pulses do not lift it; threshold 3.44x; see dsp.tacan.frontend.NOISE_FLOORS)",
        "choices": tuple(NOISE_FLOORS), "case": "lower"})
    amplitude: str = field(default="peak", metadata={
        "help": "what the FPGA reports as a pulse's amplitude: its peak, or the envelope at "
                "its pair partner (12 us away in X mode, 30 us in Y; not the noise that made "
                "the detection, so not censored by the threshold near the noise floor; the "
                "DSP then measures every pulse outside the bursts below ~1 dB)",
        "choices": ("peak", "partner"), "case": "lower"})
    detector: str = field(default="both", metadata={
        "help": "what the FPGA detects. both (default): a single-pulse search and a "
                "pulse-pair search side by side (the envelope summed with itself one pair "
                "spacing earlier: both pulses of a pair integrated; censored slow floor, its "
                "own threshold), one tagged FIFO stream; the DSP decodes the references on "
                "the single pulses and measures the bearing on the pairs -- away from the noise "
                "floor only those whose two pulses the single-pulse search saw too, chosen at "
                "run time from that paired fraction (dsp.tacan.pairsource) -- correcting their "
                "bias near the threshold (dsp.tacan.peakbias); figures: bench tacan-accuracy. "
                "pulse: the single-pulse search alone (the receiver before issue 18: "
                "no bearing at 0-2 dB at some bearings; needed by --amplitude partner). pair: "
                "the pair search alone, experimental (fewer records acquired at 0 dB, and an "
                "X beacon heard by a Y receiver at 10 dB passes it)",
        "choices": DETECTORS, "case": "lower"})
    frontend_changes: tuple = ()
    hdl_changes: tuple = ()
    service: DspServiceConfig = field(default_factory=DspServiceConfig)
    control_writes: tuple = ()
    control_latency_cycles: int = 0
    compare: str | None = field(default=None, metadata={
        "help": "also run the golden chain and report vs_golden_rms_deg",
        "choices": ("golden",), "case": "lower"})
    require_bearing: bool = True
    trace: str | None = field(default=None, metadata={
        "help": "waveform of the cycle-accurate front end, format from the suffix: .vcd "
                "(pysim, verilator) or .fst (verilator); put it under build/",
        "metavar": "FILE"})
    trace_window: tuple | None = None
    recheck: str | None = field(default=None, metadata={
        "help": "with --backend model: re-run the start of the record cycle-accurately "
                "(auto = Verilator when installed) and compare the FIFO words",
        "choices": ("auto", "pysim", "verilator", "icarus"), "case": "lower"})
    recheck_samples: int | None = field(default=None, metadata={
        "help": "ADC samples re-checked with --recheck (default 1e6 with Verilator, 4e4 "
                "with pysim and icarus)"})

    def __post_init__(self):
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {list(BACKENDS)}, not {self.backend!r}")
        if self.dsp not in DSP_MODES:
            raise ValueError(f"dsp must be one of {list(DSP_MODES)}, not {self.dsp!r}")
        if self.noise_floor not in NOISE_FLOORS:
            raise ValueError(f"noise_floor must be one of {list(NOISE_FLOORS)}, not "
                             f"{self.noise_floor!r}")
        if self.noise_floor != "clipped" and "peak" in dict(self.frontend_changes):
            raise ValueError("noise_floor chooses the peak detector's parameters: give it or "
                             "a 'peak' in frontend_changes, not both")
        if self.amplitude not in ("peak", "partner"):
            raise ValueError(f"amplitude must be 'peak' or 'partner', not {self.amplitude!r}")
        if self.detector not in DETECTORS:
            raise ValueError(f"detector must be one of {list(DETECTORS)}, not {self.detector!r}")
        if self.detector == "pair" and (self.noise_floor != "clipped" or self.amplitude != "peak"
                                        or "peak" in dict(self.frontend_changes)):
            raise ValueError("the pair detector has its own noise floor and reports the pair's "
                             "mean amplitude: give --detector pair without --noise-floor, "
                             "--amplitude or a 'peak' in frontend_changes")
        if self.detector == "both" and (self.amplitude != "peak"
                                        or "pair_peak" in dict(self.frontend_changes)):
            raise ValueError("with --detector both (the default) the bearing is measured on "
                             "the pair search's amplitudes: --amplitude partner is an option "
                             "of the single-pulse search alone (add --detector pulse), and "
                             "give no 'pair_peak' in frontend_changes")
        if self.compare not in (None, "golden"):
            raise ValueError(f"compare must be None or 'golden', not {self.compare!r}")
        if self.fixed is not None and not isinstance(self.fixed, KalmanFixedConfig):
            raise ValueError(f"fixed must be a KalmanFixedConfig, not {self.fixed!r}")
        if not isinstance(self.service, DspServiceConfig):
            raise ValueError(f"service must be a DspServiceConfig, not {self.service!r}")
        if self.settle_s is not None and not (math.isfinite(self.settle_s) and self.settle_s >= 0):
            raise ValueError(f"settle_s must be >= 0, not {self.settle_s}")
        if not (self.signal.mod_15 > 0 and self.signal.mod_135 > 0):
            raise ValueError(
                f"the bearing is the phase of the 15 Hz (coarse) and 135 Hz (fine) "
                f"modulation: both depths must be > 0, not mod_15={self.signal.mod_15:g}, "
                f"mod_135={self.signal.mod_135:g}")
        if self.require_bearing and self.settle + 0.1 > self.signal.duration_s:
            raise ValueError(
                f"duration_s={self.signal.duration_s:g} leaves no time after the filter settles "
                f"({self.settle:g} s); use a duration of at least {self.settle + 0.5:g} s "
                f"or a shorter settle time")
        ControlPath(self.control_latency_cycles)      # validates the latency
        for w in self.control_writes:
            if len(w) != 3 or w[1] not in ("freq",):
                raise ValueError(f"control writes are (cycle, 'freq', value), not {w!r}")
        if self.recheck is not None:
            if self.recheck not in ("auto", "pysim", "verilator", "icarus"):
                raise ValueError(f"recheck must be auto, pysim, verilator or icarus, not "
                                 f"{self.recheck!r}")
            if self.backend != "model":
                raise ValueError("recheck compares a model run with a cycle-accurate one: "
                                 "use it with backend='model'")
        if self.recheck_samples is not None and (
                isinstance(self.recheck_samples, bool) or
                not isinstance(self.recheck_samples, int) or self.recheck_samples < 1):
            raise ValueError(f"recheck_samples must be an integer >= 1, not "
                             f"{self.recheck_samples!r}")
        if self.trace is not None and self.backend not in ("pysim", "verilator"):
            raise ValueError(f"trace needs a cycle-accurate backend (pysim or verilator), "
                             f"not {self.backend!r}")
        if self.trace_window is not None:
            tw = self.trace_window
            if not (len(tw) == 2 and all(isinstance(v, (int, np.integer)) for v in tw)
                    and 0 <= tw[0] < tw[1]):
                raise ValueError(f"trace_window must be (start, stop) cycles with "
                                 f"0 <= start < stop, not {tw!r}")

    @property
    def settle(self) -> float:
        return 2.0 * self.kalman.memory_s if self.settle_s is None else float(self.settle_s)

    @property
    def frontend(self) -> FrontendConfig:
        changes = dict(self.frontend_changes)
        if self.noise_floor != "clipped":
            changes["peak"] = NOISE_FLOORS[self.noise_floor]
        cfg = FrontendConfig.for_signal(self.signal, **changes)
        if self.amplitude == "partner":     # the pair spacing in envelope samples
            d = pair_spacing_samples(self.signal.mode, cfg.env_rate_hz)
            cfg = replace(cfg, peak=replace(cfg.peak, partner_offset=d))
        if self.detector != "pulse":
            base = PAIR_DETECTOR if self.detector == "pair" else BOTH_PAIR_SEARCH
            pair = pair_detector(self.signal.mode, cfg.env_rate_hz,
                                 replace(base, ts_step=cfg.peak.ts_step))
            cfg = replace(cfg, **{"peak" if self.detector == "pair" else "pair_peak": pair})
        return cfg

    @property
    def hdl_params(self):
        from hdl.tacan.params import TacanFrontendParams
        return TacanFrontendParams(config=self.frontend, adc_bits=self.signal.adc_bits,
                                   **dict(self.hdl_changes))

    @property
    def receiver(self) -> ReceiverConfig:
        # the filter counts the FPGA's timestamps: ticks of the ADC clock of this run
        kal = replace(self.kalman, tick_hz=float(self.signal.fs_hz))
        k = replace(self.fixed or KalmanFixedConfig(), kalman=kal) if self.dsp == "fixed" else kal
        dec = None
        if self.amplitude == "partner":
            dec = DecoderConfig(mode=self.signal.mode, single_pulses_below=0.4)
        return ReceiverConfig(mode=self.signal.mode, kalman=k, decoder=dec,
                              pair_reports=self.detector == "pair",
                              peak_bias={"pulse": None, "pair": PAIR_PEAK_BIAS,
                                         "both": BOTH_PEAK_BIAS}[self.detector])
