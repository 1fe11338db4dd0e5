"""What a sweep's points say about word lengths: the rows per (combination, SNR), the
proposal and the tests of its confirmation (:mod:`cosim.studies.sweep` runs the points,
writes the report and runs the confirmation, :func:`cosim.studies.sweep.confirm`).

* :func:`aggregate` pools a combination's trials at one SNR into the three figures of what
  a user sees (:mod:`cosim.studies.shown`: accuracy, availability, integrity) and pairs them
  with the golden chain on the same records.
* :func:`propose` takes each parameter alone to its smallest value that, with every larger
  one, meets all three at every SNR (:func:`passes`).
* :func:`confirms` is the stricter test a confirmation run (the proposal re-run on fresh
  seeds, all values together) must pass; :func:`shortfall` ranks the runs that fail and
  :func:`widen_one` gives the candidates of the next round.
"""
from __future__ import annotations

import json
import math
import numpy as np

from .shown import paired, pool
from .spec import SweepConfig, primary_key

__all__ = ["aggregate", "propose", "ratio_ci", "judged", "available_enough", "failing", "passes",
           "confirms", "shortfall", "widen_one"]


def ratio_ci(pairs, key: str, n_boot: int = 2000, fig: str = "rmse_deg") -> list[float] | None:
    """95 % bootstrap interval (over trials, paired) of the RMSE ratio point / golden.

    Within one trial the estimates are strongly correlated (the filter's memory spans a good
    part of the scored time), so the trials are the independent samples; resampling them
    in pairs keeps the cancellation of the common noise. Seeded from ``key``: the same
    results give the same interval (:func:`cosim.studies.shown.paired` draws the same)."""
    if len(pairs) < 3:
        return None
    return paired([{"rmse": r[fig], "misleading": 0, "availability": None} for r, _ in pairs],
                  [{"rmse": g[fig], "misleading": 0, "availability": None} for _, g in pairs],
                  key, n_boot)["ratio_ci95"]


