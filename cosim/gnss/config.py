"""What one GNSS run is: :class:`GnssRunConfig` (the tracker, the backend, the DSP's FIFO
service, acquisition and scoring), :class:`DynamicsChoice` (the line-of-sight dynamics by
name), the named :data:`SCENARIOS` of the command line, every field checked when it is built,
and :func:`check_run_size` (a run the machine cannot hold or simulate in time is refused
before any work).

The run itself is :func:`cosim.gnss.run.run_gnss`; acquisition, hand-over and the closed
tracking loop are :mod:`cosim.gnss.tracking`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from dsp.gnss.ca_code import CODE_PERIOD_S
from dsp.gnss.trackers import tracker_names

from ..core.validate import check_budget, check_float, check_int
from .signal import GnssSignalConfig

__all__ = ["GnssRunConfig", "DynamicsChoice", "BACKENDS", "DSP_MODES", "SCENARIOS", "DYNAMICS",
           "WORD_BITS", "check_run_size", "run_memory_bytes", "JERK_DEFAULTS",
           "CONTROL_LATENCY_CYCLES", "TRACKER_RUN_OPTIONS", "frequency_plan_warning",
           "CODE_DEAD_ZONE_WARN_M"]

BACKENDS = ("golden", "model", "pysim", "verilator")
DSP_MODES = ("float", "fixed")
DYNAMICS = ("static", "aukf-patent", "aukf-patent-jerk", "aukf-patent-process")
#: Simulation speed of the cycle-accurate backends (cycles/s, one channel, this machine's
#: order of magnitude; the longest run started is :data:`cosim.core.validate.MAX_RUN_S`).
CYCLES_PER_S = {"pysim": 2e3, "verilator": 2e6}
#: NCO word width the trackers write (dsp.gnss.loops_fixed.WORD_BITS).
WORD_BITS = 32


#: Largest code-phase dead zone (m of pseudorange, :func:`frequency_plan_warning`) a sample
#: rate may leave without a warning: about the code loop's own noise at a strong signal
#: (45 dB-Hz, DLL Bn 1 Hz, half-chip spacing: 0.003 chip, 0.8 m).
CODE_DEAD_ZONE_WARN_M = 1.0


def frequency_plan_warning(fs_hz: float) -> str | None:
    """One line (for :func:`cosim.core.validate.warn`) when the sample rate ``fs_hz`` leaves
    the code loop a dead zone wider than :data:`CODE_DEAD_ZONE_WARN_M`
    (:func:`hdl.gnss.params.code_phase_step_chips`: a rate commensurate with the 1.023 MHz
    chip rate, such as 16.368 MS/s = 16 samples per chip), else None. A warning, not a
    refusal: a recording at such a rate is still tracked, and a code Doppler sweeps the
    samples across the chip (the dead zone holds where the code Doppler is near zero)."""
    from dsp.gnss.ca_code import CHIP_RATE_HZ
    from dsp.gnss.ephemeris import C_LIGHT
    from hdl.gnss.params import DEFAULT_FS_HZ, code_phase_step_chips
    step = code_phase_step_chips(fs_hz)
    metres = step * C_LIGHT / CHIP_RATE_HZ
    if metres <= CODE_DEAD_ZONE_WARN_M:
        return None
    k = round(1 / step)
    q = round(k * CHIP_RATE_HZ / fs_hz)
    ratio = f"{k}" if q == 1 else f"{k}/{q}"
    return (f"--fs-hz {fs_hz / 1e6:g} MS/s = {ratio} x 1.023 MHz puts the samples at only "
            f"{k} offsets within a chip: without code Doppler the code loop has a dead zone "
            f"of 1/{k} chip ({metres:.1f} m); a rate incommensurate with the chip rate, such "
            f"as the default {DEFAULT_FS_HZ / 1e6:g} MS/s "
            f"(1/{round(1 / code_phase_step_chips(DEFAULT_FS_HZ))} chip), has none")


#: The jerk segment of ``--dynamics aukf-patent-jerk`` when its options are not given.
JERK_DEFAULTS = {"jerk_g_per_s": 5.0, "jerk_start_s": 2.0, "jerk_duration_s": 2.0}
#: Cycles from the DSP issuing a register write to the register holding it, not given.
CONTROL_LATENCY_CYCLES = 40


def _flag(name: str) -> str:
    """The command-line flag of a field named in a refusal (its kebab-case name)."""
    return "--" + name.replace("_", "-")


#: Named scenarios of ``python -m cosim gnss --scenario NAME``: the options each sets (an
#: option given on the command line wins) and, under ``"tracker"``, what the patent fixes
#: that the trackers take as their defaults (written into the run's JSON).
SCENARIOS = {
    "aukf-patent": {
        "help": "the AUKF patent's scenario: the x0 dynamics (1000 m/s, 1 g), "
                "32 dB-Hz, T = 1 ms",
        "options": {"cn0_dbhz": 32.0, "dynamics": "aukf-patent"},
        # the tracker started on the patent's x0 Doppler rate (w1 / 2 pi)
        "run": {"handover_doppler_rate_hz_s": 323.356 / (2 * math.pi)},
        "tracker": {"x0": [0.0, 32995.519, 323.356, 0.0], "T_s": 1e-3,
                    "P0": "diag(1e-3) (w0 widened to the hand-over Doppler's sigma)",
                    "epsilon": 1.027, "kappa": 0.0, "beta": 2.0, "q0": 5.0,
                    "R": "1/(2 T C/N0) (--r-mode cn0) or 1e-9 (--r-mode seed)"},
    },
}


@dataclass(frozen=True)
class DynamicsChoice:
    """The line-of-sight dynamics of a run, by name (:mod:`cosim.gnss.dynamics`).

    Parameters
    ----------
    dynamics : str
        ``static`` (the signal's own profile, constant range by default), ``aukf-patent`` (the
        AUKF patent's initial dynamics, 1000 m/s and 1 g, deterministic), ``aukf-patent-jerk`` (that
        plus a constant jerk segment), ``aukf-patent-process`` (the patent's Singer jerk process,
        q = 5).
    jerk_g_per_s, jerk_start_s, jerk_duration_s : float or None
        The jerk segment of ``aukf-patent-jerk`` (None: :data:`JERK_DEFAULTS`); refused with
        any other dynamics, which have no jerk segment.
    """

    dynamics: str = field(default="static", metadata={
        "help": "line-of-sight dynamics: static, aukf-patent (1000 m/s, 1 g), aukf-patent-jerk "
                "(plus a jerk segment), aukf-patent-process (Singer jerk process, q 5); default static",
        "choices": DYNAMICS, "case": "lower"})
    jerk_g_per_s: float | None = field(default=None, metadata={
        "help": "jerk of the aukf-patent-jerk segment (g/s; default 5)"})
    jerk_start_s: float | None = field(default=None, metadata={
        "help": "start of the aukf-patent-jerk segment (s from the record's first sample, "
                "acquisition included; default 2)"})
    jerk_duration_s: float | None = field(default=None, metadata={
        "help": "length of the aukf-patent-jerk segment (s; default 2)"})

    def __post_init__(self):
        if self.dynamics not in DYNAMICS:
            raise ValueError(f"dynamics must be one of {', '.join(DYNAMICS)}, not "
                             f"{self.dynamics!r}")
        given = [k for k in JERK_DEFAULTS if getattr(self, k) is not None]
        if given and self.dynamics != "aukf-patent-jerk":
            raise ValueError(f"{', '.join(_flag(k) for k in given)} "
                             f"{'sets' if len(given) == 1 else 'set'} the jerk segment of "
                             f"--dynamics aukf-patent-jerk; --dynamics {self.dynamics} has "
                             f"none (the option would change nothing)")
        check_float("--jerk-g-per-s", self.jerk("jerk_g_per_s"), unit="g/s")
        check_float("--jerk-start-s", self.jerk("jerk_start_s"), 0.0, unit="s")
        check_float("--jerk-duration-s", self.jerk("jerk_duration_s"), 0.0, lo_open=True,
                    unit="s")

    def jerk(self, name: str) -> float:
        """The jerk segment's ``name`` (given, or its :data:`JERK_DEFAULTS` value)."""
        v = getattr(self, name)
        return JERK_DEFAULTS[name] if v is None else v

    def check_record(self, record_s: float) -> None:
        """Refuse a jerk segment that starts after a record of ``record_s`` seconds ends
        (the longest the run generates: the acquisition's span and the tracking)."""
        if self.dynamics == "aukf-patent-jerk" and self.jerk("jerk_start_s") >= record_s:
            given = "" if self.jerk_start_s is not None else " (its default)"
            raise ValueError(f"--jerk-start-s {self.jerk('jerk_start_s'):g} s{given} starts "
                             f"after the record ends ({record_s:g} s: --duration-s and the "
                             f"acquisition): the jerk segment would change nothing; start it "
                             f"earlier or lengthen --duration-s")

    def apply(self, sig: GnssSignalConfig) -> GnssSignalConfig:
        from .dynamics import aukf_patent_dynamics
        if self.dynamics == "static":
            return sig
        if self.dynamics == "aukf-patent":
            return sig.replace(dynamics=aukf_patent_dynamics(q=0))
        if self.dynamics == "aukf-patent-process":
            return sig.replace(dynamics=aukf_patent_dynamics(q=5.0))
        return sig.replace(dynamics=aukf_patent_dynamics(
            q=0, jerk_g_per_s=self.jerk("jerk_g_per_s"), jerk_start_s=self.jerk("jerk_start_s"),
            jerk_duration_s=self.jerk("jerk_duration_s")))


