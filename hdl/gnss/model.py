"""GPS L1 C/A tracking channel: the bit-exact model, the specification of the hardware
(:mod:`hdl.gnss.channel`). Parameters, register map and record layout are in
:mod:`hdl.gnss.params`.

Per ADC sample (one per ``i.valid`` cycle)
------------------------------------------
*Code generator.* ``chip`` (0..1022) indexes the PRN's C/A code (:mod:`dsp.gnss.ca_code`;
G1/G2 registers reset to all ones at every code epoch, so the generator's output is the
table entry ``code[prn][chip]``; a PRN register outside 1-32 gives G1 alone). The *early*
replica is the generator's current chip; *prompt* and *late* are the same chip stream
delayed by ``d`` and ``2 d`` samples, ``d = el_spacing_samples / 2`` (spacing counted in
samples, so early-minus-late = ``el_spacing_samples / samples_per_chip`` chips: 8 samples =
0.4995 chip at 16.384 MS/s). Logic 0 is the +1 replica, logic 1 is -1.

*Code NCO.* A ``code_phase_bits`` accumulator: after the sample, unless a slew hold is
running (then ``hold -= 1`` and nothing moves), ``acc += code_freq``; a carry advances the
chip; a carry at chip 1022 is a *generator epoch* (chip 0 starts at the next sample).

*Double-buffered registers.* The DSP writes shadow registers over the register bus
(:data:`REG_CARR_FREQ`, :data:`REG_CODE_FREQ`, :data:`REG_PRN`, :data:`REG_SLEW`; a bus write
in cycle ``c`` is in the shadow from cycle ``c + 1``). At every ``dump_epochs``-th
generator epoch (a *dump boundary*, sample ``n`` in cycle ``c_n``) the shadow registers
written before cycle ``c_n`` become active: code frequency and PRN from the next sample,
the slew (if one was written since the last boundary) as a hold of that many samples
starting at the next sample -- delaying the code by ``slew`` samples -- and the carrier
frequency from the prompt's boundary ``d + 1`` samples later, so that each integration of
the prompt sees one carrier word. The code accumulator at the boundary is kept for the
record.

*Carrier and wipe-off.* The carrier NCO (:class:`hdl.nco.Nco`, no dither, its phase port
fed by the channel's ``carr_phase_bits`` accumulator) gives ``cos, sin`` of the sample's
phase ``carr_acc`` (then ``carr_acc += carr_freq``); the mixer multiplies the sample by
``exp(-j phi)`` at full precision (no rounding, no overflow: :attr:`GnssChannelParams.mixer`):
real input ``x``, ``I = x cos``, ``Q = -x sin``; complex input (``input="complex"``, I and Q
words ``xi``, ``xq``), ``I = xi cos + xq sin``, ``Q = xq cos - xi sin``. A signal at ``+f``
(``cos 2 pi f t`` real, ``exp(+j 2 pi f t)`` complex) is wiped off by a carrier word of
``+f`` in both. A 1-bit ADC word ``s`` in {0, -1} means ``2 s + 1`` (sign samples +-1),
per component.

*Integrate and dump.* Six accumulators ``I/Q x E/P/L`` add ``I * r``, ``Q * r``. On the
first sample of a prompt integration they are dumped as one record and restart from that
sample's products; ``epoch`` counts prompt code epochs since reset (mod
``2**epoch_bits``, the record's value includes the epoch it closes), ``carr_phase`` is the
carrier accumulator of the first sample of the *new* integration and ``code_phase`` the
code accumulator (chip fraction) of the generator at its boundary, which is the prompt's
fraction at the prompt's boundary. The record enters the FIFO :attr:`GnssChannelParams.latency`
cycles after that first sample's input cycle.

Record layout (LSB first): ``ie, qe, ip, qp, il, ql`` (signed ``acc_width`` each),
``epoch`` (``epoch_bits``), ``carr_phase`` (``carr_phase_bits``), ``code_phase``
(``code_phase_bits``), then in an array ``channel``; split into FIFO words of
``fifo_width`` bits (word 0 = the lowest bits).

The per-sample work is the compiled kernel of :mod:`hdl.gnss.kernel`, one call per step for
all the channels of an array (:class:`ChannelBank`); records become FIFO words with numpy
(:meth:`dsp.record_layout.RecordLayout.to_word_array`).
"""
from __future__ import annotations

import functools
import os
from dataclasses import dataclass

import numpy as np

