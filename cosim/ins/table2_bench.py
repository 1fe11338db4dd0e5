"""``python -m cosim bench ins-table2``: the INS paper's Table 2 on the multi-satellite
receiver (:mod:`cosim.ins.table2`) -- the three loops, ``runs`` Monte Carlo runs each
batched as trials of :func:`cosim.gnss.gps_fast.run_fast` (not through the Dask engine of
:mod:`cosim.studies`), the paper's numbers beside ours, the two claims judged per axis, the
lock counts -- written to ``results/ins_table2.json`` / ``.md`` and the error-vs-time plot
``results/ins_table2.png`` (run 0 of each loop, per ECEF axis). ``quick``: a smoke run
(4 runs, 20 s), labelled ``"smoke": true`` in the JSON.
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.provenance import machine_info, write_result
from .table2 import AXES, CLAIMS, LOOPS, PAPER_TABLE2, ChannelAiding, Table2Config, \
    config_record, error_table, judge_claims, lock_counts, run_loop, table2_signal


def table2(cfg: Table2Config) -> tuple[dict, dict]:
    """``(result, series)``: the tables, verdicts and lock counts of ``cfg``; the error
    series (t, (M, runs, 6) per loop) for the plot."""
    sig, cols, info = table2_signal(cfg)
    t0 = time.perf_counter()
    aid = ChannelAiding(sig, cols, cfg.runs, cfg.seed, step_s=cfg.ins_step_s)
    tables, lock, series, walls = {}, {}, {}, {}
    for loop in LOOPS:
        t = time.perf_counter()
        r, err = run_loop(cfg, loop, sig, cols, aid)
        walls[loop] = time.perf_counter() - t
        tables[loop] = error_table(err, r.t_s, cfg.settle_s)
        lock[loop] = lock_counts(r, cfg.settle_s)
        series[loop] = (r.t_s, err)
    return {"config": config_record(cfg), "satellites": info, "tables": tables,
            "paper": PAPER_TABLE2, "axes": AXES, "claims": judge_claims(tables, lock),
            "lock": lock, "wall_s": {**walls, "total": time.perf_counter() - t0}}, series


def ins_table2_bench(out, quick: bool = False) -> dict:
    cfg = Table2Config(runs=4, duration_s=20.0) if quick else Table2Config()
    res, series = table2(cfg)
    res = {"machine": machine_info(), "benchmark": "ins-table2", "smoke": bool(quick), **res}
    out = Path(out)
    write_result(out, "ins_table2", res, _markdown(res))
    _plot(out / "ins_table2.png", series)
    return res


def _plot(path, series):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axs = plt.subplots(2, 3, figsize=(13, 6.5), sharex=True)
    for loop, (t, e) in series.items():
        for i, ax in enumerate(axs.ravel()):
            ax.plot(t, e[:, 0, i], lw=0.8, label=loop)
    for i, ax in enumerate(axs.ravel()):
        ax.set_title(f"{AXES[i]} error ({'m' if i < 3 else 'm/s'})")
        ax.grid(alpha=0.3)
    for ax in axs[1]:
        ax.set_xlabel("time (s)")
    axs[0, 0].legend(fontsize=8)
    fig.suptitle("PVT error on ECEF axes, run 0 of each loop (INS paper trajectory)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _markdown(r: dict) -> str:
    m, c = r["machine"], r["config"]
    L = ["# INS paper Table 2 on the multi-satellite receiver (fast path)", "",
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
    L += ["", "| claim | axis | improvement % | verdict | reason |", "|---|---|---|---|---|"]
    for cl in r["claims"]:
        for a in cl["axes"]:
            L.append(f"| {cl['name']}: {cl['text']} | {a['axis']} | {a['improvement_pct']:.1f} "
                     f"+- {a['se_pct']:.1f} | {a['verdict']} | {a['reason']} |")
    L += ["", "| loop | lock losses | unlocked channel-epochs | fixes missing |", "|---|---|---|---|"]
    for loop in LOOPS:
        k = r["lock"][loop]
        L.append(f"| {loop} | {k['losses']} | {k['unlocked_channel_epochs']} / "
                 f"{k['channel_epochs']} | {k['fixes_missing']} |")
    L += ["", "![errors vs time](ins_table2.png)", ""]
    return "\n".join(L)
