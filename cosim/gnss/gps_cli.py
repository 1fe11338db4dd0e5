"""``python -m cosim gps``: a GPS L1 C/A position fix from a recording or a generated scenario.

Input, one of:

* ``--file PATH`` with the file options of ``gnss-acquire`` / ``gnss-track``
  (:func:`cosim.gnss.acquire_cli.add_file_options`; ``--format`` and ``--fs-hz`` required
  with a file);
* no ``--file``: a generated scenario (:mod:`cosim.gnss.gps_scenario`: ``--duration-s``,
  ``--seed``, ``--cn0-dbhz``, ``--lat/--lon/--height``, the constellation of ``--nav RINEX``
  or the nominal one above ``--elevation-mask-deg``; ``--fs-hz``/``--if-hz`` default 5 MS/s,
  1.25 MHz; a static receiver, or ``--trajectory ins|CSV`` a moving one; ``--bit-error-rate
  P`` flips LNAV bits in the signal, drawn from ``--seed``) written to
  ``OUT/scenario.int8`` with ``truth.json``, then processed through exactly the file path.
  The fixes are compared with the truth at each epoch. A scenario with fewer than four
  satellites (of ``--prns``) above the mask, or whose trajectory leaves the Earth's
  neighbourhood or moves impossibly (:func:`cosim.gnss.constellation_geometry.check_motion`),
  is refused before any sample is written.

Processing: acquisition of ``--prns`` (:func:`dsp.gnss.search.search_all`), every satellite
found tracked on the channel array (:func:`cosim.gnss.multichannel.track_file`, the
bit-exact model by default; the aided trackers ``aided-kf`` / ``aided-pll`` only on a
generated ``--trajectory ins`` scenario, every channel aided by the INS Doppler rate of
:func:`cosim.ins.table2.ins_tracker_setup` -- the truth's plus the INS paper's sensor
errors drawn from ``--seed`` -- and tracked to 10 ms before the record's end; a recording,
a static or a CSV scenario has no INS and is refused), then the back end (:func:`cosim.gnss.gps_receiver.navigate`):
bit sync, frame sync, LNAV decoding, observables at ``--rate`` Hz, PVT. ``--ephemeris RINEX``
hot-starts from a navigation file (the scenario's own ephemerides and Klobuchar
coefficients with ``--hot-start``);
otherwise a cold start waits for each satellite's subframes 1-3. Outputs under ``--out``
(:func:`cosim.gnss.gps_outputs.write_outputs`); the table or, with ``--json``, one JSON
object on stdout; stage progress on stderr unless ``--json``. The summary counts the words
that failed parity and the fix jumps (:mod:`cosim.gnss.fix_integrity`, bound
``--jump-bound-m``).

Every option is checked, and a ``--ephemeris`` / ``--nav`` file read, before any work: bad
input exits 2 with one line. A run that gives no fix, or a fix jump, exits 1 with its
summary (the status says why).
"""
from __future__ import annotations

import sys
import time

import numpy as np

from ..core.validate import check_float, check_out_dir, dumps
from .acquire_cli import add_file_options, add_search_options, check_search_options, \
    open_file, search_file, search_status

__all__ = ["add_parser", "run", "process", "DEFAULT_OUT"]

#: Where the outputs (and a generated scenario) go.
DEFAULT_OUT = "build/gps"
#: The file options that are required only with ``--file``.
_FILE_ONLY = ("format", "fs_hz")


