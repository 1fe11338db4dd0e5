"""TACAN's entry in the receiver registry (:mod:`cosim.core.receivers`): its command-line options
(derived from :class:`~cosim.tacan.signal.TacanSignalConfig`,
:class:`~cosim.tacan.config.TacanRunConfig`, :class:`~dsp.tacan.kalman_config.KalmanConfig` and
:class:`~cosim.core.link.DspServiceConfig`), the ``tacan`` command, its sweep and fault studies,
its HDL top and its equivalence check."""
from __future__ import annotations

import math
import sys

from dsp.tacan.frontend import DETECTORS
from dsp.tacan.kalman_config import KalmanConfig

from ..core.link import DspServiceConfig
from ..core.receivers import (Arg, Benchmark, Figure, Frontend, Option, Receiver, Study,
                              config_kwargs, given_options, parse_int, register)
from ..studies.faults import FaultConfig
from ..studies.spec import SweepConfig
from ..core.validate import check_jobs, check_out_dir, check_out_file, dumps, warn
from .config import TacanRunConfig
from .signal import TacanSignalConfig
from .faults import FAULT_MODEL, TARGETS
from .study import SWEEP_MODEL

#: Clock the DSP service presets (``cosim.core.link.DSP_PRESETS``) are written for.
PRESET_CLK_HZ = 20e6

_SIG, _RUN = TacanSignalConfig, TacanRunConfig


def _link(name, help):
    return Option(DspServiceConfig, name, prefix="dsp_", default=None, help=help)


#: Options of ``python -m cosim tacan``.
OPTIONS = (
    Option(_SIG, "bearing_deg"), Option(_SIG, "snr_db"), Option(_SIG, "duration_s"),
    Option(_SIG, "seed"), Option(_SIG, "mode"), Option(_SIG, "mod_15"),
    Option(_SIG, "mod_135"), Option(_SIG, "fs_hz"), Option(_SIG, "if_hz"),
    Option(_SIG, "adc_bits"), Option(_SIG, "rotation_hz"),
    Option(KalmanConfig, "memory_s", help="Kalman filter memory (s)"),
    Option(_RUN, "settle_s"), Option(_RUN, "backend"), Option(_RUN, "dsp"),
    Option(_RUN, "compare"), Option(_RUN, "noise_floor"), Option(_RUN, "amplitude"),
    Option(_RUN, "detector"),
    Arg("--dsp-service", type=str.lower, choices=["default", "dma", "undersized"], default=None,
        help="how the DSP reads the FIFO (preset; the --dsp-* options below override its "
             "fields): default = 1 ms timer, 256 words; dma; undersized = 64 words per 10 ms, "
             "too slow for a beacon; the times hold at any --fs-hz (HDL backends; default: "
             "default)"),
    Arg("--dsp-stall", action="append", default=[], metavar="START:STOP",
        help="seconds during which the DSP does not read the FIFO (repeatable; HDL backends)"),
    _link("period_cycles", "DSP FIFO service period (FPGA clock cycles; default from the preset)"),
    _link("latency_cycles", "interrupt latency before the DSP reads (cycles; default from the "
                            "preset)"),
    _link("batch_words", "words the DSP reads per service at most (default from the preset)"),
    _link("cycles_per_word", "FPGA cycles per word read while servicing (default from the "
                             "preset)"),
    Option(_RUN, "trace"),
    Arg("--trace-window", default=None, metavar="START:STOP",
        help="seconds of the run to dump (verilator with --trace; pysim dumps the whole run)"),
    Option(_RUN, "recheck"), Option(_RUN, "recheck_samples"),
    Arg("--json", action="store_true", help="print one JSON object"),
)

#: The DSP-link options (fields of DspServiceConfig) among them.
_LINK = tuple(o for o in OPTIONS if isinstance(o, Option) and o.config is DspServiceConfig)


def _flag(o: Option) -> str:
    return o.argparse_kwargs()[0][0]


def _window(text: str, option: str) -> tuple[float, float]:
    try:
        t0, t1 = (float(v) for v in text.split(":"))
    except ValueError:
        raise ValueError(f"{option} takes START:STOP in seconds, not {text!r}") from None
    if not (math.isfinite(t0) and math.isfinite(t1) and 0 <= t0 < t1):
        raise ValueError(f"{option} needs 0 <= START < STOP, not {text!r}")
    return t0, t1


