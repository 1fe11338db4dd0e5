"""Command line: ``python -m cosim <command> ...`` (see ``--help``)."""
from __future__ import annotations

import argparse
import math
import sys

from .validate import check_jobs, check_out_dir, check_out_file, dumps, warn

#: Errors a user can cause (bad input, a full disk, a run too big): one line on stderr and
#: exit 2; the traceback only with --debug.
EXPECTED_ERRORS = (ValueError, RuntimeError, OSError, OverflowError, MemoryError)


class _Help(argparse.ArgumentDefaultsHelpFormatter):
    """--help shows every option's default (units are in each help text); an option that
    is unset by default (None, a flag, an empty list) says what unset means in its help."""

    def _get_help_string(self, action):
        text = action.help or ""
        d = action.default
        if "default" in text or d is None or d is False or d == [] or d == argparse.SUPPRESS:
            return text
        return super()._get_help_string(action)


def _parser(sub, name, **kw):
    p = sub.add_parser(name, formatter_class=_Help, **kw)
    p.add_argument("--debug", action="store_true",
                   help="show the traceback of an error instead of one line")
    return p


def _int(s: str) -> int:
    """An integer; also 1e6-style literals that are whole numbers (not 4.5)."""
    try:
        return int(s)
    except ValueError:
        pass
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {s!r}") from None
    if not (math.isfinite(v) and v.is_integer()):
        raise argparse.ArgumentTypeError(f"must be a whole number, not {s}")
    return int(v)


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


def _window(text: str, option: str) -> tuple[float, float]:
    try:
        t0, t1 = (float(v) for v in text.split(":"))
    except ValueError:
        raise ValueError(f"{option} takes START:STOP in seconds, not {text!r}") from None
    if not (math.isfinite(t0) and math.isfinite(t1) and 0 <= t0 < t1):
        raise ValueError(f"{option} needs 0 <= START < STOP, not {text!r}")
    return t0, t1


#: Clock the DSP service presets (``cosim.link.DSP_PRESETS``) are written for.
PRESET_CLK_HZ = 20e6

#: DSP-link options of ``tacan`` (the FIFO between the FPGA and the DSP) and their CLI names.
_LINK_OPTIONS = (("dsp_period_cycles", "--dsp-period-cycles", "period_cycles"),
                 ("dsp_latency_cycles", "--dsp-latency-cycles", "latency_cycles"),
                 ("dsp_batch_words", "--dsp-batch-words", "batch_words"),
                 ("dsp_cycles_per_word", "--dsp-cycles-per-word", "cycles_per_word"))


