"""Every satellite of a recording tracked at once: one ADC stream into the N-channel array,
one DSP tracker per channel closing its loop over the one control path.

Data path
---------
The recording's ADC words (:meth:`cosim.gnss.files.SampleFile.words`, block by block, one
sample per cycle) go into the array (:func:`cosim.gnss.multichannel_session.open_gnss_array`:
the bit-exact model, or Verilator / Amaranth through the same factory) on the streaming
pipeline (:class:`cosim.core.pipeline.Pipeline`, the DSP service of the
:class:`~cosim.gnss.config.GnssRunConfig`). The records of the one FIFO are demultiplexed by
their ``channel`` field (:class:`cosim.gnss.tracking.PipelineDsp`, the mechanism of the
single-channel :func:`~cosim.gnss.tracking.closed_loop`) to one :class:`ChannelSlot` per
channel, whose tracker (any registered one, float or fixed) writes that channel's carrier and
code words back.

Allocation
----------
The candidates are the acquisition's verified detections, strongest (C/N0) first; the first
``channels`` are started at reset (:func:`cosim.gnss.handover.handover_writes`, plus the PRN
register). A slot watches its lock indicators over windows of ``lock_window_ms`` prompts
(:class:`dsp.gnss.loops.LockDetector`: narrowband PLI >= ``pli_min`` and M2M4 C/N0 >=
``cn0_min_dbhz``). A slot *locks* when ``confirm_windows`` windows in a row have both; one that has not locked within
``pull_in_ms`` of its start drops its PRN as a false detection; a locked one that misses
``lost_windows`` windows in a row has *lost lock*, and its PRN goes to the back of the queue.
Either way the channel takes the next candidate: re-acquired (:func:`dsp.gnss.search.search_all`,
that PRN alone, with its verification dwell) on the last ``reacq_ms`` ms of the recording
before the channel's current boundary, so on the signal as it is now; a candidate not found
again is dropped and the next tried. The new hand-over takes effect at the channel's next
dump boundary, which the DSP knows exactly from the records
(:mod:`cosim.gnss.multichannel_epochs`).

What each assignment keeps (:class:`Assignment`): per record the time of its prompt boundary,
the tracker's Doppler, the prompt's code phase (chips, at the recording's last 1 ms grid sample
before the boundary), the prompt I/Q; per lock window the PLI, the C/N0 and the two locks.
:mod:`cosim.gnss.track_report` turns them into the user's figures.
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, CODE_PERIOD_S, L1_HZ

from ..core.validate import check_float, check_int
from .config import GnssRunConfig
from .multichannel_epochs import CodeEpochs, rehandover_writes
from .multichannel_session import array_channel_params, open_gnss_array, register_name
from .handover import handover_writes
from .tracking import (SKIP_RECORDS, PipelineDsp, Tracking, make_tracker_for,
                       record_observables)

__all__ = ["TrackConfig", "Candidate", "Assignment", "ChannelSlot", "MultiTrack",
           "track_file", "channel_params_for"]


def channel_params_for(f, hdl_changes: tuple = ()):
    """The channel for recording ``f`` (its rate, IF, ADC word length, an early-minus-late
    spacing of about half a chip; ``hdl_changes`` override); a complex recording takes the
    channel's complex (I/Q) input."""
    from hdl.gnss.params import GnssChannelParams
    from .config import WORD_BITS
    bits = f.adc_map.bits
    if bits is None:
        raise ValueError(f"--adc-map {f.adc_map} has no ADC word length: the channel takes "
                         f"ADC words (give float:B to quantise)")
    # early-minus-late about half a chip (even, >= 2 samples): 8 at 16.384 MS/s, 6 at 12
    el = max(2, 2 * round(f.fs_hz / CHIP_RATE_HZ / 4))
    # odd-level words (a sign/magnitude ADC's +-1, +-3, ..., and a float:B map's midrise
    # levels) enter the mixer as 2q+1
    kw = dict(fs_hz=f.fs_hz, if_hz=f.if_hz, adc_bits=int(bits), el_spacing_samples=el,
              adc_levels="odd" if f.adc_map.odd_levels else "twos")
    kw.update(dict(hdl_changes))
    if f.is_complex:
        kw["input"] = "complex"
    p = GnssChannelParams(**kw)
    if p.carr_phase_bits != WORD_BITS or p.code_phase_bits != WORD_BITS:
        raise ValueError(f"the trackers write {WORD_BITS}-bit NCO words")
    return p


