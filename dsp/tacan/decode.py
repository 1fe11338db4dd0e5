"""Reference-burst decoding and pulse-pair validation on the list of pulse peaks.

Done on the DSP side (not in the FPGA) on purpose: a decoder that is robust to missing and
extra pulses needs to look back over a whole burst (up to 342 us) and vote over alignments;
at 7200 peaks/s that is a few microseconds of DSP time per peak, whereas in the FPGA it
would need a peak history buffer and a voting network for each code. The FPGA ships every
peak with its timestamp; nothing is lost by deciding here.

Algorithm: every peak ``t_i`` and each of the first ``align`` template pulses ``j`` give a
hypothesis "the burst started at ``t_i - off_j``"; its score is how many template pulses
find a peak within ``tol_s``. Hypotheses scoring at least ``min_fraction`` of the template
are clustered (one burst per ``span``), the best of each cluster wins, and the burst time is
refined as the mean of ``t_match - off`` over the matched pulses.

Codes are periodic, so a burst whose first or last pulse is lost matches equally well one
code step early or late. Every reference lies on the 135 Hz grid (main ones too), so each
burst time is compared with the grid phase of its neighbours (median over +-8 bursts);
an offset that is a whole number of code steps (within ``tol_s``) is corrected, and a burst
off the grid by anything else is a false decode and is dropped (counted).

``min_fraction`` = 0.5 lets the main burst be found when the references sit in the envelope
trough at low SNR (bearing 90 deg: half the trough pulses fall under the detection
threshold at 6 dB). It cannot create main bursts from random pairs: those are at least
``min_pair_gap_s`` (50 us) apart, so at most a few template pairs (30 us apart) can match.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dsp.jit import njit_cached
from .standard import burst_offsets, pair_spacing_s

REF_MAIN, REF_AUX = 1, 2


@dataclass(frozen=True)
class DecoderConfig:
    mode: str = "X"
    tol_s: float = 1.0e-6
    min_fraction: float = 0.5
    align: int = 4

    def __post_init__(self):
        if self.mode not in ("X", "Y"):
            raise ValueError(f"mode must be 'X' or 'Y', not {self.mode!r}")
        if not self.tol_s > 0:
            raise ValueError(f"decoder tol_s must be > 0, not {self.tol_s}")
        if not 0 < self.min_fraction <= 1:
            raise ValueError(f"decoder min_fraction must be in (0, 1], not {self.min_fraction}")
        if int(self.align) < 1:
            raise ValueError(f"decoder align must be >= 1, not {self.align}")


@dataclass
class Decoded:
    """Decoded references and the pulses fit to be amplitude measurements."""

    ref_times_s: np.ndarray    # refined burst times (first-pulse time), sorted
    ref_kinds: np.ndarray      # REF_MAIN / REF_AUX
    ref_scores: np.ndarray     # matched pulses
    ref_done_s: np.ndarray     # time the burst's last pulse arrived (when a DSP knows it)
    measurement_mask: np.ndarray  # per input peak: belongs to a burst or a valid pair
    n_off_grid: int = 0        # decoded bursts dropped for being off the 135 Hz grid


def _match(t: np.ndarray, targets: np.ndarray, tol: float):
    """Index of the nearest peak to each target, and whether it is within tol."""
    j = np.searchsorted(t, targets)
    j0 = np.clip(j - 1, 0, len(t) - 1)
    j1 = np.clip(j, 0, len(t) - 1)
    d0 = np.abs(t[j0] - targets)
    d1 = np.abs(t[j1] - targets)
    best = np.where(d1 < d0, j1, j0)
    return best, np.minimum(d0, d1) <= tol


@njit_cached(nogil=True)
def _score_kernel(t, starts, offs, tol, score):
    """``score[i]`` = how many ``starts[i] + offs[c]`` have a peak within ``tol``: for each
    template pulse, :func:`_match` (nearest of the two neighbours found by a left
    ``searchsorted``) with one pointer walking ``t`` -- ``starts`` ascending makes the
    targets ascending -- so no ``peaks x align x template`` temporaries (~330 MB each for a
    minute of pulses) and no log factor. Same arithmetic as :func:`_scores_numpy`."""
    n = t.size
    for i in range(starts.size):
        score[i] = 0
    for c in range(offs.size):
        o = offs[c]
        j = 0
        for i in range(starts.size):
            x = starts[i] + o
            while j < n and t[j] < x:
                j += 1
            j0 = j - 1 if j > 0 else 0
            j1 = j if j < n else n - 1
            if min(abs(t[j0] - x), abs(t[j1] - x)) <= tol:
                score[i] += 1


def _scores(t: np.ndarray, starts: np.ndarray, offs: np.ndarray, tol: float) -> np.ndarray:
    """Matched template pulses of each start hypothesis (``starts`` ascending)."""
    score = np.empty(starts.size, np.int64)
    _score_kernel(np.ascontiguousarray(t, np.float64), np.ascontiguousarray(starts, np.float64),
                  np.ascontiguousarray(offs, np.float64), float(tol), score)
    return score


def _scores_numpy(t, starts, offs, tol):
    """:func:`_scores` with numpy (the reference the tests hold the kernel to)."""
    _, ok = _match(t, (starts[:, None] + offs[None, :]).ravel(), tol)
    return ok.reshape(starts.size, offs.size).sum(axis=1)


def _bursts(t: np.ndarray, offs: np.ndarray, cfg: DecoderConfig):
    n_al = min(int(cfg.align), len(offs))
    starts = (t[:, None] - offs[None, :n_al]).ravel()
    starts = np.unique(np.round(starts, 12))
    score = _scores(t, starts, offs, cfg.tol_s)
    need = int(np.ceil(cfg.min_fraction * len(offs)))
    good = np.flatnonzero(score >= need)
    if good.size == 0:
        return np.empty(0), np.empty(0, int), np.empty(0, int), np.zeros(len(t), bool)
    span = offs[-1]
    # Cluster hypotheses closer than the burst length; keep the best-scoring (earliest on ties).
    gs = starts[good]
    cluster = np.concatenate([[0], np.cumsum(np.diff(gs) > span)])
    order = np.lexsort((gs, -score[good], cluster))
    first = np.ones(order.size, bool)
    first[1:] = cluster[order][1:] != cluster[order][:-1]
    win = good[order[first]]
    targets = starts[win][:, None] + offs[None, :]
    idx, ok = _match(t, targets.ravel(), cfg.tol_s)
    idx, ok = idx.reshape(targets.shape), ok.reshape(targets.shape)
    times = np.empty(win.size)
    used = np.zeros(len(t), bool)
    for k in range(win.size):
        m = ok[k]
        times[k] = np.mean(t[idx[k][m]] - offs[m])
        used[idx[k][m]] = True
    return times, score[win], np.full(win.size, 0), used


def decode(times_s, mode: str = "X", cfg: DecoderConfig | None = None) -> Decoded:
    """Decode main/auxiliary references and mark the peaks usable as measurements.

    Parameters
    ----------
    times_s : array of float
        Peak times (s), sorted ascending.
    """
    cfg = cfg or DecoderConfig(mode=mode)
    t = np.asarray(times_s, dtype=np.float64)
    if not np.all(np.isfinite(t)):
        raise ValueError("peak times must be finite (NaN/inf from the front end)")
    if t.size and np.any(np.diff(t) < 0):
        raise ValueError("peak times must be sorted ascending")
    if t.size == 0:
        z = np.empty(0)
        return Decoded(z, np.empty(0, np.int8), np.empty(0, int), z, np.zeros(0, bool))
    main_off = burst_offsets(cfg.mode, "main")
    aux_off = burst_offsets(cfg.mode, "aux")
    tm, sm, _, um = _bursts(t, main_off, cfg)
    ta, sa, _, ua = _bursts(t, aux_off, cfg)
    # A burst found by both templates (overlapping spans) keeps the better fractional score.
    if tm.size and ta.size:
        span = max(main_off[-1], aux_off[-1])
        j, close = _match(tm, ta, span)
        a_worse = close & (sa / len(aux_off) <= sm[j] / len(main_off))
        i, close_m = _match(ta, tm, span)
        m_worse = close_m & (sm / len(main_off) < sa[i] / len(aux_off))
        ta, sa = ta[~a_worse], sa[~a_worse]
        tm, sm = tm[~m_worse], sm[~m_worse]
    ref_t = np.concatenate([tm, ta])
    kinds = np.concatenate([np.full(tm.size, REF_MAIN, np.int8), np.full(ta.size, REF_AUX, np.int8)])
    scores = np.concatenate([sm, sa])
    done = np.concatenate([tm + main_off[-1], ta + aux_off[-1]])
    o = np.argsort(ref_t, kind="stable")
    ref_t, kinds, scores, done = ref_t[o], kinds[o], scores[o], done[o]
    ref_t, on_grid = _snap_to_grid(ref_t, kinds, cfg)
    n_off = int(np.count_nonzero(~on_grid))
    ref_t, kinds, scores, done = ref_t[on_grid], kinds[on_grid], scores[on_grid], done[on_grid]

    pair = pair_spacing_s(cfg.mode)
    _, fwd = _match(t, t + pair, cfg.tol_s)
    _, back = _match(t, t - pair, cfg.tol_s)
    mask = um | ua | fwd | back
    return Decoded(ref_t, kinds, scores, done, mask, n_off)


#: Code steps (s) by which a burst with a lost end pulse can be mis-aligned.
_CODE_STEPS = {("X", REF_MAIN): 30e-6, ("X", REF_AUX): 12e-6,
               ("Y", REF_MAIN): 30e-6, ("Y", REF_AUX): 15e-6}


def _snap_to_grid(ref_t: np.ndarray, kinds: np.ndarray, cfg: DecoderConfig, half: int = 8):
    ok = np.ones(ref_t.size, bool)
    if ref_t.size < 3:
        return ref_t, ok
    period = 1.0 / 135.0
    dev = (ref_t - ref_t[0] + period / 2) % period - period / 2
    out = ref_t.copy()
    for i in range(ref_t.size):
        lo, hi = max(0, i - half), min(ref_t.size, i + half + 1)
        nb = np.delete(dev[lo:hi], i - lo)
        ref = np.median(nb)
        off = dev[i] - ref
        step = _CODE_STEPS[(cfg.mode, int(kinds[i]))]
        k = np.rint(off / step)
        if k != 0 and abs(off - k * step) <= cfg.tol_s and abs(k) <= 3:
            out[i] = ref_t[i] - k * step
        elif abs(off) > cfg.tol_s:
            ok[i] = False
    return out, ok
