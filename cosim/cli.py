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
    p.add_argument("--backend", default="golden",
                   help="golden | model | pysim | verilator -- front end: float golden model, bit-exact HDL model, Amaranth "
                        "simulation (short runs only) or Verilator")
    p.add_argument("--dsp", default="float", choices=["float", "fixed"],
                   help="arithmetic of the bearing DSP core")
    p.add_argument("--compare", choices=["golden"], default=None,
                   help="also run the golden chain and report vs_golden_rms_deg")
    p.add_argument("--dsp-service", choices=["default", "dma", "undersized"], default="default",
                   help="how the DSP reads the FIFO (preset; the --dsp-* options below "
                        "override its fields): default = 1 ms timer, 256 words; dma; "
                        "undersized = 64 words per 10 ms, too slow for a beacon")
    p.add_argument("--dsp-stall", action="append", default=[], metavar="START:STOP",
                   help="seconds during which the DSP does not read the FIFO (repeatable)")
    p.add_argument("--dsp-period-cycles", type=int, default=None,
                   help="DSP FIFO service period (FPGA clock cycles)")
    p.add_argument("--dsp-latency-cycles", type=int, default=None,
                   help="interrupt latency before the DSP reads (cycles)")
    p.add_argument("--dsp-batch-words", type=int, default=None,
                   help="words the DSP reads per service at most")
    p.add_argument("--dsp-cycles-per-word", type=int, default=None,
                   help="FPGA cycles per word read while servicing")
    p.add_argument("--trace", default=None, metavar="FILE",
                   help="waveform of the cycle-accurate front end (pysim: VCD; verilator: VCD, "
                        "or FST for *.fst); put it under build/")
    p.add_argument("--trace-window", default=None, metavar="START:STOP",
                   help="seconds of the run to dump (verilator; pysim dumps the whole run)")
    p.add_argument("--recheck", choices=["auto", "pysim", "verilator"], default=None,
                   help="with --backend model: re-run the start of the record cycle-accurately "
                        "(auto = Verilator when installed) and compare the FIFO words")
    p.add_argument("--recheck-samples", type=int, default=None,
                   help="ADC samples re-checked (default 1e6 with Verilator, 4e4 with pysim)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_tacan)


def _cmd_tacan(a) -> int:
    from dsp.tacan.kalman import KalmanConfig
    from .link import DSP_PRESETS, DspServiceConfig
    from .tacan import TacanRunConfig, run_tacan
    from .tacan_signal import TacanSignalConfig

    sig = TacanSignalConfig(bearing_deg=a.bearing_deg, snr_db=a.snr_db, duration_s=a.duration_s,
                            seed=a.seed, mode=a.mode, mod_15=a.mod_15, mod_135=a.mod_135,
                            fs_hz=a.fs_hz, if_hz=a.if_hz, adc_bits=a.adc_bits)
    base = DSP_PRESETS[a.dsp_service]
    svc = {f: getattr(base, f) for f in base.__dataclass_fields__}
    svc.update({k: v for k, v in (("period_cycles", a.dsp_period_cycles),
                                  ("latency_cycles", a.dsp_latency_cycles),
                                  ("batch_words", a.dsp_batch_words),
                                  ("cycles_per_word", a.dsp_cycles_per_word)) if v is not None})
    stalls = []
    for text in a.dsp_stall:
        try:
            t0, t1 = (float(v) for v in text.split(":"))
        except ValueError:
            raise ValueError(f"--dsp-stall takes START:STOP in seconds, not {text!r}") from None
        if not (math.isfinite(t0) and math.isfinite(t1) and 0 <= t0 < t1):
            raise ValueError(f"--dsp-stall needs 0 <= START < STOP, not {text!r}")
        stalls.append((int(round(t0 * a.fs_hz)), int(round(t1 * a.fs_hz))))
    svc["stalls"] = tuple(sorted(stalls))
    window = None
    if a.trace_window:
        try:
            w0, w1 = (float(v) for v in a.trace_window.split(":"))
        except ValueError:
            raise ValueError(f"--trace-window takes START:STOP in seconds, not "
                             f"{a.trace_window!r}") from None
        window = (int(round(w0 * a.fs_hz)), int(round(w1 * a.fs_hz)))
    run = TacanRunConfig(signal=sig, backend=a.backend, dsp=a.dsp,
                         kalman=KalmanConfig(memory_s=a.memory_s), settle_s=a.settle_s,
                         service=DspServiceConfig(**svc), compare=a.compare,
                         trace=a.trace, trace_window=window, recheck=a.recheck,
                         recheck_samples=a.recheck_samples)
    r = run_tacan(run)
    rc = 0 if r.get("recheck", {}).get("same_bits", True) else 1
    if a.json:
        print(json.dumps(r))
    else:
        snr = "no noise" if r["snr_db"] is None else f"SNR {r['snr_db']:g} dB"
        print(f"TACAN {r['mode']} mode, {snr}, {r['duration_s']:g} s, front end {r['backend']}, "
              f"{r['dsp']} DSP, seed {r['seed']}")
        print(f"  bearing: true {r['bearing_true_deg']:.3f} deg, estimated {r['bearing_est_deg']:.3f} deg")
        print(f"  after {r['settle_s']:g} s settling ({r['n_bearings']} bearings): RMSE {r['rmse_deg']:.3f} deg, "
              f"mean error {r['mean_error_deg']:+.3f} deg, max {r['max_abs_error_deg']:.3f} deg")
        print(f"  Cramer-Rao bound for the filter's {r['crb_window_s']:g} s memory: {r['crb_deg']:.3f} deg "
              f"(RMSE/CRB {r['rmse_over_crb']:.2f})")
        print(f"  {r['n_peaks']} peaks, {r['n_measurements']} measurements, {r['n_updates']} Kalman updates, "
              f"{r['n_main_refs']} main + {r['n_aux_refs']} aux references, {r['gated']} gated, "
              f"{r['reinit']} re-initialisations, {r['adc_clipped']} ADC samples clipped")
        ev = ", ".join(f"{k} {v}" for k, v in r["dsp_events"].items() if v) or "none"
        print(f"  FIFO: {r['fifo_dropped']} peaks dropped (FPGA counter), "
              f"{r['fifo_dropped_reported']} reported by gap markers; DSP core events: {ev}")
        if "recheck" in r:
            c = r["recheck"]
            print(f"  cycle-accurate re-check ({c['backend']}, first {c['samples']:,} samples, "
                  f"{c['words']} FIFO words): {'same bits' if c['same_bits'] else 'MISMATCH'}")
        if "vs_golden_rms_deg" in r:
            print(f"  vs golden chain on the same samples: RMS bearing difference "
                  f"{r['vs_golden_rms_deg']:.4f} deg over {r['vs_golden_n']} bearings "
                  f"(golden RMSE {r['golden_rmse_deg']:.3f} deg)")
    return rc


def _add_sweep(sub):
    p = sub.add_parser("sweep", help="quantisation sweep: word lengths/modes x SNR x trials, "
                                     "report, word-length proposal and its confirmation")
    p.add_argument("receiver", choices=["tacan"])
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUES",
                   help="swept parameter, e.g. adc_bits=4:14, nco_amp_bits=8,12,16, dsp.P=30:46:4, "
                        "dsp.K.rounding=floor,half_up (repeatable; default adc_bits=4:14)")
    p.add_argument("--snr-db", default="0:20:5", help="SNR values (a:b:step or a list)")
    p.add_argument("--design", choices=["grid", "oat"], default="grid",
                   help="grid: every combination; oat: one parameter at a time (the others "
                        "at their largest value)")
    p.add_argument("--trials", type=int, default=20)
    p.add_argument("--duration-s", type=_finite, default=1.0)
    p.add_argument("--memory-s", type=_finite, default=0.25)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--recheck", type=int, default=2,
                   help="points re-checked on the cycle-accurate backend")
    p.add_argument("--recheck-backend", choices=["auto", "pysim", "verilator"], default="auto",
                   help="auto: Verilator when installed, else the Amaranth simulation")
    p.add_argument("--recheck-samples", type=int, default=None,
                   help="ADC samples re-checked per point (default 1e6 Verilator, 6e4 pysim)")
    p.add_argument("--target", type=_finite, default=0.05,
                   help="proposal target: RMSE within (1 + target) of the float golden")
    p.add_argument("--no-confirm", action="store_true", help="skip the confirming re-run")
    p.add_argument("--out", default="build/studies/sweep")
    p.add_argument("--jobs", type=int, default=None, help="workers (default: all cores)")
    p.add_argument("--scheduler", default="local",
                   help="'local' (process pool), 'dask' (local Dask cluster) or a Dask "
                        "scheduler address")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_sweep)


