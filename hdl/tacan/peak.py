"""TACAN pulse-peak search: adaptive threshold from a block noise floor, peak of each pulse.

The algorithm, its parameters and the bit-exact model are in :mod:`hdl.tacan.peak_model`.

Hardware structure (why it looks the way it does)
-------------------------------------------------
Every path is one compare, a few LUT levels or one adder between registers, and every block
RAM read and constant product is registered before use: the TACAN front end with both
searches meets 100 MHz on the LFE5U-85F (results/synth.json, ``python -m cosim synth --all``). Before this
structure it reached 56.7 MHz: a block RAM's clock-to-output, a compare, muxes and the
floor's adder shared one cycle.

The noise floor has a one-sample recursion at every block boundary: the clip level of the
first samples of block ``b+1`` depends on the last sample of block ``b``, which may arrive on
the previous cycle. The last sample of block ``b`` is in the input register ``e_r`` at ``T``:

* ``nu_{b+1} = nu_b + ((floor(S/L) - nu_b) >> s)`` is computed as
  ``(S + nu_b*(2**s - 1)*L) >> (log2 L + s)`` (identical for integers; ``base =
  nu_b*(2**s-1)*L`` is a register computed during the block), so block end -> new ``nu``
  is one adder: the block's sum is registered at ``T + 1``, the new ``nu`` is in place from
  ``T + 2``;
* from a block's third sample on, the compare with the clip level is made as the sample
  enters ``e_r`` (a registered flag): that sample enters at ``T + 2`` or later, when the new
  ``nu`` is in place, and its contribution reaches the accumulator's adder one LUT from
  registers;
* the block's first two samples may enter before that; they wait in ``d0`` / ``d1`` and
  are compared there (registered). ``d0``'s contribution starts the block's sum with the
  third sample (in place of the accumulator), ``d1``'s is added into the floor update's
  other operand during the block (``base2 = base + cd1``), so the block end is still one
  adder from the sum to the new ``nu``. That needs the third sample to come after ``d0``'s
  compare and the block end after ``base2``: ``block_log2 >= 2`` (the model takes 1);
* block 0 accumulates ``e << s`` so that the same shift gives ``nu_1 = S_0 >> log2 L``.

With ``floor_frac`` the floor register is ``F`` (``amp_width + s`` bits, ``s`` fraction bits;
``nu = F >> s`` is its top ``amp_width`` bits, a slice): ``F_{b+1} = G_b + (S >> log2 L) =
(S + G_b L) >> log2 L`` (``G_b L`` has no bits below ``log2 L``) with ``G_b = F_b - (F_b >> s)``
a register computed during the block, ``base2 = G_b L + cd1``: again one adder from the
block's sum to the new floor, ``nu`` changing on the same cycle as without it. The block-0
sum is still that of ``e << s``, and a flag (set at reset, cleared by the first block end)
selects ``F_1 = (S_0 >> (log2 L + s)) << s``. ``F <= (2**aw - 1) << s`` (``m_b <= 2**aw -
1``), so it fits its width.

The detector runs ``det_delay`` (4) cycles behind the noise path on a delay line, so the
threshold ``T = max(thr_min, (nu * thr_mult) >> thr_frac)`` has two registered stages and
``T_{b+1}`` is ready when the detector reaches block ``b+1``. There is no multiplier:
``thr_mult = c_hi + c_lo`` (its bits from some ``k`` on and below it, split where each part
takes the fewest adders as shifted copies of ``nu``, :func:`hdl.common.const_mul`), and the
first stage registers ``nu * c_hi``, ``nu * c_lo`` and the flag ``nu < ceil((thr_min <<
thr_frac) / thr_mult)`` (the product's shift is below ``thr_min`` exactly then), the second
their sum shifted, or ``thr_min`` under the flag. The detector's pre-stage registers the
comparison ``e >= T`` so the pulse logic starts from a flop, and the comparison ``e >
max`` against the pulse's max as it will be when the sample reaches the detector (the
detector's sample if that one is taken as the max on this cycle, else the max register): the
max, its timestamp and the output take a registered select, and the max is taken without
the close decision (a closed pulse's max is not read; opening loads it). A pulse closes on
compares of its registers with constants (``below = hold - 1`` and not above, ``len =
max_len - 1``), not on their incremented values.

Pair-partner readout (``partner_offset = D > 0``): the input goes through a ``2 D``-word
delay line (one memory, written at ``wp``; read at ``wp + D`` -- the sample ``D`` back, which
the search runs on -- and at ``wp`` before the write -- the sample ``2 D`` back, the behind
value). The current input is the ahead value. Both ride the detector's delay line and are
kept with the pulse's max; the search starts once ``D`` samples are in (the memory is not
reset: the behind value is 0 until ``2 D`` samples have been written since reset). The
memory's read data is registered in the fabric, and that register is where the floor's
compare is made: two cycles more than without the readout (:attr:`PeakParams.latency`).

Pulse-pair detection (``pair_offset = D > 0``): stages around an inner
``PeakSearch(params.search_params)`` (one bit wider, partner readout at ``D``):

* sum stage (1 cycle): a ``D``-word memory of the input, written at a wrapping pointer on
  each valid input and read at the same address before the write (non-transparent,
  registered read port enabled by ``valid``: ``e[n - D]``; with ``D = 1`` a register of the
  previous input instead, a one-word memory has no address); the input and its valid are
  registered alongside, and the inner search is fed ``s[n] = e[n] + e[n - D]``. The memory is
  not reset: a saturating count of the inputs since reset makes ``e[n - D]`` read 0 until
  ``D`` samples have been written;
* the inner search, with its partner readout on ``s`` (``s[n_max + D]``, ``s[n_max - D]``);
* output filter (2 cycles): the pulse and ``pair_keep * partner`` (shifts and an adder,
  :func:`hdl.common.const_mul`) registered, then a peak goes out unless a side lobe clearly
  exceeds it (``8 amplitude >= pair_keep * partner``), with ``amplitude >> 1`` and the inner
  timestamp.

So the latency is the inner search's plus 3 (:attr:`PeakParams.latency`).

Pair checks (``pair_balance``, ``pair_spread = w``; :mod:`dsp.tacan.peak`): the output filter
becomes three stages, one cycle more (latency inner + 4):

* an envelope history of ``depth = PeakParams.pair_check_depth`` words (the power of two >=
  ``2 D + max_len + w + `` the inner latency: the inputs written between the peak's oldest tap
  ``n_max - D - w >= end_index - max_len + 1 - D - w`` and the read, at most up to
  ``end_index + D + `` inner latency, must not overwrite it), written at ``wp`` = the input
  index mod ``depth`` with each valid input; not reset, a saturating count of the inputs
  since reset (``cnt``, up to ``depth``) marks the taps before the first sample, which read 0;
* when the inner search emits a peak, ``n_max mod depth`` is its timestamp's bits from
  ``log2 ts_step`` on (``PeakParams`` checks that ``ts_step`` is a power of two and that the
  timestamp has the bits); one non-transparent registered read port per tap ``n_max + k``, ``k``
  in ``0, -D`` (balance) and ``w, -D - w, -w, -D + w`` (spread); a tap ``k < 0`` reads 0
  unless ``cnt = depth`` or ``n_max >= -k`` (until the history is full every index written
  is below ``depth``, so ``n_max`` is its low bits; registered with the reads); the pulse
  (amplitude, partner, timestamp, valid) is registered alongside;
* next cycle: the taps registered in the fabric, the constant products ``pair_keep *
  partner`` and ``pair_balance * s`` registered, the pulse alongside;
* next cycle: side-lobe rule, ``16 min(e[n_max], e[n_max - D]) >= pair_balance * s`` and
  ``s >= max(e[n_max + w] + e[n_max - D - w], e[n_max - w] + e[n_max - D + w])``, into the
  output register (``amplitude >> 1``, timestamp).
"""
from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from hdl.common import check_params, const_mul
from dsp.tacan.peak_params import PeakParams

