"""The compiled kernels of the GNSS channel model (:mod:`hdl.gnss.model`, whose module doc
is the specification they implement).

:func:`channel_kernel` advances one channel over a chunk of samples; :func:`array_kernel`
advances every channel of an array over the same chunk in one call (the channels' states
stacked, one row each), calling :func:`channel_kernel` per channel: one implementation of
the channel, so an array gives the bits of its channels run one by one
(:func:`array_kernel_parallel`: the same with the channels on numba's threads). The kernel keeps
the state in local variables over the chunk and stores it back at its end.

State vector (int64, :data:`NSTATE` entries, indices below): code NCO accumulator, chip,
slew hold left, code word in force, PRN in force, generator epochs since the last dump
boundary, generator epoch / boundary flags of the current sample, code accumulator at the
last boundary, carrier accumulator, carrier word in force, carrier word pending for the
prompt's boundary, carrier / code accumulators kept for the record, epoch counter, the four
shadow registers and the slew-written flag, delay-line position, six accumulators.
"""
from __future__ import annotations

import numba
import numpy as np

from dsp.jit import njit_cached

(CODE_ACC, CHIP, HOLD, CF, PRN, GEN_K, GEN_EP, GEN_FIRST, CODE_EPOCH, CARR_ACC,
 CARR_F, PEND_CARR, CARR_AT, CODE_AT, EPOCH, SH_CARR, SH_CODE, SH_PRN, SH_SLEW,
 SLEW_PEND, POS, ACC0) = range(22)
NSTATE = ACC0 + 6
#: Indices of the per-sample loads are cast to unsigned (all are >= 0): numba then leaves
#: out its negative-index wrap-around, a fifth of the kernel's time.
U = numba.uint64

__all__ = ["channel_kernel", "array_kernel", "array_kernel_parallel", "empty_records", "NSTATE"]


@njit_cached(nogil=True)
def channel_kernel(x, xq, cplx, scyc, wc, wa, wv, wi, wend, st, ring, table, cos_t, sin_t,
                   K, d, code_bits, carr_bits, trunc, epoch_mask, lat, rec_cyc, rec_f):
    """Advance one channel (state ``st``, delay line ``ring``) over samples ``x`` (complex
    input, ``cplx``: I in ``x``, Q in ``xq``; real: ``xq`` unused) at input cycles ``scyc``,
    applying the pending bus writes ``wc, wa, wv`` (cycle, register, value; sorted by
    cycle) from index ``wi`` up to ``wend`` at the dump boundaries; the records go to
    ``rec_cyc`` (FIFO input cycle) and ``rec_f`` (ie qe ip qp il ql epoch carr code).
    Returns (number of records, index of the first write not applied)."""
    L = 2 * d
    cmask = (1 << code_bits) - 1
    pmask = (1 << carr_bits) - 1
    code_acc, chip, hold, cf, prn = st[CODE_ACC], st[CHIP], st[HOLD], st[CF], st[PRN]
    gen_k, gen_ep, gen_first, code_epoch = st[GEN_K], st[GEN_EP], st[GEN_FIRST], st[CODE_EPOCH]
    carr_acc, carr_f, pend_carr = st[CARR_ACC], st[CARR_F], st[PEND_CARR]
    carr_at, code_at, epoch = st[CARR_AT], st[CODE_AT], st[EPOCH]
    sh_carr, sh_code, sh_prn, sh_slew = st[SH_CARR], st[SH_CODE], st[SH_PRN], st[SH_SLEW]
    slew_pend, pos = st[SLEW_PEND], st[POS]
    a0, a1, a2, a3 = st[ACC0], st[ACC0 + 1], st[ACC0 + 2], st[ACC0 + 3]
    a4, a5 = st[ACC0 + 4], st[ACC0 + 5]
    row = prn if 1 <= prn <= 32 else 0
    nrec = 0
    for n in range(x.shape[0]):
        # -- replicas (generator state before this sample's update) ------------------------
        bit_e = table[U(row), U(chip)]
        late = ring[U(pos)]
        pp = pos + d
        if pp >= L:
            pp -= L
        prompt = ring[U(pp)]
        ring[U(pos)] = bit_e | (gen_ep << 1) | (gen_first << 2)
        pos += 1
        if pos == L:
            pos = 0
        bit_p = prompt & 1
        ep_p = (prompt >> 1) & 1
        first_p = (prompt >> 2) & 1
        bit_l = late & 1
        # -- carrier, wipe-off --------------------------------------------------------------
        ph = carr_acc
        a = ph >> trunc
        xi = x[U(n)]
        c_ = cos_t[U(a)]
        s_ = sin_t[U(a)]
        if cplx:
            xqn = xq[U(n)]
            i = xi * c_ + xqn * s_
            q = xqn * c_ - xi * s_
        else:
            i = xi * c_
            q = -xi * s_
        if first_p:
            carr_at = ph
            code_at = code_epoch
            carr_f = pend_carr
        carr_acc = (ph + carr_f) & pmask
        # -- integrate and dump -------------------------------------------------------------
        re = 1 - 2 * bit_e
        rp = 1 - 2 * bit_p
        rl = 1 - 2 * bit_l
        if ep_p:
            epoch = (epoch + 1) & epoch_mask
        if first_p:
            rec_f[nrec, 0] = a0
            rec_f[nrec, 1] = a1
            rec_f[nrec, 2] = a2
            rec_f[nrec, 3] = a3
            rec_f[nrec, 4] = a4
            rec_f[nrec, 5] = a5
            rec_f[nrec, 6] = epoch
            rec_f[nrec, 7] = carr_at
            rec_f[nrec, 8] = code_at
            rec_cyc[nrec] = scyc[n] + lat
            nrec += 1
            a0 = i * re
            a1 = q * re
            a2 = i * rp
            a3 = q * rp
            a4 = i * rl
            a5 = q * rl
        else:
            a0 += i * re
            a1 += q * re
            a2 += i * rp
            a3 += q * rp
            a4 += i * rl
            a5 += q * rl
        # -- code NCO and generator update ----------------------------------------------------
        wrap = 0
        if hold > 0:
            hold -= 1
        else:
            s = code_acc + cf
            code_acc = s & cmask
            if s >> code_bits:
                if chip == 1022:
                    chip = 0
                    wrap = 1
                else:
                    chip += 1
        gen_ep = wrap
        gen_first = 0
        if wrap:
            gen_k += 1
            if gen_k == K:
                gen_k = 0
            if gen_k == 0:
                c = scyc[n]
                while wi < wend and wc[wi] < c:
                    r = wa[wi]
                    if r == 0:
                        sh_carr = wv[wi]
                    elif r == 1:
                        sh_code = wv[wi]
                    elif r == 2:
                        sh_prn = wv[wi]
                    else:
                        sh_slew = wv[wi]
                        slew_pend = 1
                    wi += 1
                cf = sh_code
                prn = sh_prn
                row = prn if 1 <= prn <= 32 else 0
                hold = sh_slew if slew_pend else 0
                slew_pend = 0
                pend_carr = sh_carr
                code_epoch = code_acc
                gen_first = 1
    st[CODE_ACC], st[CHIP], st[HOLD], st[CF], st[PRN] = code_acc, chip, hold, cf, prn
    st[GEN_K], st[GEN_EP], st[GEN_FIRST], st[CODE_EPOCH] = gen_k, gen_ep, gen_first, code_epoch
    st[CARR_ACC], st[CARR_F], st[PEND_CARR] = carr_acc, carr_f, pend_carr
    st[CARR_AT], st[CODE_AT], st[EPOCH] = carr_at, code_at, epoch
    st[SH_CARR], st[SH_CODE], st[SH_PRN], st[SH_SLEW] = sh_carr, sh_code, sh_prn, sh_slew
    st[SLEW_PEND], st[POS] = slew_pend, pos
    st[ACC0], st[ACC0 + 1], st[ACC0 + 2], st[ACC0 + 3] = a0, a1, a2, a3
    st[ACC0 + 4], st[ACC0 + 5] = a4, a5
    return nrec, wi


