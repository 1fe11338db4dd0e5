"""The generated scenario of ``python -m cosim gps``: a receiver, static or moving, under a
GPS constellation (:mod:`cosim.gnss.constellation`), written as a real-IF ``int8`` recording
under ``build/`` with its truth, to be processed through exactly the recording path.

The receiver: static at ``lat_deg, lon_deg, height_m``; or ``trajectory`` ``"ins"``: the INS
paper's along-track profile (:class:`cosim.ins.trajectory.PaperTrajectory`, its defaults: at
rest until 5 s, then 5 g/s to 50 g and on to 8300 m/s) flown east
(:func:`cosim.gnss.constellation_geometry.along_track_receiver`) from that point; or the
path of a CSV of ECEF rows (:func:`cosim.gnss.constellation_geometry.csv_receiver`), which
must cover the record. :func:`scenario_signal` realises the scenario and refuses, before
any sample is written, a motion :func:`~cosim.gnss.constellation_geometry.check_motion`
refuses, no satellite above ``mask_deg``, or fewer than four (no position fix is possible).
The elevation mask is at least the troposphere model's lowest elevation,
:data:`dsp.gnss.atmosphere.TROPO_MIN_ELEVATION_DEG` (3 deg; below it a satellite is silent
and its delay is the 3 deg value). ``bit_error_rate`` flips LNAV bits in the generator
(:class:`cosim.gnss.constellation.ConstellationConfig`); the truth lists the flipped bits'
transmit times per PRN.

Defaults: the nominal 24-satellite constellation (:func:`dsp.gnss.nominal_orbits.
nominal_constellation`, toe at the start of day 4 of ``week``) or a RINEX navigation file's
ephemerides; C/N0 the same for every satellite (``Cn0Model(cn0, 0)``); Saastamoinen's
troposphere at the receiver's height in the signal (the receiver applies the same model;
heights within :data:`dsp.gnss.atmosphere.TROPO_HEIGHT_RANGE_M`) and Klobuchar's ionosphere
at its place; a receiver
clock with a bias and a drift. The start time is chosen so that a subframe edge reaches the
receiver ``edge_after_s`` (0.5 s) into the record: the first subframe is then whole and its
TOW known 7.7 s in, so an 8 s record gives a hot-start fix.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pymap3d

from dsp.gnss.atmosphere import TROPO_MIN_ELEVATION_DEG, klobuchar_delay_m, \
    saastamoinen_delay_m
from dsp.gnss.ephemeris import KlobucharParameters

__all__ = ["ScenarioSpec", "scenario_config", "scenario_signal", "write_scenario",
           "NOMINAL_WEEK", "NOMINAL_TOE", "NOMINAL_KLOBUCHAR", "TRAJECTORIES", "MIN_SATELLITES"]

NOMINAL_WEEK = 2300
NOMINAL_TOE = 345_600.0
#: The Klobuchar coefficients broadcast with the nominal constellation (typical values).
NOMINAL_KLOBUCHAR = KlobucharParameters((1.118e-8, 7.451e-9, -5.96e-8, -5.96e-8),
                                        (90112.0, 0.0, -196608.0, -65536.0))
#: Nominal travel time (s) used to place the first subframe edge.
_TRAVEL_S = 0.075
#: The named trajectories (besides a CSV path).
TRAJECTORIES = ("ins",)
#: Satellites a position fix needs.
MIN_SATELLITES = 4


@dataclass(frozen=True)
class ScenarioSpec:
    """A generated scenario (module doc)."""

    lat_deg: float = 52.0
    lon_deg: float = 4.4
    height_m: float = 30.0
    duration_s: float = 8.0
    cn0_dbhz: float = 45.0
    seed: int = 1
    fs_hz: float = 5e6
    if_hz: float = 1.25e6
    week: int = NOMINAL_WEEK
    tow_s: float | None = None           #: None: NOMINAL_TOE + 60 s, moved to put an edge
    edge_after_s: float = 0.5
    clock_bias_s: float = 3e-4
    clock_drift: float = 5e-8
    nav_file: str | None = None           #: a RINEX navigation file (None: nominal)
    mask_deg: float = 10.0                #: elevation mask, >= TROPO_MIN_ELEVATION_DEG (3)
    bit_error_rate: float = 0.0           #: LNAV bits flipped (probability per bit)
    trajectory: str | None = None         #: None (static), "ins" or an ECEF CSV path


def _start_tow(spec: ScenarioSpec, first_tow: float) -> float:
    """The receiver's reading at sample 0: a subframe edge arrives ``edge_after_s`` in."""
    edge = 6.0 * np.ceil((first_tow + spec.edge_after_s) / 6.0)
    return float(edge - spec.edge_after_s + _TRAVEL_S + spec.clock_bias_s)


