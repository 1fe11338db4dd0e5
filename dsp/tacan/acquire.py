"""Reference acquisition near the noise floor: evidence integrated across bursts (issue 18).

:func:`dsp.tacan.decode.decode` decides every burst alone (a burst needs ``min_fraction``
of its pulses). Near 0 dB SNR, with the references in the envelope trough, the detector
catches a fifth of the auxiliary pulses and a twentieth of the main ones, and lets ~1000
noise peaks a second through: no burst passes alone, yet over a few dozen bursts the
evidence is overwhelming, because the signal guarantees a structure that noise does not
have. This module uses it, in three steps (all on the peak times only):

1. **Candidates** (a burst-code matched detector): every peak-anchored start of the
   auxiliary template with at least ``cand_hits`` (3) matched pulses, one per template span.
   Most are noise (hundreds a second); a fraction are the beacon's bursts.
2. **Grid** (:func:`acquire`): the references lie on one 135 Hz grid, ``t = a + p n``, with
   ``p`` within 5 % of 1/135 s (the rotation rate is *not* assumed to be 15 Hz). Coarse
   periods are the highest peaks of the histogram of ``(t_j - t_i) / n`` over candidate
   pairs 1..8 periods apart (a few: code-step aliases of the period vote too,
   :func:`_periods`); then all the peaks of the window are folded modulo periods within
   6e-5 of each and correlated with the auxiliary template (:func:`_fold_search`: the
   matched detector, summed over every burst of the window), and the best period and phase are
   refined by least squares on the burst times measured at the grid positions
   (:func:`refine`). It is **confirmed** only if the
   auxiliary template's pulses, summed over every grid position of the window, are each
   found significantly more often than noise would give (``min_offset_share`` of the
   template's offsets at ``hit_z`` sigma above the measured noise-peak rate) and the grid is
   not one code step off (the neighbouring alignments find fewer pulses). A beacon of the
   other mode (X vs Y) shares only 3 pulses of 12-13 with the auxiliary template and fails
   it; so does noise.
3. **Tracking and main slot** (:func:`track`): from the confirmation on, the grid is
   followed rotation by rotation (the burst times measured at the predicted positions
   refit ``a`` and ``p``; missed bursts are coasted through), every grid position gives a
   reference, and the main slot -- the one of the nine whose auxiliary-only pulses are
   missing and whose main-only pulses are there -- is declared by a likelihood-ratio test:
   per slot, the Poisson log-likelihood of "main burst here" minus "auxiliary burst here"
   (each with its own detection rate, fitted, over the noise rate); the best slot is
   declared when it leads the runner-up by ``slot_llr`` nats (odds of e^15 = 3e6 to 1
   against a wrong slot, i.e. a 40 deg multiple of bearing error) after ``min_rotations``,
   unless the test once called it auxiliary at those odds (a drifting grid can make an
   auxiliary burst look like a main one; the odds assume a grid that holds).

A confirmed grid on which no main slot is ever declared is dropped and the search starts
again after the window that confirmed it (:func:`acquire_references`).

Causality: nothing is known before the grid is confirmed and the main slot declared; the
references before that are known at the declaration (``done``), the later ones at the end
of their rotation (when the tracker has measured it).

False references: on noise alone (or the other mode) the grid is not confirmed, so no
reference and no bearing. The per-offset test needs ``min_offset_share`` (9 of 12) of the
template's offsets each ``hit_z`` (5) sigma above the Poisson noise count of the window
(at least 3 hits): for a noise count of 0.5 a window needs 5 hits at 9 offsets, probability
~3e-32 per grid hypothesis if the offsets were independent; the search tries ~4e6 (121
periods x ~3e4 phases) per window, two windows a second: < 1e-23 per minute. Checked on
noise of 1000-7200 peaks/s and on the other mode's beacon, 20-60 s (tests).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rotation import RATE_RANGE
from .scoring import REF_AUX, REF_MAIN, burst_scores
from .standard import F135, burst_offsets


@dataclass(frozen=True)
class AcquireConfig:
    tol_s: float = 1.0e-6
    cand_hits: int = 3
    hit_z: float = 5.0
    min_offset_share: float = 0.75
    min_grid_refs: int = 8
    slot_llr: float = 15.0
    min_rotations: int = 3
    window_s: float = 1.0
    #: Period hypotheses of the spacing histogram searched by the matched detector
    #: (:func:`_periods`; the highest fold score wins).
    period_hypotheses: int = 3

    def __post_init__(self):
        if isinstance(self.period_hypotheses, bool) or not isinstance(self.period_hypotheses, int) \
                or self.period_hypotheses < 1:
            raise ValueError(f"acquisition period_hypotheses must be an integer >= 1, not "
                             f"{self.period_hypotheses!r}")


@dataclass
class Acquired:
    ref_t: np.ndarray
    kinds: np.ndarray
    done: np.ndarray
    grid_s: float          # when the grid was confirmed
    main_slot_s: float     # when the main slot was declared
    period_s: float        # the grid's period at the end


def _hits(t, starts, offs, tol):
    """(len(starts), len(offs)) bool: a peak within tol of each template pulse."""
    if starts.size == 0:
        return np.zeros((0, offs.size), bool)
    x = (starts[:, None] + offs[None, :]).ravel()
    j = np.searchsorted(t, x)
    j0 = np.clip(j - 1, 0, t.size - 1)
    j1 = np.clip(j, 0, t.size - 1)
    d = np.minimum(np.abs(t[j0] - x), np.abs(t[j1] - x))
    return (d <= tol).reshape(starts.size, offs.size)


def _match_times(t, starts, offs, tol):
    """Per start: number of template pulses matched and the mean timing offset."""
    x = (starts[:, None] + offs[None, :]).ravel()
    j = np.searchsorted(t, x)
    j0 = np.clip(j - 1, 0, t.size - 1)
    j1 = np.clip(j, 0, t.size - 1)
    best = np.where(np.abs(t[j1] - x) < np.abs(t[j0] - x), j1, j0)
    d = (t[best] - x).reshape(starts.size, offs.size)
    ok = np.abs(d) <= tol
    n = ok.sum(axis=1)
    mean = np.where(n > 0, np.where(ok, d, 0).sum(axis=1) / np.maximum(n, 1), 0.0)
    return n, mean


def candidates(t, offs, cfg: AcquireConfig):
    """Peak-anchored template starts with >= cand_hits matches, best per template span."""
    if t.size == 0:
        return np.empty(0), np.empty(0, np.int64)
    starts = np.unique(np.round((t[:, None] - offs[None, :4]).ravel(), 12))
    sc = burst_scores(t, starts, offs, cfg.tol_s)
    g = np.flatnonzero(sc >= cfg.cand_hits)
    if g.size == 0:
        return np.empty(0), np.empty(0, np.int64)
    gs, gsc = starts[g], sc[g]
    cl = np.concatenate([[0], np.cumsum(np.diff(gs) > offs[-1])])
    order = np.lexsort((gs, -gsc, cl))
    first = np.ones(order.size, bool)
    first[1:] = cl[order][1:] != cl[order][:-1]
    w = order[first]
    return gs[w], gsc[w]


def _periods(c, w, p0, tol, k: int = 3):
    """Up to ``k`` period hypotheses (s), best first, from the histogram of candidate-pair
    spacings / n, n = 1..8: its highest peaks, each at least 1.25 us (five bins) from a
    better one. The candidates' starts are ambiguous by code steps (a burst caught one
    step early or late scores as well), so a pair n periods apart also votes at
    ``p + j step / n``: with few candidates such an alias can outweigh the true period
    (X, 0 dB, 60 deg, seed 124: 27 candidates in the first 0.225 s, weight 39 at +6 us
    = 12 us / 2 against 35 at the period). :func:`acquire` lets the matched detector
    (:func:`_fold_search`) choose among them."""
    hi = 8.5 * p0 * (1 + RATE_RANGE)
    est, wt = [], []
    for i in range(c.size - 1):
        j = i + 1 + np.flatnonzero(c[i + 1:np.searchsorted(c, c[i] + hi)] - c[i] > 0)
        if j.size == 0:
            continue
        d = c[j] - c[i]
        n = np.rint(d / p0)
        ok = (n >= 1) & (n <= 8)
        e = d[ok] / n[ok]
        ok2 = np.abs(e / p0 - 1) <= RATE_RANGE
        est.append(e[ok2])
        wt.append(np.minimum(w[i], w[j][ok][ok2]).astype(float))
    if not est:
        return []
    est, wt = np.concatenate(est), np.concatenate(wt)
    if est.size < 3:
        return []
    b = tol / 4
    lo = p0 * (1 - RATE_RANGE)
    kk = np.floor((est - lo) / b).astype(np.int64)
    hs = np.convolve(np.bincount(kk, weights=wt), np.ones(5), mode="same")
    out, taken = [], []
    for kb in np.argsort(-hs, kind="stable"):
        if len(out) == k or hs[kb] <= 0:
            break
        if any(abs(int(kb) - q) <= 4 for q in taken):
            continue
        taken.append(int(kb))
        near = np.abs(kk - kb) <= 2
        out.append(float(np.average(est[near], weights=wt[near])))
    return out


def confirm(t, a, p, lo, hi, offs, step, cfg: AcquireConfig, noise_rate):
    """Is the grid ``a + p n`` over ``[lo, hi)`` the beacon's (per-offset test), and at
    which code-step alignment (returns the corrected origin or None)."""
    n0 = int(np.ceil((lo - a) / p))
    n1 = int(np.floor((hi - offs[-1] - a) / p))
    if n1 - n0 + 1 < cfg.min_grid_refs:
        return None
    g = a + p * np.arange(n0, n1 + 1)
    tot = []
    for k in (-2, -1, 0, 1, 2):
        tot.append(_hits(t, g + k * step, offs, cfg.tol_s).sum())
    kb = int(np.argmax(tot)) - 2
    if kb != 0 and tot[kb + 2] <= tot[2]:
        kb = 0
    a = a + kb * step
    h = _hits(t, g + kb * step, offs, cfg.tol_s).sum(axis=0)
    lam = noise_rate * 2 * cfg.tol_s * g.size
    need = max(3.0, lam + cfg.hit_z * np.sqrt(max(lam, 0.25)))
    if np.count_nonzero(h >= need) < np.ceil(cfg.min_offset_share * offs.size):
        return None
    return a


def _fold_search(t, lo, hi, offs, p_c, tol, rel_span=6e-5, rel_step=1e-6):
    """The matched detector on the peak stream: the peaks of ``[lo, hi)`` folded modulo
    the period ``p`` and correlated with the template (pulses within ``tol`` of each
    offset), for ``p`` within ``rel_span`` of ``p_c``. Returns (origin, period, score)."""
    x = t[(t >= lo) & (t < hi)] - lo
    b = tol / 4
    w = int(round(tol / b))
    best = (-1.0, 0.0, p_c)
    for d in np.arange(-rel_span, rel_span + rel_step / 2, rel_step):
        p = p_c * (1 + d)
        nb = int(np.ceil(p / b))
        h = np.bincount(np.minimum((x % p / b).astype(np.int64), nb - 1), minlength=nb)
        hh = np.concatenate([h, h])
        cs = np.concatenate([[0], np.cumsum(np.concatenate([h[-w:], hh, h[:w]]))])
        win = cs[2 * w + 1:] - cs[:-(2 * w + 1)]          # counts within +-tol, 2*nb long
        sc = np.zeros(nb)
        for o in offs:
            k = int(round(o / b)) % nb
            sc += win[k:k + nb]
        kb = int(np.argmax(sc))
        if sc[kb] > best[0]:
            best = (float(sc[kb]), kb * b, p)
    return lo + best[1], best[2], best[0]


def acquire(t, mode: str, cfg: AcquireConfig, t_from: float | None = None, cands=None):
    """First confirmed 135 Hz grid: (a, p, t_confirmed) or None. Windows end at
    0.1, 0.15, ... s (x1.5) up to ``window_s`` after the start, then slide by half of it.
    ``cands``: :func:`candidates` of ``t`` when already computed."""
    if t.size < 10:
        return None
    aux = burst_offsets(mode, "aux")
    step = float(aux[1] - aux[0])
    c, w = candidates(t, aux, cfg) if cands is None else cands
    if c.size < cfg.min_grid_refs:
        return None
    p0 = 1.0 / F135
    t0 = float(t[0]) if t_from is None else t_from
    ends, e = [], 0.1
    while e < cfg.window_s:
        ends.append(t0 + e)
        e *= 1.5
    e = cfg.window_s
    while t0 + e < t[-1] + cfg.window_s / 2:
        ends.append(t0 + e)
        e += cfg.window_s / 2
    for end in ends:
        end = min(end, float(t[-1]))
        lo = max(t0, end - cfg.window_s)
        m = (c >= lo) & (c + aux[-1] <= end)
        if np.count_nonzero(m) < cfg.min_grid_refs:
            continue
        ps = _periods(c[m], w[m], p0, cfg.tol_s, cfg.period_hypotheses)
        if not ps:
            continue
        a, p, _ = max((_fold_search(t, lo, end, aux, q, cfg.tol_s) for q in ps),
                      key=lambda r: r[2])
        i0, i1 = np.searchsorted(t, [lo, end])
        rate = (i1 - i0) / max(end - lo, 1e-9)
        f = refine(t, a, p, lo, end, aux, cfg)
        if f is None:
            continue
        a, p = f
        a2 = confirm(t, a, p, lo, end, aux, step, cfg, rate)
        if a2 is None:
            continue
        return a2, p, end
    return None


def refine(t, a, p, lo, hi, offs, cfg: AcquireConfig):
    """Least-squares grid through the burst times measured at the grid positions."""
    n = np.arange(int(np.ceil((lo - a) / p)), int(np.floor((hi - offs[-1] - a) / p)) + 1)
    for _ in range(2):
        g = a + p * n
        nm, dm = _match_times(t, g, offs, cfg.tol_s)
        ok = nm >= cfg.cand_hits
        if np.count_nonzero(ok) < cfg.min_grid_refs:
            return None
        A = np.stack([np.ones(ok.sum()), n[ok].astype(float)], axis=1)
        (a, p), *_ = np.linalg.lstsq(A, g[ok] + dm[ok], rcond=None)
    return float(a), float(p)


def _slot_classes(mode, tol):
    main = burst_offsets(mode, "main")
    aux = burst_offsets(mode, "aux")
    near = lambda x, y: np.min(np.abs(x[:, None] - y[None, :]), axis=1) <= 2 * tol  # noqa: E731
    common = main[near(main, aux)]
    return common, main[~near(main, aux)], aux[~near(aux, main)]


def _poisson_ll(k, n, lam):
    lam = np.maximum(lam, 1e-12)
    return k * np.log(lam) - n * lam


def track(t, mode: str, a, p, t_conf, cfg: AcquireConfig):
    """Grid references over the whole record from a confirmed grid (module docstring, 3)."""
    aux = burst_offsets(mode, "aux")
    main = burst_offsets(mode, "main")
    span = max(aux[-1], main[-1])
    common, m_only, a_only = _slot_classes(mode, cfg.tol_s)
    rate = t.size / max(float(t[-1] - t[0]), 1e-9)
    nz = rate * 2 * cfg.tol_s                       # noise hits per template pulse
    n_lo = int(np.ceil((t[0] - a) / p))
    n_hi = int(np.floor((t[-1] - span - a) / p))
    if n_hi - n_lo + 1 < 9 * cfg.min_rotations:
        return None
    # Tracking, one rotation (9 positions) at a time: measure the burst times at the
    # predicted positions (aux template: it matches the main burst's common pulses too),
    # refit a, p on all measurements so far.
    meas_n, meas_t = [], []
    pos = np.empty(n_hi - n_lo + 1)
    known = np.empty(n_hi - n_lo + 1)
    n_conf = int(np.floor((t_conf - a) / p))
    # before the confirmation: the confirmed fit itself (known at the confirmation)
    k_all = np.arange(n_lo, n_hi + 1)
    early = k_all <= n_conf
    pos[early] = a + p * k_all[early]
    known[early] = t_conf
    # measurements from the data before the confirmation start the tracker
    g = a + p * k_all[early]
    nm, dm = _match_times(t, g, aux, cfg.tol_s)
    ok = nm >= cfg.cand_hits
    meas_n += list(k_all[early][ok])
    meas_t += list(g[ok] + dm[ok])
    aa, pp = a, p
    k = n_conf + 1
    while k <= n_hi:
        ks = np.arange(k, min(k + 9, n_hi + 1))
        g = aa + pp * ks
        nm, dm = _match_times(t, g, aux, cfg.tol_s)
        ok = nm >= cfg.cand_hits
        meas_n += list(ks[ok])
        meas_t += list(g[ok] + dm[ok])
        if len(meas_n) >= 3:
            mn, mt = np.asarray(meas_n, float), np.asarray(meas_t)
            keep = np.abs(mt - (aa + pp * mn)) <= cfg.tol_s
            if keep.sum() >= 3:
                A = np.stack([np.ones(keep.sum()), mn[keep]], axis=1)
                (aa, pp), *_ = np.linalg.lstsq(A, mt[keep], rcond=None)
        pos[ks - n_lo] = aa + pp * ks
        known[ks - n_lo] = pos[ks - n_lo][-1] + span
        k = ks[-1] + 1
    # Main slot: per-slot log-likelihood ratio, rotation by rotation.
    slot = k_all % 9
    hc = _hits(t, pos, common, cfg.tol_s).sum(axis=1)
    hm = _hits(t, pos, m_only, cfg.tol_s).sum(axis=1)
    ha = _hits(t, pos, a_only, cfg.tol_s).sum(axis=1)
    rot = (k_all - n_lo) // 9
    declared = None
    # A slot the test has once called auxiliary at the declaration odds is never declared
    # the main one later: near 0 dB a tracked grid that drifts by a few us makes an
    # auxiliary burst match the main-only offsets (bearing 88 deg, 0 dB, censored floor,
    # seed 3088: slot 5's ratio went from -20.7 to +15.3 over 12 rotations while the true
    # slot had no evidence either way; declared, every bearing was 160 deg off and valid).
    ever_aux = np.zeros(9, bool)
    for r in range(int(cfg.min_rotations) - 1, int(rot[-1]) + 1):
        sel = rot <= r
        if known[sel][-1] < t_conf:
            continue
        R = np.bincount(slot[sel], minlength=9).astype(float)
        C = np.bincount(slot[sel], weights=hc[sel], minlength=9)
        M = np.bincount(slot[sel], weights=hm[sel], minlength=9)
        A = np.bincount(slot[sel], weights=ha[sel], minlength=9)
        nc, nm_, na = R * common.size, R * m_only.size, R * a_only.size
        qm = np.maximum((C + M) / np.maximum(nc + nm_, 1) - nz, 0)
        qa = np.maximum((C + A) / np.maximum(nc + na, 1) - nz, 0)
        ll_main = (_poisson_ll(C, nc, qm + nz) + _poisson_ll(M, nm_, qm + nz)
                   + _poisson_ll(A, na, nz))
        ll_aux = (_poisson_ll(C, nc, qa + nz) + _poisson_ll(M, nm_, nz)
                  + _poisson_ll(A, na, qa + nz))
        llr = ll_main - ll_aux
        ever_aux |= llr <= -cfg.slot_llr
        o = np.argsort(llr)
        if (llr[o[-1]] > 0 and llr[o[-1]] - llr[o[-2]] >= cfg.slot_llr
                and not ever_aux[o[-1]]):
            declared = (int(o[-1]), float(max(known[sel][-1], t_conf)))
            break
    if declared is None:
        return None
    s_main, t_decl = declared
    kinds = np.where(slot == s_main, REF_MAIN, REF_AUX).astype(np.int8)
    done = np.maximum(known, t_decl)
    done = np.maximum(done, pos + np.where(kinds == REF_MAIN, main[-1], aux[-1]))
    return Acquired(pos, kinds, done, t_conf, t_decl, float(pp))


def acquire_references(t, mode: str, cfg: AcquireConfig | None = None):
    """Grid acquisition + tracking + main slot on a block of peak times (None: not
    confirmed)."""
    cfg = cfg or AcquireConfig()
    t = np.asarray(t, np.float64)
    t_from = None
    cands = candidates(t, burst_offsets(mode, "aux"), cfg)    # once for every search
    while True:
        got = acquire(t, mode, cfg, t_from, cands)
        if got is None:
            return None
        a, p, t_conf = got
        acq = track(t, mode, a, p, t_conf, cfg)
        if acq is not None:
            return acq
        # No main slot on that grid: a code-step alias of the period (the auxiliary code is
        # periodic, so a grid sliding by one step per period still finds its pulses for a
        # dozen positions -- X, 0 dB, 60 deg, seed 125: 0.16 % = 12 us per period,
        # confirmed in the first 0.15 s). The search starts again after its window.
        t_from = t_conf