def tacan_run_config(a) -> TacanRunConfig:
    """The :class:`cosim.tacan.config.TacanRunConfig` of ``tacan`` arguments, every option checked
    against the others before any work starts (an option that cannot affect the run is
    refused, not ignored)."""
    from ..core.link import DSP_PRESETS

    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, not {a.seed}")
    hdl = a.backend != "golden"
    given_link = [_flag(o) for o in _LINK if getattr(a, o.dest) is not None]
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
    sig = TacanSignalConfig(**config_kwargs(a, OPTIONS, TacanSignalConfig))
    base = DSP_PRESETS[a.dsp_service or "default"]
    svc = {f: getattr(base, f) for f in base.__dataclass_fields__}
    if a.fs_hz != PRESET_CLK_HZ:
        # the presets are times (1 ms timer, ...) written in cycles of a 20 MHz clock: on
        # another clock they keep their times, not their cycle counts
        k = a.fs_hz / PRESET_CLK_HZ
        for f in ("period_cycles", "latency_cycles", "cycles_per_word"):
            svc[f] = max(1 if f != "latency_cycles" else 0, int(round(svc[f] * k)))
    svc.update(config_kwargs(a, OPTIONS, DspServiceConfig))
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
    kalman = KalmanConfig(**config_kwargs(a, OPTIONS, KalmanConfig))
    settle = 2 * a.memory_s if a.settle_s is None else a.settle_s
    short = a.backend in ("pysim", "verilator") and settle + 0.1 > a.duration_s
    if short:
        warn(f"--duration-s {a.duration_s:g} is shorter than the filter needs to settle "
             f"({settle:g} s + 0.1 s): no bearing is scored; the digests of the peaks and "
             f"FIFO words show the bits")
    return TacanRunConfig(signal=sig, kalman=kalman, service=DspServiceConfig(**svc),
                          trace_window=window, require_bearing=not short,
                          **config_kwargs(a, OPTIONS, TacanRunConfig))


#: ``--detector pair`` is not fit for use yet (printed on every run with it).
PAIR_DETECTOR_WARNING = (
    "--detector pair is experimental: at 0 dB it acquires fewer records than the pulse "
    "detector (4 of 8 at 90 deg), and a beacon of the other mode can pass its pair test: an "
    "X beacon heard by the Y receiver gave 105 bearings shown valid in 60 s at 10 dB "
    "(docs/experiments/README.md)")


def _num(v, fmt: str, none: str = "-") -> str:
    return none if v is None else format(v, fmt)


def cmd_tacan(a) -> int:
    from .run import check_run_size, run_tacan
    run = tacan_run_config(a)
    check_run_size(run)
    if run.detector == "pair":
        print(f"warning: {PAIR_DETECTOR_WARNING}", file=sys.stderr)
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
        print(f"  first valid bearing at {_num(r['first_valid_bearing_s'], '.3f', 'none')} s; "
              f"rotation rate {_num(r['rotation_hz'], '.4f', 'not established')} Hz "
              f"(from the reference timing)")
        print(f"  {r['n_peaks']} peaks, {r['n_measurements']} measurements, {r['n_updates']} Kalman updates, "
              f"{r['n_main_refs']} main + {r['n_aux_refs']} aux references, {r['gated']} gated, "
              f"{r['reinit']} re-initialisations, {r['adc_clipped']} ADC samples clipped")
        pf = r.get("paired_fraction")
        print(f"  measured on: {r['measured_on']}"
              + ("" if pf is None else f" (paired fraction {pf:.2f})"))
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


def _record_options(cfg) -> tuple:
    """The record and filter options both studies take from their config."""
    return (Option(cfg, "duration_s", help="record length (s)"),
            Option(cfg, "memory_s", help="Kalman filter memory (s)"),
            Option(cfg, "seed", help="base seed (>= 0)"))


# -- sweep tacan ---------------------------------------------------------------------------
_SW = SweepConfig

