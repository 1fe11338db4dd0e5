"""The multi-satellite fast path (:mod:`cosim.gnss.gps_fast`) against the IF path,
statistically, on one generated scenario.

Both paths run the ``gps`` command's generated static scenario
(:mod:`cosim.gnss.gps_scenario`: nominal constellation, the given C/N0 on every satellite,
Saastamoinen troposphere, Klobuchar ionosphere, receiver clock bias and drift), the same
channels (:func:`~cosim.gnss.gps_fast.select_channels`), the same tracker and arithmetic.

* IF path: the recording written as the ``gps`` command writes it (``int8``, the 2-bit
  ``odd:2`` ADC), tracked on the bit-exact channel array
  (:func:`cosim.gnss.multichannel.track_file`, ``run.backend``), every channel handed over
  from the truth at sample 0 (Doppler, code phase: a perfect acquisition). Per channel
  (:func:`cosim.gnss.navigation.channel_navigation`'s records) at each measurement epoch:
  the prompt code phase (its whole code periods from the truth: the hot start's TOW), the
  Doppler, the C/N0, the carrier phase and the lock of the last window -- the series the
  fast path keeps -- and the fixes by the same back end
  (:func:`~cosim.gnss.gps_fast.fixes_from_series`).
* Fast path: :func:`~cosim.gnss.gps_fast.run_fast`, ``trials`` Monte Carlo trials.

Figures after ``settle_s`` (per path, pooled over channels, trials and epochs): the RMS of
the pseudorange error (the replica's code phase against the truth's: the receiver clock is
in both), of the Doppler error, the mean C/N0 and the 3-D position RMS. Each fast/IF
comparison is a test at two-sided level ``alpha``: a ratio of mean squares against the F
distribution with the two paths' *effective* degrees of freedom (:func:`effective_dof`: the epochs of a series are
correlated through the loops, ``nu = N / (1 + 2 sum_k rho_k^2)``, Bartlett's variance of a
sample variance, ``rho`` from the fast path's own series, the better sampled, for both); the C/N0
means by Welch's t. ``python -m cosim bench gps-fast`` records them
(:mod:`cosim.gnss.gps_fast_bench`).
"""
from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from .config import GnssRunConfig
from dsp.gnss.ephemeris import CHIP_M
from .gps_fast import fixes_from_series, run_fast, select_channels
from .gps_receiver import GpsConfig
from .multichannel import TrackConfig

__all__ = ["if_path", "if_series", "compare", "effective_dof", "variance_ratio_test", "figures"]

#: Two-sided level of each fast/IF test.
ALPHA = 0.002


def if_path(spec, out_dir, run: GnssRunConfig = GnssRunConfig(),
            gps: GpsConfig = GpsConfig(rate_hz=10.0), track: TrackConfig = TrackConfig()):
    """The IF path on the generated scenario ``spec`` (module doc): ``(signal, prns, t_m,
    series (M, 1, S), runs, wall_s)``."""
    from .files import SampleFile
    from .gps_scenario import write_scenario
    from .multichannel import Candidate, channel_params_for, track_file
    from .multichannel_session import array_channel_params
    sc = write_scenario(spec, out_dir)
    sig = sc["signal"]
    cols = select_channels(sig, track.channels)
    prns = tuple(sig.prns[j] for j in cols)
    t0 = sig.truth_at(np.array([0.0]))
    cands = [Candidate(sig.prns[j], float(t0.doppler_hz[0, j]),
                       float(t0.code_phase_chips[0, j]), float(t0.cn0_dbhz[0, j]), 0, "truth")
             for j in cols]
    f = SampleFile(sc["file"], "int8", sc["fs_hz"], sc["if_hz"])
    p = array_channel_params(channel_params_for(f), track.channels)
    n = int(round(spec.duration_s * f.fs_hz))
    wall = time.perf_counter()
    m = track_file(f, cands, run, track, n_samples=n)
    wall = time.perf_counter() - wall
    t_m = np.arange(1, int(math.floor(spec.duration_s * gps.rate_hz + 1e-9)) + 1) / gps.rate_hz
    t_m = t_m[t_m < spec.duration_s]
    ser = if_series(m, p, f, sig, prns, t_m)
    runs = fixes_from_series(sig, prns, t_m, ser, gps, sc["ephemerides"], sc["iono"])
    return sig, prns, t_m, ser, runs, wall


