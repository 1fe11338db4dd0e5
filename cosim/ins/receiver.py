"""The INS-aided loop's entry in the receiver registry (:mod:`cosim.core.receivers`):
``python -m cosim ins`` runs one of the three carrier loops (INS-aided Kalman, aided PLL,
unaided Kalman) over the INS paper's trajectory on the GNSS channel
(:func:`cosim.ins.run.run_ins`); its options are the fields of :class:`~cosim.ins.run.InsRunConfig` and the channel/DSP fields of
:class:`~cosim.gnss.config.GnssRunConfig`. The front end is the GNSS channel's (``gnss``)."""
from __future__ import annotations

from ..gnss.acq_options import ACQ_OPTIONS
from ..gnss.config import GnssRunConfig
from ..core.receivers import Arg, Benchmark, Figure, Option, Receiver, config_kwargs, register
from ..core.validate import dumps
from .run import InsRunConfig, run_ins

_INS, _RUN = InsRunConfig, GnssRunConfig

#: Options of ``python -m cosim ins``.
OPTIONS = (
    Option(_INS, "loop"), Option(_INS, "cn0_dbhz"), Option(_INS, "oscillator"),
    Option(_INS, "duration_s"), Option(_INS, "seed"), Option(_INS, "start_s"),
    Option(_INS, "jerk_g_s"), Option(_INS, "accel_g"), Option(_INS, "v_max_mps"),
    Option(_INS, "trajectory_csv"), Option(_INS, "pli_epochs"), Option(_INS, "pli_threshold"),
    Option(_RUN, "backend"), Option(_RUN, "dsp"), Option(_RUN, "dll_bn_hz"),
    Option(_RUN, "control_latency_cycles", flag="--latency"), Option(_RUN, "settle_s"),
    *ACQ_OPTIONS,
    Arg("--json", action="store_true", help="print one JSON object"),
)


def build_configs(a) -> tuple[InsRunConfig, GnssRunConfig]:
    """The run's configurations from parsed options (ValueError if refused)."""
    ins = _INS(**config_kwargs(a, OPTIONS, _INS))
    return ins, _RUN(tracker=ins.loop, **config_kwargs(a, OPTIONS, _RUN))


def cmd_ins(a) -> int:
    from ..gnss.handover import AcquisitionFailed
    from ..gnss.receiver import not_acquired
    ins, run = build_configs(a)
    try:
        r = run_ins(ins, run)
    except AcquisitionFailed as e:
        return not_acquired(e, {"loop": ins.loop, "cn0_dbhz": ins.cn0_dbhz,
                                "duration_s": ins.duration_s, "backend": run.backend,
                                "dsp": run.dsp}, a.json)
    r.pop("_series", None)
    r = {"status": "tracked", **r}
    if a.json:
        print(dumps(r))
        return 0
    osc = r["oscillator"] or "ideal clock"
    print(f"{r['loop']}  C/N0 {r['cn0_dbhz']:g} dB-Hz  {osc}  {r['duration_s']:g} s  "
          f"backend {r['backend']}  dsp {r['dsp']}")
    print(f"velocity error (LOS) mean {r['vel_err_mean_mps']:+.4f} m/s, std "
          f"{r['vel_err_std_mps']:.4f} m/s; range error mean {r['range_err_mean_m']:+.3f} m, "
          f"std {r['range_err_std_m']:.3f} m")
    dj = r["disc_rms_jerk_deg"]
    print(f"PLI mean {r['pli_mean']:.3f} min {r['pli_min']:.3f}, lock "
          f"{100 * r['lock_fraction']:.2f} % (PLI > {r['pli_threshold']:g}), cycle slips "
          f"{r['cycle_slips']}, phase RMSE {r['phase_rmse_deg']:.2f} deg, disc RMS in jerk "
          f"{'n/a' if dj is None else f'{dj:.2f} deg'}, FIFO dropped {r['fifo_dropped']}")
    print(f"digest {r['digest']['all']}")
    return 0


def _bench(out, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench import ins_bench
    return ins_bench(out, quick=quick, jobs=jobs)


def _bench_table2(out, quick: bool = False, jobs: int | None = None,
                  scheduler: str = "local") -> dict:
    from .table2_bench import ins_table2_bench
    return ins_table2_bench(out, quick=quick, jobs=jobs, scheduler=scheduler)


INS = register(Receiver(
    name="ins", help="the INS paper: INS-aided Kalman carrier loop, aided PLL or unaided Kalman "
                     "loop over the paper's trajectory on the GNSS channel; LOS velocity and "
                     "range errors, PLI, lock, cycle slips",
    config=InsRunConfig, options=OPTIONS, run=cmd_ins,
    metrics=("vel_err_std_mps", "vel_err_mean_mps", "range_err_std_m", "range_err_mean_m",
             "lock_fraction", "cycle_slips"),
    primary=Figure("vel_err_std_mps", "LOS velocity error std", "m/s"),
    benchmarks={"ins": Benchmark(_bench, jobs=True),
                "ins-table2": Benchmark(_bench_table2, jobs=True, scheduler=True)}))
