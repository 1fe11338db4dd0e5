"""The monopulse entry in the receiver registry (:mod:`cosim.core.receivers`): ``python -m cosim
monopulse``, its options derived from :class:`~cosim.monopulse.run.MonopulseRunConfig` (every
default written once, there), its HDL front end (:class:`hdl.monopulse.frontend.MonopulseFrontEnd`,
the ``model`` backend :class:`~cosim.monopulse.session.MonopulseModelSession`), its top, and
its studies (``sweep monopulse``: :mod:`cosim.monopulse.study`; ``faults monopulse``:
:mod:`cosim.monopulse.faults`) on the generic engines."""
from __future__ import annotations

import dataclasses

import sys

from ..core.receivers import (Arg, Benchmark, Figure, Frontend, Option, Receiver, Study,
                              config_kwargs, given_fields, given_options, parse_finite,
                              parse_int, register)
from ..studies.faults import FaultConfig
from ..studies.spec import SweepConfig
from ..core.validate import check_out_dir, dumps
from .faults import FAULT_MODEL, TARGETS
from .run import MonopulseRunConfig, run_monopulse
from .study import SWEEP_MODEL

OPTIONS = tuple(Option(MonopulseRunConfig, f.name) for f in dataclasses.fields(MonopulseRunConfig)
                if "help" in f.metadata) \
    + (Arg("--json", action="store_true", help="print one JSON object"),)


def _f(v, spec=".4f"):
    return "n/a" if v is None or v != v else format(v, spec)


def cmd_monopulse(a) -> int:
    from .checks import check_ignored, check_run_size
    run = MonopulseRunConfig(**config_kwargs(a, OPTIONS, MonopulseRunConfig))
    check_ignored(run, given_fields(a, OPTIONS, MonopulseRunConfig))   # at the default too
    check_run_size(run, note=True)      # accepted (the configuration checked it): how long
    r = run_monopulse(run)
    if a.json:
        print(dumps(r))
        return 0
    print(f"monopulse, SNR {r['snr_db']:g} dB, N = {r['snapshots']}, {r['duration_s']:.3f} s "
          f"({r['blocks']} blocks), {r['trials']} trial(s), backend {r['backend']}, "
          f"{r['tracker']} tracker, {r['dsp']} DSP, seed {r['seed']}")
    for ax in ("az", "el"):
        print(f"  {ax}: measurement RMS {_f(r[f'{ax}_meas_rms_deg'])} deg (mean "
              f"{_f(r[f'{ax}_meas_mean_deg'], '+.4f')}), tracking RMS "
              f"{_f(r[f'{ax}_track_rms_deg'])} deg (mean {_f(r[f'{ax}_track_mean_deg'], '+.4f')}), "
              f"CRB {_f(r[f'{ax}_crb_deg'])} deg, measurement/CRB {_f(r[f'{ax}_meas_over_crb'], '.2f')}")
    print(f"  pointing error RMS {_f(r['pointing_error_rms'], '.2e')}, max "
          f"{_f(r['pointing_error_max_fraction'], '.3f')} of the unambiguous offset; "
          f"{r['lost_track_events']} lost-track events; {r['acquired_trials']} of {r['trials']} "
          f"acquired")
    c = r["calibration"]
    print(f"  calibration bias az/el: before {c['bias_before']['az_deg']:+.4f}/"
          f"{c['bias_before']['el_deg']:+.4f} deg, after {c['bias_after']['az_deg']:+.4f}/"
          f"{c['bias_after']['el_deg']:+.4f} deg")
    print(f"  fifo_dropped {r['fifo_dropped']} ({r['fifo']}); digest "
          f"{r['digest']['steering_and_measurements']}")
    return 0


