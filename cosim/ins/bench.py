"""INS paper benchmark: the paper's Table 2 beside ours, figures 6-7, the loops' cost.

``python -m cosim bench ins`` (the INS receiver's benchmark ``ins``) writes ``results/ins.json``,
``results/ins.md`` and ``results/ins_fig6_7.png``: for 40 dB-Hz and 35 dB-Hz, TCXO and OCXO,
the three loops over the paper's trajectory (150 s; ``quick``: 35 s, 4 trials), 20 Monte
Carlo trials each on the fast path, velocity-error and range-error mean/std along the line
of sight, PLI, lock fraction, cycle slips, and epochs per second of each loop.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from .study import LOOPS, InsStudyConfig, lock_threshold, run_loop, scenario_for

#: The C/N0 threshold search: scenario length (s; covers the manoeuvre, which ends at
#: 31.9 s, and 8 s of cruise), trials, bracket (dB-Hz) and resolution (dB).
THRESHOLD = {"duration_s": 40.0, "trials": 8, "lo_dbhz": 26.0, "hi_dbhz": 42.0,
             "resolution_db": 1.0}

PAPER_TABLE2 = {  # std rows of the INS paper's Table 2 (position m, velocity m/s; x y z)
    "unaided-kf": {"pos_std": (2.670, 2.431, 0.990), "vel_std": (0.043, 0.201, 0.007)},
    "aided-pll": {"pos_std": (2.728, 2.461, 1.022), "vel_std": (0.080, 0.125, 0.025)},
    "aided-kf": {"pos_std": (2.686, 2.425, 0.993), "vel_std": (0.038, 0.120, 0.007)},
}


def _table_point(osc: str, cn0: float, loop: str, dur: float, trials: int,
                 traj: dict) -> tuple[dict, dict]:
    """One loop at one (oscillator, C/N0): its Table 2 row, its figure 6-7 series at
    40 dB-Hz (trial 0) and its cost (epochs per CPU second)."""
    cfg = InsStudyConfig(cn0_dbhz=cn0, oscillator=osc, trials=trials, duration_s=dur, **traj)
    t = time.process_time()
    r = run_loop(loop, cfg, scenario_for(cfg), keep=(cn0 == 40.0))
    el = time.process_time() - t
    s = r.pop("series", None)
    series = {}
    if s is not None:
        series[(osc, loop)] = {"t": s["t_s"], "disc": s["disc_cycles"][:, 0], "pli": s["pli"][:, 0]}
    r["cpu_s"] = el
    r["epochs_per_s"] = dur / 1e-3 / el
    r["trial_epochs_per_s"] = trials * dur / 1e-3 / el
    return r, series


def _threshold_point(osc: str, loop: str, th: dict, traj: dict) -> dict:
    cfg = InsStudyConfig(oscillator=osc, trials=th["trials"], duration_s=th["duration_s"], **traj)
    t = time.process_time()
    r = lock_threshold(loop, cfg, th["lo_dbhz"], th["hi_dbhz"], th["resolution_db"])
    r.update(oscillator=osc, cpu_s=time.process_time() - t)
    return r


def ins_bench(out: Path, quick: bool = False, jobs: int | None = None, *,
              scenario: dict | None = None) -> dict:
    """The benchmark (module doc); ``jobs`` > 1 runs its points in that many processes.
    The points run in order of importance (Table 2 at 40 dB-Hz OCXO, TCXO, then the lower
    C/N0, then the thresholds) and the results files are rewritten as each one ends, the
    points not run yet listed as pending."""
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    import multiprocessing as mp
    from cosim.core.provenance import machine_info
    out.mkdir(parents=True, exist_ok=True)
    dur, trials = (35.0, 4) if quick else (150.0, 20)
    th = dict(THRESHOLD, duration_s=35.0, trials=2, resolution_db=4.0) if quick else THRESHOLD
    sc = dict(scenario or {})
    dur, trials, th = sc.pop("duration_s", dur), sc.pop("trials", trials), sc.pop("threshold", th)
    traj = sc.pop("trajectory", {})
    if sc:
        raise ValueError(f"unknown scenario overrides {sorted(sc)}")
    t_all = time.time()
    points = [("table", osc, cn0, lp) for cn0 in (40.0, 35.0) for osc in ("ocxo", "tcxo")
              for lp in LOOPS] + [("threshold", osc, None, lp) for osc in ("ocxo", "tcxo")
                                  for lp in LOOPS]
    machine = machine_info()
    rows, thr, series, done = {}, {}, {}, set()

    def record(pt, res):
        if pt[0] == "table":
            rows[pt], sr = res
            series.update(sr)
        else:
            thr[pt] = res
        done.add(pt)
        summary = {"machine": machine, "duration_s": dur, "trials": trials,
                   "elapsed_s": time.time() - t_all, "jobs": jobs or 1,
                   "rows": [rows[p] for p in points if p in rows],
                   "paper_table2_std": PAPER_TABLE2, "threshold_search": th,
                   "thresholds": [thr[p] for p in points if p in thr],
                   "pending": [list(p) for p in points if p not in done]}
        (out / "ins.json").write_text(json.dumps(summary, indent=1))
        if series:
            _plot(out / "ins_fig6_7.png", series)
        (out / "ins.md").write_text(_md(summary))
        return summary

    def call(pt):
        kind, osc, cn0, lp = pt
        return (_table_point, (osc, cn0, lp, dur, trials, traj)) if kind == "table" else \
            (_threshold_point, (osc, lp, th, traj))

    summary = None
    if jobs and jobs > 1:
        with ProcessPoolExecutor(jobs, mp_context=mp.get_context("fork")) as ex:
            fut = {ex.submit(*(lambda f, a: (f,) + a)(*call(pt))): pt for pt in points}
            pend = set(fut)
            while pend:
                fin, pend = wait(pend, return_when=FIRST_COMPLETED)
                for f in sorted(fin, key=lambda f: points.index(fut[f])):
                    summary = record(fut[f], f.result())
    else:
        for pt in points:
            f, args = call(pt)
            summary = record(pt, f(*args))
    return summary


def _block_mean(x, n):
    m = len(x) // n
    return np.asarray(x[:m * n], float).reshape(m, n).mean(axis=1)


def _plot(path, series, segments=None):
    """Seed figures 6-7: discriminator output (20 ms means: the 1 ms values' thermal spread,
    ~13 deg rms at 40 dB-Hz, hides the dynamic stress) and PLI (100 ms means of the 10 ms
    values) vs time, the three loops, OCXO and TCXO; jerk segments shaded."""
    from ..tools.plots import pyplot, save_figure
    plt = pyplot()
    from .trajectory import PaperTrajectory
    segs = PaperTrajectory().jerk_segments() if segments is None else segments
    fig, ax = plt.subplots(2, 2, figsize=(13, 6.5), sharex=True)
    colours = {"aided-kf": "tab:blue", "aided-pll": "tab:orange", "unaided-kf": "tab:green"}
    for j, osc in enumerate(("ocxo", "tcxo")):
        for lp in LOOPS:
            s = series.get((osc, lp))
            if s is None:
                continue
            d = _block_mean(s["disc"], 20) * 360
            ax[0, j].plot((np.arange(d.size) + 0.5) * 0.02, d, lw=0.5, color=colours[lp], label=lp)
            p = _block_mean(s["pli"], 10)
            ax[1, j].plot((np.arange(p.size) + 0.5) * 0.1, p, lw=0.6, color=colours[lp], label=lp)
        ax[0, j].set_title(f"discriminator output, 20 ms means (deg), 40 dB-Hz, {osc.upper()} "
                           f"(seed fig. 6)", fontsize=9)
        ax[1, j].set_title("PLI, 100 ms means of 10 ms sums (seed fig. 7)", fontsize=9)
        ax[1, j].set_xlabel("time (s)")
        for a in ax[:, j]:
            for t0, t1 in segs:
                a.axvspan(t0, t1, color="0.85", zorder=0)
            a.grid(alpha=0.3)
            if a.lines:
                a.legend(fontsize=7, loc="lower right")
    save_figure(fig, path, dpi=100)


def figures(out: Path, duration_s: float = 150.0, seed: int = 1) -> Path:
    """Redraw :file:`ins_fig6_7.png` alone: one trial of each loop at 40 dB-Hz, OCXO and
    TCXO, over the paper's trajectory (``python -c "from pathlib import Path; from
    cosim.ins.bench import figures; figures(Path('results'))"``)."""
    series = {}
    for osc in ("ocxo", "tcxo"):
        for lp in LOOPS:
            series.update(_table_point(osc, 40.0, lp, duration_s, 1, {})[1])
    path = Path(out) / "ins_fig6_7.png"
    _plot(path, series)
    return path


