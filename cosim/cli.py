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


def _add_hdl(sub):
    p = sub.add_parser("check-equivalence",
                       help="run the bit-exact model, Amaranth sim and Verilator on one record "
                            "and count mismatching FIFO words (exit 1 on any)")
    p.add_argument("--top", default="tacan", choices=["tacan"])
    p.add_argument("--samples", type=int, default=20_000, help="ADC samples (20 MS/s)")
    p.add_argument("--backends", default="model,pysim,verilator",
                   help="comma-separated subset of model,pysim,verilator")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--stall", action="store_true",
                   help="DSP ready pattern with long stalls and a 4-word FIFO (drops, markers)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_check_equivalence)

    p = sub.add_parser("verilog", help="export every HDL block and the TACAN top to Verilog "
                                       "and lint them with Verilator")
    p.add_argument("--out", default="build/verilog")
    p.add_argument("--no-lint", action="store_true")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_verilog)

    p = sub.add_parser("synth", help="synthesise and place-and-route a top for ECP5 (YoWASP)")
    p.add_argument("--top", default="tacan", choices=["tacan"])
    p.add_argument("--device", default="LFE5U-85F")
    p.add_argument("--target-mhz", type=_finite, default=100.0)
    p.add_argument("--out", default="build/synth")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--results", default=None,
                   help="also write the figures with machine/date/command to DIR/synth_<top>.json")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_synth)


def _cmd_check_equivalence(a) -> int:
    from .equivalence import check_equivalence
    backends = tuple(b.strip() for b in a.backends.split(",") if b.strip())
    r = check_equivalence(top=a.top, samples=a.samples, backends=backends, seed=a.seed,
                          stall=a.stall)
    if a.json:
        print(json.dumps(r))
    else:
        print(f"{r['top']}: {r['samples']} samples, {r['words']} FIFO words "
              f"({r['peaks']} peaks, {r['markers']} markers, {r['dropped']} dropped), "
              f"backends {', '.join(r['backends'])}: {r['mismatches']} mismatches")
        for name, why in r["skipped"].items():
            print(f"  skipped {name}: {why}")
    return 0 if r["mismatches"] == 0 else 1


def hdl_blocks() -> dict:
    """Every HDL block (default-ish parameters) and the TACAN top, by Verilog module name."""
    from hdl.cic import Cic
    from hdl.ddc import Ddc
    from hdl.envelope import Envelope
    from hdl.fifo import DspFifo
    from hdl.fir import Fir
    from hdl.mixer import Mixer
    from hdl.model.tacan_frontend import TacanFrontendParams
    from hdl.nco import Nco
    from hdl.peak import PeakSearch
    from hdl.tacan_frontend import TacanFrontEnd
    p = TacanFrontendParams()
    return {
        "nco": lambda: Nco(p.ddc.nco),
        "mixer": lambda: Mixer(p.ddc.mixer),
        "ddc": lambda: Ddc(p.ddc),
        "cic": lambda: Cic(p.cic),
        "fir": lambda: Fir(p.fir),
        "envelope": lambda: Envelope(p.envelope),
        "peak": lambda: PeakSearch(p.peak),
        "fifo": lambda: DspFifo(p.fifo),
        "tacan_frontend": lambda: TacanFrontEnd(p),
    }


def _cmd_verilog(a) -> int:
    import shutil
    from .verilog import export_verilog, lint
    out, bad = [], 0
    do_lint = not a.no_lint and shutil.which("verilator") is not None
    for name, make in hdl_blocks().items():
        path = export_verilog(make(), name=name, out_dir=a.out)
        findings = lint(path) if do_lint else None
        bad += len(findings or [])
        out.append({"name": name, "path": str(path), "lint": findings})
    if a.json:
        print(json.dumps({"files": out, "linted": do_lint, "findings": bad}))
    else:
        for f in out:
            state = "not linted" if f["lint"] is None else \
                ("lint clean" if not f["lint"] else f"{len(f['lint'])} lint findings")
            print(f"{f['path']}  ({state})")
            for line in f["lint"] or []:
                print(f"    {line}")
        if not do_lint and not a.no_lint:
            print("verilator not on PATH: files written, not linted")
    return 0 if bad == 0 else 1


def _cmd_synth(a) -> int:
    from hdl.tacan_frontend import TacanFrontEnd
    from .synth import synth
    r = synth(TacanFrontEnd(), name="tacan_frontend", device=a.device,
              target_mhz=a.target_mhz, out_dir=a.out, seed=a.seed)
    short = {"top": a.top, **{k: r[k] for k in ("lut4", "ff", "mult18", "bram", "fmax_mhz")}}
    if a.results:
        from pathlib import Path
        from .bench import machine_info
        Path(a.results).mkdir(parents=True, exist_ok=True)
        rec = {**short, "device": r["device"], "target_mhz": r["target_mhz"],
               "timing_met": r["timing_met"], "seed": a.seed, "machine": machine_info()}
        (Path(a.results) / f"synth_{a.top}.json").write_text(json.dumps(rec, indent=1) + "\n")
    if a.json:
        print(json.dumps(short))
    else:
        print(f"{a.top} on {r['device']}: {r['lut4']} LUT4, {r['ff']} FF, {r['mult18']} MULT18, "
              f"{r['bram']} DP16KD, Fmax {r['fmax_mhz']:.1f} MHz "
              f"(target {r['target_mhz']:g}: {'met' if r['timing_met'] else 'MISSED'})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m cosim",
                                description="FPGA+DSP co-simulation of Kalman-filter navigation receivers")
    sub = p.add_subparsers(dest="command", required=True)
    _add_tacan(sub)
    _add_bench(sub)
    _add_hdl(sub)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    a = parser.parse_args(argv)
    try:
        return a.func(a)
    except (ValueError, RuntimeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
