"""Monopulse FPGA front end: the bit-exact model, the specification of the hardware
(:mod:`hdl.monopulse.frontend`). Parameters, register map and record layout are in
:mod:`hdl.monopulse.params`.

Chain (one ``sync`` clock = the ADC rate; 4 phase-coherent channels)::

    4 ADC ----------------------------------------------------+
    replica chip --(NCO latency)--+                            |
    NCO (shared) -> LO * (+-1) ----+-> 4 x DDC (external LO) -> 4 x CIC (-> 4 x FIR)
      -> 4 x complex correction k_i (registers) -> beams S, dA, dE, dd
      -> accumulate N snapshots -> normalise -> Im(d S*), |S|^2 -> CORDIC (both axes)
      -> u = u0 + 2 a / Dx, v = v0 + 2 a / Dy -> one record -> FIFO -> DSP

Per ADC sample (one per ``i.valid`` cycle)
------------------------------------------
The input word carries the four ADC codes and the replica bit of the sample's chip (0 = +1,
1 = -1). The shared NCO (:class:`hdl.nco.Nco`, word :attr:`MonopulseFrontendParams.nco_freq_word`,
fixed) gives ``(cos, sin)``; *replica wipe-off*: the LO is negated when the chip is -1 (the
NCO's table is symmetric, so the negation never overflows) and drives the four DDCs
(:class:`hdl.ddc.Ddc`, ``external_lo=True``). Despreading at the LO instead of after the
filter costs one negation for all four channels; with the default integrate-and-dump
(CIC N=1, R = fs / chip rate, chips constant over a decimation group) it equals
``sum_n z(n) c(n)`` exactly, so the matched filter of the golden chain
(:mod:`dsp.monopulse.golden`) is the accumulation that follows. Each DDC output goes through
a CIC decimator (:class:`hdl.cic.Cic`) and optionally a FIR decimator (:class:`hdl.fir.Fir`);
snapshot ``k`` is the ``k``-th decimator output since reset.

Per snapshot
------------
*Correction.* ``w_i = k_i z_i`` by a complex mixer (:class:`hdl.mixer.Mixer`,
``complex_input=True``, LO port ``cos = Re k_i``, ``sin = -Im k_i``); ``k_i`` is the channel's
coefficient register, ``(re + j im) / 2**(corr_coef_bits - 1)``, each part in
``[-(2**(b-1) - 1), 2**(b-1) - 1]`` (symmetric, so ``-im`` fits). The DSP writes the digital
steering ``exp(j phi_i0)`` times its calibration into it. Output scaled by
``2**-corr_headroom_bits`` of full scale, saturating.

*Beams* (the monopulse paper's quadrant mapping)::

    S = w1 + w2 + w3 + w4,  dA = (w1 + w2) - (w3 + w4),  dE = (w1 + w3) - (w2 + w4),
    dd = (w1 + w4) - (w2 + w3)

``dd`` (the double difference) makes the four beams a Hadamard transform of the channels,
so the DSP can recover every channel's matched-filter output for calibration:
``S_1 = (S + dA + dE + dd) / 4`` etc.

*Matched filter.* Block ``b`` is snapshots ``[b N, (b + 1) N)``; its beams are summed
exactly in ``acc_width`` bits (never overflows).

Per block (the angle unit)
--------------------------
1. Normalise (block floating point, common to the six S/dA/dE values so the ratios are
   kept): ``L`` = the signed width of the largest of them, ``r = max(0, L - cordic_in_bits)``,
   each value ``>> r`` (floor).
2. ``x = Sr^2 + Si^2``, ``y_A = dAi Sr - dAr Si``, ``y_E = dEi Sr - dEr Si``
   (``y / x = Im(d / S)``, no division).
3. Vectoring CORDIC (:class:`dsp.cordic.CordicConfig`, ``width = 2 cordic_in_bits + 1``,
   ``cordic_iterations``, signed binary angle of ``angle_bits`` per turn; ``x >= 0`` so the
   pre-rotation never happens; ``x = y = 0`` gives 0): ``a = atan(Im(d / S))`` in turns.
4. Direction cosines: ``dphi = -2 a`` (rad ``= -4 pi a_turns``), ``u = u0 - dphi / (2 pi Dx)
   = u0 + 2 a_turns / Dx``: ``du = round_half_up(a k_x / 2**(angle_bits + k_frac - dc_frac_bits))``
   with the constant ``k_x = round(2 / Dx 2**k_frac)`` (``dc_coef_bits``), ``u = u0 + du`` in
   ``dc_frac_bits`` fraction bits (``dc_bits = dc_frac_bits + 3`` signed: never overflows).
   ``u0``, ``v0`` are the steering registers (the command the DSP sent to the beam control
   unit). Azimuth/elevation (``atan2``, ``arcsin``) stay on the DSP: the tracker works on
   direction cosines, so the board hands over what it tracks.

Registers (bus ``reg_we``, ``reg_addr``, ``reg_data``; double buffered)
---------------------------------------------------------------------
:data:`REG_COEF` + i (i = 0..3): channel ``i + 1``'s coefficient, ``re | im << corr_coef_bits``
(two's complement each); :data:`REG_U0`, :data:`REG_V0`: steering direction cosines
(two's complement, ``dc_frac_bits`` fraction bits, ``|u0| <= 1``). A write in cycle ``c``
lands in the shadow register from cycle ``c + 1``. At the *block boundary* of block ``b``,
the cycle its last snapshot enters the correction stage, the shadows become active for
block ``b + 1`` (a write in the boundary cycle itself waits for the next boundary); the
record of block ``b`` carries the ``u0, v0`` active during block ``b``. Reset: every
coefficient :attr:`MonopulseFrontendParams.unit_coef` (gain 1 - 2**-(b-1), phase 0),
``u0 = v0 = 0``.

Record (LSB first; :attr:`MonopulseFrontendParams.record`)
---------------------------------------------------------------
``block`` (``block_bits``, wraps), ``u``, ``v`` (``dc_bits`` signed), ``ang_a``, ``ang_e``
(``angle_bits`` signed: ``a`` of each axis, turns), ``shift`` (the normalisation ``r``),
``s_re, s_im, da_re, da_im, de_re, de_im, dd_re, dd_im`` (``acc_width`` signed: the
accumulated beams, before normalisation), split into ``record_words`` FIFO words of
``fifo_width`` bits (word 0 = the lowest bits). It enters the FIFO
:attr:`MonopulseFrontendParams.latency` cycles after the input cycle of the ADC sample
that completes the block's last snapshot.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dsp.fixed import shift_right
from hdl.model.cic import cic_model
from hdl.model.ddc import DdcModel
from hdl.model.fifo import FifoState, fifo_model_events
from hdl.model.fir import fir_model
from hdl.model.mixer import MixerModel
from hdl.model.nco import NcoModel
from .params import ACC_FIELDS, BEAMS, REG_COEF, REG_U0, REG_V0, MonopulseFrontendParams

__all__ = ["MonopulseFrontendModel", "MonopulseRecords", "hadamard_channels", "angle_unit",
           "angle_error_bound"]


def hadamard_channels(rec: dict) -> np.ndarray:
    """The four channels' accumulated (corrected) outputs from a record's beams:
    ``S_1 = (S + dA + dE + dd) / 4``, ``S_2 = (S + dA - dE - dd) / 4``,
    ``S_3 = (S - dA + dE - dd) / 4``, ``S_4 = (S - dA - dE + dd) / 4`` (complex, LSBs)."""
    b = {n: rec[f"{n}_re"] + 1j * rec[f"{n}_im"] for n in BEAMS}
    s, a, e, d = b["s"], b["da"], b["de"], b["dd"]
    return np.array([s + a + e + d, s + a - e - d, s - a + e - d, s - a - e + d]) / 4


# -- the angle unit ------------------------------------------------------------------------

def angle_unit(acc: np.ndarray, u0: np.ndarray, v0: np.ndarray,
               params: MonopulseFrontendParams) -> dict:
    """Bit-exact angle unit on accumulated beams ``acc`` (m, 8) int64 (the order of
    :data:`BEAMS`, re/im) with the blocks' steering words ``u0``, ``v0`` (signed ints).
    Returns the record fields ``u, v, ang_a, ang_e, shift`` as int64 arrays."""
    p = params
    acc = np.asarray(acc, np.int64).reshape(-1, 8)
    six = acc[:, :6]
    mag = np.bitwise_or.reduce(six ^ (six >> np.int64(63)), axis=1) if len(acc) else \
        np.zeros(0, np.int64)
    length = np.array([int(m).bit_length() + 1 for m in mag], np.int64)
    r = np.maximum(length - p.cordic_in_bits, 0)
    t = six >> r[:, None]
    sr, si, ar, ai, er, ei = (t[:, j] for j in range(6))
    x = sr * sr + si * si
    ya = ai * sr - ar * si
    ye = ei * sr - er * si
    cfg = p.cordic
    ang_a = cfg(ya, x).angle
    ang_e = cfg(ye, x).angle
    out = {"shift": r, "ang_a": ang_a, "ang_e": ang_e}
    for name, ang, base, (k, s) in (("u", ang_a, u0, p.dc_coefs[0]),
                                    ("v", ang_e, v0, p.dc_coefs[1])):
        out[name] = np.asarray(base, np.int64) + shift_right(ang * np.int64(k), s, "half_up")
    return out


def angle_error_bound(params: MonopulseFrontendParams, x_lsb) -> tuple[float, float]:
    """Bound on ``|u - u_exact|`` (and ``v``) from the angle unit alone, given the
    magnitude ``x_lsb`` of the CORDIC input vector (normalised LSBs squared): the CORDIC's
    angle bound (:meth:`dsp.cordic.CordicConfig.angle_error_bound`, in turns times
    ``2 / D``), the ``2 / D`` constant's quantisation, the half-up rounding of ``du``; the
    normalisation's floor (each of S, d within 1 LSB, at least ``2**(cordic_in_bits - 2)``
    for the largest) is the caller's term (:meth:`MonopulseFrontendModel` tests add it)."""
    p = params
    out = []
    for d, (k, s) in zip((p.spacing_x_wl, p.spacing_y_wl), p.dc_coefs):
        turns = float(p.cordic.angle_error_bound(x_lsb)) / (2 * math.pi)
        kf = s + p.dc_frac_bits - p.angle_bits
        coef = abs(k / 2.0 ** kf - 2 / d) * 0.25
        out.append(2 / d * turns + coef + 0.5 * 2.0 ** -p.dc_frac_bits)
    return out[0], out[1]


