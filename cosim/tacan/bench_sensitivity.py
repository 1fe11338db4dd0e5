"""The ``tacan-sensitivity`` benchmark (registered in the TACAN receiver's entry, :mod:`cosim.tacan.receiver`; results
written to ``results/`` with the machine, date and command): issue 18's acceptance for
``--detector both`` (both searches in the FPGA): 0-20 dB at 90 and 270 deg, every bearing at
0 dB, and integrity over 60 s (the other mode, noise alone).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..core.provenance import machine_info, map_jobs
from .bench_runs import one_run, snr_rows, sweep_0db


def _other_mode(kw: dict) -> dict:
    """Integrity: a beacon of mode ``beacon`` (or noise alone, ``beacon=None``: a beacon 60
    dB under the noise) heard by a receiver of mode ``rx`` with ``detector`` (golden chain,
    90 deg, seed 5): the references it decodes and the bearings it shows valid."""
    from dataclasses import replace
    from .config import TacanRunConfig
    from .frontends import golden_frontend
    from .run import run_dsp
    from .signal import TacanSignalConfig, generate
    beacon, rx = kw["beacon"], kw["rx"]
    sig = TacanSignalConfig(mode=beacon or rx, bearing_deg=90.0, duration_s=kw["duration_s"],
                            seed=5, snr_db=kw["snr_db"] if beacon else -60.0)
    run = TacanRunConfig(signal=replace(sig, mode=rx), detector=kw["detector"],
                         require_bearing=False)
    fo = golden_frontend(generate(sig).samples, run)
    tr = run_dsp(fo, run)
    return {**kw, "peaks": int(fo.ticks.size), "main_refs": int(tr.n_main_refs),
            "aux_refs": int(tr.n_aux_refs), "bearings": int(tr.times_s.size),
            "valid_bearings": int(np.count_nonzero(tr.valid)) if tr.valid is not None else 0}


def tacan_sensitivity(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    """Issue 18's acceptance for ``--detector both`` (both searches in the FPGA, the DSP
    decoding on the single pulses and measuring on the pairs): RMSE / CRB, mean error and
    time to the first valid bearing at 90 and 270 deg (golden chain, 3 s records, seeds
    100-107, the tacan-detector bench's records); every bearing at 0 dB (2 s records, the
    tacan-accuracy bench's); and integrity over 60 s: the other mode in both directions and
    noise alone, no bearing shown valid."""
    from dsp.tacan.kalman_config import KalmanConfig
    from dsp.tacan.bounds import crb_deg
    from .signal import TacanSignalConfig
    t_start = time.perf_counter()
    det = "both"
    snrs = (0.0, 3.0, 10.0) if quick else (0.0, 1.0, 2.0, 3.0, 4.0, 6.0, 10.0, 20.0)
    seeds = range(100, 101 if quick else 108)
    runs = map_jobs(jobs, one_run, [dict(bearing_deg=b, snr_db=s, duration_s=3.0, seed=k,
                                      detector=det)
                                 for s in snrs for b in (90.0, 270.0) for k in seeds],
                f"SNR sweep (--detector {det})")
    kc = KalmanConfig()
    crbs = {s: crb_deg(TacanSignalConfig(snr_db=s).matched_filter_rel_sigma(), 0.21, 0.21,
                       kc.n_eff) for s in snrs}
    rows = snr_rows(runs, snrs, crbs)
    crb0 = crb_deg(TacanSignalConfig(snr_db=0.0).matched_filter_rel_sigma(), 0.21, 0.21, kc.n_eff)
    sweep0, rows0 = sweep_0db(30 if quick else 2, crb0, jobs, detector=det)
    dur = 10.0 if quick else 60.0
    cases = [dict(beacon=b, rx=r, snr_db=snr, duration_s=dur, detector=det)
             for b, r in (("X", "Y"), ("Y", "X")) for snr in ((10.0,) if quick else (10.0, 20.0))]
    cases.append(dict(beacon=None, rx="X", snr_db=None, duration_s=dur, detector=det))
    # one 60 s record holds ~8 GB at its peak: at most two at once
    integrity = map_jobs(min(jobs or 2, 2), _other_mode, cases, "integrity (60 s)")
    summary = {"benchmark": "tacan-sensitivity", "machine": machine_info(), "quick": quick,
               "elapsed_s": time.perf_counter() - t_start, "detector": det,
               "seeds": list(seeds), "snr_sweep": rows, "bearing_sweep_if_0db": sweep0,
               "integrity": integrity}
    out.mkdir(parents=True, exist_ok=True)
    (out / "tacan_sensitivity.json").write_text(json.dumps({**summary, "bearing_sweep_0db_rows":
                                                           rows0}, indent=1))
    (out / "tacan_sensitivity.md").write_text(_sensitivity_markdown(summary))
    return summary


def _sensitivity_markdown(s: dict) -> str:
    m, seeds = s["machine"], s["seeds"]
    f = lambda v, fmt: "-" if v is None else format(v, fmt)
    lines = [f"TACAN sensitivity with `--detector {s['detector']}` (both searches in the FPGA; "
             f"golden chain; `{m['command']}`, {m['date']}, {m['cpu']}, commit {m['commit']}, "
             f"{s['elapsed_s']:.0f} s). {len(seeds)} records of 3 s per point (seeds "
             f"{seeds[0]}-{seeds[-1]}); RMSE over the records of all bearings after 1 s; time to "
             f"first valid bearing: median over the records", "",
             "| SNR dB | bearing | CRB deg | RMSE deg | RMSE / CRB | mean error deg | records "
             "with a bearing | first valid bearing s | misleading |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in s["snr_sweep"]:
        lines.append(f"| {r['snr_db']:g} | {r['bearing_deg']:g} | {r['crb_deg']:.3f} | "
                     f"{f(r['rmse_deg'], '.3f')} | {f(r['rmse_over_crb'], '.2f')} | "
                     f"{f(r['mean_error_deg'], '+.3f')} | {r['valid_trials']}/{r['trials']} | "
                     f"{f(r['first_valid_bearing_s'], '.2f')} | {r['misleading_bearings']} |")
    z = s["bearing_sweep_if_0db"]
    lines += ["", f"Every bearing at 0 dB ({z['step_deg']} deg steps, {z['duration_s']:g} s "
              f"records): {z['locked']} of {z['bearings']} give a bearing, {z['within_2x_crb']} "
              f"within 2x the bound ({z['crb_deg']:.3f} deg), {z['sector_slips']} sector slips "
              f"(error > 20 deg), RMSE {f(z['rmse_deg'], '.3f')} deg "
              f"({f(z['rmse_over_crb'], '.2f')}x), of the valid bearings "
              f"{f(z['valid_rmse_deg'], '.3f')} deg, {z['misleading_bearings']} misleading.",
              "", "Integrity (90 deg, seed 5): what a receiver shows for a beacon of the other "
              "mode, and for noise alone", "",
              "| heard | receiver | SNR dB | s | peaks | main refs | aux refs | bearings | "
              "shown valid |", "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in s["integrity"]:
        lines.append(f"| {r['beacon'] or 'noise alone'} | {r['rx']} | {f(r['snr_db'], 'g')} | "
                     f"{r['duration_s']:g} | {r['peaks']} | {r['main_refs']} | {r['aux_refs']} | "
                     f"{r['bearings']} | {r['valid_bearings']} |")
    return "\n".join(lines) + "\n"
