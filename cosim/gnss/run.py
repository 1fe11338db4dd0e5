"""End-to-end GNSS run: IF signal -> acquisition -> tracking channel (a backend) -> FIFO ->
tracker -> NCO words back over the control path, closed loop.

1. *Acquisition* (:func:`dsp.gnss.acquisition.acquire`, FFT code-phase search) on a snapshot
   of the first ``acq_ms`` ms of the record, then :func:`~dsp.gnss.acquisition.refine_doppler`
   (squared prompt sums over ``refine_ms`` ms) so the PLL starts within a few Hz.
2. *Hand-over*: the carrier word (IF + Doppler), the code word (chip rate + Doppler / 1540)
   and a code slew (samples of hold that put the prompt on the acquired code phase) are
   written at reset; they are active from the first dump boundary (1 ms). The first
   :data:`SKIP_RECORDS` records (the reset epoch and the epoch holding the slew) are not
   tracked. The acquisition is thus treated as if its snapshot had been taken just before
   tracking starts (its own duration is not simulated).
3. *Tracking* on the streaming pipeline (:class:`cosim.pipeline.Pipeline`): the channel
   session (:func:`cosim.gnss.session.open_gnss`), the DSP reading the FIFO every
   ``service_period_us``; every record is reassembled (:func:`dsp.records.receive_records`)
   and given to the tracker (:func:`dsp.gnss.trackers.make_tracker`, float or fixed), whose
   carrier and code words are written back, ``control_latency_cycles`` after the DSP issues
   them (``compute_cycles`` after its read window). A write reaches the shadow registers
   well within the epoch, so it is active from the next dump boundary: the loop's latency
   is one epoch (``TrackerContext.latency_epochs = 1``).

Backends: ``model`` (bit-exact channel + FIFO), ``pysim`` (Amaranth), ``verilator`` give the
same bits (the test checks it); ``golden`` is the float64 correlator chain
(:class:`dsp.gnss.correlator.GoldenCorrelator`, no HDL, no FIFO) on the ADC codes, with the
same hand-over, the same one-epoch loop latency and the tracker in the arithmetic asked for.
The HDL takes the ADC's two's-complement word ``q`` (the signal's odd codes ``2 q + 1``,
:mod:`cosim.gnss.signal`); the golden chain takes the codes.

Scoring (per record, against the generator's truth at the record's dump boundary, after
``settle_s``): carrier phase error = signal minus NCO phase (cycles), unwrapped over the
records; ``cycle_slips`` = changes of its nearest Costas lock point (half cycles,
:func:`cosim.gnss.loopsim.cycle_slips`); ``phase_rmse_deg`` = rms of the error about its lock
point; ``doppler_rmse_hz`` = the tracker's Doppler minus the true one; ``code_rmse_chips`` =
true code phase minus the prompt's; ``lock_fraction`` = share of 100-record windows in
phase lock (narrowband PLI >= 0.8, :class:`dsp.gnss.loops.LockDetector`); ``cn0_est_dbhz``
(M2M4 on the prompts).
"""
from __future__ import annotations

import hashlib
import inspect
import math
from dataclasses import dataclass, field, replace

import numpy as np

from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, CODE_PERIOD_S, L1_HZ
from dsp.gnss.trackers import tracker_names

from ..validate import check_float, check_int, check_memory
from .signal import GnssSignalConfig, GnssSignalGenerator

__all__ = ["GnssRunConfig", "DynamicsChoice", "run_gnss", "closed_loop", "ClosedLoop",
           "handover_writes", "adc_words", "BACKENDS", "DSP_MODES", "SCENARIOS", "tracker_report",
           "SKIP_RECORDS", "DYNAMICS"]

BACKENDS = ("golden", "model", "pysim", "verilator")
DSP_MODES = ("float", "fixed")
DYNAMICS = ("static", "seed002", "seed002-jerk", "seed002-process")
#: Records not tracked after reset: the reset epoch, and the epoch holding the code slew.
SKIP_RECORDS = 2
#: Simulation speed of the cycle-accurate backends (cycles/s, one channel, this machine's
#: order of magnitude) and the longest run started on them (s of wall time).
CYCLES_PER_S = {"pysim": 2e3, "verilator": 2e6}
MAX_WALL_S = 3600.0
#: NCO word width the trackers write (dsp.gnss.loops_fixed.WORD_BITS).
WORD_BITS = 32