from dsp.gnss.ca_code import ca_code_table
from hdl.model.fifo import FifoState, fifo_model_events
from hdl.model.nco import nco_full_tables
from .kernel import (CARR_F, CF, NSTATE, PEND_CARR, PRN, SH_CARR, SH_CODE, SH_PRN,
                     array_kernel, array_kernel_parallel, empty_records)
from .params import GnssChannelParams


@functools.lru_cache(maxsize=64)
def _layout(params: GnssChannelParams):
    """(acc_width, record layout, register map, latency) of ``params``, derived once (the
    properties rebuild them on every access)."""
    return params.acc_width, params.record, params.registers, params.latency


@functools.lru_cache(maxsize=64)
def _fifo(params: GnssChannelParams):
    return params.fifo


def _initial_state(p: GnssChannelParams) -> np.ndarray:
    """A channel's state vector after reset (:mod:`hdl.gnss.kernel`)."""
    st = np.zeros(NSTATE, np.int64)
    cw, kw = p.carr_word(p.if_hz), p.code_word()
    st[CF] = st[SH_CODE] = kw
    st[PRN] = st[SH_PRN] = p.prn
    st[CARR_F] = st[PEND_CARR] = st[SH_CARR] = cw
    return st


@functools.lru_cache(maxsize=8)
def _tables(nco):
    """(C/A code table, cos and sin tables of the carrier NCO ``nco``) as int64."""
    cos_t, sin_t = nco_full_tables(nco)
    return ca_code_table().astype(np.int64), cos_t.astype(np.int64), sin_t.astype(np.int64)


@dataclass
class ChannelRecords:
    """Records a model step produced (before the FIFO)."""

    cycles: np.ndarray                   #: FIFO input cycle of each record
    fields: np.ndarray                   #: (n, 9) int64: ie qe ip qp il ql epoch carr code

    def words(self, params: GnssChannelParams, channel=None) -> np.ndarray:
        """The records as FIFO words, ``(n, record_words)`` int64 (the accumulators wrap to
        ``acc_width`` bits as the hardware's); ``channel``: the ``channel`` field of an
        array's records (an int or one per record)."""
        return record_words(params, self.fields, channel)

    def values(self, params: GnssChannelParams, channel: int | None = None) -> list[int]:
        """The records as integers (:meth:`dsp.record_layout.RecordLayout.pack`)."""
        return words_to_values(params, self.words(params, channel))


def record_words(params: GnssChannelParams, fields, channel=None) -> np.ndarray:
    """Records ``fields`` (``(n, 9)``: ie qe ip qp il ql epoch carr code) as FIFO words,
    ``(n, record_words)`` (:meth:`ChannelRecords.words`)."""
    _, layout, _, _ = _layout(params)
    fp = _fifo(params)
    f = np.asarray(fields, np.int64).reshape(-1, 9)
    if not f.shape[0]:
        return np.zeros((0, fp.record_words), np.int64)
    if params.channel_bits:
        g = np.empty((f.shape[0], 10), np.int64)
        g[:, :9] = f
        g[:, 9] = 0 if channel is None else channel
        f = g
    return layout.to_word_array(f, fp.width, fp.record_words)


def words_to_values(params: GnssChannelParams, words) -> list[int]:
    """FIFO words of records ``(n, record_words)`` -> the records as integers."""
    w = _fifo(params).width
    return [sum(int(x) << (j * w) for j, x in enumerate(row)) for row in words.tolist()]