def _cmd_sweep(a) -> int:
    from .studies.sweep import SweepConfig, parse_param, parse_values, study
    params = tuple(parse_param(t) for t in a.param) or SweepConfig().params
    snrs = tuple(float(v) for v in parse_values(a.snr_db))
    cfg = SweepConfig(params=params, snr_db=snrs, trials=a.trials, duration_s=a.duration_s,
                      memory_s=a.memory_s, seed=a.seed, recheck=a.recheck,
                      recheck_backend=a.recheck_backend,
                      recheck_samples=a.recheck_samples, target_rel=a.target,
                      design=a.design)
    s = study(cfg, a.out, jobs=a.jobs, scheduler=a.scheduler, confirm_proposal=not a.no_confirm,
              progress=not a.json)
    if a.json:
        print(json.dumps({k: s[k] for k in ("proposal", "elapsed_s", "n_points", "rechecks")} |
                         {"confirmed": (s.get("confirmation") or {}).get("confirmed"),
                          "confirmed_params": (s.get("confirmation") or {}).get("params"),
                          "report": f"{a.out}/report.md"}))
    else:
        print(f"{s['n_points']} points in {s['elapsed_s']:.0f} s; report: {a.out}/report.md")
        print(f"proposal: {s['proposal']}")
        if s.get("confirmation"):
            c = s["confirmation"]
            print(f"confirmed: {c['confirmed']}" + (f" with {c['params']}" if c.get("params")
                                                    else ""))
    return 0


