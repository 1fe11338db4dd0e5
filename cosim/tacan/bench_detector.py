"""The ``tacan-detector`` benchmark (registered in the TACAN receiver's entry, :mod:`cosim.tacan.receiver`; results
written to ``results/`` with the machine, date and command): the single-pulse search's
options near the noise floor (``--amplitude partner``, ``--noise-floor censored``) and
``--detector pair``, 0-10 dB, 90 and 270 deg, and on noise alone; with the bounds of the
detector's operating points.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..core.provenance import machine_info, map_jobs
from .bench_runs import detector_operating_point, one_run, pool_runs


#: The detector variants of ``tacan-detector``: (label, TacanRunConfig options).
DETECTOR_VARIANTS = (("default (peak, clipped floor)", {"detector": "pulse"}),
                     ("--amplitude partner", {"detector": "pulse", "amplitude": "partner"}),
                     ("--noise-floor censored", {"detector": "pulse", "noise_floor": "censored"}),
                     ("both", {"detector": "pulse", "amplitude": "partner",
                               "noise_floor": "censored"}),
                     ("--detector pair", {"detector": "pair"}))


def tacan_detector(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    """RMSE / CRB and mean error of the detector variants near the noise floor (golden
    chain, 3 s records, the same seeds for every variant)."""
    from dsp.tacan.kalman_config import KalmanConfig
    from dsp.tacan.bounds import crb_deg
    from .detector import detector_bounds
    from .signal import TacanSignalConfig
    t_start = time.perf_counter()
    snrs = (0.0, 3.0) if quick else (0.0, 1.0, 2.0, 3.0, 6.0, 10.0)
    seeds = range(100, 101 if quick else 108)
    items = [dict(bearing_deg=b, snr_db=s, duration_s=3.0, seed=k, **opt)
             for s in snrs for b in (90.0, 270.0) for _, opt in DETECTOR_VARIANTS for k in seeds]
    runs = map_jobs(jobs, one_run, items, "detector variants")
    floors = ("clipped", "censored")
    ops = map_jobs(jobs, detector_operating_point, [dict(snr_db=s, noise_floor=f)
                                        for s in sorted(set(snrs) | {6.0, 10.0})
                                        for f in floors], "detector operating points")
    noise = map_jobs(jobs, _noise_alone, [opt for _, opt in DETECTOR_VARIANTS], "noise alone")
    n = len(seeds)
    kc = KalmanConfig()
    rows, i = [], 0
    for s in snrs:
        crb = crb_deg(TacanSignalConfig(snr_db=s).matched_filter_rel_sigma(), 0.21, 0.21, kc.n_eff)
        for b in (90.0, 270.0):
            for label, opt in DETECTOR_VARIANTS:
                p = pool_runs(runs[i:i + n])
                i += n
                rows.append({"snr_db": s, "bearing_deg": b, "variant": label, **p, "crb_deg": crb,
                             "rmse_over_crb": p["rmse_deg"] / crb if p["rmse_deg"] is not None
                             else None})
    bound_rows = [{**op, **detector_bounds(op, 0.21, 0.21, kc.n_eff)} for op in ops]
    summary = {"benchmark": "tacan-detector", "machine": machine_info(), "quick": quick,
               "elapsed_s": time.perf_counter() - t_start, "seeds": list(seeds), "rows": rows,
               "bounds": bound_rows,
               "noise_alone": [{"variant": label, **r}
                               for (label, _), r in zip(DETECTOR_VARIANTS, noise)]}
    out.mkdir(parents=True, exist_ok=True)
    (out / "tacan_detector.json").write_text(json.dumps(summary, indent=1))
    (out / "tacan_detector.md").write_text(_detector_markdown(summary))
    return summary


def _times(v: float) -> str:
    return f"{v:.2f}x" if v < 10 else f"{v:.0f}x"


def _detector_markdown(summary: dict) -> str:
    rows, seeds, n = summary["rows"], summary["seeds"], len(summary["seeds"])
    m = summary["machine"]
    f = lambda v, fmt: "-" if v is None else format(v, fmt)
    lines = [f"TACAN detector options near the noise floor, golden chain (`{m['command']}`, "
             f"{m['date']}, {m['cpu']}, commit {m['commit']}, {summary['elapsed_s']:.0f} s); "
             f"{n} records of 3 s per point (seeds {seeds[0]}-{seeds[-1]}), RMSE / CRB and mean "
             f"error (deg) of all bearings after 1 s", "",
             "| SNR dB | bearing | CRB deg | " + " | ".join(v for v, _ in DETECTOR_VARIANTS) + " |",
             "|---:|---:|---:|" + "---|" * len(DETECTOR_VARIANTS)]
    for j in range(0, len(rows), len(DETECTOR_VARIANTS)):
        g = rows[j:j + len(DETECTOR_VARIANTS)]
        cells = [f"{f(r['rmse_over_crb'], '.2f')}x, {f(r['mean_error_deg'], '+.2f')}"
                 + ("" if r["locked"] == r["trials"] else f" ({r['locked']}/{r['trials']})")
                 for r in g]
        lines.append(f"| {g[0]['snr_db']:g} | {g[0]['bearing_deg']:g} | {g[0]['crb_deg']:.3f} | "
                     + " | ".join(cells) + " |")
    if summary.get("noise_alone"):
        lines += ["", "On noise alone (a beacon 40 dB under the noise, 4 s, seed 100): the FPGA's "
                  "reports and the DSP's amplitude measurements per second (the pulse detectors' "
                  "noise peaks enter only as pulses of pairs, 12 us apart; the pair detector's "
                  "reports are pairs) and the references decoded:", "",
                  "| variant | reports / s | measurements / s | references |", "|---|---:|---:|---:|"]
        for r in summary["noise_alone"]:
            lines.append(f"| {r['variant']} | {r['reports_per_s']:.0f} | "
                         f"{r['measurements_per_s']:.1f} | {r['references']} |")
    lines += ["", "What the detector's output allows (`dsp.tacan.bounds`, `cosim.tacan.detector`): its "
              "operating point measured on a 1 s record at 90 deg (seed 100) and the bounds of a DSP "
              "using the detections' times and amplitudes (both), their number only (rate) or the "
              "amplitudes of the detected pulses (marks: any DSP fitting the peak amplitudes, the "
              "default's; `--amplitude partner` reads another observation, not covered), over the "
              "Cramer-Rao bound:", "",
              "| SNR dB | noise floor | threshold / sigma | noise peaks / pulse | pulses detected "
              "(model) | bound: both | rate | marks |", "|---:|---|---:|---:|---:|---:|---:|---:|"]
    for b in summary["bounds"]:
        c = b["crb_deg"]
        lines.append(f"| {b['snr_db']:g} | {b['noise_floor']} | {b['threshold_sigma']:.2f} | "
                     f"{b['false_peaks_per_pulse']:.3f} | {b['detected_fraction']:.3f} "
                     f"({b['model_detected_fraction']:.3f}) | {b['bound_both_deg'] / c:.2f}x | "
                     f"{_times(b['bound_rate_deg'] / c)} | {b['bound_marks_deg'] / c:.2f}x |")
    return "\n".join(lines) + "\n"


def _noise_alone(opt: dict) -> dict:
    """A detector variant on noise alone (a beacon 40 dB under the noise, 4 s): what the FPGA
    reports per second and what the DSP takes as amplitude measurements (the decoder's
    pulses of pairs; with ``--detector pair`` every report's two pulses)."""
    from dsp.tacan.decode import DecoderConfig, decode
    from dsp.tacan.frontend import run_golden_frontend
    from dsp.tacan.receiver import expand_pairs
    from .config import TacanRunConfig
    from .signal import TacanSignalConfig, generate
    sig = TacanSignalConfig(bearing_deg=90.0, snr_db=-40.0, duration_s=4.0, seed=100)
    run = TacanRunConfig(signal=sig, require_bearing=False, **opt)
    pk = run_golden_frontend(generate(sig).samples, run.frontend, sig.adc_bits)
    rc = run.receiver
    t = pk.times_s
    if rc.pair_reports:
        t = expand_pairs(t, pk.amplitudes[None, :], rc.mode)[0]
    dec = decode(t, rc.mode, rc.decoder or DecoderConfig(mode=rc.mode))
    return {"reports_per_s": pk.timestamps.size / sig.duration_s,
            "measurements_per_s": int(np.count_nonzero(dec.measurement_mask)) / sig.duration_s,
            "references": int(dec.ref_times_s.size)}