def _add_tacan(sub):
    p = _parser(sub, "tacan", help="run a TACAN scenario end to end and print the bearing")
    p.add_argument("--bearing-deg", type=_finite, default=90.0,
                   help="true bearing (deg, -360..360)")
    p.add_argument("--snr-db", type=_snr, default=10.0,
                   help="SNR of the pulses (dB, in the 2 MHz noise band), or 'none' for no noise")
    p.add_argument("--duration-s", type=_finite, default=3.0, help="record length (s)")
    p.add_argument("--seed", type=int, default=1, help="random seed (>= 0)")
    p.add_argument("--mode", type=str.upper, choices=["X", "Y"], default="X",
                   help="TACAN channel mode (case-insensitive)")
    p.add_argument("--mod-15", type=_finite, default=0.21,
                   help="15 Hz modulation depth A (fraction, > 0)")
    p.add_argument("--mod-135", type=_finite, default=0.21,
                   help="135 Hz modulation depth B (fraction, > 0, A + B < 1)")
    p.add_argument("--fs-hz", type=_finite, default=20e6,
                   help="ADC sample rate = FPGA clock (Hz); the IF band must sit in one "
                        "Nyquist zone")
    p.add_argument("--if-hz", type=_finite, default=63e6, help="analog IF (Hz), bandpass sampled")
    p.add_argument("--adc-bits", type=int, default=12, help="ADC word length (bits, 1..24)")
    p.add_argument("--memory-s", type=_finite, default=0.5, help="Kalman filter memory (s)")
    p.add_argument("--settle-s", type=_finite, default=None,
                   help="bearings before this time (s) are not scored (default 2 x --memory-s)")
    p.add_argument("--backend", type=str.lower, default="golden",
                   choices=["golden", "model", "pysim", "verilator"],
                   help="front end: float golden model (no FIFO), bit-exact HDL model, Amaranth "
                        "simulation (~3k cycles/s: records of a few 0.01 s) or Verilator")
    p.add_argument("--dsp", type=str.lower, default="float", choices=["float", "fixed"],
                   help="arithmetic of the bearing DSP core")
    p.add_argument("--compare", type=str.lower, choices=["golden"], default=None,
                   help="also run the golden chain and report vs_golden_rms_deg")
    p.add_argument("--dsp-service", type=str.lower, choices=["default", "dma", "undersized"],
                   default=None,
                   help="how the DSP reads the FIFO (preset; the --dsp-* options below "
                        "override its fields): default = 1 ms timer, 256 words; dma; "
                        "undersized = 64 words per 10 ms, too slow for a beacon; the times "
                        "hold at any --fs-hz (HDL backends; default: default)")
    p.add_argument("--dsp-stall", action="append", default=[], metavar="START:STOP",
                   help="seconds during which the DSP does not read the FIFO (repeatable; "
                        "HDL backends)")
    p.add_argument("--dsp-period-cycles", type=_int, default=None,
                   help="DSP FIFO service period (FPGA clock cycles; default from the preset)")
    p.add_argument("--dsp-latency-cycles", type=_int, default=None,
                   help="interrupt latency before the DSP reads (cycles; default from the preset)")
    p.add_argument("--dsp-batch-words", type=_int, default=None,
                   help="words the DSP reads per service at most (default from the preset)")
    p.add_argument("--dsp-cycles-per-word", type=_int, default=None,
                   help="FPGA cycles per word read while servicing (default from the preset)")
    p.add_argument("--trace", default=None, metavar="FILE",
                   help="waveform of the cycle-accurate front end, format from the suffix: "
                        ".vcd (pysim, verilator) or .fst (verilator); put it under build/")
    p.add_argument("--trace-window", default=None, metavar="START:STOP",
                   help="seconds of the run to dump (verilator with --trace; pysim dumps the "
                        "whole run)")
    p.add_argument("--recheck", type=str.lower, choices=["auto", "pysim", "verilator"],
                   default=None,
                   help="with --backend model: re-run the start of the record cycle-accurately "
                        "(auto = Verilator when installed) and compare the FIFO words")
    p.add_argument("--recheck-samples", type=_int, default=None,
                   help="ADC samples re-checked with --recheck (default 1e6 with Verilator, "
                        "4e4 with pysim)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_tacan)


def tacan_run_config(a):
    """The :class:`cosim.tacan.run.TacanRunConfig` of ``tacan`` arguments, every option checked
    against the others before any work starts (an option that cannot affect the run is
    refused, not ignored)."""
    from dsp.tacan.kalman import KalmanConfig
    from .link import DSP_PRESETS, DspServiceConfig
    from .tacan.run import TacanRunConfig
    from .tacan.signal import TacanSignalConfig

    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, not {a.seed}")
    hdl = a.backend != "golden"
    given_link = [opt for attr, opt, _ in _LINK_OPTIONS if getattr(a, attr) is not None]
    if a.dsp_service is not None:
        given_link.insert(0, "--dsp-service")
    if a.dsp_stall:
        given_link.append("--dsp-stall")
    if given_link and not hdl:
        raise ValueError(f"{', '.join(given_link)} set how the DSP reads the FPGA FIFO, but "
                         f"--backend golden has no FIFO: use --backend model, pysim or "
                         f"verilator")
    if a.trace_window is not None and a.trace is None:
        raise ValueError("--trace-window selects what --trace dumps: give --trace FILE too")
    if a.trace_window is not None and a.backend == "pysim":
        raise ValueError("--trace-window works with --backend verilator; pysim dumps the "
                         "whole run")
    if a.recheck_samples is not None and a.recheck is None:
        raise ValueError("--recheck-samples sets how much --recheck re-runs: give --recheck "
                         "too")
    if a.trace is not None:
        if a.backend not in ("pysim", "verilator"):
            raise ValueError(f"--trace needs a cycle-accurate backend (--backend pysim or "
                             f"verilator), not {a.backend}")
        check_out_file(a.trace, "--trace", (".vcd", ".fst"))
        if a.trace.lower().endswith(".fst") and a.backend != "verilator":
            raise ValueError("--trace: FST is written by --backend verilator only; use a "
                             ".vcd file with pysim")
    sig = TacanSignalConfig(bearing_deg=a.bearing_deg, snr_db=a.snr_db, duration_s=a.duration_s,
                            seed=a.seed, mode=a.mode, mod_15=a.mod_15, mod_135=a.mod_135,
                            fs_hz=a.fs_hz, if_hz=a.if_hz, adc_bits=a.adc_bits)
    base = DSP_PRESETS[a.dsp_service or "default"]
    svc = {f: getattr(base, f) for f in base.__dataclass_fields__}
    if a.fs_hz != PRESET_CLK_HZ:
        # the presets are times (1 ms timer, ...) written in cycles of a 20 MHz clock: on
        # another clock they keep their times, not their cycle counts
        k = a.fs_hz / PRESET_CLK_HZ
        for f in ("period_cycles", "latency_cycles", "cycles_per_word"):
            svc[f] = max(1 if f != "latency_cycles" else 0, int(round(svc[f] * k)))
    svc.update({field: getattr(a, attr) for attr, _, field in _LINK_OPTIONS
                if getattr(a, attr) is not None})
    stalls = []
    for text in a.dsp_stall:
        t0, t1 = _window(text, "--dsp-stall")
        if t0 >= a.duration_s:
            raise ValueError(f"--dsp-stall {text} starts after the end of the run "
                             f"(--duration-s {a.duration_s:g}): it would change nothing")
        stalls.append((int(round(t0 * a.fs_hz)), int(round(t1 * a.fs_hz))))
    svc["stalls"] = tuple(sorted(stalls))
    window = None
    if a.trace_window:
        w0, w1 = _window(a.trace_window, "--trace-window")
        if w0 >= a.duration_s:
            raise ValueError(f"--trace-window {a.trace_window} starts after the end of the run "
                             f"(--duration-s {a.duration_s:g})")
        window = (int(round(w0 * a.fs_hz)), int(round(w1 * a.fs_hz)))
    kalman = KalmanConfig(memory_s=a.memory_s)
    settle = 2 * a.memory_s if a.settle_s is None else a.settle_s
    short = a.backend in ("pysim", "verilator") and settle + 0.1 > a.duration_s
    if short:
        warn(f"--duration-s {a.duration_s:g} is shorter than the filter needs to settle "
             f"({settle:g} s + 0.1 s): no bearing is scored; the digests of the peaks and "
             f"FIFO words show the bits")
    return TacanRunConfig(signal=sig, backend=a.backend, dsp=a.dsp, kalman=kalman,
                          settle_s=a.settle_s, service=DspServiceConfig(**svc),
                          compare=a.compare, trace=a.trace, trace_window=window,
                          recheck=a.recheck, recheck_samples=a.recheck_samples,
                          require_bearing=not short)


def _num(v, fmt: str, none: str = "-") -> str:
    return none if v is None else format(v, fmt)


def _cmd_tacan(a) -> int:
    from .tacan.run import check_run_size, run_tacan
    run = tacan_run_config(a)
    check_run_size(run)
    r = run_tacan(run, progress=not a.json)
    rc = 0 if r.get("recheck", {}).get("same_bits", True) else 1
    if rc:
        print(f"error: the cycle-accurate re-check ({r['recheck']['backend']}) gave other FIFO "
              f"bits than the model", file=sys.stderr)
    if a.json:
        print(dumps(r))
    else:
        snr = "no noise" if r["snr_db"] is None else f"SNR {r['snr_db']:g} dB"
        print(f"TACAN {r['mode']} mode, {snr}, {r['duration_s']:g} s, front end {r['backend']}, "
              f"{r['dsp']} DSP, seed {r['seed']}")
        print(f"  bearing: true {r['bearing_true_deg']:.3f} deg, estimated "
              f"{_num(r['bearing_est_deg'], '.3f', 'none')} deg")
        if r["n_bearings"]:
            print(f"  after {r['settle_s']:g} s settling ({r['n_bearings']} bearings): RMSE "
                  f"{r['rmse_deg']:.3f} deg, mean error {r['mean_error_deg']:+.3f} deg, max "
                  f"{r['max_abs_error_deg']:.3f} deg")
            print(f"  Cramer-Rao bound for the filter's {r['crb_window_s']:g} s memory: "
                  f"{_num(r['crb_deg'], '.3f')} deg (RMSE/CRB {_num(r['rmse_over_crb'], '.2f')})")
        else:
            print(f"  no bearing scored (the run ends before the filter has settled, "
                  f"{r['settle_s']:g} s)")
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
                  f"{_num(r['vs_golden_rms_deg'], '.4f')} deg over {r['vs_golden_n']} bearings "
                  f"(golden RMSE {_num(r['golden_rmse_deg'], '.3f')} deg)")
        print(f"  digest: {', '.join(f'{k} {v}' for k, v in r['digest'].items() if v)}")
    return rc


