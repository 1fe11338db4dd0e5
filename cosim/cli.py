"""Command line: ``python -m cosim <command> ...`` (see ``--help``)."""
from __future__ import annotations

import argparse
import json
import math
import sys


def _finite(s: str) -> float:
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {s!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be a finite number, not {s}")
    return v


def _snr(s: str):
    return None if s.lower() in ("none", "inf") else _finite(s)


def _add_tacan(sub):
    p = sub.add_parser("tacan", help="run a TACAN scenario end to end and print the bearing")
    p.add_argument("--bearing-deg", type=_finite, default=90.0)
    p.add_argument("--snr-db", type=_snr, default=10.0, help="dB, or 'none' for no noise")
    p.add_argument("--duration-s", type=_finite, default=3.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--mode", choices=["X", "Y"], default="X")
    p.add_argument("--mod-15", type=_finite, default=0.21, help="15 Hz modulation depth A")
    p.add_argument("--mod-135", type=_finite, default=0.21, help="135 Hz modulation depth B")
    p.add_argument("--fs-hz", type=_finite, default=20e6)
    p.add_argument("--if-hz", type=_finite, default=63e6, help="analog IF, bandpass sampled")
    p.add_argument("--adc-bits", type=int, default=12)
    p.add_argument("--memory-s", type=_finite, default=0.5, help="Kalman filter memory")
    p.add_argument("--settle-s", type=_finite, default=None)
    p.add_argument("--backend", default="golden")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_tacan)


def _cmd_tacan(a) -> int:
    from dsp.tacan.kalman import KalmanConfig
    from .tacan import TacanRunConfig, run_tacan
    from .tacan_signal import TacanSignalConfig

    sig = TacanSignalConfig(bearing_deg=a.bearing_deg, snr_db=a.snr_db, duration_s=a.duration_s,
                            seed=a.seed, mode=a.mode, mod_15=a.mod_15, mod_135=a.mod_135,
                            fs_hz=a.fs_hz, if_hz=a.if_hz, adc_bits=a.adc_bits)
    run = TacanRunConfig(signal=sig, backend=a.backend, kalman=KalmanConfig(memory_s=a.memory_s),
                         settle_s=a.settle_s)
    r = run_tacan(run)
    if a.json:
        print(json.dumps(r))
    else:
        snr = "no noise" if r["snr_db"] is None else f"SNR {r['snr_db']:g} dB"
        print(f"TACAN {r['mode']} mode, {snr}, {r['duration_s']:g} s, backend {r['backend']}, seed {r['seed']}")
        print(f"  bearing: true {r['bearing_true_deg']:.3f} deg, estimated {r['bearing_est_deg']:.3f} deg")
        print(f"  after {r['settle_s']:g} s settling ({r['n_bearings']} bearings): RMSE {r['rmse_deg']:.3f} deg, "
              f"mean error {r['mean_error_deg']:+.3f} deg, max {r['max_abs_error_deg']:.3f} deg")
        print(f"  Cramer-Rao bound for the filter's {r['crb_window_s']:g} s memory: {r['crb_deg']:.3f} deg "
              f"(RMSE/CRB {r['rmse_over_crb']:.2f})")
        print(f"  {r['n_peaks']} peaks, {r['n_measurements']} measurements, {r['n_updates']} Kalman updates, "
              f"{r['n_main_refs']} main + {r['n_aux_refs']} aux references, {r['gated']} gated, "
              f"{r['reinit']} re-initialisations, {r['adc_clipped']} ADC samples clipped")
    return 0


def _add_bench(sub):
    p = sub.add_parser("bench", help="run a benchmark and write its results under results/")
    p.add_argument("name", choices=["tacan-accuracy"])
    p.add_argument("--quick", action="store_true", help="reduced sweep (smoke test)")
    p.add_argument("--out", default="results")
    p.add_argument("--jobs", type=int, default=None, help="worker processes (default: all cores)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench)


def _cmd_bench(a) -> int:
    from . import bench
    summary = bench.run(a.name, out=a.out, quick=a.quick, jobs=a.jobs)
    if a.json:
        print(json.dumps(summary))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m cosim",
                                description="FPGA+DSP co-simulation of Kalman-filter navigation receivers")
    sub = p.add_subparsers(dest="command", required=True)
    _add_tacan(sub)
    _add_bench(sub)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    a = parser.parse_args(argv)
    try:
        return a.func(a)
    except (ValueError, RuntimeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