def aggregate(cfg: SweepConfig, results: list[dict]) -> list[dict]:
    """Per (combo, SNR): the three figures of what a user sees (:mod:`cosim.studies.shown`)
    pooled over the trials, each beside the golden chain's on the same records --
    accuracy (RMSE and mean error of the valid estimates; the paired ratio and its
    interval), availability (mean fraction of epochs with a valid estimate, the paired
    difference and its interval, time to first valid estimate), integrity (misleading
    estimates, their rate and its interval, those the golden chain does not also make) --
    and the CRB, the filter's events, ADC clips and FIFO drops."""
    P = primary_key(cfg.receiver)
    gold = {(r["snr_db"], r["trial"]): r for r in results if r.get("kind") == "golden"}
    pts = [r for r in results if r.get("kind") == "point"]
    rows = []
    for combo in cfg.combos:
        cl = [list(c) for c in combo]
        for snr in cfg.snr_db:
            rs = sorted((r for r in pts if r["combo"] == cl and r["snr_db"] == float(snr)),
                        key=lambda r: r["trial"])
            if not rs:
                continue
            err = [r.get("error") for r in rs if r.get("error")]
            gs = [gold.get((r["snr_db"], r["trial"])) or {} for r in rs]
            pairs = [(r["shown"], g["shown"]) for r, g in zip(rs, gs)
                     if r.get("shown") and g.get("shown")]
            fp = pool([r["shown"] for r in rs if r.get("shown")]) if any(
                r.get("shown") for r in rs) else None
            fg = pool([g for _, g in pairs]) if pairs else None
            pr = paired([p for p, _ in pairs], [g for _, g in pairs],
                        json.dumps([cl, float(snr)])) if pairs else {}
            ev: dict = {}
            for r in rs:
                for k, v in (r.get("dsp_events") or {}).items():
                    ev[k] = ev.get(k, 0) + int(v)
            g_reinit = sum(int((g.get("dsp_events") or {}).get("reinit", 0)) for g in gs)
            get = lambda d, k: None if d is None else d[k]
            row = {**{n: v for n, v in combo}, "snr_db": float(snr), "trials": len(rs),
                   "invalid": err[0] if err else None,
                   # accuracy
                   "locked": get(fp, "trials_valid") or 0,
                   "golden_locked": get(fg, "trials_valid") or 0,
                   "golden_reinit": g_reinit,
                   P: get(fp, "rmse"), "golden_" + P: get(fg, "rmse"),
                   "ratio_to_golden": pr.get("ratio"), "ratio_ci95": pr.get("ratio_ci95"),
                   "mean_error": get(fp, "mean_error"),
                   "golden_mean_error": get(fg, "mean_error"),
                   # availability
                   "availability": get(fp, "availability"),
                   "golden_availability": get(fg, "availability"),
                   "availability_diff": pr.get("availability_diff"),
                   "availability_diff_ci95": pr.get("availability_diff_ci95"),
                   "first_valid_s": get(fp, "first_valid_s_median"),
                   "first_valid_s_max": get(fp, "first_valid_s_max"),
                   "golden_first_valid_s": get(fg, "first_valid_s_median"),
                   "never_valid": get(fp, "never_valid"),
                   # integrity
                   "n_valid": get(fp, "n_valid"), "misleading": get(fp, "misleading"),
                   "misleading_rate": get(fp, "misleading_rate"),
                   "misleading_rate_ci95": get(fp, "misleading_rate_ci95"),
                   "golden_misleading": get(fg, "misleading"),
                   "excess_misleading": pr.get("excess_misleading", 0),
                   "crb_deg": rs[0].get("crb_deg") or gs[0].get("crb_deg"),
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


def judged(row: dict) -> bool:
    """Accuracy and availability are judged where the golden chain shows a valid estimate
    on >= 80 % of the trials (below, there is little to compare with); integrity is judged
    everywhere."""
    return row["golden_locked"] >= 0.8 * row["trials"]


def available_enough(row: dict, margin: float) -> bool:
    """Availability not below the golden chain's on the same records by more than
    ``margin`` (an absolute fraction of the epochs): the measured paired difference."""
    d = row["availability_diff"]
    return d is not None and d >= -margin


def failing(row: dict, target_rel: float, margin: float = 0.02, strict: bool = False) -> list:
    """The figures a point fails at one SNR (empty: it meets the target), of ``invalid``,
    ``integrity``, ``availability``, ``re-init`` and ``accuracy``.

    * **Integrity**: no misleading estimate the golden chain does not also make on the
      same record (at every SNR: one is enough to refuse, whatever the RMSE).
    * **Availability**: the fraction of epochs with a valid estimate not below the golden
      chain's by more than ``margin`` (:func:`available_enough`).
    * **Re-init**: the filter not re-initialised more often than the golden one (a
      re-initialisation is the fixed-point filter diverging: ``P`` 34 bits, one in 10
      trials, a 37x ratio whose interval still reached 0.94).
    * **Accuracy**: the paired RMSE ratio of the valid estimates within ``1 + target_rel``
      -- or, unless ``strict`` (the confirmation), not significantly above it (the lower
      end of its 95 % bootstrap interval is): at low SNR the trial-to-trial spread of a
      short run is several per cent, and a width must not be refused for noise the study
      cannot resolve (the report shows the intervals).

    Accuracy, availability and re-inits are not judged where the golden chain shows a
    valid estimate on fewer than 80 % of the trials (:func:`judged`)."""
    if row["invalid"]:
        return ["invalid"]
    out = ["integrity"] if row["excess_misleading"] > 0 else []
    if not judged(row):
        return out
    if not available_enough(row, margin):
        out.append("availability")
    if _reinit_beyond_golden(row):
        out.append("re-init")
    r, ci = row["ratio_to_golden"], row.get("ratio_ci95")
    if r is None or not (r <= 1 + target_rel or (not strict and ci is not None
                                                 and ci[0] <= 1 + target_rel)):
        out.append("accuracy")
    return out


def passes(row: dict, target_rel: float, margin: float = 0.02) -> bool:
    """A point meets the proposal's target at one SNR on all three figures of what a user
    sees (:func:`failing` is empty)."""
    return not failing(row, target_rel, margin)


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
            ok_vals.append((v, bool(sel) and all(passes(r, cfg.target_rel, cfg.availability_margin)
                                                  for r in sel)))
        best = None
        for v, ok in reversed(ok_vals):
            if not ok:
                break
            best = v
        out[n] = best
    return out


def confirms(row: dict, target_rel: float, margin: float = 0.02) -> bool:
    """The confirmation's test at one SNR, stricter than the proposal's: the measured paired
    accuracy ratio itself must be within ``1 + target_rel``; as in the proposal, no
    misleading estimate the golden chain does not also make, availability not below the
    golden chain's by more than ``margin``, and no more re-initialisations than the golden
    filter (a combination of word lengths that makes the filter diverge now and then is not
    confirmed by a lucky RMSE)."""
    return not failing(row, target_rel, margin, strict=True)


def shortfall(rows: list[dict], target_rel: float, margin: float = 0.02) -> tuple:
    """How far a confirmation run is from confirming, to rank the candidates of a round
    (smaller is nearer): the SNRs that fail, the misleading estimates and filter
    re-initialisations beyond the golden chain's, the availability lost, the worst
    measured ratio."""
    bad = sum(1 for r in rows if not confirms(r, target_rel, margin))
    extra = sum(_excess_reinit(r) + int(r["excess_misleading"]) for r in rows)
    lost = sum(max(0.0, -(r["availability_diff"] or 0.0)) for r in rows)
    worst = max((r["ratio_to_golden"] for r in rows if r.get("ratio_to_golden") is not None),
                default=math.inf)
    return bad, extra, lost, worst


def widen_one(cfg: SweepConfig, params: dict) -> list[tuple[str, dict]]:
    """Each numeric parameter alone one swept value wider (where there is one)."""
    out = []
    for n, vals in cfg.params:
        if n in params and all(isinstance(x, (int, float)) for x in vals):
            larger = sorted(v for v in vals if v > params[n])
            if larger:
                out.append((n, {**params, n: larger[0]}))
    return out
