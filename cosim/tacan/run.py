"""End-to-end TACAN scenario: IF signal -> front end (a backend) -> FIFO link -> bearing DSP.

Front-end backends (what turns ADC samples into pulse peaks):

``golden``     float64 model of the front end (:mod:`dsp.tacan.frontend`); no FIFO.
``model``      bit-exact numpy model of the HDL (:class:`hdl.tacan.model.TacanFrontendModel`)
               and of its FIFO, read by the DSP service model of :mod:`cosim.link`.
``pysim``      the Amaranth design in ``amaranth.sim`` (cycle-accurate, ~1k cycles/s: short
               scenarios only).
``verilator``  the exported Verilog compiled with Verilator (cycle-accurate, compiled speed).

The three HDL backends produce the same FIFO words on the same cycles (the tests check it);
the DSP side is common: it decodes the tagged FIFO words (data / gap markers), unwraps the
32-bit timestamps, converts amplitudes to its input format and runs the bearing processor
(:func:`dsp.tacan.receiver.process_peaks`) in float (golden) or fixed point (``dsp``).

``compare="golden"`` also runs the golden chain (golden front end + float DSP) on the same
samples and reports ``vs_golden_rms_deg``: the RMS difference of the bearings produced at the
same references after settling.
"""
from __future__ import annotations

import hashlib
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from dsp.tacan.frontend import (BOTH_PAIR_SEARCH, DETECTORS, NOISE_FLOORS, PAIR_DETECTOR,
                                FrontendConfig,
                                pair_detector, pair_spacing_samples, run_golden_frontend)
from dsp.tacan.kalman_config import KalmanConfig, KalmanFixedConfig
from dsp.tacan.peakbias import BOTH_PEAK_BIAS, PAIR_PEAK_BIAS
from dsp.tacan.receiver import (BearingTrack, ReceiverConfig, amplitude_codes, bearing_stats,
                                ReceiverState, process_peaks)
from dsp.tacan.bearing import wrap_deg
from dsp.tacan.bounds import crb_deg
from dsp.tacan.decode import DecoderConfig
from dsp.tacan.fifo_rx import receive_words
from ..link import ControlPath, DspServiceConfig
from .signal import TacanSignalConfig, generate

BACKENDS = ("golden", "model", "pysim", "verilator")
DSP_MODES = ("float", "fixed")

