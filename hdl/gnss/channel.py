"""GPS L1 C/A tracking channel: code NCO and C/A generator, carrier NCO and wipe-off,
early/prompt/late integrate-and-dump, records to the DSP FIFO, double-buffered registers.

Arithmetic and timing are specified in :mod:`hdl.gnss.model` (module docstring); this
file builds it. Pipeline of one sample (input cycle ``c``):

* ``c``: code NCO / generator / delay line / carrier accumulator update (registers);
  the replicas and the carrier phase of the sample are the registers' values in ``c``;
* ``c .. c+5``: carrier NCO (:class:`hdl.nco.Nco`, phase port), the ADC word (real input)
  or words (I and Q, ``input="complex"``) delayed alongside; ``c+5 .. c+10``: real mixer
  (:class:`hdl.mixer.Mixer`, two input stages; complex input: the complex mixer, one cycle
  more, ``c+5 .. c+11``); replica bits and epoch flags delayed alongside;
* then the six replica products ``+-I``, ``+-Q`` (registered), the accumulators (a dump
  loads the record registers) and the record valid: :attr:`GnssChannelParams.latency`
  cycles (12 real, 13 complex) from ``c``.
"""
from __future__ import annotations

from dataclasses import replace

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from dsp.gnss.ca_code import G1_FEEDBACK, G2_FEEDBACK, G2_TAPS
from hdl.common import FANOUT_SLICE, fanout_copies, iq_layout
from hdl.fifo import DspFifo
from hdl.mixer import Mixer
from hdl.nco import Nco

from .params import ACC_FIELDS, GnssChannelParams

__all__ = ["CaCodeGenerator", "GnssCorrelator", "GnssChannel", "GnssChannelArray", "array_params",
           "input_shape", "record_layout", "gnss_top"]


def input_shape(params: GnssChannelParams):
    """The ADC input payload: ``signed(adc_bits)`` (real input), or ``{"i", "q"}`` of
    ``signed(adc_bits)`` each, ``i`` at the LSB (complex input,
    :meth:`GnssChannelParams.pack_samples`)."""
    if params.complex_input:
        return iq_layout(params.adc_bits)
    return signed(params.adc_bits)


def record_layout(params: GnssChannelParams) -> data.StructLayout:
    """The record as a struct, fields LSB first (:attr:`GnssChannelParams.record`)."""
    return data.StructLayout({n: (signed(w) if s else unsigned(w))
                              for n, w, s in params.record.fields})


def array_params(params: GnssChannelParams, channels: int) -> GnssChannelParams:
    """``params`` with the ``channel`` record field an array of ``channels`` needs."""
    if isinstance(channels, bool) or not isinstance(channels, int) or not 1 <= channels <= 64:
        raise ValueError(f"GNSS channel array needs channels in [1, 64], not {channels!r}")
    return replace(params, channel_bits=max(1, (channels - 1).bit_length()))


def _check_params(obj, params):
    if not isinstance(params, GnssChannelParams):
        obj._MustUse__silence = True
        raise ValueError(f"{type(obj).__name__} needs a GnssChannelParams, not {params!r}")


def _lfsr_step(reg, feedback):
    fb = reg[feedback[0] - 1]
    for t in feedback[1:]:
        fb = fb ^ reg[t - 1]
    return Cat(fb, reg[:9])


class CaCodeGenerator(wiring.Component):
    """C/A code generator: G1 and G2 10-stage registers (IS-GPS-200, :mod:`dsp.gnss.ca_code`)
    and the G2 phase selector of Table 3-Ia.

    Ports
    -----
    prn : In(unsigned(6))
        PRN 1-32 (any other value: G1 alone); combinational into ``chip``.
    step : In(1)
        Advance one chip at the clock edge.
    restart : In(1)
        Set both registers to all ones at the clock edge (the code epoch; overrides
        ``step``). Only with ``restart=True``: G1 and G2 have period 1023, the code length,
        so a generator stepped once per chip from all ones is back at all ones after the
        last chip without it.
    chip : Out(1)
        The current chip, logic level (0 = +1): G1 stage 10 XOR the PRN's two G2 stages.
    """

    def __init__(self, restart: bool = True):
        self.has_restart = bool(restart)
        # Explicit members: this module's annotations are strings (``from __future__``).
        super().__init__({"prn": In(unsigned(6)), "step": In(1), "chip": Out(1),
                          **({"restart": In(1)} if restart else {})})

    def elaborate(self, platform):
        m = Module()
        g1 = Signal(10, init=0x3FF)
        g2 = Signal(10, init=0x3FF)
        g2i = Signal()
        with m.Switch(self.prn):
            for n, (a, b) in G2_TAPS.items():
                with m.Case(n):
                    m.d.comb += g2i.eq(g2[a - 1] ^ g2[b - 1])
            with m.Default():
                m.d.comb += g2i.eq(0)
        m.d.comb += self.chip.eq(g1[9] ^ g2i)
        with m.If(self.step):
            m.d.sync += [g1.eq(_lfsr_step(g1, G1_FEEDBACK)), g2.eq(_lfsr_step(g2, G2_FEEDBACK))]
        if self.has_restart:
            with m.If(self.restart):        # overrides step (the later assignment wins)
                m.d.sync += [g1.eq(0x3FF), g2.eq(0x3FF)]
        return m


