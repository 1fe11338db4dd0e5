"""The monopulse entry in the receiver registry (:mod:`cosim.receivers`): ``python -m cosim
monopulse``, its options derived from :class:`~cosim.monopulse.run.MonopulseRunConfig` (every
default written once, there), its HDL front end (:class:`hdl.monopulse.frontend.MonopulseFrontEnd`,
the ``model`` backend :class:`~cosim.monopulse.session.MonopulseModelSession`) and its top.
No sweep or fault study is declared yet."""
from __future__ import annotations

import dataclasses

from ..receivers import Arg, Figure, Frontend, Option, Receiver, config_kwargs, register
from ..validate import dumps
from .run import MonopulseRunConfig, run_monopulse

OPTIONS = tuple(Option(MonopulseRunConfig, f.name) for f in dataclasses.fields(MonopulseRunConfig)
                if "help" in f.metadata) \
    + (Arg("--json", action="store_true", help="print one JSON object"),)


def _f(v, spec=".4f"):
    return "n/a" if v is None or v != v else format(v, spec)


def cmd_monopulse(a) -> int:
    run = MonopulseRunConfig(**config_kwargs(a, OPTIONS, MonopulseRunConfig))
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


def _component(params):
    from hdl.monopulse.frontend import MonopulseFrontEnd
    return MonopulseFrontEnd(params)


def _model_session(params, **kw):
    from .session import MonopulseModelSession
    return MonopulseModelSession(params, **kw)


def _top():
    from hdl.monopulse.frontend import monopulse_top
    return monopulse_top()


def _equivalence(**kw) -> dict:
    from .equivalence import check_monopulse_equivalence
    return check_monopulse_equivalence(**kw)


def _frontend():
    from hdl.monopulse.model import MonopulseFrontendParams
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
    equivalence=_equivalence,
))