class ChannelBank:
    """The state of ``channels`` channels on one input (stacked, one row each) and the
    compiled kernel that advances them all over a chunk (:func:`hdl.gnss.kernel.array_kernel`);
    :class:`GnssChannelModel` is a bank of one, :class:`GnssArrayModel` holds one.

    Parameters
    ----------
    params : GnssChannelParams
    channels : int
    parallel : bool
        Share the channels out among numba's threads
        (:func:`hdl.gnss.kernel.array_kernel_parallel`; the same bits). Sets
        ``OMP_WAIT_POLICY=passive`` unless it is set (idle threads must not spin between
        the calls, one per DSP service).
    """

    def __init__(self, params: GnssChannelParams, channels: int = 1, parallel: bool = False):
        self.params = p = params
        self.channels = int(channels)
        self.parallel = bool(parallel)
        if self.parallel:
            # OpenMP threads that spin between the (sub-millisecond) calls burn the cores a
            # shared machine needs: they wait passively unless the user chose otherwise
            # (read when numba first starts its threads).
            os.environ.setdefault("OMP_WAIT_POLICY", "passive")
        self._table, self._cos, self._sin = _tables(p.nco)
        self.state = np.tile(_initial_state(p), (self.channels, 1))
        self.ring = np.zeros((self.channels, p.el_spacing_samples), np.int64)
        self._writes = np.zeros((0, 4), np.int64)       # channel, cycle, reg, value
        self._k = (p.complex_input, p.dump_epochs, p.half_spacing, p.code_phase_bits,
                   p.carr_phase_bits, p.nco.trunc_bits, (1 << p.epoch_bits) - 1)
        self.n_samples = 0
        self.next_cycle = 0

    def prepare(self, samples, cycles):
        """The checked samples (int64, the 1-bit map applied) as the kernel's ``I`` and ``Q``
        streams (real input: the one stream twice) and their input cycles (default: one
        per cycle from :attr:`next_cycle`)."""
        p = self.params
        x = p.check_samples(samples)
        if p.odd_levels:
            x = 2 * x + 1
        if p.complex_input:
            x, xq = np.ascontiguousarray(x[:, 0]), np.ascontiguousarray(x[:, 1])
        else:
            xq = x
        if cycles is None:
            scyc = np.arange(self.next_cycle, self.next_cycle + x.shape[0], dtype=np.int64)
        else:
            scyc = np.ascontiguousarray(cycles, dtype=np.int64)
        if scyc.shape != x.shape:
            raise ValueError(f"GNSS cycles must give one input cycle per sample ({x.size}), "
                             f"not shape {scyc.shape}")
        return x, xq, scyc

    def add_writes(self, writes, checked: bool = False) -> None:
        """Bus writes ``(channel, cycle, reg, value)`` (each value checked by the register
        map unless ``checked``: already checked by the caller), pending until their dump
        boundary."""
        _, _, regs, _ = _layout(self.params)
        if checked:
            w = [(int(ch), int(c), int(a), int(v)) for ch, c, a, v in writes]
        else:
            w = [(int(ch), int(c), int(a), regs.check_write(int(a), v))
                 for ch, c, a, v in writes]
        if not w:
            return
        allw = np.concatenate([self._writes, np.array(w, np.int64)])
        # per channel by cycle; a channel's writes of one cycle in the order given
        allw = allw[np.argsort(allw[:, 1], kind="stable")]
        self._writes = allw[np.argsort(allw[:, 0], kind="stable")]

    def advance(self, x, xq, scyc):
        """Every channel over prepared samples (:meth:`prepare`); returns the records'
        ``(FIFO input cycles, fields (n, 9), channels)``, channel by channel."""
        _, _, _, lat = _layout(self.params)
        cplx, K, d, cb, pb, trunc, emask = self._k
        wv = self._writes
        chans = np.arange(self.channels)
        wstart = np.searchsorted(wv[:, 0], chans, "left")
        wend = np.searchsorted(wv[:, 0], chans, "right")
        rec_cyc, rec_f, nrec = empty_records(self.channels, x.shape[0])
        kern = array_kernel_parallel if self.parallel else array_kernel
        kern(x, xq, cplx, scyc, np.ascontiguousarray(wv[:, 1]),
                     np.ascontiguousarray(wv[:, 2]), np.ascontiguousarray(wv[:, 3]), wstart,
                     wend, self.state, self.ring, self._table, self._cos, self._sin, K, d, cb,
                     pb, trunc, emask, lat, rec_cyc, rec_f, nrec)
        if wv.shape[0]:             # drop the writes applied
            self._writes = wv[np.arange(wv.shape[0]) >= wstart[wv[:, 0]]]
        self.n_samples += x.shape[0]
        if x.shape[0]:
            self.next_cycle = int(scyc[-1]) + 1
        if self.channels == 1:
            k = int(nrec[0])
            return rec_cyc[0, :k].copy(), rec_f[0, :k].copy(), np.zeros(k, np.int64)
        have = np.arange(rec_cyc.shape[1])[None, :] < nrec[:, None]
        return rec_cyc[have], rec_f[have], np.repeat(chans, nrec)