class GnssCorrelator(wiring.Component):
    """One channel's correlator core (no FIFO).

    Ports
    -----
    i : In(stream.Signature(input_shape(params), always_ready=True))
        ADC samples (real, or I and Q: :func:`input_shape`), one per ``valid`` cycle (gaps
        allowed).
    reg_we, reg_addr (2 bits), reg_data (``reg_data_width`` bits) : In
        Register bus: a write when ``reg_we`` is high (addresses
        :attr:`~hdl.gnss.params.GnssChannelParams.registers`), into the shadow registers.
    rec : Out(stream.Signature(record_layout(params), always_ready=True))
        One record per dump, :attr:`GnssChannelParams.latency` cycles after the input cycle
        of the dump's first sample; the payload holds until the next dump.
    """

    def __init__(self, params: GnssChannelParams):
        _check_params(self, params)
        self.params = params
        self.layout = record_layout(replace(params, channel_bits=0))
        super().__init__({
            "i": In(stream.Signature(input_shape(params), always_ready=True)),
            "reg_we": In(1),
            "reg_addr": In(2),
            "reg_data": In(unsigned(params.reg_data_width)),
            "rec": Out(stream.Signature(self.layout, always_ready=True)),
        })

    @property
    def latency(self) -> int:
        return self.params.latency

    def elaborate(self, platform):
        p = self.params
        m = Module()
        CB, PB, SB = p.code_phase_bits, p.carr_phase_bits, p.slew_bits
        K, d = p.dump_epochs, p.half_spacing
        L = 2 * d
        cw, kw = p.carr_word(p.if_hz), p.code_word()
        valid = self.i.valid

        # -- registers: shadow (bus side) and active ------------------------------------
        sh_carr = Signal(PB, init=cw)
        sh_code = Signal(CB, init=kw)
        sh_prn = Signal(6, init=p.prn)
        sh_slew = Signal(SB)
        slew_pend = Signal()
        cf = Signal(CB, init=kw)
        prn = Signal(6, init=p.prn)
        pend_carr = Signal(PB, init=cw)
        carr_f = Signal(PB, init=cw)

        # -- code NCO and C/A generator ----------------------------------------------------
        # Registered for timing (same behaviour as the model's ``acc += code_freq``): ``s``
        # holds ``acc + cf`` of the current state (its carry is the chip advance), and
        # ``hold == 0``, ``chip == 1022`` and ``gen_k == K - 1`` are flags kept with their
        # counters, so the boundary decision is a few gates from registers and the 32-bit
        # adders (both next sums, with the old and the new code word) run in parallel to it.
        s = Signal(CB + 1, init=kw)
        chip = Signal(range(1023))
        chip_last = Signal()
        hold = Signal(SB)
        hold_zero = Signal(init=1)
        gen_ep = Signal()
        gen_first = Signal()
        code_epoch = Signal(CB)
        m.submodules.ca = ca = CaCodeGenerator(restart=False)
        bit_e = ca.chip
        m.d.comb += ca.prn.eq(prn)

        s_keep = Signal(CB + 1)
        s_new = Signal(CB + 1)
        m.d.comb += [s_keep.eq(s[:CB] + cf), s_new.eq(s[:CB] + sh_code)]
        advance = Signal()
        wrap = Signal()
        boundary = Signal()
        m.d.comb += [advance.eq(valid & hold_zero & s[CB]),
                     wrap.eq(advance & chip_last)]
        # The boundary is decided a cycle ahead: ``armed`` is always ``hold_zero & s[CB] &
        # chip_last & gen_k_last`` (a valid sample now is a boundary), loaded with the next
        # values of those registers. A boundary enables ~140 latched bits; from four
        # registers through three LUT levels to that enable net it was the 12-channel
        # array's next critical path. The next value is 0 after any wrap (chip_last
        # clears), so the boundary's own loads of hold_zero and s do not enter it.
        armed = Signal()
        ep_last = Signal()           # chip_last & gen_k_last, in the next cycle
        if K > 1:
            gen_k = Signal(range(K))
            gen_k_last = Signal()
            with m.If(wrap):
                m.d.sync += [gen_k.eq(Mux(gen_k_last, 0, gen_k + 1)),
                             gen_k_last.eq(~gen_k_last & (gen_k == K - 2))]
        else:
            gen_k_last = Const(1, 1)
        m.d.comb += [boundary.eq(valid & armed),
                     ep_last.eq(gen_k_last & Mux(advance, ~chip_last & (chip == 1021),
                                                 chip_last))]
        m.d.sync += armed.eq(ep_last
                             & Mux(valid & ~hold_zero, hold == 1, hold_zero)
                             & Mux(valid & hold_zero, s_keep[CB], s[CB]))

        with m.If(valid):
            m.d.sync += [gen_ep.eq(wrap), gen_first.eq(boundary)]
            with m.If(~hold_zero):
                m.d.sync += [hold.eq(hold - 1), hold_zero.eq(hold == 1)]
            with m.Else():
                m.d.sync += s.eq(s_keep)
            with m.If(advance):
                m.d.sync += [chip.eq(Mux(chip_last, 0, chip + 1)), chip_last.eq(chip == 1021)]
        # No restart at the code epoch: G1 and G2 are maximal-length 10-stage LFSRs (period
        # 1023 = the code length), so the step out of chip 1022 returns both to all ones,
        # the state the restart would load, and they always hold the state of ``chip``. The
        # restart (``wrap`` into 20 register enables and D inputs) was the 12-channel array's
        # critical path (chip advance -> C/A restart); the chips are the same.
        m.d.comb += ca.step.eq(advance)
        with m.If(boundary):
            m.d.sync += [cf.eq(sh_code), prn.eq(sh_prn), hold.eq(Mux(slew_pend, sh_slew, 0)),
                         hold_zero.eq(~slew_pend | (sh_slew == 0)), s.eq(s_new),
                         slew_pend.eq(0), pend_carr.eq(sh_carr), code_epoch.eq(s[:CB])]
        # Bus writes after the latch: a write in the boundary cycle waits for the next one.
        # (Separate Ifs, not a Switch: the export of a Switch over all 4 addresses leaves
        # per-register case statements Verilator flags as incomplete.)
        we, regs = self.reg_we, p.registers

        def write(name):   # bus write of register ``name``: its data bits
            r = regs[name]
            return we & (self.reg_addr == r.address), self.reg_data[:r.width]

        for name, sh in (("carr_freq", sh_carr), ("code_freq", sh_code), ("prn", sh_prn)):
            hit, bits = write(name)
            with m.If(hit):
                m.d.sync += sh.eq(bits)
        hit, bits = write("slew")
        with m.If(hit):
            m.d.sync += [sh_slew.eq(bits), slew_pend.eq(1)]

        # -- delay line: (code bit, epoch, first) per sample --------------------------------
        taps = [Signal(3, name=f"line{k}") for k in range(L)]
        with m.If(valid):
            m.d.sync += taps[0].eq(Cat(bit_e, gen_ep, gen_first))
            m.d.sync += [taps[k].eq(taps[k - 1]) for k in range(1, L)]
        prompt, late = taps[d - 1], taps[L - 1]
        bit_p, ep_p, first_p, bit_l = prompt[0], prompt[1], prompt[2], late[0]

        # -- carrier accumulator and NCO -----------------------------------------------------
        carr_acc = Signal(PB)
        carr_at = Signal(PB)
        code_at = Signal(CB)
        with m.If(valid):
            with m.If(first_p):
                m.d.sync += [carr_at.eq(carr_acc), code_at.eq(code_epoch),
                             carr_f.eq(pend_carr), carr_acc.eq(carr_acc + pend_carr)]
            with m.Else():
                m.d.sync += carr_acc.eq(carr_acc + carr_f)
        m.submodules.nco = nco = Nco(p.nco)
        m.d.comb += [nco.i.valid.eq(valid), nco.freq.eq(0), nco.phase.eq(carr_acc)]

        # -- ADC word and flags alongside the NCO / mixer pipelines -------------------------
        mp = p.mixer
        pay = self.i.payload
        comps = {"i": pay.i, "q": pay.q} if p.complex_input else {"": pay}
        delayed = {}
        for comp, x in comps.items():
            if p.odd_levels:
                x = Cat(Const(1, 1), x).as_signed()   # q -> 2 q + 1 (odd levels)
            for k in range(p.nco.latency):
                r = Signal(signed(mp.in_width), name=f"x{comp}_d{k + 1}")
                m.d.sync += r.eq(x)
                x = r
            delayed[comp] = x
        m.submodules.mixer = mixer = Mixer(mp)
        if p.complex_input:
            m.d.comb += [mixer.i.payload.x.i.eq(delayed["i"]),
                         mixer.i.payload.x.q.eq(delayed["q"])]
        else:
            m.d.comb += mixer.i.payload.x.eq(delayed[""])
        m.d.comb += [mixer.i.valid.eq(nco.o.valid), mixer.i.payload.lo.eq(nco.o.payload)]
        flags = Cat(bit_e, bit_p, bit_l, ep_p, first_p)
        for k in range(p.nco.latency + mp.latency):
            r = Signal(5, name=f"flags_d{k + 1}")
            m.d.sync += r.eq(flags)
            flags = r
        f_e, f_p, f_l, f_ep, f_first = (flags[k] for k in range(5))

        # -- replica products (registered: the negation's carry chain and the accumulator's
        # are not in one cycle), then integrate and dump ------------------------------------
        W = p.acc_width
        iv, qv = mixer.o.payload.i, mixer.o.payload.q
        accs = {n: Signal(signed(W), name=f"acc_{n}") for n in ACC_FIELDS}
        terms = {}
        for arm, bit in (("e", f_e), ("p", f_p), ("l", f_l)):
            for comp, v in (("i", iv), ("q", qv)):
                t = Signal(signed(p.iq_width + 1), name=f"t_{comp}{arm}")
                m.d.sync += t.eq(Mux(bit, -v, v))
                terms[comp + arm] = t
        t_valid, t_ep, t_first = Signal(), Signal(), Signal()
        m.d.sync += [t_valid.eq(mixer.o.valid), t_ep.eq(f_ep), t_first.eq(f_first)]
        epoch = Signal(p.epoch_bits)
        rec = Signal(self.layout)
        rec_valid = Signal()
        m.d.sync += rec_valid.eq(0)
        # The dump's record load enable (t_valid & t_first) decided a cycle ahead into
        # registers, one per FANOUT_SLICE record bits (hdl.common.fanout_copies): the
        # record's clock enables come from a flip-flop, not through a LUT from the input
        # valid that every channel of an array shares (the 12-channel I/Q array's critical
        # path at one seed).
        new = Signal(self.layout)
        m.d.comb += [getattr(new, n).eq(accs[n]) for n in ACC_FIELDS]
        m.d.comb += [new.epoch.eq(epoch + 1), new.carr_phase.eq(carr_at),
                     new.code_phase.eq(code_at)]
        rec_bits, new_bits = Value.cast(rec), Value.cast(new)
        for bits, load in fanout_copies(m, mixer.o.valid & f_first, len(rec_bits), "rec_load"):
            with m.If(load):
                m.d.sync += rec_bits[bits].eq(new_bits[bits])
                if bits.start == 0:
                    m.d.sync += rec_valid.eq(1)
        with m.If(t_valid):
            with m.If(t_ep):
                m.d.sync += epoch.eq(epoch + 1)
            with m.If(t_first):
                m.d.sync += [accs[n].eq(terms[n]) for n in ACC_FIELDS]
            with m.Else():
                m.d.sync += [accs[n].eq(accs[n] + terms[n]) for n in ACC_FIELDS]
        m.d.comb += [self.rec.valid.eq(rec_valid), self.rec.payload.eq(rec)]
        return m


