"""Simulation-speed benchmark of the TACAN front end: the three tiers in one run.

``sim-speed`` runs the full front end (DDC -> CIC -> FIR -> envelope -> peak search -> FIFO)
on the same TACAN IF record with

* the Amaranth simulator (``amaranth.sim``, cycle-accurate, Python per clock),
* the exported Verilog compiled with Verilator (cycle-accurate, compiled, driven in batches),
* the exported Verilog in Icarus Verilog driven by cocotb (event-driven, on pysim's cycles),
* the bit-exact numpy/numba model (vectorised, one core),

checks that they agree bit for bit with the model on the part each ran (``simulators``: one
line, ``model == pysim == verilator == icarus``, cycles and wall times), and writes
``results/sim_speed.json`` / ``.md`` (machine, date, command, figures and the ratios, which
are what to compare on a shared machine: they are measured in one run).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..core.provenance import machine_info


def _best(fn, reps: int) -> float:
    best = float("inf")
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def sim_speed(out: Path, quick: bool = False) -> dict:
    from hdl.tacan.model import TacanFrontendModel
    from hdl.tacan.frontend import TacanFrontEnd
    from ..core.link import DspServiceConfig
    from ..backends.pysim import run_stream
    from .config import TacanRunConfig
    from .signal import TacanSignalConfig, generate
    from ..backends.verilator import VerilatorStreamSim
    from ..backends.verilator_harness import verilator_available, verilator_version

    t_start = time.perf_counter()
    n_pysim = 4_000 if quick else 40_000
    n_vl = 2_000_000 if quick else 20_000_000
    n_model = 2_000_000 if quick else 60_000_000
    n_max = max(n_vl, n_model)
    sig = TacanSignalConfig(duration_s=n_max / 20e6 + 1e-3, seed=1)
    run = TacanRunConfig(signal=sig, backend="model", require_bearing=False)
    p = run.hdl_params
    x = generate(sig).samples
    ready = DspServiceConfig().ready_mask(n_max)
    inputs = {"freq": p.nco_freq_word}

    # -- bit-exact model ------------------------------------------------------------------
    m = TacanFrontendModel(p)
    m.run(x[:200_000])                                    # compile / load the kernels
    t_model = _best(lambda: m.run(x[:n_model]), 1 if quick else 2)

    # -- Amaranth simulation ----------------------------------------------------------------
    t0 = time.perf_counter()
    ps = run_stream(TacanFrontEnd(p), x[:n_pysim], out_ready=ready[:n_pysim], n_cycles=n_pysim,
                    inputs=inputs)
    t_pysim = time.perf_counter() - t0

    # -- Verilator ------------------------------------------------------------------------------
    vl = None
    if verilator_available():
        t0 = time.perf_counter()
        sim = VerilatorStreamSim(TacanFrontEnd(p), name="tacan_frontend")
        t_build = time.perf_counter() - t0
        sim.run(x[:100_000], out_ready=ready[:100_000], n_cycles=100_000, inputs=inputs)
        res = {}

        def go():
            res["r"] = sim.run(x[:n_vl], out_ready=ready[:n_vl], n_cycles=n_vl, inputs=inputs)
        t_vl = _best(go, 1 if quick else 2)
        vr = res["r"]
        vl = {"cycles": n_vl, "seconds": t_vl, "cycles_per_s": n_vl / t_vl,
              "build_or_load_s": t_build, "built": bool(sim.built),
              "version": verilator_version()}
    # -- Icarus Verilog (pysim's cycles: it runs at a few 1e3 cycles/s) ----------------------
    from ..backends.icarus import IcarusStreamSim, icarus_available, icarus_version
    ic = None
    if icarus_available():
        t0 = time.perf_counter()
        isim = IcarusStreamSim(TacanFrontEnd(p), name="tacan_frontend")
        t_build = time.perf_counter() - t0
        t0 = time.perf_counter()
        ir = isim.run(x[:n_pysim], out_ready=ready[:n_pysim], n_cycles=n_pysim, inputs=inputs)
        t_ic = time.perf_counter() - t0
        ic = {"cycles": n_pysim, "seconds": t_ic, "cycles_per_s": n_pysim / t_ic,
              "build_or_load_s": t_build, "built": bool(isim.built), "version": icarus_version()}
    # -- agreement on the common part (pysim's cycles) ---------------------------------------
    from .frontends import FRONTENDS
    short = FRONTENDS["model"](x[:n_pysim], run)
    words_model = short.words
    same_pysim = bool(np.array_equal(ps.words, words_model[:len(ps.words)])
                      and np.array_equal(ps.cycles, short.cycles[:len(ps.cycles)]))
    same_ic = None
    if ic is not None:
        same_ic = bool(len(ir.words) == len(ps.words)
                       and np.array_equal(ir.words, words_model[:len(ir.words)])
                       and np.array_equal(ir.cycles, short.cycles[:len(ir.cycles)]))
    same_vl = None
    if vl is not None:
        long_model = FRONTENDS["model"](x[:n_vl], run)
        k = int(np.searchsorted(vr.cycles, n_vl - p.latency - 8 * p.decimation))
        same_vl = bool(np.array_equal(vr.words[:k], long_model.words[:k])
                       and np.array_equal(vr.cycles[:k], long_model.cycles[:k]))

    rows = {"pysim_cycles_per_s": n_pysim / t_pysim,
            "verilator_cycles_per_s": vl["cycles_per_s"] if vl else None,
            "icarus_cycles_per_s": ic["cycles_per_s"] if ic else None,
            "model_samples_per_s": n_model / t_model}
    from ..tools.equivalence import simulators_line
    per = {"model": {"mismatches": 0, "seconds": t_model, "cycles": n_model},
           "pysim": {"mismatches": int(not same_pysim), "seconds": t_pysim, "cycles": n_pysim}}
    if vl is not None:
        per["verilator"] = {"mismatches": int(not same_vl), "seconds": t_vl, "cycles": n_vl}
    if ic is not None:
        per["icarus"] = {"mismatches": int(not same_ic), "seconds": t_ic, "cycles": n_pysim}
    fs = sig.fs_hz
    summary = {
        "benchmark": "sim-speed", "machine": machine_info(), "quick": quick,
        "design": "TACAN front end (hdl.tacan.frontend.TacanFrontEnd, default parameters)",
        "workload": {"pysim_cycles": n_pysim, "verilator_cycles": n_vl,
                     "icarus_cycles": n_pysim, "model_samples": n_model, "fs_hz": fs},
        "speed": rows,
        "real_time": {k: (v / fs if v else None) for k, v in rows.items()},
        "ratios": {
            "verilator_over_pysim": (rows["verilator_cycles_per_s"] / rows["pysim_cycles_per_s"]
                                     if vl else None),
            "model_over_pysim": rows["model_samples_per_s"] / rows["pysim_cycles_per_s"],
            "model_over_verilator": (rows["model_samples_per_s"] / rows["verilator_cycles_per_s"]
                                     if vl else None)},
        "targets": {"verilator_cycles_per_s": 20e6, "verilator_over_pysim": 1000,
                    "model_samples_per_s": 20e6},
        "verilator": vl,
        "icarus": ic,
        "bit_identical": {"pysim_vs_model": same_pysim, "verilator_vs_model": same_vl,
                          "icarus_vs_model": same_ic},
        "simulators": simulators_line(per),
        "elapsed_s": None,
    }
    summary["elapsed_s"] = time.perf_counter() - t_start
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "sim_speed.json").write_text(json.dumps(summary, indent=1))
    (out / "sim_speed.md").write_text(_md(summary))
    return summary


def _md(s: dict) -> str:
    m, r, q, t = s["machine"], s["speed"], s["ratios"], s["targets"]
    f = (lambda v, fmt=",.0f": "-" if v is None else format(v, fmt))
    rt = s["real_time"]
    bi = s["bit_identical"]
    lines = [f"Simulation speed, TACAN front end (`{m['command']}`, {m['date']}, {m['cpu']}, "
             f"commit {m['commit']})", "",
             "| tier | cycles (samples)/s | x real time (20 MS/s) | target |",
             "|---|---:|---:|---:|",
             f"| Amaranth pysim (cycle-accurate) | {f(r['pysim_cycles_per_s'])} | "
             f"{f(rt['pysim_cycles_per_s'], '.2e')} | |",
             f"| Verilator (cycle-accurate, compiled) | {f(r['verilator_cycles_per_s'])} | "
             f"{f(rt['verilator_cycles_per_s'], '.3f')} | {t['verilator_cycles_per_s']:,.0f} |",
             f"| Icarus Verilog + cocotb (cycle-accurate, event-driven) | "
             f"{f(r.get('icarus_cycles_per_s'))} | "
             f"{f(rt.get('icarus_cycles_per_s'), '.2e')} | |",
             f"| bit-exact model (one core) | {f(r['model_samples_per_s'])} | "
             f"{f(rt['model_samples_per_s'], '.2f')} | {t['model_samples_per_s']:,.0f} |", "",
             f"Verilator / pysim: {f(q['verilator_over_pysim'])}x (target 1000x); model / "
             f"pysim: {f(q['model_over_pysim'])}x; model / Verilator: "
             f"{f(q['model_over_verilator'], '.1f')}x. Bit-identical FIFO words: pysim vs "
             f"model {bi['pysim_vs_model']}, Verilator vs model {bi['verilator_vs_model']}, "
             f"Icarus vs model {bi.get('icarus_vs_model')}.", "",
             f"Simulators: {s.get('simulators', '-')}."]
    return "\n".join(lines) + "\n"
