"""FIFO towards the DSP, with counted drops and in-band gap markers.

Word format (LSB first): ``width`` payload bits, then a 2-bit tag (0 = data word,
2 = marker whose payload is the number of words dropped just before it, saturating at
``2**width - 1``; 1 and 3 reserved), then with ``parity`` an even-parity bit over the word,
computed at the write side and stored with it. With ``record_words = n > 1`` the input is a
record of ``n`` payloads in one cycle, queued as ``n`` words (the first tagged 1, start of
record) or dropped whole, and markers count records. The drop/marker policy and the model
are in :mod:`hdl.model.fifo`.
"""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.fifo import AsyncFIFOBuffered, SyncFIFOBuffered
from amaranth.lib.wiring import In, Out

from hdl.model.fifo import TAG_DATA, TAG_MARKER, TAG_START, FifoParams

__all__ = ["DspFifo", "FifoParams"]


def _gray_encode(v):
    return v ^ (v >> 1)


def _gray_decode(g):
    bits = [None] * len(g)
    acc = Const(0, 1)
    for k in reversed(range(len(g))):
        acc = acc ^ g[k]
        bits[k] = acc
    return Cat(*bits)


class DspFifo(wiring.Component):
    """Queue from the FPGA front end to the DSP; a full queue drops and reports, never stalls.

    Parameters
    ----------
    params : FifoParams

    Ports
    -----
    i : In(stream.Signature(unsigned(record_words * width), always_ready=True)), write domain
        Words (records: word ``j`` in bits ``[j * width, (j + 1) * width)``) from the front
        end (the peak search cannot be stalled).
    o : Out(stream.Signature(StructLayout({"payload": unsigned(width), "tag": unsigned(2)}))),
        read domain
        Tagged words with a real ``ready`` (the DSP). SyncFIFOBuffered: a word written to an
        empty queue is offered 2 cycles later.
    overflow_count : Out(unsigned(count_width))
        Words (records) dropped since reset, saturating. Synchronous: write domain, updated
        the cycle after the drop. Asynchronous: in the read domain, Gray-coded across; it
        lags by at most 1 write-clock + 3 read-clock cycles and every value it shows was true.
    """

    def __init__(self, params: FifoParams | None = None):
        self.params = params if params is not None else FifoParams()
        p = self.params
        fields = {"payload": unsigned(p.width), "tag": unsigned(2)}
        if p.parity:
            fields["parity"] = unsigned(1)
        self.out_layout = data.StructLayout(fields)
        super().__init__({
            "i": In(stream.Signature(unsigned(p.in_width), always_ready=True)),
            "o": Out(stream.Signature(self.out_layout)),
            "overflow_count": Out(unsigned(p.count_width)),
        })

    def elaborate(self, platform):
        p = self.params
        m = Module()
        wd = p.w_domain if p.asynchronous else "sync"
        if p.asynchronous:
            fifo = AsyncFIFOBuffered(width=p.word_width, depth=p.depth,
                                     w_domain=p.w_domain, r_domain=p.r_domain)
        else:
            fifo = SyncFIFOBuffered(width=p.word_width, depth=p.depth)
        m.submodules.fifo = self._queue = fifo

        n, W = p.record_words, p.width
        # Hold register: one record, shifted down a word per write; hold_left words to go.
        hold = Signal(unsigned(p.in_width))
        hold_left = Signal(range(n + 1))
        pending = Signal(unsigned(p.width))
        # pending != 0, kept in a register of its own (set wherever pending is): the 48-bit
        # compare was on the critical path of the monopulse record FIFO.
        pend_nz = Signal()
        ovf = Signal(unsigned(p.count_width))
        drop = Signal()
        marker_drop = Signal()      # the marker is written and the record dropped (n > 1)
        iv = self.i.valid
        word = self.i.payload
        if n == 1:
            fits = fifo.w_rdy
        else:
            # Free memory words: SyncFIFOBuffered's level counts its output register too, so
            # the memory holds level - r_rdy words. That count is kept here in a register of
            # its own (the same rule as the queue's inner level: + a write, - a move to the
            # output register), so the fit test is a compare on a register: through the
            # queue's level adder it was the critical path of the monopulse record FIFO
            # (89 MHz). A test checks used == level - r_rdy every cycle.
            k = p.depth - 1 - n
            used = self._used = Signal(range(p.depth), name="used")
            w_do = fifo.w_en & fifo.w_rdy
            r_do = (used != 0) & (~fifo.r_rdy | fifo.r_en)
            inc, dec = w_do & ~r_do, r_do & ~w_do
            with m.If(inc):
                m.d[wd] += used.eq(used + 1)
            with m.Elif(dec):
                m.d[wd] += used.eq(used - 1)
            # fits == (used <= k), registered with it: its next value from compares of the
            # current count (early) chosen by the late inc/dec, so the drop decision starts at
            # a register (the compare in front of it was the critical path, 95.1 MHz).
            fits = self._fits = Signal(init=1, name="fits")
            m.d[wd] += fits.eq(Mux(inc, used < k, Mux(dec, used <= k + 1, used <= k)))
        start_tag = TAG_START if n > 1 else TAG_DATA

        def put(payload, tag):
            w = Cat(payload, tag if isinstance(tag, Value) else Const(tag, 2))
            if p.parity:
                w = Cat(w, w.xor())
            m.d.comb += [fifo.w_en.eq(1), fifo.w_data.eq(w)]

        with m.If(hold_left != 0):
            with m.If(fifo.w_rdy):
                if n == 1:
                    put(hold[:W], TAG_DATA)
                else:
                    put(hold[:W], Mux(hold_left == n, Const(TAG_START, 2), Const(TAG_DATA, 2)))
                with m.If(iv & (hold_left == 1) & ~pend_nz & fits):
                    m.d[wd] += hold_left.eq(n)
                with m.Else():
                    m.d[wd] += hold_left.eq(hold_left - 1)
                    m.d.comb += drop.eq(iv)
            with m.Else():
                m.d.comb += drop.eq(iv)
        with m.Elif(pend_nz):
            with m.If(fifo.w_rdy):
                put(pending, TAG_MARKER)
                m.d[wd] += [pending.eq(0), pend_nz.eq(0)]
                with m.If(iv):
                    with m.If(fits):
                        m.d[wd] += hold_left.eq(n)
                    with m.Else():
                        m.d.comb += [drop.eq(1), marker_drop.eq(1)]
            with m.Else():
                m.d.comb += drop.eq(iv)
        with m.Elif(iv):
            with m.If(fits):
                put(word[:W], start_tag)
                if n > 1:
                    m.d[wd] += hold_left.eq(n - 1)
            with m.Else():
                m.d.comb += drop.eq(1)

        # The hold register's next value does not wait for the decision above (whether the
        # record fits, which comes through the queue level's adder): its content is read only
        # while hold_left != 0, and wherever the decision takes the input record the register
        # has loaded it (from the queue's point of view it is the same register). Its select
        # fans out to every bit of a record (384 for the monopulse record), which made the
        # fit -> hold path the critical one (77-88 MHz).
        with m.If(hold_left == 0):
            # a record taken now: whole behind a marker, or its words after the first
            m.d[wd] += hold.eq(Mux(pend_nz, word, word >> W) if n > 1 else word)
        with m.Elif(fifo.w_rdy):
            with m.If(hold_left == 1):
                m.d[wd] += hold.eq(word)        # the next record, if it is taken
            if n > 1:
                with m.Else():
                    m.d[wd] += hold.eq(hold >> W)

        with m.If(drop):
            with m.If(marker_drop):
                m.d[wd] += [pending.eq(1), pend_nz.eq(1)]
            # Otherwise pending is not cleared in a cycle that drops.
            with m.Elif(pending != p.marker_max):
                m.d[wd] += [pending.eq(pending + 1), pend_nz.eq(1)]
            with m.If(ovf != p.count_max):
                m.d[wd] += ovf.eq(ovf + 1)

        m.d.comb += [
            self.o.payload.eq(fifo.r_data),
            self.o.valid.eq(fifo.r_rdy),
            fifo.r_en.eq(self.o.ready),
        ]

        if p.asynchronous:
            # One bit changes per increment, so a sample taken mid-change is the old or the
            # new count, never a mix.
            ovf_gray = Signal(unsigned(p.count_width))
            m.d[wd] += ovf_gray.eq(_gray_encode(ovf))
            gray_r = Signal(unsigned(p.count_width))
            m.submodules.ovf_cdc = FFSynchronizer(ovf_gray, gray_r, o_domain=p.r_domain)
            m.d[p.r_domain] += self.overflow_count.eq(_gray_decode(gray_r))
        else:
            m.d.comb += self.overflow_count.eq(ovf)
        return m
