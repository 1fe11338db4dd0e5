"""Pulse-peak search: the bit-exact compiled model of :class:`hdl.tacan.peak.PeakSearch`.

The algorithm and the numpy implementation it is tested against
(:func:`dsp.tacan.peak.peak_search_numpy`; :func:`dsp.tacan.peak.peak_search_float` is the
golden's float64 twin) are in :mod:`dsp.tacan.peak`, its parameters and state
(:class:`~dsp.tacan.peak_params.PeakParams`, :class:`~dsp.tacan.peak_params.PeakState`) in
:mod:`dsp.tacan.peak_params`. :func:`peak_search` is a compiled (numba) per-sample loop that
follows the algorithm's steps as written; it runs in chunks with a ``PeakState`` and gives
the same bits as one long run. With ``floor_frac`` the kernel
carries the floor with its ``smooth_log2`` fraction bits (``F``, the HDL's wider floor
register; :attr:`PeakState.nuf`) and derives ``nu = F >> smooth_log2`` from it at each block
end.
"""
from __future__ import annotations

import copy

import numpy as np

from dsp.jit import njit_cached
from dsp.tacan.peak import search_pairs
from dsp.tacan.peak_params import PeakParams, PeakResult, PeakState

__all__ = ["peak_search"]


def peak_search(env, params: PeakParams, state: PeakState | None = None
                ) -> tuple[PeakResult, PeakState]:
    """Bit-exact model of :class:`hdl.tacan.peak.PeakSearch` on a chunk of envelope samples.

    Parameters
    ----------
    env : array of int
        Unsigned envelope samples (``amp_width`` bits), the valid transfers only.
    state : PeakState, optional
        From the previous chunk (not modified); default: just after reset.

    Returns
    -------
    (PeakResult, PeakState)
        ``thresholds`` holds the per-sample threshold (``2**62`` in block 0).
    """
    env = np.asarray(env)
    if env.size and (env.min() < 0 or env.max() >= 1 << params.amp_width):
        raise ValueError(f"peak search input must be unsigned {params.amp_width}-bit integers")
    q = params.search_params
    return search_pairs(np.ascontiguousarray(env, dtype=np.int64), params, state,
                        lambda c, st, a, b: _search_compiled(c, q, st, a, b))


# -- implementation ------------------------------------------------------------------------
@njit_cached(nogil=True)
def _search_kernel(e, n, nu, nuf, bsum, is_open, start, pmax, nmax, below, length,
                   block_log2, clip_log2, smooth_log2, thr_mult, thr_frac, thr_min, hold, max_len,
                   clip_to_floor, floor_frac, ahead, behind, pa, pb, thr, amp, imax, iend,
                   pa_out, pb_out):
    """The integer search, one sample at a time (the module docstring's algorithm as
    written). Writes the per-sample threshold to ``thr`` and the pulses to ``amp``/``imax``/
    ``iend`` (capacity ``len(e) // 2 + 1``: a pulse needs two samples, and one may be carried
    in); returns their count and the new state. With the pair-partner readout (``ahead``
    and ``behind`` as long as ``e``, else empty) the open pulse's ``pa``/``pb`` follow its
    max and go to ``pa_out``/``pb_out``. With ``floor_frac`` the floor is carried as ``nuf``
    (``F``, ``smooth_log2`` fraction bits) and ``nu = nuf >> smooth_log2``."""
    N = e.shape[0]
    partner = ahead.shape[0] == N and N > 0
    mask = (np.int64(1) << block_log2) - 1
    inf = np.int64(1) << np.int64(62)
    b = n >> block_log2
    T = inf if b == 0 else max(thr_min, (nu * thr_mult) >> thr_frac)
    clip = nu << clip_log2
    cnt = 0
    for j in range(N):
        x = e[j]
        thr[j] = T
        if b == 0:
            bsum += x
        elif x <= clip:
            bsum += x
        else:
            bsum += nu if clip_to_floor else clip
        if not is_open:
            if x >= T:
                is_open = True
                start = n
                pmax = x
                nmax = n
                below = 0
                length = 1
                if partner:
                    pa = ahead[j]
                    pb = behind[j]
        else:
            if x > pmax:
                pmax = x
                nmax = n
                if partner:
                    pa = ahead[j]
                    pb = behind[j]
            if x >= T:
                below = 0
            else:
                below += 1
            length += 1
            if below == hold or length == max_len:
                amp[cnt] = pmax
                imax[cnt] = nmax
                iend[cnt] = n
                pa_out[cnt] = pa
                pb_out[cnt] = pb
                cnt += 1
                is_open = False
        if (n & mask) == mask:   # block complete: new floor, threshold of the next block
            m = bsum >> block_log2
            if floor_frac:
                nuf = (m << smooth_log2) if b == 0 else nuf - (nuf >> smooth_log2) + m
                nu = nuf >> smooth_log2
            else:
                nu = m if b == 0 else nu + ((m - nu) >> smooth_log2)
            bsum = 0
            b += 1
            T = max(thr_min, (nu * thr_mult) >> thr_frac)
            clip = nu << clip_log2
        n += 1
    return cnt, n, nu, nuf, bsum, is_open, start, pmax, nmax, below, length, pa, pb


def _search_compiled(e, p: PeakParams, state, ahead=None, behind=None):
    """:func:`_search` (integer) via :func:`_search_kernel`."""
    st = copy.copy(state) if state is not None else PeakState()
    N = e.size
    cap = N // 2 + 1
    thr = np.empty(N, dtype=np.int64)
    amp = np.empty(cap, dtype=np.int64)
    imax = np.empty(cap, dtype=np.int64)
    iend = np.empty(cap, dtype=np.int64)
    pa_out = np.zeros(cap, dtype=np.int64)
    pb_out = np.zeros(cap, dtype=np.int64)
    partner = ahead is not None
    none = np.zeros(0, dtype=np.int64)
    (cnt, n, nu, nuf, bsum, is_open, start, pmax, nmax, below, length, pa, pb) = _search_kernel(
        e, int(st.n), int(st.nu), int(st.nuf), int(st.bsum), bool(st.open), int(st.start),
        int(st.pmax), int(st.nmax), int(st.below), int(st.length), p.block_log2, p.clip_log2,
        p.smooth_log2, p.thr_mult, p.thr_frac, p.thr_min, p.hold, p.max_len,
        bool(p.clip_to_floor), bool(p.floor_frac), ahead.astype(np.int64) if partner else none,
        behind.astype(np.int64) if partner else none, int(st.pa), int(st.pb),
        thr, amp, imax, iend, pa_out, pb_out)
    st.n, st.nu, st.nuf, st.bsum, st.open = int(n), int(nu), int(nuf), int(bsum), bool(is_open)
    if st.open:
        st.start, st.pmax, st.nmax = int(start), int(pmax), int(nmax)
        st.below, st.length = int(below), int(length)
        st.pa, st.pb = int(pa), int(pb)
    else:  # canonical closed state, so equal histories give equal states
        st.start = st.nmax = st.below = st.length = 0
        st.pmax = st.pa = st.pb = 0
    index = imax[:cnt].copy()
    ts = (index * np.int64(p.ts_step)) & np.int64((1 << p.ts_bits) - 1)
    res = PeakResult(amplitude=amp[:cnt].copy(), timestamp=ts, index=index,
                     end_index=iend[:cnt].copy(), thresholds=thr)
    if partner:
        a, b = pa_out[:cnt], pb_out[:cnt]
        res.partner, res.partner_late = np.maximum(a, b), a >= b
    return res, st
