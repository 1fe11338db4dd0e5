"""The compiled step of :mod:`dsp.tacan.kalman`'s filter: one source, two arithmetics.

:func:`_trial` runs one trial's filter over all its steps in terms of the operators of
:mod:`dsp.qops`; numba compiles it for ``float64`` state (the golden filter: every operator
is the real operation) and for ``int64`` state (the fixed-point DSP core: every operator
quantises to the formats of :class:`dsp.tacan.kalman_config.KalmanFixedConfig`, whose integer
constants ``ci`` it reads at the indices below). :func:`step_consts` computes the per-step
values every trial shares; :func:`run_serial` / :func:`run_parallel` run a batch of trials
block by block. :class:`dsp.tacan.kalman.EnvelopeKalman` prepares the inputs and keeps the
state; the design of the filter is described there.
"""
from __future__ import annotations

import numba
import numpy as np

from ..jit import njit_cached
from ..qops import (align, div_norm, div_square, ewma, floor_one, lut_index, mac2, mulw, rs, sat,
                    scale_sat, snorm)
from .phase_ops import rate_dt, sincos_dt

__all__ = ["BLOCK", "EVENT_NAMES", "run_parallel", "run_serial", "step_consts", "_trial"]

#: The event counters, in the order of the kernel's ``ev`` array (``ev[12]``: noise reports).
EVENT_NAMES = ("sat_y", "sat_x", "sat_P", "sat_K", "sat_innov", "sat_r", "sat_rmult",
               "p_clamps", "p_neg", "reinit", "gated", "implausible", "noise_reports",
               "state_faults")
EVENT_INDEX = {n: i for i, n in enumerate(EVENT_NAMES)}

_jit = njit_cached(nogil=True)
# Index of each format's (frac, min, max, half) in the integer constants.
_Y, _X, _P, _K, _CS, _IV, _R = 5, 9, 13, 17, 21, 25, 29


@_jit
def step_consts(lut, dts, rms, ci, cv, out):
    """Per-step values shared by all trials: out[k] = (sa, ca, sb, cb, q_rot, q_dc, r_mult)."""
    csf, csh, ph = ci[_CS], ci[_CS + 3], ci[_P + 3]
    for k in range(dts.size):
        dt = dts[k]
        out[k, 0], out[k, 1] = sincos_dt(lut, dt, cv[0], csf, csh)
        out[k, 2], out[k, 3] = sincos_dt(lut, dt, cv[1], csf, csh)
        out[k, 4] = rate_dt(cv[2], dt, ci[4], ph)
        out[k, 5] = rate_dt(cv[3], dt, ci[4], ph)
        out[k, 6] = rms[k]


@_jit
def _reset(x, P, p0):
    for i in range(5):
        x[i] = p0 - p0
        for j in range(5):
            P[i, j] = p0 if i == j else p0 - p0


@_jit
def _predict_only(x, P, xp, Pp):
    """The step keeps the prediction (no measurement, a gated or a noise report)."""
    for i in range(5):
        x[i] = xp[i]
        for j in range(5):
            P[i, j] = Pp[i, j]


@_jit
def _restart(x, P, p0, cnt, ev):
    """Re-initialise after a numerical fault (``S <= 0`` or a negative variance): counted
    as ``p_neg`` and ``reinit``; the warm-up starts again."""
    ev[8] += 1
    ev[9] += 1
    _reset(x, P, p0)
    cnt[0] = 0
    cnt[1] = 0