def _add_sweep(sub):
    p = _parser(sub, "sweep", help="quantisation sweep: word lengths/modes x SNR x trials, "
                                   "report, word-length proposal and its confirmation")
    p.add_argument("receiver", type=str.lower, choices=["tacan"], help="receiver")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUES",
                   help="swept parameter, e.g. adc_bits=4:14, nco_amp_bits=8,12,16, dsp.P=30:46:4, "
                        "dsp.K.rounding=floor,half_up (repeatable; default adc_bits=4:14)")
    p.add_argument("--snr-db", default="0:20:5", help="SNR values (dB; a:b:step or a list)")
    p.add_argument("--design", type=str.lower, choices=["grid", "oat"], default="grid",
                   help="grid: every combination; oat: one parameter at a time (the others "
                        "at their largest value)")
    p.add_argument("--trials", type=_int, default=20, help="Monte Carlo records per SNR")
    p.add_argument("--duration-s", type=_finite, default=1.0, help="record length (s)")
    p.add_argument("--memory-s", type=_finite, default=0.25, help="Kalman filter memory (s)")
    p.add_argument("--seed", type=int, default=0, help="base seed (>= 0)")
    p.add_argument("--recheck", type=_int, default=2,
                   help="points re-checked on the cycle-accurate backend (0: none)")
    p.add_argument("--recheck-backend", type=str.lower, choices=["auto", "pysim", "verilator"],
                   default=None,
                   help="auto: Verilator when installed, else the Amaranth simulation "
                        "(default auto)")
    p.add_argument("--recheck-samples", type=_int, default=None,
                   help="ADC samples re-checked per point (default 1e6 Verilator, 6e4 pysim)")
    p.add_argument("--target", type=_finite, default=0.05,
                   help="proposal target: RMSE within (1 + target) of the float golden "
                        "(fraction)")
    p.add_argument("--no-confirm", action="store_true", help="skip the confirming re-run")
    p.add_argument("--out", default="build/studies/sweep", help="output directory")
    p.add_argument("--jobs", type=_int, default=None,
                   help="worker processes, 1 .. the cores (default: all cores)")
    p.add_argument("--scheduler", default="local",
                   help="'local' (process pool), 'dask' (local Dask cluster) or a Dask "
                        "scheduler address")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_sweep)


