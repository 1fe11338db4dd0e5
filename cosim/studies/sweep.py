"""Quantisation sweeps: word lengths and modes x SNR x Monte Carlo trials, with a report.

A sweep crosses any word-length or mode parameter of the HDL front end and of the DSP core
with SNR and trials, runs every point on the bit-exact fast path (the front end's numpy
model, the FIFO/link model and the fixed-point DSP core), judges it as a user sees it --
accuracy of the estimates shown valid, availability, integrity (:mod:`cosim.studies.shown`)
-- against the float golden chain run on the *same* record (paired comparison: the
trial-to-trial noise cancels), and writes CSV/JSON of every point, plots, and a Markdown
report (:mod:`cosim.studies.report`) with the range and saturation log and a word-length
proposal.

The receiver is a registered one (:mod:`cosim.core.receivers`) whose ``sweep`` study has a
:class:`~cosim.core.receivers.SweepModel`: it names the parameters (``--param NAME=VALUES``;
TACAN's: :mod:`cosim.tacan.study`), runs one record (the point runner: swept values + SNR +
trial seed -> metrics with ``shown``, the three figures of what a user sees, and the golden
run of the same record) and
keeps its own front-end cache; everything else here is generic.

Values: ``a:b`` (integers a..b), ``a:b:s`` (a, a+s, ... <= b), or a comma list.

Execution: tasks are (SNR, trial) records -- one signal generation, the golden chain once,
then every parameter combination -- run on a local process pool (default: all cores) or a
Dask cluster (``scheduler="dask"`` starts a local one, or give a scheduler address). Every
point is cached as ``points/<key>.json`` under the output directory, so an interrupted sweep
resumes where it stopped; the key hashes everything that defines the point, the project's
sources included.

The sweep's configuration and parameter lists: :mod:`cosim.studies.spec`; the proposal and
the tests of its confirmation: :mod:`cosim.studies.proposal`; the confirmation run:
:func:`confirm`.
"""
from __future__ import annotations

import csv
import hashlib
import json
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from cosim.core.validate import check_jobs, dumps
from dsp.shown import FIGURE_KEYS

from .engine import run_tasks
from .proposal import aggregate, confirms, propose, shortfall, widen_one
from .report import plot, proposal_record, report_md
from .spec import SweepConfig, primary_key, sweep_model

#: CPU seconds one point costs per second of record (TACAN's: model front end, FIFO, fixed
#: DSP and its share of the golden chain; measured ~1 s, with margin; a receiver gives its
#: own in ``SweepModel.cpu_s_per_record_s``; the longest study started is
#: :data:`cosim.core.validate.MAX_STUDY_S`).
CPU_S_PER_RECORD_S = 1.5


# ---------------------------------------------------------------------------------------
# One point
# ---------------------------------------------------------------------------------------
def check_points(cfg: SweepConfig) -> None:
    """Every point's configuration, built and validated before the first point runs: a
    value the front end or the DSP core refuses (a 4.5-bit ADC, an unknown rounding, a
    word too narrow for its signal) stops the study here, with the message, instead of
    ending up as an "invalid" row of the report. Also refuses a study too big to start
    (points x record length)."""
    from cosim.core.validate import MAX_STUDY_S, check_budget, cores
    model = sweep_model(cfg.receiver)
    for combo in cfg.combos:
        try:
            model.check_point(cfg, combo)
        except ValueError as e:
            raise ValueError(f"sweep point {', '.join(f'{n}={v}' for n, v in combo)}: {e}") \
                from None
    # the summary holds every point (a few kB each with its range log); the points are
    # spread over the cores
    check_budget(f"{cfg.n_points:,} points of {cfg.duration_s:g} s",
                 "the swept values, --snr-db, --trials or --duration-s",
                 memory_bytes=cfg.n_points * 20e3,
                 seconds=cfg.n_points * cfg.duration_s * model.cpu_s_per_record_s / cores(),
                 max_seconds=MAX_STUDY_S)


def point_key(cfg: SweepConfig, combo, snr_db, trial) -> str:
    """The cache key of a point: its configuration and the project's sources
    (:func:`dsp.jit.source_hash`), so that a cached point never outlives the code that
    computed it (a new default detector, a new lock rule)."""
    from dsp.jit import PROJECT_PACKAGES, PROJECT_ROOT, source_hash
    code = source_hash(tuple(str(PROJECT_ROOT / p) for p in PROJECT_PACKAGES))
    d = {"receiver": cfg.receiver, "combo": [list(c) for c in combo], "snr_db": float(snr_db),
         "trial": trial, "duration_s": cfg.duration_s, "memory_s": cfg.memory_s,
         "seed": cfg.seed, "code": code}
    return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:20]


