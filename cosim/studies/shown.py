"""What a user sees of a receiver's estimates, the three figures every study judges by:

* **accuracy** -- RMSE, mean and worst error of the estimates the receiver shows as valid,
  after settling (a flagged estimate is not shown: it counts against availability, never
  for accuracy);
* **availability** -- the fraction of display epochs after settling whose latest estimate
  is shown valid, and the time to the first valid estimate;
* **integrity** -- the count and rate of *misleading* estimates: shown valid, after
  settling, and beyond the receiver's stated error bound (TACAN: a 20 deg sector error;
  GNSS: a cycle slip or a Doppler error over its bound; monopulse: a pointing error beyond
  the unambiguous half-width).

:func:`shown_figures` computes them for one record from the receiver's estimates (when each
became available, its error against the truth, its valid flag); :func:`pool` sums them
over the trials of a study point; :func:`paired` sets a point beside the float golden chain
on the same records (the accuracy ratio, the availability difference, the misleading
estimates the golden chain does not also make, with their intervals). The sweep
(:mod:`cosim.studies.proposal`) and the fault studies (:mod:`cosim.studies.faults`) judge
and report through these; each receiver's study model only says what its estimates, flags
and bound are.
"""
from __future__ import annotations

import hashlib
import math

import numpy as np

__all__ = ["shown_figures", "pool", "paired", "wilson_ci", "FIGURE_KEYS"]

#: The keys of :func:`shown_figures`.
FIGURE_KEYS = ("n_estimates", "n_valid", "rmse", "mean_error", "max_abs_error", "n_epochs",
               "available_epochs", "availability", "first_valid_s", "misleading",
               "misleading_rate", "bound", "epoch_s")


def _f(v):
    v = float(v)
    return v if math.isfinite(v) else None


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
    sv = scored & v
    ev = e[sv]
    bad = np.zeros(e.size, bool)
    if bound is not None:
        bad |= np.abs(np.where(np.isfinite(e), e, 0.0)) > bound
    if misleading is not None:
        m = np.asarray(misleading, dtype=bool).ravel()
        if m.size != e.size:
            raise ValueError(f"misleading must have one value per estimate ({e.size}), "
                             f"not {m.size}")
        bad |= m
    n_mis = int(np.count_nonzero(sv & bad))
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
    return {"n_estimates": int(np.count_nonzero(scored)), "n_valid": int(ev.size),
            "rmse": _f(np.sqrt(np.mean(ev ** 2))) if ev.size else None,
            "mean_error": _f(np.mean(ev)) if ev.size else None,
            "max_abs_error": _f(np.max(np.abs(ev))) if ev.size else None,
            "n_epochs": n_ep, "available_epochs": avail,
            "availability": avail / n_ep if n_ep else None,
            "first_valid_s": _f(t[first[0]]) if first.size else None,
            "misleading": n_mis, "misleading_rate": n_mis / ev.size if ev.size else None,
            "bound": bound, "epoch_s": float(epoch_s)}


def wilson_ci(k: int, n: int, z: float = 1.96) -> list[float] | None:
    """95 % Wilson score interval of a rate ``k / n`` (None for ``n = 0``): for zero
    misleading estimates in ``n`` it is ``[0, ~3.8 / n]``, what the study can vouch for."""
    if n <= 0:
        return None
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return [0.0 if k == 0 else max(0.0, c - h), 1.0 if k == n else min(1.0, c + h)]


def pool(figs: list[dict]) -> dict:
    """The figures of a study point over its trials (one :func:`shown_figures` dict each):
    accuracy over the trials that showed a valid estimate (RMSE: the root of the mean of
    the trials' mean squares, each trial one sample; mean error: the mean of theirs),
    availability the mean over every trial (a trial without a valid estimate counts 0),
    the time to the first valid estimate (median and worst over the trials that had one,
    and how many never had), the misleading estimates summed and their rate per valid
    estimate with its Wilson interval."""
    if not figs:
        raise ValueError("pool needs at least one record's figures")
    acc = [f for f in figs if f["n_valid"] and f["rmse"] is not None]
    av = [f["availability"] for f in figs if f["availability"] is not None]
    ttf = [f["first_valid_s"] for f in figs if f["first_valid_s"] is not None]
    nv = sum(int(f["n_valid"]) for f in figs)
    mis = sum(int(f["misleading"]) for f in figs)
    return {"trials": len(figs), "trials_valid": len(acc),
            "rmse": float(np.sqrt(np.mean([f["rmse"] ** 2 for f in acc]))) if acc else None,
            "mean_error": float(np.mean([f["mean_error"] for f in acc])) if acc else None,
            "max_abs_error": max((f["max_abs_error"] for f in acc), default=None),
            "availability": float(np.mean(av)) if av else None,
            "first_valid_s_median": float(np.median(ttf)) if ttf else None,
            "first_valid_s_max": max(ttf) if ttf else None,
            "never_valid": len(figs) - len(ttf),
            "n_valid": nv, "misleading": mis,
            "misleading_rate": mis / nv if nv else None,
            "misleading_rate_ci95": wilson_ci(mis, nv)}


def _seed(key: str) -> int:
    return int.from_bytes(hashlib.sha256(key.encode()).digest()[:8], "little")


def paired(point: list[dict], golden: list[dict], key: str, n_boot: int = 2000) -> dict:
    """A point beside the golden chain on the same records (``point[i]`` and ``golden[i]``
    the figures of record ``i``): the accuracy ratio (over the records where both show a
    valid estimate) and its 95 % paired bootstrap interval over the records, the
    availability difference (point - golden) and its interval, and the misleading
    estimates the golden chain does not also make (per record, the point's count beyond
    the golden one's). Intervals need >= 3 records (else None); seeded from ``key``."""
    if len(point) != len(golden):
        raise ValueError(f"{len(point)} point records against {len(golden)} golden ones")
    both = [(p, g) for p, g in zip(point, golden) if p["rmse"] is not None
            and g["rmse"] is not None]
    out = {"ratio": None, "ratio_ci95": None, "availability_diff": None,
           "availability_diff_ci95": None,
           "excess_misleading": int(sum(max(0, int(p["misleading"]) - int(g["misleading"]))
                                        for p, g in zip(point, golden)))}
    rng = np.random.default_rng(_seed(key))
    if both:
        a = np.array([p["rmse"] ** 2 for p, _ in both])
        b = np.array([g["rmse"] ** 2 for _, g in both])
        if b.mean() > 0:
            out["ratio"] = float(np.sqrt(a.mean() / b.mean()))
        if len(both) >= 3:
            idx = rng.integers(0, len(both), (n_boot, len(both)))
            r = np.sqrt(a[idx].mean(axis=1) / np.maximum(b[idx].mean(axis=1), 1e-300))
            out["ratio_ci95"] = [float(x) for x in np.quantile(r, [0.025, 0.975])]
    av = [(p["availability"], g["availability"]) for p, g in zip(point, golden)
          if p["availability"] is not None and g["availability"] is not None]
    if av:
        d = np.array([p - g for p, g in av])
        out["availability_diff"] = float(d.mean())
        if len(d) >= 3:
            idx = rng.integers(0, len(d), (n_boot, len(d)))
            out["availability_diff_ci95"] = [float(x) for x in
                                             np.quantile(d[idx].mean(axis=1), [0.025, 0.975])]
    return out
