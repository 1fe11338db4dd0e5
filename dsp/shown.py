"""The figures of what a user sees of a receiver's estimates, computed in one place:
:func:`shown_figures` (accuracy, availability and integrity of one record; the studies'
definitions are in :mod:`cosim.studies.shown`, which pools and pairs them) and
:func:`valid_figures` (the accuracy and integrity part, which the receivers' own
statistics use: :func:`dsp.tacan.receiver.bearing_stats`).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["shown_figures", "valid_figures", "FIGURE_KEYS"]

#: The keys of :func:`shown_figures`.
FIGURE_KEYS = ("n_estimates", "n_valid", "rmse", "mean_error", "max_abs_error", "n_epochs",
               "available_epochs", "availability", "first_valid_s", "misleading",
               "misleading_rate", "bound", "epoch_s")


def _f(v):
    v = float(v)
    return v if math.isfinite(v) else None


def _per(m, n: int) -> np.ndarray:
    m = np.asarray(m, dtype=bool).ravel()
    if m.size != n:
        raise ValueError(f"misleading must have one value per estimate ({n}), not {m.size}")
    return m


def valid_figures(err, valid, *, bound: float | None = None, misleading=None) -> dict:
    """Accuracy and integrity of the scored estimates (the caller's window): ``n_valid``
    (shown valid, error finite), their ``rmse``, ``mean_error``, ``max_abs_error`` (None
    without any), ``misleading`` (shown valid and ``|err| > bound``, or the receiver's
    own ``misleading`` flag) and ``misleading_rate`` (per valid estimate; None without
    any). The one computation of these figures: :func:`shown_figures` and the receivers'
    per-trial statistics (e.g. :func:`dsp.tacan.receiver.bearing_stats`) call it."""
    e = np.asarray(err, dtype=np.float64).ravel()
    v = np.asarray(valid, dtype=bool).ravel()
    if v.size != e.size:
        raise ValueError(f"err and valid must have one value per estimate, not {e.size}, "
                         f"{v.size}")
    v = v & np.isfinite(e)
    ev = e[v]
    bad = np.zeros(e.size, bool)
    if bound is not None:
        bad |= np.abs(np.where(np.isfinite(e), e, 0.0)) > bound
    if misleading is not None:
        bad |= _per(misleading, e.size)
    n_mis = int(np.count_nonzero(v & bad))
    return {"n_valid": int(ev.size),
            "rmse": _f(np.sqrt(np.mean(ev ** 2))) if ev.size else None,
            "mean_error": _f(np.mean(ev)) if ev.size else None,
            "max_abs_error": _f(np.max(np.abs(ev))) if ev.size else None,
            "misleading": n_mis, "misleading_rate": n_mis / ev.size if ev.size else None}


def shown_figures(t_s, err, valid, *, settle_s: float, end_s: float, epoch_s: float,
                  bound: float | None = None, misleading=None) -> dict:
    """The three figures of one record.

    Parameters
    ----------
    t_s : array (M,)
        When each estimate became available to the user (s from the record's start),
        non-decreasing.
    err : array (M,)
        Each estimate's error against the truth (NaN: no estimate, counted as not valid).
    valid : array of bool (M,)
        The receiver shows the estimate as valid (not flagged).
    settle_s, end_s : float
        The scored window: estimates from ``settle_s`` (the filter's settling) to ``end_s``
        (the record's end); none after settling: no epoch, availability None.
    epoch_s : float
        The display epoch: the window is cut into ``floor((end_s - settle_s) / epoch_s)``
        epochs; an epoch is *available* when the latest estimate produced within it is
        valid (no estimate in it: not available).
    bound : float, optional
        An estimate shown valid with ``|err| > bound`` is misleading.
    misleading : array of bool (M,), optional
        The receiver's own misleading test per estimate (e.g. a cycle slip); OR-ed with
        the bound's. Only estimates shown valid after settling count.

    Returns a dict (:data:`FIGURE_KEYS`): ``rmse``, ``mean_error``, ``max_abs_error`` over
    the valid estimates after settling (None without any), ``availability`` =
    ``available_epochs / n_epochs``, ``first_valid_s`` (None: never valid), ``misleading``
    (count) and ``misleading_rate`` (per valid estimate; None without any)."""
    t = np.asarray(t_s, dtype=np.float64).ravel()
    e = np.asarray(err, dtype=np.float64).ravel()
    v = np.asarray(valid, dtype=bool).ravel()
    if not (t.size == e.size == v.size):
        raise ValueError(f"t_s, err and valid must have one value per estimate, not "
                         f"{t.size}, {e.size}, {v.size}")
    if not (epoch_s > 0 and math.isfinite(epoch_s)):
        raise ValueError(f"epoch_s must be > 0, not {epoch_s}")
    if t.size > 1 and np.any(np.diff(t) < 0):
        raise ValueError("t_s must be non-decreasing (the order the estimates were shown)")
    v = v & np.isfinite(e)
    scored = (t >= settle_s) & (t <= end_s)
    acc = valid_figures(e[scored], v[scored], bound=bound,
                        misleading=None if misleading is None else _per(misleading, e.size)[scored])
    # availability: the latest estimate of each display epoch
    n_ep = max(0, int(math.floor((end_s - settle_s) / epoch_s + 1e-9)))
    avail = 0
    if n_ep > 0 and scored.any():
        idx = np.flatnonzero(scored)
        k = np.floor((t[idx] - settle_s) / epoch_s + 1e-12).astype(np.int64)
        inside = k < n_ep
        idx, k = idx[inside], k[inside]
        if idx.size:
            last = np.r_[k[1:] != k[:-1], True]        # the last estimate of its epoch
            avail = int(np.count_nonzero(v[idx[last]]))
    first = np.flatnonzero(v)
    return {"n_estimates": int(np.count_nonzero(scored)), "n_valid": acc["n_valid"],
            "rmse": acc["rmse"], "mean_error": acc["mean_error"],
            "max_abs_error": acc["max_abs_error"],
            "n_epochs": n_ep, "available_epochs": avail,
            "availability": avail / n_ep if n_ep else None,
            "first_valid_s": _f(t[first[0]]) if first.size else None,
            "misleading": acc["misleading"], "misleading_rate": acc["misleading_rate"],
            "bound": bound, "epoch_s": float(epoch_s)}