def _md(s: dict) -> str:
    m = s["machine"]
    L = [f"# The INS paper: INS-aided Kalman carrier loop vs aided PLL vs unaided Kalman loop", "",
         f"`{m['command']}`, {m['date']}, {m['cpu']}, commit {m['commit']}; fast path, "
         f"{s['trials']} trials per loop, {s['duration_s']:g} s of the paper's trajectory "
         f"(8300 m/s, 50 g, 5 g/s), INS 10 deg/h + 1 mg; {s['elapsed_s']:.0f} s wall in all on {s['jobs']} process(es).", "",
         "The paper's Table 2 (std rows; position m, velocity m/s, per ECEF axis, full PVT):", "",
         "| loop | pos std x y z | vel std x y z |", "|---|---|---|"]
    for lp, v in s["paper_table2_std"].items():
        L.append(f"| {lp} | {' / '.join(map(str, v['pos_std']))} | {' / '.join(map(str, v['vel_std']))} |")
    L += ["", "Ours (one satellite, along the line of sight: velocity from the loop's Doppler "
          "estimate, range from the DLL's code error):", "",
          "| osc | C/N0 | loop | vel mean m/s | vel std m/s | range mean m | range std m | "
          "disc RMS jerk deg | PLI mean | lock frac min | slips | epochs per CPU s |",
          "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in s["rows"]:
        L.append(f"| {r['oscillator']} | {r['cn0_dbhz']:g} | {r['loop']} | {r['vel_err_mean_mps']:+.4f} | "
                 f"{r['vel_err_std_mps']:.4f} | {r['range_err_mean_m']:+.3f} | {r['range_err_std_m']:.3f} | "
                 f"{r['disc_rms_jerk_deg']:.2f} | {r['pli_mean']:.3f} | {r['lock_fraction_min']:.3f} | "
                 f"{r['cycle_slips']} | {r['epochs_per_s']:.0f} |")
    th = s["threshold_search"]
    L += ["", f"C/N0 tracking threshold through the trajectory (lowest C/N0 at which every one "
          f"of {th['trials']} trials keeps lock: PLI > 0.5 in >= 99 % of the 10-ms PLI values "
          f"and no cycle slip; first {th['duration_s']:g} s of the trajectory, which hold the "
          f"whole manoeuvre; bisection between {th['lo_dbhz']:g} and {th['hi_dbhz']:g} dB-Hz "
          f"to {th['resolution_db']:g} dB):", "",
          "| osc | loop | threshold dB-Hz | loses lock at dB-Hz | points run |", "|---|---|---:|---:|---|"]
    for r in s["thresholds"]:
        thv = "none" if r["threshold_dbhz"] is None else f"{r['threshold_dbhz']:g}"
        fl = r.get("fails_at_dbhz")
        pts = ", ".join(f"{c:g}{'+' if v['holds'] else '-'}" for c, v in sorted(r["points"].items()))
        L.append(f"| {r['oscillator']} | {r['loop']} | {thv} | {'' if fl is None else f'{fl:g}'} | {pts} |")
    if s.get("pending"):
        L += ["", "**Not run (pending when this file was written):** " + "; ".join(
            f"{k} {o} {'' if c is None else f'{c:g} dB-Hz '}{lp}" for k, o, c, lp in s["pending"])]
    L += ["", "![discriminator and PLI](ins_fig6_7.png)", ""]
    return "\n".join(L) + "\n"
