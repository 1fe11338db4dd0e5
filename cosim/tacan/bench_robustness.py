"""The ``tacan-robustness`` benchmark: the bias at 10 dB with the beacon rotating off 15 Hz
and with a -6 dB echo, with ``--detector pulse`` and with ``--detector both``; results written to ``results/`` with the machine, date
and command (registered in the TACAN receiver's entry, :mod:`cosim.tacan.receiver`).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

from ..core.provenance import machine_info, map_jobs
from .bench_runs import one_run, pool_runs


#: Rotation-rate offsets (relative) and echoes of the robustness table (10 dB, golden chain).
ROBUST_ROTATIONS = (0.0, 0.005, -0.005, 0.01, -0.01)
ROBUST_ECHO_PHASES = (0.0, 1.5708, 3.1416)


def robustness_rows(quick: bool, jobs, **opts) -> list:
    """Bias at 10 dB, 90 and 270 deg: beacon rotating 0.5 % and 1 % off 15 Hz, and a -6 dB
    echo 2 us late (same bearing; carrier phases 0, 90, 180 deg), with the run options
    ``opts`` (e.g. ``detector="both"``)."""
    seeds = 1 if quick else 2
    cases = [("rotation", {"rotation_hz": 15.0 * (1 + e)}, f"rotation {100 * e:+.1f} %")
             for e in ROBUST_ROTATIONS]
    cases += [("echo", {"multipath": {"delay_s": 2e-6, "rel_amplitude": 10 ** (-6 / 20),
                                      "phase_rad": ph}},
               f"echo -6 dB, 2 us, phase {round(ph * 57.29578):d} deg")
              for ph in (ROBUST_ECHO_PHASES[:1] if quick else ROBUST_ECHO_PHASES)]
    items = [dict(bearing_deg=b, snr_db=10.0, duration_s=3.0, seed=200 + k, **kw, **opts)
             for _, kw, _ in cases for b in (90.0, 270.0) for k in range(seeds)]
    what = "".join(f", --{k.replace('_', '-')} {v}" for k, v in opts.items())
    runs = map_jobs(jobs, one_run, items, f"robustness (10 dB{what})")
    rows = []
    for i, (kind, kw, label) in enumerate(cases):
        for j, b in enumerate((90.0, 270.0)):
            rs = runs[(2 * i + j) * seeds:(2 * i + j + 1) * seeds]
            rows.append({"case": label, "kind": kind, "bearing_deg": b, **pool_runs(rs),
                         "rotation_hz_est": [r.get("rotation_hz") for r in rs]})
    return rows


def robustness_markdown(rows, what: str = "") -> list:
    f = lambda v, fmt: "-" if v is None else format(v, fmt)
    out = ["", f"Robustness at 10 dB{what} (IF chain, golden, 3 s; the bias is the mean error over "
           "the trials after settling):", "",
           "| case | bearing | locked | mean error deg | RMSE deg | max err deg | rotation estimated Hz |",
           "|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        est = sorted({round(v, 5) for v in r["rotation_hz_est"] if v is not None})
        out.append(f"| {r['case']} | {r['bearing_deg']:g} | {r['locked']}/{r['trials']} | "
                   f"{f(r['mean_error_deg'], '+.3f')} | "
                   f"{f(r['rmse_deg'], '.3f')} | {f(r['max_abs_error_deg'], '.3f')} | "
                   f"{', '.join(format(v, '.5f') for v in est) or '-'} |")
    return out


def tacan_robustness(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    """The robustness table (rotation off 15 Hz, echo) with ``--detector pulse``, and the
    same with ``--detector both``."""
    t_start = time.perf_counter()
    rows = robustness_rows(quick, jobs, detector="pulse")
    rows_both = robustness_rows(quick, jobs, detector="both")
    summary = {"benchmark": "tacan-robustness", "machine": machine_info(), "quick": quick,
               "elapsed_s": time.perf_counter() - t_start, "robustness_10db": rows,
               "robustness_10db_both": rows_both}
    out.mkdir(parents=True, exist_ok=True)
    (out / "tacan_robustness.json").write_text(json.dumps(summary, indent=1))
    m = summary["machine"]
    head = [f"TACAN bearing robustness, golden chain (`{m['command']}`, {m['date']}, {m['cpu']}, "
            f"commit {m['commit']}, {summary['elapsed_s']:.0f} s)"]
    both = ["", "With `--detector both` (both searches in the FPGA):"] \
        + robustness_markdown(rows_both)[1:]
    (out / "tacan_robustness.md").write_text("\n".join(head + robustness_markdown(
        rows, ", `--detector pulse`") + both)
                                             + "\n")
    return summary
