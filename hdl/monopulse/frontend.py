"""Monopulse FPGA front end: shared NCO, 4 DDC/CIC(/FIR) channels, correction, beams,
matched-filter accumulation, angle unit (CORDIC), record FIFO. One ``sync`` clock.

Arithmetic, registers, record and timing are specified in :mod:`hdl.monopulse.model`
(module docstring); this file builds it from the shared blocks (:class:`hdl.nco.Nco`,
:class:`hdl.ddc.Ddc` with ``external_lo``, :class:`hdl.cic.Cic`, :class:`hdl.fir.Fir`,
:class:`hdl.mixer.Mixer` as the complex correction multiplier, :class:`hdl.fifo.DspFifo`).
"""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..cic import Cic
from ..common import check_params, fit_width, round_shift
from ..ddc import Ddc
from ..fifo import DspFifo
from ..fir import Fir
from ..mixer import Mixer
from ..nco import Nco
from .params import MonopulseFrontendParams

__all__ = ["MonopulseFrontEnd", "monopulse_top"]


class MonopulseFrontEnd(wiring.Component):
    """The monopulse front end from four ADC streams to measurement records for the DSP.

    Parameters
    ----------
    params : MonopulseFrontendParams

    Ports
    -----
    i : In(stream.Signature(unsigned(4 * adc_bits + 1), always_ready=True))
        One sample of the four ADCs (channel ``j`` in bits ``[j b, (j + 1) b)``, signed) and
        the replica bit of its chip (bit ``4 b``; 0 = +1, 1 = -1); gaps in ``valid`` allowed.
    reg_we, reg_addr (3 bits), reg_data (``reg_data_width`` bits) : In
        Register bus (:attr:`~hdl.monopulse.params.MonopulseFrontendParams.registers`);
        a write when ``reg_we`` is high, into the shadow registers.
    o : Out(stream.Signature(DspFifo out layout))
        Tagged FIFO words, ``record_words`` per record (the first tagged 1), real ``ready``.
    overflow_count : Out(unsigned(fifo_count_bits))
        Records dropped because the FIFO was full (registered: one cycle after the drop).
    """

    def __init__(self, params: MonopulseFrontendParams | None = None):
        params = MonopulseFrontendParams() if params is None else params
        self.params = p = check_params(self, params, MonopulseFrontendParams)
        self._fifo = DspFifo(p.fifo)
        super().__init__({
            "i": In(stream.Signature(unsigned(4 * p.adc_bits + 1), always_ready=True)),
            "reg_we": In(1),
            "reg_addr": In(3),
            "reg_data": In(unsigned(p.reg_data_width)),
            "o": Out(stream.Signature(self._fifo.out_layout)),
            "overflow_count": Out(unsigned(p.fifo_count_bits)),
        })

    @property
    def latency(self) -> int:
        return self.params.latency

    def elaborate(self, platform):
        p = self.params
        m = Module()
        b = p.adc_bits
        pay = self.i.payload
        valid = self.i.valid

        # -- shared NCO, replica wipe-off on the LO ----------------------------------------
        m.submodules.nco = nco = Nco(p.nco)
        m.d.comb += [nco.i.valid.eq(valid), nco.freq.eq(p.nco_freq_word)]
        chip = pay[4 * b]
        for k in range(p.nco.latency):      # the NCO pipeline runs every cycle
            d = Signal(name=f"chip_d{k + 1}")
            m.d.sync += d.eq(chip)
            chip = d
        aw = p.nco.amp_bits
        lo_c, lo_s = Signal(signed(aw)), Signal(signed(aw))
        # The table is symmetric (|value| <= 2**(aw-1) - 1): the negation fits aw bits.
        m.d.comb += [lo_c.eq(Mux(chip, -nco.o.payload.cos, nco.o.payload.cos)),
                     lo_s.eq(Mux(chip, -nco.o.payload.sin, nco.o.payload.sin))]

        # -- registers --------------------------------------------------------------------
        cb = p.corr_coef_bits
        sh_re = [Signal(signed(cb), init=p.unit_coef, name=f"sh_re{c}") for c in range(4)]
        sh_im = [Signal(signed(cb), name=f"sh_im{c}") for c in range(4)]
        ac_re = [Signal(signed(cb), init=p.unit_coef, name=f"ac_re{c}") for c in range(4)]
        ac_im = [Signal(signed(cb), name=f"ac_im{c}") for c in range(4)]
        dcw = p.dc_bits
        sh_u0, sh_v0 = Signal(signed(dcw)), Signal(signed(dcw))
        ac_u0, ac_v0 = Signal(signed(dcw)), Signal(signed(dcw))
        rec_u0, rec_v0 = Signal(signed(dcw)), Signal(signed(dcw))
        we, regs = self.reg_we, p.registers

        def write(name):   # bus write of register ``name``: its data bits
            r = regs[name]
            return we & (self.reg_addr == r.address), self.reg_data[:r.width]

        for c in range(4):
            hit, bits = write(f"coef{c + 1}")
            with m.If(hit):
                m.d.sync += [sh_re[c].eq(bits[:cb]), sh_im[c].eq(bits[cb:2 * cb])]
        for name, sh in (("u0", sh_u0), ("v0", sh_v0)):
            hit, bits = write(name)
            with m.If(hit):
                m.d.sync += sh.eq(bits)

        # -- four channels: DDC, CIC, (FIR), correction ------------------------------------
        corr = []
        dec_valid = None
        for c in range(4):
            ddc = Ddc(p.ddc, external_lo=True)
            cic = Cic(p.cic)
            m.submodules[f"ddc{c}"] = ddc
            m.submodules[f"cic{c}"] = cic
            m.d.comb += [ddc.i.valid.eq(valid), ddc.i.payload.eq(pay[c * b:(c + 1) * b]),
                         ddc.lo.valid.eq(nco.o.valid), ddc.lo.payload.cos.eq(lo_c),
                         ddc.lo.payload.sin.eq(lo_s)]
            wiring.connect(m, ddc.o, cic.i)
            dec = cic.o
            if p.fir is not None:
                fir = Fir(p.fir)
                m.submodules[f"fir{c}"] = fir
                wiring.connect(m, cic.o, fir.i)
                dec = fir.o
            mix = Mixer(p.corr)
            m.submodules[f"corr{c}"] = mix
            nim = Signal(signed(cb), name=f"nim{c}")
            m.d.comb += [nim.eq(-ac_im[c]),
                         mix.i.valid.eq(dec.valid),
                         mix.i.payload.x.i.eq(dec.payload.i), mix.i.payload.x.q.eq(dec.payload.q),
                         mix.i.payload.lo.cos.eq(ac_re[c]), mix.i.payload.lo.sin.eq(nim)]
            corr.append(mix.o)
            dec_valid = dec.valid if dec_valid is None else dec_valid

        # -- snapshot count and block boundary (at the correction input) ------------------
        N = p.snapshots
        cnt = Signal(range(max(N, 2)))
        # first == (cnt == 0) and last == (cnt == N - 1) at every cycle, kept in registers
        # (no latency): last enables ~250 coefficient and steering bits, and through the
        # counter's compare it was the critical path at nextpnr seed 2 (99.9 MHz).
        first = Signal(init=1)
        last = Signal(init=N == 1)
        with m.If(dec_valid):
            m.d.sync += [cnt.eq(Mux(last, 0, cnt + 1)), first.eq(last),
                         last.eq(Mux(last, N == 1, cnt == N - 2) if N >= 2 else 1)]
            with m.If(last):
                m.d.sync += [a.eq(s) for a, s in zip(ac_re + ac_im, sh_re + sh_im)]
                m.d.sync += [ac_u0.eq(sh_u0), ac_v0.eq(sh_v0), rec_u0.eq(ac_u0),
                             rec_v0.eq(ac_v0)]
        f_first, f_last = first, last
        for k in range(p.corr.latency):     # the mixer pipeline runs every cycle
            a, z = Signal(name=f"first_d{k + 1}"), Signal(name=f"last_d{k + 1}")
            m.d.sync += [a.eq(f_first), z.eq(f_last)]
            f_first, f_last = a, z

        # -- beams ------------------------------------------------------------------------
        bw = p.beam_width
        w = [(o.payload.i, o.payload.q) for o in corr]
        beams = []
        bvalid, bfirst, blast = Signal(), Signal(), Signal()
        m.d.sync += [bvalid.eq(corr[0].valid), bfirst.eq(f_first), blast.eq(f_last)]
        names = ("s", "da", "de", "dd")
        exprs = {}
        for part, pn in ((0, "re"), (1, "im")):
            w1, w2, w3, w4 = (w[c][part] for c in range(4))
            exprs[("s", pn)] = (w1 + w2) + (w3 + w4)
            exprs[("da", pn)] = (w1 + w2) - (w3 + w4)
            exprs[("de", pn)] = (w1 + w3) - (w2 + w4)
            exprs[("dd", pn)] = (w1 + w4) - (w2 + w3)
        for n in names:
            for pn in ("re", "im"):
                s = Signal(signed(bw), name=f"beam_{n}_{pn}")
                m.d.sync += s.eq(exprs[(n, pn)])
                beams.append(s)

        # -- matched-filter accumulation ----------------------------------------------------
        W = p.acc_width
        accs = [Signal(signed(W), name=f"acc{j}") for j in range(8)]
        dump = [Signal(signed(W), name=f"dump{j}") for j in range(8)]
        dvalid = Signal()
        blk = Signal(p.block_bits)
        dblk = Signal(p.block_bits)
        m.d.sync += dvalid.eq(0)
        with m.If(bvalid):
            for a, bm, d in zip(accs, beams, dump):
                tot = Mux(bfirst, bm, a + bm)
                m.d.sync += a.eq(tot)
                with m.If(blast):
                    m.d.sync += d.eq(tot)
            with m.If(blast):
                m.d.sync += [dvalid.eq(1), dblk.eq(blk), blk.eq(blk + 1)]

        # -- angle unit ----------------------------------------------------------------------
        B = p.cordic_in_bits
        six = dump[:6]
        # S1: OR of the magnitudes (v XOR its sign): the width of the largest value.
        v1 = Signal()
        mm = Signal(W)
        orv = Const(0, W)
        for v in six:
            orv = orv | (v ^ v[-1].replicate(W))
        m.d.sync += [v1.eq(dvalid), mm.eq(orv)]
        # S2: thermometer code f_s = (r >= s): some bit at or above B - 2 + s (s = 1 .. W - B).
        nsh = max(0, W - B)
        v2 = Signal()
        thermo = Signal(max(1, nsh + 1))
        m.d.sync += v2.eq(v1)
        if nsh:
            m.d.sync += thermo.eq(Cat(Const(1, 1), *(mm[B - 2 + s:].any() for s in range(1, nsh + 1))))
        # S3: r = the last set position (one-hot -> binary).
        v3 = Signal()
        r = Signal(p.shift_bits)
        m.d.sync += v3.eq(v2)
        if nsh:
            bits = []
            for j in range(p.shift_bits):
                terms = [thermo[s] & ~thermo[s + 1] if s < nsh else thermo[s]
                         for s in range(1, nsh + 1) if (s >> j) & 1]
                bits.append(Cat(*terms).any() if terms else Const(0, 1))
            m.d.sync += r.eq(Cat(*bits))
        else:
            m.d.sync += r.eq(0)
        # S4: shift.
        v4 = Signal()
        t = [Signal(signed(B), name=f"norm{j}") for j in range(6)]
        m.d.sync += v4.eq(v3)
        m.d.sync += [tj.eq(v >> r) for tj, v in zip(t, six)]
        # S5: products (registered 18x18 operands and results).
        v5 = Signal()
        pw = 2 * B
        sr, si, ar, ai, er, ei = t
        prods = {}
        for name, (x1, x2) in {"rr": (sr, sr), "ii": (si, si), "a1": (ai, sr), "a2": (ar, si),
                               "e1": (ei, sr), "e2": (er, si)}.items():
            s = Signal(signed(pw), name=f"prod_{name}")
            m.d.sync += s.eq(x1 * x2)
            prods[name] = s
        m.d.sync += v5.eq(v4)
        # S6: x = |S|^2, y = Im(d S*).
        cw = p.cordic.width
        v6 = Signal()
        xr, ya, ye = (Signal(signed(cw), name=n) for n in ("cx", "cya", "cye"))
        m.d.sync += [v6.eq(v5), xr.eq(prods["rr"] + prods["ii"]),
                     ya.eq(prods["a1"] - prods["a2"]), ye.eq(prods["e1"] - prods["e2"])]
        # S7: CORDIC load (x >= 0: no pre-rotation), zero flags.
        cfg = p.cordic
        g = cfg.guard_bits
        dw = cfg.datapath_bits
        zw = cfg.lut_bits + 1
        valid_c = Signal(name="cordic_v0")
        m.d.sync += valid_c.eq(v6)
        axes = []
        for ax, y in (("a", ya), ("e", ye)):
            xs = Signal(signed(dw), name=f"x{ax}_0")
            ys = Signal(signed(dw), name=f"y{ax}_0")
            zs = Signal(signed(zw), name=f"z{ax}_0")
            zero = Signal(name=f"zero{ax}_0")
            m.d.sync += [xs.eq(xr << g), ys.eq(y << g), zs.eq(0),
                         zero.eq((xr == 0) & (y == 0))]
            axes.append([xs, ys, zs, zero])
        # S8 .. S7 + n: micro-rotations.
        vc = valid_c
        for i, atan_i in enumerate(cfg.lut):
            v_next = Signal(name=f"cordic_v{i + 1}")
            m.d.sync += v_next.eq(vc)
            vc = v_next
            for st in axes:
                xs, ys, zs, zero = st
                xn = Signal(signed(dw), name=f"{xs.name[:2]}_{i + 1}")
                yn = Signal(signed(dw), name=f"{ys.name[:2]}_{i + 1}")
                zn = Signal(signed(zw), name=f"{zs.name[:2]}_{i + 1}")
                zr = Signal(name=f"{zero.name[:5]}_{i + 1}")
                up = ys[-1]
                dx, dy = ys >> i, xs >> i
                m.d.sync += [xn.eq(Mux(up, xs - dx, xs + dx)), yn.eq(Mux(up, ys + dy, ys - dy)),
                             zn.eq(Mux(up, zs - atan_i, zs + atan_i)), zr.eq(zero)]
                st[:] = [xn, yn, zn, zr]
        # S8 + n: angle rounding (half up to angle_bits per turn, wrapped, signed).
        ab = p.angle_bits
        va = Signal()
        m.d.sync += va.eq(vc)
        angs = []
        for (xs, ys, zs, zero), ax in zip(axes, "ae"):
            a = Signal(signed(ab), name=f"ang_{ax}")
            rz = round_shift(zs, cfg.lut_bits - ab, "half_up")
            m.d.sync += a.eq(Mux(zero, 0, rz[:ab]))
            angs.append(a)
        # S9 + n: a * k.
        vk = Signal()
        m.d.sync += vk.eq(va)
        kp = []
        for a, (k, s), ax in zip(angs, p.dc_coefs, "ae"):
            prod = Signal(signed(ab + p.dc_coef_bits), name=f"ak_{ax}")
            m.d.sync += prod.eq(a * k)
            kp.append((prod, s))
        ang_d = [Signal(signed(ab), name=f"ang_{ax}_d") for ax in "ae"]
        m.d.sync += [d.eq(a) for d, a in zip(ang_d, angs)]
        # S10 + n: u = u0 + round(a k / 2**s): the record.
        rv = Signal()
        uv = [Signal(signed(dcw), name=n) for n in ("u_out", "v_out")]
        m.d.sync += rv.eq(vk)
        for o, (prod, s), base in zip(uv, kp, (rec_u0, rec_v0)):
            m.d.sync += o.eq(fit_width(base + round_shift(prod, s, "half_up"), dcw, "wrap"))
        ang_r = [Signal(signed(ab), name=f"ang_{ax}_r") for ax in "ae"]
        r_d = Signal(p.shift_bits)
        m.d.sync += [d.eq(a) for d, a in zip(ang_r, ang_d)]
        # The shift and the block number are held since the dump (the next is a block away).
        m.d.comb += r_d.eq(r)

        # -- record into the FIFO ------------------------------------------------------------
        m.submodules.fifo = fifo = self._fifo
        fields = [dblk, uv[0], uv[1], ang_r[0], ang_r[1], r_d] + dump
        # The drop counter leaves through a register of its own (as the GNSS array's), so
        # the FIFO's counter is placed by the FIFO's logic and not pulled towards the output
        # pins: FIFO fit logic -> counter enable was the critical path, 79.5 MHz, 6 ns of it
        # one wire.
        ovf = Signal.like(fifo.overflow_count, name="overflow_count_r")
        m.d.sync += ovf.eq(fifo.overflow_count)
        m.d.comb += [fifo.i.valid.eq(rv), fifo.i.payload.eq(Cat(*fields)),
                     self.overflow_count.eq(ovf)]
        wiring.connect(m, fifo.o, wiring.flipped(self.o))
        return m


def monopulse_top(params: MonopulseFrontendParams | None = None) -> MonopulseFrontEnd:
    """The export / synthesis top (default parameters)."""
    return MonopulseFrontEnd(params)