#: Memory a run holds per ADC sample (bytes; measured ~14 on the model backend: the IF
#: record, the ADC codes and the front end's working arrays), with margin.
BYTES_PER_SAMPLE = {"golden": 32, "model": 32, "pysim": 48, "verilator": 48}
#: Simulation speed of the cycle-accurate backends (cycles/s, whole TACAN top) and the
#: longest run they are started for (s of wall time).
CYCLES_PER_S = {"pysim": 3e3, "verilator": 5e6}
MAX_WALL_S = 3600.0


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
                "the single pulses and measures the bearing on the pairs, correcting their "
                "bias near the threshold (dsp.tacan.peakbias): 1.1-1.6x the bound from 0 to "
                "20 dB. pulse: the single-pulse search alone (the receiver before issue 18: "
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
        "choices": ("auto", "pysim", "verilator"), "case": "lower"})
    recheck_samples: int | None = field(default=None, metadata={
        "help": "ADC samples re-checked with --recheck (default 1e6 with Verilator, 4e4 "
                "with pysim)"})

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
            if self.recheck not in ("auto", "pysim", "verilator"):
                raise ValueError(f"recheck must be auto, pysim or verilator, not "
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


@dataclass
class FrontendOutput:
    """What the DSP receives from a front-end backend (one record).

    ticks : int64 unwrapped ADC tick of each peak, golden convention (the tick that
        completes the envelope sample); amplitude_fs : float amplitudes (FS);
    amplitude_lsb : envelope LSBs (HDL backends) or None; words/cycles : FIFO words read by
    the DSP and their read cycles (HDL backends); fifo_dropped : FPGA overflow counter at
    the end; dropped_reported : sum of the gap markers the DSP read; source : with two
    searches (``FrontendConfig.pair_peak``) the search of each peak (int8,
    ``dsp.tacan.frontend.SOURCE_PULSE`` / ``SOURCE_PAIR``), else None.
    """

    ticks: np.ndarray
    amplitude_fs: np.ndarray
    amplitude_lsb: np.ndarray | None = None
    words: np.ndarray | None = None
    cycles: np.ndarray | None = None
    fifo_dropped: int = 0
    dropped_reported: int = 0
    n_cycles: int = 0
    scale_to_fs: float = 1.0
    extra: dict = field(default_factory=dict)
    source: np.ndarray | None = None   # with two searches: each peak's (dsp.tacan.frontend)


# ---------------------------------------------------------------------------------------
# Front-end backends
# ---------------------------------------------------------------------------------------
def _golden(samples, run: TacanRunConfig) -> FrontendOutput:
    pk = run_golden_frontend(samples, run.frontend, run.signal.adc_bits)
    return FrontendOutput(ticks=np.asarray(pk.timestamps, np.int64),
                          amplitude_fs=np.asarray(pk.amplitudes, np.float64), source=pk.source)


def _n_cycles(samples, params) -> int:
    """Cycles simulated: every ADC sample plus enough to flush the last peak out."""
    return int(len(samples) + params.latency + 4 * params.decimation + 64)


def _freq_segments(run: TacanRunConfig, params, n_cycles: int):
    ctl = ControlPath(run.control_latency_cycles, initial={"freq": params.nco_freq_word})
    for c, reg, v in run.control_writes:
        ctl.write(int(c), reg, int(v))
    return ctl


def _dsp_receive(words, cycles, params, n_cycles, ovf_count) -> FrontendOutput:
    """The DSP side of the link: tagged words -> peaks (unwrapped ticks, amplitudes; with
    two searches their sources, each search's timestamps checked on their own)."""
    out = receive_words(words, width=params.fifo.width, amp_width=params.peak.amp_width,
                        ts_bits=params.peak.ts_bits, parity=params.fifo.parity,
                        source_bits=params.source_bits)
    ts, amp, rx = out[0], out[1], out[-1]
    ticks = ts + np.int64(params.decimation - 1)     # golden convention (see peaks_to_fs)
    return FrontendOutput(ticks=ticks, amplitude_fs=amp * params.scale_to_fs, amplitude_lsb=amp,
                          words=np.asarray(words, np.int64), cycles=np.asarray(cycles, np.int64),
                          fifo_dropped=int(ovf_count),
                          dropped_reported=int(rx.stats["dropped_reported"]),
                          n_cycles=int(n_cycles), scale_to_fs=params.scale_to_fs,
                          extra={"rx": dict(rx.stats)},
                          source=out[2] if params.source_bits else None)


def _session_frontend(samples, run: TacanRunConfig, backend: str) -> FrontendOutput:
    """An HDL backend's output for one record, on the streaming pipeline: a front-end
    session (:func:`cosim.session.open_frontend`) fed the record and ``_n_cycles - len``
    idle cycles to flush the last peak, the DSP reading with ``run.service``, the
    ``control_writes`` scheduled at their effect cycles (open loop: the DSP runs after)."""
    from ..pipeline import Pipeline
    from ..session import open_frontend
    p = run.hdl_params
    n_cycles = _n_cycles(samples, p)
    ctl = _freq_segments(run, p, n_cycles)
    # One ADC sample per cycle from reset: a write taking effect at cycle c changes the NCO
    # word from ADC sample c on, on every backend.
    writes = [(c, "freq", v) for c, _, v in ctl.writes()]
    with open_frontend(backend, p, log_ranges=backend == "model",
                       vcd=run.trace if backend == "pysim" else None) as fe:
        pipe = Pipeline(fe, run.service)
        pipe.schedule(writes)
        pipe.feed(samples)
        pipe.idle(n_cycles - len(samples))
        res = pipe.result()
        fo = _dsp_receive(res.words, res.cycles, p, n_cycles, res.overflow_count)
        if backend == "model":
            fo.extra["ranges"] = fe.ranges()
            fo.extra["fifo_max_level"] = int(fe.fifo_state.max_level)
    return fo


def _model(samples, run: TacanRunConfig) -> FrontendOutput:
    return _session_frontend(samples, run, "model")


def _hdl_sim(samples, run: TacanRunConfig, kind: str) -> FrontendOutput:
    if kind == "pysim" or run.trace is None:
        return _session_frontend(samples, run, kind)
    # A Verilator waveform needs the one-shot run (a session's time base is per step).
    from hdl.tacan.frontend import TacanFrontEnd
    from ..verilator import VerilatorStreamSim
    p = run.hdl_params
    n_cycles = _n_cycles(samples, p)
    ctl = _freq_segments(run, p, n_cycles)
    ready = run.service.ready_mask(n_cycles)
    writes = [(c, "freq", v) for c, _, v in ctl.writes()]
    sim = VerilatorStreamSim(TacanFrontEnd(p), name="tacan_frontend")
    res = sim.run(samples, out_ready=ready, n_cycles=n_cycles,
                  inputs={"freq": p.nco_freq_word}, writes=writes,
                  final={"overflow_count": "overflow_count"},
                  trace=run.trace, trace_window=run.trace_window)
    return _dsp_receive(res.words, res.cycles, p, n_cycles, res.final["overflow_count"])


FRONTENDS = {"golden": _golden, "model": _model,
             "pysim": lambda s, r: _hdl_sim(s, r, "pysim"),
             "verilator": lambda s, r: _hdl_sim(s, r, "verilator")}


# ---------------------------------------------------------------------------------------
def run_dsp(fo: FrontendOutput, run: TacanRunConfig,
            state: ReceiverState | None = None) -> BearingTrack:
    """The bearing DSP on a front end's output (float or fixed by ``run.dsp``), from
    ``state`` when given (e.g. a core with scheduled upsets, :mod:`cosim.tacan.faults`); the
    timestamps' clock is the receiver configuration's (the signal's ``fs_hz``)."""
    rc = run.receiver
    times = fo.ticks / rc.kalman.tick_hz
    if rc.dsp == "fixed" and fo.amplitude_lsb is not None:
        amps = amplitude_codes(fo.amplitude_lsb, fo.scale_to_fs, rc.kalman.y)
    else:
        amps = fo.amplitude_fs
    return process_peaks(times, amps, rc, ticks=fo.ticks, source=fo.source, state=state)


def _match_rms(track: BearingTrack, ref: BearingTrack, settle: float, tol_s: float = 50e-6):
    """RMS difference (deg) of the bearings of two tracks at the same references."""
    keep = track.times_s >= settle
    t, b = track.times_s[keep], track.bearing_deg[0, keep]
    if t.size == 0 or ref.times_s.size == 0:
        return math.nan, 0
    j = np.clip(np.searchsorted(ref.times_s, t), 1, ref.times_s.size - 1)
    j = np.where(np.abs(ref.times_s[j - 1] - t) < np.abs(ref.times_s[j] - t), j - 1, j)
    ok = np.abs(ref.times_s[j] - t) <= tol_s
    if not ok.any():
        return math.nan, 0
    d = wrap_deg(b[ok] - ref.bearing_deg[0, j[ok]])
    return float(np.sqrt(np.mean(d ** 2))), int(ok.sum())


def _finite_or_none(v) -> float | None:
    return float(v) if math.isfinite(float(v)) else None


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def frontend_key(run: TacanRunConfig) -> tuple:
    """What a front end's output depends on: runs with equal keys on the same samples get
    the same :class:`FrontendOutput` (the DSP side may differ)."""
    return (run.backend, run.signal, run.noise_floor, run.amplitude, run.frontend_changes,
            run.hdl_changes, run.service,
            run.control_writes, run.control_latency_cycles)


def check_run_size(run: TacanRunConfig) -> None:
    """Refuse, before any work, a run that cannot fit this machine: the memory its record
    needs (:data:`BYTES_PER_SAMPLE`) and, on a cycle-accurate backend, the simulation time
    (:data:`CYCLES_PER_S`, at most :data:`MAX_WALL_S`). The message names the option."""
    from ..validate import check_memory
    sig = run.signal
    n = sig.duration_s * sig.fs_hz
    per = BYTES_PER_SAMPLE[run.backend] + (16 if run.compare else 0)
    check_memory(n * per, f"{n:.3g} ADC samples (--duration-s {sig.duration_s:g} x --fs-hz "
                          f"{sig.fs_hz:g})", "--duration-s or --fs-hz")
    for be, cycles in ((run.backend, n), (run.recheck, run.recheck_samples or 0)):
        if be in CYCLES_PER_S and cycles / CYCLES_PER_S[be] > MAX_WALL_S:
            opt = "--duration-s" if be == run.backend else "--recheck-samples"
            raise ValueError(
                f"{be} simulates about {CYCLES_PER_S[be]:.0e} cycles/s: {cycles:,.0f} cycles "
                f"would take ~{cycles / CYCLES_PER_S[be] / 3600:.1f} h (limit "
                f"{MAX_WALL_S / 3600:g} h, {CYCLES_PER_S[be] * MAX_WALL_S:,.0f} cycles): "
                f"reduce {opt}" + ("; long records run on --backend model (with --recheck "
                                   "for the cycle-accurate proof of its start)"
                                   if be == "pysim" else ""))


def run_tacan(run: TacanRunConfig, signal=None, frontend_cache: dict | None = None,
              progress: bool = False) -> dict:
    """Run one scenario end to end; returns the result record (JSON-serialisable).

    ``signal`` (a :class:`cosim.tacan.signal.TacanSignal` of ``run.signal``) skips the
    generation (studies digitise one record with several ADCs). ``frontend_cache`` (a dict
    the caller keeps) reuses the front end's output between runs that differ only in the
    DSP (:func:`frontend_key`), e.g. a sweep of DSP word lengths. ``progress`` shows the
    stages of the run on stderr (a tqdm bar; the cycle-accurate backends with their
    estimated time).
    """
    sig = run.signal
    t0 = time.perf_counter()
    if signal is not None and signal.truth.config != sig:
        raise ValueError("signal was generated for another configuration than run.signal")
    check_run_size(run)
    bar = _Stages(run, progress)
    bar.stage("signal")
    s = generate(sig) if signal is None else signal
    t1 = time.perf_counter()
    bar.stage(f"front end ({run.backend})")
    key = frontend_key(run) if frontend_cache is not None and run.trace is None else None
    if key is not None and key in frontend_cache:
        fo = frontend_cache[key]
    else:
        fo = FRONTENDS[run.backend](s.samples, run)
        if key is not None:
            frontend_cache[key] = fo
    t2 = time.perf_counter()
    bar.stage(f"DSP ({run.dsp})")
    track = run_dsp(fo, run)
    t3 = time.perf_counter()
    st = bearing_stats(track, s.truth.bearing_deg, run.settle)
    rel_sigma = sig.matched_filter_rel_sigma()
    crb = crb_deg(rel_sigma, sig.mod_15, sig.mod_135, run.kalman.n_eff)
    if st["n"] == 0 and run.require_bearing:
        raise RuntimeError(
            "no bearing was produced after the filter settled: no reference bursts were "
            f"decoded ({track.n_main_refs} main, {track.n_aux_refs} auxiliary from "
            f"{track.n_peaks} peaks); the signal may be too weak or the mode wrong")
    locked = st["n"] > 0
    rmse = float(st["rmse_deg"][0]) if locked else None
    events = {k: int(v[0]) for k, v in track.events.items()}
    r = {
        "bearing_true_deg": s.truth.bearing_deg,
        "bearing_est_deg": float(st["final_deg"][0]) if locked else
        (float(track.bearing_deg[0, -1]) if track.bearing_deg.shape[1] else None),
        "rmse_deg": rmse,
        "mean_error_deg": float(st["mean_error_deg"][0]) if locked else None,
        "max_abs_error_deg": float(st["max_abs_error_deg"][0]) if locked else None,
        "crb_deg": crb if math.isfinite(crb) else None,
        "rmse_over_crb": (rmse / crb if 0 < crb < math.inf else None) if locked else None,
        "crb_window_s": run.kalman.memory_s,
        "n_updates": int(track.n_updates),
        "n_bearings": int(st["n"]),
        # what a user sees: the bearings shown valid after settling, and the misleading
        # ones among them (bearing_stats)
        "n_valid_bearings": int(st["n_valid"][0]),
        "valid_rmse_deg": _finite_or_none(st["valid_rmse_deg"][0]),
        "misleading_bearings": int(st["misleading"][0]),
        "n_peaks": int(track.n_peaks),
        "n_measurements": int(track.n_measurements),
        "n_main_refs": int(track.n_main_refs),
        "n_aux_refs": int(track.n_aux_refs),
        "refs_off_grid": int(track.n_refs_off_grid),
        "first_valid_bearing_s": _finite_or_none(track.first_valid_s()[0]),
        "rotation_hz": track.state.rotation_hz if track.state is not None else None,
        "gated": int(track.gated[0]),
        "reinit": int(track.reinit[0]),
        "adc_clipped": int(s.truth.n_clipped),
        "fifo_dropped": int(fo.fifo_dropped),
        "fifo_dropped_reported": int(fo.dropped_reported),
        "fifo_max_level": fo.extra.get("fifo_max_level"),
        "dsp_events": events,
        "backend": run.backend,
        "dsp": run.dsp,
        "mode": sig.mode,
        "snr_db": sig.snr_db,
        "duration_s": sig.duration_s,
        "seed": sig.seed,
        "settle_s": run.settle,
        "n_cycles": int(fo.n_cycles),
        "ranges": _ranges(fo, track, s.truth.n_clipped),
        "digest": {"peaks": _digest(fo.ticks, fo.amplitude_fs),
                   "fifo": _digest(fo.words) if fo.words is not None else None,
                   "bearings": _digest(track.times_s, track.bearing_deg)},
        "elapsed_s": {"signal": t1 - t0, "frontend": t2 - t1, "dsp": t3 - t2},
    }
    if run.recheck is not None:
        bar.stage(f"re-check ({run.recheck})")
        r["recheck"] = recheck_cycle_accurate(run, s.samples, run.recheck,
                                              run.recheck_samples)
    if run.compare == "golden":
        bar.stage("golden chain")
        t4 = time.perf_counter()
        gfo = _golden(s.samples, run)
        gold = run_dsp(gfo, TacanRunConfig(**{**_fields(run), "backend": "golden",
                                               "dsp": "float", "compare": None,
                                               "recheck": None}))
        rms, n = _match_rms(track, gold, run.settle)
        r["vs_golden_rms_deg"] = rms
        r["vs_golden_n"] = n
        gst = bearing_stats(gold, s.truth.bearing_deg, run.settle)
        r["golden_rmse_deg"] = float(gst["rmse_deg"][0]) if gst["n"] else None
        r["elapsed_s"]["golden"] = time.perf_counter() - t4
    bar.close()
    return r


class _Stages:
    """Progress of one run on stderr: a bar over its stages, and for a cycle-accurate
    backend the estimated simulation time (:data:`CYCLES_PER_S`)."""

    def __init__(self, run: TacanRunConfig, enabled: bool):
        self.bar = None
        import sys
        if not enabled or not sys.stderr.isatty():     # a bar on a terminal, not in logs
            return
        import sys
        from tqdm import tqdm
        n = 3 + (run.recheck is not None) + (run.compare is not None)
        self.bar = tqdm(total=n, desc="tacan", file=sys.stderr, leave=False,
                        bar_format="{desc}: {n_fmt}/{total_fmt} stages [{elapsed}] {postfix}")
        if run.backend in CYCLES_PER_S:
            c = run.signal.duration_s * run.signal.fs_hz
            print(f"{run.backend}: {c:,.0f} cycles, about {c / CYCLES_PER_S[run.backend]:.0f} s",
                  file=sys.stderr)
        self.started = False

    def stage(self, name: str) -> None:
        if self.bar is not None:
            if self.started:
                self.bar.update()
            self.started = True
            self.bar.set_postfix_str(name)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.update()
            self.bar.close()


def _ranges(fo: FrontendOutput, track: BearingTrack, adc_clipped: int) -> dict:
    """Range log of the run (Fixed-Point Designer style): per signal the smallest and largest
    value seen against its word's range, and its overflow/saturation count. Front-end
    signals (``fe.*``, as fractions of the word's full scale, LSBs in ``min_lsb``/``max_lsb``)
    with the bit-exact model backend; the fixed-point DSP's formats (``dsp.*``, real units,
    pre-saturation values)."""
    out = {}
    for name, v in (fo.extra.get("ranges") or {}).items():
        top = v["hi"] + 1          # full scale of the word: 2**(b-1) signed, 2**b unsigned
        out[f"fe.{name}"] = {"min": v["min"] / top, "max": v["max"] / top,
                             "lo": v["lo"] / top, "hi": v["hi"] / top,
                             "min_lsb": v["min"], "max_lsb": v["max"], "bits": v["bits"],
                             "headroom_bits": v["headroom_bits"], "unit": "FS",
                             "overflows": int(adc_clipped) if name == "adc" else 0}
    if track.state is not None:
        for name, v in track.state.kf.ranges().items():
            peak = max(abs(v["min"] or 0.0), abs(v["max"] or 0.0))
            out[f"dsp.{name}"] = {"min": v["min"], "max": v["max"], "lo": v["lo"], "hi": v["hi"],
                                  "headroom_bits": math.log2(v["hi"] / peak) if peak else None,
                                  "unit": "value", "overflows": v["saturations"]}
    return out


def recheck_cycle_accurate(run: TacanRunConfig, samples, backend: str = "auto",
                           n: int | None = None) -> dict:
    """Re-run the first ``n`` ADC samples of a model run on a cycle-accurate backend and
    compare the FIFO words and their cycles (and the overflow count) bit for bit.

    ``backend``: ``"verilator"``, ``"pysim"`` or ``"auto"`` (Verilator when installed);
    ``n`` defaults to 1,000,000 samples (50 ms) with Verilator and 40,000 with pysim.
    """
    from ..verilator import verilator_available
    if backend == "auto":
        backend = "verilator" if verilator_available() else "pysim"
    if backend not in ("pysim", "verilator"):
        raise ValueError(f"recheck backend must be auto, pysim or verilator, not {backend!r}")
    n = int(n or (1_000_000 if backend == "verilator" else 40_000))
    x = np.asarray(samples)[:n]
    t0 = time.perf_counter()
    ref_run = TacanRunConfig(**{**_fields(run), "backend": "model", "trace": None,
                                "compare": None, "recheck": None})
    a = _model(x, ref_run)
    b = FRONTENDS[backend](x, TacanRunConfig(**{**_fields(ref_run), "backend": backend}))
    same = (np.array_equal(a.words, b.words) and np.array_equal(a.cycles, b.cycles)
            and a.fifo_dropped == b.fifo_dropped)
    return {"backend": backend, "samples": int(x.size), "words": int(a.words.size),
            "same_bits": bool(same), "seconds": time.perf_counter() - t0}


def _fields(run: TacanRunConfig) -> dict:
    return {f: getattr(run, f) for f in run.__dataclass_fields__}


def frontend_output(run: TacanRunConfig) -> tuple[FrontendOutput, BearingTrack]:
    """The front end's output and the DSP's track for ``run`` (for tests and studies)."""
    s = generate(run.signal)
    fo = FRONTENDS[run.backend](s.samples, run)
    return fo, run_dsp(fo, run)
