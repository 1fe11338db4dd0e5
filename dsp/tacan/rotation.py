"""The beacon's rotation rate from the reference-burst times: the 135 Hz grid the
references lie on (period ``1 / (9 f)``), estimated robustly per block
(:func:`estimate_rotation`) and tracked causally (:func:`rotation_track`), rounded to
:data:`RATE_QUANTUM`."""
from __future__ import annotations

import numpy as np

from .standard import F15, F135


#: Resolution of the rotation-rate estimate, relative to 15 Hz (0.15 mHz). The estimate is
#: rounded to it, so a nominal beacon -- whose estimate is within ~1e-6 of 15 Hz after a
#: fifth of a second of references -- gives exactly 15 Hz (the DSP's words and bits are
#: then those of the nominal rate), and the rounding leaves at most 5e-6 of rate error:
#: a filter lag of ~0.007 deg (the lag is ~2 pi df memory_s in the 135 Hz phase, / 9).
RATE_QUANTUM = 1e-5
#: Rotation rates the estimator accepts (relative deviation from 15 Hz); the generator's range.
RATE_RANGE = 0.05


def quantize_rotation(f_hz: float) -> float:
    """A rotation-rate estimate rounded to :data:`RATE_QUANTUM` steps of 15 Hz (exactly
    ``F15`` on the nominal step) and clipped to ``F15 (1 +- RATE_RANGE)``."""
    k = round((float(f_hz) / F15 - 1.0) / RATE_QUANTUM)
    kmax = round(RATE_RANGE / RATE_QUANTUM)
    k = max(-kmax, min(kmax, k))
    return F15 * (1.0 + k * RATE_QUANTUM) if k else F15


def grid_index(ref_t: np.ndarray, period: float) -> np.ndarray:
    """Grid index of each (time-sorted) reference, counted gap by gap from the first: a
    gap of ``k`` periods is read right while ``k`` times the period's error stays below half
    a period (a beacon 5 % off 15 Hz: gaps up to 9 periods), where indices from one origin
    (``(t - t0) / p``) slip after ``1 / (2 x error)`` periods."""
    if ref_t.size == 0:
        return np.empty(0, np.int64)
    return np.concatenate([[0], np.cumsum(np.rint(np.diff(ref_t) / period))]).astype(np.int64)


def period_median(ref_t: np.ndarray) -> float | None:
    """Robust 135 Hz period from the gaps between consecutive references: the median of
    ``gap / k`` over gaps of ``k`` = 1..8 nominal periods (None: fewer than 3 such gaps)."""
    p0 = 1.0 / F135
    d = np.diff(ref_t)
    k = np.rint(d / p0)
    ok = (k >= 1) & (k <= 8)
    if np.count_nonzero(ok) < 3:
        return None
    p = float(np.median(d[ok] / k[ok]))
    return p if abs(p / p0 - 1.0) <= RATE_RANGE else None


def estimate_rotation(ref_t: np.ndarray, tol: float, min_refs: int,
                      min_span_s: float = 0.0) -> float | None:
    """Rotation rate (Hz, :func:`quantize_rotation`) from reference times: a robust median
    period, then the least-squares grid (:func:`fit_grid`) through them. None when there
    are fewer than ``min_refs`` references, they span less than ``min_span_s``, or no
    grid holds 80 % of them."""
    t = np.sort(np.asarray(ref_t, dtype=np.float64))
    if t.size < max(int(min_refs), 3) or t[-1] - t[0] < min_span_s:
        return None
    p = period_median(t)
    if p is None:
        return None
    fit = fit_grid(t, p, tol, int(min_refs))
    if fit is None:
        return None
    return quantize_rotation(1.0 / (9.0 * fit[1]))


#: The last few :func:`rotation_track` results by their exact inputs (one record's
#: references, decoded once, are tracked again by each detector variant measured on them).
_TRACKS: dict = {}
_TRACKS_KEPT = 4


def rotation_track(ref_t, tol: float, min_refs: int, min_span_s: float,
                   window_s: float = 2.0, prior_rate: float | None = None):
    """:func:`compute_rotation_track`, its result kept for the same inputs (the same reference
    times bit for bit and the same parameters; the last :data:`_TRACKS_KEPT`) and given
    again as copies: the same arrays as computing it again."""
    ref_t = np.asarray(ref_t, dtype=np.float64)
    key = (ref_t.tobytes(), float(tol), int(min_refs), float(min_span_s), float(window_s),
           None if prior_rate is None else float(prior_rate))
    got = _TRACKS.get(key)
    if got is None:
        got = compute_rotation_track(ref_t, tol, min_refs, min_span_s, window_s, prior_rate)
        while len(_TRACKS) >= _TRACKS_KEPT:
            _TRACKS.pop(next(iter(_TRACKS)))
        _TRACKS[key] = got
    return got[0].copy(), got[1].copy()


def compute_rotation_track(ref_t, tol: float, min_refs: int, min_span_s: float,
                           window_s: float = 2.0, prior_rate: float | None = None):
    """Causal rotation-rate estimate after each reference of ``ref_t`` (given in the order
    the references become known): :func:`estimate_rotation` of the references known so
    far that lie within ``window_s`` of the newest (a tracker: it follows a slowly changing
    rate, and the cost per reference stays bounded), holding the latest estimate (``F15``
    before the first) when they do not suffice. ``prior_rate`` (an earlier block's
    estimate, None: none yet) is held until the first estimate.

    Returns
    -------
    (rates, confirmed) : float array, bool array
        The rate after each reference and whether an estimate exists by then (the
        reference timing is *confirmed*: a 135 Hz grid through ``min_refs`` references
        spanning ``min_span_s``; the receiver flags its bearings until then).
    """
    ref_t = np.asarray(ref_t, dtype=np.float64)
    out = np.empty(ref_t.size)
    conf = np.zeros(ref_t.size, bool)
    f = F15 if prior_rate is None else float(prior_rate)
    have = prior_rate is not None
    known = []
    for i in range(ref_t.size):
        known.append(ref_t[i])
        if len(known) > 4 * int(window_s * F135):
            known = known[-int(window_s * F135) * 2:]
        w = np.asarray(known)
        w = w[w >= w.max() - window_s]
        e = estimate_rotation(w, tol, min_refs, min_span_s)
        if e is not None:
            f, have = e, True
        out[i], conf[i] = f, have
    return out, conf


def fit_grid(ref_t: np.ndarray, period: float, tol: float, min_refs: int):
    """Least-squares 135 Hz grid ``t = a + p n`` through the (time-sorted) references:
    indices counted gap by gap with ``period`` (:func:`grid_index`), then refitted twice on
    the references within ``tol`` of the grid (a burst mis-aligned by a code step does not
    pull it). None when fewer than ``min_refs`` references, or fewer than 80 % of them,
    lie on one grid."""
    a, p = float(ref_t[0]), period
    inl = np.ones(ref_t.size, bool)
    n = grid_index(ref_t, p)
    for it in range(3):
        if it:
            n = np.rint((ref_t - a) / p)
        A = np.stack([np.ones(np.count_nonzero(inl)), n[inl]], axis=1)
        (a, p), *_ = np.linalg.lstsq(A, ref_t[inl], rcond=None)
        n = np.rint((ref_t - a) / p)
        inl = np.abs(ref_t - (a + p * n)) <= tol
        if np.count_nonzero(inl) < max(min_refs, 2):
            return None
    if np.count_nonzero(inl) < 0.8 * ref_t.size:
        return None
    return float(a), float(p), np.rint((ref_t - a) / p).astype(np.int64)
