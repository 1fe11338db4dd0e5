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
0.5 chip at 16.368 MS/s). Logic 0 is the +1 replica, logic 1 is -1.

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
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from dsp.gnss.ca_code import ca_code_table
from dsp.jit import njit_cached
from hdl.model.fifo import FifoState, fifo_model_events
from hdl.model.nco import nco_full_tables
from .params import ACC_FIELDS, GnssChannelParams


# -- compiled kernel ---------------------------------------------------------------------
# int64 state vector layout
(_CODE_ACC, _CHIP, _HOLD, _CF, _PRN, _GEN_K, _GEN_EP, _GEN_FIRST, _CODE_EPOCH, _CARR_ACC,
 _CARR_F, _PEND_CARR, _CARR_AT, _CODE_AT, _EPOCH, _SH_CARR, _SH_CODE, _SH_PRN, _SH_SLEW,
 _SLEW_PEND, _POS, _ACC0) = range(22)
_NSTATE = _ACC0 + 6


@njit_cached(nogil=True)
def _channel_kernel(x, xq, cplx, scyc, wc, wa, wv, wi, st, ring, table, cos_t, sin_t, K, d,
                    code_bits, carr_bits, trunc, epoch_mask, lat, rec_cyc, rec_f):
    """Advance over samples ``x`` (complex input, ``cplx``: I in ``x``, Q in ``xq``; real:
    ``xq`` unused) at input cycles ``scyc``; returns (records, next write)."""
    L = 2 * d
    cmask = (1 << code_bits) - 1
    pmask = (1 << carr_bits) - 1
    nrec = 0
    for n in range(x.shape[0]):
        # -- replicas (generator state before this sample's update) --------------------
        prn = st[_PRN]
        row = prn if 1 <= prn <= 32 else 0
        bit_e = table[row, st[_CHIP]]
        pos = st[_POS]
        late = ring[pos]
        prompt = ring[(pos + d) % L]
        ring[pos] = bit_e | (st[_GEN_EP] << 1) | (st[_GEN_FIRST] << 2)
        st[_POS] = (pos + 1) % L
        bit_p = prompt & 1
        ep_p = (prompt >> 1) & 1
        first_p = (prompt >> 2) & 1
        bit_l = late & 1
        # -- carrier, wipe-off ----------------------------------------------------------
        ph = st[_CARR_ACC]
        a = ph >> trunc
        xi = x[n]
        if cplx:
            i = xi * cos_t[a] + xq[n] * sin_t[a]
            q = xq[n] * cos_t[a] - xi * sin_t[a]
        else:
            i = xi * cos_t[a]
            q = -xi * sin_t[a]
        if first_p:
            st[_CARR_AT] = ph
            st[_CODE_AT] = st[_CODE_EPOCH]
            st[_CARR_F] = st[_PEND_CARR]
        st[_CARR_ACC] = (ph + st[_CARR_F]) & pmask
        # -- integrate and dump ---------------------------------------------------------
        re = 1 - 2 * bit_e
        rp = 1 - 2 * bit_p
        rl = 1 - 2 * bit_l
        if ep_p:
            st[_EPOCH] = (st[_EPOCH] + 1) & epoch_mask
        if first_p:
            for j in range(6):
                rec_f[nrec, j] = st[_ACC0 + j]
            rec_f[nrec, 6] = st[_EPOCH]
            rec_f[nrec, 7] = st[_CARR_AT]
            rec_f[nrec, 8] = st[_CODE_AT]
            rec_cyc[nrec] = scyc[n] + lat
            nrec += 1
            st[_ACC0 + 0] = i * re
            st[_ACC0 + 1] = q * re
            st[_ACC0 + 2] = i * rp
            st[_ACC0 + 3] = q * rp
            st[_ACC0 + 4] = i * rl
            st[_ACC0 + 5] = q * rl
        else:
            st[_ACC0 + 0] += i * re
            st[_ACC0 + 1] += q * re
            st[_ACC0 + 2] += i * rp
            st[_ACC0 + 3] += q * rp
            st[_ACC0 + 4] += i * rl
            st[_ACC0 + 5] += q * rl
        # -- code NCO and generator update ------------------------------------------------
        wrap = 0
        if st[_HOLD] > 0:
            st[_HOLD] -= 1
        else:
            s = st[_CODE_ACC] + st[_CF]
            st[_CODE_ACC] = s & cmask
            if s >> code_bits:
                if st[_CHIP] == 1022:
                    st[_CHIP] = 0
                    wrap = 1
                else:
                    st[_CHIP] += 1
        st[_GEN_EP] = wrap
        st[_GEN_FIRST] = 0
        if wrap:
            st[_GEN_K] += 1
            if st[_GEN_K] == K:
                st[_GEN_K] = 0
            if st[_GEN_K] == 0:
                c = scyc[n]
                while wi < wc.shape[0] and wc[wi] < c:
                    r = wa[wi]
                    if r == 0:
                        st[_SH_CARR] = wv[wi]
                    elif r == 1:
                        st[_SH_CODE] = wv[wi]
                    elif r == 2:
                        st[_SH_PRN] = wv[wi]
                    else:
                        st[_SH_SLEW] = wv[wi]
                        st[_SLEW_PEND] = 1
                    wi += 1
                st[_CF] = st[_SH_CODE]
                st[_PRN] = st[_SH_PRN]
                st[_HOLD] = st[_SH_SLEW] if st[_SLEW_PEND] else 0
                st[_SLEW_PEND] = 0
                st[_PEND_CARR] = st[_SH_CARR]
                st[_CODE_EPOCH] = st[_CODE_ACC]
                st[_GEN_FIRST] = 1
    return nrec, wi