SWEEP_OPTIONS = (
    Arg("--param", action="append", default=[], metavar="NAME=VALUES",
        help="swept parameter, e.g. adc_bits=4:14, nco_amp_bits=8,12,16, dsp.P=30:46:4, "
             "dsp.K.rounding=floor,half_up (repeatable; default adc_bits=4:14)"),
    Arg("--snr-db", default=None,
        help=f"SNR values (dB; a:b:step or a list; default "
             f"{','.join(f'{v:g}' for v in _SW.__dataclass_fields__['snr_db'].default)})"),
    Option(_SW, "design", choices=("grid", "oat"), case="lower",
           help="grid: every combination; oat: one parameter at a time (the others at their "
                "largest value)"),
    Option(_SW, "trials", help="Monte Carlo records per SNR"),
    *_record_options(_SW),
    Option(_SW, "recheck", help="points re-checked on the cycle-accurate backend (0: none)"),
    Option(_SW, "recheck_backend", default=None, choices=("auto", "pysim", "verilator"),
           case="lower", help="auto: Verilator when installed, else the Amaranth simulation "
                              "(default auto)"),
    Option(_SW, "recheck_samples",
           help="ADC samples re-checked per point (default 1e6 Verilator, 6e4 pysim)"),
    Option(_SW, "target_rel", flag="--target",
           help="proposal target: RMSE within (1 + target) of the float golden (fraction)"),
    Option(_SW, "availability_margin",
           help="proposal target: availability at most this much (fraction) below the float "
                "golden's"),
    Arg("--no-confirm", action="store_true", help="skip the confirming re-run"),
    Arg("--out", default="build/studies/sweep", help="output directory"),
    Arg("--jobs", type=parse_int, default=None,
        help="worker processes, 1 .. the cores (default: all cores)"),
    Arg("--scheduler", default="local",
        help="'local' (process pool), 'dask' (local Dask cluster) or a Dask scheduler address"),
    Arg("--json", action="store_true", help="print one JSON object"),
)


def cmd_sweep(a) -> int:
    from ..studies.engine import check_scheduler
    from ..studies.spec import check_recheck, parse_param, parse_values
    from ..studies.sweep import check_points, study
    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, not {a.seed}")
    if a.recheck < 0:
        raise ValueError(f"--recheck must be >= 0 (points re-checked), not {a.recheck}")
    if a.recheck == 0 and (a.recheck_backend is not None or a.recheck_samples is not None):
        raise ValueError("--recheck-backend/--recheck-samples set the re-checks, but "
                         "--recheck 0 runs none")
    params = tuple(parse_param(t) for t in a.param) or SweepConfig().params
    snrs = SweepConfig().snr_db if a.snr_db is None else parse_values(a.snr_db, "--snr-db")
    if not all(isinstance(v, (int, float)) for v in snrs):
        raise ValueError(f"--snr-db takes numbers (dB), not {a.snr_db!r}")
    jobs = check_jobs(a.jobs)
    check_scheduler(a.scheduler, a.jobs, flag="--scheduler", reach=True)
    check_out_dir(a.out, "--out")
    cfg = SweepConfig(params=params, snr_db=tuple(float(v) for v in snrs),
                      **config_kwargs(a, SWEEP_OPTIONS, SweepConfig))
    check_recheck(cfg, "recheck" in given_options(a))
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


def _decades(ber) -> str:
    """``(1e-6, ..., 1e-3)`` as ``--ber`` writes it: ``1e-6:1e-3``."""
    return ":".join(f"{v:.0e}".replace("e-0", "e-") for v in (min(ber), max(ber)))


# -- faults tacan --------------------------------------------------------------------------
_FC = FaultConfig

FAULT_OPTIONS = (
    Option(_FC, "target", choices=TARGETS, case="lower", help="where the bits flip"),
    Arg("--ber", default=None,
        help=f"bit error rates (per bit): lo:hi (every decade) or a comma list (default "
             f"{_decades(_FC.__dataclass_fields__['ber'].default)})"),
    Arg("--bits", default=None,
        help="only these bit positions (comma list, 0 = LSB), e.g. the MSBs (default: every "
             "bit of the target's words)"),
    Option(_FC, "snr_db", help="SNR (dB)"),
    Option(_FC, "trials", help="records per BER"),
    *_record_options(_FC),
    Option(_FC, "backend", default=None, choices=("model", "pysim", "verilator"), case="lower",
           help="front end of the register target (the others use the model; default model)"),
    Option(_FC, "scrub_period_s", default=None,
           help="register target: the DSP rewrites the register this often (s; default 0.01)"),
    Option(_FC, "fifo_parity",
           help="fifo target: FIFO words carry an even-parity bit, checked by the DSP"),
    Option(_FC, "detector", default=None, choices=DETECTORS, case="lower",
           help="the front end's peak search(es), as tacan --detector (default: the "
                "receiver's, both)"),
    Arg("--out", default="build/studies/faults", help="output directory"),
    Arg("--json", action="store_true", help="print one JSON object"),
)