@dataclass(frozen=True)
class GnssRunConfig:
    """How one GNSS run acquires, tracks and is scored (the scenario is a
    :class:`~cosim.gnss.signal.GnssSignalConfig`).

    Parameters
    ----------
    tracker : str
        A tracker registered in :mod:`dsp.gnss.trackers`.
    bn_hz, dll_bn_hz, r_mode : float, float, str or None
        Carrier and code loop noise bandwidths (Hz) and the measurement noise of the AUKF
        patent's trackers, for the trackers that take them
        (:func:`dsp.gnss.trackers.tracker_options`; given to another tracker: refused);
        None: the tracker's own default.
    backend : str
        One of :data:`BACKENDS`.
    dsp : str
        ``float`` or ``fixed`` arithmetic of the tracker.
    control_latency_cycles : int or None
        Cycles from the DSP issuing a register write to the register holding it (HDL
        backends; None: :data:`CONTROL_LATENCY_CYCLES`; refused on ``golden``).
    compute_cycles : int
        Cycles from the end of the DSP's read window to its writes.
    service_period_us : float
        The DSP's FIFO service period (us).
    service_latency_cycles, service_batch_words : int
        The rest of the service (:class:`cosim.core.link.DspServiceConfig`, 4 cycles per word).
    settle_s : float
        Records before this time are not scored.
    acq_coherent_ms, acq_noncoherent : int or None
        A fixed acquisition dwell of ``acq_coherent_ms`` ms coherent x ``acq_noncoherent``
        sums (both or neither); None: the sequential search whose dwell extends
        (:data:`dsp.gnss.dwell.DEFAULT_SCHEDULE`).
    acq_pfa : float
        False-alarm probability of the whole acquisition search.
    acq_limit_ms : int
        Signal the search may consume (ms).
    acq_max_doppler_hz : float
        Doppler searched (+- Hz).
    refine_ms : int
        Shortest Doppler and code-phase refinement after the detection (ms; at least 20
        coherent lengths of the detecting dwell, up to 200 ms:
        :func:`cosim.gnss.handover.refine_length_ms`).
    compare : str or None
        ``golden``: also run the golden chain (float) and report the differences (not on
        ``backend="golden"``, which is that chain).
    hdl_changes : tuple of (name, value)
        Overrides of :class:`hdl.gnss.params.GnssChannelParams`.
    block_samples : int
        Samples generated and fed per block.
    """

    tracker: str = field(default="pll3", metadata={
        "help": "tracker (dsp.gnss.trackers): " + ", ".join(tracker_names()),
        "choices": tracker_names(), "case": "lower"})
    bn_hz: float | None = field(default=None, metadata={
        "help": "carrier loop noise bandwidth (Hz) of the PLL trackers (default 15)"})
    dll_bn_hz: float | None = field(default=None, metadata={
        "help": "code loop noise bandwidth (Hz; default 1)"})
    backend: str = field(default="model", metadata={
        "help": "channel: golden (float correlators, no HDL), model (bit-exact), pysim "
                "(Amaranth, ~2k cycles/s: a few ms), verilator",
        "choices": BACKENDS, "case": "lower"})
    dsp: str = field(default="fixed", metadata={"help": "arithmetic of the tracker",
                                                "choices": DSP_MODES, "case": "lower"})
    control_latency_cycles: int | None = field(default=None, metadata={
        "help": "cycles from the DSP issuing a register write to the register holding it "
                f"(HDL backends; default {CONTROL_LATENCY_CYCLES})"})
    compute_cycles: int = field(default=200, metadata={
        "help": "DSP processing cycles from its read window to its writes"})
    service_period_us: float = field(default=500.0, metadata={
        "help": "DSP FIFO service period (us; under a code period less the DSP's delays, so "
                "a record's words reach the channel before its next dump)"})
    service_latency_cycles: int = field(default=50, metadata={
        "help": "interrupt latency before the DSP reads (cycles)"})
    service_batch_words: int = field(default=16, metadata={
        "help": "FIFO words the DSP reads per service at most"})
    settle_s: float = field(default=0.5, metadata={
        "help": "records before this time (s) are not scored (the 3rd-order loop's pull-in "
                "of the unknown Doppler rate rings for ~0.5-0.8 s at Bn 15 Hz)"})
    acq_coherent_ms: int | None = field(default=None, metadata={
        "help": "acquisition: coherent integration (whole ms, 1..20; with --noncoherent: a "
                "fixed dwell; default: the sequential search, 1 to 20 ms as it extends)"})
    acq_noncoherent: int | None = field(default=None, metadata={
        "help": "acquisition: non-coherent sums of the fixed dwell (>= 1; with "
                "--coherent-ms)"})
    acq_pfa: float = field(default=1e-3, metadata={
        "help": "acquisition: false-alarm probability of the whole search (an absent "
                "PRN reported), held over every dwell and look"})
    acq_limit_ms: int = field(default=500, metadata={
        "help": "acquisition: signal the search may consume (ms)"})
    acq_max_doppler_hz: float = field(default=7000.0, metadata={
        "help": "acquisition: Doppler searched (+- Hz)"})
    refine_ms: int = field(default=20, metadata={
        "help": "shortest Doppler / code-phase refinement after the detection (ms)"})
    handover_doppler_sigma_hz: float = field(default=3.0, metadata={
        "help": "1-sigma error of the refined hand-over Doppler told to the tracker (Hz)"})
    r_mode: str | None = field(default=None, metadata={
        "help": "measurement noise R of the AUKF patent's trackers (aukf, ukf): cn0 = 1/(2 T C/N0) "
                "of the nominal C/N0 (default), seed = the patent's 1e-9",
        "choices": ("cn0", "seed"), "case": "lower"})
    handover_doppler_rate_hz_s: float = field(default=0.0, metadata={
        "help": "Doppler rate the tracker starts on (Hz/s; acquisition does not measure it; "
                "--scenario aukf-patent: the patent's x0, 51.464 Hz/s)"})
    compare: str | None = field(default=None, metadata={
        "help": "also run the golden chain (float) and report the differences",
        "choices": ("golden",), "case": "lower"})
    hdl_changes: tuple = ()
    block_samples: int = 1 << 17

    def __post_init__(self):
        if self.tracker not in tracker_names():
            raise ValueError(f"tracker must be one of {', '.join(tracker_names())}, not "
                             f"{self.tracker!r}")
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, not "
                             f"{self.backend!r}")
        if self.dsp not in DSP_MODES:
            raise ValueError(f"dsp must be float or fixed, not {self.dsp!r}")
        if self.r_mode not in (None, "cn0", "seed"):
            raise ValueError(f"--r-mode must be cn0 or seed, not {self.r_mode!r}")
        if self.compare not in (None, "golden"):
            raise ValueError(f"compare must be None or 'golden', not {self.compare!r}")
        if self.bn_hz is not None:
            check_float("--bn-hz", self.bn_hz, 0.0, 100.0, lo_open=True, unit="Hz")
        if self.dll_bn_hz is not None:
            check_float("--dll-bn-hz", self.dll_bn_hz, 0.0, 20.0, lo_open=True, unit="Hz")
        self.check_applies()
        check_int("--latency", self.latency_cycles, 0)
        check_int("compute_cycles", self.compute_cycles, 0)
        check_float("service_period_us", self.service_period_us, 0.0, 900.0, lo_open=True,
                    unit="us")
        check_int("service_latency_cycles", self.service_latency_cycles, 0)
        check_int("service_batch_words", self.service_batch_words, 1)
        check_float("settle_s", self.settle_s, 0.0, unit="s")
        self.acq_schedule()
        check_float("--pfa", self.acq_pfa, 0.0, 1.0, lo_open=True, hi_open=True)
        check_float("acq_max_doppler_hz", self.acq_max_doppler_hz, 0.0, 50e3, lo_open=True,
                    unit="Hz")
        check_int("refine_ms", self.refine_ms, 2, 200)
        check_float("handover_doppler_sigma_hz", self.handover_doppler_sigma_hz, 0.0, 250.0,
                    lo_open=True, unit="Hz")
        check_float("handover_doppler_rate_hz_s", self.handover_doppler_rate_hz_s, -1e4, 1e4,
                    unit="Hz/s")
        check_int("block_samples", self.block_samples, 1024)
        for kv in self.hdl_changes:
            if not (isinstance(kv, tuple) and len(kv) == 2 and isinstance(kv[0], str)):
                raise ValueError(f"hdl_changes are (name, value) pairs, not {kv!r}")

    def check_applies(self) -> None:
        """Refuse an option given for a run it cannot change (the one rule set of what
        applies where): a tracker option the tracker does not take
        (:func:`dsp.gnss.trackers.tracker_options`), the control latency on the golden
        chain (no register bus), the golden comparison of the golden chain itself."""
        from dsp.gnss.trackers import tracker_names as names, tracker_options
        takes = tracker_options(self.tracker)
        for k in TRACKER_RUN_OPTIONS:
            if getattr(self, k) is not None and k not in takes:
                who = [t for t in names() if k in tracker_options(t)]
                raise ValueError(f"{_flag(k)} applies to the trackers {', '.join(who)}; "
                                 f"--tracker {self.tracker} has no such setting (the option "
                                 f"would change nothing)")
        if self.backend == "golden" and self.control_latency_cycles is not None:
            raise ValueError("--latency is the HDL channel's register-write latency; "
                             "--backend golden has no register bus (the option would change "
                             "nothing): use --backend model, pysim or verilator")
        if self.backend == "golden" and self.compare == "golden":
            raise ValueError("--compare golden compares the channel with the golden chain; "
                             "--backend golden is that chain (it would compare it with "
                             "itself): use --backend model, pysim or verilator")

    @property
    def latency_cycles(self) -> int:
        """The control latency in force (:data:`CONTROL_LATENCY_CYCLES` if not given)."""
        return CONTROL_LATENCY_CYCLES if self.control_latency_cycles is None \
            else self.control_latency_cycles

    def tracker_kwargs(self) -> dict:
        """The run's options the tracker takes (``bn_hz``, ``dll_bn_hz``, ``r_mode``), those
        given; the tracker's own defaults for the rest."""
        return {k: getattr(self, k) for k in TRACKER_RUN_OPTIONS if getattr(self, k) is not None}

    def tracker_setting(self, name: str):
        """The value of tracker option ``name`` in force (given or the tracker's default),
        None if the tracker has no such setting (the JSON's ``bn_hz`` of an AUKF)."""
        from dsp.gnss.trackers import tracker_options
        takes = tracker_options(self.tracker)
        if name not in takes:
            return None
        v = getattr(self, name)
        return takes[name] if v is None else v

    def check_loop_timing(self, fs_hz: float) -> None:
        """Refuse an HDL run whose DSP loop cannot answer a record before the channel's next
        dump: the trackers close the loop with one epoch of latency
        (``TrackerContext.latency_epochs = 1``), so the worst case (a record dumped just
        after a service: the service period, its interrupt latency, reading a batch, the
        compute and the control latency) must stay under one code period."""
        if self.backend == "golden":
            return
        svc = self.service(fs_hz)
        rest = (svc.period_cycles + svc.latency_cycles + svc.cycles_per_word * svc.batch_words
                + self.compute_cycles)
        epoch = int(round(fs_hz * CODE_PERIOD_S))
        if rest + self.latency_cycles >= epoch:
            raise ValueError(f"--latency {self.latency_cycles} cycles: the DSP's writes would "
                             f"reach the channel up to {rest + self.latency_cycles:,} cycles "
                             f"after a record's dump, later than the next dump ({epoch:,} "
                             f"cycles, one code period at {fs_hz / 1e6:g} MS/s) the trackers' "
                             f"one-epoch loop needs them by: at most {max(0, epoch - 1 - rest)} "
                             f"cycles here")

    def acq_schedule(self) -> tuple:
        """The acquisition's dwells (:mod:`dsp.gnss.dwell`) within ``acq_limit_ms``
        (ValueError naming the option if refused)."""
        from dsp.gnss.dwell import DEFAULT_SCHEDULE, fixed_schedule, schedule_within
        t, k = self.acq_coherent_ms, self.acq_noncoherent
        if (t is None) != (k is None):
            raise ValueError("--coherent-ms and --noncoherent go together (a fixed dwell of "
                             "T ms x K sums): give both, or neither for the search that "
                             "extends its dwell")
        if t is None:
            return schedule_within(DEFAULT_SCHEDULE, self.acq_limit_ms)
        d = fixed_schedule(t, k)
        if d[0].span_ms() > self.acq_limit_ms:
            raise ValueError(f"--coherent-ms {t} x --noncoherent {k} needs "
                             f"{d[0].span_ms()} ms of signal (bit-edge offsets included): "
                             f"more than --acq-limit-ms {self.acq_limit_ms}")
        return schedule_within(d, self.acq_limit_ms)

    def service(self, fs_hz: float):
        """The DSP's FIFO service at the channel clock ``fs_hz``."""
        from ..core.link import DspServiceConfig
        return DspServiceConfig(period_cycles=max(1, round(self.service_period_us * 1e-6 * fs_hz)),
                                latency_cycles=self.service_latency_cycles,
                                batch_words=self.service_batch_words, cycles_per_word=4)

    def hdl_params(self, sig: GnssSignalConfig):
        """The channel for the scenario: its rate, digital IF, ADC and PRN."""
        from hdl.gnss.params import GnssChannelParams
        p = GnssChannelParams(fs_hz=sig.fs_hz, if_hz=sig.digital_if_hz, adc_bits=sig.adc_bits,
                              prn=sig.prn, **dict(self.hdl_changes))
        if p.carr_phase_bits != WORD_BITS or p.code_phase_bits != WORD_BITS:
            raise ValueError(f"the trackers write {WORD_BITS}-bit NCO words: carr_phase_bits "
                             f"and code_phase_bits must be {WORD_BITS}, not "
                             f"{p.carr_phase_bits} and {p.code_phase_bits}")
        return p