# -- the studies (sweep / faults monopulse): record options with the monopulse defaults -----
def _study_record_args(duration, memory, trials, snr):
    return (Arg("--duration-s", type=parse_finite, default=duration,
                help="record length (s; the HDL loop runs ~0.7 M ADC samples/s)"),
            Arg("--memory-s", type=parse_finite, default=memory,
                help="the scored window starts at 2 x this (s)"),
            Arg("--trials", type=parse_int, default=trials, help="records per point"),
            Arg("--seed", type=parse_int, default=0, help="base seed (>= 0)"),
            snr)


def _record_kwargs(a) -> dict:
    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, not {a.seed}")
    return dict(duration_s=a.duration_s, memory_s=a.memory_s, trials=a.trials, seed=a.seed)


_SW = SweepConfig
SWEEP_OPTIONS = (
    Arg("--param", action="append", default=[], metavar="NAME=VALUES",
        help="swept parameter, e.g. cordic_iterations=8:20:4, adc_bits=4,8,12, "
             "cordic_in_bits=8,12,16, corr_out_bits=12,18, dsp.x=32,40 (repeatable; "
             "default cordic_iterations=8,12,16,20)"),
    *_study_record_args(0.25, 0.05, 2, Arg("--snr-db", default="-8",
                                              help="SNR values (dB; a:b:step or a list)")),
    Option(_SW, "design", choices=("grid", "oat"), case="lower",
           help="grid: every combination; oat: one parameter at a time"),
    Arg("--recheck", type=parse_int, default=0,
        help="points re-checked on a cycle-accurate backend (their first blocks: same FIFO "
             "words, writes and DSP bits as the model)"),
    Option(_SW, "recheck_backend", default=None, choices=("auto", "pysim", "verilator"),
           case="lower", help="auto: Verilator when installed, else pysim (default auto)"),
    Option(_SW, "target_rel", flag="--target",
           help="proposal target: tracking RMS within (1 + target) of the float golden"),
    Arg("--no-confirm", action="store_true", help="skip the confirming re-run"),
    Arg("--out", default="build/studies/sweep_monopulse", help="output directory"),
    Arg("--jobs", type=parse_int, default=None,
        help="worker processes, 1 .. the cores (default: all cores)"),
    Arg("--json", action="store_true", help="print one JSON object"),
)


def cmd_sweep(a) -> int:
    from ..studies.spec import check_recheck, parse_param, parse_values
    from ..studies.sweep import check_points, study
    from ..core.validate import check_jobs
    if a.recheck < 0:
        raise ValueError(f"--recheck must be >= 0 (points re-checked), not {a.recheck}")
    if a.recheck == 0 and a.recheck_backend is not None:
        raise ValueError("--recheck-backend sets the re-checks, but --recheck 0 runs none")
    params = tuple(parse_param(t, "monopulse") for t in a.param) or None
    snrs = parse_values(a.snr_db, "--snr-db")
    if not all(isinstance(v, (int, float)) for v in snrs):
        raise ValueError(f"--snr-db takes numbers (dB), not {a.snr_db!r}")
    jobs = check_jobs(a.jobs)
    check_out_dir(a.out, "--out")
    kw = config_kwargs(a, SWEEP_OPTIONS, SweepConfig)
    cfg = SweepConfig(receiver="monopulse", snr_db=tuple(float(v) for v in snrs),
                      recheck=a.recheck, **({"params": params} if params else {}),
                      **_record_kwargs(a), **kw)
    check_recheck(cfg, "recheck" in given_options(a))
    check_points(cfg)
    s = study(cfg, a.out, jobs=jobs, confirm_proposal=not a.no_confirm, progress=not a.json)
    if a.json:
        print(dumps({k: s[k] for k in ("proposal", "elapsed_s", "n_points", "rechecks")} |
                    {"confirmed": (s.get("confirmation") or {}).get("confirmed"),
                     "report": f"{a.out}/report.md"}))
    else:
        print(f"{s['n_points']} points in {s['elapsed_s']:.0f} s; report: {a.out}/report.md")
        print(f"proposal: {s['proposal']}")
    bad = [c for c in s.get("rechecks", []) if c.get("same_bits") is False]
    if bad:
        print(f"error: {len(bad)} cycle-accurate re-check(s) gave other bits than the model: "
              f"{[c['combo'] for c in bad]}", file=sys.stderr)
        return 1
    return 0


