"""GNSS's entry in the receiver registry (:mod:`cosim.core.receivers`): the ``gnss`` command
(options derived from :class:`~cosim.gnss.signal.GnssSignalConfig`,
:class:`~cosim.gnss.config.DynamicsChoice` and :class:`~cosim.gnss.config.GnssRunConfig`), the
channel's front end for :func:`cosim.backends.factory.open_frontend`, and its HDL top."""
from __future__ import annotations

from ..core.receivers import (Arg, Benchmark, Figure, Frontend, Option, Receiver, Study,
                              config_kwargs, parse_int, register)
from ..studies.spec import SweepConfig
from ..core.validate import check_jobs, check_out_dir, dumps, warn
from .study import SWEEP_MODEL
from .acq_options import ACQ_OPTIONS
from .config import SCENARIOS, DynamicsChoice, GnssRunConfig, frequency_plan_warning
from .run import run_gnss
from .signal import GnssSignalConfig, check_cn0

_SIG, _DYN, _RUN = GnssSignalConfig, DynamicsChoice, GnssRunConfig

#: Options of ``python -m cosim gnss``.
OPTIONS = (
    Arg("--scenario", type=str.lower, choices=tuple(SCENARIOS), default=None,
        help="named preset; its values fill the options not given: " + "; ".join(
            f"{k}: {v['help']}" for k, v in SCENARIOS.items())),
    Option(_SIG, "prn"), Option(_SIG, "cn0_dbhz", default=None,
                                help="carrier to noise density (dB-Hz; default 45)"),
    Option(_SIG, "duration_s"),
    Option(_SIG, "seed", help="random seed (>= 0) of the noise, data bits, dynamics"),
    Option(_SIG, "fs_hz", help="ADC sample rate = channel clock (S/s)"),
    Option(_SIG, "if_hz", help="IF (Hz), in the first Nyquist zone"),
    Option(_SIG, "adc_bits"), Option(_SIG, "code_phase_chips"),
    Option(_DYN, "dynamics", default=None), Option(_DYN, "jerk_g_per_s"), Option(_DYN, "jerk_start_s"),
    Option(_DYN, "jerk_duration_s"),
    Option(_RUN, "tracker"), Option(_RUN, "bn_hz"), Option(_RUN, "dll_bn_hz"),
    Option(_RUN, "backend"), Option(_RUN, "dsp"), Option(_RUN, "r_mode"),
    Option(_RUN, "control_latency_cycles", flag="--latency"),
    Option(_RUN, "settle_s"), Option(_RUN, "compare"),
    *ACQ_OPTIONS,
    Arg("--json", action="store_true", help="print one JSON object"),
)


def build_configs(a) -> tuple[GnssSignalConfig, GnssRunConfig]:
    """The signal and run configurations of parsed options (ValueError if refused); a
    ``--scenario`` fills the options left unset. A sample rate that leaves the code loop a
    dead zone is warned about (:func:`~cosim.gnss.config.frequency_plan_warning`)."""
    if getattr(a, "scenario", None):
        for k, v in SCENARIOS[a.scenario]["options"].items():
            if getattr(a, k) is None:
                setattr(a, k, v)
    from .handover import acquisition_span_ms
    sig = _SIG(**config_kwargs(a, OPTIONS, _SIG))
    if (msg := frequency_plan_warning(sig.fs_hz)) is not None:
        warn(msg)
    dyn = _DYN(**config_kwargs(a, OPTIONS, _DYN))
    run = config_kwargs(a, OPTIONS, _RUN)
    if getattr(a, "scenario", None):
        run = {**SCENARIOS[a.scenario].get("run", {}), **run}
    run = _RUN(**run)
    dyn.check_record(sig.duration_s + acquisition_span_ms(run) * 1e-3)
    run.check_loop_timing(sig.fs_hz)
    return dyn.apply(sig), run


# -- sweep gnss: the AUKF core's word lengths (cosim/gnss/study.py) --------------------------
_SW = SweepConfig

SWEEP_OPTIONS = (
    Arg("--param", action="append", default=[], metavar="NAME=VALUES",
        help="swept width of an AUKF core format, e.g. dsp.P=32:48:4, dsp.gain=16:32:4 "
             "(repeatable; default dsp.P=32:48:4)"),
    Arg("--cn0-dbhz", default=None, help="C/N0 values (dB-Hz; a:b:step or a list; default 32)"),
    Option(_SW, "design", choices=("grid", "oat"), case="lower",
           help="grid: every combination; oat: one parameter at a time (the others at their "
                "largest value)"),
    Option(_SW, "trials", help="Monte Carlo records per C/N0"),
    Option(_SW, "duration_s", help="record length (s)"),
    Option(_SW, "seed", help="base seed (>= 0)"),
    Option(_SW, "target_rel", flag="--target",
           help="proposal target: phase RMSE within (1 + target) of the float64 AUKF (fraction)"),
    Arg("--no-confirm", action="store_true", help="skip the confirming re-run"),
    Arg("--out", default="build/studies/sweep_gnss", help="output directory"),
    Arg("--jobs", type=parse_int, default=None,
        help="worker processes, 1 .. the cores (default: all cores)"),
    Arg("--json", action="store_true", help="print one JSON object"),
)