def _cmd_sweep(a) -> int:
    from .studies.sweep import SweepConfig, check_points, parse_param, parse_values, study
    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, not {a.seed}")
    if a.recheck < 0:
        raise ValueError(f"--recheck must be >= 0 (points re-checked), not {a.recheck}")
    if a.recheck == 0 and (a.recheck_backend is not None or a.recheck_samples is not None):
        raise ValueError("--recheck-backend/--recheck-samples set the re-checks, but "
                         "--recheck 0 runs none")
    params = tuple(parse_param(t) for t in a.param) or SweepConfig().params
    snrs = parse_values(a.snr_db, "--snr-db")
    if not all(isinstance(v, (int, float)) for v in snrs):
        raise ValueError(f"--snr-db takes numbers (dB), not {a.snr_db!r}")
    jobs = check_jobs(a.jobs)
    import re
    if a.scheduler not in ("local", "dask") and not re.fullmatch(
            r"(tcp|tls|inproc|ucx)://[^\s:/]+(:\d+)?|[^\s:/]+:\d+", a.scheduler):
        raise ValueError(f"--scheduler must be local, dask or a Dask scheduler address "
                         f"(tcp://HOST:PORT), not {a.scheduler!r}")
    if a.scheduler not in ("local", "dask") and a.jobs is not None:
        raise ValueError("--jobs sizes the local pool or cluster; a remote Dask scheduler "
                         "(--scheduler ADDRESS) has its own workers")
    check_out_dir(a.out, "--out")
    cfg = SweepConfig(params=params, snr_db=tuple(float(v) for v in snrs), trials=a.trials,
                      duration_s=a.duration_s, memory_s=a.memory_s, seed=a.seed,
                      recheck=a.recheck, recheck_backend=a.recheck_backend or "auto",
                      recheck_samples=a.recheck_samples, target_rel=a.target,
                      design=a.design)
    check_points(cfg)
    s = study(cfg, a.out, jobs=jobs, scheduler=a.scheduler, confirm_proposal=not a.no_confirm,
              progress=not a.json)
    if a.json:
        print(dumps({k: s[k] for k in ("proposal", "elapsed_s", "n_points", "rechecks")} |
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
    bad = [c for c in s.get("rechecks", []) if c.get("same_bits") is False]
    if bad:
        print(f"error: {len(bad)} cycle-accurate re-check(s) gave other FIFO bits than the "
              f"model: {[c['combo'] for c in bad]}", file=sys.stderr)
        return 1
    return 0


def _add_faults(sub):
    p = _parser(sub, "faults", help="bit-error study: flip bits in the ADC samples, FIFO words, "
                                    "the NCO register or the DSP state")
    p.add_argument("receiver", type=str.lower, choices=["tacan"], help="receiver")
    p.add_argument("--target", type=str.lower, choices=["adc", "fifo", "register", "dsp-state"],
                   default="adc", help="where the bits flip")
    p.add_argument("--ber", default="1e-6:1e-3",
                   help="bit error rates (per bit): lo:hi (every decade) or a comma list")
    p.add_argument("--bits", default=None,
                   help="only these bit positions (comma list, 0 = LSB), e.g. the MSBs "
                        "(default: every bit of the target's words)")
    p.add_argument("--snr-db", type=_finite, default=10.0, help="SNR (dB)")
    p.add_argument("--trials", type=_int, default=3, help="records per BER")
    p.add_argument("--duration-s", type=_finite, default=2.0, help="record length (s)")
    p.add_argument("--memory-s", type=_finite, default=0.5, help="Kalman filter memory (s)")
    p.add_argument("--seed", type=int, default=0, help="base seed (>= 0)")
    p.add_argument("--backend", type=str.lower, choices=["model", "pysim", "verilator"],
                   default=None,
                   help="front end of the register target (the others use the model; "
                        "default model)")
    p.add_argument("--scrub-period-s", type=_finite, default=None,
                   help="register target: the DSP rewrites the register this often (s; "
                        "default 0.01)")
    p.add_argument("--fifo-parity", action="store_true",
                   help="fifo target: FIFO words carry an even-parity bit, checked by the DSP")
    p.add_argument("--out", default="build/studies/faults", help="output directory")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_faults)


def _cmd_faults(a) -> int:
    from .studies.faults import FaultConfig, parse_ber, report_stem, run_faults
    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, not {a.seed}")
    if a.target != "register":
        given = [o for o, v in (("--backend", a.backend), ("--scrub-period-s", a.scrub_period_s))
                 if v is not None]
        if given:
            raise ValueError(f"{', '.join(given)} only affect(s) --target register, not "
                             f"--target {a.target}")
    bits = None
    if a.bits:
        try:
            bits = tuple(int(b) for b in a.bits.split(","))
        except ValueError:
            raise ValueError(f"--bits takes a comma list of bit positions, not {a.bits!r}") from None
    check_out_dir(a.out, "--out")
    fc = FaultConfig(target=a.target, ber=parse_ber(a.ber), bits=bits, snr_db=a.snr_db,
                     trials=a.trials, duration_s=a.duration_s, memory_s=a.memory_s,
                     seed=a.seed, backend=a.backend or "model",
                     scrub_period_s=0.01 if a.scrub_period_s is None else a.scrub_period_s,
                     fifo_parity=a.fifo_parity)
    s = run_faults(fc, a.out, progress=not a.json)
    if a.json:
        print(dumps({"target": a.target, "rows": s["rows"], "elapsed_s": s["elapsed_s"],
                     "report": f"{a.out}/{report_stem(fc)}.md"}, default=str))
    else:
        print(f"{len(s['rows'])} bit error rates x {a.trials} trials in {s['elapsed_s']:.0f} s")
        for r in s["rows"]:
            rm = "-" if r["rmse_deg"] is None else f"{r['rmse_deg']:.3f}"
            mx = "-" if r["max_abs_error_deg"] is None else f"{r['max_abs_error_deg']:.3f}"
            print(f"  BER {r['ber']:g}: {r['flips']} flips, RMSE {rm} deg, worst {mx} deg, "
                  f"NaN {r['nan_bearings']}, exceptions {r['exceptions']}, "
                  f"re-inits {r['reinit']}")
        print(f"report: {a.out}/{report_stem(fc)}.md")
    exc = sum(r["exceptions"] for r in s["rows"])
    nan = sum(r["nan_bearings"] for r in s["rows"])
    if exc or nan:
        first = next((r["exception"] for r in s.get("records", []) if r.get("exception")), "")
        print(f"error: the receiver must give no exception and no NaN bearing; got {exc} "
              f"exception(s), {nan} NaN bearing(s)" + (f" (first: {first})" if first else ""),
              file=sys.stderr)
        return 1
    return 0


def _add_adc_loss(sub):
    # Listed for --help; main() hands the arguments to cosim.studies.adc_loss.main.
    sub.add_parser("adc-loss", help="ADC quantisation loss on a noise-dominated tone: Monte "
                                    "Carlo against theory (1.96 dB at 1 bit, ...); see "
                                    "`python -m cosim adc-loss --help`", add_help=False)


#: Benchmarks that spread over worker processes (--jobs); the others measure one core or
#: size their own pool.
_BENCH_JOBS = ("tacan-accuracy",)


def _add_bench(sub):
    p = _parser(sub, "bench", help="run a benchmark and write its results under results/")
    from .bench import BENCHMARKS
    p.add_argument("name", type=str.lower, choices=sorted(BENCHMARKS), help="benchmark")
    p.add_argument("--quick", action="store_true",
                   help="reduced sweep (smoke test); written to build/bench_quick unless "
                        "--out is given, never to results/")
    p.add_argument("--out", default=None,
                   help="output directory (default results, or build/bench_quick with --quick)")
    p.add_argument("--jobs", type=_int, default=None,
                   help=f"worker processes, 1 .. the cores ({', '.join(_BENCH_JOBS)}; default: "
                        f"all cores)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=_cmd_bench)


def _cmd_bench(a) -> int:
    from pathlib import Path
    from . import bench
    out = a.out or ("build/bench_quick" if a.quick else "results")
    if a.quick and Path(out).resolve() == (bench._REPO / "results").resolve():
        raise ValueError("--quick results are a smoke test: they must not overwrite the "
                         "published results/ (use another --out)")
    if a.jobs is not None and a.name not in _BENCH_JOBS:
        raise ValueError(f"--jobs has no effect on bench {a.name} (only on "
                         f"{', '.join(_BENCH_JOBS)})")
    jobs = check_jobs(a.jobs) if a.jobs is not None else None
    check_out_dir(out, "--out")
    summary = bench.run(a.name, out=out, quick=a.quick, jobs=jobs)
    if a.json:
        print(dumps(summary))
    return 0


def _add_hdl(sub):
    p = _parser(sub, "check-equivalence",
                help="run the bit-exact model, Amaranth sim and Verilator on one record "
                     "and count mismatching FIFO words (exit 1 on any, or when fewer than "
                     "two backends compared a non-empty record)")
    p.add_argument("--top", type=str.lower, default="tacan", choices=["tacan"], help="design")
    p.add_argument("--samples", type=_int, default=20_000,
                   help="ADC samples (20 MS/s; pysim runs up to 40000)")
    p.add_argument("--backends", default="model,pysim,verilator",
                   help="comma-separated subset of model,pysim,verilator (at least two)")
    p.add_argument("--seed", type=int, default=1, help="signal seed (>= 0)")
    p.add_argument("--stall", action="store_true",
                   help="DSP ready pattern with long stalls and a 4-word FIFO (drops, markers)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_check_equivalence)

    p = _parser(sub, "verilog", help="export every HDL block and the TACAN top to Verilog "
                                     "and lint them with Verilator")
    p.add_argument("--out", default="build/verilog", help="output directory")
    p.add_argument("--no-lint", action="store_true", help="do not lint")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_verilog)

    p = _parser(sub, "synth", help="synthesise and place-and-route a top for ECP5 (YoWASP)")
    p.add_argument("--top", type=str.lower, default="tacan", choices=["tacan"], help="design")
    p.add_argument("--device", default="LFE5U-85F", help="ECP5 part")
    p.add_argument("--target-mhz", type=_finite, default=100.0, help="clock target (MHz)")
    p.add_argument("--out", default="build/synth", help="output directory")
    p.add_argument("--seed", type=int, default=1, help="nextpnr seed")
    p.add_argument("--results", default=None,
                   help="also write the figures with machine/date/command to DIR/synth_<top>.json")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_synth)


def _cmd_check_equivalence(a) -> int:
    from .equivalence import BACKENDS, check_equivalence, check_record_size
    backends = tuple(b.strip().lower() for b in a.backends.split(",") if b.strip())
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"--backends takes a subset of {','.join(BACKENDS)}, not {unknown}")
    if len(set(backends)) < 2:
        raise ValueError(f"--backends must name at least two backends to compare, not "
                         f"{a.backends!r}")
    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, not {a.seed}")
    check_record_size(a.samples)
    r = check_equivalence(top=a.top, samples=a.samples, backends=backends, seed=a.seed,
                          stall=a.stall, progress=not a.json)
    if a.json:
        print(dumps(r))
    else:
        print(f"{r['top']}: {r['samples']} samples, {r['words']} FIFO words "
              f"({r['peaks']} peaks, {r['markers']} markers, {r['dropped']} dropped), "
              f"backends {', '.join(r['backends'])}: {r['mismatches']} mismatches")
        for c in r["compared"]:
            print(f"  compared {c}")
        for name, why in r["skipped"].items():
            print(f"  skipped {name}: {why}")
    if not r["equivalent"] or r["mismatches"]:
        print(f"error: {r['verdict'] if not r['equivalent'] else str(r['mismatches']) + ' mismatches'}",
              file=sys.stderr)
        return 1
    return 0


