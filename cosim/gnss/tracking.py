"""Acquisition, hand-over and the closed tracking loop of a GNSS run.

1. *Acquisition* (:func:`acquire_handover`, :mod:`cosim.gnss.handover`): the sequential
   search of :mod:`dsp.gnss.dwell` on the record from its first sample, its dwell extending
   until the PRN is detected, then the Doppler and code phase refined on the following
   milliseconds and propagated to the sample after them, where tracking starts (the
   tracking sees the record from there: :class:`cosim.gnss.handover.RecordFrom`).
2. *Hand-over* (:func:`cosim.gnss.handover.handover_writes`): the carrier word (IF + Doppler), the code word
   (chip rate + Doppler / 1540) and a code slew (samples of hold that put the prompt on the
   acquired code phase) are written at reset; they are active from the first dump boundary
   (1 ms). The first :data:`SKIP_RECORDS` records (the reset epoch and the epoch holding the
   slew) are not tracked.
3. *Tracking* (:func:`closed_loop`) on the streaming pipeline
   (:class:`cosim.core.pipeline.Pipeline`): the channel session
   (:func:`cosim.gnss.session.open_gnss`), the DSP reading the FIFO every
   ``service_period_us``; every record is reassembled (:func:`dsp.records.receive_records`)
   and given to the tracker (:func:`dsp.gnss.trackers.make_tracker`, float or fixed), whose
   carrier and code words are written back, ``control_latency_cycles`` after the DSP issues
   them (``compute_cycles`` after its read window). A write reaches the shadow registers
   well within the epoch, so it is active from the next dump boundary: the loop's latency
   is one epoch (``TrackerContext.latency_epochs = 1``). :func:`record_boundaries` replays
   the dump-boundary sample of every record.

:func:`golden_track` is the float64 correlator chain
(:class:`dsp.gnss.correlator.GoldenCorrelator`, no HDL, no FIFO) on the ADC codes, with the
same hand-over, the same one-epoch loop latency and the tracker in the arithmetic asked for.
The HDL takes the ADC's two's-complement word ``q`` (the signal's odd codes ``2 q + 1``,
:mod:`cosim.gnss.signal`; :func:`adc_words`); the golden chain takes the codes.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace

import numpy as np

from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_PERIOD_S, L1_HZ
from hdl.gnss.params import ACC_FIELDS

from .config import REPLAY_BLOCK, WORD_BITS, GnssRunConfig
from .handover import acquire_handover, handover_writes

__all__ = ["Tracking", "TrackingSink", "PipelineDsp",
           "record_observables", "make_tracker_for", "ClosedLoop", "closed_loop", "adc_words",
           "record_boundaries", "golden_track", "SKIP_RECORDS"]

#: Records not tracked after reset: the reset epoch, and the epoch holding the code slew.
SKIP_RECORDS = 2


def _make_tracker(run: GnssRunConfig, fs_hz, if_hz, inverted, cn0_dbhz, doppler_hz: float,
                  spacing_chips: float, arith_name: str, extra: tuple | None = None):
    from dsp.gnss.loops_fixed import FLOAT, FixedArith
    from dsp.gnss.trackers import TrackerContext, make_tracker
    ctx = TrackerContext(fs_hz=fs_hz, T_s=CODE_PERIOD_S, if_hz=if_hz,
                         inverted=inverted, doppler0_hz=doppler_hz,
                         doppler_rate0_hz_s=run.handover_doppler_rate_hz_s, cn0_dbhz=cn0_dbhz,
                         spacing_chips=spacing_chips, latency_epochs=1,
                         doppler0_sigma_hz=run.handover_doppler_sigma_hz)
    arith = FixedArith() if arith_name == "fixed" else FLOAT
    opts = run.tracker_kwargs()
    if extra is not None:       # (TrackerContext changes, tracker options) of the caller
        ctx = replace(ctx, **extra[0])
        opts.update(extra[1])
    return make_tracker(run.tracker, ctx, arith, **opts), arith


#: The tracker of a run for a channel (public name of the factory closed_loop uses).
make_tracker_for = _make_tracker


class Tracking:
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


def record_observables(p, d: dict):
    """A record's observables for :meth:`Tracking.record`: the carrier NCO phase (cycles),
    the prompt's code phase at its boundary (chips) and the six correlations."""
    return (d["carr_phase"] / 2.0 ** p.carr_phase_bits,
            d["code_phase"] / 2.0 ** p.code_phase_bits, [d[k] for k in ACC_FIELDS])


class TrackingSink:
    """One channel's DSP: a record (its fields) in, the tracker's carrier and code words out
    as register writes ``[(carr_reg, word), (code_reg, word)]`` (None for a skipped
    record)."""

    def __init__(self, p, track: Tracking, regs=("carr_freq", "code_freq")):
        self.p, self.track, self.regs = p, track, regs

    def __call__(self, d: dict):
        # (the boundary sample is not in the record: record_boundaries recomputes it)
        r = self.track.record(None, *record_observables(self.p, d))
        if r is None:
            return None
        return [(self.regs[0], r[0]), (self.regs[1], r[1])]