def _shown(metrics: dict, cfg: SweepConfig) -> dict:
    """A record's metrics with what a user sees: the receiver gives ``shown``, the figures
    of :func:`dsp.shown.shown_figures` (accuracy, availability, integrity); a
    record is ``locked`` when it showed a valid estimate after settling."""
    fig = metrics.get("shown")
    if not isinstance(fig, dict) or any(k not in fig for k in FIGURE_KEYS):
        raise RuntimeError(f"the {cfg.receiver} study model's record gave no 'shown' figures "
                           f"(dsp.shown.shown_figures)")
    return {**metrics, "locked": fig["n_valid"] > 0}


def run_task(cfg: SweepConfig, snr_db: float, trial: int, combos: list, cache_dir: str | None,
             recheck_combos: tuple = ()) -> list[dict]:
    """All points of one record (SNR, trial): the receiver's record (its signal generated
    once, its front-end cache), its golden run once, then every point not yet cached."""
    model = sweep_model(cfg.receiver)
    cache = Path(cache_dir) if cache_dir else None
    out, todo = [], []
    for combo in combos:
        key = point_key(cfg, combo, snr_db, trial)
        f = cache / f"{key}.json" if cache else None
        if f is not None and f.exists():
            out.append({**json.loads(f.read_text()), "from_cache": True})
        else:
            todo.append((combo, key, f))
    gkey = point_key(cfg, (("golden", 1),), snr_db, trial)
    gfile = cache / f"{gkey}.json" if cache else None
    golden = json.loads(gfile.read_text()) if gfile is not None and gfile.exists() else None
    if not todo and golden is not None:
        return out + [golden]
    rec = model.record(cfg, snr_db, trial, [c for c, _, _ in todo])
    base = {"snr_db": float(snr_db), "trial": trial, **rec.base}
    if golden is None:
        golden = {**base, "combo": [["golden", 1]], "kind": "golden", "locked": False}
        try:
            golden.update(_shown(rec.golden(), cfg))
        except (ValueError, RuntimeError) as e:
            golden["error"] = str(e)
        if gfile is not None:
            gfile.write_text(json.dumps(golden))
    for combo, key, f in todo:
        row = {**base, "combo": [list(c) for c in combo], "kind": "point", "locked": False,
               "key": key}
        # the configuration was validated before the study started (check_points); an
        # error here stops the study with its message instead of becoming a row
        row.update(_shown(rec.point(combo, recheck=tuple(combo) in recheck_combos), cfg))
        if f is not None:
            f.write_text(json.dumps(row))
        out.append(row)
    return out + [golden]


# ---------------------------------------------------------------------------------------
# Execution
# ---------------------------------------------------------------------------------------
def _task_entry(args):
    return run_task(*args)


def _recheck_choice(cfg: SweepConfig) -> tuple:
    """Combos re-checked cycle-accurately (seeded choice), each at the first SNR/trial."""
    combos = cfg.combos
    if cfg.recheck <= 0:
        return ()
    rng = np.random.default_rng([cfg.seed, 4242])
    idx = rng.choice(len(combos), size=min(cfg.recheck, len(combos)), replace=False)
    return tuple(tuple(combos[i]) for i in sorted(idx))


def run_sweep(cfg: SweepConfig, out: str | Path, *, jobs: int | None = None,
              scheduler: str = "local", progress: bool = True) -> dict:
    """Run (or resume) a sweep and write its report under ``out``; returns the summary.

    ``scheduler``: ``"local"`` (process pool of ``jobs`` workers, default all cores),
    ``"dask"`` (a local Dask cluster of ``jobs`` workers) or a Dask scheduler address
    (``"tcp://host:8786"``).
    """
    from tqdm import tqdm
    tqdm.monitor_interval = 0     # no monitor thread left behind in the caller's process
    out = Path(out)
    cache = out / "points"
    cache.mkdir(parents=True, exist_ok=True)
    (out / "sweep.json").write_text(json.dumps(_cfg_dict(cfg), indent=1))
    t0 = time.perf_counter()
    rc = _recheck_choice(cfg)
    combos = cfg.combos
    tasks = []
    for si, snr in enumerate(cfg.snr_db):
        for trial in range(cfg.trials):
            chk = rc if (si == 0 and trial == 0) else ()
            tasks.append((cfg, float(snr), trial, combos, str(cache), chk))
    jobs = check_jobs(jobs, "jobs")
    bar = tqdm(total=len(tasks), desc=f"sweep ({cfg.n_points} points)", file=sys.stderr,
               disable=not progress)
    results = []
    for r in run_tasks(_task_entry, tasks, jobs=jobs, scheduler=scheduler,
                       on_done=bar.update):
        results.extend(r)
    bar.close()
    elapsed = time.perf_counter() - t0
    return write_report(cfg, results, out, elapsed=elapsed)


