"""The TACAN benchmarks: measured figures written to ``results/`` with the machine, date and
command (registered in :data:`cosim.bench.BENCHMARKS`).

``tacan-accuracy``: bearing RMSE and mean error of the end-to-end TACAN chain (IF samples ->
golden front end -> Kalman DSP) versus SNR at 90 and 270 degrees, with the single-pulse
search (``--detector pulse``) and with both searches (``--detector both``, the default);
every bearing 0-359 at 10 dB (single pulses), and at 0 dB with both detectors; the Cramer-Rao bound for the filter's memory; the
pulse-level fast path at 10/15/20 dB over several seeds, looking for 40-degree sector
slips; and the robustness table.

``tacan-robustness``: the robustness table alone (rotation off 15 Hz, a -6 dB echo), with
``--detector pulse`` and with ``--detector both``.

``tacan-detector``: the single-pulse search's options near the noise floor (``--amplitude
partner``, ``--noise-floor censored``) and ``--detector pair``, 0-10 dB, 90 and 270 deg,
and on noise alone.

``tacan-sensitivity``: issue 18's acceptance for ``--detector both`` (both searches in the
FPGA): 0-20 dB at 90 and 270 deg, every bearing at 0 dB, and integrity over 60 s (the
other mode, noise alone).

``tacan-confidence``: issue 18's criterion 2 where it is decided (3 and 4 dB, 90 and 270 deg)
with 32 records per point: RMSE / CRB with a bootstrap interval, the mean error with its
standard error, and the verdict.
"""
from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import numpy as np

from ..bench import machine_info, map_jobs


def _one_run(kw: dict) -> dict:
    from .run import TacanRunConfig, run_tacan
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


def _pool(rows: list, key: str = "rmse_deg") -> dict:
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


def _sweep_0db(step: int, crb: float, jobs, **opts) -> tuple[dict, list]:
    """Every bearing in ``step`` deg steps at 0 dB (2 s records, IF chain) with the run
    options ``opts``: the pooled figures and one row per bearing."""
    b0 = np.arange(0, 360, step, dtype=float)
    what = "".join(f", --{k.replace('_', '-')} {v}" for k, v in opts.items())
    runs = map_jobs(jobs, _one_run, [dict(bearing_deg=float(b), snr_db=0.0, duration_s=2.0,
                                      seed=3000 + int(b), **opts) for b in b0],
                f"bearing sweep (IF, 0 dB{what})")
    rows = [{k: r.get(k) for k in ("bearing_deg", "locked", "rmse_deg", "mean_error_deg",
                                   "max_abs_error_deg", "first_valid_bearing_s", "valid_rmse_deg",
                                   "misleading_bearings")} for r in runs]
    p = _pool(runs)
    locked = [r for r in rows if r["locked"]]
    return ({**p, **opts, "bearings": int(b0.size), "step_deg": step, "duration_s": 2.0,
             "crb_deg": crb,
             "rmse_over_crb": p["rmse_deg"] / crb if p["rmse_deg"] is not None else None,
             "within_2x_crb": int(sum(r["rmse_deg"] <= 2 * crb for r in locked)),
             "sector_slips": int(sum(r["max_abs_error_deg"] > 20 for r in locked))}, rows)


#: Rotation-rate offsets (relative) and echoes of the robustness table (10 dB, golden chain).
ROBUST_ROTATIONS = (0.0, 0.005, -0.005, 0.01, -0.01)
ROBUST_ECHO_PHASES = (0.0, 1.5708, 3.1416)


def _robustness(quick: bool, jobs, **opts) -> list:
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
    runs = map_jobs(jobs, _one_run, items, f"robustness (10 dB{what})")
    rows = []
    for i, (kind, kw, label) in enumerate(cases):
        for j, b in enumerate((90.0, 270.0)):
            rs = runs[(2 * i + j) * seeds:(2 * i + j + 1) * seeds]
            rows.append({"case": label, "kind": kind, "bearing_deg": b, **_pool(rs),
                         "rotation_hz_est": [r.get("rotation_hz") for r in rs]})
    return rows


