"""Burst-template scoring on a list of pulse-peak times, shared by the burst decoder
(:mod:`dsp.tacan.decode`) and the acquisition across bursts (:mod:`dsp.tacan.acquire`):
the nearest peak to each target time, and how many pulses of a burst template a start
hypothesis matches."""
from __future__ import annotations

import numpy as np

from dsp.jit import njit_cached

#: Reference-burst kinds: the main (north) burst and the auxiliary (40 deg) bursts.
REF_MAIN, REF_AUX = 1, 2


def match_nearest(t: np.ndarray, targets: np.ndarray, tol: float):
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
    template pulse, :func:`match_nearest` (nearest of the two neighbours found by a left
    ``searchsorted``) with one pointer walking ``t`` -- ``starts`` ascending makes the
    targets ascending -- so no ``peaks x align x template`` temporaries (~330 MB each for a
    minute of pulses) and no log factor. Same arithmetic as :func:`burst_scores_numpy`."""
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


def burst_scores(t: np.ndarray, starts: np.ndarray, offs: np.ndarray, tol: float) -> np.ndarray:
    """Matched template pulses of each start hypothesis (``starts`` ascending)."""
    score = np.empty(starts.size, np.int64)
    _score_kernel(np.ascontiguousarray(t, np.float64), np.ascontiguousarray(starts, np.float64),
                  np.ascontiguousarray(offs, np.float64), float(tol), score)
    return score


def burst_scores_numpy(t, starts, offs, tol):
    """:func:`burst_scores` with numpy (the reference the tests hold the kernel to)."""
    _, ok = match_nearest(t, (starts[:, None] + offs[None, :]).ravel(), tol)
    return ok.reshape(starts.size, offs.size).sum(axis=1)