def _klobuchar(lat, lon, az, el, t, k):
    """The Klobuchar delay (m) at the rows of times ``t`` (T, S), the receiver at ``lat``,
    ``lon`` (T, S) (the model takes one time and place per call)."""
    el = np.maximum(np.asarray(el, dtype=np.float64), 0.0)
    out = np.empty(el.shape)
    for i in range(el.shape[0]):
        out[i] = klobuchar_delay_m(float(lat[i, 0]), float(lon[i, 0]), el[i], az[i],
                                   float(np.mod(t[i, 0], 604800.0)), k.alpha, k.beta)
    return out


def _saastamoinen(lat, el, h):
    """Saastamoinen's delay (m) at the rows of elevations ``el`` (T, S), the receiver at
    heights ``h`` (T, S) and latitude ``lat`` (the start's: the model's latitude term moves
    the zenith delay by millimetres over a flight), elevations below the model's lowest
    taken at it (module doc)."""
    el = np.maximum(np.asarray(el, dtype=np.float64), TROPO_MIN_ELEVATION_DEG)
    out = np.empty(el.shape)
    for i in range(el.shape[0]):
        out[i] = saastamoinen_delay_m(lat, float(h[i, 0]), el[i])
    return out


def _receiver(spec: ScenarioSpec):
    from .constellation_geometry import StaticReceiver, along_track_receiver, csv_receiver
    if spec.trajectory is None:
        return StaticReceiver.geodetic(spec.lat_deg, spec.lon_deg, spec.height_m)
    if spec.trajectory == "ins":
        from ..ins.trajectory import PaperTrajectory
        return along_track_receiver(PaperTrajectory(), spec.lat_deg, spec.lon_deg,
                                    spec.height_m, 90.0)
    rx = csv_receiver(spec.trajectory, "--trajectory")
    t0, t1 = rx.span_s
    if t0 > 0.0 or t1 < spec.duration_s:
        raise ValueError(f"--trajectory {spec.trajectory!r} covers {t0:g} .. {t1:g} s: it must "
                         f"cover the record, 0 .. {spec.duration_s:g} s")
    return rx


def scenario_config(spec: ScenarioSpec):
    """``(ConstellationConfig, KlobucharParameters)`` of the scenario ``spec`` (module doc);
    the coefficients are those broadcast and in the signal."""
    from dsp.gnss.nominal_orbits import nominal_constellation

    from .constellation import ConstellationConfig
    from .constellation_geometry import Cn0Model, ReceiverClock
    from .rinex_nav import read_rinex_nav
    iono = NOMINAL_KLOBUCHAR
    if spec.nav_file is not None:
        nav = read_rinex_nav(spec.nav_file)
        ephs = nav.ephemerides
        e0 = min(ephs, key=lambda e: (e.week, e.toe))
        week, tow0 = int(e0.week), float(e0.toe)
        iono = nav.iono or NOMINAL_KLOBUCHAR
    else:
        ephs = nominal_constellation(spec.week, NOMINAL_TOE)
        week, tow0 = spec.week, NOMINAL_TOE + 60.0
    tow = _start_tow(spec, tow0 if spec.tow_s is None else spec.tow_s)
    lat = spec.lat_deg
    iono = iono.quantised()
    cfg = ConstellationConfig(
        ephs, week, tow, _receiver(spec), fs_hz=spec.fs_hz, if_hz=spec.if_hz,
        complex_output=False, duration_s=spec.duration_s,
        clock=ReceiverClock(spec.clock_bias_s, spec.clock_drift),
        cn0=Cn0Model(spec.cn0_dbhz, 0.0),
        tropo=lambda el, h: _saastamoinen(lat, el, h),
        iono=lambda la, lo, az, el, t: _klobuchar(la, lo, az, el, t, iono),
        klobuchar=iono, seed=spec.seed, mask_deg=spec.mask_deg,
        bit_error_rate=spec.bit_error_rate)
    return cfg, iono


