"""GNSS's entry in the receiver registry (:mod:`cosim.receivers`): the ``gnss`` command
(options derived from :class:`~cosim.gnss.signal.GnssSignalConfig`,
:class:`~cosim.gnss.run.DynamicsChoice` and :class:`~cosim.gnss.run.GnssRunConfig`), the
channel's front end for :func:`cosim.session.open_frontend`, and its HDL top."""
from __future__ import annotations

from ..receivers import Arg, Figure, Frontend, Option, Receiver, config_kwargs, register
from ..validate import dumps
from .run import DynamicsChoice, GnssRunConfig, run_gnss
from .signal import GnssSignalConfig

_SIG, _DYN, _RUN = GnssSignalConfig, DynamicsChoice, GnssRunConfig

#: Options of ``python -m cosim gnss``.
OPTIONS = (
    Option(_SIG, "prn"), Option(_SIG, "cn0_dbhz", help="carrier to noise density (dB-Hz)"), Option(_SIG, "duration_s"),
    Option(_SIG, "seed", help="random seed (>= 0) of the noise, data bits, dynamics"),
    Option(_SIG, "fs_hz", help="ADC sample rate = channel clock (S/s)"),
    Option(_SIG, "if_hz", help="IF (Hz), in the first Nyquist zone"),
    Option(_SIG, "adc_bits"), Option(_SIG, "code_phase_chips"),
    Option(_DYN, "dynamics"), Option(_DYN, "jerk_g_per_s"), Option(_DYN, "jerk_start_s"),
    Option(_DYN, "jerk_duration_s"),
    Option(_RUN, "tracker"), Option(_RUN, "bn_hz"), Option(_RUN, "dll_bn_hz"),
    Option(_RUN, "backend"), Option(_RUN, "dsp"),
    Option(_RUN, "control_latency_cycles", flag="--latency"),
    Option(_RUN, "settle_s"), Option(_RUN, "compare"),
    Arg("--json", action="store_true", help="print one JSON object"),
)


def build_configs(a) -> tuple[GnssSignalConfig, GnssRunConfig]:
    """The signal and run configurations of parsed options (ValueError if refused)."""
    sig = _SIG(**config_kwargs(a, OPTIONS, _SIG))
    sig = _DYN(**config_kwargs(a, OPTIONS, _DYN)).apply(sig)
    return sig, _RUN(**config_kwargs(a, OPTIONS, _RUN))


def cmd_gnss(a) -> int:
    sig, run = build_configs(a)
    r = run_gnss(sig, run)
    r.pop("_series", None)
    if a.json:
        print(dumps(r))
        return 0
    acq = r["acquired"]
    print(f"PRN {r['prn']}  C/N0 {r['cn0_dbhz']} dB-Hz  {r['duration_s']:g} s  tracker "
          f"{r['tracker']} (Bn {r['bn_hz']:g} Hz)  backend {r['backend']}  dsp {r['dsp']}")
    print(f"acquired: Doppler {acq['doppler_refined_hz']:.1f} Hz (bin "
          f"{acq['doppler_found_hz']:.1f}, true {acq['doppler_true_hz']:.1f}), code phase "
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


def _equivalence(**kw) -> dict:
    from .equivalence import check_gnss_equivalence
    return check_gnss_equivalence(**kw)


def _frontend():
    from hdl.gnss.model import GnssChannelParams
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
    tops={"gnss_channel": _top, "gnss_channel_array12": lambda: _top(12)},
    array_top=_top,
    equivalence=_equivalence))
