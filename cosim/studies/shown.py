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

:func:`dsp.shown.shown_figures` (with :func:`dsp.shown.valid_figures`, the
accuracy and integrity part that the receivers' own statistics use) computes them for one
record from the receiver's estimates (when each became available, its error against the
truth, its valid flag); :func:`pool` sums them
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

__all__ = ["pool", "paired", "wilson_ci"]


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
    """The figures of a study point over its trials (one :func:`dsp.shown.shown_figures`
    dict each): accuracy over the trials that showed a valid estimate (RMSE: the root of the mean of
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