def cmd_sweep(a) -> int:
    from ..studies.spec import parse_param, parse_values
    from ..studies.sweep import check_points, study
    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, not {a.seed}")
    params = tuple(parse_param(t, "gnss") for t in a.param)
    cn0 = (32.0,) if a.cn0_dbhz is None else parse_values(a.cn0_dbhz, "--cn0-dbhz")
    if not all(isinstance(v, (int, float)) for v in cn0):
        raise ValueError(f"--cn0-dbhz takes numbers (dB-Hz), not {a.cn0_dbhz!r}")
    for v in cn0:
        check_cn0("--cn0-dbhz", v)
    check_out_dir(a.out, "--out")
    cfg = SweepConfig(receiver="gnss", params=params, snr_db=tuple(float(v) for v in cn0),
                      recheck=0, **config_kwargs(a, SWEEP_OPTIONS, SweepConfig))
    check_points(cfg)
    s = study(cfg, a.out, jobs=check_jobs(a.jobs), confirm_proposal=not a.no_confirm,
              progress=not a.json)
    conf = s.get("confirmation") or {}
    if a.json:
        print(dumps({k: s[k] for k in ("proposal", "elapsed_s", "n_points")} |
                    {"confirmed": conf.get("confirmed"), "confirmed_params": conf.get("params"),
                     "report": f"{a.out}/report.md"}))
    else:
        print(f"{s['n_points']} points in {s['elapsed_s']:.0f} s; report: {a.out}/report.md")
        print(f"proposal: {s['proposal']}")
        if conf:
            print(f"confirmed: {conf['confirmed']}" + (f" with {conf['params']}" if conf.get("params") else ""))
    return 0


def not_acquired(e, head: dict, as_json: bool) -> int:
    """A run whose acquisition found nothing (:class:`~cosim.gnss.handover.AcquisitionFailed`):
    a result, ``status`` ``"not acquired"`` with the search's record, exit 1 (``gnss``,
    ``ins``)."""
    r = {**head, "status": "not acquired", "acquired": e.acquisition, "message": str(e)}
    print(dumps(r) if as_json else f"not acquired: {e}")
    return 1


def cmd_gnss(a) -> int:
    from .handover import AcquisitionFailed
    sig, run = build_configs(a)
    try:
        r = run_gnss(sig, run)
    except AcquisitionFailed as e:
        return not_acquired(e, {"prn": sig.prn, "cn0_dbhz": sig.cn0_dbhz,
                                "duration_s": sig.duration_s, "tracker": run.tracker,
                                "backend": run.backend, "dsp": run.dsp}, a.json)
    r.pop("_series", None)
    r = {"status": "tracked", **r}
    if a.scenario:
        r["scenario"] = {"name": a.scenario, **SCENARIOS[a.scenario]}
    if a.json:
        print(dumps(r))
        return 0
    acq = r["acquired"]
    bn = "" if r["bn_hz"] is None else f" (Bn {r['bn_hz']:g} Hz)"
    print(f"PRN {r['prn']}  C/N0 {r['cn0_dbhz']} dB-Hz  {r['duration_s']:g} s  tracker "
          f"{r['tracker']}{bn}  backend {r['backend']}  dsp {r['dsp']}")
    print(f"acquired by the {acq['search']} search ({acq['dwell']}, at {acq['noncoherent']} "
          f"sums) after {1e3 * acq['t_detect_s']:.0f} ms of signal, pfa {acq['pfa']:g}; "
          f"tracking from {1e3 * acq['t_start_s']:.0f} ms: Doppler "
          f"{acq['doppler_refined_hz']:.1f} Hz (true {acq['doppler_true_hz']:.1f}), code phase "
          f"{acq['code_phase_found_chips']:.3f} chips (true {acq['code_phase_true_chips']:.3f})")
    lf = r["lock_fraction"]
    print(f"carrier phase RMSE {r['phase_rmse_deg']:.2f} deg, Doppler RMSE "
          f"{r['doppler_rmse_hz']:.3f} Hz, code RMSE {r['code_rmse_chips']:.4f} chips, "
          f"cycle slips {r['cycle_slips']}, lock "
          f"{'n/a' if lf is None else f'{100 * lf:.0f} %'}, C/N0 est "
          f"{r['cn0_est_dbhz']:.1f} dB-Hz, FIFO dropped {r['fifo_dropped']}")
    if "vs_golden_phase_rms_deg" in r:
        print(f"vs golden (float chain): phase {r['vs_golden_phase_rms_deg']:.3f} deg rms, "
              f"Doppler {r['vs_golden_doppler_rms_hz']:.4f} Hz rms")
    if r["q_hat"] is not None:
        q = r["q_hat"]
        print(f"q_hat final {q['final']:.4g} (q0 {q['q0']:g}; per {q['block_s']:g} s block "
              f"{q['min']:.3g}..{q['max']:.3g}), diverged {r['diverged']}")
    print(f"digest {r['digest']['all']}")
    return 0