def cmd_faults(a) -> int:
    from ..studies.faults import finish, parse_ber, parse_bits, run_faults
    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, not {a.seed}")
    if a.target != "register":
        given = [o for o, v in (("--backend", a.backend), ("--scrub-period-s", a.scrub_period_s))
                 if v is not None]
        if given:
            raise ValueError(f"{', '.join(given)} only affect(s) --target register, not "
                             f"--target {a.target}")
    bits = parse_bits(a.bits)
    check_out_dir(a.out, "--out")
    ber = {} if a.ber is None else {"ber": parse_ber(a.ber)}
    fc = FaultConfig(bits=bits, **ber,
                     **config_kwargs(a, FAULT_OPTIONS, FaultConfig))
    s = run_faults(fc, a.out, progress=not a.json)

    def row(r):
        rm = "-" if r["rmse_deg"] is None else f"{r['rmse_deg']:.3f}"
        mx = "-" if r["max_abs_error_deg"] is None else f"{r['max_abs_error_deg']:.3f}"
        return (f"{r['flips']} flips, RMSE {rm} deg, worst {mx} deg, NaN {r['nan_bearings']}, "
                f"exceptions {r['exceptions']}, re-inits {r['reinit']}")
    return finish(a, fc, s, row)


# -- the entry -----------------------------------------------------------------------------
def _top():
    """The default receiver's front end (``TacanRunConfig().hdl_params``)."""
    from hdl.tacan.frontend import TacanFrontEnd
    return TacanFrontEnd(TacanRunConfig().hdl_params)


def _stream_case(*args) -> dict:
    from .stream_case import tacan_case
    return tacan_case(*args)


def _equivalence(**kw) -> dict:
    from .equivalence import check_equivalence
    return check_equivalence(top="tacan", **kw)


def _component(params):
    from hdl.tacan.frontend import TacanFrontEnd
    return TacanFrontEnd(params)


def _model_session(params, **kw):
    from .session import TacanModelSession
    return TacanModelSession(params, **kw)


def _tacan_bench(name: str):
    def bench(out, quick: bool = False, jobs: int | None = None) -> dict:
        from importlib import import_module
        module = import_module(f"{__package__}.bench_{name}")
        return getattr(module, f"tacan_{name}")(out, quick=quick, jobs=jobs)
    bench.__name__ = f"tacan_{name}"
    return bench


def _dsp_speed(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_dsp import dsp_speed
    return dsp_speed(out, quick=quick)


def _dsp_hour(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_dsp import dsp_hour
    return dsp_hour(out, quick=quick)


def _sim_speed(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_sim import sim_speed
    return sim_speed(out, quick=quick)


#: ``python -m cosim bench <name>`` of the TACAN receiver.
BENCHMARKS = {
    **{f"tacan-{k}": Benchmark(_tacan_bench(k), jobs=True)
       for k in ("accuracy", "robustness", "detector", "sensitivity", "confidence")},
    "tacan-record": Benchmark(_tacan_bench("record")),
    "dsp-speed": Benchmark(_dsp_speed), "dsp-hour": Benchmark(_dsp_hour),
    "sim-speed": Benchmark(_sim_speed),
}


def _frontend():
    from hdl.tacan.params import TacanFrontendParams
    return Frontend(params=TacanFrontendParams, component=_component, model=_model_session,
                    verilog_name="tacan_frontend",
                    inputs=lambda p: {"freq": p.nco_freq_word})


TACAN = register(Receiver(
    name="tacan",
    help="run a TACAN scenario end to end and print the bearing",
    config=TacanRunConfig,
    options=OPTIONS,
    run=cmd_tacan,
    metrics=("rmse_deg", "mean_error_deg", "max_abs_error_deg", "rmse_over_crb",
             "vs_golden_rms_deg"),
    primary=Figure("rmse_deg", "bearing RMSE", "deg"),
    frontend=_frontend(),
    tops={"tacan_frontend": _top},
    stream_cases={"tacan_frontend": _stream_case},
    equivalence=_equivalence,
    sweep=Study("quantisation sweep: word lengths/modes x SNR x trials, report, word-length "
                "proposal and its confirmation", SWEEP_OPTIONS, cmd_sweep, model=SWEEP_MODEL),
    faults=Study("bit-error study: flip bits in the ADC samples, FIFO words, the NCO register "
                 "or the DSP state", FAULT_OPTIONS, cmd_faults, model=FAULT_MODEL),
    benchmarks=BENCHMARKS,
))