class GnssChannelModel:
    """Bit-exact model of the correlator core of one channel, chunk by chunk.

    ``step(samples, writes, cycles=...)`` advances over consecutive ADC samples; the state
    (NCOs, code generator, delay line, accumulators, shadow registers, writes not yet
    applied) is carried to the next call, so a run split into chunks gives the same bits.

    Parameters
    ----------
    params : GnssChannelParams
    """

    def __init__(self, params: GnssChannelParams):
        self.params = params
        self.bank = ChannelBank(params, 1)
        #: the state vector (:mod:`hdl.gnss.kernel`) and delay line
        self.state, self.ring = self.bank.state[0], self.bank.ring[0]

    @property
    def n_samples(self) -> int:
        return self.bank.n_samples

    @property
    def next_cycle(self) -> int:
        return self.bank.next_cycle

    def step(self, samples, writes=(), *, cycles=None) -> ChannelRecords:
        """Advance over ``samples``.

        Parameters
        ----------
        samples : array of int
            ADC words (signed ``adc_bits``), in order: real input, a 1-D array; complex input
            (``input="complex"``), an ``(n, 2)`` array of ``(I, Q)`` pairs
            (:meth:`GnssChannelParams.check_samples`).
        writes : iterable of (cycle, reg, value)
            Register writes on the bus (cycle from reset; ``reg`` 0-3 = :data:`REG_CARR_FREQ`
            ...); a write takes effect at the first dump boundary in a later cycle, in this
            or a later step.
        cycles : array of int, optional
            Input cycle of each sample (default: one per cycle, continuing from the last
            step).
        """
        x, xq, scyc = self.bank.prepare(samples, cycles)
        self.bank.add_writes((0, c, a, v) for c, a, v in writes)
        cyc, fields, _ = self.bank.advance(x, xq, scyc)
        return ChannelRecords(cyc, fields)


# -- whole channel / array with the FIFO ---------------------------------------------------

@dataclass
class ChannelRun:
    """Model prediction of a channel's (or array's) FIFO output."""

    words: np.ndarray           #: packed FIFO output words (payload | tag << width)
    cycles: np.ndarray          #: their output cycles
    record_cycles: np.ndarray   #: FIFO input cycle of each record
    records: list               #: record values (ints), in FIFO input order
    dropped: np.ndarray


class Arbiter:
    """The array's arbiter, chunk by chunk.

    A record pending from cycle ``r`` (per channel at most one at a time) is granted in the
    first cycle ``>= r`` in which no lower channel is pending and at least ``spacing``
    cycles (the FIFO's ``record_words``: it writes one word per cycle) have passed since the
    previous grant; it reaches the FIFO input two cycles after its grant (one-hot select
    register, then the multiplexed record register). Grants are only decided
    below a *horizon* (no later record can be pending before it); the rest wait for the next
    :meth:`feed`.
    """

    def __init__(self, spacing: int = 1):
        self.spacing = int(spacing)
        self.t = -(1 << 62)            # earliest cycle of the next grant
        self.waiting: list = []        # (ready, channel, value) not granted yet

    def feed(self, ready_cycles, channels, values, horizon: int | None = None):
        """Add records, grant what can be decided; returns (FIFO input cycles, values)."""
        import heapq
        w = sorted(self.waiting + [(int(r), int(c), v) for r, c, v in
                                   zip(ready_cycles, channels, values)],
                   key=lambda e: (e[0], e[1]))
        lim = (1 << 62) if horizon is None else int(horizon)
        pend: list = []
        out_c, out_v = [], []
        k, t = 0, self.t
        while True:
            if not pend:
                if k >= len(w):
                    break
                t = max(t, w[k][0])
            if t >= lim:
                break
            while k < len(w) and w[k][0] <= t:
                heapq.heappush(pend, (w[k][1], w[k][0], k))
                k += 1
            _, _, j = heapq.heappop(pend)
            out_c.append(t + 2)
            out_v.append(w[j][2])
            t += self.spacing
        self.t = t
        self.waiting = [w[j] for _, _, j in pend] + w[k:]
        return np.array(out_c, np.int64), out_v


def arbitrate(ready_cycles, channels, spacing: int = 1) -> np.ndarray:
    """FIFO input cycles the :class:`Arbiter` gives records pending from ``ready_cycles``
    (same order as given)."""
    idx = list(range(len(ready_cycles)))
    c, v = Arbiter(spacing).feed(ready_cycles, channels, idx)
    out = np.empty(len(idx), np.int64)
    out[np.asarray(v, np.int64)] = c
    return out


