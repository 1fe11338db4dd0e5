"""GPS L1 C/A tracking channel: parameters, register map, record layout and bit-exact model.

The hardware is :mod:`hdl.gnss.channel`; this module is its specification.

Per ADC sample (one per ``i.valid`` cycle)
------------------------------------------
*Code generator.* ``chip`` (0..1022) indexes the PRN's C/A code (:mod:`dsp.gnss.ca_code`;
G1/G2 registers reset to all ones at every code epoch, so the generator's output is the
table entry ``code[prn][chip]``; a PRN register outside 1-32 gives G1 alone). The *early*
replica is the generator's current chip; *prompt* and *late* are the same chip stream
delayed by ``d`` and ``2 d`` samples, ``d = el_spacing_samples / 2`` (spacing counted in
samples, so early-minus-late = ``el_spacing_samples / samples_per_chip`` chips: 8 samples =
0.5 chip at 16.368 MS/s). Logic 0 is the +1 replica, logic 1 is -1.

*Code NCO.* A ``code_phase_bits`` accumulator: after the sample, unless a slew hold is
running (then ``hold -= 1`` and nothing moves), ``acc += code_freq``; a carry advances the
chip; a carry at chip 1022 is a *generator epoch* (chip 0 starts at the next sample).

*Double-buffered registers.* The DSP writes shadow registers over the register bus
(:data:`REG_CARR_FREQ`, :data:`REG_CODE_FREQ`, :data:`REG_PRN`, :data:`REG_SLEW`; a bus write
in cycle ``c`` is in the shadow from cycle ``c + 1``). At every ``dump_epochs``-th
generator epoch (a *dump boundary*, sample ``n`` in cycle ``c_n``) the shadow registers
written before cycle ``c_n`` become active: code frequency and PRN from the next sample,
the slew (if one was written since the last boundary) as a hold of that many samples
starting at the next sample -- delaying the code by ``slew`` samples -- and the carrier
frequency from the prompt's boundary ``d + 1`` samples later, so that each integration of
the prompt sees one carrier word. The code accumulator at the boundary is kept for the
record.

*Carrier and wipe-off.* The carrier NCO (:class:`hdl.nco.Nco`, no dither, its phase port
fed by the channel's ``carr_phase_bits`` accumulator) gives ``cos, sin`` of the sample's
phase ``carr_acc`` (then ``carr_acc += carr_freq``); the real mixer gives
``I = x cos``, ``Q = -x sin`` at full precision (no rounding). A 1-bit ADC word ``s`` in
{0, -1} means ``x = 2 s + 1`` (sign samples +-1).

*Integrate and dump.* Six accumulators ``I/Q x E/P/L`` add ``I * r``, ``Q * r``. On the
first sample of a prompt integration they are dumped as one record and restart from that
sample's products; ``epoch`` counts prompt code epochs since reset (mod
``2**epoch_bits``, the record's value includes the epoch it closes), ``carr_phase`` is the
carrier accumulator of the first sample of the *new* integration and ``code_phase`` the
code accumulator (chip fraction) of the generator at its boundary, which is the prompt's
fraction at the prompt's boundary. The record enters the FIFO :attr:`GnssChannelParams.latency`
cycles after that first sample's input cycle.

Record layout (LSB first): ``ie, qe, ip, qp, il, ql`` (signed ``acc_width`` each),
``epoch`` (``epoch_bits``), ``carr_phase`` (``carr_phase_bits``), ``code_phase``
(``code_phase_bits``), then in an array ``channel``; split into FIFO words of
``fifo_width`` bits (word 0 = the lowest bits).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import NamedTuple

import numpy as np

from dsp.jit import njit_cached

from dsp.fixed import check_width
from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, ca_code_table, check_prn
from dsp.record_layout import RecordLayout
from hdl.model.fifo import FifoParams, FifoState, fifo_model_events
from hdl.model.mixer import MixerParams
from hdl.model.nco import NcoParams, nco_freq_word, nco_full_tables

#: Register addresses (per channel; an array adds ``4 * channel``).
REG_CARR_FREQ, REG_CODE_FREQ, REG_PRN, REG_SLEW = range(4)
REG_NAMES = {"carr_freq": REG_CARR_FREQ, "code_freq": REG_CODE_FREQ, "prn": REG_PRN,
             "slew": REG_SLEW}
#: Signal bandwidth of C/A (main lobe, null to null), Hz: the lowest sample rate accepted.
CA_BANDWIDTH_HZ = 2 * CHIP_RATE_HZ
#: Record fields before ``channel``.
ACC_FIELDS = ("ie", "qe", "ip", "qp", "il", "ql")


def _number(name, v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(float(v)):
        raise ValueError(f"GNSS channel {name} must be a finite number, not {v!r}")
    return float(v)


class CodeWord(NamedTuple):
    word: int          #: code NCO frequency word
    actual_hz: float   #: chipping rate it gives, chip/s
    error_hz: float    #: actual - requested


def code_freq_word(chip_rate_hz: float, *, fs_hz: float, code_phase_bits: int) -> CodeWord:
    """Code NCO word for ``chip_rate_hz`` (nominal 1.023e6 plus code Doppler) at ``fs_hz``,
    rounded to nearest; at most one chip per sample."""
    check_width("GNSS code_phase_bits", code_phase_bits, minimum=8, maximum=32)
    r = _number("chip_rate_hz", chip_rate_hz)
    fs = _number("fs_hz", fs_hz)
    if not 0 < r < fs:
        raise ValueError(f"code chip rate must be in (0, fs_hz = {fs!r}) (at most one chip "
                         f"per sample), not {chip_rate_hz!r}")
    n = round(Fraction(r) / Fraction(fs) * (1 << code_phase_bits))
    if n >= 1 << code_phase_bits:
        raise ValueError(f"code chip rate {chip_rate_hz!r} rounds to one chip per sample")
    actual = float(Fraction(n) * Fraction(fs) / (1 << code_phase_bits))
    return CodeWord(int(n), actual, actual - r)


def dump_epochs_for(dump_s: float) -> int:
    """Code periods in a dump of ``dump_s`` seconds; ``ValueError`` unless it is a whole
    number (>= 1) of 1 ms code periods."""
    t = _number("dump length", dump_s)
    k = round(t / 1e-3)
    if k < 1 or abs(t - k * 1e-3) > 1e-12:
        raise ValueError(f"dump length must be a whole number (>= 1) of 1 ms code periods, "
                         f"not {dump_s!r} s")
    return int(k)


@dataclass(frozen=True)
class GnssChannelParams:
    """Parameters of one tracking channel (:class:`hdl.gnss.channel.GnssChannel`).

    Parameters
    ----------
    fs_hz : float
        ADC sample rate = clock rate, Hz (>= 2.046 MHz, the C/A main-lobe bandwidth).
    if_hz : float
        Nominal IF, Hz, in the first Nyquist zone ``[0, fs_hz / 2)``: the reset carrier word.
    adc_bits : int
        Signed ADC word (1..16); 1 bit means sign samples +-1.
    carr_phase_bits, carr_table_bits, lo_bits : int
        Carrier NCO accumulator (8..32), sine-table address (4..12) and LO amplitude bits
        (2..16).
    code_phase_bits : int
        Code NCO accumulator (8..32).
    el_spacing_samples : int
        Early-minus-late spacing in samples, even, 2..128 (prompt is in the middle).
    dump_epochs : int
        Code periods per dump, 1..64 (must be whole: see :func:`dump_epochs_for`).
    slew_bits : int
        Width of the slew register (samples of code hold), 1..24.
    epoch_bits : int
        Width of the record's epoch counter, 1..32.
    max_code_doppler_hz : float
        Largest code-rate decrease below 1.023 Mcps the accumulator widths allow for, Hz.
    prn : int
        PRN at reset, 1..32.
    fifo_width, fifo_depth : int
        FIFO payload bits per word and depth in words.
    record_words : int, optional
        FIFO words per record; default the fewest that hold the record.
    channel_bits : int
        Width of a ``channel`` field appended to the record (0 for a single channel; set
        by :class:`GnssChannelArray`).
    """

    fs_hz: float = 16.368e6
    if_hz: float = 4.092e6
    adc_bits: int = 2
    carr_phase_bits: int = 32
    carr_table_bits: int = 8
    lo_bits: int = 4
    code_phase_bits: int = 32
    el_spacing_samples: int = 8
    dump_epochs: int = 1
    slew_bits: int = 16
    epoch_bits: int = 16
    max_code_doppler_hz: float = 100.0
    prn: int = 1
    fifo_width: int = 51
    fifo_depth: int = 512
    record_words: int | None = None
    channel_bits: int = 0

    def __post_init__(self):
        fs = _number("fs_hz", self.fs_hz)
        if fs < CA_BANDWIDTH_HZ:
            raise ValueError(f"GNSS sample rate fs_hz must be >= the C/A signal bandwidth "
                             f"{CA_BANDWIDTH_HZ:g} Hz, not {self.fs_hz!r}")
        f_if = _number("if_hz", self.if_hz)
        if not 0 <= f_if < fs / 2:
            raise ValueError(f"GNSS IF must lie in the first Nyquist zone [0, fs_hz/2 = "
                             f"{fs / 2:g}) Hz, not {self.if_hz!r}")
        check_width("GNSS adc_bits", self.adc_bits, minimum=1, maximum=16)
        check_width("GNSS carr_phase_bits", self.carr_phase_bits, minimum=8, maximum=32)
        check_width("GNSS carr_table_bits", self.carr_table_bits, minimum=4,
                    maximum=min(12, self.carr_phase_bits))
        check_width("GNSS lo_bits", self.lo_bits, minimum=2, maximum=16)
        check_width("GNSS code_phase_bits", self.code_phase_bits, minimum=8, maximum=32)
        s = self.el_spacing_samples
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or not 2 <= s <= 128 \
                or s % 2:
            raise ValueError(f"GNSS el_spacing_samples (early-minus-late, samples) must be an "
                             f"even integer in [2, 128], not {s!r}")
        k = self.dump_epochs
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
            if isinstance(k, (float, np.floating)) and float(k).is_integer():
                raise ValueError(f"GNSS dump_epochs must be an int, not {k!r}")
            raise ValueError(f"GNSS dump length must be a whole number of code periods "
                             f"(dump_epochs an integer in [1, 64]), not {k!r}")
        check_width("GNSS dump_epochs", k, minimum=1, maximum=64)
        check_width("GNSS slew_bits", self.slew_bits, minimum=1, maximum=24)
        check_width("GNSS epoch_bits", self.epoch_bits, minimum=1, maximum=32)
        cd = _number("max_code_doppler_hz", self.max_code_doppler_hz)
        if not 0 <= cd < CHIP_RATE_HZ / 2:
            raise ValueError(f"GNSS max_code_doppler_hz must be in [0, {CHIP_RATE_HZ / 2:g}), "
                             f"not {self.max_code_doppler_hz!r}")
        check_prn(self.prn)
        if fs / CHIP_RATE_HZ * CODE_LENGTH < 4 * s:
            raise ValueError(f"GNSS el_spacing_samples must be below a quarter code period, "
                             f"not {s}")
        check_width("GNSS channel_bits", self.channel_bits, minimum=0, maximum=8)
        # A record wider than the FIFO's record is refused here, FIFO limits by FifoParams.
        rw = self.record_words
        if rw is not None:
            check_width("GNSS record_words", rw, minimum=1, maximum=64)
            if rw * self.fifo_width < self.record_bits:
                raise ValueError(
                    f"GNSS record of {self.record_bits} bits is wider than the FIFO record "
                    f"(record_words * fifo_width = {rw} * {self.fifo_width} = "
                    f"{rw * self.fifo_width} bits)")
        self.fifo  # validates width and depth (FifoParams' own messages)

    # -- derived ---------------------------------------------------------------------------
    @property
    def half_spacing(self) -> int:
        """``d``: prompt is ``d`` samples behind early, late ``2 d``."""
        return self.el_spacing_samples // 2

    @property
    def nco(self) -> NcoParams:
        return NcoParams(phase_bits=self.carr_phase_bits, table_bits=self.carr_table_bits,
                         amp_bits=self.lo_bits, dither_bits=0, phase_port=True)

    @property
    def mixer_in_width(self) -> int:
        return max(2, self.adc_bits)

    @property
    def mixer(self) -> MixerParams:
        """Full-precision real mixer (``drop_bits == 0``: nothing rounded, never overflows,
        the NCO's peak being symmetric)."""
        a, b = self.mixer_in_width, self.lo_bits
        return MixerParams(in_width=a, complex_input=False, lo_width=b, out_width=a + b - 1,
                           rounding="floor", overflow="wrap")

    @property
    def iq_width(self) -> int:
        return self.mixer.out_width

    @property
    def max_dump_samples(self) -> int:
        """Longest dump the accumulators are sized for: ``dump_epochs`` code periods at the
        slowest chipping rate plus the longest slew."""
        per = math.ceil(CODE_LENGTH * self.fs_hz / (CHIP_RATE_HZ - self.max_code_doppler_hz))
        return self.dump_epochs * per + (1 << self.slew_bits) - 1

    @property
    def acc_width(self) -> int:
        """Signed accumulator width: ``|I| < 2**(iq_width-1)`` per sample, so
        ``iq_width + ceil(log2(max_dump_samples))`` holds any dump."""
        return self.iq_width + (self.max_dump_samples - 1).bit_length()

    @property
    def reg_data_width(self) -> int:
        return max(self.carr_phase_bits, self.code_phase_bits, self.slew_bits, 6)

    @property
    def record(self) -> RecordLayout:
        """The record's fields, LSB first: the six accumulators, ``epoch``, ``carr_phase``,
        ``code_phase`` and, in an array, ``channel``."""
        f = [(n, self.acc_width, True) for n in ACC_FIELDS]
        f += [("epoch", self.epoch_bits, False), ("carr_phase", self.carr_phase_bits, False),
              ("code_phase", self.code_phase_bits, False)]
        if self.channel_bits:
            f.append(("channel", self.channel_bits, False))
        return RecordLayout(tuple(f))

    @property
    def record_bits(self) -> int:
        return self.record.bits

    @property
    def fifo(self) -> FifoParams:
        rw = self.record_words or -(-self.record_bits // self.fifo_width)
        return FifoParams(width=self.fifo_width, depth=self.fifo_depth, record_words=rw)

    @property
    def latency(self) -> int:
        """Cycles from the input cycle of a dump's first sample to its record at the FIFO
        input: carrier NCO, mixer, replica-product register, accumulator/record register."""
        return self.nco.latency + self.mixer.latency + 2

    # -- register values -------------------------------------------------------------------
    def carr_word(self, f_hz: float) -> int:
        return nco_freq_word(f_hz, f_clk_hz=self.fs_hz, phase_bits=self.carr_phase_bits).word

    def code_word(self, chip_rate_hz: float = CHIP_RATE_HZ) -> int:
        return code_freq_word(chip_rate_hz, fs_hz=self.fs_hz,
                              code_phase_bits=self.code_phase_bits).word

    def check_write(self, reg: int, value: int) -> int:
        """A register write's value, refused if it does not fit (PRN: 1-32)."""
        widths = {REG_CARR_FREQ: self.carr_phase_bits, REG_CODE_FREQ: self.code_phase_bits,
                  REG_SLEW: self.slew_bits}
        if reg == REG_PRN:
            return check_prn(value)
        if reg not in widths:
            raise ValueError(f"GNSS register must be one of {sorted(REG_NAMES.values())}, "
                             f"not {reg!r}")
        v = int(value)
        if not 0 <= v < 1 << widths[reg]:
            raise ValueError(f"GNSS register {reg} takes unsigned {widths[reg]}-bit values, "
                             f"not {value!r}")
        return v


def bus_writes(writes, *, data_width: int = 32) -> list[tuple[int, str, int]]:
    """DSP register writes ``(cycle, addr, value)`` -> port-level writes for
    :func:`cosim.pysim.run_stream` / Verilator: ``reg_we`` high for one cycle with
    ``reg_addr`` and ``reg_data``; at most one write per cycle."""
    ws = sorted((int(c), int(a), int(v)) for c, a, v in writes)
    cyc = [c for c, _, _ in ws]
    if len(set(cyc)) != len(cyc):
        raise ValueError("at most one register write per cycle")
    out = []
    busy = set(cyc)
    for c, a, v in ws:
        out += [(c, "reg_we", 1), (c, "reg_addr", a), (c, "reg_data", v & ((1 << data_width) - 1))]
        if c + 1 not in busy:
            out.append((c + 1, "reg_we", 0))
    return sorted(out, key=lambda w: w[0])


# -- compiled kernel ---------------------------------------------------------------------
# int64 state vector layout
(_CODE_ACC, _CHIP, _HOLD, _CF, _PRN, _GEN_K, _GEN_EP, _GEN_FIRST, _CODE_EPOCH, _CARR_ACC,
 _CARR_F, _PEND_CARR, _CARR_AT, _CODE_AT, _EPOCH, _SH_CARR, _SH_CODE, _SH_PRN, _SH_SLEW,
 _SLEW_PEND, _POS, _ACC0) = range(22)
_NSTATE = _ACC0 + 6


@njit_cached(nogil=True)
def _channel_kernel(x, scyc, wc, wa, wv, wi, st, ring, table, cos_t, sin_t, K, d, code_bits,
                    carr_bits, trunc, epoch_mask, lat, rec_cyc, rec_f):
    """Advance over samples ``x`` (input cycles ``scyc``); returns (records, next write)."""
    L = 2 * d
    cmask = (1 << code_bits) - 1
    pmask = (1 << carr_bits) - 1
    nrec = 0
    for n in range(x.shape[0]):
        # -- replicas (generator state before this sample's update) --------------------
        prn = st[_PRN]
        row = prn if 1 <= prn <= 32 else 0
        bit_e = table[row, st[_CHIP]]
        pos = st[_POS]
        late = ring[pos]
        prompt = ring[(pos + d) % L]
        ring[pos] = bit_e | (st[_GEN_EP] << 1) | (st[_GEN_FIRST] << 2)
        st[_POS] = (pos + 1) % L
        bit_p = prompt & 1
        ep_p = (prompt >> 1) & 1
        first_p = (prompt >> 2) & 1
        bit_l = late & 1
        # -- carrier, wipe-off ----------------------------------------------------------
        ph = st[_CARR_ACC]
        a = ph >> trunc
        xi = x[n]
        i = xi * cos_t[a]
        q = -xi * sin_t[a]
        if first_p:
            st[_CARR_AT] = ph
            st[_CODE_AT] = st[_CODE_EPOCH]
            st[_CARR_F] = st[_PEND_CARR]
        st[_CARR_ACC] = (ph + st[_CARR_F]) & pmask
        # -- integrate and dump ---------------------------------------------------------
        re = 1 - 2 * bit_e
        rp = 1 - 2 * bit_p
        rl = 1 - 2 * bit_l
        if ep_p:
            st[_EPOCH] = (st[_EPOCH] + 1) & epoch_mask
        if first_p:
            for j in range(6):
                rec_f[nrec, j] = st[_ACC0 + j]
            rec_f[nrec, 6] = st[_EPOCH]
            rec_f[nrec, 7] = st[_CARR_AT]
            rec_f[nrec, 8] = st[_CODE_AT]
            rec_cyc[nrec] = scyc[n] + lat
            nrec += 1
            st[_ACC0 + 0] = i * re
            st[_ACC0 + 1] = q * re
            st[_ACC0 + 2] = i * rp
            st[_ACC0 + 3] = q * rp
            st[_ACC0 + 4] = i * rl
            st[_ACC0 + 5] = q * rl
        else:
            st[_ACC0 + 0] += i * re
            st[_ACC0 + 1] += q * re
            st[_ACC0 + 2] += i * rp
            st[_ACC0 + 3] += q * rp
            st[_ACC0 + 4] += i * rl
            st[_ACC0 + 5] += q * rl
        # -- code NCO and generator update ------------------------------------------------
        wrap = 0
        if st[_HOLD] > 0:
            st[_HOLD] -= 1
        else:
            s = st[_CODE_ACC] + st[_CF]
            st[_CODE_ACC] = s & cmask
            if s >> code_bits:
                if st[_CHIP] == 1022:
                    st[_CHIP] = 0
                    wrap = 1
                else:
                    st[_CHIP] += 1
        st[_GEN_EP] = wrap
        st[_GEN_FIRST] = 0
        if wrap:
            st[_GEN_K] += 1
            if st[_GEN_K] == K:
                st[_GEN_K] = 0
            if st[_GEN_K] == 0:
                c = scyc[n]
                while wi < wc.shape[0] and wc[wi] < c:
                    r = wa[wi]
                    if r == 0:
                        st[_SH_CARR] = wv[wi]
                    elif r == 1:
                        st[_SH_CODE] = wv[wi]
                    elif r == 2:
                        st[_SH_PRN] = wv[wi]
                    else:
                        st[_SH_SLEW] = wv[wi]
                        st[_SLEW_PEND] = 1
                    wi += 1
                st[_CF] = st[_SH_CODE]
                st[_PRN] = st[_SH_PRN]
                st[_HOLD] = st[_SH_SLEW] if st[_SLEW_PEND] else 0
                st[_SLEW_PEND] = 0
                st[_PEND_CARR] = st[_SH_CARR]
                st[_CODE_EPOCH] = st[_CODE_ACC]
                st[_GEN_FIRST] = 1
    return nrec, wi


@dataclass
class ChannelRecords:
    """Records a model step produced (before the FIFO)."""

    cycles: np.ndarray                   #: FIFO input cycle of each record
    fields: np.ndarray                   #: (n, 9) int64: ie qe ip qp il ql epoch carr code

    def values(self, params: GnssChannelParams, channel: int | None = None) -> list[int]:
        out = []
        w = params.acc_width
        for row in self.fields:
            d = {n: int(v) for n, v in zip(ACC_FIELDS, row[:6])}
            for n in ACC_FIELDS:   # the hardware's accumulators wrap
                d[n] = ((d[n] + (1 << (w - 1))) & ((1 << w) - 1)) - (1 << (w - 1))
            d.update(epoch=int(row[6]), carr_phase=int(row[7]), code_phase=int(row[8]))
            if params.channel_bits:
                d["channel"] = 0 if channel is None else int(channel)
            out.append(params.record.pack(d))
        return out


class GnssChannelModel:
    """Bit-exact model of the correlator core of one channel, chunk by chunk.

    ``step(samples, writes, cycles=...)`` advances over consecutive ADC samples; the state
    (NCOs, code generator, delay line, accumulators, shadow registers, writes not yet
    applied) is carried to the next call, so a run split into chunks gives the same bits.

    Parameters
    ----------
    params : GnssChannelParams
    """

    _table = None

    def __init__(self, params: GnssChannelParams):
        self.params = p = params
        if GnssChannelModel._table is None:
            GnssChannelModel._table = ca_code_table().astype(np.int64)
        cos_t, sin_t = nco_full_tables(p.nco)
        self._cos, self._sin = cos_t.astype(np.int64), sin_t.astype(np.int64)
        st = np.zeros(_NSTATE, np.int64)
        cw, kw = p.carr_word(p.if_hz), p.code_word()
        st[_CF] = st[_SH_CODE] = kw
        st[_PRN] = st[_SH_PRN] = p.prn
        st[_CARR_F] = st[_PEND_CARR] = st[_SH_CARR] = cw
        self.state = st
        self.ring = np.zeros(p.el_spacing_samples, np.int64)
        self._writes = np.zeros((0, 3), np.int64)
        self.n_samples = 0
        self.next_cycle = 0

    def step(self, samples, writes=(), *, cycles=None) -> ChannelRecords:
        """Advance over ``samples``.

        Parameters
        ----------
        samples : array of int
            ADC words (signed ``adc_bits``), in order.
        writes : iterable of (cycle, reg, value)
            Register writes on the bus (cycle from reset; ``reg`` 0-3 = :data:`REG_CARR_FREQ`
            ...); a write takes effect at the first dump boundary in a later cycle, in this
            or a later step.
        cycles : array of int, optional
            Input cycle of each sample (default: one per cycle, continuing from the last
            step).
        """
        p = self.params
        x = np.asarray(samples)
        if x.dtype.kind not in "iu":
            raise ValueError(f"GNSS samples must be integers, not dtype {x.dtype}")
        x = x.astype(np.int64)
        lo, hi = -(1 << (p.adc_bits - 1)), (1 << (p.adc_bits - 1)) - 1
        if x.size and (x.min() < lo or x.max() > hi):
            raise ValueError(f"GNSS samples must be signed {p.adc_bits}-bit in [{lo}, {hi}]")
        if p.adc_bits == 1:
            x = 2 * x + 1
        if cycles is None:
            scyc = np.arange(self.next_cycle, self.next_cycle + x.size, dtype=np.int64)
        else:
            scyc = np.ascontiguousarray(cycles, dtype=np.int64)
        w = [(int(c), int(a), p.check_write(int(a), v)) for c, a, v in writes]
        if w:
            new = np.array(w, np.int64)
            allw = np.concatenate([self._writes, new])
            self._writes = allw[np.argsort(allw[:, 0], kind="stable")]
        wv = self._writes
        max_rec = x.size // 1000 + 2
        rec_cyc = np.zeros(max_rec, np.int64)
        rec_f = np.zeros((max_rec, 9), np.int64)
        nrec, wi = _channel_kernel(
            x, scyc, np.ascontiguousarray(wv[:, 0]), np.ascontiguousarray(wv[:, 1]),
            np.ascontiguousarray(wv[:, 2]), 0, self.state, self.ring, self._table, self._cos,
            self._sin, p.dump_epochs, p.half_spacing, p.code_phase_bits, p.carr_phase_bits,
            p.nco.trunc_bits, (1 << p.epoch_bits) - 1, p.latency, rec_cyc, rec_f)
        self._writes = wv[wi:]
        self.n_samples += x.size
        if x.size:
            self.next_cycle = int(scyc[-1]) + 1
        return ChannelRecords(rec_cyc[:nrec].copy(), rec_f[:nrec].copy())


# -- whole channel / array with the FIFO ---------------------------------------------------

@dataclass
class ChannelRun:
    """Model prediction of a channel's (or array's) FIFO output."""

    words: np.ndarray           #: packed FIFO output words (payload | tag << width)
    cycles: np.ndarray          #: their output cycles
    record_cycles: np.ndarray   #: FIFO input cycle of each record
    records: list               #: record values (ints), in FIFO input order
    dropped: np.ndarray


class Arbiter:
    """The array's arbiter, chunk by chunk.

    A record pending from cycle ``r`` (per channel at most one at a time) is granted in the
    first cycle ``>= r`` in which no lower channel is pending and at least ``spacing``
    cycles (the FIFO's ``record_words``: it writes one word per cycle) have passed since the
    previous grant; it reaches the FIFO input two cycles after its grant (one-hot select
    register, then the multiplexed record register). Grants are only decided
    below a *horizon* (no later record can be pending before it); the rest wait for the next
    :meth:`feed`.
    """

    def __init__(self, spacing: int = 1):
        self.spacing = int(spacing)
        self.t = -(1 << 62)            # earliest cycle of the next grant
        self.waiting: list = []        # (ready, channel, value) not granted yet

    def feed(self, ready_cycles, channels, values, horizon: int | None = None):
        """Add records, grant what can be decided; returns (FIFO input cycles, values)."""
        import heapq
        w = sorted(self.waiting + [(int(r), int(c), v) for r, c, v in
                                   zip(ready_cycles, channels, values)],
                   key=lambda e: (e[0], e[1]))
        lim = (1 << 62) if horizon is None else int(horizon)
        pend: list = []
        out_c, out_v = [], []
        k, t = 0, self.t
        while True:
            if not pend:
                if k >= len(w):
                    break
                t = max(t, w[k][0])
            if t >= lim:
                break
            while k < len(w) and w[k][0] <= t:
                heapq.heappush(pend, (w[k][1], w[k][0], k))
                k += 1
            _, _, j = heapq.heappop(pend)
            out_c.append(t + 2)
            out_v.append(w[j][2])
            t += self.spacing
        self.t = t
        self.waiting = [w[j] for _, _, j in pend] + w[k:]
        return np.array(out_c, np.int64), out_v


def arbitrate(ready_cycles, channels, spacing: int = 1) -> np.ndarray:
    """FIFO input cycles the :class:`Arbiter` gives records pending from ``ready_cycles``
    (same order as given)."""
    idx = list(range(len(ready_cycles)))
    c, v = Arbiter(spacing).feed(ready_cycles, channels, idx)
    out = np.empty(len(idx), np.int64)
    out[np.asarray(v, np.int64)] = c
    return out


class GnssArrayModel:
    """Bit-exact model of :class:`hdl.gnss.channel.GnssChannelArray` (``channels = 1``
    without arbiter and channel field: :class:`hdl.gnss.channel.GnssChannel`).

    ``step(samples, writes, cycles=...)`` returns the records of the chunk with their FIFO
    input cycles (state carried, chunks give the same bits); :meth:`run` is a whole run from
    reset including the FIFO (:func:`hdl.model.fifo.fifo_model_events`).
    """

    def __init__(self, params: GnssChannelParams, channels: int = 1, *, arbiter=None):
        self.params = params
        self.channels = channels
        self.arbiter = channels > 1 if arbiter is None else arbiter
        self.models = [GnssChannelModel(params) for _ in range(channels)]
        self._arb = Arbiter(params.fifo.record_words)
        self.fifo_state = FifoState()

    def step(self, samples, writes=(), *, cycles=None):
        """Advance every channel over ``samples``; writes are ``(cycle, addr, value)`` with
        ``addr = 4 * channel + reg``. Returns ``(fifo_input_cycles, record_values)`` of the
        records decided so far (in the array, records the arbiter cannot grant yet because a
        later chunk may hold a lower channel's record wait for the next step or
        :meth:`flush`)."""
        per = [[] for _ in range(self.channels)]
        for c, a, v in writes:
            ch, reg = divmod(int(a), 4)
            if not 0 <= ch < self.channels:
                raise ValueError(f"GNSS register address {a} is beyond {self.channels} "
                                 f"channels")
            per[ch].append((c, reg, v))
        cyc, vals, chans = [], [], []
        for ch, m in enumerate(self.models):
            r = m.step(samples, per[ch], cycles=cycles)
            cyc.append(r.cycles)
            vals += r.values(self.params, ch)
            chans.append(np.full(r.cycles.size, ch))
        cyc = np.concatenate(cyc) if cyc else np.zeros(0, np.int64)
        chans = np.concatenate(chans) if chans else np.zeros(0, np.int64)
        if self.arbiter:
            # A later sample (cycle >= next_cycle) makes a record pending from
            # next_cycle + latency + 1 at the earliest.
            horizon = self.models[0].next_cycle + self.params.latency + 1
            return self._arb.feed(cyc + 1, chans, vals, horizon)
        order = np.argsort(cyc, kind="stable")
        return cyc[order], [vals[j] for j in order]

    def flush(self):
        """Grant every record still waiting (end of the run)."""
        if not self.arbiter:
            return np.zeros(0, np.int64), []
        return self._arb.feed([], [], [], None)

    def run(self, samples, writes=(), *, n_cycles: int, out_ready=None,
            cycles=None) -> ChannelRun:
        """One whole run from reset: records, then the FIFO over ``n_cycles`` cycles."""
        rc, vals = self.step(samples, writes, cycles=cycles)
        rc2, vals2 = self.flush()
        rc = np.concatenate([rc, rc2])
        vals = list(vals) + list(vals2)
        keep = rc < n_cycles
        rc = rc[keep]
        vals = [v for v, k in zip(vals, keep) if k]
        p = self.params
        fp = p.fifo
        recs = np.array([p.record.to_words(v, fp.width, fp.record_words) for v in vals],
                        np.int64).reshape(-1, fp.record_words)
        ready = np.ones(n_cycles, bool) if out_ready is None else \
            np.asarray(out_ready, bool)[:n_cycles]
        if ready.size < n_cycles:
            ready = np.concatenate([ready, np.ones(n_cycles - ready.size, bool)])
        res = fifo_model_events(rc, recs, n_cycles, ready, fp, state=self.fifo_state)
        self.fifo_state = res.state
        return ChannelRun(res.words, res.cycles, rc, vals, res.dropped)