__all__ = ["PeakSearch", "PeakParams"]


def _csd_terms(c: int) -> int:
    """Shifted copies of ``x`` in :func:`hdl.common.const_mul` ``(x, c)`` (nonzero canonical
    signed digits of ``c``)."""
    n = 0
    while c:
        if c & 1:
            c -= 2 - (c & 3)
            n += 1
        c >>= 1
    return n


def _split_const(c: int) -> tuple[int, int]:
    """``(c_hi, c_lo)``: ``c``'s bits from ``k`` on and below ``k``, at the ``k`` (lowest of
    the ties) whose larger part takes the fewest shifted copies (adders) in
    :func:`hdl.common.const_mul`: 46 = 40 + 6, one adder each; 48 = 32 + 16, none."""
    k = min(range(c.bit_length() + 1),
            key=lambda k: max(_csd_terms(c >> k << k), _csd_terms(c & ((1 << k) - 1))))
    return c >> k << k, c & ((1 << k) - 1)


def _ceil_div(a: int, b: int) -> int:
    return -(-a // b)


class PeakSearch(wiring.Component):
    """Pulse-peak search over an envelope stream.

    Parameters
    ----------
    params : PeakParams

    Ports
    -----
    i : In(stream.Signature(unsigned(amp_width), always_ready=True))
        Envelope samples; ``n`` (and the timestamp) advance on each valid transfer only.
    o : Out(stream.Signature(StructLayout({"amplitude": unsigned(amp_width),
            "timestamp": unsigned(ts_bits)}), always_ready=True))
        One transfer per pulse, ``params.latency`` (6) cycles after the transfer of the
        sample that closes the pulse. ``timestamp = (n_peak * ts_step) mod 2**ts_bits``.
        With the pair-partner readout (``partner_offset = D``) the payload adds ``partner``
        (``amp_width``) and ``partner_late`` (1 bit), and the transfer comes ``latency`` (8)
        cycles after that of the sample ``D`` after the closing one. With the pulse-pair
        detection (``pair_offset = D``) the payload is ``amplitude`` (the pair's mean,
        ``s >> 1``) and ``timestamp`` only, ``latency`` (11; 12 with the pair checks) cycles
        after the transfer of the sample ``D`` after the closing one.
    """

    def __init__(self, params: PeakParams | None = None):
        self.params = check_params(self, PeakParams() if params is None else params, PeakParams)
        p = self.params
        if p.block_log2 < 2:     # (the pair detection's inner search has the same blocks)
            self._MustUse__silence = True     # never elaborated (hdl.common.check_params)
            raise ValueError(f"PeakSearch needs peak block_log2 >= 2 (a block's first two "
                             f"samples wait for the new floor; the model takes 1), not "
                             f"{p.block_log2}")
        fields = {"amplitude": unsigned(p.amp_width), "timestamp": unsigned(p.ts_bits)}
        if p.partner_offset:
            fields.update(partner=unsigned(p.amp_width), partner_late=unsigned(1))
        self.out_layout = data.StructLayout(fields)
        super().__init__({
            "i": In(stream.Signature(unsigned(p.amp_width), always_ready=True)),
            "o": Out(stream.Signature(self.out_layout, always_ready=True)),
        })

    def elaborate(self, platform):
        if self.params.pair_offset:
            return self._elaborate_pairs()
        p = self.params
        m = Module()
        aw = p.amp_width
        L = p.block_len
        K = p.block_log2 + p.smooth_log2

        # Input register (the noise path's compare starts from a flop).
        e_r = Signal(unsigned(aw))
        v_r = Signal()
        D = p.partner_offset
        if not D:
            x_in, v_in = self.i.payload, self.i.valid
            a_r = b_r = None
        else:
            # 2D-word delay line; its (registered) read data is the search's input register
            depth = 2 * D
            m.submodules.line = line = Memory(shape=unsigned(aw), depth=depth, init=[])
            wr = line.write_port()
            rd_c = line.read_port()            # x[n - D]
            rd_b = line.read_port()            # x[n - 2D] (read before this write)
            wp = Signal(range(depth))
            seen = Signal(range(depth + 1))    # inputs since reset, saturating at 2D
            a_m = Signal(unsigned(aw))
            b_ok = Signal()
            v_m = Signal()
            m.d.comb += [wr.addr.eq(wp), wr.data.eq(self.i.payload), wr.en.eq(self.i.valid),
                         rd_c.addr.eq(Mux(wp >= D, wp - D, wp + D)), rd_b.addr.eq(wp),
                         rd_c.en.eq(self.i.valid), rd_b.en.eq(self.i.valid)]
            m.d.sync += v_m.eq(self.i.valid & (seen >= D))
            with m.If(self.i.valid):
                m.d.sync += [wp.eq(Mux(wp == depth - 1, 0, wp + 1)), a_m.eq(self.i.payload),
                             b_ok.eq(seen == depth)]
                with m.If(seen != depth):
                    m.d.sync += seen.eq(seen + 1)
            # the memory's read data is registered once more in the fabric (its
            # clock-to-output went straight into the floor's compare and accumulator: 56.7
            # MHz on the LFE5U-85F): one cycle of latency (PeakParams.latency)
            e_m, v_m2 = Signal(unsigned(aw)), Signal()
            a_m2, b_m2 = Signal(unsigned(aw)), Signal(unsigned(aw))
            m.d.sync += [e_m.eq(rd_c.data), v_m2.eq(v_m), a_m2.eq(a_m),
                         b_m2.eq(Mux(b_ok, rd_b.data, 0))]
            x_in, v_in = e_m, v_m2
            a_r, b_r = Signal(unsigned(aw)), Signal(unsigned(aw))
            m.d.sync += [a_r.eq(a_m2), b_r.eq(b_m2)]
        m.d.sync += [e_r.eq(x_in), v_r.eq(v_in)]

        # -- noise floor ------------------------------------------------------------------
        # Block positions as flags (registers): f0 / f1 / f2 = the sample in e_r is the
        # block's first / second / third; the *_n values are those of the sample entering
        # e_r on this cycle.
        pos = Signal(unsigned(p.block_log2))
        last = pos == L - 1
        f0, f1, f2 = Signal(init=1), Signal(), Signal()
        blk0 = Signal(init=1)
        with m.If(v_r):
            m.d.sync += [pos.eq(pos + 1), f0.eq(last), f1.eq(f0), f2.eq(f1)]
            with m.If(last):
                m.d.sync += blk0.eq(0)
        step = v_r
        f0_n, f1_n, f2_n = Mux(step, last, f0), Mux(step, f0, f1), Mux(step, f1, f2)
        blk0_n = blk0 & ~(step & last)

        if p.floor_frac:
            # the floor with smooth_log2 fraction bits; nu is its top aw bits
            nu_f = Signal(unsigned(p.floor_width))
            nu = nu_f[p.smooth_log2:]
        else:
            nu = Signal(unsigned(aw))
        clip = Signal(unsigned(aw + p.clip_log2))
        m.d.comb += clip.eq(nu << p.clip_log2)
        cl = nu if p.clip_to_floor else clip     # what a sample over the clip level adds

        def term(e, in_blk0):   # a sample's contribution before the clip: block 0 sums e << s
            return Mux(in_blk0, e << p.smooth_log2, e)

        # Samples from the block's third on: the compare against the clip level is made as
        # the sample enters e_r (registered: over_r), so e_r's contribution is one LUT from
        # registers and the adder is alone in its cycle. A block's first two samples may
        # enter before the new clip level is in place (the last sample of block b is in e_r
        # at T, nu_{b+1} from T + 2); they wait in d0 / d1 and are compared there: d0's
        # contribution (cd0) starts the block's sum at its third sample, d1's (cd1) is added
        # into the floor update's other operand (base2) during the block. Needs L >= 4.
        reg_r = Signal()          # e_r is a valid sample from the block's third on
        first_r = Signal()        # ... the third (its sum starts from cd0)
        over_r = Signal()         # ... and over the clip level (never in block 0)
        e_pre = Signal(unsigned(aw + p.smooth_log2))
        m.d.sync += [reg_r.eq(v_in & ~f0_n & ~f1_n), first_r.eq(v_in & f2_n),
                     over_r.eq(~blk0_n & (x_in > clip)), e_pre.eq(term(x_in, blk0_n))]

        # the deferred samples: d0 / d1 and their terms before the clip, and the registered
        # compares (dsel: over the clip level, not block 0); their terms are muxed in front
        # of the adders that take them (cd0, cd1)
        cds = []
        for k, flag in ((0, f0), (1, f1)):
            d_k = Signal(unsigned(aw), name=f"d{k}")
            d_pre = Signal(unsigned(aw + p.smooth_log2), name=f"d{k}_pre")
            d_clip = Signal(name=f"d{k}_clip")
            d_sel = Signal(name=f"d{k}_sel")
            with m.If(v_r & flag):
                m.d.sync += [d_k.eq(e_r), d_pre.eq(term(e_r, blk0)), d_clip.eq(~blk0)]
            m.d.sync += d_sel.eq(d_clip & (d_k > clip))
            cds.append(Mux(d_sel, cl, d_pre))
        cd0, cd1 = cds

        acc = Signal(unsigned(p.acc_width))
        lhs = Mux(first_r, cd0, acc)
        rhs = Mux(reg_r, Mux(over_r, cl, e_pre), 0)
        total = Signal(unsigned(p.acc_width))
        m.d.comb += total.eq(lhs + rhs)
        with m.If(reg_r):
            m.d.sync += acc.eq(total)
        s_reg = Signal(unsigned(p.acc_width))    # the block's sum without d1's term
        s_v = Signal()
        m.d.sync += [s_v.eq(v_r & last), s_reg.eq(total)]

        # the floor update: one adder from the block's sum (s_reg + base2) to the new nu
        base2 = Signal(unsigned(p.acc_width + 1))
        if p.floor_frac:
            # F_{b+1} = G_b + (S >> log2 L) = (S + G_b L) >> log2 L with G_b = F_b - (F_b >> s);
            # block 0: F_1 = (S_0 >> (log2 L + s)) << s
            keep = Signal(unsigned(p.floor_width))
            f_init = Signal(init=1)                  # the next block end is block 0's
            m.d.sync += [keep.eq(nu_f - (nu_f >> p.smooth_log2)),
                         base2.eq(Mux(f_init, 0, keep << p.block_log2) + cd1)]
            upd = s_reg + base2
            with m.If(s_v):
                m.d.sync += [nu_f.eq(Mux(f_init, (upd >> K) << p.smooth_log2,
                                         upd >> p.block_log2)),
                             f_init.eq(0)]
        else:
            # nu_{b+1} = (S + nu_b (2**s - 1) L) >> (log2 L + s)
            base = Signal(unsigned(p.acc_width))
            # (the constant is 2**(log2 L + s) - L: one subtracter, no multiplier)
            m.d.sync += [base.eq(const_mul(nu, ((1 << p.smooth_log2) - 1) * L)),
                         base2.eq(base + cd1)]
            with m.If(s_v):
                m.d.sync += nu.eq((s_reg + base2) >> K)

        # Threshold pipeline, no multiplier: the partial products nu * c_hi and nu * c_lo
        # (shifted copies of nu) and whether nu is below thr_min's floor registered, then
        # their sum (one adder) or thr_min into t_next.
        c_hi, c_lo = _split_const(p.thr_mult)
        pw = aw + p.thr_mult.bit_length()
        thr_hi = Signal(unsigned(pw))
        thr_lo = Signal(unsigned(pw))
        thr_low = Signal()                       # max(thr_min, .) is thr_min
        t_next = Signal(unsigned(p.thr_width))
        m.d.sync += [thr_hi.eq(const_mul(nu, c_hi)), thr_lo.eq(const_mul(nu, c_lo)),
                     thr_low.eq(nu < _ceil_div(p.thr_min << p.thr_frac, p.thr_mult))]
        m.d.sync += t_next.eq(Mux(thr_low, p.thr_min, (thr_hi + thr_lo) >> p.thr_frac))

        # -- detector, det_delay cycles behind ----------------------------------------------
        # A pre-stage (det_delay - 1 cycles behind) picks the threshold and registers the
        # comparison, so the pulse logic starts from a flop.
        pe, pv = e_r, v_r
        pa, pb = a_r, b_r
        for k in range(p.det_delay - 1):
            ne, nv = Signal(unsigned(aw), name=f"d{k}_e"), Signal(name=f"d{k}_v")
            m.d.sync += [ne.eq(pe), nv.eq(pv)]
            pe, pv = ne, nv
            if D:
                na, nb = Signal(unsigned(aw), name=f"d{k}_a"), Signal(unsigned(aw), name=f"d{k}_b")
                m.d.sync += [na.eq(pa), nb.eq(pb)]
                pa, pb = na, nb

        pre_pos = Signal(unsigned(p.block_log2))
        pre_first = Signal(init=1)  # the next pre-stage sample starts a block
        pre_blk0 = Signal(init=1)
        thr = Signal(unsigned(p.thr_width))
        t_use = Mux(pre_first, t_next, thr)
        de = Signal(unsigned(aw))
        dv = Signal()
        above = Signal()
        m.d.sync += [de.eq(pe), dv.eq(pv), above.eq(pv & ~pre_blk0 & (pe >= t_use))]
        if D:
            da, db = Signal(unsigned(aw)), Signal(unsigned(aw))
            m.d.sync += [da.eq(pa), db.eq(pb)]
        with m.If(pv):
            m.d.sync += [pre_pos.eq(pre_pos + 1), pre_first.eq(pre_pos == L - 1)]
            with m.If(pre_pos == L - 1):
                m.d.sync += pre_blk0.eq(0)
            with m.If(pre_first):
                m.d.sync += thr.eq(t_next)

        ts = Signal(unsigned(p.ts_bits))
        is_open = Signal()
        pmax = Signal(unsigned(aw))
        pts = Signal(unsigned(p.ts_bits))
        below = Signal(range(p.hold + 1))
        plen = Signal(range(p.max_len + 1))

        below_n = Mux(above, 0, below + 1)
        len_n = plen + 1
        # (compares of the registers with constants: no adder in front of the enables)
        close = (~above & (below == p.hold - 1)) | (plen == p.max_len - 1)
        # upd = de > pmax, registered: the pre-stage compares its sample with the max that is
        # current when the sample reaches the detector (de if `take`, else pmax)
        upd = Signal()
        take = Signal()       # de becomes the pulse's max: it opens the pulse or exceeds the
        #                       max (on the closing sample too: a closed pulse's max is not read)
        m.d.comb += take.eq(dv & Mux(is_open, upd, above))
        m.d.sync += upd.eq(Mux(take, pe > de, pe > pmax))
        new_max = Mux(upd, de, pmax)
        new_ts = Mux(upd, ts, pts)

        o_valid = Signal()
        o_amp = Signal(unsigned(aw))
        o_ts = Signal(unsigned(p.ts_bits))
        m.d.sync += o_valid.eq(0)
        if D:   # the ahead/behind values at the pulse's max
            pa_c, pb_c = Signal(unsigned(aw)), Signal(unsigned(aw))
            o_pa, o_pb = Signal(unsigned(aw)), Signal(unsigned(aw))
            new_a, new_b = Mux(upd, da, pa_c), Mux(upd, db, pb_c)
        with m.If(take):
            m.d.sync += [pmax.eq(de), pts.eq(ts)]
            if D:
                m.d.sync += [pa_c.eq(da), pb_c.eq(db)]
        with m.If(dv):
            m.d.sync += ts.eq(ts + p.ts_step)
            with m.If(~is_open):
                with m.If(above):
                    m.d.sync += [is_open.eq(1), below.eq(0), plen.eq(1)]
            with m.Else():
                with m.If(close):
                    m.d.sync += [is_open.eq(0), o_valid.eq(1), o_amp.eq(new_max),
                                 o_ts.eq(new_ts)]
                    if D:
                        m.d.sync += [o_pa.eq(new_a), o_pb.eq(new_b)]
                with m.Else():
                    m.d.sync += [below.eq(below_n), plen.eq(len_n)]
        m.d.comb += [
            self.o.valid.eq(o_valid),
            self.o.payload.amplitude.eq(o_amp),
            self.o.payload.timestamp.eq(o_ts),
        ]
        if D:
            late = o_pa >= o_pb
            m.d.comb += [self.o.payload.partner.eq(Mux(late, o_pa, o_pb)),
                         self.o.payload.partner_late.eq(late)]
        return m

    def _elaborate_pairs(self):
        """Pulse-pair detection: sum stage -> inner search on the pair sum -> side-lobe
        filter (the module docstring)."""
        p = self.params
        D = p.pair_offset
        aw = p.amp_width
        m = Module()

        # -- sum stage: s[n] = e[n] + e[n - D] ----------------------------------------------
        seen = Signal(range(D + 1))               # inputs since reset, saturating at D
        old_ok = Signal()                         # `old` is e[n - D] (else e = 0 there)
        x_r = Signal(unsigned(aw))
        v_r = Signal()
        m.d.sync += v_r.eq(self.i.valid)
        with m.If(self.i.valid):
            m.d.sync += [x_r.eq(self.i.payload), old_ok.eq(seen == D)]
            with m.If(seen != D):
                m.d.sync += seen.eq(seen + 1)
        if D == 1:   # e[n - 1] is the input register itself (a 1-word memory has no address)
            old = Signal(unsigned(aw))
            with m.If(self.i.valid):
                m.d.sync += old.eq(x_r)
        else:
            m.submodules.hist = hist = Memory(shape=unsigned(aw), depth=D, init=[])
            wr = hist.write_port()
            rd = hist.read_port(transparent_for=())   # e[n - D]: read before this write
            wp = Signal(range(D))
            m.d.comb += [wr.addr.eq(wp), wr.data.eq(self.i.payload), wr.en.eq(self.i.valid),
                         rd.addr.eq(wp), rd.en.eq(self.i.valid)]
            with m.If(self.i.valid):
                m.d.sync += wp.eq(Mux(wp == D - 1, 0, wp + 1))
            old = rd.data

        m.submodules.search = inner = PeakSearch(p.search_params)
        m.d.comb += [inner.i.valid.eq(v_r),
                     inner.i.payload.eq(x_r + Mux(old_ok, old, 0))]

        # -- output filter: drop the peaks a side lobe clearly exceeds ----------------------
        q = inner.o.payload
        if not p.pair_checks:   # the pulse and its partner's product registered, then the rule
            a, ts, v = Signal(unsigned(aw + 1)), Signal(unsigned(p.ts_bits)), Signal()
            kp = Signal(unsigned(aw + 5))
            m.d.sync += [v.eq(inner.o.valid), a.eq(q.amplitude), ts.eq(q.timestamp),
                         kp.eq(const_mul(q.partner, p.pair_keep))]
            m.d.sync += [self.o.valid.eq(v & ((a << 3) >= kp)),
                         self.o.payload.amplitude.eq(a >> 1),
                         self.o.payload.timestamp.eq(ts)]
            return m
        self._pair_checks(m, inner)
        return m

    def _pair_checks(self, m, inner):
        """The pair checks: an envelope history read at the peak's taps when the inner search
        emits it (registered reads, 1 cycle), then the checks and the side-lobe rule on the
        registered pulse, and the output register (the module docstring)."""
        p = self.params
        D, w, aw = p.pair_offset, p.pair_spread, p.amp_width
        depth = p.pair_check_depth
        abits = depth.bit_length() - 1
        step = int(p.ts_step).bit_length() - 1

        # envelope history: e[n] at n mod depth, written with each valid input
        m.submodules.env_hist = mem = Memory(shape=unsigned(aw), depth=depth, init=[])
        wr = mem.write_port()
        wp = Signal(abits)                        # inputs since reset, mod depth
        cnt = Signal(range(depth + 1))            # inputs since reset, saturating at depth
        m.d.comb += [wr.addr.eq(wp), wr.data.eq(self.i.payload), wr.en.eq(self.i.valid)]
        with m.If(self.i.valid):
            m.d.sync += wp.eq(wp + 1)
            with m.If(cnt != depth):
                m.d.sync += cnt.eq(cnt + 1)

        # the taps n_max + k; n_max mod depth from the timestamp (n_max * ts_step)
        q = inner.o.payload
        n_lo = q.timestamp[step:step + abits]
        # until the history is full (cnt < depth) every sample written has an index < depth,
        # so n_max = n_lo; once it is full every tap is at or after the first sample
        full = cnt == depth
        offsets = [0, -D]
        if w:
            offsets += [w, -D - w, -w, -D + w]
        taps = {}
        for k in offsets:
            if k in taps:
                continue
            rd = mem.read_port(transparent_for=())
            m.d.comb += [rd.addr.eq(n_lo + (k % depth)), rd.en.eq(inner.o.valid)]
            if k >= 0:
                taps[k] = rd.data
            else:
                ok = Signal(name=f"tap_ok_m{-k}")
                with m.If(inner.o.valid):
                    m.d.sync += ok.eq(full | (n_lo >= -k))
                taps[k] = Mux(ok, rd.data, 0)

        # the registered pulse (the reads' cycle); its constant products are registered for
        # the next cycle, beside the taps (block RAM data registered in the fabric)
        a = Signal(unsigned(aw + 1))
        pt = Signal(unsigned(aw + 1))
        ts = Signal(unsigned(p.ts_bits))
        v = Signal()
        m.d.sync += [v.eq(inner.o.valid), a.eq(q.amplitude), pt.eq(q.partner), ts.eq(q.timestamp)]
        a2 = Signal(unsigned(aw + 1))
        ts2 = Signal(unsigned(p.ts_bits))
        v2 = Signal()
        kp = Signal(unsigned(aw + 5))
        m.d.sync += [v2.eq(v), a2.eq(a), ts2.eq(ts), kp.eq(const_mul(pt, p.pair_keep))]
        t = {}
        for k, val in taps.items():
            t[k] = Signal(unsigned(aw), name=f"tap_{'m' if k < 0 else ''}{abs(k)}")
            m.d.sync += t[k].eq(val)

        keep = (a2 << 3) >= kp
        if p.pair_balance:
            bp = Signal(unsigned(aw + 5))
            m.d.sync += bp.eq(const_mul(a, p.pair_balance))
            e0, eD = t[0], t[-D]
            lo = Mux(e0 < eD, e0, eD)
            keep = keep & ((lo << 4) >= bp)
        if w:
            s1 = Signal(unsigned(aw + 1))
            s2 = Signal(unsigned(aw + 1))
            m.d.comb += [s1.eq(t[w] + t[-D - w]), s2.eq(t[-w] + t[-D + w])]
            keep = keep & (a2 >= s1) & (a2 >= s2)
        m.d.sync += [self.o.valid.eq(v2 & keep),
                     self.o.payload.amplitude.eq(a2 >> 1),
                     self.o.payload.timestamp.eq(ts2)]