def if_series(m, p, f, sig, prns, t_m, *, doppler_instant: bool = False) -> dict:
    """The fast path's series (``code_chips``, ``doppler_hz``, ``cn0_dbhz``,
    ``carrier_cycles``: (M, 1, S), NaN where no channel tracks; ``locked``) of the IF run
    ``m`` (:func:`~cosim.gnss.multichannel.track_file` on ``f``, channel parameters ``p``)
    at the measurement instants ``t_m`` for the satellites ``prns`` of the generated
    signal ``sig`` (module doc). Each assignment fills only the epochs inside its own
    records (a PRN assigned again after a loss keeps both assignments' epochs). The
    Doppler: the report of the record holding the instant, or (``doppler_instant``) the
    tracker's last two reports interpolated linearly to the instant, each tagged at its
    record's prompt boundary plus the tracker's ``doppler_offset_epochs`` epochs (the fast
    path's ``doppler_instant``)."""
    from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH
    from .navigation import channel_navigation
    t_m = np.asarray(t_m, float)
    N = np.round(t_m * f.fs_hz).astype(np.int64)
    tr = sig.truth_at(t_m)
    chi_true = sig.chi0 + CHIP_RATE_HZ * t_m[:, None] - tr.pseudorange_m / CHIP_M
    M, S = t_m.size, len(prns)
    ser = {k: np.full((M, 1, S), np.nan) for k in
           ("code_chips", "doppler_hz", "cn0_dbhz", "carrier_cycles")}
    ser["locked"] = np.zeros((M, 1, S), bool)
    for a in m.assignments:
        if a.prn not in prns:
            continue
        j = list(prns).index(a.prn)
        nav = channel_navigation(a, m, p, reference_week=sig.cfg.week, inverted=False,
                                 if_hz=f.if_hz)
        if nav.g.size < (3 if doppler_instant else 2):
            continue
        k, chips, inside = nav.record_at(N)
        ct = chi_true[:, list(sig.prns).index(a.prn)]
        d = np.mod(chips - ct + CODE_LENGTH / 2, CODE_LENGTH) - CODE_LENGTH / 2
        if doppler_instant:
            dop = np.where(k >= 2, _doppler_at(nav, k, t_m, a.doppler_offset_epochs), np.nan)
        else:
            dop = nav.doppler[np.clip(k, 0, nav.doppler.size - 1)]
        wi = np.searchsorted(nav.win_t, t_m, side="right") - 1
        lk = ((wi >= 0) & nav.win_ok[np.clip(wi, 0, None)]) if nav.win_t.size \
            else np.zeros(M, bool)
        for key, v in (("code_chips", ct + d), ("doppler_hz", dop), ("cn0_dbhz", nav.cn0_at(N)),
                       ("carrier_cycles", -nav.carrier_cycles(N)), ("locked", lk)):
            ser[key][inside, 0, j] = v[inside]
    return ser


def _doppler_at(nav, k, t_m, offset_epochs: float):
    """The tracker's reports after records ``k - 1`` and ``k`` of ``nav`` interpolated to
    ``t_m`` (:func:`if_series`)."""
    fs = nav.fs_hz
    kk = np.clip(k, 2, nav.n_p.size - 1)
    tb = nav.n_p / fs
    tag1 = tb[kk] + offset_epochs * (tb[kk] - tb[kk - 1])
    tag0 = tb[kk - 1] + offset_epochs * (tb[kk - 1] - tb[kk - 2])
    d0, d1 = nav.doppler[kk - 1], nav.doppler[kk]
    return d0 + (d1 - d0) * (t_m - tag0) / (tag1 - tag0)


