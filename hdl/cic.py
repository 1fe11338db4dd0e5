"""CIC decimator (Hogenauer), pipelined, real or complex, with optional register pruning.

The parameters, widths, pruning and the bit-exact model are in :mod:`hdl.model.cic`.
"""
from __future__ import annotations

from amaranth.hdl import Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from hdl.model.cic import CicParams

__all__ = ["Cic", "sample_shape", "channel_values", "round_shift", "fit_width"]


def sample_shape(width: int, channels: int):
    """``signed(width)`` for real samples, ``StructLayout({"i", "q"})`` for complex ones."""
    if channels == 1:
        return signed(width)
    return data.StructLayout({"i": signed(width), "q": signed(width)})


def channel_values(payload, channels: int) -> list:
    """The per-channel signed values of a stream payload (real: [x]; complex: [i, q])."""
    if channels == 1:
        return [payload]
    return [payload.i, payload.q]


def round_shift(value, shift: int, rounding: str):
    """``value`` (signed) shifted right by ``shift`` bits with ``dsp.fixed`` rounding.

    One adder (floor: none); the result is one bit wider than ``value >> shift`` so a
    rounding carry is never lost (the caller applies the overflow mode).
    """
    if shift <= 0:
        return value << -shift if shift < 0 else value
    if rounding == "floor":
        return value >> shift
    if rounding == "half_up":
        return (value + Const(1 << (shift - 1), unsigned(shift))) >> shift
    if rounding == "zero":
        bias = Mux(value[-1], Const((1 << shift) - 1, unsigned(shift)), 0)
        return (value + bias) >> shift
    if rounding == "half_even":
        # q = value >> shift; adding half - 1 + lsb(q) rounds ties to even.
        return (value + Const((1 << (shift - 1)) - 1, unsigned(shift)) + value[shift]) >> shift
    raise ValueError(f"rounding must be one of floor, half_up, half_even, zero, not {rounding!r}")


def fit_width(value, width: int, overflow: str):
    """``value`` (signed) brought into ``width`` signed bits by saturation or wraparound."""
    if len(value) <= width:
        return value
    if overflow == "wrap":
        return value[:width].as_signed()
    hi, lo = (1 << (width - 1)) - 1, -(1 << (width - 1))
    return Mux(value > hi, Const(hi, signed(width)),
               Mux(value < lo, Const(lo, signed(width)), value[:width].as_signed()))


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
        if not isinstance(params, CicParams):
            self._MustUse__silence = True   # a half-built component is not an "unused" one
            raise TypeError(f"Cic takes a CicParams, not {type(params).__name__}")
        self.params = params
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
