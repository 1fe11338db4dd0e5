"""The INS paper's Table 2 loops on the IF path: the scenario of :mod:`cosim.ins.table2`
recorded as the ``gps`` command records it and tracked on the bit-exact 12-channel array
model (:func:`cosim.gnss.multichannel.track_file`, backend ``model``, the trackers in fixed
point), every channel aided as on the fast path -- the check of the fast path against the
full IF path on this scenario.

Scenario and window
-------------------
:meth:`Table2Config.spec` over the first ``if_window_s`` of the trajectory (the same
trajectory, constellation, clock and seed as the fast path's 150 s: the scenario does not
depend on its length), written to ``scenario.int8`` by
:func:`cosim.gnss.gps_scenario.write_scenario` (2-bit real IF, 5 MS/s); the table's
satellites (:func:`~cosim.ins.table2.table2_signal`), one channel each, handed over from the
truth at sample 0 (Doppler, code phase: a perfect acquisition, as the fast path's hot start
and :func:`cosim.gnss.gps_fast_check.if_path`). The tracking stops ``AIDING_TAIL_S`` before the
record's end (the loops ask for the aiding of the next two epochs).

Aiding
------
Each channel's tracker is built with the aiding of :meth:`ChannelAiding.channel
<cosim.ins.table2.ChannelAiding.channel>` (``track_file``'s ``tracker_setup``): the fast
path's table -- the truth's Doppler rate plus the INS errors of Monte Carlo run 0 projected
on that satellite's line of sight -- at the midpoints of the received code epochs from the
channel's first tracked epoch. The first tracked record's boundary is checked against that
table's epochs (``aiding_epoch_offset_us``: the code tracking error, < 1 us; over 50 us
is an internal error).

Observables and fixes
---------------------
The series of :func:`cosim.gnss.gps_fast_check.if_series` (the fast path's series from the
IF run, each assignment on its own epochs, so the two paths are scored alike) with
``doppler_instant``: the Doppler interpolated to the measurement instant as the fast path's;
the fixes by :func:`cosim.gnss.gps_fast.fixes_from_series`; errors on ECEF
x, y, z, vx, vy, vz against the truth.

Comparison (:func:`compare_if`)
-------------------------------
On the epochs after ``settle_s`` where the IF run has a fix, per loop and axis: the IF
run's mean and standard deviation of the error over those epochs, and the same statistic of
each fast-path Monte Carlo run over the same epochs; the IF value is *inside* the fast
path's distribution when ``|z| <= Z_INSIDE`` (``z``: its distance from the runs' mean in
runs' standard deviations); its percentile among the runs is given too.
"""
from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from dsp.gnss.ca_code import CODE_PERIOD_S

from .table2 import AIDING_TAIL_S, AXES, ChannelAiding, Table2Config, table2_signal, \
    tracker_options

__all__ = ["write_if_scenario", "run_if_loop", "compare_if", "Z_INSIDE"]

#: The IF value is inside the fast path's distribution within this many standard deviations.
Z_INSIDE = 3.0


def _window_cfg(cfg: Table2Config) -> Table2Config:
    if not cfg.if_window_s > 0:
        raise ValueError("if_window_s is 0: no IF run configured")
    return replace(cfg, duration_s=float(cfg.if_window_s), runs=1)


def write_if_scenario(cfg: Table2Config, out_dir) -> dict:
    """Write the window's recording under ``out_dir`` (module doc); ``{"file", "fs_hz",
    "if_hz", "prns", "wall_s"}``."""
    from ..gnss.gps_scenario import scenario_signal, write_scenario
    t = time.perf_counter()
    w = _window_cfg(cfg)
    sig, cols, _ = table2_signal(w)
    sc = write_scenario(w.spec(), Path(out_dir), scenario_signal(w.spec()))
    return {"file": sc["file"], "fs_hz": sc["fs_hz"], "if_hz": sc["if_hz"],
            "prns": [int(sig.prns[j]) for j in cols], "wall_s": time.perf_counter() - t}


