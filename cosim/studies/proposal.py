"""What a sweep's points say about word lengths: the rows per (combination, SNR), the
proposal and the tests of its confirmation (:mod:`cosim.studies.sweep` runs the points,
writes the report and runs the confirmation, :func:`cosim.studies.sweep.confirm`).

* :func:`aggregate` pools a combination's trials at one SNR and pairs them with the golden
  chain on the same records (:func:`ratio_ci`: the paired ratio's bootstrap interval).
* :func:`propose` takes each parameter alone to its smallest value that locks,
  re-initialises and scores like the golden chain (:func:`passes`).
* :func:`confirms` is the stricter test a confirmation run (the proposal re-run on fresh
  seeds, all values together) must pass; :func:`shortfall` ranks the runs that fail and
  :func:`widen_one` gives the candidates of the next round.
"""
from __future__ import annotations

import hashlib
import json
import math
import numpy as np

from .spec import SweepConfig, primary_key

__all__ = ["aggregate", "propose", "ratio_ci", "passes", "confirms", "shortfall", "widen_one"]


def ratio_ci(pairs, key: str, n_boot: int = 2000, fig: str = "rmse_deg") -> list[float] | None:
    """95 % bootstrap interval (over trials, paired) of the RMSE ratio point / golden.

    Within one trial the bearings are strongly correlated (the filter's memory spans a good
    part of the scored time), so the trials are the independent samples; resampling them
    in pairs keeps the cancellation of the common noise. Seeded from ``key``: the same
    results give the same interval."""
    if len(pairs) < 3:
        return None
    a = np.array([r[fig] ** 2 for r, _ in pairs])
    b = np.array([g[fig] ** 2 for _, g in pairs])
    seed = int.from_bytes(hashlib.sha256(key.encode()).digest()[:8], "little")
    idx = np.random.default_rng(seed).integers(0, len(pairs), (n_boot, len(pairs)))
    ratio = np.sqrt(a[idx].mean(axis=1) / np.maximum(b[idx].mean(axis=1), 1e-300))
    lo, hi = np.quantile(ratio, [0.025, 0.975])
    return [float(lo), float(hi)]


def aggregate(cfg: SweepConfig, results: list[dict]) -> list[dict]:
    """Per (combo, SNR): RMSE over the trials (locked ones), lock rate, the paired golden
    RMSE on the same records, CRB, events, drops."""
    P = primary_key(cfg.receiver)
    gold = {(r["snr_db"], r["trial"]): r for r in results if r.get("kind") == "golden"}
    pts = [r for r in results if r.get("kind") == "point"]
    rows = []
    for combo in cfg.combos:
        cl = [list(c) for c in combo]
        for snr in cfg.snr_db:
            rs = [r for r in pts if r["combo"] == cl and r["snr_db"] == float(snr)]
            if not rs:
                continue
            err = [r.get("error") for r in rs if r.get("error")]
            ok = [r for r in rs if r["locked"] and r.get(P) is not None]
            gok = [gold.get((r["snr_db"], r["trial"])) for r in ok]
            paired = [(r, g) for r, g in zip(ok, gok) if g and g.get("locked")]
            ev: dict = {}
            for r in rs:
                for k, v in (r.get("dsp_events") or {}).items():
                    ev[k] = ev.get(k, 0) + int(v)
            rmse = float(np.sqrt(np.mean([r[P] ** 2 for r in ok]))) if ok else None
            g_rmse = float(np.sqrt(np.mean([g[P] ** 2 for _, g in paired]))) if paired else None
            p_rmse = float(np.sqrt(np.mean([r[P] ** 2 for r, _ in paired]))) if paired else None
            ng = sum(1 for r in rs if (gold.get((r["snr_db"], r["trial"])) or {}).get("locked"))
            g_reinit = sum(int(((gold.get((r["snr_db"], r["trial"])) or {}).get("dsp_events")
                                or {}).get("reinit", 0)) for r in rs)
            row = {**{n: v for n, v in combo}, "snr_db": float(snr), "trials": len(rs),
                   "invalid": err[0] if err else None,
                   "locked": len(ok), "golden_locked": ng, "golden_reinit": g_reinit,
                   P: rmse, "golden_" + P: g_rmse,
                   "ratio_to_golden": (p_rmse / g_rmse) if (paired and g_rmse) else None,
                   "ratio_ci95": ratio_ci(paired, json.dumps([cl, float(snr)]), fig=P),
                   "mean_error_deg": float(np.mean([r["mean_error_deg"] for r in ok]))
                   if ok and all(r.get("mean_error_deg") is not None for r in ok) else None,
                   "crb_deg": rs[0].get("crb_deg") or (gold.get((rs[0]["snr_db"], rs[0]["trial"])) or {}).get("crb_deg"),
                   "adc_clipped": int(sum(r.get("adc_clipped") or 0 for r in rs)),
                   "fifo_dropped": int(sum(r.get("fifo_dropped") or 0 for r in rs)),
                   "dsp_events": ev}
            rows.append(row)
    return rows