def hdl_blocks() -> dict:
    """Every HDL block (default-ish parameters) and the TACAN top, by Verilog module name."""
    from hdl.cic import Cic
    from hdl.ddc import Ddc
    from hdl.envelope import Envelope
    from hdl.fifo import DspFifo
    from hdl.fir import Fir
    from hdl.mixer import Mixer
    from hdl.tacan.model import TacanFrontendParams
    from hdl.nco import Nco
    from hdl.peak import PeakSearch
    from hdl.tacan.frontend import TacanFrontEnd
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
    check_out_dir(a.out, "--out")
    out, bad = [], 0
    do_lint = not a.no_lint and shutil.which("verilator") is not None
    for name, make in hdl_blocks().items():
        path = export_verilog(make(), name=name, out_dir=a.out)
        findings = lint(path) if do_lint else None
        bad += len(findings or [])
        out.append({"name": name, "path": str(path), "lint": findings})
    if a.json:
        print(dumps({"files": out, "linted": do_lint, "findings": bad}))
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
    from hdl.tacan.frontend import TacanFrontEnd
    from .synth import synth
    check_out_dir(a.out, "--out")
    if a.results is not None:
        check_out_dir(a.results, "--results")
    if not 0 < a.target_mhz <= 1000:
        raise ValueError(f"--target-mhz must be in (0, 1000] MHz, not {a.target_mhz:g}")
    r = synth(TacanFrontEnd(), name="tacan_frontend", device=a.device,
              target_mhz=a.target_mhz, out_dir=a.out, seed=a.seed)
    short = {"top": a.top, **{k: r[k] for k in ("lut4", "ff", "mult18", "bram", "fmax_mhz")}}
    if a.results:
        from pathlib import Path
        from .bench import machine_info
        Path(a.results).mkdir(parents=True, exist_ok=True)
        rec = {**short, "device": r["device"], "target_mhz": r["target_mhz"],
               "timing_met": r["timing_met"], "seed": a.seed, "machine": machine_info()}
        (Path(a.results) / f"synth_{a.top}.json").write_text(dumps(rec, indent=1) + "\n")
    if a.json:
        print(dumps(short))
    else:
        print(f"{a.top} on {r['device']}: {r['lut4']} LUT4, {r['ff']} FF, {r['mult18']} MULT18, "
              f"{r['bram']} DP16KD, Fmax {r['fmax_mhz']:.1f} MHz "
              f"(target {r['target_mhz']:g}: {'met' if r['timing_met'] else 'MISSED'})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m cosim", formatter_class=_Help,
                                description="FPGA+DSP co-simulation of Kalman-filter navigation "
                                            "receivers. Bad input exits 2 with one line on "
                                            "stderr (--debug: the traceback).")
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
    except EXPECTED_ERRORS as e:
        if a.debug:
            raise
        print(f"error: {_one_line(e)}", file=sys.stderr)
        return 2


def _one_line(e: BaseException) -> str:
    """An expected error as one line (a MemoryError or OverflowError may have no text)."""
    text = " ".join(str(e).split())
    if isinstance(e, MemoryError):
        return "out of memory" + (f": {text}" if text else "") + \
            " (reduce the run: --duration-s, --samples, --trials, ...)"
    if isinstance(e, OSError) and not isinstance(e, FileNotFoundError) and e.filename:
        return f"{e.strerror or type(e).__name__}: {e.filename}"
    return text or type(e).__name__