@dataclass(frozen=True)
class TrackConfig:
    """How the channels are allocated and judged (module doc)."""

    channels: int = 12
    lock_window_ms: int = 20
    pli_block_ms: int = 10
    pli_min: float = 0.8
    cn0_min_dbhz: float = 30.0
    confirm_windows: int = 2
    pull_in_ms: int = 100
    lost_windows: int = 5
    reacq_ms: int = 70
    pfa: float = 1e-3
    max_doppler_hz: float = 5000.0
    #: The bit-exact array's channels on numba's threads (the same bits; model backend).
    parallel: bool = False

    def __post_init__(self):
        check_int("--channels", self.channels, 1, 12)
        if not isinstance(self.parallel, bool):
            raise ValueError(f"--parallel must be a bool, not {self.parallel!r}")
        check_int("lock_window_ms", self.lock_window_ms, 2, 1000)
        check_int("pli_block_ms", self.pli_block_ms, 1, 20)
        if self.lock_window_ms % self.pli_block_ms:
            raise ValueError(f"lock_window_ms {self.lock_window_ms} must be a multiple of "
                             f"pli_block_ms {self.pli_block_ms}")
        check_float("pli_min", self.pli_min, -1.0, 1.0)
        check_float("cn0_min_dbhz", self.cn0_min_dbhz, 0.0, 70.0, unit="dB-Hz")
        check_int("--pull-in-ms", self.pull_in_ms, self.lock_window_ms, 100_000)
        check_int("lost_windows", self.lost_windows, 1, 1000)
        check_int("confirm_windows", self.confirm_windows, 1, 1000)
        check_int("reacq_ms", self.reacq_ms, 20, 1000)


@dataclass
class Candidate:
    """A satellite to track: Doppler (Hz) and code phase (chips) at sample ``n_ref``."""

    prn: int
    doppler_hz: float
    code_phase_chips: float
    cn0_dbhz: float
    n_ref: int = 0
    source: str = "acquisition"

    @classmethod
    def of(cls, det, n_ref: int = 0, source: str = "acquisition") -> "Candidate":
        return cls(det.prn, float(det.doppler_hz), float(det.code_phase_chips),
                   float(det.cn0_dbhz), int(n_ref), source)


@dataclass
class Assignment:
    """One PRN on one channel from its hand-over to the end (or its release)."""

    prn: int
    channel: int
    candidate: Candidate
    start_sample: int
    status: str = "pull-in"                 #: pull-in, locked, tracked, dropped, lost
    end_reason: str = ""
    lock_sample: int | None = None
    end_sample: int | None = None
    #: the tracker's Doppler report stands for its record's end plus this many epochs
    doppler_offset_epochs: float = 0.0
    t: list = field(default_factory=list)
    doppler: list = field(default_factory=list)
    code_phase: list = field(default_factory=list)
    ip: list = field(default_factory=list)
    qp: list = field(default_factory=list)
    win_t: list = field(default_factory=list)
    win_pli: list = field(default_factory=list)
    win_cn0: list = field(default_factory=list)
    win_phase_lock: list = field(default_factory=list)
    win_cn0_lock: list = field(default_factory=list)