class GnssArrayModel:
    """Bit-exact model of :class:`hdl.gnss.channel.GnssChannelArray` (``channels = 1``
    without arbiter and channel field: :class:`hdl.gnss.channel.GnssChannel`).

    ``step(samples, writes, cycles=...)`` returns the records of the chunk with their FIFO
    input cycles (state carried, chunks give the same bits); :meth:`run` is a whole run from
    reset including the FIFO (:func:`hdl.model.fifo.fifo_model_events`). The channels run in
    one compiled call per step (:class:`ChannelBank`), on numba's threads with
    ``parallel=True`` (the same bits; it pays on otherwise idle cores).
    """

    def __init__(self, params: GnssChannelParams, channels: int = 1, *, arbiter=None,
                 parallel: bool = False):
        self.params = params
        self.channels = channels
        self.arbiter = channels > 1 if arbiter is None else arbiter
        self.bank = ChannelBank(params, channels, parallel)
        self._arb = Arbiter(_fifo(params).record_words)
        self._held_ids = np.zeros(0, np.int64)          # records waiting for the arbiter
        self._held = np.zeros((0, _fifo(params).record_words), np.int64)
        self._next_id = 0
        self.fifo_state = FifoState()

    def step(self, samples, writes=(), *, cycles=None):
        """Advance every channel over ``samples``; writes are ``(cycle, addr, value)`` with
        ``addr = 4 * channel + reg``. Returns ``(fifo_input_cycles, record_values)`` of the
        records decided so far (in the array, records the arbiter cannot grant yet because a
        later chunk may hold a lower channel's record wait for the next step or
        :meth:`flush`)."""
        rc, words = self.step_words(samples, writes, cycles=cycles)
        return rc, words_to_values(self.params, words)

    def step_words(self, samples, writes=(), *, cycles=None, checked: bool = False):
        """:meth:`step` with the records as FIFO words, ``(n, record_words)`` int64;
        ``checked``: the writes' values were checked by the register map already."""
        w = []
        for c, a, v in writes:
            ch, reg = divmod(int(a), 4)
            if not 0 <= ch < self.channels:
                raise ValueError(f"GNSS register address {a} is beyond {self.channels} "
                                 f"channels")
            w.append((ch, c, reg, v))
        # the samples are checked once for every channel (all at the same cycle)
        x, xq, scyc = self.bank.prepare(samples, cycles)
        self.bank.add_writes(w, checked)
        cyc, fields, chans = self.bank.advance(x, xq, scyc)
        words = record_words(self.params, fields, chans)
        if self.arbiter:
            # A later sample (cycle >= next_cycle) makes a record pending from
            # next_cycle + latency + 1 at the earliest.
            horizon = self.bank.next_cycle + _layout(self.params)[3] + 1
            return self._grant(cyc + 1, chans, words, horizon)
        order = np.argsort(cyc, kind="stable")
        return cyc[order], words[order]

    def _grant(self, ready, chans, words, horizon):
        """The arbiter's grants (FIFO input cycles, words) of the records waiting and the
        new ones (``words``, pending from ``ready``); the rest are held."""
        ids = np.arange(self._next_id, self._next_id + words.shape[0], dtype=np.int64)
        self._next_id += words.shape[0]
        held_ids = np.concatenate([self._held_ids, ids])
        held = np.concatenate([self._held, words])
        rc, got = self._arb.feed(ready, chans, ids.tolist(), horizon)
        at = np.searchsorted(held_ids, np.asarray(got, np.int64))
        keep = np.ones(held_ids.size, bool)
        keep[at] = False
        out = held[at]
        self._held_ids, self._held = held_ids[keep], held[keep]
        return rc, out

    def flush(self):
        """Grant every record still waiting (end of the run)."""
        rc, words = self.flush_words()
        return rc, words_to_values(self.params, words)

    def flush_words(self):
        """:meth:`flush` with the records as FIFO words."""
        if not self.arbiter:
            return np.zeros(0, np.int64), np.zeros((0, _fifo(self.params).record_words),
                                                   np.int64)
        return self._grant(np.zeros(0, np.int64), np.zeros(0, np.int64),
                           np.zeros((0, self._held.shape[1]), np.int64), None)

    def run(self, samples, writes=(), *, n_cycles: int, out_ready=None,
            cycles=None) -> ChannelRun:
        """One whole run from reset: records, then the FIFO over ``n_cycles`` cycles."""
        rc, words = self.step_words(samples, writes, cycles=cycles)
        rc2, words2 = self.flush_words()
        rc = np.concatenate([rc, rc2])
        recs = np.concatenate([words, words2])
        keep = rc < n_cycles
        rc, recs = rc[keep], recs[keep]
        fp = _fifo(self.params)
        vals = words_to_values(self.params, recs)
        ready = np.ones(n_cycles, bool) if out_ready is None else \
            np.asarray(out_ready, bool)[:n_cycles]
        if ready.size < n_cycles:
            ready = np.concatenate([ready, np.ones(n_cycles - ready.size, bool)])
        res = fifo_model_events(rc, recs, n_cycles, ready, fp, state=self.fifo_state)
        self.fifo_state = res.state
        return ChannelRun(res.words, res.cycles, rc, vals, res.dropped)