def _excess_reinit(row: dict) -> int:
    """How many more times the fixed-point filter was re-initialised than the golden one."""
    return max(0, int((row.get("dsp_events") or {}).get("reinit", 0))
               - int(row.get("golden_reinit", 0)))


def _reinit_beyond_golden(row: dict) -> bool:
    """The fixed-point filter was re-initialised more often than the golden one."""
    return _excess_reinit(row) > 0


def passes(row: dict, target_rel: float) -> bool:
    """A point meets the target at one SNR: it locks as often as the golden chain, its
    filter is not re-initialised more often than the golden one, and its paired RMSE ratio
    to the golden one is within ``1 + target_rel`` -- or not significantly above it (the
    lower end of its 95 % bootstrap interval is): at low SNR the trial-to-trial spread of a
    short run is several per cent, and a width must not be refused for noise the study
    cannot resolve (the report shows the intervals). A re-initialisation is not that noise:
    it is the fixed-point filter diverging (``P`` 34 bits: one in 10 trials, a 37x ratio
    whose interval still reached 0.94), and it refuses the width. SNRs where the golden
    chain does not lock on most trials are not judged."""
    if row["invalid"]:
        return False
    if row["golden_locked"] < 0.8 * row["trials"]:
        return True
    if row["locked"] < row["golden_locked"] or _reinit_beyond_golden(row):
        return False
    r = row["ratio_to_golden"]
    if r is None:
        return False
    ci = row.get("ratio_ci95")
    return r <= 1 + target_rel or (ci is not None and ci[0] <= 1 + target_rel)


def propose(cfg: SweepConfig, rows: list[dict]) -> dict:
    """Smallest value of each numeric swept parameter (the others at their largest swept
    value) such that it and every larger value pass at every SNR (see :func:`passes`)."""
    names = [n for n, _ in cfg.params]
    ref = {n: max(v) if all(isinstance(x, (int, float)) for x in v) else v[0]
           for n, v in cfg.params}
    out = {}
    for n, vals in cfg.params:
        if not all(isinstance(x, (int, float)) for x in vals):
            continue
        ok_vals = []
        for v in sorted(vals):
            sel = [r for r in rows if r[n] == v and all(r[m] == ref[m] for m in names if m != n)]
            ok_vals.append((v, bool(sel) and all(passes(r, cfg.target_rel) for r in sel)))
        best = None
        for v, ok in reversed(ok_vals):
            if not ok:
                break
            best = v
        out[n] = best
    return out


def confirms(row: dict, target_rel: float) -> bool:
    """The confirmation's test at one SNR, stricter than the proposal's: the measured paired
    ratio itself must be within ``1 + target_rel``; as in the proposal, the lock count that
    of the golden chain and no more re-initialisations than the golden filter (a combination
    of word lengths that makes the filter diverge now and then is not confirmed by a lucky
    RMSE)."""
    if row["invalid"]:
        return False
    if row["golden_locked"] < 0.8 * row["trials"]:
        return True
    if row["locked"] < row["golden_locked"]:
        return False
    if _reinit_beyond_golden(row):
        return False
    return row["ratio_to_golden"] is not None and row["ratio_to_golden"] <= 1 + target_rel


def shortfall(rows: list[dict], target_rel: float) -> tuple:
    """How far a confirmation run is from confirming, to rank the candidates of a round
    (smaller is nearer): the SNRs that fail, the filter re-initialisations beyond the golden
    chain's, the worst measured ratio."""
    bad = sum(1 for r in rows if not confirms(r, target_rel))
    extra = sum(_excess_reinit(r) for r in rows)
    worst = max((r["ratio_to_golden"] for r in rows if r.get("ratio_to_golden") is not None),
                default=math.inf)
    return bad, extra, worst


def widen_one(cfg: SweepConfig, params: dict) -> list[tuple[str, dict]]:
    """Each numeric parameter alone one swept value wider (where there is one)."""
    out = []
    for n, vals in cfg.params:
        if n in params and all(isinstance(x, (int, float)) for x in vals):
            larger = sorted(v for v in vals if v > params[n])
            if larger:
                out.append((n, {**params, n: larger[0]}))
    return out
