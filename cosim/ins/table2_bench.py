"""``python -m cosim bench ins-table2``: the INS paper's Table 2 on the multi-satellite
receiver (:mod:`cosim.ins.table2`) -- the three loops, ``runs`` Monte Carlo runs each on
the fast path, the paper's numbers beside ours, the two claims judged per axis, the lock
counts; one run of each loop through the bit-exact array model in fixed point on the first
``if_window_s`` of the scenario (:mod:`cosim.ins.table2_if`) checked against the fast
path's runs on the same epochs; the C/N0 tracking threshold of each loop -- written to
``results/ins_table2.json`` / ``.md`` and the error-vs-time plot ``results/ins_table2.png``
(run 0 of each loop, per ECEF axis, with the IF runs). ``quick``: a smoke run (4 runs,
20 s, a 7 s IF window, a coarse threshold search), labelled ``"smoke": true`` in the JSON.

Engine
------
Every run goes through :func:`cosim.studies.engine.run_tasks` (the sweeps' engine: a local
process pool of ``jobs`` workers, a local Dask cluster, or a Dask scheduler's address, whose
workers need this checkout and the IF recording's directory): the Monte Carlo in tasks of
``chunk_runs`` runs (run ``r``'s INS errors from ``(seed, r)``, the trial noise of the task
starting at run ``r0`` from ``(seed, r0, 1)``, the same for the three loops: paired runs,
whatever the number of workers), the three IF runs, and the threshold search's runs.

Resumption
----------
Each finished task's result is kept under ``out_dir/tasks`` keyed by the task and the
code's git trees (``cosim``, ``dsp``, ``hdl``; nothing is kept from uncommitted code): the
same command run again after an interruption takes the finished tasks from there (their
measured wall times with them) and runs the rest; ``tasks_from_cache`` in the result
counts them.

Threshold
---------
Per loop, on the fast path: ``threshold_runs`` runs over the first
``threshold_duration_s`` of the scenario (its high-dynamics segment included) at a C/N0 of
the grid ``threshold_lo_dbhz + i threshold_step_db`` up to ``threshold_hi_dbhz``; the loop
*keeps lock* when the lock detector's phase lock (narrowband PLI over the ``TrackConfig``
windows; its C/N0 criterion off, so that the threshold is the loop's, not the estimator's
30 dB-Hz) holds on every channel at every measurement epoch after ``settle_s`` in every
run and no fix is missing. Both ends are run first; then a bisection on the grid (the
loop's lock taken as monotonic in C/N0). The threshold is the lowest grid C/N0 found to
keep lock, the next lower one found not to (or "<= lo", "> hi").
"""
from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.provenance import machine_info, write_result
from .table2 import AXES, LOOPS, PAPER_TABLE2, ChannelAiding, Table2Config, \
    config_record, error_table, judge_claims, lock_counts, run_loop, table2_signal

__all__ = ["table2", "ins_table2_bench", "BENCH", "QUICK"]

#: The benchmark's configuration: :class:`Table2Config`'s defaults (150 s, 20 runs per loop,
#: a 35 s IF window, a 1 dB threshold search of 4 runs of 40 s).
BENCH = Table2Config()
#: The smoke run's configuration.
QUICK = Table2Config(runs=4, duration_s=20.0, chunk_runs=2, if_window_s=7.0,
                     threshold_runs=1, threshold_duration_s=10.0, threshold_lo_dbhz=26.0,
                     threshold_hi_dbhz=42.0, threshold_step_db=8.0)


def _chunk_seed(seed: int, first: int) -> int:
    return int(np.random.SeedSequence((int(seed), int(first), 1)).generate_state(1)[0])