def _cfg_dict(cfg: SweepConfig) -> dict:
    d = asdict(cfg)
    d["params"] = [[n, list(v)] for n, v in cfg.params]
    d["snr_db"] = list(cfg.snr_db)
    return d


def write_report(cfg: SweepConfig, results: list[dict], out: Path, *, elapsed: float = 0.0) -> dict:
    from cosim.core.provenance import machine_info
    out = Path(out)
    P = primary_key(cfg.receiver)
    rows = aggregate(cfg, results)
    proposal = propose(cfg, rows)
    pts = sorted((r for r in results if r.get("kind") in ("point", "golden")),
                 key=lambda r: (r["snr_db"], r["trial"], json.dumps(r["combo"])))
    rechecks = [{"combo": r["combo"], **r["recheck"]} for r in pts if r.get("recheck")]
    ranges = _collect_ranges(pts)
    cached = sum(1 for r in results if r.get("kind") == "point" and r.get("from_cache"))
    summary = {"study": "sweep", "machine": machine_info(), "config": _cfg_dict(cfg),
               "from_cache": cached,
               "elapsed_s": elapsed, "n_points": cfg.n_points, "rows": rows,
               "proposal": proposal, "target_rel": cfg.target_rel, "rechecks": rechecks,
               "ranges": ranges}
    (out / "summary.json").write_text(dumps(summary, indent=1))
    names = [n for n, _ in cfg.params]
    with open(out / "points.csv", "w", newline="") as f:
        w = csv.writer(f)
        shown = ("n_estimates", "n_valid", "rmse", "mean_error", "max_abs_error",
                 "availability", "first_valid_s", "misleading")
        w.writerow(["kind", "combo", "snr_db", "trial", "bearing_deg", "locked"]
                   + [f"shown_{k}" for k in shown]
                   + ["crb_deg", "adc_clipped", "fifo_dropped", "gated", "reinit", "error"])
        for r in pts:
            sh = r.get("shown") or {}
            w.writerow([r["kind"], json.dumps(r["combo"]), r["snr_db"], r["trial"],
                        r.get("bearing_deg"), r["locked"]] + [sh.get(k) for k in shown]
                       + [r.get("crb_deg"), r.get("adc_clipped"), r.get("fifo_dropped"),
                          r.get("gated"), r.get("reinit"), r.get("error")])
    with open(out / "summary.csv", "w", newline="") as f:
        keys = names + ["snr_db", "trials", "locked", "golden_locked", P,
                        "golden_" + P, "ratio_to_golden", "mean_error", "crb_deg",
                        "availability", "golden_availability", "availability_diff",
                        "first_valid_s", "golden_first_valid_s", "misleading",
                        "golden_misleading", "excess_misleading", "misleading_rate",
                        "adc_clipped", "fifo_dropped", "invalid"]
        w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    plots = plot(cfg, rows, out)
    (out / "report.md").write_text(report_md(cfg, summary, plots))
    return summary


def _collect_ranges(pts) -> dict:
    """Per signal over every point: min/max seen, the word's range, the least headroom and
    the overflow/saturation count (Fixed-Point Designer's range log)."""
    agg: dict = {}
    for r in pts:
        for sig, d in (r.get("ranges") or {}).items():
            a = agg.setdefault(sig, {"min": None, "max": None, "lo": d.get("lo"),
                                     "hi": d.get("hi"), "headroom_bits": None,
                                     "overflows": 0, "unit": d.get("unit", ""), "points": 0})
            if d.get("min") is not None:
                a["min"] = d["min"] if a["min"] is None else min(a["min"], d["min"])
                a["max"] = d["max"] if a["max"] is None else max(a["max"], d["max"])
            # the word changes with the swept width: keep the tightest case
            hb = d.get("headroom_bits")
            if hb is not None and (a["headroom_bits"] is None or hb < a["headroom_bits"]):
                a["headroom_bits"], a["lo"], a["hi"] = hb, d.get("lo"), d.get("hi")
            a["overflows"] += int(d.get("overflows") or 0)
            a["points"] += 1
    return agg