@njit_cached(nogil=True)
def array_kernel(x, xq, cplx, scyc, wc, wa, wv, wstart, wend, st, ring, table, cos_t, sin_t,
                 K, d, code_bits, carr_bits, trunc, epoch_mask, lat, rec_cyc, rec_f, nrec):
    """:func:`channel_kernel` for every channel ``ch`` (row ``ch`` of ``st``, ``ring``,
    ``rec_cyc``, ``rec_f``; its writes ``wstart[ch] .. wend[ch]`` of ``wc, wa, wv``) over the
    same samples. ``nrec[ch]`` gets its number of records, ``wstart[ch]`` its first write
    not applied."""
    for ch in range(st.shape[0]):
        nrec[ch], wstart[ch] = channel_kernel(
            x, xq, cplx, scyc, wc, wa, wv, wstart[ch], wend[ch], st[ch], ring[ch], table,
            cos_t, sin_t, K, d, code_bits, carr_bits, trunc, epoch_mask, lat, rec_cyc[ch],
            rec_f[ch])


@njit_cached(nogil=True, parallel=True)
def array_kernel_parallel(x, xq, cplx, scyc, wc, wa, wv, wstart, wend, st, ring, table, cos_t,
                          sin_t, K, d, code_bits, carr_bits, trunc, epoch_mask, lat, rec_cyc,
                          rec_f, nrec):
    """:func:`array_kernel` with the channels shared out among numba's threads (each
    channel's state and outputs are its own: the same bits)."""
    for ch in numba.prange(st.shape[0]):
        nrec[ch], wstart[ch] = channel_kernel(
            x, xq, cplx, scyc, wc, wa, wv, wstart[ch], wend[ch], st[ch], ring[ch], table,
            cos_t, sin_t, K, d, code_bits, carr_bits, trunc, epoch_mask, lat, rec_cyc[ch],
            rec_f[ch])


def empty_records(channels: int, n_samples: int):
    """Record buffers of :func:`array_kernel` for a chunk of ``n_samples`` (a record closes
    at most once per code period, over 2000 samples at the lowest sample rate)."""
    m = n_samples // 1000 + 2
    return (np.zeros((channels, m), np.int64), np.zeros((channels, m, 9), np.int64),
            np.zeros(channels, np.int64))