def _snr_rows(runs: list, snrs, crbs: dict) -> list:
    """One row per SNR and bearing (90, 270 deg) of the SNR sweep ``runs``: pooled figures,
    the bound and RMSE / CRB."""
    rows = []
    for s in snrs:
        for b in (90.0, 270.0):
            rs = [r for r in runs if r["snr_db"] == s and r["bearing_deg"] == b]
            row = {"snr_db": s, "bearing_deg": b, **_pool(rs), "crb_deg": crbs[s],
                   "gated": int(sum(r["gated"] for r in rs)),
                   "reinit": int(sum(r["reinit"] for r in rs))}
            row["rmse_over_crb"] = row["rmse_deg"] / crbs[s] if row["rmse_deg"] is not None \
                else None
            rows.append(row)
    return rows


def tacan_accuracy(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    """The receiver's accuracy with the single-pulse search (``--detector pulse``, the default
    until 2026-12-05) and with both searches (``--detector both``, the default): SNR -3..20
    dB at 90 / 270 deg, every bearing at 0 dB; with single pulses also every bearing at 10
    dB, the pulse-level fast path and the robustness table (``tacan-robustness`` has both)."""
    from dsp.tacan.kalman_config import KalmanConfig
    from dsp.tacan.bounds import crb_deg
    from dsp.tacan.receiver import ReceiverConfig, bearing_stats, process_peaks
    from .detector import detector_bounds
    from .signal import TacanSignalConfig, pulse_observations

    t_start = time.perf_counter()
    snrs = [-3, 0, 3, 10, 20] if quick else [-3, 0, 2, 3, 4] + list(range(6, 21, 2))
    duration = 2.0 if quick else 3.0
    kc = KalmanConfig()
    crbs = {s: crb_deg(TacanSignalConfig(snr_db=float(s)).matched_filter_rel_sigma(), 0.21, 0.21,
                       kc.n_eff) for s in snrs}
    # single pulses: 2 records per point (seeds 100-101); both searches (the default): 4
    # (seeds 100-103; tacan-sensitivity has 8 at fewer SNRs)
    sweeps = {}
    for det, trials in (("pulse", 1 if quick else 2), ("both", 1 if quick else 4)):
        items = [dict(bearing_deg=b, snr_db=float(s), duration_s=duration, seed=100 + k,
                      detector=det) for s in snrs for b in (90.0, 270.0) for k in range(trials)]
        sweeps[det] = _snr_rows(map_jobs(jobs, _one_run, items, f"SNR sweep (--detector {det})"),
                                snrs, crbs)
    # what the single-pulse search's output allows at each SNR (dsp.tacan.bounds)
    ops = map_jobs(jobs, _operating_point, [dict(snr_db=float(s), noise_floor="clipped")
                                            for s in snrs], "detector operating points")
    for row in sweeps["pulse"]:
        op = ops[snrs.index(row["snr_db"])]
        bounds = detector_bounds(op, 0.21, 0.21, kc.n_eff)
        row.update(detection_bound_deg=bounds["bound_both_deg"],
                   amplitude_bound_deg=bounds["bound_marks_deg"])

    step = 15 if quick else 2
    bearings = np.arange(0, 360, step, dtype=float)
    sweep_items = [dict(bearing_deg=float(b), snr_db=10.0, duration_s=1.6, seed=1000 + int(b),
                        detector="pulse") for b in bearings]
    sweep = map_jobs(jobs, _one_run, sweep_items, "bearing sweep (IF, 10 dB)")
    brg_rows = [{"bearing_deg": r["bearing_deg"], "locked": r["locked"], "rmse_deg": r["rmse_deg"],
                 "mean_error_deg": r["mean_error_deg"], "max_abs_error_deg": r["max_abs_error_deg"]}
                for r in sweep]
    locked = [r for r in brg_rows if r["locked"]]

    # 0 dB, every bearing in 2 deg steps: a bearing, no sector slip, RMSE within 2x the bound
    crb0 = crb_deg(TacanSignalConfig(snr_db=0.0).matched_filter_rel_sigma(), 0.21, 0.21, kc.n_eff)
    sweep_0db, rows0 = _sweep_0db(30 if quick else 2, crb0, jobs, detector="pulse")
    sweep_0db_both, rows0_both = _sweep_0db(30 if quick else 2, crb0, jobs, detector="both")
    robust = _robustness(quick, jobs, detector="pulse")

    # Pulse-level fast path: all bearings as one batch per SNR and seed.
    pl_rows = []
    for snr in (10.0, 15.0, 20.0):
        worst, rm = 0.0, []
        for seed in range(2 if quick else 5):
            cfg = TacanSignalConfig(snr_db=snr, duration_s=2.0, seed=seed)
            t, amps, _ = pulse_observations(cfg, bearings)
            tr = process_peaks(t, amps, ReceiverConfig(kalman=kc))
            st = bearing_stats(tr, bearings, 2 * kc.memory_s)
            worst = max(worst, float(np.max(st["max_abs_error_deg"])))
            rm.append(st["rmse_deg"])
        rm = np.concatenate(rm)
        pl_rows.append({"snr_db": snr, "bearings": int(bearings.size), "seeds": 2 if quick else 5,
                        "rmse_deg": float(np.sqrt(np.mean(rm ** 2))), "max_abs_error_deg": worst,
                        "crb_deg": crb_deg(cfg.matched_filter_rel_sigma(), cfg.mod_15, cfg.mod_135,
                                           kc.n_eff)})

    worst_if = max(r["max_abs_error_deg"] for r in locked) if locked else None
    summary = {
        "benchmark": "tacan-accuracy", "machine": machine_info(), "quick": quick,
        "elapsed_s": time.perf_counter() - t_start,
        "scenario": {"mode": "X", "mod_15": 0.21, "mod_135": 0.21, "fs_hz": 20e6, "if_hz": 63e6,
                     "adc_bits": 12, "backend": "golden", "kalman_memory_s": kc.memory_s,
                     "settle_s": 2 * kc.memory_s, "detector": "pulse"},
        "snr_sweep": sweeps["pulse"],
        "snr_sweep_both": sweeps["both"],
        "bearing_sweep_if_10db": {"bearings": int(bearings.size), "locked": len(locked), "duration_s": 1.6,
                                  "rmse_deg": float(np.sqrt(np.mean([r["rmse_deg"] ** 2 for r in locked]))) if locked else None,
                                  "max_abs_error_deg": worst_if,
                                  "sector_slips": int(sum(r["max_abs_error_deg"] > 20 for r in locked))},
        "bearing_sweep_pulse_level": pl_rows,
        "bearing_sweep_if_0db": sweep_0db,
        "bearing_sweep_if_0db_both": sweep_0db_both,
        "robustness_10db": robust,
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "tacan_accuracy.json").write_text(json.dumps({**summary, "bearing_sweep_rows": brg_rows,
                                                         "bearing_sweep_0db_rows": rows0,
                                                         "bearing_sweep_0db_both_rows": rows0_both},
                                                        indent=1))
    with open(out / "tacan_accuracy_snr.csv", "w", newline="") as f:
        rows = [{"detector": d, **r} for d in ("pulse", "both") for r in sweeps[d]]
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with open(out / "tacan_accuracy_bearings.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(brg_rows[0]))
        w.writeheader()
        w.writerows(brg_rows)
    _plot_accuracy(out / "tacan_accuracy.png", sweeps["pulse"], brg_rows, sweeps["both"])
    (out / "tacan_accuracy.md").write_text(_accuracy_markdown(summary))
    return summary


def _plot_accuracy(path: Path, snr_rows, brg_rows, both_rows=()):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    for b, mk in ((90.0, "o-"), (270.0, "s-")):
        rs = [r for r in snr_rows if r["bearing_deg"] == b and r["rmse_deg"] is not None]
        a1.semilogy([r["snr_db"] for r in rs], [r["rmse_deg"] for r in rs], mk, label=f"RMSE, {b:g} deg")
        a1.semilogy([r["snr_db"] for r in rs], [abs(r["mean_error_deg"]) for r in rs], mk,
                    alpha=0.4, label=f"|mean error|, {b:g} deg")
    for b, mk in ((90.0, "x:"), (270.0, "+:")):
        rs = [r for r in both_rows if r["bearing_deg"] == b and r["rmse_deg"] is not None]
        if rs:
            a1.semilogy([r["snr_db"] for r in rs], [r["rmse_deg"] for r in rs], mk,
                        label=f"RMSE, {b:g} deg, --detector both")
    rs = [r for r in snr_rows if r["bearing_deg"] == 90.0]
    a1.semilogy([r["snr_db"] for r in rs], [r["crb_deg"] for r in rs], "k--", label="Cramer-Rao bound")
    if all("amplitude_bound_deg" in r for r in rs):
        a1.semilogy([r["snr_db"] for r in rs], [r["amplitude_bound_deg"] for r in rs], "k:",
                    label="bound of an amplitude fit (single-pulse search output)")
    a1.axhline(0.61, color="r", ls=":", label="seed hardware, 10 dB (0.61)")
    a1.set_xlabel("SNR (dB, peak pulse power / noise in 2 MHz)")
    a1.set_ylabel("bearing error (deg)")
    a1.set_title("TACAN X mode, A = B = 0.21, golden chain")
    a1.grid(True, which="both", alpha=0.3)
    a1.legend(fontsize=7)
    brg_rows = [r for r in brg_rows if r["locked"]]
    a2.plot([r["bearing_deg"] for r in brg_rows], [r["rmse_deg"] for r in brg_rows], ".", label="RMSE")
    a2.plot([r["bearing_deg"] for r in brg_rows], [r["max_abs_error_deg"] for r in brg_rows], ".",
            alpha=0.5, label="max |error|")
    a2.set_xlabel("true bearing (deg)")
    a2.set_ylabel("error (deg)")
    a2.set_title("every bearing at 10 dB (a sector slip would be 40 deg)")
    a2.grid(True, alpha=0.3)
    a2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _snr_table(rows, bounds: bool = False) -> list:
    f = lambda v, fmt: "-" if v is None else format(v, fmt)
    out = ["| SNR dB | bearing | locked | RMSE deg | mean err deg | max err deg | CRB deg | RMSE/CRB "
           "| first valid bearing s (median) | valid-only RMSE deg | misleading |"
           + (" bounds / CRB: detections, amplitudes |" if bounds else ""),
           "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|" + ("---:|" if bounds else "")]
    for r in rows:
        out.append(f"| {r['snr_db']:g} | {r['bearing_deg']:g} | {r['locked']}/{r['trials']} | "
                   f"{f(r['rmse_deg'], '.3f')} | {f(r['mean_error_deg'], '+.3f')} | "
                   f"{f(r['max_abs_error_deg'], '.3f')} | {r['crb_deg']:.3f} | "
                   f"{f(r['rmse_over_crb'], '.2f')} | {f(r['first_valid_bearing_s'], '.2f')} | "
                   f"{f(r.get('valid_rmse_deg'), '.3f')} | {r.get('misleading_bearings', '-')} |"
                   + (f" {r['detection_bound_deg'] / r['crb_deg']:.2f}, "
                      f"{r['amplitude_bound_deg'] / r['crb_deg']:.2f} |" if bounds else ""))
    return out


def _accuracy_markdown(s: dict) -> str:
    m = s["machine"]
    f = lambda v, fmt: "-" if v is None else format(v, fmt)
    lines = [f"TACAN bearing accuracy, golden chain (`{m['command']}`, {m['date']}, {m['cpu']}, "
             f"commit {m['commit']}, {s['elapsed_s']:.0f} s)", "",
             "The single-pulse search alone (`--detector pulse`, the default until "
             "2026-12-05):", ""] + _snr_table(s["snr_sweep"], bounds=True)
    lines += ["", "Bounds: what the single-pulse search's output allows (`dsp.tacan.bounds`, "
              "operating point measured per SNR by `cosim.tacan.detector`): a DSP using the "
              "detections' times and amplitudes, and one fitting the detected amplitudes only "
              "(ours)."]
    if s.get("snr_sweep_both"):
        lines += ["", "Both searches (`--detector both`, the default: the single-pulse and the "
                  "pulse-pair searches in the FPGA; references decoded on the pulses, the bearing "
                  "measured on the pairs with their bias model):", ""] \
            + _snr_table(s["snr_sweep_both"])
    b = s["bearing_sweep_if_10db"]
    lines += ["", f"Every bearing 0-359 deg in {360 // b['bearings']} deg steps at 10 dB, single "
              f"pulses (IF chain, "
              f"{b['duration_s']:g} s each, {b['locked']}/{b['bearings']} locked): "
              f"RMSE {f(b['rmse_deg'], '.3f')} deg, worst error {f(b['max_abs_error_deg'], '.3f')} deg, "
              f"sector slips {b['sector_slips']}.", "",
              "| pulse-level, SNR dB | bearings x seeds | RMSE deg | worst error deg | CRB deg |",
              "|---:|---:|---:|---:|---:|"]
    for r in s["bearing_sweep_pulse_level"]:
        lines.append(f"| {r['snr_db']:g} | {r['bearings']} x {r['seeds']} | {r['rmse_deg']:.3f} | "
                     f"{r['max_abs_error_deg']:.3f} | {r['crb_deg']:.3f} |")
    for key, what in (("bearing_sweep_if_0db", " with `--detector pulse`"),
                      ("bearing_sweep_if_0db_both", " with `--detector both`")):
        z = s.get(key)
        if z is None:
            continue
        lines += ["", f"Every bearing 0-359 deg in {z['step_deg']} deg steps at 0 dB{what} "
                  f"(IF chain, {z['duration_s']:g} s each): a bearing at "
                  f"{z['locked']}/{z['bearings']}, RMSE {f(z['rmse_deg'], '.3f')} deg "
                  f"({f(z['rmse_over_crb'], '.2f')} x the bound {z['crb_deg']:.3f}), within 2x "
                  f"the bound at {z['within_2x_crb']}, mean error "
                  f"{f(z['mean_error_deg'], '+.3f')} deg, worst "
                  f"{f(z['max_abs_error_deg'], '.3f')} deg, sector slips {z['sector_slips']}, "
                  f"first valid bearing (median) {f(z['first_valid_bearing_s'], '.2f')} s; the "
                  f"bearings shown valid: RMSE {f(z.get('valid_rmse_deg'), '.3f')} deg, "
                  f"misleading (valid, > 20 deg off) {z.get('misleading_bearings', '-')}."]
    if s.get("robustness_10db"):
        lines += _robustness_markdown(s["robustness_10db"], ", `--detector pulse`")
    return "\n".join(lines) + "\n"


def _robustness_markdown(rows, what: str = "") -> list:
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
    """The robustness table of ``tacan-accuracy`` alone (rotation off 15 Hz, echo), and the
    same with ``--detector both``."""
    t_start = time.perf_counter()
    rows = _robustness(quick, jobs, detector="pulse")
    rows_both = _robustness(quick, jobs, detector="both")
    summary = {"benchmark": "tacan-robustness", "machine": machine_info(), "quick": quick,
               "elapsed_s": time.perf_counter() - t_start, "robustness_10db": rows,
               "robustness_10db_both": rows_both}
    out.mkdir(parents=True, exist_ok=True)
    (out / "tacan_robustness.json").write_text(json.dumps(summary, indent=1))
    m = summary["machine"]
    head = [f"TACAN bearing robustness, golden chain (`{m['command']}`, {m['date']}, {m['cpu']}, "
            f"commit {m['commit']}, {summary['elapsed_s']:.0f} s)"]
    both = ["", "With `--detector both` (both searches in the FPGA):"] \
        + _robustness_markdown(rows_both)[1:]
    (out / "tacan_robustness.md").write_text("\n".join(head + _robustness_markdown(
        rows, ", `--detector pulse`") + both)
                                             + "\n")
    return summary


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
    runs = map_jobs(jobs, _one_run, items, "detector variants")
    floors = ("clipped", "censored")
    ops = map_jobs(jobs, _operating_point, [dict(snr_db=s, noise_floor=f)
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
                p = _pool(runs[i:i + n])
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
    from .run import TacanRunConfig
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


def _operating_point(kw: dict) -> dict:
    from .detector import operating_point
    from .run import TacanRunConfig
    from .signal import TacanSignalConfig
    sig = TacanSignalConfig(bearing_deg=90.0, duration_s=1.0, seed=100, snr_db=kw["snr_db"])
    return operating_point(TacanRunConfig(signal=sig, noise_floor=kw["noise_floor"], settle_s=0.5,
                                          detector="pulse"))


def _other_mode(kw: dict) -> dict:
    """Integrity: a beacon of mode ``beacon`` (or noise alone, ``beacon=None``: a beacon 60
    dB under the noise) heard by a receiver of mode ``rx`` with ``detector`` (golden chain,
    90 deg, seed 5): the references it decodes and the bearings it shows valid."""
    from dataclasses import replace
    from .run import TacanRunConfig, _golden, run_dsp
    from .signal import TacanSignalConfig, generate
    beacon, rx = kw["beacon"], kw["rx"]
    sig = TacanSignalConfig(mode=beacon or rx, bearing_deg=90.0, duration_s=kw["duration_s"],
                            seed=5, snr_db=kw["snr_db"] if beacon else -60.0)
    run = TacanRunConfig(signal=replace(sig, mode=rx), detector=kw["detector"],
                         require_bearing=False)
    fo = _golden(generate(sig).samples, run)
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
    runs = map_jobs(jobs, _one_run, [dict(bearing_deg=b, snr_db=s, duration_s=3.0, seed=k,
                                      detector=det)
                                 for s in snrs for b in (90.0, 270.0) for k in seeds],
                f"SNR sweep (--detector {det})")
    kc = KalmanConfig()
    crbs = {s: crb_deg(TacanSignalConfig(snr_db=s).matched_filter_rel_sigma(), 0.21, 0.21,
                       kc.n_eff) for s in snrs}
    rows = _snr_rows(runs, snrs, crbs)
    crb0 = crb_deg(TacanSignalConfig(snr_db=0.0).matched_filter_rel_sigma(), 0.21, 0.21, kc.n_eff)
    sweep0, rows0 = _sweep_0db(30 if quick else 2, crb0, jobs, detector=det)
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


#: Issue 18's criterion 2 at 90 and 270 deg: RMSE <= 1.5 x the bound, |mean error| <= 0.1 deg
CRITERION_RMSE_OVER_CRB, CRITERION_MEAN_DEG = 1.5, 0.1


def tacan_confidence(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    """Issue 18's criterion 2 where it is decided: 3 and 4 dB, 90 and 270 deg, the default
    detector, 32 records of 3 s each (golden chain, seeds 100-131). The 4-record
    (``tacan-accuracy``) and 8-record (``tacan-sensitivity``) benches put 3-4 dB at 90 deg on
    either side of 1.5 (1.56 / 1.65x and 1.49 / 1.45x): their records' noise, not the
    receiver. Reported: RMSE / CRB with a 95 % bootstrap interval over the records, the mean
    error with its standard error, and whether each point meets the criterion (RMSE / CRB
    <= 1.5 and |mean| <= 0.1 deg; the interval says how firmly)."""
    from dsp.tacan.kalman_config import KalmanConfig
    from dsp.tacan.bounds import crb_deg
    from .signal import TacanSignalConfig
    t_start = time.perf_counter()
    snrs = (3.0,) if quick else (3.0, 4.0)
    seeds = range(100, 102 if quick else 132)
    items = [dict(bearing_deg=b, snr_db=s, duration_s=3.0, seed=k)
             for s in snrs for b in (90.0, 270.0) for k in seeds]
    runs = map_jobs(jobs, _one_run, items, "records")
    kc = KalmanConfig()
    rng = np.random.default_rng(0)
    rows = []
    for s in snrs:
        crb = crb_deg(TacanSignalConfig(snr_db=s).matched_filter_rel_sigma(), 0.21, 0.21, kc.n_eff)
        for b in (90.0, 270.0):
            got = [r for r, it in zip(runs, items) if it["snr_db"] == s and it["bearing_deg"] == b]
            p = _pool(got)          # pooled RMSE and mean error of the locked records
            row = {"snr_db": s, "bearing_deg": b, "records": len(got), "locked": p["locked"],
                   "crb_deg": crb, "rmse_deg": p["rmse_deg"], "mean_error_deg": p["mean_error_deg"],
                   "rmse_over_crb": None, "ci95": None, "mean_error_se_deg": None, "meets": False}
            if p["locked"]:
                ok = [r for r in got if r["locked"] and r["rmse_deg"] is not None]
                ms = np.array([r["rmse_deg"] for r in ok]) ** 2
                me = np.array([r["mean_error_deg"] for r in ok])
                boot = np.sqrt(ms[rng.integers(0, ms.size, (2000, ms.size))].mean(axis=1)) / crb
                ratio = p["rmse_deg"] / crb
                row.update(rmse_over_crb=ratio,
                           ci95=[float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))],
                           mean_error_se_deg=float(me.std(ddof=1) / np.sqrt(me.size))
                           if me.size > 1 else None,
                           meets=bool(p["locked"] == len(got) and ratio <= CRITERION_RMSE_OVER_CRB
                                      and abs(p["mean_error_deg"]) <= CRITERION_MEAN_DEG))
            rows.append(row)
    summary = {"benchmark": "tacan-confidence", "machine": machine_info(), "quick": quick,
               "elapsed_s": time.perf_counter() - t_start, "seeds": [seeds[0], seeds[-1]],
               "criterion": {"rmse_over_crb": CRITERION_RMSE_OVER_CRB,
                             "abs_mean_deg": CRITERION_MEAN_DEG}, "rows": rows}
    out.mkdir(parents=True, exist_ok=True)
    (out / "tacan_confidence.json").write_text(json.dumps(summary, indent=1))
    (out / "tacan_confidence.md").write_text(_confidence_markdown(summary))
    return summary


def _confidence_markdown(s: dict) -> str:
    m, (k0, k1) = s["machine"], s["seeds"]
    f = lambda v, fmt: "-" if v is None else format(v, fmt)
    lines = [f"TACAN criterion 2 with {k1 - k0 + 1} records per point (default detector, both "
             f"searches; golden chain, 3 s, seeds {k0}-{k1}; `{m['command']}`, {m['date']}, "
             f"{m['cpu']}, commit {m['commit']}, {s['elapsed_s']:.0f} s): RMSE of all bearings "
             f"after 1 s over the records, its 95 % bootstrap interval over the records, the "
             f"mean error and its standard error; meets = RMSE / CRB <= "
             f"{s['criterion']['rmse_over_crb']:g} and |mean| <= "
             f"{s['criterion']['abs_mean_deg']:g} deg", "",
             "| SNR dB | bearing | locked | CRB deg | RMSE deg | RMSE / CRB | 95 % interval | "
             "mean error deg | its SE | meets |", "|---:|---:|---:|---:|---:|---:|---|---:|---:|---|"]
    for r in s["rows"]:
        ci = "-" if r["ci95"] is None else f"{r['ci95'][0]:.2f}-{r['ci95'][1]:.2f}"
        lines.append(f"| {r['snr_db']:g} | {r['bearing_deg']:g} | {r['locked']}/{r['records']} | "
                     f"{r['crb_deg']:.3f} | {f(r['rmse_deg'], '.3f')} | "
                     f"{f(r['rmse_over_crb'], '.2f')} | {ci} | {f(r['mean_error_deg'], '+.3f')} | "
                     f"{f(r['mean_error_se_deg'], '.3f')} | {'yes' if r['meets'] else 'no'} |")
    return "\n".join(lines) + "\n"