def _component(params):
    from hdl.gnss.channel import GnssChannel
    return GnssChannel(params)


def _model_session(params, **kw):
    from .session import GnssModelSession
    return GnssModelSession(params, **kw)


def _top(channels: int = 1):
    from hdl.gnss.channel import gnss_top
    return gnss_top(channels)


def _top_iq(channels: int = 1):
    from hdl.gnss.channel import gnss_top
    return gnss_top(channels, input="complex")


def _stream_case(channels: int, iq: bool):
    def case(*args) -> dict:
        from .stream_case import gnss_case
        return gnss_case(*args, channels=channels, iq=iq)
    return case


def _equivalence(scenario: str | None = None, channels: int | None = None, **kw) -> dict:
    """The channel's check (:func:`cosim.gnss.equivalence.check_gnss_equivalence`), or with
    ``scenario`` the array's closed loop on a window of it
    (:func:`cosim.gnss.array_equivalence.check_array_equivalence`, ``channels`` default 8)."""
    if scenario is None:
        if channels is not None:
            raise ValueError("--channels is for --scenario (the channel array's closed loop)")
        from .equivalence import check_gnss_equivalence
        return check_gnss_equivalence(**kw)
    from .array_equivalence import check_array_equivalence
    return check_array_equivalence(scenario=scenario, channels=8 if channels is None else
                                   channels, **kw)


def _gnss_speed(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench import gnss_speed
    return gnss_speed(out, quick=quick)


def _gnss_tracking(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench import gnss_tracking
    return gnss_tracking(out, quick=quick)


def _gnss_throughput(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .track_bench import gnss_throughput
    return gnss_throughput(out, quick=quick)


def _aukf(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .study_aukf import bench as aukf_bench
    return aukf_bench(out, quick=quick)


def _aukf_convergence(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .study_aukf import bench_convergence
    return bench_convergence(out, quick=quick)


def _gnss_acquisition(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_acquisition import gnss_acquisition
    return gnss_acquisition(out, quick=quick, jobs=jobs)


def _gps_fast(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .gps_fast_bench import gps_fast
    return gps_fast(out, quick=quick)


def _gps_fix(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .fix_bench import gps_fix
    return gps_fix(out, quick=quick)


#: ``python -m cosim bench <name>`` of the GNSS receiver (the AUKF's among them).
BENCHMARKS = {"gnss-speed": Benchmark(_gnss_speed), "gnss-tracking": Benchmark(_gnss_tracking),
              "gnss-throughput": Benchmark(_gnss_throughput),
              "gnss-acquisition": Benchmark(_gnss_acquisition, jobs=True),
              "aukf": Benchmark(_aukf), "aukf-convergence": Benchmark(_aukf_convergence),
              "gps-fast": Benchmark(_gps_fast), "gps-fix": Benchmark(_gps_fix)}


def _frontend():
    from hdl.gnss.params import GnssChannelParams
    return Frontend(params=GnssChannelParams, component=_component, model=_model_session,
                    verilog_name="gnss_channel")


GNSS = register(Receiver(
    name="gnss", help="acquire and track one GPS L1 C/A channel closed loop (FPGA channel "
                      "+ DSP tracker) and print its errors against the truth",
    config=GnssRunConfig, options=OPTIONS, run=cmd_gnss,
    metrics=("phase_rmse_deg", "doppler_rmse_hz", "code_rmse_chips", "cycle_slips",
             "lock_fraction"),
    primary=Figure("phase_rmse_deg", "carrier phase RMSE", "deg"),
    frontend=_frontend(),
    sweep=Study("word-length sweep of the fixed-point AUKF core on the fast path "
                "(paired with the float64 AUKF), proposal and its confirmation", SWEEP_OPTIONS,
                cmd_sweep, model=SWEEP_MODEL),
    tops={"gnss_channel": _top, "gnss_channel_array12": lambda: _top(12),
          "gnss_channel_iq": _top_iq, "gnss_channel_array12_iq": lambda: _top_iq(12)},
    stream_cases={"gnss_channel": _stream_case(1, False),
                  "gnss_channel_iq": _stream_case(1, True),
                  "gnss_channel_array12": _stream_case(12, False),
                  "gnss_channel_array12_iq": _stream_case(12, True)},
    array_top=_top,
    variants={"iq": _top_iq},
    equivalence=_equivalence,
    equivalence_scenarios=("gps",),
    benchmarks=BENCHMARKS))