def add_parser(sub, make_parser) -> None:
    """Register ``gps`` on the subparsers ``sub`` (as :mod:`cosim.cli` does)."""
    from dsp.gnss.trackers import tracker_names
    p = make_parser(sub, "gps", help="GPS L1 C/A position fixes from a recording or a "
                                     "generated scenario: acquisition, tracking on the FPGA "
                                     "array, LNAV decoding, observables, PVT; RINEX, NMEA, "
                                     "CSV, JSON, plots")
    add_file_options(p)
    for act in p._actions:                       # --file, --format, --fs-hz: file mode only
        if act.dest in ("file",) + _FILE_ONLY:
            act.required = False
    add_search_options(p)
    g = p.add_argument_group("generated scenario (without --file)")
    g.add_argument("--seed", type=int, default=1, help="noise and clock seed")
    g.add_argument("--cn0-dbhz", type=float, default=45.0, help="C/N0 of every satellite")
    g.add_argument("--nav", default=None, metavar="RINEX",
                   help="constellation from a RINEX navigation file (default: nominal)")
    g.add_argument("--lat", type=float, default=52.0, help="receiver latitude (deg)")
    g.add_argument("--lon", type=float, default=4.4, help="receiver longitude (deg)")
    g.add_argument("--height", type=float, default=30.0, help="receiver height (m)")
    g.add_argument("--hot-start", action="store_true",
                   help="hot start from the generator's ephemerides")
    g.add_argument("--elevation-mask-deg", type=float, default=None,
                   help="satellites generated above this elevation (default 10 deg, at least 3: "
                        "the troposphere model's lowest)")
    g.add_argument("--trajectory", default=None, metavar="ins|CSV",
                   help="a moving receiver: 'ins' (the INS paper's profile flown east from "
                        "--lat/--lon/--height) or a CSV of t,x,y,z[,vx,vy,vz] (ECEF m, m/s; "
                        "t s from the record's start)")
    g.add_argument("--bit-error-rate", type=float, default=None, metavar="P",
                   help="probability that an LNAV bit is flipped in the signal (default 0; "
                        "the flips drawn from --seed)")
    p.add_argument("--duration-s", type=float, default=None,
                   help="scenario length (default 8 s) or the first seconds of --file")
    p.add_argument("--ephemeris", default=None, metavar="RINEX",
                   help="hot start: ephemerides (and Klobuchar) from a RINEX navigation file")
    p.add_argument("--week", type=int, default=None,
                   help="GPS week of the recording (cold start on --file without --ephemeris)")
    p.add_argument("--rate", type=float, default=1.0, choices=(1.0, 10.0),
                   help="measurement epochs per second")
    p.add_argument("--channels", type=int, default=12, help="channels of the array (1..12)")
    p.add_argument("--tracker", type=str.lower, default="pll3", choices=tracker_names(),
                   help="the DSP tracker of every channel")
    p.add_argument("--dsp", type=str.lower, default="fixed", choices=("fixed", "float"),
                   help="arithmetic of the trackers")
    p.add_argument("--bn-hz", type=float, default=None,
                   help="carrier loop noise bandwidth of the PLL trackers (Hz; default 15)")
    p.add_argument("--backend", type=str.lower, default="model",
                   choices=("model", "pysim", "verilator"), help="the channel array")
    p.add_argument("--parallel", action="store_true",
                   help="the model's channels on numba's threads (same bits)")
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help="output directory")
    p.add_argument("--jump-bound-m", type=float, default=None,
                   help="a fix more than this off the truth, or stepping this much more than "
                        "the truth (or its Doppler velocity) from the previous fix, is a fix "
                        "jump (default 30 m)")
    p.add_argument("--no-plots", action="store_true", help="write no PNG plots")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _say(a, msg: str) -> None:
    if not a.json:
        print(msg, file=sys.stderr, flush=True)


