"""The records the TACAN benchmarks run and how they pool them: one golden-chain run per
item (:func:`one_run`, a worker of :func:`cosim.core.provenance.map_jobs`), the pooled figures of a
set of runs (:func:`pool_runs`), the rows of an SNR sweep (:func:`snr_rows`), the 0 dB sweep
over every bearing (:func:`sweep_0db`) and the single-pulse search's operating point
(:func:`detector_operating_point`).
"""
from __future__ import annotations

import numpy as np

from ..core.provenance import map_jobs


def one_run(kw: dict) -> dict:
    from .config import TacanRunConfig
    from .run import run_tacan
    from .signal import Multipath, TacanSignalConfig
    kw = dict(kw)
    echo = kw.pop("multipath", None)
    opts = {k: kw.pop(k) for k in ("amplitude", "noise_floor", "detector") if k in kw}
    sig = TacanSignalConfig(**kw, multipath=None if echo is None else Multipath(**echo))
    try:
        r = run_tacan(TacanRunConfig(signal=sig, backend="golden", **opts))
        r["locked"] = True
    except RuntimeError:  # no reference decoded: the receiver has no bearing (counted)
        r = {"locked": False, "snr_db": kw["snr_db"], "rmse_deg": None, "mean_error_deg": None,
             "max_abs_error_deg": None, "gated": 0, "reinit": 0, "first_valid_bearing_s": None,
             "rotation_hz": None}
    r.pop("elapsed_s", None)
    r["bearing_deg"] = kw["bearing_deg"]
    return r


def pool_runs(rows: list, key: str = "rmse_deg") -> dict:
    """RMSE (root of the mean square over the trials), mean error and worst error of the
    locked trials among ``rows``, and the median time to the first valid bearing."""
    ok = [r for r in rows if r["locked"] and r["rmse_deg"] is not None]
    ttfb = [r["first_valid_bearing_s"] for r in rows if r.get("first_valid_bearing_s") is not None]
    okv = [r for r in ok if r.get("valid_rmse_deg") is not None]
    out = {"trials": len(rows), "locked": len(ok), "rmse_deg": None, "mean_error_deg": None,
           "max_abs_error_deg": None,
           "valid_rmse_deg": float(np.sqrt(np.mean([r["valid_rmse_deg"] ** 2 for r in okv])))
           if okv else None,
           "misleading_bearings": int(sum(r.get("misleading_bearings", 0) for r in ok)),
           "first_valid_bearing_s": float(np.median(ttfb)) if ttfb else None,
           "valid_trials": len(ttfb)}
    if ok:
        out.update(rmse_deg=float(np.sqrt(np.mean([r["rmse_deg"] ** 2 for r in ok]))),
                   mean_error_deg=float(np.mean([r["mean_error_deg"] for r in ok])),
                   max_abs_error_deg=float(max(r["max_abs_error_deg"] for r in ok)))
    return out


def sweep_0db(step: int, crb: float, jobs, **opts) -> tuple[dict, list]:
    """Every bearing in ``step`` deg steps at 0 dB (2 s records, IF chain) with the run
    options ``opts``: the pooled figures and one row per bearing."""
    b0 = np.arange(0, 360, step, dtype=float)
    what = "".join(f", --{k.replace('_', '-')} {v}" for k, v in opts.items())
    runs = map_jobs(jobs, one_run, [dict(bearing_deg=float(b), snr_db=0.0, duration_s=2.0,
                                      seed=3000 + int(b), **opts) for b in b0],
                f"bearing sweep (IF, 0 dB{what})")
    rows = [{k: r.get(k) for k in ("bearing_deg", "locked", "rmse_deg", "mean_error_deg",
                                   "max_abs_error_deg", "first_valid_bearing_s", "valid_rmse_deg",
                                   "misleading_bearings")} for r in runs]
    p = pool_runs(runs)
    locked = [r for r in rows if r["locked"]]
    return ({**p, **opts, "bearings": int(b0.size), "step_deg": step, "duration_s": 2.0,
             "crb_deg": crb,
             "rmse_over_crb": p["rmse_deg"] / crb if p["rmse_deg"] is not None else None,
             "within_2x_crb": int(sum(r["rmse_deg"] <= 2 * crb for r in locked)),
             "sector_slips": int(sum(r["max_abs_error_deg"] > 20 for r in locked))}, rows)


def snr_rows(runs: list, snrs, crbs: dict) -> list:
    """One row per SNR and bearing (90, 270 deg) of the SNR sweep ``runs``: pooled figures,
    the bound and RMSE / CRB."""
    rows = []
    for s in snrs:
        for b in (90.0, 270.0):
            rs = [r for r in runs if r["snr_db"] == s and r["bearing_deg"] == b]
            row = {"snr_db": s, "bearing_deg": b, **pool_runs(rs), "crb_deg": crbs[s],
                   "gated": int(sum(r["gated"] for r in rs)),
                   "reinit": int(sum(r["reinit"] for r in rs))}
            row["rmse_over_crb"] = row["rmse_deg"] / crbs[s] if row["rmse_deg"] is not None \
                else None
            rows.append(row)
    return rows


def detector_operating_point(kw: dict) -> dict:
    from .detector import operating_point
    from .config import TacanRunConfig
    from .signal import TacanSignalConfig
    sig = TacanSignalConfig(bearing_deg=90.0, duration_s=1.0, seed=100, snr_db=kw["snr_db"])
    return operating_point(TacanRunConfig(signal=sig, noise_floor=kw["noise_floor"], settle_s=0.5,
                                          detector="pulse"))
