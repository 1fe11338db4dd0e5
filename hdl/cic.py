"""CIC decimator (Hogenauer), pipelined, real or complex, with optional register pruning.

The parameters, widths, pruning and the bit-exact model are in :mod:`hdl.model.cic`.
"""
from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal, signed
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from hdl.common import channel_values, check_params, fit_width, round_shift, sample_shape
from hdl.model.cic import CicParams

__all__ = ["Cic"]


class Cic(wiring.Component):
    """N-stage CIC decimator: integrators at the input rate, combs at the output rate.

    Parameters
    ----------
    params : CicParams
        Stages, rate, differential delay, widths, rounding, pruning (all widths are read
        from it).

    Ports
    -----
    i : In(stream.Signature(shape, always_ready=True))
        Input samples, ``signed(in_width)`` or ``StructLayout({"i", "q"})`` of them; one
        per cycle at most, gaps in ``valid`` allowed.
    o : Out(stream.Signature(shape, always_ready=True))
        Decimated samples, ``signed(out_width)`` (or i/q of them): one per R inputs, the
        R-th, 2R-th, ... input since reset; ``valid`` rises ``params.latency`` cycles after
        the input transfer that completes the group.

    Every stage is one adder between registers: integrator ``j`` adds the registered
    output of stage ``j-1`` (so the integrator chain is a pipeline, not a carry chain
    through N adders), combs update only on decimated samples. Integrators wrap in two's
    complement, which Hogenauer's width makes harmless.
    """

    def __init__(self, params: CicParams):
        self.params = check_params(self, params, CicParams)
        super().__init__({
            "i": In(stream.Signature(sample_shape(params.in_width, params.channels),
                                     always_ready=True)),
            "o": Out(stream.Signature(sample_shape(params.out_width, params.channels),
                                      always_ready=True)),
        })

    def elaborate(self, platform):
        p = self.params
        m = Module()
        n = p.stages
        lsbs = (0,) + p.stage_lsbs
        widths = p.stage_widths

        # Integrators: stage j accumulates the registered output of stage j-1.
        prev = channel_values(self.i.payload, p.channels)
        valid = self.i.valid
        for j in range(n):
            sh = lsbs[j + 1] - lsbs[j]
            v_next = Signal(name=f"int{j}_valid")
            regs = [Signal(signed(widths[j]), name=f"int{j}_{c}") for c in range(p.channels)]
            with m.If(valid):
                for acc, x in zip(regs, prev):
                    m.d.sync += acc.eq(acc + (x >> sh))
            m.d.sync += v_next.eq(valid)
            prev, valid = regs, v_next

        # Decimation: keep the R-th, 2R-th, ... sample since reset.
        count = Signal(range(p.rate))
        with m.If(valid):
            m.d.sync += count.eq(Mux(count == p.rate - 1, 0, count + 1))
        valid = valid & (count == p.rate - 1)

        # Combs at the output rate, each with its M-deep delay line.
        for j in range(n):
            k = n + j
            sh = lsbs[k + 1] - lsbs[k]
            v_next = Signal(name=f"comb{j}_valid")
            regs = []
            for c, x in enumerate(prev):
                xs = x >> sh
                delay = [Signal(signed(widths[k]), name=f"comb{j}_{c}_d{d}")
                         for d in range(p.diff_delay)]
                out = Signal(signed(widths[k]), name=f"comb{j}_{c}")
                with m.If(valid):
                    m.d.sync += delay[0].eq(xs)
                    for d in range(1, p.diff_delay):
                        m.d.sync += delay[d].eq(delay[d - 1])
                    m.d.sync += out.eq(xs - delay[-1])
                regs.append(out)
            m.d.sync += v_next.eq(valid)
            prev, valid = regs, v_next

        # Output: rounding register, then overflow register (a rounding carry at positive
        # full scale is the only way out of range).
        shift = p.out_shift - lsbs[2 * n]
        rounded = []
        v_round = Signal()
        for c, x in enumerate(prev):
            expr = round_shift(x, shift, p.rounding)
            r = Signal(signed(len(expr)), name=f"round_{c}")
            m.d.sync += r.eq(expr)
            rounded.append(r)
        m.d.sync += v_round.eq(valid)
        outs = channel_values(self.o.payload, p.channels)
        for o, r in zip(outs, rounded):
            m.d.sync += o.eq(fit_width(r, p.out_width, p.overflow))
        m.d.sync += self.o.valid.eq(v_round)
        return m
