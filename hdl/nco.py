"""LUT numerically controlled oscillator with quarter-wave symmetry and optional phase dither.

Arithmetic, table and dither are specified in :mod:`hdl.model.nco` (module docstring); this
file only builds that in a 4-stage pipeline:

1. accumulate (``acc += freq``), add the ``phase`` offset, keep the top
   ``table_bits + dither_bits`` bits; take the dither word and step the LFSR;
2. add the signed dither, keep the top ``table_bits`` bits (the table address);
3. fold the address into the quarter table (XOR with the quadrant LSB) and read the ROM
   (two synchronous read ports of one block RAM);
4. register the ROM data (block-RAM clock-to-out is too slow to negate in the same cycle
   at 100 MHz on ECP5);
5. negate by quadrant, register the output.
"""
from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from .common import check_params, lo_layout
from .model.nco import LFSR_BITS, NcoParams, nco_quarter_table


class Nco(wiring.Component):
    """Quarter-wave LUT NCO.

    Parameters
    ----------
    params : NcoParams

    Ports
    -----
    i : In(stream.Signature(unsigned(0), always_ready=True))
        Step requests: every cycle with ``i.valid`` produces one output sample and then
        advances the phase by ``freq``. Gaps are allowed.
    freq : In(unsigned(phase_bits))
        Phase increment per step (two's complement for negative frequencies), sampled in
        the cycle of each step; see :func:`hdl.model.nco.nco_freq_word`.
    phase : In(unsigned(phase_bits)), only if ``params.phase_port``
        Phase offset added to the accumulator, sampled in the cycle of each step.
    o : Out(stream.Signature(lo_layout(amp_bits), always_ready=True))
        ``(cos, sin)`` of each step, ``params.latency`` (= 5) cycles after the step.
    """

    def __init__(self, params: NcoParams):
        self.params = params = check_params(self, params, NcoParams, article="an")
        members = {
            "i": In(stream.Signature(unsigned(0), always_ready=True)),
            "freq": In(unsigned(params.phase_bits)),
            "o": Out(stream.Signature(lo_layout(params.amp_bits), always_ready=True)),
        }
        if params.phase_port:
            members["phase"] = In(unsigned(params.phase_bits))
        super().__init__(members)

    @property
    def latency(self) -> int:
        return self.params.latency

    def elaborate(self, platform):
        p = self.params
        m = Module()
        P, T, D = p.phase_bits, p.table_bits, p.dither_bits
        qb = p.quarter_bits

        # -- stage 1: accumulator, offset, dither word --------------------------------
        acc = Signal(P)
        v1 = Signal()
        ph1 = Signal(T + D)
        with m.If(self.i.valid):
            m.d.sync += acc.eq(acc + self.freq)
        phase = acc + self.phase if p.phase_port else acc
        m.d.sync += [v1.eq(self.i.valid), ph1.eq(phase[p.dither_shift:P])]

        if D:
            lfsr = Signal(LFSR_BITS, init=p.dither_seed)
            d1 = Signal(signed(D))
            # D steps of s[m+63] = s[m] ^ s[m+1] at once; D <= 62 keeps every tap in the
            # current register.
            new_bits = Cat(*(lfsr[k] ^ lfsr[k + 1] for k in range(D)))
            with m.If(self.i.valid):
                m.d.sync += [lfsr.eq(Cat(lfsr[D:], new_bits)), d1.eq(lfsr[:D])]

        # -- stage 2: dither add, table address ----------------------------------------
        v2 = Signal()
        addr = Signal(T)
        m.d.sync += v2.eq(v1)
        if D:
            d_ext = Signal(T + D)  # sign-extended: the sum is only needed mod 2**(T+D)
            m.d.comb += d_ext.eq(d1)
            m.d.sync += addr.eq((ph1 + d_ext)[D:D + T])
        else:
            m.d.sync += addr.eq(ph1)

        # -- stage 3: quarter-wave fold, ROM read ----------------------------------------
        m.submodules.rom = rom = Memory(shape=unsigned(p.rom_width), depth=p.rom_depth,
                                        init=[int(v) for v in nco_quarter_table(p)])
        rd_sin = rom.read_port(domain="sync")
        rd_cos = rom.read_port(domain="sync")
        k = addr[:qb]
        q = addr[qb:]
        sin_addr = k ^ q[0].replicate(qb)
        m.d.comb += [rd_sin.addr.eq(sin_addr), rd_cos.addr.eq(~sin_addr)]
        v3 = Signal()
        sin_neg = Signal()
        cos_neg = Signal()
        m.d.sync += [v3.eq(v2), sin_neg.eq(q[1]), cos_neg.eq(q[1] ^ q[0])]

        # -- stage 4: ROM data register (the block RAM's clock-to-out is ~6 ns on ECP5) --
        v4 = Signal()
        sin_mag = Signal(p.rom_width)
        cos_mag = Signal(p.rom_width)
        sin_neg4 = Signal()
        cos_neg4 = Signal()
        m.d.sync += [v4.eq(v3), sin_mag.eq(rd_sin.data), cos_mag.eq(rd_cos.data),
                     sin_neg4.eq(sin_neg), cos_neg4.eq(cos_neg)]

        # -- stage 5: sign ---------------------------------------------------------------
        m.d.sync += [
            self.o.valid.eq(v4),
            self.o.payload.sin.eq(Mux(sin_neg4, -sin_mag, sin_mag)),
            self.o.payload.cos.eq(Mux(cos_neg4, -cos_mag, cos_mag)),
        ]
        return m