def _add_faults(sub):
    p = sub.add_parser("faults", help="bit-error study: flip bits in the ADC samples, FIFO words, "
                                      "the NCO register or the DSP state")
    p.add_argument("receiver", choices=["tacan"])
    p.add_argument("--target", choices=["adc", "fifo", "register", "dsp-state"], default="adc")
    p.add_argument("--ber", default="1e-6:1e-3",
                   help="bit error rates: lo:hi (every decade) or a comma list")
    p.add_argument("--bits", default=None,
                   help="only these bit positions (comma list, 0 = LSB), e.g. the MSBs")
    p.add_argument("--snr-db", type=_finite, default=10.0)
    p.add_argument("--trials", type=int, default=3)
    p.add_argument("--duration-s", type=_finite, default=2.0)
    p.add_argument("--memory-s", type=_finite, default=0.5)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--backend", choices=["model", "pysim", "verilator"], default="model",
                   help="front end for the register target (the others use the model)")
    p.add_argument("--scrub-period-s", type=_finite, default=0.01,
                   help="register target: the DSP rewrites the register this often")
    p.add_argument("--fifo-parity", action="store_true",
                   help="FIFO words carry an even-parity bit, checked by the DSP")
    p.add_argument("--out", default="build/studies/faults")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_faults)


def _cmd_faults(a) -> int:
    from .studies.faults import FaultConfig, parse_ber, report_stem, run_faults
    bits = None
    if a.bits:
        try:
            bits = tuple(int(b) for b in a.bits.split(","))
        except ValueError:
            raise ValueError(f"--bits takes a comma list of bit positions, not {a.bits!r}") from None
    fc = FaultConfig(target=a.target, ber=parse_ber(a.ber), bits=bits, snr_db=a.snr_db,
                     trials=a.trials, duration_s=a.duration_s, memory_s=a.memory_s,
                     seed=a.seed, backend=a.backend, scrub_period_s=a.scrub_period_s,
                     fifo_parity=a.fifo_parity)
    s = run_faults(fc, a.out, progress=not a.json)
    if a.json:
        print(json.dumps({"target": a.target, "rows": s["rows"], "elapsed_s": s["elapsed_s"],
                          "report": f"{a.out}/{report_stem(fc)}.md"},
                         default=str))
    else:
        print(f"{len(s['rows'])} bit error rates x {a.trials} trials in {s['elapsed_s']:.0f} s")
        for r in s["rows"]:
            rm = "-" if r["rmse_deg"] is None else f"{r['rmse_deg']:.3f}"
            mx = "-" if r["max_abs_error_deg"] is None else f"{r['max_abs_error_deg']:.3f}"
            print(f"  BER {r['ber']:g}: {r['flips']} flips, RMSE {rm} deg, worst {mx} deg, "
                  f"NaN {r['nan_bearings']}, exceptions {r['exceptions']}, "
                  f"re-inits {r['reinit']}")
        print(f"report: {a.out}/{report_stem(fc)}.md")
    return 0


def _add_adc_loss(sub):
    # Listed for --help; main() hands the arguments to cosim.studies.adc_loss.main.
    sub.add_parser("adc-loss", help="ADC quantisation loss on a noise-dominated tone: Monte "
                                    "Carlo against theory (1.96 dB at 1 bit, ...); see "
                                    "`python -m cosim adc-loss --help`", add_help=False)


def _add_bench(sub):
    p = sub.add_parser("bench", help="run a benchmark and write its results under results/")
    from .bench import BENCHMARKS
    p.add_argument("name", choices=sorted(BENCHMARKS))
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
    """Every HDL block (default-ish parameters), the TACAN top and the GNSS channel tops (1 and
    12 channels), by Verilog module name."""
    from hdl.cic import Cic
    from hdl.ddc import Ddc
    from hdl.envelope import Envelope
    from hdl.fifo import DspFifo
    from hdl.fir import Fir
    from hdl.gnss.channel import gnss_top
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
        "gnss_channel": lambda: gnss_top(1),
        "gnss_channel_array12": lambda: gnss_top(12),
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
    _add_sweep(sub)
    _add_faults(sub)
    _add_adc_loss(sub)
    _add_bench(sub)
    _add_hdl(sub)
    return p


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    from .bench import source_commit
    source_commit()         # results name the code this run started with
    if argv[:1] == ["adc-loss"]:        # its own parser (python -m cosim.studies.adc_loss)
        from .studies.adc_loss import main as adc_loss_main
        return adc_loss_main(argv[1:])
    parser = build_parser()
    a = parser.parse_args(argv)
    try:
        return a.func(a)
    except (ValueError, RuntimeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