def effective_dof(x, max_lag: int | None = None) -> float:
    """Effective degrees of freedom of the mean square of ``x`` (M epochs, any series; a
    zero-mean process): ``sum_series M / (1 + 2 sum_{k >= 1} rho_k^2)`` with ``rho`` the
    pooled autocorrelation, summed up to its first non-positive lag (or ``max_lag``,
    default M / 4). Series with a NaN are left out."""
    x = np.asarray(x, np.float64)
    x = x.reshape(x.shape[0], -1)
    x = x[:, np.all(np.isfinite(x), axis=0)]
    M = x.shape[0]
    if x.size == 0 or M < 4:
        raise ValueError("effective_dof needs at least 4 epochs of finite series")
    z = x
    v = np.mean(z * z)
    K = max(1, M // 4 if max_lag is None else int(max_lag))
    s = 0.0
    for k in range(1, K + 1):
        r = np.mean(z[k:] * z[:-k]) / v
        if r <= 0:
            break
        s += r * r
    return float(x.shape[1] * M / (1.0 + 2.0 * s))


def variance_ratio_test(var_a: float, nu_a: float, var_b: float, nu_b: float,
                        alpha: float = ALPHA) -> dict:
    """``var_a / var_b`` against ``F(nu_a, nu_b)`` at two-sided level ``alpha``: the ratio,
    its acceptance interval and whether it lies inside."""
    from scipy.stats import f as fdist
    r = var_a / var_b
    lo, hi = float(fdist.ppf(alpha / 2, nu_a, nu_b)), float(fdist.ppf(1 - alpha / 2, nu_a, nu_b))
    return {"ratio": float(r), "interval": [lo, hi], "dof": [float(nu_a), float(nu_b)],
            "pass": bool(lo <= r <= hi)}


def _settled(t_m, settle_s):
    return np.asarray(t_m) >= settle_s


def _series(e):
    """(M, trials * S): the channels' error series that are finite throughout."""
    e = np.asarray(e, np.float64)
    e = e.reshape(e.shape[0], -1)
    return e[:, np.all(np.isfinite(e), axis=0)]


def figures(t_m, range_err, doppler_err, cn0, pos_err, settle_s: float) -> dict:
    """The figures of one path (module doc) from its (M, trials, S) errors, C/N0 and (M,
    trials) 3-D position errors (each (M, trials, 3) ECEF components)."""
    k = _settled(t_m, settle_s)
    r, d = _series(range_err[k]), _series(doppler_err[k])
    c = np.asarray(cn0[k], float)
    c = c[np.isfinite(c)]
    p = np.asarray(pos_err[k], float)
    p = p[np.all(np.isfinite(p), axis=-1)]
    return {"range_rms_m": float(np.sqrt(np.mean(r * r))),
            "doppler_rms_hz": float(np.sqrt(np.mean(d * d))),
            "cn0_mean_dbhz": float(c.mean()), "cn0_std_db": float(c.std()),
            "cn0_n": int(c.size), "position_rms_m": float(np.sqrt(np.mean(np.sum(p * p, -1)))),
            "fixes": int(p.shape[0]), "epochs_used": int(k.sum())}


def _pos_components(runs, truth_pos):
    M, T = len(runs[0].epochs), len(runs)
    out = np.full((M, T, 3), np.nan)
    for i, g in enumerate(runs):
        for m, e in enumerate(g.epochs):
            if e.solution is not None and e.solution.valid:
                out[m, i] = np.asarray(e.solution.position_ecef_m) - truth_pos[m]
    return out


def compare(spec, out_dir, run: GnssRunConfig = GnssRunConfig(),
            gps: GpsConfig = GpsConfig(rate_hz=10.0), track: TrackConfig = TrackConfig(),
            trials: int = 20, seed: int = 1, settle_s: float = 1.0,
            alpha: float = ALPHA, mai: bool = True) -> dict:
    """Both paths on ``spec`` (module doc); their figures and the tests. ``mai``: the
    fast path models the other satellites' interference (False: to show what the tests
    catch)."""
    sig, prns, t_m, ser_if, runs_if, wall_if = if_path(spec, out_dir, run, gps, track)
    fast = run_fast(sig.cfg, run=run, gps=gps, track=track, trials=trials, seed=seed,
                    signal=sig, mai=mai)
    if fast.prns != prns or fast.t_s.size != t_m.size:
        raise RuntimeError("internal: the two paths did not track the same channels/epochs")
    tr = fast.truth
    chi_t = fast.truth_chips()
    rerr_if = (chi_t[:, None, :] - ser_if["code_chips"]) * CHIP_M
    derr_if = ser_if["doppler_hz"] - tr.doppler_hz[:, None, :]
    pos_if = _pos_components(runs_if, tr.rx_position_m)
    pos_fast = _pos_components(fast.runs, tr.rx_position_m)
    rerr_f, derr_f = fast.range_error_m(), fast.doppler_error_hz()
    fi = figures(t_m, rerr_if, derr_if, ser_if["cn0_dbhz"], pos_if, settle_s)
    ff = figures(t_m, rerr_f, derr_f, fast.series["cn0_dbhz"], pos_fast, settle_s)
    k = _settled(t_m, settle_s)
    tests = {}
    for name, ef, ei in (("range_ms", rerr_f, rerr_if), ("doppler_ms", derr_f, derr_if)):
        zf, zi = _series(ef[k]), _series(ei[k])
        # rho from the fast path's series (H0: the same process), applied to both
        share = effective_dof(zf) / zf.size
        tests[name] = variance_ratio_test(float(np.mean(zf ** 2)), share * zf.size,
                                          float(np.mean(zi ** 2)), share * zi.size, alpha)
    pf = pos_fast[k].reshape(-1, 3)
    pi = pos_if[k].reshape(-1, 3)
    pf, pi = pf[np.all(np.isfinite(pf), 1)], pi[np.all(np.isfinite(pi), 1)]
    zf3 = _series(pos_fast[k])
    share = effective_dof(zf3) / zf3.size
    tests["position_ms"] = variance_ratio_test(float(np.mean(np.sum(pf ** 2, 1))),
                                               share * pf.size, float(np.mean(np.sum(pi ** 2, 1))),
                                               share * pi.size, alpha)
    from scipy.stats import t as tdist
    cf = fast.series["cn0_dbhz"][k]
    cf = cf[np.isfinite(cf)]
    ci = ser_if["cn0_dbhz"][k]
    ci = ci[np.isfinite(ci)]
    se = math.sqrt(cf.var(ddof=1) / cf.size + ci.var(ddof=1) / ci.size)
    dfw = se ** 4 / ((cf.var(ddof=1) / cf.size) ** 2 / (cf.size - 1)
                     + (ci.var(ddof=1) / ci.size) ** 2 / (ci.size - 1))
    half = float(tdist.ppf(1 - alpha / 2, dfw)) * se
    diff = float(cf.mean() - ci.mean())
    tests["cn0_mean"] = {"difference_db": diff, "interval": [-half, half],
                         "pass": bool(abs(diff) <= half)}
    return {"cn0_dbhz": spec.cn0_dbhz, "duration_s": spec.duration_s, "prns": list(prns),
            "trials_fast": trials, "rate_hz": gps.rate_hz, "settle_s": settle_s,
            "tracker": run.tracker, "dsp": run.dsp, "alpha": alpha, "mai": mai,
            "if": {**fi, "wall_s": wall_if, "backend": run.backend},
            "fast": {**ff, "wall_s": fast.wall_s, "track_wall_s": fast.track_wall_s},
            "tests": tests, "all_pass": all(t["pass"] for t in tests.values())}


def scenario(cn0_dbhz: float, duration_s: float, seed: int = 1):
    """The ``gps`` command's generated scenario at ``cn0_dbhz`` for ``duration_s``."""
    from .gps_scenario import ScenarioSpec
    return replace(ScenarioSpec(), cn0_dbhz=float(cn0_dbhz), duration_s=float(duration_s),
                   seed=int(seed))