class ChannelSlot:
    """The DSP of one channel: its code epochs, its tracker (when assigned), its lock
    detector and the allocation rules (module doc); a sink of
    :class:`~cosim.gnss.tracking.PipelineDsp`."""

    def __init__(self, owner: "_Allocator", ch: int):
        self.owner, self.ch = owner, ch
        self.regs = (owner.name(ch, "carr_freq"), owner.name(ch, "code_freq"))
        self.epochs = CodeEpochs(owner.p)
        self.track: Tracking | None = None
        self.asg: Assignment | None = None
        self.det = None
        self.misses = self.hits = 0
        self.release = ""              # reason, while a re-hand-over waits for its boundary

    def assign(self, cand: Candidate, start_sample: int, prompt_start: int | None = None) -> None:
        """Start tracking ``cand``; ``prompt_start``: the sample where the prompt starts its
        first code period after the hand-over (the slew record's), from which the first
        tracked epoch starts one code period later (the ``tracker_setup`` hook's time)."""
        from dsp.gnss.loops import LockDetector
        o = self.owner
        extra = None
        if o.setup is not None:
            rate = CHIP_RATE_HZ * (1 + cand.doppler_hz / L1_HZ)
            t_first = (prompt_start if prompt_start is not None else start_sample) / o.p.fs_hz \
                + CODE_LENGTH / rate
            extra = o.setup(cand.prn, t_first)
        tracker, arith = make_tracker_for(o.run, o.p.fs_hz, o.p.if_hz, o.inverted,
                                          cand.cn0_dbhz, cand.doppler_hz, o.spacing, o.run.dsp,
                                          extra)
        self.track = Tracking(tracker, arith, o.p, SKIP_RECORDS)
        c = o.cfg
        self.det = LockDetector(CODE_PERIOD_S, window=c.lock_window_ms, m=c.pli_block_ms,
                                pli_min=c.pli_min, cn0_min_dbhz=c.cn0_min_dbhz)
        self.asg = Assignment(cand.prn, self.ch, cand, start_sample,
                              doppler_offset_epochs=float(getattr(tracker,
                                                                  "doppler_offset_epochs", 0.0)))
        o.assignments.append(self.asg)
        self.misses, self.hits, self.release = 0, 0, ""

    def __call__(self, d: dict):
        o, p = self.owner, self.owner.p
        prev_cf = self.epochs.cf
        n_w = self.epochs.record(d["code_phase"])
        if self.track is None:
            return None
        carr, code, iq6 = record_observables(p, d)
        if self.release:
            return self._rehandover()
        r = self.track.record(None, carr, code, iq6)
        if r is None:
            return None
        a = self.asg
        n_p = n_w + 1 + p.half_spacing               # the prompt's boundary sample
        g = (n_p // o.n_ms) * o.n_ms
        a.t.append(n_p / p.fs_hz)
        a.doppler.append(self.track.doppler[-1])
        a.code_phase.append((code - (n_p - g) * prev_cf / 2.0 ** p.code_phase_bits)
                            % CODE_LENGTH)
        a.ip.append(float(iq6[2]))
        a.qp.append(float(iq6[3]))
        writes = [(self.regs[0], r[0]), (self.regs[1], r[1])]
        if self.det.update(complex(iq6[2], iq6[3])):
            self._window(n_p)
            if self.release:
                return self._rehandover() or writes
        return writes

    def _window(self, n_p: int) -> None:
        a, det, c = self.asg, self.det, self.owner.cfg
        a.win_t.append(n_p / self.owner.p.fs_hz)
        a.win_pli.append(float(det.pli))
        a.win_cn0.append(float(det.cn0_dbhz))
        a.win_phase_lock.append(bool(det.phase_lock))
        a.win_cn0_lock.append(bool(det.cn0_lock))
        ok = bool(det.phase_lock) and bool(det.cn0_lock)
        self.hits = self.hits + 1 if ok else 0
        if a.status == "pull-in":
            if self.hits >= c.confirm_windows:
                a.status, a.lock_sample = "locked", n_p
            elif n_p - a.start_sample >= c.pull_in_ms * self.owner.n_ms:
                self.release = "dropped: no lock within the pull-in time (a false detection)"
        elif a.status == "locked":
            self.misses = 0 if ok else self.misses + 1
            if self.misses >= c.lost_windows:
                self.release = f"lost lock ({self.misses} windows out of lock)"

    def _rehandover(self):
        """Release the PRN and hand the channel over to the next candidate found again on the
        current signal, effective at its next boundary; None: not yet (the writes could not
        reach the registers before that boundary) or no candidate left (idle)."""
        o = self.owner
        n_next, acc = self.epochs.next_boundary()
        if o.call is not None and o.call.effect_cycle + 64 >= n_next:
            return None
        a = self.asg
        if a is not None and a.status != "tracked":
            lost = a.status == "locked"
            a.status = "lost" if lost else "dropped"
            a.end_reason, a.end_sample = self.release, self.epochs.n_w
            if lost:
                o.queue.append(Candidate(a.prn, a.doppler[-1] if a.doppler else
                                         a.candidate.doppler_hz, 0.0, a.candidate.cn0_dbhz,
                                         0, "lost"))
        self.track, self.asg, self.release = None, None, ""
        cand = o.next_candidate(self.epochs.n_w + 1, self.ch)
        if cand is None:
            return None
        w = rehandover_writes(o.p, n_next, acc, cand.doppler_hz, cand.code_phase_chips,
                              cand.n_ref, o.inverted)
        # the new PRN's records: the one closing at n_next is the old PRN's, the next holds
        # the slew (SKIP_RECORDS)
        self.assign(cand, n_next + 1 + o.p.half_spacing,
                    n_next + 1 + dict(w)["slew"] + o.p.half_spacing)
        return [(o.name(self.ch, "prn"), cand.prn)] + [(o.name(self.ch, r), v) for r, v in w]


class _Allocator:
    """The channels' shared state: the candidate queue, re-acquisition, the assignments."""

    def __init__(self, f, p, run, cfg, queue, setup=None):
        self.f, self.p, self.run, self.cfg, self.setup = f, p, run, cfg, setup
        self.inverted = f.doppler_sign_inverted
        self.n_ms = f.samples_per_ms
        self.spacing = p.el_spacing_samples * CHIP_RATE_HZ / p.fs_hz
        self.queue = list(queue)
        self.assignments: list[Assignment] = []
        self.reacq: list[dict] = []
        self.call = None
        self.slots: list[ChannelSlot] = []
        self._nbus = 0

    def name(self, ch: int, reg: str) -> str:
        return register_name(self.cfg.channels, ch, reg)

    def before(self, call) -> None:
        """Every DSP call: the bus writes made since the last one, to their channels."""
        self.call = call
        bw = call.session.bus_writes
        for b, addr, v in bw[self._nbus:]:
            ch, reg = divmod(int(addr), 4)
            self.slots[ch].epochs.bus(b, reg, v)
        self._nbus = len(bw)

    def next_candidate(self, n_end: int, ch: int):
        """The next queued candidate found again on the ``reacq_ms`` ms before sample
        ``n_end`` (None: the queue is empty)."""
        from dsp.gnss.search import search_all
        busy = {s.asg.prn for s in self.slots if s.asg is not None}
        while self.queue:
            c = self.queue.pop(0)
            if c.prn in busy:
                continue
            n0 = max(0, n_end - self.cfg.reacq_ms * self.n_ms)
            t0 = time.time()
            rep = search_all(lambda a, n: self.f.read(n0 + a, n), n_end - n0, self.f.fs_hz,
                             self.f.if_hz, self.inverted, [c.prn], self.cfg.pfa,
                             self.cfg.max_doppler_hz, refine_ms=min(100, self.cfg.reacq_ms))
            found = bool(rep.detections)
            self.reacq.append({"prn": c.prn, "channel": ch, "t_s": n_end / self.f.fs_hz,
                               "window_ms": (n_end - n0) / self.n_ms, "found": found,
                               "wall_s": round(time.time() - t0, 2)})
            if found:
                return Candidate.of(rep.detections[0], n0, "re-acquired")
        return None


@dataclass
class MultiTrack:
    """A multi-channel run: the assignments, re-acquisitions, pipeline result, timing."""

    assignments: list
    reacquisitions: list
    candidates: list
    channels: int
    n_samples: int
    fs_hz: float
    backend: str
    tracker: str
    dsp: str
    pipeline: object
    rx_stats: dict
    wall_s: float
    bus_writes: list


def track_file(f, candidates, run: GnssRunConfig, cfg: TrackConfig = TrackConfig(), *,
               n_samples: int | None = None, block_samples: int = 1 << 17,
               progress: bool = False, hdl_changes: tuple = (),
               keep_words: bool = False, tracker_setup=None) -> MultiTrack:
    """Track the ``candidates`` (acquired on ``f``, a :class:`cosim.gnss.files.SampleFile`;
    code phases at sample 0) on ``cfg.channels`` channels of the array on ``run.backend``
    (``model`` or ``verilator``/``pysim``) with ``run``'s tracker, arithmetic and DSP service,
    over the first ``n_samples`` samples (default all), streamed in blocks. ``keep_words``:
    the result's pipeline keeps every FIFO word read and its read cycle (else only their
    digest). ``tracker_setup(prn, t_first_s) -> (TrackerContext changes, tracker options)``:
    per assignment, what the tracker is built with beyond the run's (e.g. the INS aiding,
    ``{"aiding": aiding}``: :mod:`cosim.ins.table2_if`), ``t_first_s`` the start of its
    first tracked epoch (the received code epoch after the slew's, to the hand-over's code
    phase error); the trackers that need an aiding source run only with it."""
    from dsp.gnss.trackers import needs_aiding

    from ..core.pipeline import Pipeline
    if needs_aiding(run.tracker) and tracker_setup is None:
        raise ValueError(f"tracker {run.tracker} needs an aiding source: give tracker_setup")
    if tracker_setup is not None and not callable(tracker_setup):
        raise ValueError("tracker_setup must be a callable (prn, t_first_s) -> (ctx, options)")
    if run.backend == "golden":
        raise ValueError("--backend golden has no channel array: use model or verilator")
    n = f.n_samples if n_samples is None else int(n_samples)
    if not 0 < n <= f.n_samples:
        raise ValueError(f"--duration-s: {n} samples asked, the recording has "
                         f"{f.n_samples}")
    p = array_channel_params(channel_params_for(f, hdl_changes), cfg.channels)
    cands = sorted(candidates, key=lambda c: -c.cn0_dbhz)
    alloc = _Allocator(f, p, run, cfg, cands[cfg.channels:], tracker_setup)
    alloc.slots = [ChannelSlot(alloc, ch) for ch in range(cfg.channels)]
    # the service reads what the array writes: every channel's record each 1 ms (twice over)
    need = math.ceil(2 * cfg.channels * p.fifo.record_words * run.service_period_us / 1e3)
    if run.service_batch_words < need:
        run = dataclasses.replace(run, service_batch_words=need)
    svc = run.service(p.fs_hz)
    dsp = PipelineDsp(p, dict(enumerate(alloc.slots)), before=alloc.before)
    t0 = time.time()
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n, unit="S", unit_scale=True, desc="gnss-track", leave=False)
    with open_gnss_array(run.backend, p, cfg.channels, cfg.parallel) as fe:
        pipe = Pipeline(fe, svc, dsp, compute_cycles=run.compute_cycles,
                        control_latency_cycles=run.latency_cycles,
                        keep_words=keep_words)
        init = []
        for ch, c in enumerate(cands[:cfg.channels]):
            init.append((0, alloc.name(ch, "prn"), c.prn))
            hw = handover_writes(p, c.doppler_hz, c.code_phase_chips, alloc.inverted)
            init += [(cyc, alloc.name(ch, r), v) for cyc, r, v in hw]
            # the reset word's first boundary, then the slew: the prompt's first code period
            n1 = alloc.slots[ch].epochs.next_boundary()[0]
            alloc.slots[ch].assign(c, 0, n1 + 1 + hw[2][2] + p.half_spacing)
        pipe.schedule(sorted(init, key=lambda w: w[0]))
        for a in range(0, n, block_samples):
            x = f.words(a, min(block_samples, n - a))
            pipe.feed(p.pack_samples(x))      # the input port's payloads (I/Q packed)
            if bar is not None:
                bar.update(x.shape[0])
        if hasattr(fe, "end_input"):
            fe.end_input()
        pipe.idle(p.latency + 8 * p.fifo.record_words * cfg.channels + svc.period_cycles + 64)
        res = pipe.result()
        bus = list(fe.bus_writes)
    if bar is not None:
        bar.close()
    for s in alloc.slots:
        if s.asg is not None and s.asg.status in ("locked", "pull-in"):
            s.asg.end_sample = n
            if s.asg.status == "locked":
                s.asg.status = "tracked"
            else:
                s.asg.end_reason = "still pulling in at the end of the recording"
    return MultiTrack(alloc.assignments, alloc.reacq, cands, cfg.channels, n, f.fs_hz,
                      run.backend, run.tracker, run.dsp, res, dict(dsp.rx.stats),
                      time.time() - t0, bus)