#: The run options a tracker may take (:func:`dsp.gnss.trackers.tracker_options`).
TRACKER_RUN_OPTIONS = ("bn_hz", "dll_bn_hz", "r_mode")


#: Memory of a run (bytes), as :func:`run_memory_bytes` adds it up: the process itself
#: (interpreter, numpy, scipy, numba and the compiled kernels: 0.24-0.33 GB resident after
#: a 3 s run), per block sample (the generator's float64 temporaries, 72 B a sample in
#: tracemalloc, the stream's window, the codes and the channel's ADC words), the channel
#: replay of :func:`cosim.gnss.tracking.record_boundaries` (bit-exact model on
#: ``REPLAY_BLOCK`` zero samples, 25 B a sample), and per tracked epoch (the DSP's records,
#: the tracker's history, the HDL backends' writes and bus writes, the scoring's arrays, the
#: INS solution). Measured: the tracking alone grows by 0.37 kB an epoch on the golden
#: chain and 1.4 kB on the model (tracemalloc over two durations,
#: tests/cosim/gnss/test_streaming.py); the INS paper's 150 s peaks at 0.49 GB resident
#: on the golden chain and 0.66 GB on the model, 1.6 and 2.2 kB an epoch above the process
#: (these estimates: 0.69 and 0.87 GiB).
PROCESS_BYTES = 400 * 2 ** 20
BLOCK_BYTES_PER_SAMPLE = 128
REPLAY_BLOCK = 1 << 20
REPLAY_BYTES_PER_SAMPLE = 32
EPOCH_BYTES = {"golden": 2048, "model": 3072, "pysim": 3072, "verilator": 3072}