def _code_version() -> str | None:
    """The git trees of ``cosim``, ``dsp`` and ``hdl`` at HEAD; None when they hold
    uncommitted changes (or there is no git): then nothing is cached."""
    import subprocess
    from ..core.provenance import REPO_ROOT
    try:
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--",
                                "cosim", "dsp", "hdl"], capture_output=True, text=True,
                               cwd=REPO_ROOT, timeout=30)
        trees = subprocess.run(["git", "rev-parse", "HEAD:cosim", "HEAD:dsp", "HEAD:hdl"],
                               capture_output=True, text=True, cwd=REPO_ROOT, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    if dirty.returncode or trees.returncode or dirty.stdout.strip():
        return None
    return " ".join(trees.stdout.split())


def _cached(cache, t):
    """``_task(t)``, kept in ``cache = (directory, code version)`` (module doc) and taken
    from it when the same task of the same code finished before (``"cached": True``)."""
    import hashlib
    import os
    import pickle
    from dataclasses import asdict
    d, ver = cache
    if ver is None:
        return _task(t)
    kind, cfg, loop = t[:3]
    rest = (t[3]["file"], t[3]["prns"]) if kind == "if" else t[3:]
    key = hashlib.sha256(repr((ver, kind, asdict(cfg), loop, rest)).encode()).hexdigest()[:20]
    path = Path(d) / f"{kind}-{loop}-{key}.pkl"
    if path.exists():
        r = pickle.loads(path.read_bytes())
        if kind != "rec" or Path(r["file"]).exists():
            return {**r, "cached": True}
    r = _task(t)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(pickle.dumps(r))
    os.replace(tmp, path)
    return r


def _task(t):
    """One engine task (module doc): ``("mc", cfg, loop, first, n)``, ``("if", cfg, loop,
    recording)`` or ``("thr", cfg, loop, cn0_dbhz)``."""
    kind, cfg, loop = t[:3]
    w = time.perf_counter()
    if kind == "rec":
        from .table2_if import write_if_scenario
        return {**write_if_scenario(cfg, t[3]), "kind": "rec"}
    if kind == "if":
        from .table2_if import run_if_loop
        return {**run_if_loop(cfg, loop, t[3]), "kind": "if"}
    if kind == "mc":
        first, n = t[3], t[4]
    else:
        cfg = replace(cfg, cn0_dbhz=float(t[3]), duration_s=cfg.threshold_duration_s)
        first, n = 0, cfg.threshold_runs
    sig, cols, _ = table2_signal(cfg)
    aid = ChannelAiding(sig, cols, n, cfg.seed, step_s=cfg.ins_step_s, first_run=first)
    r, err = run_loop(cfg, loop, sig, cols, aid, runs=n, seed=_chunk_seed(cfg.seed, first),
                      cn0_min_dbhz=30.0 if kind == "mc" else 0.0)
    lock = lock_counts(r, cfg.settle_s)
    out = {"kind": kind, "loop": loop, "lock": lock, "wall_s": time.perf_counter() - w}
    if kind == "mc":
        out.update(t_s=r.t_s, err=err)
    else:
        out.update(cn0_dbhz=float(t[3]), held=bool(lock["losses"] == 0 and
                                                   lock["unlocked_channel_epochs"] == 0
                                                   and lock["fixes_missing"] == 0))
    return out


def _grid(cfg):
    n = int(math.floor((cfg.threshold_hi_dbhz - cfg.threshold_lo_dbhz)
                       / cfg.threshold_step_db + 1e-9))
    return [cfg.threshold_lo_dbhz + i * cfg.threshold_step_db for i in range(n + 1)]


def table2(cfg: Table2Config, out_dir="build/ins_table2", *, jobs=None,
           scheduler: str = "local", cache: bool = True) -> tuple[dict, dict]:
    """``(result, series)``: the tables, verdicts, lock counts, IF runs and their check,
    thresholds of ``cfg`` (module doc); the error series (t, (M, runs, 6) per loop; the IF
    runs' under ``"if"``) for the plot."""
    from functools import partial
    from ..studies.engine import run_tasks
    from .table2_if import compare_if
    t0 = time.perf_counter()
    fn = partial(_cached, (str(Path(out_dir) / "tasks"), _code_version() if cache else None))
    sig, cols, info = table2_signal(cfg)
    tasks = [("mc", cfg, loop, a, min(cfg.chunk_runs, cfg.runs - a))
             for loop in LOOPS for a in range(0, cfg.runs, cfg.chunk_runs)]
    if cfg.if_window_s > 0:          # the recording first, the IF runs with the next batch
        tasks.append(("rec", cfg, None, str(Path(out_dir) / "if")))
    grid = _grid(cfg)
    state = {loop: [0, len(grid) - 1] for loop in LOOPS}          # grid indices lo, hi
    evals = {loop: {} for loop in LOOPS}
    if cfg.threshold_runs > 0:
        tasks += [("thr", cfg, loop, grid[i]) for loop in LOOPS for i in state[loop]]
    first = run_tasks(fn, tasks, jobs=jobs, scheduler=scheduler)
    n_cached = sum(bool(r.get("cached")) for r in first)
    rec = next((r for r in first if r["kind"] == "rec"), None)
    nxt = [("if", cfg, loop, rec) for loop in LOOPS] if rec is not None else []
    for r in first:
        if r["kind"] == "thr":
            evals[r["loop"]][r["cn0_dbhz"]] = r
    while True:                                    # the bisections, the loops side by side

        for loop in LOOPS if cfg.threshold_runs > 0 else ():
            e = evals[loop]
            while True:
                lo, hi = state[loop]
                if e[grid[lo]]["held"] or not e[grid[hi]]["held"] or hi - lo <= 1:
                    break
                mid = (lo + hi) // 2
                if grid[mid] not in e:
                    nxt.append(("thr", cfg, loop, grid[mid]))
                    break
                state[loop] = [lo, mid] if e[grid[mid]]["held"] else [mid, hi]
        if not nxt:
            break
        got = run_tasks(fn, nxt, jobs=jobs, scheduler=scheduler)
        n_cached += sum(bool(r.get("cached")) for r in got)
        for r in got:
            if r["kind"] == "thr":
                evals[r["loop"]][r["cn0_dbhz"]] = r
            else:
                first.append(r)
        nxt = []
    tables, lock, series, walls = {}, {}, {}, {}
    for loop in LOOPS:
        rs = [r for r in first if r["kind"] == "mc" and r["loop"] == loop]
        err = np.concatenate([r["err"] for r in rs], axis=1)
        t_s = rs[0]["t_s"]
        tables[loop] = error_table(err, t_s, cfg.settle_s)
        lock[loop] = {k: ([x for r in rs for x in r["lock"][k]] if k == "losses_per_run"
                          else sum(r["lock"][k] for r in rs)) for k in rs[0]["lock"]}
        series[loop] = (t_s, err)
        walls[loop] = sum(r["wall_s"] for r in rs)
    out = {"config": config_record(cfg), "satellites": info, "tables": tables,
           "paper": PAPER_TABLE2, "axes": AXES, "claims": judge_claims(tables, lock),
           "lock": lock}
    if rec is not None:
        ifs = {r["loop"]: r for r in first if r["kind"] == "if"}
        out["if_path"] = {
            "what": (f"one run per loop through the bit-exact array model ({cfg.if_window_s:g} s "
                     f"of the scenario from its start, tracked to "
                     f"{next(iter(ifs.values()))['signal_s']:.2f} s; trackers fixed point), "
                     f"against the fast path's {cfg.runs} runs on the same epochs"),
            "window_s": cfg.if_window_s, "recording_wall_s": rec["wall_s"],
            "loops": {loop: {"lock": ifs[loop]["lock"], "assignments": ifs[loop]["assignments"],
                             "aiding_epoch_offset_us": ifs[loop]["aiding_epoch_offset_us"],
                             "wall_s": ifs[loop]["wall_s"], "signal_s": ifs[loop]["signal_s"],
                             "backend": ifs[loop]["backend"], "dsp": ifs[loop]["dsp"],
                             "check": compare_if(ifs[loop], *series[loop], cfg.settle_s),
                             "t_s": [float(x) for x in ifs[loop]["t_s"]],
                             "err": [[None if not np.isfinite(v) else float(v) for v in row]
                                     for row in ifs[loop]["err"]]}
                      for loop in LOOPS}}
        series["if"] = {loop: (ifs[loop]["t_s"], ifs[loop]["err"]) for loop in LOOPS}
        walls.update({f"if {loop}": ifs[loop]["wall_s"] for loop in LOOPS})
    if cfg.threshold_runs > 0:
        out["threshold"] = {loop: _threshold(evals[loop], state[loop], grid) for loop in LOOPS}
        walls["threshold"] = sum(r["wall_s"] for e in evals.values() for r in e.values())
    out["wall_s"] = {**walls, "total": time.perf_counter() - t0}
    out["tasks_from_cache"] = n_cached
    return out, series


def _threshold(e: dict, st, grid) -> dict:
    lo, hi = st
    ev = [{"cn0_dbhz": c, "held": e[c]["held"], "lock": e[c]["lock"]} for c in sorted(e)]
    if e[grid[lo]]["held"]:
        return {"threshold_dbhz": None, "text": f"<= {grid[lo]:g}", "evaluations": ev}
    if not e[grid[hi]]["held"]:
        return {"threshold_dbhz": None, "text": f"> {grid[hi]:g}", "evaluations": ev}
    return {"threshold_dbhz": grid[hi], "text": f"{grid[hi]:g} (not {grid[lo]:g})",
            "evaluations": ev}


def ins_table2_bench(out, quick: bool = False, jobs: int | None = None,
                     scheduler: str = "local") -> dict:
    cfg = QUICK if quick else BENCH
    out = Path(out)
    res, series = table2(cfg, Path("build") / "ins_table2", jobs=jobs, scheduler=scheduler)
    res = {"machine": machine_info(), "benchmark": "ins-table2", "smoke": bool(quick),
           "engine": {"scheduler": scheduler, "jobs": jobs},
           **res}
    write_result(out, "ins_table2", res, _markdown(res))
    _plot(out / "ins_table2.png", series)
    return res


def _plot(path, series):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axs = plt.subplots(2, 3, figsize=(13, 6.5), sharex=True)
    colours = {}
    for loop in LOOPS:
        t, e = series[loop]
        for i, ax in enumerate(axs.ravel()):
            ln, = ax.plot(t, e[:, 0, i], lw=0.8, label=f"{loop} (fast, run 0)")
            colours[loop] = ln.get_color()
    for loop, (t, e) in series.get("if", {}).items():
        for i, ax in enumerate(axs.ravel()):
            ax.plot(t, e[:, i], "o--", ms=3, lw=0.8, color=colours[loop],
                    label=f"{loop} (IF, bit-exact)")
    for i, ax in enumerate(axs.ravel()):
        ax.set_title(f"{AXES[i]} error ({'m' if i < 3 else 'm/s'})")
        ax.grid(alpha=0.3)
    for ax in axs[1]:
        ax.set_xlabel("time (s)")
    axs[0, 0].legend(fontsize=7)
    fig.suptitle("PVT error on ECEF axes, run 0 of each loop on the fast path and the "
                 "bit-exact IF run (INS paper trajectory)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _markdown(r: dict) -> str:
    m, c = r["machine"], r["config"]
    L = ["# INS paper Table 2 on the multi-satellite receiver (fast path, IF path check)", "",
         f"Measured {m['date']} on {m['host']} ({m['cpu']}, {m['cores']} cores, shared), "
         f"commit {m['commit']}, command `{m['command']}`."
         + (" **Smoke run (not the result).**" if r["smoke"] else ""), "",
         f"{c['runs']} runs per loop, {c['duration_s']:g} s, C/N0 {c['cn0_dbhz']:g} dB-Hz, "
         f"Kalman loops' oscillator model {c['oscillator']}, dsp {c['dsp']}, fixes at "
         f"{c['rate_hz']:g} Hz after {c['settle_s']:g} s; satellites "
         f"{', '.join(r['satellites']['prns'])}.", "",
         "| row | " + " | ".join(AXES) + " |", "|---" * (len(AXES) + 1) + "|"]
    for stat in ("mean", "std"):
        for loop in LOOPS:
            t = r["tables"][loop]
            L.append(f"| {stat}, {loop} (ours) | " + " | ".join(
                f"{v:.3f} +- {s:.3f}" for v, s in zip(t[stat], t[f"{stat}_se"])) + " |")
            L.append(f"| {stat}, {loop} (paper) | "
                     + " | ".join(f"{v:.3f}" for v in r["paper"][stat][loop]) + " |")
    L += ["", "| claim | axis | improvement %, all runs | improvement %, runs without a lock "
          "loss of an aided loop | verdict | reason |", "|---|---|---|---|---|---|"]
    for cl in r["claims"]:
        for a in cl["axes"]:
            n0 = a.get("runs_no_loss", a.get("runs"))
            L.append(f"| {cl['name']}: {cl['text']} | {a['axis']} | {a['improvement_pct']:.1f} "
                     f"+- {a['se_pct']:.1f} | {a.get('improvement_pct_no_loss', math.nan):.1f} "
                     f"+- {a.get('se_pct_no_loss', math.nan):.1f} ({n0} runs) | {a['verdict']} "
                     f"| {a['reason']} |")
    L += ["", "| loop | lock losses | runs with a loss | unlocked channel-epochs | fixes missing |",
          "|---|---|---|---|---|"]
    for loop in LOOPS:
        k = r["lock"][loop]
        pr = k.get("losses_per_run", [])
        L.append(f"| {loop} | {k['losses']} | {sum(x > 0 for x in pr)} / {len(pr)} | "
                 f"{k['unlocked_channel_epochs']} / {k['channel_epochs']} | {k['fixes_missing']} |")
    if "if_path" in r:
        ip = r["if_path"]
        L += ["", f"IF path: {ip['what']}; the IF value inside the fast path's distribution "
              f"when |z| <= 3 (z in the runs' standard deviations).", "",
              "| loop | stat | " + " | ".join(AXES) + " | inside | lock losses (IF) |",
              "|---" * (len(AXES) + 4) + "|"]
        for loop in LOOPS:
            q = ip["loops"][loop]
            ch = q["check"]
            for stat in ("mean", "std"):
                L.append(f"| {loop} | {stat}: IF (z) | " + " | ".join(
                    f"{ch['axes'][ax][stat]['if']:.3f} ({ch['axes'][ax][stat]['z']:+.1f})"
                    for ax in AXES) + (f" | {ch['inside']}/{ch['tests']} | "
                                       f"{q['lock']['losses']} |" if stat == "mean" else " | | |"))
                L.append(f"| {loop} | {stat}: fast mean +- sd | " + " | ".join(
                    f"{ch['axes'][ax][stat]['fast_mean']:.3f} +- "
                    f"{ch['axes'][ax][stat]['fast_std']:.3f}" for ax in AXES) + " | | |")
    if "threshold" in r:
        L += ["", f"C/N0 tracking threshold (fast path, {c['threshold_runs']} run(s) of "
              f"{c['threshold_duration_s']:g} s per C/N0, grid {c['threshold_lo_dbhz']:g} .. "
              f"{c['threshold_hi_dbhz']:g} dB-Hz step {c['threshold_step_db']:g} dB; phase lock "
              f"on every channel at every epoch after {c['settle_s']:g} s):", "",
              "| loop | threshold (dB-Hz) | C/N0 run: held |", "|---|---|---|"]
        for loop in LOOPS:
            th = r["threshold"][loop]
            L.append(f"| {loop} | {th['text']} | " + ", ".join(
                f"{e['cn0_dbhz']:g}: {'yes' if e['held'] else 'no'}"
                for e in th["evaluations"]) + " |")
    L += ["", "![errors vs time](ins_table2.png)", ""]
    return "\n".join(L)