def process(a):
    """The work of ``run`` on parsed options ``a``: ``(GpsRun, summary, scenario)`` with the
    outputs written; ``scenario`` is :func:`cosim.gnss.gps_scenario.write_scenario`'s result
    (None with ``--file``)."""
    from dsp.gnss.atmosphere import TROPO_MIN_ELEVATION_DEG

    from .config import GnssRunConfig
    from .fix_integrity import JUMP_BOUND_M
    from .gps_outputs import write_outputs
    from .gps_receiver import GpsConfig, navigate
    from .gps_scenario import ScenarioSpec, scenario_signal
    from .multichannel import Candidate, TrackConfig, channel_params_for, track_file
    from .multichannel_session import array_channel_params, check_parallel
    from .rinex_nav import read_rinex_nav
    t_wall = time.time()
    from dsp.gnss.trackers import needs_aiding
    aided = needs_aiding(a.tracker)
    # a recording has no INS; a generated --trajectory ins scenario has one (module doc)
    prns = check_search_options(a, tracker=a.tracker if a.file is not None else None)
    if aided and a.file is None and a.trajectory != "ins":
        raise ValueError(f"--tracker {a.tracker} needs an INS aiding source: a generated "
                         f"scenario has one with --trajectory ins, a static or CSV one none")
    out = check_out_dir(a.out, "--out")
    bound = JUMP_BOUND_M if a.jump_bound_m is None else \
        check_float("--jump-bound-m", a.jump_bound_m, 0.0, lo_open=True, unit="m")
    gcfg = GpsConfig(rate_hz=a.rate)
    tcfg = TrackConfig(channels=a.channels, pfa=a.acq_pfa, max_doppler_hz=a.max_doppler_hz,
                       parallel=a.parallel)
    check_parallel(a.parallel, a.backend)
    run_cfg = GnssRunConfig(tracker=a.tracker, dsp=a.dsp, backend=a.backend, bn_hz=a.bn_hz)
    hot = rinex = None
    if a.ephemeris is not None:
        rinex = read_rinex_nav(a.ephemeris)
        if not rinex.ephemerides:
            raise ValueError(f"--ephemeris {a.ephemeris}: no GPS ephemeris in the file")
        hot = rinex.ephemerides
    truth = sig = sc = None
    if a.file is None:
        for opt in ("format", "adc_map"):
            if getattr(a, opt) is not None:
                raise ValueError(f"--{opt.replace('_', '-')} needs --file (a generated "
                                 f"scenario is written as int8)")
        if a.hot_start and hot is not None:
            raise ValueError("give --hot-start or --ephemeris, not both")
        dur = 8.0 if a.duration_s is None else a.duration_s
        check_float("--duration-s", dur, 0.1, 3600.0, unit="s")
        check_float("--cn0-dbhz", a.cn0_dbhz, 20.0, 70.0, unit="dB-Hz")
        mask = 10.0 if a.elevation_mask_deg is None else a.elevation_mask_deg
        check_float("--elevation-mask-deg", mask, TROPO_MIN_ELEVATION_DEG, 90.0, hi_open=True,
                    unit="deg")
        ber = 0.0 if a.bit_error_rate is None else a.bit_error_rate
        check_float("--bit-error-rate", ber, 0.0, 0.5)
        if a.seed < 0:
            raise ValueError(f"--seed must be >= 0, not {a.seed}")
        check_float("--lat", a.lat, -90, 90, unit="deg")
        check_float("--lon", a.lon, -180, 180, unit="deg")
        spec = ScenarioSpec(lat_deg=a.lat, lon_deg=a.lon, height_m=a.height, duration_s=dur,
                            cn0_dbhz=a.cn0_dbhz, seed=a.seed,
                            fs_hz=5e6 if a.fs_hz is None else a.fs_hz,
                            if_hz=1.25e6 if a.if_hz == 0.0 else a.if_hz, nav_file=a.nav,
                            mask_deg=mask, bit_error_rate=ber, trajectory=a.trajectory)
        if a.nav is not None:
            read_rinex_nav(a.nav)                   # a bad file refused before work
        signal = scenario_signal(spec, prns)        # motion, mask, satellites: before work
        from .gps_scenario import write_scenario
        _say(a, f"generating {dur:g} s of the scenario under {out} ...")
        sc = write_scenario(spec, out, signal)
        truth, sig = sc["truth"], sc["signal"]
        a.file, a.format, a.fs_hz, a.if_hz = sc["file"], "int8", sc["fs_hz"], sc["if_hz"]
        week = sc["week"]
        # a hot start knows the generator's ephemerides and Klobuchar coefficients; a cold
        # start only what it decodes
        hot = sc["ephemerides"] if a.hot_start else hot
        iono = sc["iono"] if a.hot_start else (rinex.iono if rinex is not None else None)
        n_dur = None
    else:
        if a.hot_start:
            raise ValueError("--hot-start is for a generated scenario: give --ephemeris")
        for opt in ("elevation_mask_deg", "trajectory", "bit_error_rate"):
            if getattr(a, opt) is not None:
                raise ValueError(f"--{opt.replace('_', '-')} is for a generated scenario, "
                                 f"not --file")
        for opt in _FILE_ONLY:
            if getattr(a, opt) is None:
                raise ValueError(f"--file needs --{opt.replace('_', '-')}")
        week = a.week
        if week is None and hot is not None:
            week = int(min(e.week for e in hot))
        if week is None:
            raise ValueError("a cold start on --file needs --week (the GPS week, to resolve "
                             "the broadcast 10-bit week and date the epochs)")
        if week < 0:
            raise ValueError(f"--week must be >= 0, not {week}")
        iono = None if rinex is None else rinex.iono
        n_dur = a.duration_s
    f = open_file(a)
    p = array_channel_params(channel_params_for(f), a.channels)
    n = f.n_samples
    if n_dur is not None:
        check_float("--duration-s", n_dur, 0, f.duration_s, lo_open=True, unit="s")
        n = int(round(n_dur * f.fs_hz))
    _say(a, f"acquiring PRNs {a.prns} on {f.path} ...")
    rep = search_file(f, a, prns)
    cands = [Candidate.of(d) for d in rep.detections]
    _say(a, f"found {[c.prn for c in cands]}; tracking {n / f.fs_hz:g} s on the "
            f"{a.backend} array ...")
    setup = None
    if aided:                  # the INS of the generated scenario (module doc)
        from ..ins.table2 import AIDING_TAIL_S, ins_tracker_setup
        setup = ins_tracker_setup(sig, a.seed)
        n -= int(round(AIDING_TAIL_S * f.fs_hz))
    if cands:
        m = track_file(f, cands, run_cfg, tcfg, n_samples=n,
                       progress=not a.json and sys.stderr.isatty(), tracker_setup=setup)
        _say(a, f"tracked in {m.wall_s:.1f} s; navigating ...")
        g = navigate(m, p, reference_week=week, inverted=f.doppler_sign_inverted,
                     if_hz=f.if_hz, ephemerides=hot, iono=iono, config=gcfg)
    else:
        from .gps_receiver import GpsRun
        g = GpsRun([], [], f.fs_hz, "hot" if hot is not None else "cold", None, None)
    if sig is not None:                   # the truth at every epoch (a moving receiver)
        ep = np.array([e.sample for e in g.epochs if e.solution is not None], dtype=np.int64)
        if ep.size:
            pos = sig.truth_at(ep / f.fs_hz).rx_position_m
            truth = dict(truth, ecef_at_sample={int(n): [float(x) for x in p_]
                                                for n, p_ in zip(ep, pos)})
    s = write_outputs(g, out, truth, plots=not a.no_plots, jump_bound_m=bound)
    s["recording"] = f.describe()
    s["acquired"] = [c.prn for c in cands]
    s["status"] = search_status(rep)
    s["wall_s"] = round(time.time() - t_wall, 2)
    return g, s, sc


def run(a) -> int:
    """``python -m cosim gps``: exit 1 when the run gives no fix or a fix jump."""
    from .gps_outputs import table
    _, s, _ = process(a)
    rc = 0 if s["fixes"] and not s["fix_jumps"]["count"] else 1
    if a.json:
        print(dumps(s))
        return rc
    print(table(s))
    print("files: " + ", ".join(s["files"]))
    return rc