def run_memory_bytes(sig: GnssSignalConfig, run: GnssRunConfig) -> float:
    """Estimated peak memory (bytes) of :func:`cosim.gnss.run.run_gnss` on ``sig`` and
    ``run``: every backend streams the record in blocks of ``run.block_samples``, so only
    the per-epoch outputs grow with the duration (constants above); ``compare="golden"``
    adds the golden chain's run after the backend's, its epochs held beside the first."""
    epochs = sig.duration_s / CODE_PERIOD_S + 2
    need = PROCESS_BYTES + BLOCK_BYTES_PER_SAMPLE * min(run.block_samples, sig.n_samples)
    need += EPOCH_BYTES[run.backend] * epochs
    if run.backend != "golden":
        need += REPLAY_BYTES_PER_SAMPLE * min(REPLAY_BLOCK, sig.n_samples)
    if run.compare == "golden":
        need += EPOCH_BYTES["golden"] * epochs
    return need


def check_run_size(sig: GnssSignalConfig, run: GnssRunConfig) -> None:
    """Refuse, before work, a run whose per-epoch records and block buffers
    (:func:`run_memory_bytes`) the machine cannot hold, or a cycle-accurate run that would
    take hours (:data:`CYCLES_PER_S`), by :func:`cosim.core.validate.check_budget` (the
    message names the option)."""
    n = sig.n_samples
    check_budget(f"{sig.duration_s:g} s of tracking ({sig.n_epochs:,} epochs of records)",
                 "--duration-s", memory_bytes=run_memory_bytes(sig, run))
    if run.backend in CYCLES_PER_S:
        rate = CYCLES_PER_S[run.backend]
        check_budget(f"{n:,} cycles on the {run.backend} backend (about {rate:.0e} "
                     f"cycles/s; --duration-s {sig.duration_s:g})", "--duration-s",
                     seconds=n / rate)