@_jit
def _trial(x, P, r_st, cnt, ev, sc, ys, ci, cv, bt, gt, bs, nq):
    """One trial over all steps. ``r_st`` (1,) the r estimate, ``cnt`` = [n, consecutive
    gated, consecutive implausible inputs]; ``ys[k]`` equal to ``cv[7]`` (int: the int64
    minimum) or NaN (float) is no measurement: predict only. ``bt`` (empty: none) is the
    expected measurement bias at the predicted amplitude, a table of step ``2**bs`` in the
    ``x`` format's units; with it, a measurement below ``nq[0]`` while the predicted
    amplitude is ``nq[1]`` or more (``nq[1] > 0``) after the warm-up (before it the
    prediction is no yardstick) is a noise report: predict only
    (:meth:`EnvelopeKalman.set_peak_bias`). ``gt`` (as long as ``bt``, in the ``cs``
    format) is the slope of the expected report at that amplitude, ``1 + d bias / ds``:
    the measurement row is ``gt[j] H`` (the linearisation of the biased measurement)."""
    yf = ci[_Y]
    xf, xlo, xhi, xh = ci[_X], ci[_X + 1], ci[_X + 2], ci[_X + 3]
    pf, plo, phi, ph = ci[_P], ci[_P + 1], ci[_P + 2], ci[_P + 3]
    kf, klo, khi, kh = ci[_K], ci[_K + 1], ci[_K + 2], ci[_K + 3]
    csf = ci[_CS]
    ivf, ivlo, ivhi, ivh = ci[_IV], ci[_IV + 1], ci[_IV + 2], ci[_IV + 3]
    rf, rlo, rhi, rh = ci[_R], ci[_R + 1], ci[_R + 2], ci[_R + 3]
    kw_bits = 1
    kv = khi
    while kv > 0:
        kv >>= 1
        kw_bits += 1
    ksplit = min(62 - kw_bits, kf)
    warmup, max_rej, r_smooth, gfrac = ci[0], ci[1], ci[2], ci[3]
    p0, g2, skip = cv[4], cv[5], cv[7]
    zero = p0 - p0
    M = np.empty_like(P)
    Pp = np.empty_like(P)
    xp = np.empty_like(x)
    PH = np.empty_like(x)
    K = np.empty_like(x)
    A = np.zeros_like(P)
    A[4, 4] = align(zero + 1, csf)
    for k in range(ys.size):
        sa, ca, sb, cb = sc[k, 0], sc[k, 1], sc[k, 2], sc[k, 3]
        A[0, 0], A[0, 1], A[1, 0], A[1, 1] = ca, sa, -sa, ca
        A[2, 2], A[2, 3], A[3, 2], A[3, 3] = cb, sb, -sb, cb
        # -- predict x
        for i in range(0, 4, 2):
            a0, a1 = A[i, i], A[i, i + 1]
            xp[i] = sat(rs(a0 * x[i] + a1 * x[i + 1], csf, xh), xlo, xhi, ev, 1)
            xp[i + 1] = sat(rs(-a1 * x[i] + a0 * x[i + 1], csf, xh), xlo, xhi, ev, 1)
        xp[4] = x[4]
        # -- predict P: M = A P (rounded to P), Pp = M A^T + Q (upper triangle, mirrored)
        # (only the columns the upper triangle of Pp reads: j >= the block of i)
        for i in range(5):
            bi = i - (i & 1) if i < 4 else 4
            for j in range(bi, 5):
                if i == 4:
                    M[i, j] = P[i, j]
                else:
                    M[i, j] = sat(mac2(P[bi, j], A[i, bi], P[bi + 1, j], A[i, bi + 1],
                                       csf, csf, ph), plo, phi, ev, 2)
        for i in range(5):
            for j in range(i, 5):
                if j == 4:
                    v = M[i, 4]
                else:
                    bj = j - (j & 1)
                    v = mac2(M[i, bj], A[j, bj], M[i, bj + 1], A[j, bj + 1], csf, csf, ph)
                if i == j:
                    v += sc[k, 4] if i < 4 else sc[k, 5]
                v = sat(v, plo, phi, ev, 2)
                Pp[i, j] = v
                Pp[j, i] = v
        y = ys[k]
        if y != y or y == skip:     # implausible input: not a measurement
            ev[11] += 1
            cnt[2] += 1
            _predict_only(x, P, xp, Pp)
            continue
        cnt[2] = 0
        yh = xp[0] + xp[2] + xp[4]
        if bt.size and nq[1] > 0 and cnt[0] >= warmup and yh >= nq[1] \
                and align(y, xf - yf) < nq[0]:
            ev[12] += 1             # a noise report where the signal stands clear of it
            _predict_only(x, P, xp, Pp)
            continue
        # -- innovation, S, e2 = innov^2 / S
        for i in range(5):
            PH[i] = Pp[i, 0] + Pp[i, 2] + Pp[i, 4]
        if bt.size:                 # what the front end reports at that amplitude, and
            j = min(max(lut_index(yh, bs), 0), bt.size - 1)   # its slope: the row g H
            g = gt[j]
            for i in range(5):
                PH[i] = mulw(PH[i], g, csf, csf, ph)
            S = mulw(PH[0] + PH[2] + PH[4], g, csf, csf, ph) + sc[k, 6]
            yh = yh + bt[j]
        else:
            S = PH[0] + PH[2] + PH[4] + sc[k, 6]
        iv = sat(rs(align(y, xf - yf) - yh, xf - ivf, ivh), ivlo, ivhi, ev, 4)
        r = r_st[0]
        n = cnt[0]
        if not S > 0:
            _restart(x, P, p0, cnt, ev)
            continue
        Sn, nb = snorm(S)
        e2 = div_square(iv, Sn, nb, rf - 2 * ivf + pf, rh, rhi, ev, 5)
        thr = scale_sat(g2, r, gfrac, rhi)     # gate^2 r
        warm = n >= warmup
        gated = warm and e2 > thr
        if gated:
            _predict_only(x, P, xp, Pp)
        else:
            for i in range(5):
                K[i] = div_norm(PH[i], Sn, nb, kf, kh, klo, khi, ev, 3)
            sh_x = kf + ivf - xf
            for i in range(5):
                x[i] = sat(xp[i] + rs(K[i] * iv, sh_x, xh), xlo, xhi, ev, 1)
            bad = False
            for i in range(5):
                for j in range(i, 5):
                    v = sat(Pp[i, j] - mulw(PH[j], K[i], kf, ksplit, ph), plo, phi, ev, 2)
                    if i == j:
                        if v < 0:
                            bad = True
                        else:
                            v = floor_one(v, ev, 7)
                    P[i, j] = v
                    P[j, i] = v
            if bad:
                _restart(x, P, p0, cnt, ev)
                continue
        # r estimate: running mean over the second half of the warm-up, then an EWMA of the
        # innovation power clipped at the gate
        if (not gated) and n >= warmup // 2:
            if warm:
                acc = e2 if e2 < thr else thr
                m = r_smooth
            else:
                acc = e2
                m = max(1, n - warmup // 2 + 1)
            r_st[0] = ewma(r, acc, m, rh, rlo, rhi, ev, 5)
        cnt[0] = n + 1
        if gated:
            ev[10] += 1
            cnt[1] += 1
            if cnt[1] >= max_rej:
                ev[9] += 1
                _reset(x, P, p0)
                cnt[0] = 0
                cnt[1] = 0
        else:
            cnt[1] = 0


#: Steps per block: all trials run one block of the shared per-step values (7 words a
#: step) while it is in cache.
BLOCK = 2048


@_jit
def run_serial(x, P, r, cnt, ev, sc, ys, ci, cv, bt, gt, bs, nq):
    for k0 in range(0, ys.shape[1], BLOCK):
        k1 = min(k0 + BLOCK, ys.shape[1])
        for b in range(ys.shape[0]):
            _trial(x[b], P[b], r[b:b + 1], cnt[b], ev[b], sc[k0:k1], ys[b, k0:k1], ci, cv,
                   bt, gt, bs, nq)


@njit_cached(nogil=True, parallel=True)
def run_parallel(x, P, r, cnt, ev, sc, ys, ci, cv, bt, gt, bs, nq):
    for k0 in range(0, ys.shape[1], BLOCK):
        k1 = min(k0 + BLOCK, ys.shape[1])
        for b in numba.prange(ys.shape[0]):
            _trial(x[b], P[b], r[b:b + 1], cnt[b], ev[b], sc[k0:k1], ys[b, k0:k1], ci, cv,
                   bt, gt, bs, nq)


# ---------------------------------------------------------------------------------------