class PipelineDsp:
    """The pipeline's DSP callback: reassemble the FIFO records and hand each to the sink of
    its channel (``sinks[channel]``, the record's ``channel`` field; 0 without one), a
    callable ``sink(fields) -> writes or None``. The writes of a sink's last record of the
    call go back, channel by channel in channel order (a sink's earlier outputs in the same
    call are superseded, as the registers would be). ``before(call)``, if given, is called
    first on every call (e.g. to see the bus writes made so far)."""

    def __init__(self, p, sinks: dict, before=None):
        from dsp.records import RecordRxState
        self.p, self.sinks, self.before = p, sinks, before
        self.fifo = p.fifo
        self.rx = RecordRxState()
        self.layout = p.record          # (derived on every access of the property)
        self.fields = self.layout.fields

    def __call__(self, call):
        from dsp.records import receive_records
        p, fp = self.p, self.fifo
        if self.before is not None:
            self.before(call)
        if not call.words.size:
            return ()
        b = receive_records(call.words, width=fp.width, record_words=fp.record_words,
                            parity=fp.parity, state=self.rx)
        out = {}
        names = self.layout.names
        for row in self.layout.from_word_array(b.records, fp.width).tolist():
            d = dict(zip(names, row))
            ch = d.get("channel", 0)
            r = self.sinks[ch](d)
            if r is not None:
                out[ch] = r
        return [w for ch in sorted(out) for w in out[ch]]


@dataclass
class ClosedLoop:
    """A closed-loop run of the channel: the DSP's record of every tracked record
    (``track``), the pipeline's result (words, writes, digest), the bus writes made and
    the record receiver's counters."""

    track: "Tracking"
    pipeline: object
    bus_writes: list
    rx_stats: dict


def closed_loop(backend: str, p, run: GnssRunConfig, blocks, doppler_hz: float,
                code_phase_chips: float, *, inverted: bool = False,
                cn0_dbhz: float | None = None, keep_words: bool = False,
                tracker_extra: tuple | None = None) -> ClosedLoop:
    """Track on channel ``p`` (a session on ``backend``) fed ``blocks`` (iterable of ADC
    word arrays, one word per cycle), started by :func:`~cosim.gnss.handover.handover_writes`, the DSP service
    and tracker of ``run``, its writes decided on the fly."""
    from ..core.pipeline import Pipeline
    from .session import open_gnss
    spacing = p.el_spacing_samples * CHIP_RATE_HZ / p.fs_hz
    tracker, arith = _make_tracker(run, p.fs_hz, p.if_hz, inverted, cn0_dbhz, doppler_hz,
                                   spacing, run.dsp, tracker_extra)
    track = Tracking(tracker, arith, p, SKIP_RECORDS)
    dsp = PipelineDsp(p, {0: TrackingSink(p, track)})
    svc = run.service(p.fs_hz)
    with open_gnss(backend, p) as fe:
        pipe = Pipeline(fe, svc, dsp, compute_cycles=run.compute_cycles,
                        control_latency_cycles=run.latency_cycles,
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


def record_boundaries(p, bus_writes, n_records, n_total, block: int = REPLAY_BLOCK):
    """Dump-boundary sample of the records ``1 .. n_records`` of the HDL channel, from the
    code NCO's words in force (replayed exactly: the code generator's epochs only depend on
    the code word, PRN-independent, and the slew)."""
    from hdl.gnss.model import GnssChannelModel
    # Run the bit-exact channel on zero samples with the same bus writes: its records come
    # at the same cycles (the code NCO does not see the samples). In blocks of ``block``
    # samples (REPLAY_BLOCK: ~25 B a sample of the model's temporaries; a 150 s record is
    # 2.5e9 samples), until n_records are out.
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


def golden_track(gen, run, hand, arith_name, tracker_extra=None):
    """Track the record of ``gen`` on the float64 correlator chain from the hand-over ``hand``,
    the tracker of ``run`` in ``arith_name`` arithmetic, one epoch of loop latency; returns
    the :class:`Tracking` and the dump-boundary sample of every tracked record. The record
    is streamed (:class:`~cosim.gnss.signal.SampleStream`, ``run.block_samples`` at a
    time, one epoch correlated per read): what is held is one block and the per-record
    outputs, whatever the duration; the bits do not depend on ``run.block_samples``."""
    from dsp.gnss.correlator import GoldenCorrelator
    sig = gen.cfg
    p = run.hdl_params(sig)
    spacing = p.el_spacing_samples * CHIP_RATE_HZ / sig.fs_hz
    tracker, arith = _make_tracker(run, sig.fs_hz, sig.digital_if_hz, sig.spectrum_inverted,
                                   sig.cn0_dbhz, hand["doppler_hz"], spacing, arith_name,
                                   tracker_extra)
    track = Tracking(tracker, arith, p, 1)
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