# -- the model ---------------------------------------------------------------------------

@dataclass
class MonopulseRecords:
    """Records a model step produced (before the FIFO)."""

    cycles: np.ndarray     #: FIFO input cycle of each record
    values: list           #: record values (Python ints)
    fields: dict           #: field name -> int64 array (one entry per record)
    overflows: int = 0     #: saturated correction outputs in this step


class MonopulseFrontendModel:
    """Bit-exact model of :class:`hdl.monopulse.frontend.MonopulseFrontEnd` before its FIFO,
    chunk by chunk.

    ``step(x, chips, writes, cycles=...)`` advances over consecutive ADC samples; the state
    (NCO, CIC/FIR registers, partial block, shadow/active registers, writes not yet applied)
    is carried, so a run split anywhere gives the same records. :meth:`run` adds the FIFO.
    """

    def __init__(self, params: MonopulseFrontendParams):
        if not isinstance(params, MonopulseFrontendParams):
            raise ValueError(f"MonopulseFrontendModel needs a MonopulseFrontendParams, not "
                             f"{params!r}")
        self.params = p = params
        self.nco = NcoModel(p.nco)
        self.ddc = DdcModel(p.ddc)
        self.corr = MixerModel(p.corr)
        self._nco_state = None
        self._cic_state = [None] * 4
        self._fir_state = [None] * 4
        unit = p.unit_coef
        self.shadow = {REG_COEF + i: unit for i in range(4)}
        self.shadow.update({REG_U0: 0, REG_V0: 0})
        self.active = dict(self.shadow)
        self._writes: list[tuple[int, int, int]] = []   # (cycle, reg, value), sorted
        self.n_samples = 0
        self.n_snapshots = 0
        self.next_cycle = 0
        self._acc = np.zeros(8, np.int64)
        self.fifo_state = FifoState()
        # Snapshots decimated but not yet at the correction input before the horizon (their
        # block boundary may still see a register write): (z, t_corr, k).
        self._pend = (np.zeros((0, 4, 2), np.int64), np.zeros(0, np.int64),
                      np.zeros(0, np.int64))

    # -- registers -------------------------------------------------------------------------
    def _latch(self, t_boundary: int) -> tuple[int, int]:
        """Apply the writes before ``t_boundary`` to the shadows, make them active; return
        the (u0, v0) words of the block that ends here."""
        while self._writes and self._writes[0][0] < t_boundary:
            _, reg, v = self._writes.pop(0)
            self.shadow[reg] = v
        u0v0 = (self.active[REG_U0], self.active[REG_V0])
        self.active = dict(self.shadow)
        return u0v0

    def _coefs(self) -> list[tuple[int, int]]:
        b = self.params.corr_coef_bits
        out = []
        for i in range(4):
            v = self.active[REG_COEF + i]
            re, im = v & ((1 << b) - 1), v >> b
            re = re - (1 << b) if re >> (b - 1) else re
            im = im - (1 << b) if im >> (b - 1) else im
            out.append((re, im))
        return out

    def _signed_dc(self, w: int) -> int:
        b = self.params.dc_bits
        return w - (1 << b) if w >> (b - 1) else w

    # -- stepping --------------------------------------------------------------------------
    def step(self, x, chips, writes=(), *, cycles=None, horizon=None) -> MonopulseRecords:
        """Advance over ADC samples ``x`` (n, 4) with replica bits ``chips`` (n,).

        ``writes``: register writes ``(cycle, reg, value)``; a write takes effect at the
        first block boundary in a later cycle (this or a later step). ``cycles``: input
        cycle of each sample (default one per cycle, continuing). ``horizon``: the snapshots
        reaching the correction stage before this cycle are processed (default: the cycle
        after the last sample); the others wait, since a write made later may still land
        before their block boundary (:meth:`advance` processes them).
        """
        p = self.params
        x = np.asarray(x)
        if x.ndim != 2 or x.shape[1] != 4:
            raise ValueError(f"monopulse ADC samples must have shape (n, 4), not {x.shape}")
        if x.size and x.dtype.kind not in "iu":
            raise ValueError(f"monopulse ADC samples must be integers, not dtype {x.dtype}")
        x = x.astype(np.int64)
        c = np.asarray(chips).astype(np.int64).ravel()
        if c.size != x.shape[0]:
            raise ValueError(f"monopulse replica needs one bit per sample ({x.shape[0]}), "
                             f"not {c.size}")
        if c.size and (c.min() < 0 or c.max() > 1):
            raise ValueError("monopulse replica bits must be 0 (+1) or 1 (-1)")
        n = x.shape[0]
        if cycles is None:
            scyc = np.arange(self.next_cycle, self.next_cycle + n, dtype=np.int64)
        else:
            scyc = np.asarray(cycles, np.int64).ravel()
            if scyc.size != n:
                raise ValueError(f"monopulse cycles must give one cycle per sample ({n})")
        regs = p.registers
        new = [(int(cy), int(a), regs.check_write(int(a), v)) for cy, a, v in writes]
        if new:
            self._writes = sorted(self._writes + new, key=lambda w: w[0])
        cos, sin, self._nco_state = self.nco.run(n, p.nco_freq_word, self._nco_state)
        sgn = 1 - 2 * c
        cos, sin = cos * sgn, sin * sgn
        snaps = []
        for ch in range(4):
            i, q = self.ddc.mix(x[:, ch], cos, sin)
            y, self._cic_state[ch] = cic_model(p.cic, np.stack([i, q], axis=1),
                                               self._cic_state[ch])
            if p.fir is not None:
                y, self._fir_state[ch] = fir_model(p.fir, y, self._fir_state[ch])
            snaps.append(y)
        z = np.stack(snaps, axis=1)                       # (m, 4, 2)
        m = z.shape[0]
        k = self.n_snapshots + np.arange(m, dtype=np.int64)
        # ADC sample (chunk index) completing each snapshot, and the cycles that follow.
        last = (k + 1) * p.snapshot_decimation - 1 - self.n_samples
        t_corr = scyc[last] + p.latency_pre if m else np.zeros(0, np.int64)
        self.n_samples += n
        self.n_snapshots += m
        if n:
            self.next_cycle = int(scyc[-1]) + 1
        pz, pt, pk = self._pend
        self._pend = (np.concatenate([pz, z]), np.concatenate([pt, t_corr]),
                      np.concatenate([pk, k]))
        return self.advance(self.next_cycle if horizon is None else horizon)

    def advance(self, horizon: int) -> MonopulseRecords:
        """Process the snapshots waiting for the correction stage with ``t_corr < horizon``
        (every register write before ``horizon`` must have been given)."""
        p = self.params
        pz, pt, pk = self._pend
        j = int(np.searchsorted(pt, horizon))
        z, t_corr, k = pz[:j], pt[:j], pk[:j]
        self._pend = (pz[j:], pt[j:], pk[j:])
        m = z.shape[0]
        k0 = int(k[0]) if m else 0
        N = p.snapshots
        blk = k // N
        w = np.empty((m, 4, 2), np.int64)
        out_cyc, u0s, v0s, accs, blocks = [], [], [], [], []
        over = 0
        # One coefficient set per block: loop over the blocks this chunk touches.
        start = 0
        while start < m:
            b = int(blk[start])
            stop = min(m, (b + 1) * N - k0)
            coefs = self._coefs()
            for ch, (re, im) in enumerate(coefs):
                zi, zq = z[start:stop, ch, 0], z[start:stop, ch, 1]
                pi, pq = self.corr.products((zi, zq), np.full(zi.shape, re), np.full(zi.shape, -im))
                fi, ni = p.corr.out_format.fit(shift_right(pi, p.corr.drop_bits, p.corr_rounding))
                fq, nq = p.corr.out_format.fit(shift_right(pq, p.corr.drop_bits, p.corr_rounding))
                w[start:stop, ch, 0], w[start:stop, ch, 1] = fi, fq
                over += int(ni) + int(nq)
            w1, w2, w3, w4 = (w[start:stop, j] for j in range(4))
            beams = np.concatenate([w1 + w2 + w3 + w4, (w1 + w2) - (w3 + w4),
                                    (w1 + w3) - (w2 + w4), (w1 + w4) - (w2 + w3)], axis=1)
            self._acc = self._acc + beams.sum(axis=0)
            if (b + 1) * N - k0 <= m:                    # the block ends in this chunk
                j = stop - 1
                u0, v0 = self._latch(int(t_corr[j]))
                u0s.append(self._signed_dc(u0))
                v0s.append(self._signed_dc(v0))
                accs.append(self._acc.copy())
                blocks.append(b)
                out_cyc.append(int(t_corr[j]) + p.corr.latency + 2 + p.latency_angle)
                self._acc = np.zeros(8, np.int64)
            start = stop
        acc = np.array(accs, np.int64).reshape(-1, 8)
        f = angle_unit(acc, np.array(u0s, np.int64), np.array(v0s, np.int64), p)
        f["block"] = np.array(blocks, np.int64) & ((1 << p.block_bits) - 1)
        for j, name in enumerate(ACC_FIELDS):
            f[name] = acc[:, j]
        vals = [p.record.pack({k_: f[k_][r] for k_ in f}) for r in range(len(blocks))]
        return MonopulseRecords(np.array(out_cyc, np.int64), vals, f, over)

    def run(self, x, chips, writes=(), *, n_cycles: int, out_ready=None, cycles=None):
        """One step then the FIFO over ``n_cycles`` cycles from the model's FIFO state:
        returns ``(records, fifo_result)`` (records written at or after ``n_cycles`` are
        not offered)."""
        r = self.step(x, chips, writes, cycles=cycles, horizon=n_cycles)
        keep = r.cycles < n_cycles
        p = self.params
        words = np.array([p.record.to_words(v, p.fifo_width) for v, k in zip(r.values, keep) if k],
                         np.int64).reshape(-1, p.record_words)
        ready = np.ones(n_cycles, bool) if out_ready is None else np.asarray(out_ready, bool)
        if ready.size < n_cycles:
            ready = np.r_[ready[:n_cycles], np.ones(n_cycles - ready.size, bool)]
        res = fifo_model_events(r.cycles[keep], words, n_cycles - self.fifo_state.cycle,
                                ready[self.fifo_state.cycle:n_cycles], self.params.fifo,
                                state=self.fifo_state)
        self.fifo_state = res.state
        return r, res
