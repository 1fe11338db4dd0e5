"""The compiled (numba) per-cycle kernel of :func:`hdl.model.fifo.fifo_model` and the layout
of the int64 state vector it reads and updates (the policy is described in
:mod:`hdl.model.fifo`)."""
from __future__ import annotations

import numpy as np

from dsp.jit import njit_cached

# Layout of the int64 state vector the kernel reads and updates.
# (SV_HOLD_V: hold words still to write; the hold words themselves are a separate array.)
SV_OUT_FULL, SV_OUT_REG, SV_HOLD_V, SV_PENDING, SV_OVF, SV_HEAD, SV_CNT, SV_MAXLVL = range(8)


@njit_cached(nogil=True)
def _next_ready(c, lim, rmode, rmask, rbase, period, offset, count, stride):
    """First cycle in ``[c, lim)`` with ``ready`` high, else ``lim``."""
    if rmode == 0:
        while c < lim:
            if rmask[c - rbase]:
                return c
            c += 1
        return lim
    if c < offset:
        c = offset
    else:
        r = (c - offset) % period
        if r > (count - 1) * stride:
            c += period - r
        else:
            m = r % stride
            if m != 0:
                c += stride - m
    return c if c < lim else lim


@njit_cached(nogil=True)
def run_fifo_kernel(wc, words, c, c_end, rmode, rmask, rbase, period, offset, count, stride,
                 depth, wmask, marker_tag, count_max, st, ring, out_w, out_c, dropped,
                 hold, tagw):
    """Run cycles ``c .. c_end - 1``; the policy of :mod:`hdl.model.fifo`, exactly as
    :func:`hdl.model.fifo_reference.fifo_model_reference` steps it (``record_words == 1``).
    ``words`` is ``(n_in, n)``, ``hold`` the hold register's ``n`` words, ``tagw[j]`` the
    tag bits of a record's word ``j``. Returns the number of output words."""
    out_full = st[SV_OUT_FULL]
    out_reg = st[SV_OUT_REG]
    left = st[SV_HOLD_V]          # hold words still to write
    nrec = hold.size
    pending = st[SV_PENDING]
    ovf = st[SV_OVF]
    head = st[SV_HEAD]
    cnt = st[SV_CNT]
    maxlvl = st[SV_MAXLVL]
    cap = depth - 1          # memory words (0 for depth 1: the output register only)
    ring_n = ring.size
    n_in = wc.size
    k = 0
    n_out = 0
    span = (count - 1) * stride
    while c < c_end:
        nin = wc[k] if k < n_in else c_end
        iv = nin == c
        if not iv:
            # Nothing can change while the front end cannot write and the queue cannot
            # move: skip to the next input word or the next ready cycle.
            front_idle = left == 0 and pending == 0
            if front_idle and out_full == 0 and cnt == 0:
                c = nin
                continue
            if depth > 1:
                w_rdy = cnt != cap
            else:
                w_rdy = out_full == 0
            if out_full != 0 and (front_idle or not w_rdy):
                nr = _next_ready(c, nin, rmode, rmask, rbase, period, offset, count, stride)
                if nr > c:
                    c = nr
                    continue
        if rmode == 0:
            rdy = rmask[c - rbase]
        else:
            q = c - offset
            rdy = False
            if q >= 0:
                r = q % period
                rdy = r <= span and r % stride == 0
        if out_full != 0 and rdy:
            out_w[n_out] = out_reg
            out_c[n_out] = c
            n_out += 1
        if depth > 1:
            free = cap - cnt
        else:
            free = 1 - out_full
        w_rdy = free > 0
        fits = free >= nrec
        # behind a word written this cycle (rules 1-2); records never wait in the hold
        fits1 = free >= nrec + 1 if nrec > 1 else w_rdy
        write = False
        wv = 0
        drop = False
        if left != 0:
            if w_rdy:
                write = True
                j = nrec - left
                wv = hold[j] | tagw[j]
                left -= 1
                if iv:
                    if left == 0 and pending == 0 and fits1:
                        for j in range(nrec):
                            hold[j] = words[k, j] & wmask
                        left = nrec
                    else:
                        drop = True
            elif iv:
                drop = True
        elif pending != 0:
            if w_rdy:
                write = True
                wv = marker_tag | pending
                pending = 0
                if iv:
                    if fits1:
                        for j in range(nrec):
                            hold[j] = words[k, j] & wmask
                        left = nrec
                    else:
                        drop = True
            elif iv:
                drop = True
        elif iv:
            if fits:
                write = True
                wv = (words[k, 0] & wmask) | tagw[0]
                if nrec > 1:
                    for j in range(nrec):
                        hold[j] = words[k, j] & wmask
                    left = nrec - 1
            else:
                drop = True
        if drop:
            dropped[k] = True
            if pending < wmask:
                pending += 1
            if ovf < count_max:
                ovf += 1
        if iv:
            k += 1
        if depth > 1:
            if cnt > 0 and (out_full == 0 or rdy):
                out_reg = ring[head]
                head += 1
                if head == ring_n:
                    head = 0
                cnt -= 1
                out_full = 1
            elif rdy:
                out_full = 0
            if write:
                t = head + cnt
                if t >= ring_n:
                    t -= ring_n
                ring[t] = wv
                cnt += 1
        else:
            if write:
                out_reg = wv
                out_full = 1
            elif out_full != 0 and rdy:
                out_full = 0
        if cnt + out_full > maxlvl:
            maxlvl = cnt + out_full
        c += 1
    st[SV_OUT_FULL] = out_full
    st[SV_OUT_REG] = out_reg
    st[SV_HOLD_V] = left
    st[SV_PENDING] = pending
    st[SV_OVF] = ovf
    st[SV_HEAD] = head
    st[SV_CNT] = cnt
    st[SV_MAXLVL] = maxlvl
    return n_out
