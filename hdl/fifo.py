"""FIFO towards the DSP, with counted drops and in-band gap markers.

Word format (LSB first): ``width`` payload bits, then a 2-bit tag (0 = data word,
2 = marker whose payload is the number of words dropped just before it, saturating at
``2**width - 1``; 1 and 3 reserved), then with ``parity`` an even-parity bit over the word,
computed at the write side and stored with it. The drop/marker policy and the model are in
:mod:`hdl.model.fifo`.
"""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Signal, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.fifo import AsyncFIFOBuffered, SyncFIFOBuffered
from amaranth.lib.wiring import In, Out

from hdl.model.fifo import TAG_DATA, TAG_MARKER, FifoParams

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
    i : In(stream.Signature(unsigned(width), always_ready=True)), write domain
        Words from the front end (the peak search cannot be stalled).
    o : Out(stream.Signature(StructLayout({"payload": unsigned(width), "tag": unsigned(2)}))),
        read domain
        Tagged words with a real ``ready`` (the DSP). SyncFIFOBuffered: a word written to an
        empty queue is offered 2 cycles later.
    overflow_count : Out(unsigned(count_width))
        Words dropped since reset, saturating. Synchronous: write domain, updated the cycle
        after the drop. Asynchronous: in the read domain, Gray-coded across; it lags by at
        most 1 write-clock + 3 read-clock cycles and every value it shows was true.
    """

    def __init__(self, params: FifoParams | None = None):
        self.params = params if params is not None else FifoParams()
        p = self.params
        fields = {"payload": unsigned(p.width), "tag": unsigned(2)}
        if p.parity:
            fields["parity"] = unsigned(1)
        self.out_layout = data.StructLayout(fields)
        super().__init__({
            "i": In(stream.Signature(unsigned(p.width), always_ready=True)),
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
        m.submodules.fifo = fifo

        hold_v = Signal()
        hold_d = Signal(unsigned(p.width))
        pending = Signal(unsigned(p.width))
        ovf = Signal(unsigned(p.count_width))
        drop = Signal()
        iv = self.i.valid
        word = self.i.payload

        def put(payload, tag):
            w = Cat(payload, Const(tag, 2))
            if p.parity:
                w = Cat(w, w.xor())
            m.d.comb += [fifo.w_en.eq(1), fifo.w_data.eq(w)]

        with m.If(hold_v):
            with m.If(fifo.w_rdy):
                put(hold_d, TAG_DATA)
                with m.If(iv & (pending == 0)):
                    m.d[wd] += hold_d.eq(word)
                with m.Else():
                    m.d[wd] += hold_v.eq(0)
                    m.d.comb += drop.eq(iv)
            with m.Else():
                m.d.comb += drop.eq(iv)
        with m.Elif(pending != 0):
            with m.If(fifo.w_rdy):
                put(pending, TAG_MARKER)
                m.d[wd] += pending.eq(0)
                with m.If(iv):
                    m.d[wd] += [hold_v.eq(1), hold_d.eq(word)]
            with m.Else():
                m.d.comb += drop.eq(iv)
        with m.Elif(iv):
            with m.If(fifo.w_rdy):
                put(word, TAG_DATA)
            with m.Else():
                m.d.comb += drop.eq(1)

        with m.If(drop):
            # pending is never cleared in a cycle that drops (the marker needs w_rdy).
            with m.If(pending != p.marker_max):
                m.d[wd] += pending.eq(pending + 1)
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