def run_if_loop(cfg: Table2Config, loop: str, rec: dict) -> dict:
    """One run of ``loop`` on the recording ``rec`` of :func:`write_if_scenario` (module
    doc): ``{"t_s", "err" (M, 6), "lock", "aiding_epoch_offset_us", "assignments",
    "wall_s", "signal_s"}``."""
    from ..gnss.config import GnssRunConfig
    from ..gnss.files import SampleFile
    from ..gnss.gps_fast import fixes_from_series
    from ..gnss.gps_fast_check import if_series
    from ..gnss.gps_receiver import GpsConfig
    from ..gnss.multichannel import Candidate, TrackConfig, channel_params_for, track_file
    from ..gnss.multichannel_session import array_channel_params
    w = _window_cfg(cfg)
    sig, cols, _ = table2_signal(w)
    prns = tuple(int(sig.prns[j]) for j in cols)
    if list(prns) != list(rec["prns"]):
        raise ValueError(f"the recording's satellites {rec['prns']} are not the table's {prns}")
    S = len(prns)
    t0 = sig.truth_at(np.array([0.0]))
    cands = [Candidate(sig.prns[j], float(t0.doppler_hz[0, j]),
                       float(t0.code_phase_chips[0, j]), float(t0.cn0_dbhz[0, j]), 0, "truth")
             for j in cols]
    aid = ChannelAiding(sig, cols, 1, cfg.seed, step_s=cfg.ins_step_s) \
        if loop != "unaided-kf" else None
    given = []                  # per assignment (track_file makes one per setup call)

    def setup(prn, t_first_s):
        ctx = {}
        if aid is not None:
            ctx["aiding"] = aid.channel(prns.index(prn), t_first_s)
        given.append(ctx.get("aiding"))
        return ctx, tracker_options(loop, cfg)

    f = SampleFile(rec["file"], "int8", rec["fs_hz"], rec["if_hz"])
    fs = f.fs_hz
    p = array_channel_params(channel_params_for(f), S)
    n = int(round((w.duration_s - AIDING_TAIL_S) * fs))
    run = GnssRunConfig(tracker=loop, dsp="fixed", backend="model")
    wall = time.perf_counter()
    m = track_file(f, cands, run, TrackConfig(channels=S), n_samples=n, tracker_setup=setup)
    wall = time.perf_counter() - wall
    t_m = np.arange(1, int(math.floor(w.duration_s * cfg.rate_hz + 1e-9)) + 1) / cfg.rate_hz
    t_m = t_m[t_m < n / fs]
    M = t_m.size
    tr = sig.truth_at(t_m)
    if len(given) != len(m.assignments):
        raise RuntimeError("internal: the tracker setups and the assignments do not pair")
    offset = 0.0             # each assignment's first tracked epoch against its aiding's
    for a, g in zip(m.assignments, given):
        if g is not None and a.t:
            offset = max(offset, abs(a.t[0] - g.mid_s[0] - CODE_PERIOD_S / 2))
    ser = if_series(m, p, f, sig, prns, t_m, doppler_instant=True)
    if offset * 1e6 > 50.0:
        raise RuntimeError(f"internal: a channel's first tracked epoch is {offset * 1e6:.1f} us "
                           f"off the aiding's epochs")
    runs = fixes_from_series(sig, prns, t_m, ser, GpsConfig(rate_hz=cfg.rate_hz))
    err = np.full((M, 6), np.nan)
    for i, e in enumerate(runs[0].epochs):
        if e.solution is not None and e.solution.valid:
            err[i, :3] = np.asarray(e.solution.position_ecef_m) - tr.rx_position_m[i]
            err[i, 3:] = np.asarray(e.solution.velocity_ecef_mps) - tr.rx_velocity_mps[i]
    lk = ser["locked"][t_m >= cfg.settle_s, 0]
    lock = {"losses": int(np.sum(lk[:-1] & ~lk[1:])), "unlocked_channel_epochs": int(np.sum(~lk)),
            "channel_epochs": int(lk.size),
            "fixes_missing": int(np.sum(~np.isfinite(err[t_m >= cfg.settle_s, 0])))}
    return {"loop": loop, "t_s": t_m, "err": err, "lock": lock,
            "aiding_epoch_offset_us": offset * 1e6 if any(g is not None for g in given) else None,
            "assignments": [{"prn": a.prn, "channel": a.channel, "status": a.status,
                             "end_reason": a.end_reason} for a in m.assignments],
            "digest": m.pipeline.digest if hasattr(m.pipeline, "digest") else None,
            "wall_s": wall, "signal_s": n / fs, "backend": run.backend, "dsp": run.dsp}


def compare_if(ifr: dict, t_fast, err_fast, settle_s: float) -> dict:
    """The IF run ``ifr`` (:func:`run_if_loop`) against the fast path's Monte Carlo errors
    ``err_fast`` (M, runs, 6) at ``t_fast`` on the IF run's fixed epochs after ``settle_s``
    (module doc)."""
    t_if, e_if = np.asarray(ifr["t_s"]), np.asarray(ifr["err"])
    use = (t_if >= settle_s) & np.isfinite(e_if[:, 0])
    tf = np.asarray(t_fast)
    idx = [int(np.flatnonzero(np.isclose(tf, t))[0]) if np.any(np.isclose(tf, t)) else -1
           for t in t_if[use]]
    if len(idx) < 2 or min(idx) < 0:
        raise ValueError("the IF run needs >= 2 fixes after settle_s on the fast path's epochs")
    ef = np.asarray(err_fast)[idx]                        # (E, runs, 6)
    ei = e_if[use]                                        # (E, 6)
    out = {"epochs_s": [float(x) for x in t_if[use]], "axes": {}}
    for stat, fn in (("mean", lambda x, a: np.nanmean(x, axis=a)),
                     ("std", lambda x, a: np.nanstd(x, axis=a, ddof=1))):
        v_if, v_fast = fn(ei, 0), fn(ef, 0)               # (6,), (runs, 6)
        for i, ax in enumerate(AXES):
            runs = v_fast[:, i]
            mu, sd = float(np.mean(runs)), float(np.std(runs, ddof=1))
            z = (float(v_if[i]) - mu) / sd if sd > 0 else math.inf
            out["axes"].setdefault(ax, {})[stat] = {
                "if": float(v_if[i]), "fast_mean": mu, "fast_std": sd,
                "fast_min": float(runs.min()), "fast_max": float(runs.max()),
                "z": z, "percentile": float(100 * np.mean(runs < v_if[i])),
                "inside": bool(abs(z) <= Z_INSIDE)}
    flags = [out["axes"][ax][s]["inside"] for ax in AXES for s in ("mean", "std")]
    out["inside"], out["tests"] = int(sum(flags)), len(flags)
    return out
