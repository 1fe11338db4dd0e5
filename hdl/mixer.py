"""Pipelined complex mixer ``y = x * exp(-j*phi)``; scaling and rounding in
:mod:`hdl.model.mixer`.

Pipeline (one register per line, so each multiplier has registered inputs and output; a
product of a narrow operand, such as a GNSS channel's 2-3 bit sample, is shifts and adds in
LUTs, a wider one an ECP5 MULT18X18D: :func:`hdl.common.narrow_mul`):

1. inputs (the real mixer negates ``sin`` here, so ``q`` is a plain product), then
   ``input_stages - 1`` more copies of them (timing: the last can sit beside the DSP block).
   With two or more stages, the registers of the last carry the ``keep`` attribute: mixers
   fed the same LO (several DDCs on one NCO) or the same samples (channels on one ADC
   stream) have identical copies, which yosys would otherwise merge into one register
   driving every mixer's multipliers (:mod:`cosim.tools.synth` keeps registers marked
   ``keep``);
2. products;
3. complex input only: sum / difference of the products;
4. rounding adder, arithmetic right shift by ``drop_bits``;
5. overflow (wrap or saturate) into the output register.
"""
from __future__ import annotations

from amaranth.hdl import Module, Signal, signed
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from .common import check_params, fit_width, iq_layout, lo_layout, narrow_mul, round_shift
from .model.mixer import MixerParams


def mixer_in_layout(params: MixerParams) -> data.StructLayout:
    """Mixer input payload: ``{"x": sample, "lo": {"cos", "sin"}}``, ``x`` at the LSB."""
    x = iq_layout(params.in_width) if params.complex_input else signed(params.in_width)
    return data.StructLayout({"x": x, "lo": lo_layout(params.lo_width)})


class Mixer(wiring.Component):
    """Complex mixer.

    Parameters
    ----------
    params : MixerParams

    Ports
    -----
    i : In(stream.Signature(mixer_in_layout(params), always_ready=True))
        ``x`` (real ``signed(in_width)`` or ``{"i","q"}``) with its LO ``{"cos","sin"}``
        (``signed(lo_width)`` each) in the same transfer.
    o : Out(stream.Signature(iq_layout(out_width), always_ready=True))
        ``x * exp(-j*phi)``, ``params.latency`` cycles (4 real, 5 complex) after the input.
    """

    def __init__(self, params: MixerParams):
        self.params = check_params(self, params, MixerParams)
        super().__init__({
            "i": In(stream.Signature(mixer_in_layout(params), always_ready=True)),
            "o": Out(stream.Signature(iq_layout(params.out_width), always_ready=True)),
        })

    @property
    def latency(self) -> int:
        return self.params.latency

    def elaborate(self, platform):
        p = self.params
        m = Module()
        a, b = p.in_width, p.lo_width
        pay = self.i.payload

        valid = self.i.valid
        stages = []  # valid of each register stage

        def stage():
            v = Signal(name=f"v{len(stages) + 1}")
            m.d.sync += v.eq(stages[-1] if stages else valid)
            stages.append(v)
            return v

        stage()
        if p.complex_input:
            xi, xq = Signal(signed(a)), Signal(signed(a))
            c, s = Signal(signed(b)), Signal(signed(b))
            m.d.sync += [xi.eq(pay.x.i), xq.eq(pay.x.q), c.eq(pay.lo.cos), s.eq(pay.lo.sin)]
            xi, xq, c, s = self._more_input_stages(m, stage, xi, xq, c, s)
            stage()
            pw = p.product_width
            pic, pqs, pqc, pis = (Signal(signed(pw), name=n) for n in ("p_ic", "p_qs", "p_qc", "p_is"))
            m.d.sync += [pic.eq(narrow_mul(xi, c)), pqs.eq(narrow_mul(xq, s)),
                         pqc.eq(narrow_mul(xq, c)), pis.eq(narrow_mul(xi, s))]
            stage()
            yi, yq = Signal(signed(p.sum_width)), Signal(signed(p.sum_width))
            m.d.sync += [yi.eq(pic + pqs), yq.eq(pqc - pis)]
        else:
            x, c = Signal(signed(a)), Signal(signed(b))
            sn = Signal(signed(b + 1))  # -sin: -(-2**(b-1)) needs b+1 bits
            m.d.sync += [x.eq(pay.x), c.eq(pay.lo.cos), sn.eq(-pay.lo.sin)]
            x, c, sn = self._more_input_stages(m, stage, x, c, sn)
            stage()
            yi, yq = Signal(signed(p.product_width)), Signal(signed(p.product_width))
            m.d.sync += [yi.eq(narrow_mul(x, c)), yq.eq(narrow_mul(x, sn))]

        stage()
        ri_val = round_shift(yi, p.drop_bits, p.rounding)
        rq_val = round_shift(yq, p.drop_bits, p.rounding)
        ri, rq = Signal(signed(len(ri_val))), Signal(signed(len(rq_val)))
        m.d.sync += [ri.eq(ri_val), rq.eq(rq_val)]

        ow = p.out_width

        def fit(r):
            # wrap: the assignment keeps the low bits (or sign-extends a narrow r)
            return fit_width(r, ow, "saturate") if p.overflow == "saturate" else r

        m.d.sync += [
            self.o.valid.eq(stages[-1]),
            self.o.payload.i.eq(fit(ri)),
            self.o.payload.q.eq(fit(rq)),
        ]
        return m

    def _more_input_stages(self, m, stage, *regs):
        """``input_stages - 1`` more register copies of the input registers ``regs`` (the
        last marked ``keep``)."""
        last = self.params.input_stages - 1
        for k in range(1, last + 1):
            stage()
            nxt = tuple(Signal.like(r, name=f"{r.name}_p{k}",
                                    attrs={"keep": 1} if k == last else {}) for r in regs)
            m.d.sync += [n.eq(r) for n, r in zip(nxt, regs)]
            regs = nxt
        return regs