def scenario_signal(spec: ScenarioSpec, prns=None):
    """``(ConstellationSignal, KlobucharParameters)`` of ``spec``, refused (module doc) when
    fewer than :data:`MIN_SATELLITES` of the satellites above the mask (of ``prns``, the
    PRNs the receiver searches, when given) are in it; no sample is computed."""
    from .constellation import ConstellationSignal
    cfg, iono = scenario_config(spec)
    try:
        sig = ConstellationSignal(cfg)
    except ValueError as e:
        if "elevation mask" in str(e):
            raise ValueError(f"--elevation-mask-deg {spec.mask_deg:g}: {e}") from None
        raise
    grid = np.append(np.arange(0.0, spec.duration_s, 1.0), spec.duration_s)
    try:
        sig.truth_at(grid)              # the atmosphere models along the receiver's path
    except ValueError as e:
        if spec.trajectory is None:
            raise
        raise ValueError(f"--trajectory {spec.trajectory}: {e}") from None
    seen = [p for p in sig.prns if prns is None or p in prns]
    if len(seen) < MIN_SATELLITES:
        raise ValueError(f"only {len(seen)} satellite(s) above the {spec.mask_deg:g} deg "
                         f"elevation mask (--elevation-mask-deg)"
                         + ("" if prns is None else " among --prns") + f": "
                         f"{['G%02d' % p for p in seen]}; a position fix needs "
                         f"{MIN_SATELLITES}")
    return sig, iono


def write_scenario(spec: ScenarioSpec, out_dir, signal=None) -> dict:
    """Write the recording ``scenario.int8`` and ``truth.json`` to ``out_dir``; return the
    recording's file options, the generator's ephemerides (for a hot start), the truth
    (receiver ECEF and geodetic position at sample 0, the trajectory, clock, flipped bits)
    and the realised signal. ``signal``: the ``(ConstellationSignal, KlobucharParameters)`` of
    :func:`scenario_signal` when already made."""
    from .constellation import write_constellation
    sig, iono = scenario_signal(spec) if signal is None else signal
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = sig.cfg
    week, tow = cfg.week, cfg.tow_s
    path = out / "scenario.int8"
    write_constellation(path, "int8", sig)
    tr = sig.truth_at(np.array([0.0]))
    flips = sig.flipped_bits()
    lat, lon, h = (float(x) for x in pymap3d.ecef2geodetic(*tr.rx_position_m[0]))
    truth = {"receiver_ecef_m": [float(x) for x in tr.rx_position_m[0]],
             "lat_deg": lat, "lon_deg": lon, "height_m": h,
             "trajectory": spec.trajectory,
             "week": week, "tow_at_sample0_s": tow, "clock_bias_s": spec.clock_bias_s,
             "clock_drift": spec.clock_drift, "prns": list(sig.prns),
             "cn0_dbhz": spec.cn0_dbhz, "seed": spec.seed, "duration_s": spec.duration_s,
             "mask_deg": spec.mask_deg,
             "bit_errors": {"rate": spec.bit_error_rate,
                            "flipped": sum(len(v) for v in flips.values()),
                            "flipped_tow_s": {f"G{p:02d}": v for p, v in flips.items()}}}
    (out / "truth.json").write_text(json.dumps(truth, indent=1))
    return {"file": str(path), "format": "int8", "fs_hz": spec.fs_hz, "if_hz": spec.if_hz,
            "week": week, "ephemerides": tuple(sig.ephemerides),
            "iono": iono, "truth": truth, "signal": sig}