FAULT_OPTIONS = (
    Option(FaultConfig, "target", choices=TARGETS, case="lower", help="where the bits flip"),
    Arg("--ber", default="1e-6:1e-3",
        help="bit error rates (per bit): lo:hi (every decade) or a comma list"),
    Arg("--bits", default=None,
        help="only these bit positions (comma list, 0 = LSB; default: every bit)"),
    *_study_record_args(0.2, 0.02, 1, Arg("--snr-db", type=parse_finite, default=-8.0,
                                             help="SNR per subarray (dB)")),
    Arg("--out", default="build/studies/faults_monopulse", help="output directory"),
    Arg("--json", action="store_true", help="print one JSON object"),
)


def cmd_faults(a) -> int:
    from ..studies.faults import finish, parse_ber, parse_bits, run_faults
    bits = parse_bits(a.bits)
    check_out_dir(a.out, "--out")
    fc = FaultConfig(receiver="monopulse", bits=bits, ber=parse_ber(a.ber), snr_db=a.snr_db,
                     **_record_kwargs(a), **config_kwargs(a, FAULT_OPTIONS, FaultConfig))
    s = run_faults(fc, a.out, progress=not a.json)

    def row(r):
        f_ = (lambda v, spec: "-" if v is None else format(v, spec))
        return (f"{r['flips']} flips, azimuth tracking RMS {f_(r['rmse_deg'], '.4f')} deg, "
                f"worst {f_(r['max_abs_error_deg'], '.3f')} deg, lost tracks {r['reinit']}, "
                f"bad records {r['gated']}, exceptions {r['exceptions']}")
    return finish(a, fc, s, row)


def _component(params):
    from hdl.monopulse.frontend import MonopulseFrontEnd
    return MonopulseFrontEnd(params)


def _model_session(params, **kw):
    from .session import MonopulseModelSession
    return MonopulseModelSession(params, **kw)


def _top():
    from hdl.monopulse.frontend import monopulse_top
    return monopulse_top()


def _stream_case(*args) -> dict:
    from .stream_case import monopulse_case
    return monopulse_case(*args)


def _equivalence(**kw) -> dict:
    from .equivalence import check_monopulse_equivalence
    return check_monopulse_equivalence(**kw)


def _bench(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench import bench as monopulse_bench
    return monopulse_bench(out, quick=quick)


def _frontend():
    from hdl.monopulse.params import MonopulseFrontendParams
    return Frontend(params=MonopulseFrontendParams, component=_component, model=_model_session,
                    verilog_name="monopulse_frontend")


MONOPULSE = register(Receiver(
    name="monopulse",
    help="run the monopulse closed beam-steering loop and print the angle errors",
    config=MonopulseRunConfig,
    options=OPTIONS,
    run=cmd_monopulse,
    metrics=("az_track_rms_deg", "el_track_rms_deg", "az_meas_rms_deg", "el_meas_rms_deg",
             "az_meas_over_crb", "el_meas_over_crb", "pointing_error_max_fraction"),
    primary=Figure("az_track_rms_deg", "azimuth tracking RMS", "deg"),
    frontend=_frontend(),
    tops={"monopulse_frontend": _top},
    stream_cases={"monopulse_frontend": _stream_case},
    equivalence=_equivalence,
    sweep=Study("word-length sweep of the closed loop on the bit-exact front end (ADC bits, "
                "CORDIC, accumulator and tracker widths) against the float golden",
                SWEEP_OPTIONS, cmd_sweep, model=SWEEP_MODEL),
    faults=Study("bit-error study: flip bits in the ADC samples or the FIFO words of the "
                 "closed loop", FAULT_OPTIONS, cmd_faults, model=FAULT_MODEL),
    benchmarks={"monopulse": Benchmark(_bench)},
))