#: Named scenarios of ``python -m cosim gnss --scenario NAME``: the options each sets (an
#: option given on the command line wins) and, under ``"tracker"``, what the seed fixes
#: that the trackers take as their defaults (written into the run's JSON).
SCENARIOS = {
    "seed002": {
        "help": "seed 002 (RECEIVERS.md section 1): the x0 dynamics (1000 m/s, 1 g), "
                "32 dB-Hz, T = 1 ms",
        "options": {"cn0_dbhz": 32.0, "dynamics": "seed002"},
        # an acquisition for 32 dB-Hz (the default 1 ms x 5 and 1 ms x 20 miss it):
        # 2 ms coherent (125 Hz bins) x 20 non-coherent, 40 ms Doppler refinement
        # and the tracker started on the seed's x0 Doppler rate (w1 / 2 pi)
        "run": {"acq_coherent_ms": 2, "acq_noncoherent": 20, "acq_bin_hz": 125.0,
                "refine_ms": 40, "handover_doppler_rate_hz_s": 323.356 / (2 * math.pi)},
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
        ``static`` (the signal's own profile, constant range by default), ``seed002`` (the
        seed-002 initial dynamics, 1000 m/s and 1 g, deterministic), ``seed002-jerk`` (that
        plus a constant jerk segment), ``seed002-process`` (the seed-002 Singer jerk process,
        q = 5).
    jerk_g_per_s, jerk_start_s, jerk_duration_s : float
        The jerk segment of ``seed002-jerk``.
    """

    dynamics: str = field(default="static", metadata={
        "help": "line-of-sight dynamics: static, seed002 (1000 m/s, 1 g), seed002-jerk "
                "(plus a jerk segment), seed002-process (Singer jerk process, q 5); default static",
        "choices": DYNAMICS, "case": "lower"})
    jerk_g_per_s: float = field(default=5.0, metadata={
        "help": "jerk of the seed002-jerk segment (g/s)"})
    jerk_start_s: float = field(default=2.0, metadata={
        "help": "start of the seed002-jerk segment (s)"})
    jerk_duration_s: float = field(default=2.0, metadata={
        "help": "length of the seed002-jerk segment (s)"})

    def __post_init__(self):
        if self.dynamics not in DYNAMICS:
            raise ValueError(f"dynamics must be one of {', '.join(DYNAMICS)}, not "
                             f"{self.dynamics!r}")
        check_float("jerk_g_per_s", self.jerk_g_per_s, unit="g/s")
        check_float("jerk_start_s", self.jerk_start_s, 0.0, unit="s")
        check_float("jerk_duration_s", self.jerk_duration_s, 0.0, lo_open=True, unit="s")

    def apply(self, sig: GnssSignalConfig) -> GnssSignalConfig:
        from .dynamics import seed002
        if self.dynamics == "static":
            return sig
        if self.dynamics == "seed002":
            return sig.replace(dynamics=seed002(q=0))
        if self.dynamics == "seed002-process":
            return sig.replace(dynamics=seed002(q=5.0))
        return sig.replace(dynamics=seed002(q=0, jerk_g_per_s=self.jerk_g_per_s,
                                            jerk_start_s=self.jerk_start_s,
                                            jerk_duration_s=self.jerk_duration_s))


@dataclass(frozen=True)
class GnssRunConfig:
    """How one GNSS run acquires, tracks and is scored (the scenario is a
    :class:`~cosim.gnss.signal.GnssSignalConfig`).

    Parameters
    ----------
    tracker : str
        A tracker registered in :mod:`dsp.gnss.trackers`.
    bn_hz, dll_bn_hz : float
        Carrier and code loop noise bandwidths (Hz), for trackers that take them.
    backend : str
        One of :data:`BACKENDS`.
    dsp : str
        ``float`` or ``fixed`` arithmetic of the tracker.
    control_latency_cycles : int
        Cycles from the DSP issuing a register write to the register holding it.
    compute_cycles : int
        Cycles from the end of the DSP's read window to its writes.
    service_period_us : float
        The DSP's FIFO service period (us).
    service_latency_cycles, service_batch_words : int
        The rest of the service (:class:`cosim.link.DspServiceConfig`, 4 cycles per word).
    settle_s : float
        Records before this time are not scored.
    acq_coherent_ms, acq_noncoherent, acq_bin_hz, acq_pfa, refine_ms :
        Acquisition: coherent ms, non-coherent sums, Doppler bin (Hz, <= 500 for the
        refinement), false-alarm probability, refinement length (ms).
    compare : str or None
        ``golden``: also run the golden chain (float) and report the differences.
    hdl_changes : tuple of (name, value)
        Overrides of :class:`hdl.gnss.params.GnssChannelParams`.
    block_samples : int
        Samples generated and fed per block.
    """

    tracker: str = field(default="pll3", metadata={
        "help": "tracker (dsp.gnss.trackers): " + ", ".join(tracker_names()),
        "choices": tracker_names(), "case": "lower"})
    bn_hz: float = field(default=15.0, metadata={"help": "carrier loop noise bandwidth (Hz)"})
    dll_bn_hz: float = field(default=1.0, metadata={"help": "code loop noise bandwidth (Hz)"})
    backend: str = field(default="model", metadata={
        "help": "channel: golden (float correlators, no HDL), model (bit-exact), pysim "
                "(Amaranth, ~2k cycles/s: a few ms), verilator",
        "choices": BACKENDS, "case": "lower"})
    dsp: str = field(default="fixed", metadata={"help": "arithmetic of the tracker",
                                                "choices": DSP_MODES, "case": "lower"})
    control_latency_cycles: int = field(default=40, metadata={
        "help": "cycles from the DSP issuing a register write to the register holding it"})
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
    acq_coherent_ms: int = field(default=1, metadata={"help": "acquisition coherent ms"})
    acq_noncoherent: int = field(default=5, metadata={"help": "acquisition non-coherent sums"})
    acq_bin_hz: float = field(default=250.0, metadata={
        "help": "acquisition Doppler bin (Hz, <= 500)"})
    acq_pfa: float = field(default=1e-3, metadata={"help": "acquisition false-alarm "
                                                           "probability per search"})
    refine_ms: int = field(default=20, metadata={"help": "Doppler refinement length (ms)"})
    handover_doppler_sigma_hz: float = field(default=3.0, metadata={
        "help": "1-sigma error of the refined hand-over Doppler told to the tracker (Hz)"})
    r_mode: str = field(default="cn0", metadata={
        "help": "measurement noise R of the seed-002 trackers (aukf, ukf): cn0 = 1/(2 T C/N0) "
                "of the nominal C/N0, seed = the seed's 1e-9",
        "choices": ("cn0", "seed"), "case": "lower"})
    handover_doppler_rate_hz_s: float = field(default=0.0, metadata={
        "help": "Doppler rate the tracker starts on (Hz/s; acquisition does not measure it; "
                "--scenario seed002: the seed's x0, 51.464 Hz/s)"})
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
        if self.r_mode not in ("cn0", "seed"):
            raise ValueError(f"r_mode must be cn0 or seed, not {self.r_mode!r}")
        if self.r_mode != "cn0":
            from dsp.gnss.trackers import TRACKERS
            if "r_mode" not in inspect.signature(TRACKERS[self.tracker][0]).parameters:
                raise ValueError(f"r_mode {self.r_mode} applies to the seed-002 trackers "
                                 f"(aukf, ukf), not {self.tracker}")
        if self.compare not in (None, "golden"):
            raise ValueError(f"compare must be None or 'golden', not {self.compare!r}")
        check_float("bn_hz", self.bn_hz, 0.0, 100.0, lo_open=True, unit="Hz")
        check_float("dll_bn_hz", self.dll_bn_hz, 0.0, 20.0, lo_open=True, unit="Hz")
        check_int("control_latency_cycles", self.control_latency_cycles, 0)
        check_int("compute_cycles", self.compute_cycles, 0)
        check_float("service_period_us", self.service_period_us, 0.0, 900.0, lo_open=True,
                    unit="us")
        check_int("service_latency_cycles", self.service_latency_cycles, 0)
        check_int("service_batch_words", self.service_batch_words, 1)
        check_float("settle_s", self.settle_s, 0.0, unit="s")
        check_int("acq_coherent_ms", self.acq_coherent_ms, 1, 10)
        check_int("acq_noncoherent", self.acq_noncoherent, 1, 100)
        check_float("acq_bin_hz", self.acq_bin_hz, 0.0, 500.0, lo_open=True, unit="Hz")
        check_float("acq_pfa", self.acq_pfa, 0.0, 1.0, lo_open=True, hi_open=True)
        check_int("refine_ms", self.refine_ms, 2, 200)
        check_float("handover_doppler_sigma_hz", self.handover_doppler_sigma_hz, 0.0, 250.0,
                    lo_open=True, unit="Hz")
        check_float("handover_doppler_rate_hz_s", self.handover_doppler_rate_hz_s, -1e4, 1e4,
                    unit="Hz/s")
        check_int("block_samples", self.block_samples, 1024)
        for kv in self.hdl_changes:
            if not (isinstance(kv, tuple) and len(kv) == 2 and isinstance(kv[0], str)):
                raise ValueError(f"hdl_changes are (name, value) pairs, not {kv!r}")

    def service(self, fs_hz: float):
        """The DSP's FIFO service at the channel clock ``fs_hz``."""
        from ..link import DspServiceConfig
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


# -- acquisition and hand-over ---------------------------------------------------------------
def _acquire(gen: GnssSignalGenerator, run: GnssRunConfig) -> tuple[dict, dict]:
    from dsp.gnss.acquisition import acquire, refine_doppler
    sig = gen.cfg
    n_ms = max(run.acq_coherent_ms * run.acq_noncoherent, run.refine_ms)
    N = int(round(sig.fs_hz * CODE_PERIOD_S))
    if sig.n_samples < n_ms * N:
        raise ValueError(f"duration_s {sig.duration_s:g} s is shorter than the acquisition "
                         f"snapshot ({n_ms} ms)")
    x = gen.samples(0, n_ms * N)[0].astype(np.float64)
    a = acquire(x, sig.fs_hz, sig.prn, sig.digital_if_hz, sig.spectrum_inverted,
                n_coherent=run.acq_coherent_ms, n_noncoherent=run.acq_noncoherent,
                bin_width_hz=run.acq_bin_hz, pfa=run.acq_pfa)
    truth = gen.truth_at([0.0])
    out = {"detected": bool(a.detected), "doppler_found_hz": a.doppler_hz,
           "doppler_true_hz": float(truth["doppler_hz"][0]),
           "code_phase_found_chips": a.code_phase_chips,
           "code_phase_true_chips": float(truth["code_phase_chips"][0]),
           "peak": a.peak, "threshold": a.threshold, "bin_width_hz": a.bin_width_hz}
    if not a.detected:
        raise ValueError(f"acquisition did not find PRN {sig.prn} (peak {a.peak:.1f} below the "
                         f"threshold {a.threshold:.1f} for pfa {run.acq_pfa:g}): C/N0 too low "
                         f"for a {run.acq_coherent_ms} x {run.acq_noncoherent} ms search")
    fine = refine_doppler(x, sig.fs_hz, sig.prn, sig.digital_if_hz, a.doppler_hz,
                          a.code_phase_chips, sig.spectrum_inverted, n_ms=run.refine_ms)
    out["doppler_refined_hz"] = fine
    return out, {"doppler_hz": fine, "code_phase_chips": a.code_phase_chips}


def handover_writes(p, doppler_hz: float, code_phase_chips: float, inverted: bool = False):
    """Register writes at reset (effect cycles 0, 1, 2) that start channel ``p`` on an
    acquisition: carrier word (IF + Doppler), code word (chip rate + Doppler / 1540) and
    the slew (samples of code hold) that puts the prompt on ``code_phase_chips`` (the
    received code phase at sample 0)."""
    s = -1.0 if inverted else 1.0
    cw = p.carr_word(p.if_hz + s * doppler_hz)
    kw = p.code_word(CHIP_RATE_HZ * (1 + doppler_hz / L1_HZ))
    n_code = CODE_LENGTH * p.fs_hz / CHIP_RATE_HZ
    slew = int(round((-code_phase_chips * p.fs_hz / CHIP_RATE_HZ - p.half_spacing)
                     % n_code)) % int(round(n_code))
    if slew >= 1 << p.slew_bits:
        raise ValueError(f"the code slew of {slew} samples does not fit slew_bits "
                         f"{p.slew_bits}: use slew_bits >= {slew.bit_length()}")
    return [(0, "carr_freq", cw), (1, "code_freq", kw), (2, "slew", slew)]


def _make_tracker(run: GnssRunConfig, fs_hz, if_hz, inverted, cn0_dbhz, doppler_hz: float,
                  spacing_chips: float, arith_name: str, extra: tuple | None = None):
    from dsp.gnss.loops_fixed import FLOAT, FixedArith
    from dsp.gnss.trackers import TrackerContext, TRACKERS, make_tracker
    ctx = TrackerContext(fs_hz=fs_hz, T_s=CODE_PERIOD_S, if_hz=if_hz,
                         inverted=inverted, doppler0_hz=doppler_hz,
                         doppler_rate0_hz_s=run.handover_doppler_rate_hz_s, cn0_dbhz=cn0_dbhz,
                         spacing_chips=spacing_chips, latency_epochs=1,
                         doppler0_sigma_hz=run.handover_doppler_sigma_hz)
    arith = FixedArith() if arith_name == "fixed" else FLOAT
    params = inspect.signature(TRACKERS[run.tracker][0]).parameters
    opts = {k: getattr(run, k) for k in ("bn_hz", "dll_bn_hz", "r_mode") if k in params}
    if extra is not None:       # (TrackerContext changes, tracker options) of the caller
        ctx = replace(ctx, **extra[0])
        opts.update(extra[1])
    return make_tracker(run.tracker, ctx, arith, **opts), arith


class _Tracking:
    """The DSP's side of the loop: records in, tracker, NCO words out; keeps the
    observables of every record (dump boundary sample, NCO phases, prompt, Doppler)."""

    def __init__(self, tracker, arith, p, skip):
        self.tracker, self.arith, self.p, self.skip = tracker, arith, p, skip
        self.n_seen = 0
        self.obs = []        # (n_boundary, carrier_nco_cycles, prompt_code_chips, ip, qp)
        self.doppler = []
        self.words = []

    def record(self, n_b, carr_cycles, code_chips, iq6):
        self.n_seen += 1
        if self.n_seen <= self.skip:
            return None
        out = self.tracker.step(*iq6)
        if self.arith.fixed:
            cw, kw = (int(np.asarray(v)) for v in out)
        else:       # the float tracker's frequencies as the channel's words (rounded)
            cw = self.p.carr_word(float(np.asarray(out[0])))
            kw = self.p.code_word(float(np.asarray(out[1])))
        m = (1 << WORD_BITS) - 1
        cw, kw = cw & m, kw & m
        self.obs.append((n_b, carr_cycles, code_chips, float(iq6[2]), float(iq6[3])))
        self.doppler.append(float(np.asarray(self.tracker.doppler_hz())))
        self.words.append((cw, kw))
        return cw, kw

    def digest(self) -> str:
        h = hashlib.sha256()
        h.update(np.array(self.words, np.int64).tobytes())
        h.update(np.array(self.doppler, np.float64).tobytes())
        return h.hexdigest()[:16]


class _PipelineDsp:
    """The pipeline's DSP callback: reassemble the FIFO records, track each."""

    def __init__(self, p, track: _Tracking):
        from dsp.records import RecordRxState
        self.p, self.track = p, track
        self.fifo = p.fifo
        self.rx = RecordRxState()
        self.fields = p.record.fields

    def __call__(self, call):
        from dsp.records import receive_records
        from hdl.gnss.params import ACC_FIELDS
        p, fp = self.p, self.fifo
        if not call.words.size:
            return ()
        b = receive_records(call.words, width=fp.width, record_words=fp.record_words,
                            parity=fp.parity, state=self.rx)
        out = None
        for row in b.records:
            v = 0
            for j, w in enumerate(row):
                v |= int(w) << (j * fp.width)
            d = p.record.unpack(v)
            # (the boundary sample is not in the record: _boundaries recomputes it)
            r = self.track.record(None, d["carr_phase"] / 2.0 ** p.carr_phase_bits,
                                  d["code_phase"] / 2.0 ** p.code_phase_bits,
                                  [d[k] for k in ACC_FIELDS])
            if r is not None:
                out = r
        if out is None:
            return ()
        return [("carr_freq", out[0]), ("code_freq", out[1])]


@dataclass
class ClosedLoop:
    """A closed-loop run of the channel: the DSP's record of every tracked record
    (``track``), the pipeline's result (words, writes, digest), the bus writes made and
    the record receiver's counters."""

    track: "_Tracking"
    pipeline: object
    bus_writes: list
    rx_stats: dict


def closed_loop(backend: str, p, run: GnssRunConfig, blocks, doppler_hz: float,
                code_phase_chips: float, *, inverted: bool = False,
                cn0_dbhz: float | None = None, keep_words: bool = False,
                tracker_extra: tuple | None = None) -> ClosedLoop:
    """Track on channel ``p`` (a session on ``backend``) fed ``blocks`` (iterable of ADC
    word arrays, one word per cycle), started by :func:`handover_writes`, the DSP service
    and tracker of ``run``, its writes decided on the fly."""
    from ..pipeline import Pipeline
    from .session import open_gnss
    spacing = p.el_spacing_samples * CHIP_RATE_HZ / p.fs_hz
    tracker, arith = _make_tracker(run, p.fs_hz, p.if_hz, inverted, cn0_dbhz, doppler_hz,
                                   spacing, run.dsp, tracker_extra)
    track = _Tracking(tracker, arith, p, SKIP_RECORDS)
    dsp = _PipelineDsp(p, track)
    svc = run.service(p.fs_hz)
    with open_gnss(backend, p) as fe:
        pipe = Pipeline(fe, svc, dsp, compute_cycles=run.compute_cycles,
                        control_latency_cycles=run.control_latency_cycles,
                        keep_words=keep_words)
        pipe.schedule(handover_writes(p, doppler_hz, code_phase_chips, inverted))
        for x in blocks:
            pipe.feed(np.asarray(x, np.int64))
        pipe.idle(p.latency + 8 * p.fifo.record_words + svc.period_cycles + 64)
        res = pipe.result()
        bus = list(fe.bus_writes)
    return ClosedLoop(track, res, bus, dict(dsp.rx.stats))


def adc_words(codes) -> np.ndarray:
    """The channel's ADC words ``q`` of the generator's odd codes ``2 q + 1``."""
    return (np.asarray(codes).astype(np.int64) - 1) >> 1


def _boundaries(p, bus_writes, n_records, n_total, block: int = 1 << 22):
    """Dump-boundary sample of the records ``1 .. n_records`` of the HDL channel, from the
    code NCO's words in force (replayed exactly: the code generator's epochs only depend on
    the code word, PRN-independent, and the slew)."""
    from hdl.gnss.model import GnssChannelModel
    # Run the bit-exact channel on zero samples with the same bus writes: its records come
    # at the same cycles (the code NCO does not see the samples). In blocks (a 150 s record
    # is 2.5e9 samples: one array of them would not fit), until n_records are out.
    m = GnssChannelModel(p)
    out, got, k = [], 0, 0
    while got < n_records and k < n_total:
        n = min(int(block), n_total - k)
        r = m.step(np.zeros(n, np.int64), bus_writes if k == 0 else ())
        out.append(r.cycles)
        got += r.cycles.size
        k += n
    cyc = np.concatenate(out) if out else np.zeros(0, np.int64)
    return cyc[:n_records] - p.latency


def _golden_track(gen, run, hand, arith_name, tracker_extra=None):
    from dsp.gnss.correlator import GoldenCorrelator
    sig = gen.cfg
    p = run.hdl_params(sig)
    spacing = p.el_spacing_samples * CHIP_RATE_HZ / sig.fs_hz
    tracker, arith = _make_tracker(run, sig.fs_hz, sig.digital_if_hz, sig.spectrum_inverted,
                                   sig.cn0_dbhz, hand["doppler_hz"], spacing, arith_name,
                                   tracker_extra)
    track = _Tracking(tracker, arith, p, 1)
    s = -1.0 if sig.spectrum_inverted else 1.0
    cf = sig.digital_if_hz + s * hand["doppler_hz"]
    kf = CHIP_RATE_HZ * (1 + hand["doppler_hz"] / L1_HZ)
    corr = GoldenCorrelator(sig.fs_hz, sig.prn, spacing, cf, kf,
                            code_phase_chips=hand["code_phase_chips"])
    from .signal import SampleStream
    src = SampleStream(gen, adc=True, block_samples=run.block_samples)
    pending = None
    boundaries = []
    while True:
        M = corr.samples_needed()
        x = src(corr.n_next, M)
        if len(x) < M:
            break
        d = corr.integrate(np.asarray(x, np.float64))
        if pending is not None:       # the HDL's one-epoch loop latency
            corr.set_frequencies(*pending)
            pending = None
        n_b = corr.n_next
        r = track.record(n_b, d.carrier_phase_dump, d.code_phase_dump,
                         [d.ie, d.qe, d.ip, d.qp, d.il, d.ql])
        if r is not None:
            boundaries.append(n_b)
            pending = (r[0] * sig.fs_hz / 2.0 ** WORD_BITS, r[1] * sig.fs_hz / 2.0 ** WORD_BITS)
    return track, np.array(boundaries, np.int64)


# -- scoring ---------------------------------------------------------------------------------
def _score(gen, track: _Tracking, n_b, settle_s):
    from dsp.gnss.cn0 import cn0_m2m4
    from dsp.gnss.loops import LockDetector
    from .loopsim import cycle_slips
    sig = gen.cfg
    obs = np.array([o[1:] for o in track.obs], np.float64).reshape(-1, 4)
    k = min(len(n_b), len(obs))
    n_b, obs = np.asarray(n_b[:k], np.int64), obs[:k]
    dop = np.array(track.doppler[:k])
    t = n_b / sig.fs_hz
    tr = gen.truth_at(t)
    s = -1.0 if sig.spectrum_inverted else 1.0
    f_ratio = sig.digital_if_hz / sig.fs_hz
    if_ph = np.mod(n_b.astype(np.float64) * f_ratio, 1.0)
    e = if_ph + s * tr["carrier_phase_cycles"] - obs[:, 0]
    e = np.unwrap(2 * np.pi * e) / (2 * np.pi)
    code = np.mod(tr["code_phase_chips"] - obs[:, 1] + CODE_LENGTH / 2, CODE_LENGTH) \
        - CODE_LENGTH / 2
    keep = t >= settle_s
    out = {"n_records": int(k), "n_scored": int(keep.sum())}
    if not keep.any():
        raise ValueError(f"no record after settle_s = {settle_s:g} s: lengthen duration_s "
                         f"({sig.duration_s:g} s) or shorten settle_s")
    es = e[keep]
    resid = es - 0.5 * np.rint(es / 0.5)
    out["phase_rmse_deg"] = float(np.sqrt(np.mean(resid ** 2)) * 360.0)
    out["cycle_slips"] = int(cycle_slips(es, costas=True))
    out["doppler_rmse_hz"] = float(np.sqrt(np.mean((dop[keep] - tr["doppler_hz"][keep]) ** 2)))
    out["code_rmse_chips"] = float(np.sqrt(np.mean(code[keep] ** 2)))
    prompt = obs[keep, 2] + 1j * obs[keep, 3]
    ld = LockDetector(CODE_PERIOD_S, window=100, m=10)
    locks = []
    for pv in prompt:
        if ld.update(pv):
            locks.append(bool(ld.phase_lock))
    out["lock_fraction"] = float(np.mean(locks)) if locks else None
    out["cn0_est_dbhz"] = float(cn0_m2m4(prompt, CODE_PERIOD_S))
    out["_series"] = (t, e, dop)
    return out


def tracker_report(tracker) -> dict:
    """The tracker's own figures for the JSON: ``q_hat`` (final value, per-block trajectory
    of one stream, the slave's block length) and ``diverged`` (its own loss-of-lock rule) of
    the seed-002 trackers, None for trackers without them, plus the rest of ``report()``
    under ``tracker_report``."""
    rep = tracker.report() if hasattr(tracker, "report") else {}
    out = {"q_hat": None, "diverged": None}
    if "q_hat" in rep:
        q = rep["q_hat"]
        prm = rep.get("params", {})
        out["q_hat"] = {"final": q["median_final"], "q0": prm.get("q0"),
                        "block_s": prm.get("block_s"), "trajectory": q["trajectory_median"],
                        "min": min(q["trajectory_median"]), "max": max(q["trajectory_median"]),
                        "adaptive": prm.get("adaptive")}
    if "diverged" in rep:
        d = rep["diverged"]
        out["diverged"] = bool(np.any(d))
    if rep:
        out["tracker_report"] = {k: v for k, v in rep.items() if k not in ("q_hat", "diverged")}
    return out


def check_run_size(sig: GnssSignalConfig, run: GnssRunConfig) -> None:
    """Refuse, before work, a record the machine cannot hold or a cycle-accurate run that
    would take hours (the message names the option)."""
    n = sig.n_samples
    check_memory(n * 8.0 if run.backend == "golden" else 64.0 * n / 1024,
                 f"{n:.3g} ADC samples", "--duration-s")
    if run.backend in CYCLES_PER_S and n / CYCLES_PER_S[run.backend] > MAX_WALL_S:
        raise ValueError(f"{run.backend} simulates about {CYCLES_PER_S[run.backend]:.0e} "
                         f"cycles/s: {n:,} cycles would take "
                         f"~{n / CYCLES_PER_S[run.backend] / 3600:.1f} h (limit "
                         f"{MAX_WALL_S / 3600:g} h): reduce --duration-s")


def run_gnss(signal_cfg: GnssSignalConfig, run_cfg: GnssRunConfig, *,
             keep_words: bool = False, tracker_setup=None, keep_track: bool = False) -> dict:
    """One GNSS run end to end (module doc); returns the JSON-safe result. With
    ``keep_words`` the result's ``_pipeline`` holds the :class:`PipelineResult` (tests).
    ``tracker_setup(gen, p, hand, backend) -> (ctx_changes, options)``, called after the
    acquisition, adds to the tracker's :class:`~dsp.gnss.trackers.TrackerContext` (e.g. an
    INS ``aiding``) and options (the INS-aided loops, :mod:`cosim.ins.run`); with
    ``keep_track`` the result's ``_track`` holds the DSP's per-record observables and
    the records' dump-boundary samples."""
    if not isinstance(signal_cfg, GnssSignalConfig):
        raise ValueError(f"signal_cfg must be a GnssSignalConfig, not "
                         f"{type(signal_cfg).__name__}")
    if not isinstance(run_cfg, GnssRunConfig):
        raise ValueError(f"run_cfg must be a GnssRunConfig, not {type(run_cfg).__name__}")
    sig, run = signal_cfg, run_cfg
    p = run.hdl_params(sig)
    run.service(sig.fs_hz)      # DspServiceConfig's own checks (window inside the period)
    check_run_size(sig, run)
    from dsp.gnss.trackers import needs_aiding
    if needs_aiding(run.tracker) and tracker_setup is None:
        raise ValueError(f"tracker {run.tracker} needs an INS aiding source: run it with "
                         f"`python -m cosim ins --loop {run.tracker}` (the seed-003 trajectory "
                         "and INS error model)")
    if sig.duration_s <= run.settle_s:
        raise ValueError(f"duration_s {sig.duration_s:g} s leaves nothing after settle_s "
                         f"{run.settle_s:g} s")
    gen = GnssSignalGenerator(sig)
    acq, hand = _acquire(gen, run)
    extra = None if tracker_setup is None else tracker_setup(gen, p, hand, run.backend)
    result = {"prn": sig.prn, "cn0_dbhz": sig.cn0_dbhz, "duration_s": sig.duration_s,
              "tracker": run.tracker, "bn_hz": run.bn_hz, "backend": run.backend,
              "dsp": run.dsp, "acquired": acq}
    if run.backend == "golden":
        track, n_b = _golden_track(gen, run, hand, run.dsp, extra)
        result.update(fifo_dropped=0, dropped_reported=0)
        digest = {"dsp": track.digest()}
        pres = None
    else:
        n = sig.n_samples
        blocks = (adc_words(gen.samples(k, min(run.block_samples, n - k))[0])
                  for k in range(0, n, run.block_samples))
        cl = closed_loop(run.backend, p, run, blocks, hand["doppler_hz"],
                         hand["code_phase_chips"], inverted=sig.spectrum_inverted,
                         cn0_dbhz=sig.cn0_dbhz, keep_words=keep_words, tracker_extra=extra)
        track, pres, bus, rx = cl.track, cl.pipeline, cl.bus_writes, cl.rx_stats
        n_b = _boundaries(p, bus, track.n_seen, sig.n_samples)[SKIP_RECORDS:]
        result.update(fifo_dropped=int(pres.overflow_count),
                      dropped_reported=int(rx["dropped_reported"]),
                      broken_records=int(rx["broken_records"]))
        digest = dict(pres.digest)
        digest["dsp"] = track.digest()
        result["writes"] = len(pres.writes)
    score = _score(gen, track, n_b, run.settle_s)
    series = score.pop("_series")
    result.update(score)
    result.update(tracker_report(track.tracker))
    h = hashlib.sha256("".join(f"{k}={v};" for k, v in sorted(digest.items())).encode())
    digest["all"] = h.hexdigest()[:16]
    result["digest"] = digest
    if run.compare == "golden":
        g = run_gnss(sig, replace(run, backend="golden", dsp="float", compare=None))
        gt, ge, gd = g.pop("_series")
        t, e, d = series
        keep = t >= run.settle_s
        result["golden"] = {k: g[k] for k in ("doppler_rmse_hz", "phase_rmse_deg",
                                              "code_rmse_chips", "cycle_slips",
                                              "lock_fraction", "cn0_est_dbhz")}
        result["vs_golden_doppler_rms_hz"] = float(np.sqrt(np.mean(
            (d[keep] - np.interp(t[keep], gt, gd)) ** 2)))
        result["vs_golden_phase_rms_deg"] = float(360 * np.sqrt(np.mean(
            (e[keep] - 0.5 * np.rint(e[keep] / 0.5)
             - np.interp(t[keep], gt, ge - 0.5 * np.rint(ge / 0.5))) ** 2)))
    result["_series"] = series
    if keep_track:
        result["_track"] = (track, n_b)
    if keep_words:
        result["_pipeline"] = pres
    return result
