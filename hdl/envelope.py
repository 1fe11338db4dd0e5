"""Envelope (magnitude) of a complex stream by pipelined CORDIC vectoring.

See :mod:`hdl.model.envelope` for the algorithm, the output scaling and the bit-exact model.
"""
from __future__ import annotations

from amaranth.hdl import Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from hdl.common import check_params, iq_layout, round_shift
from hdl.model.envelope import EnvelopeParams

__all__ = ["Envelope", "EnvelopeParams"]


class Envelope(wiring.Component):
    """Magnitude ``|i + jq|`` by CORDIC vectoring, one sample per cycle.

    ``mag_out ~= eff_gain * |z| / 2**shift`` (``eff_gain`` = CORDIC gain ~1.6468 by default,
    ~1 with ``compensate=True``; see :class:`EnvelopeParams`).

    Parameters
    ----------
    params : EnvelopeParams

    Ports
    -----
    i : In(stream.Signature(StructLayout({"i": signed(in_width), "q": signed(in_width)}),
           always_ready=True))
        Complex input samples; gaps in ``valid`` are allowed.
    o : Out(stream.Signature(unsigned(out_width), always_ready=True))
        Magnitude, ``params.latency`` cycles after the input (1 fold stage, one stage per
        iteration, 1 rounding/saturation stage, +2 for the compensation multiplier).
        The pipeline advances every cycle; ``valid`` travels alongside the data.
    """

    def __init__(self, params: EnvelopeParams | None = None):
        self.params = check_params(self, EnvelopeParams() if params is None else params,
                                   EnvelopeParams)
        p = self.params
        layout = iq_layout(p.in_width)
        super().__init__({
            "i": In(stream.Signature(layout, always_ready=True)),
            "o": Out(stream.Signature(unsigned(p.out_width), always_ready=True)),
        })

    def elaborate(self, platform):
        p = self.params
        m = Module()
        ww = p.work_width

        # Stage 0: first-quadrant fold and guard bits. |-2**(w-1)| needs w unsigned bits.
        xi, yi = self.i.payload.i, self.i.payload.q
        x = Signal(signed(ww), name="x0")
        y = Signal(signed(ww), name="y0")
        v = Signal(name="v0")
        ax = Mux(xi[-1], -xi, xi).as_unsigned()[:p.in_width]
        ay = Mux(yi[-1], -yi, yi).as_unsigned()[:p.in_width]
        m.d.sync += [
            x.eq(ax << p.guard_bits),
            y.eq(ay << p.guard_bits),
            v.eq(self.i.valid),
        ]

        for k in range(p.iterations):
            xn = Signal(signed(ww), name=f"x{k + 1}")
            yn = Signal(signed(ww), name=f"y{k + 1}")
            vn = Signal(name=f"v{k + 1}")
            # Arithmetic shifts (floor), as the model's ``>>`` on int64.
            with m.If(~y[-1]):
                m.d.sync += [xn.eq(x + (y >> k)), yn.eq(y - (x >> k))]
            with m.Else():
                m.d.sync += [xn.eq(x - (y >> k)), yn.eq(y + (x >> k))]
            m.d.sync += vn.eq(v)
            x, y, v = xn, yn, vn

        # x >= 0 here (it only grows from a non-negative start while y shrinks).
        mag = x.as_unsigned()[:ww - 1]
        if p.compensate:
            # Registered multiplier inputs and output (ECP5 DSP-friendly).
            a = Signal(unsigned(ww - 1))
            prod = Signal(unsigned(ww - 1 + p.comp_bits))
            va, vp = Signal(), Signal()
            m.d.sync += [a.eq(mag), va.eq(v)]
            m.d.sync += [prod.eq(a * Const(p.comp_const, unsigned(p.comp_bits))), vp.eq(va)]
            mag, v = prod, vp

        q = Signal(unsigned(len(mag) + 1))
        m.d.comb += q.eq(round_shift(mag, p.total_shift, p.rounding))
        out = Signal(unsigned(p.out_width), name="mag")
        ov = Signal()
        m.d.sync += [
            out.eq(Mux(q > p.max_out, p.max_out, q[:p.out_width])),
            ov.eq(v),
        ]
        m.d.comb += [self.o.payload.eq(out), self.o.valid.eq(ov)]
        return m