class GnssChannel(wiring.Component):
    """One tracking channel: :class:`GnssCorrelator` into the record FIFO.

    Ports
    -----
    i : In(stream.Signature(input_shape(params), always_ready=True))
        ADC samples (real, or I and Q: :func:`input_shape`).
    reg_we, reg_addr (2 bits), reg_data : In
        Register bus (see :class:`GnssCorrelator`).
    o : Out(stream.Signature(DspFifo out layout))
        Tagged FIFO words to the DSP, ``record_words`` per record (first tagged 1).
    overflow_count : Out(unsigned(count_width))
        Records dropped.
    """

    def __init__(self, params: GnssChannelParams):
        _check_params(self, params)
        self.params = params
        self.fifo_params = params.fifo
        self._fifo = DspFifo(self.fifo_params)
        super().__init__({
            "i": In(stream.Signature(input_shape(params), always_ready=True)),
            "reg_we": In(1),
            "reg_addr": In(2),
            "reg_data": In(unsigned(params.reg_data_width)),
            "o": Out(stream.Signature(self._fifo.out_layout)),
            "overflow_count": Out(unsigned(self.fifo_params.count_width)),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.core = core = GnssCorrelator(replace(self.params, channel_bits=0))
        m.submodules.fifo = fifo = self._fifo
        m.d.comb += [core.i.valid.eq(self.i.valid), core.i.payload.eq(self.i.payload),
                     core.reg_we.eq(self.reg_we), core.reg_addr.eq(self.reg_addr),
                     core.reg_data.eq(self.reg_data),
                     fifo.i.valid.eq(core.rec.valid),
                     fifo.i.payload.eq(Value.cast(core.rec.payload)),
                     self.overflow_count.eq(fifo.overflow_count)]
        wiring.connect(m, wiring.flipped(self.o), fifo.o)
        return m


class GnssChannelArray(wiring.Component):
    """``channels`` tracking channels on one ADC stream, one record FIFO.

    The records carry a ``channel`` field (:func:`array_params`); an arbiter passes at most
    one record every ``record_words`` cycles (the FIFO writes a word per cycle), the lowest
    pending channel first, two cycles from grant to the FIFO input (records of one channel are a code period apart, so one pending
    flag per channel suffices: the core's record register holds until its next dump).

    Ports
    -----
    i : In(stream.Signature(input_shape(params), always_ready=True))
        ADC samples, the same to every channel.
    reg_we, reg_addr (``2 + ceil(log2(channels))`` bits: ``4 * channel + reg``), reg_data : In
    o : Out(stream.Signature(DspFifo out layout))
    overflow_count : Out(unsigned(count_width))
        Records dropped, registered: one cycle behind the FIFO's count.
    """

    def __init__(self, params: GnssChannelParams, channels: int = 12):
        _check_params(self, params)
        try:
            ap = array_params(params, channels)
        except ValueError:
            self._MustUse__silence = True
            raise
        self.channels = channels
        self.params = ap if params.channel_bits == 0 else params
        if (1 << self.params.channel_bits) < channels:
            self._MustUse__silence = True
            raise ValueError(f"GNSS channel_bits {self.params.channel_bits} cannot number "
                             f"{channels} channels")
        self.fifo_params = self.params.fifo
        self._fifo = DspFifo(self.fifo_params)
        self.addr_bits = 2 + max(1, (channels - 1).bit_length())
        super().__init__({
            "i": In(stream.Signature(input_shape(params), always_ready=True)),
            "reg_we": In(1),
            "reg_addr": In(self.addr_bits),
            "reg_data": In(unsigned(params.reg_data_width)),
            "o": Out(stream.Signature(self._fifo.out_layout)),
            "overflow_count": Out(unsigned(self.fifo_params.count_width)),
        })

    def elaborate(self, platform):
        m = Module()
        p = self.params
        core_p = replace(p, channel_bits=0, record_words=None)
        m.submodules.fifo = fifo = self._fifo
        cores = []
        for ch in range(self.channels):
            core = GnssCorrelator(core_p)
            m.submodules[f"ch{ch}"] = core
            m.d.comb += [core.i.valid.eq(self.i.valid), core.i.payload.eq(self.i.payload),
                         core.reg_we.eq(self.reg_we & (self.reg_addr[2:] == ch)),
                         core.reg_addr.eq(self.reg_addr[:2]), core.reg_data.eq(self.reg_data)]
            cores.append(core)
        pend = Signal(self.channels)
        # Grant: the lowest pending channel, at most one every record_words cycles (the FIFO
        # writes one word per cycle); the granted record reaches the FIFO input register two
        # cycles later. For 100 MHz with 12 channels the record multiplexer is two register
        # stages (channel groups, then their OR), fed by a one-hot select decided a cycle
        # ahead of the grant (``sel_next``: the lowest channel of the next cycle's pending
        # flags), so that the grant's timing is unchanged. The single-stage multiplexer's
        # select register was the critical path (6 ns of routing in one net).
        sel_valid = Signal()
        out = Signal(p.record_bits)
        out_valid = Signal()
        m.d.sync += sel_valid.eq(0)
        n = self.fifo_params.record_words
        gap = Signal(range(max(n, 2)))
        with m.If(gap != 0):
            m.d.sync += gap.eq(gap - 1)
        grant = Signal(self.channels)       # one-hot: the channel granted in this cycle
        m.d.comb += grant.eq(Mux(pend.any() & (gap == 0), pend & -pend, 0))
        with m.If(grant.any()):
            m.d.sync += [sel_valid.eq(1), gap.eq(n - 1)]
        recv = Cat(core.rec.valid for core in cores)
        # New records set their flags after the grant clears its own.
        m.d.sync += pend.eq((pend & ~grant) | recv)
        # sel_next == the one-hot select of a grant in the next cycle (it is not used
        # otherwise). A grant sets the gap, so with record_words > 1 no grant follows one and
        # the next cycle's pending flags are ``pend | recv`` whenever a grant can follow.
        nxt = (pend | recv) if n > 1 else ((pend & ~grant) | recv)
        # One copy of it per FANOUT_SLICE record bits (hdl.common.fanout_copies), so that no
        # select bit drives more than FANOUT_SLICE AND gates: one copy driving all of a
        # record's bits was the 12-channel I/Q array's critical path (sel_next ->
        # rec_group1, 8.8 ns of routing).
        sels = [r for _, r in fanout_copies(m, nxt & -nxt, p.record_bits, "sel_next",
                                             self.channels)]
        # The record of a granted channel holds until its next dump, a code period later.
        group = 4
        parts = []
        for g0 in range(0, self.channels, group):
            mux = Const(0, p.record_bits)
            for ch in range(g0, min(g0 + group, self.channels)):
                rec = Cat(Value.cast(cores[ch].rec.payload), Const(ch, p.channel_bits))
                mask = Cat(sels[b // FANOUT_SLICE][ch] for b in range(p.record_bits))
                mux = mux | (rec & mask)
            part = Signal(p.record_bits, name=f"rec_group{g0 // group}")
            m.d.sync += part.eq(mux)
            parts.append(part)
        m.d.sync += [out_valid.eq(sel_valid), out.eq(_or_all(parts))]
        # The drop counter leaves through a register of its own, so that the FIFO's counter
        # is placed by the FIFO's logic and not pulled towards the output (at 12 channels the
        # FIFO's fit logic -> counter enable was the critical path, 95.6 MHz, 3.8 ns of it
        # one wire).
        ovf = Signal.like(fifo.overflow_count, name="overflow_count_r")
        m.d.sync += ovf.eq(fifo.overflow_count)
        m.d.comb += [fifo.i.valid.eq(out_valid), fifo.i.payload.eq(out),
                     self.overflow_count.eq(ovf)]
        wiring.connect(m, wiring.flipped(self.o), fifo.o)
        return m


def _or_all(values):
    acc = values[0]
    for v in values[1:]:
        acc = acc | v
    return acc


def gnss_top(channels: int = 1, params: GnssChannelParams | None = None, *,
             input: str | None = None):
    """The synthesis / export top for ``channels`` channels: :class:`GnssChannel` for 1,
    :class:`GnssChannelArray` otherwise; default parameters unless ``params`` is given,
    with ``input="complex"`` the default parameters' complex-input build at zero IF."""
    if params is None:
        p = GnssChannelParams() if input in (None, "real") else \
            GnssChannelParams(input=input, if_hz=0.0)   # refuses an unknown input kind
    elif input is not None and input != params.input:
        raise ValueError(f"gnss_top: input {input!r} contradicts params.input "
                         f"{params.input!r}")
    else:
        p = params
    return GnssChannel(p) if channels == 1 else GnssChannelArray(p, channels)