@functools.lru_cache(maxsize=64)
def _layout(params: GnssChannelParams):
    """(acc_width, record layout, register map, latency) of ``params``, derived once (the
    properties rebuild them on every access)."""
    return params.acc_width, params.record, params.registers, params.latency


@dataclass
class ChannelRecords:
    """Records a model step produced (before the FIFO)."""

    cycles: np.ndarray                   #: FIFO input cycle of each record
    fields: np.ndarray                   #: (n, 9) int64: ie qe ip qp il ql epoch carr code

    def values(self, params: GnssChannelParams, channel: int | None = None) -> list[int]:
        out = []
        w, layout, _, _ = _layout(params)
        for row in self.fields:
            d = {n: int(v) for n, v in zip(ACC_FIELDS, row[:6])}
            for n in ACC_FIELDS:   # the hardware's accumulators wrap
                d[n] = ((d[n] + (1 << (w - 1))) & ((1 << w) - 1)) - (1 << (w - 1))
            d.update(epoch=int(row[6]), carr_phase=int(row[7]), code_phase=int(row[8]))
            if params.channel_bits:
                d["channel"] = 0 if channel is None else int(channel)
            out.append(layout.pack(d))
        return out


class GnssChannelModel:
    """Bit-exact model of the correlator core of one channel, chunk by chunk.

    ``step(samples, writes, cycles=...)`` advances over consecutive ADC samples; the state
    (NCOs, code generator, delay line, accumulators, shadow registers, writes not yet
    applied) is carried to the next call, so a run split into chunks gives the same bits.

    Parameters
    ----------
    params : GnssChannelParams
    """

    _table = None

    def __init__(self, params: GnssChannelParams):
        self.params = p = params
        if GnssChannelModel._table is None:
            GnssChannelModel._table = ca_code_table().astype(np.int64)
        cos_t, sin_t = nco_full_tables(p.nco)
        self._cos, self._sin = cos_t.astype(np.int64), sin_t.astype(np.int64)
        self._trunc = p.nco.trunc_bits
        st = np.zeros(_NSTATE, np.int64)
        cw, kw = p.carr_word(p.if_hz), p.code_word()
        st[_CF] = st[_SH_CODE] = kw
        st[_PRN] = st[_SH_PRN] = p.prn
        st[_CARR_F] = st[_PEND_CARR] = st[_SH_CARR] = cw
        self.state = st
        self.ring = np.zeros(p.el_spacing_samples, np.int64)
        self._writes = np.zeros((0, 3), np.int64)
        self.n_samples = 0
        self.next_cycle = 0

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
        x, xq, scyc = self._prepare(samples, cycles)
        return self._advance(x, xq, scyc, writes)

    def _prepare(self, samples, cycles):
        """The checked samples (int64, the 1-bit map applied) as the kernel's ``I`` and ``Q``
        streams (real input: the one stream twice) and their input cycles."""
        p = self.params
        x = p.check_samples(samples)
        if p.odd_levels:
            x = 2 * x + 1
        if p.complex_input:
            x, xq = np.ascontiguousarray(x[:, 0]), np.ascontiguousarray(x[:, 1])
        else:
            xq = x
        if cycles is None:
            scyc = np.arange(self.next_cycle, self.next_cycle + x.size, dtype=np.int64)
        else:
            scyc = np.ascontiguousarray(cycles, dtype=np.int64)
        return x, xq, scyc

    def _advance(self, x, xq, scyc, writes) -> ChannelRecords:
        """:meth:`step` on prepared samples (:meth:`_prepare`)."""
        p = self.params
        _, _, regs, lat = _layout(p)
        w = [(int(c), int(a), regs.check_write(int(a), v)) for c, a, v in writes]
        if w:
            new = np.array(w, np.int64)
            allw = np.concatenate([self._writes, new])
            self._writes = allw[np.argsort(allw[:, 0], kind="stable")]
        wv = self._writes
        max_rec = x.size // 1000 + 2
        rec_cyc = np.zeros(max_rec, np.int64)
        rec_f = np.zeros((max_rec, 9), np.int64)
        if scyc.shape != x.shape:
            raise ValueError(f"GNSS cycles must give one input cycle per sample ({x.size}), "
                             f"not shape {scyc.shape}")
        nrec, wi = _channel_kernel(
            x, xq, p.complex_input, scyc, np.ascontiguousarray(wv[:, 0]), np.ascontiguousarray(wv[:, 1]),
            np.ascontiguousarray(wv[:, 2]), 0, self.state, self.ring, self._table, self._cos,
            self._sin, p.dump_epochs, p.half_spacing, p.code_phase_bits, p.carr_phase_bits,
            self._trunc, (1 << p.epoch_bits) - 1, lat, rec_cyc, rec_f)
        self._writes = wv[wi:]
        self.n_samples += x.size
        if x.size:
            self.next_cycle = int(scyc[-1]) + 1
        return ChannelRecords(rec_cyc[:nrec].copy(), rec_f[:nrec].copy())


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
    reset including the FIFO (:func:`hdl.model.fifo.fifo_model_events`).
    """

    def __init__(self, params: GnssChannelParams, channels: int = 1, *, arbiter=None):
        self.params = params
        self.channels = channels
        self.arbiter = channels > 1 if arbiter is None else arbiter
        self.models = [GnssChannelModel(params) for _ in range(channels)]
        self._arb = Arbiter(params.fifo.record_words)
        self.fifo_state = FifoState()

    def step(self, samples, writes=(), *, cycles=None):
        """Advance every channel over ``samples``; writes are ``(cycle, addr, value)`` with
        ``addr = 4 * channel + reg``. Returns ``(fifo_input_cycles, record_values)`` of the
        records decided so far (in the array, records the arbiter cannot grant yet because a
        later chunk may hold a lower channel's record wait for the next step or
        :meth:`flush`)."""
        per = [[] for _ in range(self.channels)]
        for c, a, v in writes:
            ch, reg = divmod(int(a), 4)
            if not 0 <= ch < self.channels:
                raise ValueError(f"GNSS register address {a} is beyond {self.channels} "
                                 f"channels")
            per[ch].append((c, reg, v))
        cyc, vals, chans = [], [], []
        # the samples are checked once for every channel (all at the same cycle)
        x, xq, scyc = self.models[0]._prepare(samples, cycles)
        recs = [m._advance(x, xq, scyc, w) for m, w in zip(self.models, per)]
        for ch, r in enumerate(recs):
            cyc.append(r.cycles)
            vals += r.values(self.params, ch)
            chans.append(np.full(r.cycles.size, ch))
        cyc = np.concatenate(cyc) if cyc else np.zeros(0, np.int64)
        chans = np.concatenate(chans) if chans else np.zeros(0, np.int64)
        if self.arbiter:
            # A later sample (cycle >= next_cycle) makes a record pending from
            # next_cycle + latency + 1 at the earliest.
            horizon = self.models[0].next_cycle + _layout(self.params)[3] + 1
            return self._arb.feed(cyc + 1, chans, vals, horizon)
        order = np.argsort(cyc, kind="stable")
        return cyc[order], [vals[j] for j in order]

    def flush(self):
        """Grant every record still waiting (end of the run)."""
        if not self.arbiter:
            return np.zeros(0, np.int64), []
        return self._arb.feed([], [], [], None)

    def run(self, samples, writes=(), *, n_cycles: int, out_ready=None,
            cycles=None) -> ChannelRun:
        """One whole run from reset: records, then the FIFO over ``n_cycles`` cycles."""
        rc, vals = self.step(samples, writes, cycles=cycles)
        rc2, vals2 = self.flush()
        rc = np.concatenate([rc, rc2])
        vals = list(vals) + list(vals2)
        keep = rc < n_cycles
        rc = rc[keep]
        vals = [v for v, k in zip(vals, keep) if k]
        p = self.params
        fp = p.fifo
        recs = np.array([p.record.to_words(v, fp.width, fp.record_words) for v in vals],
                        np.int64).reshape(-1, fp.record_words)
        ready = np.ones(n_cycles, bool) if out_ready is None else \
            np.asarray(out_ready, bool)[:n_cycles]
        if ready.size < n_cycles:
            ready = np.concatenate([ready, np.ones(n_cycles - ready.size, bool)])
        res = fifo_model_events(rc, recs, n_cycles, ready, fp, state=self.fifo_state)
        self.fifo_state = res.state
        return ChannelRun(res.words, res.cycles, rc, vals, res.dropped)