def confirm(cfg: SweepConfig, proposal: dict, out: Path, *, jobs=None, scheduler="local",
            progress=True, max_backoff: int = 3) -> dict:
    """Re-run the proposed combination (all proposed values together) on fresh seeds and
    check it against the golden chain with the stricter :func:`confirms`.

    Word lengths that each pass alone can fail together (their losses add up). Then each
    parameter in turn is widened by one swept step, the others kept, and each of these
    candidates re-run: the one that confirms is the answer (of several, the one that widens
    least -- one more bit before two -- then the one with the smallest worst ratio); when
    none does, the nearest by :func:`shortfall` is kept and the next round widens from it,
    up to ``max_backoff`` rounds. So only the widths that matter grow: a filter gain one
    step too short costs one parameter a step, not all of them. Should no round confirm,
    every parameter at its widest swept value (the sweep's reference) is the last attempt.
    Returns the summary: ``confirmed``, the ``params`` finally confirmed (or last tried),
    the ``attempts`` (params, rows, and the parameter each candidate widened)."""
    if not proposal or any(v is None for v in proposal.values()):
        return {"confirmed": False, "reason": "no complete proposal (some parameter never "
                                             "meets the target in the swept range)",
                "attempts": []}
    ref = cfg.reference
    attempts = []

    def attempt(params: dict, widened: str | None) -> dict:
        fixed = tuple((n, (params[n],)) for n, _ in cfg.params)
        ccfg = replace(cfg, params=fixed, seed=cfg.seed + 1, recheck=0, design="grid")
        s = run_sweep(ccfg, out / "confirm", jobs=jobs, scheduler=scheduler,
                            progress=progress)
        rows = s["rows"]
        a = {"params": dict(params), "widened": widened, "rows": rows,
             "confirmed": bool(all(confirms(r, cfg.target_rel, cfg.availability_margin)
                                        for r in rows))}
        attempts.append(a)
        return a

    best = attempt({n: (proposal[n] if n in proposal else ref[n]) for n, _ in cfg.params},
                   None)
    for _ in range(max_backoff):
        if best["confirmed"]:
            break
        cands = [attempt(p, n) for n, p in widen_one(cfg, best["params"])]
        if not cands:
            break
        best = min(cands, key=lambda a: (not a["confirmed"],
                                         a["params"][a["widened"]] - best["params"][a["widened"]]
                                         if a["confirmed"] else 0,
                                         shortfall(a["rows"], cfg.target_rel,
                                                   cfg.availability_margin)))
    if not best["confirmed"]:
        widest = {n: ref[n] for n, _ in cfg.params}
        if widest != best["params"]:
            best = attempt(widest, "all")
    res = {"confirmed": best["confirmed"], "params": best["params"], "seed": cfg.seed + 1,
           "rows": best["rows"], "attempts": attempts}
    model = sweep_model(cfg.receiver)
    if cfg.recheck > 0 and model.confirm_recheck is not None:
        # the combination proposed is the one to build: prove its bits on the RTL too
        combo = tuple((n, best["params"][n]) for n, _ in cfg.params)
        res["recheck"] = {"combo": [list(c) for c in combo], **model.confirm_recheck(cfg, combo)}
    return res


def study(cfg: SweepConfig, out: str | Path, *, jobs: int | None = None,
          scheduler: str = "local", confirm_proposal: bool = True, progress: bool = True) -> dict:
    """A sweep, its word-length proposal and (optionally) the confirming re-run; the report
    (``report.md``) includes the confirmation; ``proposal.json`` is its published summary
    (:func:`cosim.studies.report.proposal_record`)."""
    out = Path(out)
    s = run_sweep(cfg, out, jobs=jobs, scheduler=scheduler, progress=progress)
    if confirm_proposal:
        s["confirmation"] = confirm(cfg, s["proposal"], out, jobs=jobs, scheduler=scheduler,
                                    progress=progress)
        (out / "summary.json").write_text(dumps(s, indent=1))
        plots = sorted(p.name for p in out.glob("rmse_vs_*.png"))
        (out / "report.md").write_text(report_md(cfg, s, plots))
    (out / "proposal.json").write_text(dumps(proposal_record(s), indent=1))
    return s
