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

        n = p.record_words
        # The words dropped since the last marker: pend_l counts them a cycle late, from a
        # register (drop_d), and pending -- what a marker carries -- adds the drop still in
        # flight. Counting straight from the drop decision put the width-bit increment and
        # its saturation compare at the end of the decision (hold_left -> fits -> pending,
        # the 12-channel array's critical path at 98.4 MHz).
        drop_d = Signal()
        pend_l = Signal(unsigned(p.width))
        pending = Signal(unsigned(p.width))
        m.d.comb += pending.eq(Mux(pend_l == p.marker_max, pend_l, pend_l + drop_d))
        m.d[wd] += pend_l.eq(pending)       # a marker written clears it (below)
        # pending != 0, kept in a register of its own (set wherever pending is): the 48-bit
        # compare was on the critical path of the monopulse record FIFO.
        pend_nz = Signal()
        ovf = Signal(unsigned(p.count_width))
        pend_nx = Signal()          # its next value
        m.d.comb += pend_nx.eq(pend_nz)
        m.d[wd] += pend_nz.eq(pend_nx)
        drop = Signal()
        if n == 1:
            self._words(m, fifo, wd, pending, pend_l, pend_nz, pend_nx, drop)
        else:
            self._records(m, fifo, wd, pending, pend_l, pend_nz, pend_nx, drop)

        # A drop sets pend_nz, also in the cycle that writes a marker (n > 1: the record
        # dropped behind it is the next marker's first).
        with m.If(drop):
            m.d.comb += pend_nx.eq(1)

        # The overflow counter counts the drops a cycle late too: its enable, straight from
        # the drop decision, was the critical path (79.5 MHz, a 6 ns wire to where the
        # counter was placed). The count shown, ovf, is still the count of every drop before
        # this cycle: the late counter plus the drop still in flight.
        ovf_l = Signal(unsigned(p.count_width))
        m.d[wd] += drop_d.eq(drop)
        with m.If(drop_d & (ovf_l != p.count_max)):
            m.d[wd] += ovf_l.eq(ovf_l + 1)
        m.d.comb += ovf.eq(Mux(ovf_l == p.count_max, ovf_l, ovf_l + drop_d))

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

    def _put(self, m, fifo, payload, tag):
        w = Cat(payload, tag if isinstance(tag, Value) else Const(tag, 2))
        if self.params.parity:
            w = Cat(w, w.xor())
        m.d.comb += [fifo.w_en.eq(1), fifo.w_data.eq(w)]

    def _words(self, m, fifo, wd, pending, pend_l, pend_nz, pend_nx, drop):
        """Single words (``record_words == 1``): the hold register keeps a word that waits
        behind a marker."""
        hold = Signal(unsigned(self.params.width))
        hold_v = Signal()
        iv, word = self.i.valid, self.i.payload
        with m.If(hold_v):
            with m.If(fifo.w_rdy):
                self._put(m, fifo, hold, TAG_DATA)
                with m.If(iv & ~pend_nz):
                    m.d[wd] += hold.eq(word)
                with m.Else():
                    m.d[wd] += hold_v.eq(0)
                    m.d.comb += drop.eq(iv)
            with m.Else():
                m.d.comb += drop.eq(iv)
        with m.Elif(pend_nz):
            with m.If(fifo.w_rdy):
                self._put(m, fifo, pending, TAG_MARKER)
                m.d[wd] += pend_l.eq(0)
                m.d.comb += pend_nx.eq(0)
                with m.If(iv):
                    m.d[wd] += [hold.eq(word), hold_v.eq(1)]
            with m.Else():
                m.d.comb += drop.eq(iv)
        with m.Elif(iv):
            with m.If(fifo.w_rdy):
                self._put(m, fifo, word, TAG_DATA)
            with m.Else():
                m.d.comb += drop.eq(1)

    def _records(self, m, fifo, wd, pending, pend_l, pend_nz, pend_nx, drop):
        """Records (``record_words = n > 1``): every decision starts at a register.

        A record is taken only when the queue memory can take all of its words and, when a
        word (the last of the previous record, or a marker) is written in the same cycle,
        that one too; so once taken a record is written a word per cycle without a stall,
        and ``w_rdy`` never enters the hold register's select, which fans out to every bit
        of a record (384 for the monopulse record; it was the critical path at 89.7 MHz).
        """
        p = self.params
        n, W = p.record_words, p.width
        iv, word = self.i.valid, self.i.payload
        cap = p.depth - 1               # memory words (SyncFIFOBuffered: + output register)
        # Words in the queue memory (SyncFIFOBuffered's level counts its output register
        # too: level - r_rdy), counted here with the queue's own rule (+ a write, - a move to
        # the output register) so that the flags below are compares on a register, each
        # registered with it: next value from compares of the current count, chosen by the
        # late inc/dec. A test checks all of them against the queue every cycle.
        used = self._used = Signal(range(p.depth), name="used")
        w_do = fifo.w_en & fifo.w_rdy
        r_do = (used != 0) & (~fifo.r_rdy | fifo.r_en)
        inc, dec = w_do & ~r_do, r_do & ~w_do
        with m.If(inc):
            m.d[wd] += used.eq(used + 1)
        with m.Elif(dec):
            m.d[wd] += used.eq(used - 1)

        def flag(name, limit):
            """Registered ``used <= limit`` (0 <= limit < cap; constant compares written as
            constants, which Verilator's lint flags)."""
            after_inc = used < limit if limit > 0 else Const(0)
            after_dec = used <= limit + 1 if limit + 1 < cap else Const(1)
            f = Signal(init=1, name=name)
            m.d[wd] += f.eq(Mux(inc, after_inc, Mux(dec, after_dec, used <= limit)))
            return f
        w_ok = self._w_ok = flag("w_ok", cap - 1)       # == fifo.w_rdy
        fits = self._fits = flag("fits", cap - n)       # the record: n words
        fits1 = self._fits1 = flag("fits1", cap - n - 1)    # a word now and the record

        # Next values of hold_left and pend_nz, so that the hold register's selects can be
        # registered from them.
        hold_left = self._hold_left = Signal(range(n + 1), name="hold_left")
        left_nx = Signal(range(n + 1))
        m.d.comb += left_nx.eq(hold_left)
        m.d[wd] += hold_left.eq(left_nx)
        hold = Signal(unsigned(p.in_width))
        with m.If(hold_left != 0):
            # w_rdy holds here: the record was taken with room for all of it.
            self._put(m, fifo, hold[:W], Mux(hold_left == n, Const(TAG_START, 2),
                                             Const(TAG_DATA, 2)))
            with m.If(iv & (hold_left == 1) & ~pend_nz & fits1):
                m.d.comb += left_nx.eq(n)
            with m.Else():
                m.d.comb += [left_nx.eq(hold_left - 1), drop.eq(iv)]
        with m.Elif(pend_nz):
            with m.If(w_ok):
                self._put(m, fifo, pending, TAG_MARKER)
                m.d[wd] += pend_l.eq(0)
                m.d.comb += pend_nx.eq(0)
                with m.If(iv):
                    with m.If(fits1):
                        m.d.comb += left_nx.eq(n)
                    with m.Else():
                        m.d.comb += drop.eq(1)
            with m.Else():
                m.d.comb += drop.eq(iv)
        with m.Elif(iv):
            with m.If(fits):
                self._put(m, fifo, word[:W], TAG_START)
                m.d.comb += left_nx.eq(n - 1)
            with m.Else():
                m.d.comb += drop.eq(1)

        # The hold register: the input record whole (taken behind the last word of the
        # previous one or behind a marker), its words after the first (taken with its first
        # word written at once), or shifted down a word. It is read only while hold_left != 0
        # and loads the input record whether or not it is taken. The two selects are
        # registers (from the next hold_left / pend_nz), each driving the whole record.
        whole = Signal(name="hold_whole")      # hold_left == 1 | (== 0 & pend_nz)
        rest = Signal(init=1, name="hold_rest")        # hold_left == 0 & ~pend_nz
        m.d[wd] += [whole.eq((left_nx == 1) | ((left_nx == 0) & pend_nx)),
                    rest.eq((left_nx == 0) & ~pend_nx)]
        with m.If(whole):
            m.d[wd] += hold.eq(word)
        with m.Elif(rest):
            m.d[wd] += hold.eq(word >> W)
        with m.Else():
            m.d[wd] += hold.eq(hold >> W)
