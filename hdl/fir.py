"""Symmetric (type I) FIR decimator / CIC droop compensator, pipelined.

Two architectures with the same output values (only the latency differs), chosen by
``FirParams.input_spacing``: fully parallel (one multiplier per distinct non-zero tap, one
sample per cycle) or, when the input cadence guarantees S >= 2 cycles between samples,
time-shared (each multiplier does S taps per sample). The parameters, coefficient
quantisation, widths and the bit-exact model are in :mod:`hdl.model.fir`.
"""
from __future__ import annotations

from amaranth.hdl import Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from hdl.common import channel_values, check_params, fit_width, round_shift, sample_shape
from hdl.model.fir import FirParams

__all__ = ["Fir"]


class Fir(wiring.Component):
    """Symmetric FIR with decimation: delay line, pre-adders, multipliers, adder tree.

    Parameters
    ----------
    params : FirParams
        Taps, coefficient width, decimation, widths, rounding, overflow, input spacing.

    Ports
    -----
    i : In(stream.Signature(shape, always_ready=True))
        Input samples, ``signed(in_width)`` or ``StructLayout({"i", "q"})`` of them; gaps
        in ``valid`` allowed; at most one per cycle (``input_spacing == 1``) or one per
        ``input_spacing`` cycles.
    o : Out(stream.Signature(shape, always_ready=True))
        Filtered samples, ``signed(out_width)`` (or i/q of them), one per ``decimation``
        inputs (the D-th, 2D-th, ... since reset), ``params.latency`` cycles after the input
        transfer that produced them.
    overrun : Out(1)
        Sticky: an input came while the time-shared multipliers were still busy with the
        previous sample (inputs closer than ``input_spacing``); cleared by reset only.
        Always 0 in the fully parallel architecture.

    Fully parallel pipeline (one register level each): delay line, pre-adders
    ``x[k] + x[L-1-k]``, multiplier input (operand limbs), multiplier output, a routing
    register away from the DSP block, ``tree_levels`` of two-input adders, rounding,
    overflow. Multipliers are built from 18x18 signed pieces (ECP5 MULT18X18D): an operand
    wider than 18 bits is split into 17-bit unsigned low limbs and a signed top limb
    (``FirParams.data_limbs``/``coef_limbs``), and the shifted pieces are leaves of the
    adder tree, so no cycle holds more than one DSP or one adder. Time-shared
    (``mux_factor`` T >= 2): each multiplier takes T pre-added pairs in turn (operand and
    coefficient chosen by a phase counter) into one accumulator per piece. The delay line
    shifts only on valid input; the rest runs every cycle with a valid bit alongside.
    Tree nodes and accumulators are kept at ``acc_width`` bits: the true sum fits, so
    two's-complement wraparound of partial sums cannot change it.
    """

    def __init__(self, params: FirParams):
        self.params = check_params(self, params, FirParams)
        super().__init__({
            "i": In(stream.Signature(sample_shape(params.in_width, params.channels),
                                     always_ready=True)),
            "o": Out(stream.Signature(sample_shape(params.out_width, params.channels),
                                      always_ready=True)),
            "overrun": Out(1),
        })

    def elaborate(self, platform):
        p = self.params
        m = Module()

        # Decimation: keep the D-th, 2D-th, ... input since reset.
        keep = Signal()
        if p.decimation == 1:
            m.d.comb += keep.eq(1)
        else:
            count = Signal(range(p.decimation))
            with m.If(self.i.valid):
                m.d.sync += count.eq(Mux(count == p.decimation - 1, 0, count + 1))
            m.d.comb += keep.eq(count == p.decimation - 1)

        lines = []
        for c, x in enumerate(channel_values(self.i.payload, p.channels)):
            line = [Signal(signed(p.in_width), name=f"line{c}_{k}") for k in range(p.numtaps)]
            with m.If(self.i.valid):
                m.d.sync += line[0].eq(x)
                for k in range(1, p.numtaps):
                    m.d.sync += line[k].eq(line[k - 1])
            lines.append(line)

        if p.mux_factor == 1:
            valid, sums = self._parallel(m, lines, keep)
        else:
            valid, sums = self._shared(m, lines, keep)

        # Tree over the per-multiplier results, then rounding and overflow registers.
        results = []
        for c, leaves in enumerate(sums):
            acc = self._tree(m, leaves, f"sum{c}")
            rounded = round_shift(acc, p.out_shift, p.rounding)
            r = Signal(signed(len(rounded)), name=f"round{c}")
            m.d.sync += r.eq(rounded)
            results.append(r)
        for _ in range(p.tree_levels + 1):
            v_next = Signal()
            m.d.sync += v_next.eq(valid)
            valid = v_next
        for o, r in zip(channel_values(self.o.payload, p.channels), results):
            m.d.sync += o.eq(fit_width(r, p.out_width, p.overflow))
        m.d.sync += self.o.valid.eq(valid)
        return m

    def _pair(self, line, t):
        """The symmetric pair sum feeding tap ``t`` (the centre tap has no partner)."""
        n = self.params.numtaps
        return line[t] if t == n // 2 else line[t] + line[n - 1 - t]

    def _multiply(self, m, a, coef, name):
        """``a * coef`` as 18x18 pieces, each with a registered input (limbs), a registered
        output and one more register for the route away from the DSP block; returns
        ``[(piece, shift)]`` whose shifted sum is the product (3 cycles after ``a``)."""
        p = self.params
        aw = p.acc_width
        if isinstance(coef, int):
            c_limbs = [(lsb, Const(v)) for lsb, _w, v in p.tap_coef_limbs(coef)]
        else:
            c_limbs = []
            for j, (lsb, w, sgn) in enumerate(p.coef_limbs):
                r = Signal(signed(w) if sgn else unsigned(w), name=f"{name}_c{j}")
                v = coef[lsb:lsb + w]
                m.d.sync += r.eq(v.as_signed() if sgn else v)
                c_limbs.append((lsb, r))
        pieces = []
        for i, (a_lsb, w, sgn) in enumerate(p.data_limbs):
            a_reg = Signal(signed(w) if sgn else unsigned(w), name=f"{name}_a{i}")
            v = a[a_lsb:a_lsb + w]
            m.d.sync += a_reg.eq(v.as_signed() if sgn else v)
            for j, (c_lsb, c) in enumerate(c_limbs):
                expr = a_reg * c
                prod = Signal(expr.shape(), name=f"{name}_p{i}{j}")
                sign_bit = 0 if expr.shape().signed else 1
                out = Signal(signed(min(aw, len(expr) + sign_bit)), name=f"{name}_q{i}{j}")
                m.d.sync += [prod.eq(expr), out.eq(prod)]
                pieces.append((out, a_lsb + c_lsb))
        return pieces

    def _leaves(self, pieces):
        """Shifted pieces as adder-tree leaves, at most ``acc_width`` bits (mod arithmetic)."""
        aw = self.params.acc_width
        out = []
        for sig, shift in pieces:
            v = sig << shift if shift else sig
            out.append(v[:aw].as_signed() if len(v) > aw else v)
        return out

    def _parallel(self, m, lines, keep):
        """Pre-adders and constant multipliers for every tap; returns (valid, leaves)."""
        p = self.params
        line_valid = Signal()
        m.d.sync += line_valid.eq(self.i.valid & keep)
        out = []
        for c, line in enumerate(lines):
            pieces = []
            for t in p.nonzero_taps:
                pre = Signal(signed(p.preadd_width), name=f"pre{c}_{t}")
                m.d.sync += pre.eq(self._pair(line, t))
                pieces += self._multiply(m, pre, t, f"mul{c}_{t}")
            out.append(self._leaves(pieces))
        valid = line_valid
        for _ in range(4):              # pre-add, multiplier in, out, routing
            v_next = Signal()
            m.d.sync += v_next.eq(valid)
            valid = v_next
        return valid, out

    def _shared(self, m, lines, keep):
        """Each multiplier takes ``mux_factor`` taps in turn; returns (valid, accumulators)."""
        p = self.params
        t_mux, k_mul = p.mux_factor, p.multipliers_per_channel
        taps = list(p.nonzero_taps) + [None] * (t_mux * k_mul - len(p.nonzero_taps))

        # Phase counter: phases 0..T-1 in the T cycles after a kept input.
        ph = Signal(range(t_mux))
        ph_valid = Signal()
        last = ph == t_mux - 1
        start = self.i.valid & keep
        with m.If(ph_valid & ~last):
            m.d.sync += ph.eq(ph + 1)
        with m.Else():
            m.d.sync += [ph.eq(0), ph_valid.eq(start)]
        # A shift of the delay line before the last phase would mix two samples.
        with m.If(self.i.valid & ph_valid & ~last):
            m.d.sync += self.overrun.eq(1)

        # Flags travel with the data (pre-add, multiplier in, out, routing): first and last
        # phase of a sample, any phase.
        first, lastf, valid = ph_valid & (ph == 0), ph_valid & last, ph_valid
        for _ in range(4):
            f, l, v = Signal(), Signal(), Signal()
            m.d.sync += [f.eq(first), l.eq(lastf), v.eq(valid)]
            first, lastf, valid = f, l, v
        done = Signal()
        m.d.sync += done.eq(lastf)
        out = []
        for c, line in enumerate(lines):
            accs = []
            for k in range(k_mul):
                pre = Signal(signed(p.preadd_width), name=f"pre{c}_{k}")
                coef = Signal(signed(p.coef_bits), name=f"coef{c}_{k}")
                with m.Switch(ph):
                    for s in range(t_mux):
                        t = taps[k * t_mux + s]
                        with m.Case(s):
                            if t is None:
                                m.d.sync += [pre.eq(0), coef.eq(0)]
                            else:
                                m.d.sync += [pre.eq(self._pair(line, t)),
                                             coef.eq(p.unique_taps[t])]
                for j, leaf in enumerate(self._leaves(self._multiply(m, pre, coef,
                                                                     f"mul{c}_{k}"))):
                    acc = Signal(signed(p.acc_width), name=f"acc{c}_{k}_{j}")
                    with m.If(valid):
                        m.d.sync += acc.eq(Mux(first, leaf, acc + leaf))
                    accs.append(acc)
            out.append(accs)
        return done, out

    def _tree(self, m, leaves, name):
        """Pairwise adder tree, one registered level at a time (``tree_levels`` levels)."""
        aw = self.params.acc_width
        level = 0
        while len(leaves) > 1:
            nxt = []
            for k in range(0, len(leaves) - 1, 2):
                a, b = leaves[k], leaves[k + 1]
                s = Signal(signed(min(aw, max(len(a), len(b)) + 1)), name=f"{name}_l{level}_{k // 2}")
                m.d.sync += s.eq(a + b)
                nxt.append(s)
            if len(leaves) % 2:
                s = Signal(signed(len(leaves[-1])), name=f"{name}_l{level}_pass")
                m.d.sync += s.eq(leaves[-1])
                nxt.append(s)
            leaves = nxt
            level += 1
        assert level == self.params.tree_levels
        return leaves[0]
