"""The INS paper's Table 2 on the multi-satellite receiver: position and velocity errors of
the full PVT solution on ECEF x, y, z for the three carrier loops (``aided-kf``,
``aided-pll``, ``unaided-kf``), on the correlation-domain fast path
(:func:`cosim.gnss.gps_fast.run_fast`).

Scenario
--------
:class:`~cosim.gnss.gps_scenario.ScenarioSpec` with ``trajectory="ins"``: the paper's
along-track profile (:class:`cosim.ins.trajectory.PaperTrajectory`: 150 s, 5 g/s to 50 g,
8300 m/s) flown east from ``lat_deg, lon_deg, height_m`` under the nominal 24-satellite
constellation, one C/N0 for every satellite. Every satellite above the mask at the start is
a channel; :func:`table2_signal` refuses the scenario (``ValueError``, before any tracking)
when fewer than ``min_satellites`` of them stay above the mask for the whole run, or when one
of them sets during it (its channel would lose the signal).

Aiding
------
Per channel ``j`` and tracked epoch ``k`` the Doppler rate the INS predicts at the epoch's
midpoint: the truth's Doppler rate (the numerical derivative of the generator's Doppler on
the INS grid, ``ins_step_s``) plus the INS error's effect,
``doppler_rate(R + dp, V + dv, A + da, Rs, Vs, As) - doppler_rate(R, V, A, Rs, Vs, As)``
(:func:`cosim.ins.trajectory.doppler_rate_hz_s`, satellites from their broadcast ephemeris
at the transmit time). The INS errors are :mod:`cosim.ins.ins_error`'s model
(:func:`~cosim.ins.ins_error.acceleration_error_enu`: gyro drift, accelerometer bias, random
walks) with the specific force ``f = A - g`` in the local east-north-up frame at the
receiver's current place (a level platform heading east), one realisation per Monte Carlo
run (seed ``(seed, run)``), the same for the three loops (paired runs). The epoch midpoints
are the truth's: channel ``j``'s epoch ``k`` spans the received code phases ``c_j + 1023 k``
to ``c_j + 1023 (k + 1)`` chips (``c_j`` the first code epoch after the start, where
:func:`run_fast` starts the channel), within the code tracking error (< 1 us) of the
replica's.

Receiver
--------
:func:`run_fast` with every channel on the loop (``dsp``: its arithmetic), the fast path's
lock detector, and the Doppler of each measurement interpolated to the measurement instant
(``doppler_instant``: at 50 g a 1 ms time-tag error is 0.5 m/s of velocity, and the PLL's
Doppler report stands half an epoch later than the Kalman loop's). The ``oscillator``
(``tcxo``, ``ocxo``, None) is the Kalman loops' process-noise model; the scenario's receiver
clock is a bias and a drift, with no phase noise.

Figures
-------
Per loop and run, the fixes at ``rate_hz`` after ``settle_s``: error = fix minus truth on
ECEF x, y, z (position, m; velocity, m/s); per run the mean and standard deviation over the
epochs; the table gives the mean over runs of the per-run means and of the per-run stds
(the paper's std is over the epochs of its run) and their standard errors over runs. Lock:
the lock detector of the fast path (:class:`dsp.gnss.loops.LockDetector`) at every
measurement epoch after ``settle_s``: lock losses (a locked channel found unlocked),
unlocked channel-epochs, fixes missing. The verdicts are :func:`judge_claims`'.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import pymap3d

from dsp.gnss.ca_code import CODE_PERIOD_S

from ..core.validate import check_float, check_int
from .ins_error import InsErrors, acceleration_error_enu, integrate_errors
from .trajectory import G_MPS2, doppler_rate_hz_s

__all__ = ["Table2Config", "PAPER_TABLE2", "CLAIMS", "table2_signal", "ChannelAiding",
           "ins_tracker_setup", "AIDING_TAIL_S",
           "run_loop", "tracker_options", "EpochRates", "error_table", "judge_claims", "LOOPS", "AXES"]

LOOPS = ("unaided-kf", "aided-pll", "aided-kf")
AXES = ("x", "y", "z", "vx", "vy", "vz")
#: The paper's Table 2 (its decimals restored; units not given, presumably m and m/s;
#: docs/explanation/ins.md).
PAPER_TABLE2 = {
    "mean": {"unaided-kf": (0.725, 3.806, 0.914, 0.068, -0.077, 0.003),
             "aided-pll": (0.701, 3.803, 0.931, 0.118, -0.066, 0.002),
             "aided-kf": (0.707, 3.783, 0.913, 0.068, -0.076, 0.002)},
    "std": {"unaided-kf": (2.670, 2.431, 0.990, 0.043, 0.201, 0.007),
            "aided-pll": (2.728, 2.461, 1.022, 0.080, 0.125, 0.025),
            "aided-kf": (2.686, 2.425, 0.993, 0.038, 0.120, 0.007)}}
#: The paper's two claims: the aided Kalman loop's error std lower than the aided PLL's
#: by at least ``min_pct`` on each of ``axes``.
CLAIMS = ({"name": "claim 1", "text": "aided KF 2-3 % lower position error std than aided PLL",
           "axes": ("x", "y", "z"), "min_pct": 2.0},
          {"name": "claim 2", "text": "aided KF 4-72 % lower velocity error std than aided PLL",
           "axes": ("vx", "vy", "vz"), "min_pct": 4.0})


@dataclass(frozen=True)
class Table2Config:
    """The Table 2 scenario and its Monte Carlo (module doc)."""

    cn0_dbhz: float = 40.0
    oscillator: str | None = "ocxo"
    duration_s: float = 150.0
    runs: int = 20
    seed: int = 3
    lat_deg: float = 52.0
    lon_deg: float = 4.4
    height_m: float = 30.0
    #: receiver TOW at the start: the nominal toe + 3000 s, where the 6 satellites above the
    #: mask at 52 N 4.4 E stay above it through the run (None: the scenario's default)
    tow_s: float | None = 348_600.0
    mask_deg: float = 10.0
    min_satellites: int = 6
    rate_hz: float = 1.0
    settle_s: float = 5.0
    dsp: str = "float"
    ins_step_s: float = 0.01
    pli_epochs: int = 20
    #: Monte Carlo runs per task of the engine (:mod:`cosim.studies.engine`)
    chunk_runs: int = 10
    #: the bit-exact IF run: the first ``if_window_s`` of the scenario (0: none; 35 s
    #: holds the whole manoeuvre, 5-32 s)
    if_window_s: float = 35.0
    #: the C/N0 threshold search: runs, scenario length, bracket and resolution (dB-Hz)
    threshold_runs: int = 4
    threshold_duration_s: float = 40.0
    threshold_lo_dbhz: float = 24.0
    threshold_hi_dbhz: float = 44.0
    threshold_step_db: float = 1.0

    def __post_init__(self):
        check_float("cn0_dbhz", self.cn0_dbhz, 20.0, 60.0, unit="dB-Hz")
        check_float("duration_s", self.duration_s, 0.0, 150.0, lo_open=True, unit="s")
        check_int("runs", self.runs, 1, 100_000)
        check_int("seed", self.seed, 0)
        check_int("min_satellites", self.min_satellites, 4, 32)
        check_float("rate_hz", self.rate_hz, 0.0, 50.0, lo_open=True, unit="Hz")
        check_float("settle_s", self.settle_s, 0.0, self.duration_s, unit="s")
        check_float("ins_step_s", self.ins_step_s, 0.0, 0.1, lo_open=True, unit="s")
        check_int("chunk_runs", self.chunk_runs, 1, 100_000)
        check_float("if_window_s", self.if_window_s, 0.0, 150.0, unit="s")
        if 0 < self.if_window_s <= self.settle_s + 1:
            raise ValueError(f"if_window_s {self.if_window_s:g} s holds no fix after settle_s "
                             f"{self.settle_s:g} s (0: no IF run)")
        check_int("threshold_runs", self.threshold_runs, 0, 100_000)
        check_float("threshold_duration_s", self.threshold_duration_s, self.settle_s + 1,
                    150.0, unit="s")
        check_float("threshold_lo_dbhz", self.threshold_lo_dbhz, 20.0, 60.0, unit="dB-Hz")
        check_float("threshold_hi_dbhz", self.threshold_hi_dbhz, self.threshold_lo_dbhz, 60.0,
                    lo_open=True, unit="dB-Hz")
        check_float("threshold_step_db", self.threshold_step_db, 0.0, 20.0, lo_open=True,
                    unit="dB")
        if self.oscillator not in (None, "tcxo", "ocxo"):
            raise ValueError(f"oscillator must be tcxo, ocxo or None, not {self.oscillator!r}")
        if self.dsp not in ("float", "fixed"):
            raise ValueError(f"dsp must be float or fixed, not {self.dsp!r}")

    def spec(self):
        from ..gnss.gps_scenario import ScenarioSpec
        return ScenarioSpec(lat_deg=self.lat_deg, lon_deg=self.lon_deg, height_m=self.height_m,
                            duration_s=self.duration_s, cn0_dbhz=self.cn0_dbhz, seed=self.seed,
                            mask_deg=self.mask_deg, trajectory="ins", tow_s=self.tow_s)


def table2_signal(cfg: Table2Config):
    """``(ConstellationSignal, channels, info)``: the realised scenario, the indices (into
    ``sig.prns``) of the satellites tracked, and the satellites' record (PRNs, elevations at
    start and end). Refused (module doc) with too few satellites in view."""
    from ..gnss.gps_scenario import scenario_signal
    sig, _ = scenario_signal(cfg.spec())
    grid = np.append(np.arange(0.0, cfg.duration_s, 1.0), cfg.duration_s)
    tr = sig.truth_at(grid)
    up0 = np.flatnonzero(tr.sounding[0])
    stays = up0[tr.sounding[:, up0].all(axis=0)]
    name = ["G%02d" % p for p in sig.prns]
    if stays.size < cfg.min_satellites:
        raise ValueError(f"only {stays.size} satellite(s) stay above the {cfg.mask_deg:g} deg mask "
                         f"for the whole {cfg.duration_s:g} s ({[name[j] for j in stays]}); the "
                         f"table needs {cfg.min_satellites}: choose another place or time")
    if stays.size < up0.size:
        gone = [name[j] for j in up0 if j not in stays]
        raise ValueError(f"satellite(s) {gone} set below the {cfg.mask_deg:g} deg mask during the "
                         f"run: their channels would lose the signal; choose another place or time")
    info = {"prns": [name[j] for j in up0],
            "elevation_start_deg": [round(float(x), 2) for x in tr.elevation_deg[0, up0]],
            "elevation_end_deg": [round(float(x), 2) for x in tr.elevation_deg[-1, up0]],
            "min_in_view": int(tr.sounding[:, up0].sum(axis=1).min())}
    return sig, up0, info


class ChannelAiding:
    """``aiding(k)`` of :func:`run_fast` (module doc): the INS Doppler rate (Hz/s) of every
    (run, channel) at the midpoint of the channel's epoch ``k``, shape (runs, S)."""

    def __init__(self, sig, cols, runs: int, seed: int, errors: InsErrors | None = None,
                 step_s: float = 0.01, first_run: int = 0):
        from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH
        from dsp.gnss.ephemeris import satellite_position_velocity, select_ephemeris

        from dsp.gnss.ephemeris import CHIP_M
        err = errors or InsErrors()
        dur = sig.cfg.duration_s
        h = float(step_s)
        n = int(math.floor(dur / h)) + 1
        s = np.arange(n) * h                                  # the INS grid (receiver time)
        tr = sig.truth_at(s)
        cols = np.asarray(cols, np.int64)
        S = cols.size
        # truth's Doppler rate per satellite
        self.true_rate = np.gradient(tr.doppler_hz[:, cols], h, axis=0)      # (n, S)
        # receiver and satellite kinematics (ECEF), frame per point
        rx = sig.cfg.receiver
        d = 1e-3
        R, V = tr.rx_position_m, tr.rx_velocity_mps
        _, v1 = rx.state(s + d)
        _, v0 = rx.state(s - d)
        A = (v1 - v0) / (2 * d)
        lat, lon, _ = pymap3d.ecef2geodetic(R[:, 0], R[:, 1], R[:, 2])
        la, lo = np.radians(lat), np.radians(lon)
        C = np.stack([np.stack([-np.sin(lo), np.cos(lo), 0 * lo], -1),       # (n, 3, 3) ECEF->ENU
                      np.stack([-np.sin(la) * np.cos(lo), -np.sin(la) * np.sin(lo), np.cos(la)], -1),
                      np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], -1)], 1)
        f_enu = (np.einsum("nij,nj->ni", C, A) + np.array([0.0, 0.0, G_MPS2])).T
        ephs = [select_ephemeris(sig.ephemerides, int(sig.prns[j]), sig.cfg.week,
                                 float(tr.t_tx[0, j])) for j in cols]
        Rs, Vs = satellite_position_velocity(ephs, tr.t_tx[:, cols])          # (n, S, 3)
        _, Vs1 = satellite_position_velocity(ephs, tr.t_tx[:, cols] + d)
        _, Vs0 = satellite_position_velocity(ephs, tr.t_tx[:, cols] - d)
        As = (Vs1 - Vs0) / (2 * d)
        self.delta = np.empty((n, runs, S))
        for r in range(runs):
            da = np.einsum("nji,jn->in", C, acceleration_error_enu(
                f_enu, h, err, _run_seed(seed, first_run + r)))
            dv, dp = integrate_errors(da, h)
            for j in range(S):
                rs, vs, as_ = Rs[:, j].T, Vs[:, j].T, As[:, j].T
                self.delta[:, r, j] = (doppler_rate_hz_s(R.T + dp, V.T + dv, A.T + da, rs, vs, as_)
                                       - doppler_rate_hz_s(R.T, V.T, A.T, rs, vs, as_))
        # the channels' epoch midpoints: received code phase = c_j + 1023 (k + 1/2)
        chi = sig.chi0 + CHIP_RATE_HZ * s[:, None] - tr.pseudorange_m[:, cols] / CHIP_M
        c0 = CODE_LENGTH * np.ceil(chi[0] / CODE_LENGTH)
        K = int(math.floor((chi[-1] - c0).min() / CODE_LENGTH)) - 1
        kk = c0[None, :] + CODE_LENGTH * (np.arange(K)[:, None] + 0.5)
        self.mid = np.stack([np.interp(kk[:, j], chi[:, j], s) for j in range(S)], 1)  # (K, S)
        self.tab = self.true_rate[:, None, :] + self.delta                 # (n, runs, S)
        self.h, self.n, self.S = h, n, S
        self._cols = np.arange(S)

    def rate(self, s_mid):
        """(runs, S): the INS Doppler rate at the times ``s_mid`` (S,) of each channel."""
        u = np.asarray(s_mid) / self.h
        i = np.clip(np.floor(u).astype(np.int64), 0, self.n - 2)
        w = u - i
        tab, c = self.tab, self._cols
        return (tab[i, :, c] * (1 - w)[:, None] + tab[i + 1, :, c] * w[:, None]).T

    def channel(self, j: int, t_first_s: float, run: int = 0):
        """``aiding(k)`` of one channel of the IF path (column ``j``, Monte Carlo run
        ``run``) whose first tracked epoch starts at ``t_first_s`` (s; within a quarter of
        an epoch): the rate of :meth:`rate` at the midpoints of the received code epochs
        from that one on, the same table and formula as the fast path's."""
        T = CODE_PERIOD_S
        i0 = int(np.argmin(np.abs(self.mid[:, j] - T / 2 - t_first_s)))
        if abs(self.mid[i0, j] - T / 2 - t_first_s) > T / 4:
            raise ValueError(f"no received code epoch starts near {t_first_s:.6f} s "
                             f"(channel {j}): outside the aiding's table")
        u = self.mid[i0:, j] / self.h
        i = np.clip(np.floor(u).astype(np.int64), 0, self.n - 2)
        w = u - i
        rates = self.tab[i, run, j] * (1 - w) + self.tab[i + 1, run, j] * w
        return EpochRates(rates, self.mid[i0:, j])

    def __call__(self, k):
        if not 0 <= k < self.mid.shape[0]:
            raise ValueError(f"aiding asked for epoch {k}: the run holds epochs "
                             f"0..{self.mid.shape[0] - 1}")
        return self.rate(self.mid[k])


#: An aided loop asks the aiding of the epochs after the one it tracks: a record tracked
#: with the aiding of :meth:`ChannelAiding.channel` stops this long before its end.
AIDING_TAIL_S = 0.01


def ins_tracker_setup(sig, seed: int, step_s: float = 0.01, options=None):
    """``track_file``'s ``tracker_setup`` for the generated moving scenario ``sig``: every
    channel aided by :meth:`ChannelAiding.channel` (the truth's Doppler rate plus the INS
    errors of :mod:`cosim.ins.ins_error`'s model, realisation ``(seed, 0)``) of its PRN,
    from its first tracked epoch; ``options``: the tracker options it adds."""
    cols = np.arange(len(sig.prns))
    aid = ChannelAiding(sig, cols, 1, seed, step_s=step_s)
    prns = [int(p) for p in sig.prns]

    def setup(prn, t_first_s):
        if int(prn) not in prns:
            raise ValueError(f"PRN {prn} is not in the scenario: no INS aiding for it")
        return {"aiding": aid.channel(prns.index(int(prn)), t_first_s)}, dict(options or {})
    return setup


class EpochRates:
    """``aiding(k)``: the Doppler rate (Hz/s) of a channel's tracked epoch ``k`` from a
    table (:meth:`ChannelAiding.channel`); ``mid_s`` the epochs' midpoints (s)."""

    def __init__(self, rates, mid_s):
        self.rates, self.mid_s = np.asarray(rates, float), np.asarray(mid_s, float)

    def __call__(self, k):
        if not 0 <= k < self.rates.size:
            raise ValueError(f"aiding asked for epoch {k}: the channel's table holds epochs "
                             f"0..{self.rates.size - 1}")
        return float(self.rates[k])


def _run_seed(seed: int, r: int) -> int:
    return int(np.random.SeedSequence((int(seed), int(r))).generate_state(1)[0])


def run_loop(cfg: Table2Config, loop: str, sig, cols, aiding: ChannelAiding, *,
             runs: int | None = None, seed: int | None = None, cn0_min_dbhz: float = 30.0):
    """One loop's Monte Carlo (``runs`` batched trials of :func:`run_fast`, default
    ``cfg.runs``; trial noise from ``seed``, default ``cfg.seed``; the lock detector's C/N0
    criterion ``cn0_min_dbhz``): ``(FastGpsRun, errors)``, errors (M, runs, 6) of the fixes
    on ECEF x, y, z, vx, vy, vz (NaN: no fix)."""
    from ..gnss.config import GnssRunConfig
    from ..gnss.gps_fast import run_fast
    from ..gnss.gps_receiver import GpsConfig
    from ..gnss.multichannel import TrackConfig
    if loop not in LOOPS:
        raise ValueError(f"loop must be one of {LOOPS}, not {loop!r}")
    r = run_fast(sig.cfg, signal=sig, run=GnssRunConfig(tracker=loop, dsp=cfg.dsp),
                 gps=GpsConfig(rate_hz=cfg.rate_hz),
                 track=TrackConfig(channels=cols.size, cn0_min_dbhz=cn0_min_dbhz),
                 trials=cfg.runs if runs is None else runs,
                 seed=cfg.seed if seed is None else seed,
                 aiding=aiding if loop != "unaided-kf" else None,
                 tracker_options=tracker_options(loop, cfg), doppler_instant=True)
    if r.prns != tuple(sig.prns[j] for j in cols):
        raise ValueError("internal: run_fast tracked other satellites than the table's")
    return r, fix_errors(r)


def tracker_options(loop, cfg):
    """The loop's options (both paths): PLI epochs; the Kalman loops' oscillator model."""
    o = {"pli_epochs": cfg.pli_epochs}
    if loop != "aided-pll":
        o["oscillator"] = cfg.oscillator
    return o


def fix_errors(r) -> np.ndarray:
    """(M, trials, 6): each fix's ECEF position and velocity minus the truth (NaN: none)."""
    out = np.full((r.t_s.size, r.trials, 6), np.nan)
    for k, g in enumerate(r.runs):
        for m, e in enumerate(g.epochs):
            if e.solution is not None and e.solution.valid:
                out[m, k, :3] = np.asarray(e.solution.position_ecef_m) - r.truth.rx_position_m[m]
                out[m, k, 3:] = np.asarray(e.solution.velocity_ecef_mps) - r.truth.rx_velocity_mps[m]
    return out


def error_table(err, t_s, settle_s: float) -> dict:
    """Statistics of the errors ``err`` (M, runs, 6) after ``settle_s``: per axis the mean
    over runs of the per-run mean and std (``mean``, ``std``), their standard errors over
    runs (``mean_se``, ``std_se``), the per-run stds (``std_runs``, runs x 6) and the fixes
    used. A run without two fixes is refused."""
    e = np.asarray(err, float)[np.asarray(t_s) >= settle_s]
    n = np.sum(np.isfinite(e[..., 0]), axis=0)
    if e.shape[0] < 2 or np.any(n < 2):
        raise ValueError(f"every run needs >= 2 fixes after settle_s {settle_s:g} s; got "
                         f"{n.min() if n.size else 0}")
    mu = np.nanmean(e, axis=0)                       # (runs, 6)
    sd = np.nanstd(e, axis=0, ddof=1)
    runs = e.shape[1]
    se = (lambda x: np.std(x, axis=0, ddof=1) / math.sqrt(runs)) if runs > 1 \
        else (lambda x: np.full(6, np.nan))
    return {"mean": mu.mean(0).tolist(), "std": sd.mean(0).tolist(), "mean_se": se(mu).tolist(),
            "std_se": se(sd).tolist(), "std_runs": sd.tolist(), "fixes": int(n.sum()),
            "epochs": int(e.shape[0] * runs)}


def _claim_verdict(d, min_pct):
    """``(verdict, mean, se)`` of the per-run improvements ``d`` (%), or ``(None, ...)``
    with fewer than 2 runs."""
    dm = float(d.mean()) if d.size else math.nan
    se = float(d.std(ddof=1) / math.sqrt(d.size)) if d.size > 1 else math.nan
    if d.size < 2:
        return None, dm, se
    return ("held" if dm >= min_pct and dm > 2 * se else "not held"), dm, se


def _runs_text(idx) -> str:
    return ", ".join(str(int(i)) for i in idx)


def judge_claims(tables: dict, lock: dict | None = None) -> list:
    """The paper's claims (:data:`CLAIMS`) judged per axis on the tables of ``aided-kf`` and
    ``aided-pll`` (:func:`error_table`): per run the improvement ``1 - std_kf / std_pll``
    (paired runs), its mean ``d`` and standard error ``se`` over runs. ``held``: ``d >=
    min_pct`` and ``d > 2 se`` (better than the PLL beyond the Monte Carlo noise); ``not
    held``: otherwise.

    Lock losses (``lock[loop]["losses_per_run"]``, :func:`lock_counts`): the claim is judged
    twice, on all runs and on the runs where neither aided loop lost lock (``*_no_loss``).
    The same verdict both ways stands, its reason naming the losses and both improvements;
    verdicts that differ (the losses decide it), or fewer than 2 runs without a loss, give
    ``not comparable``. Fewer than 2 runs in all: ``not comparable``."""
    kf, pll = tables["aided-kf"], tables["aided-pll"]
    a, b = np.asarray(kf["std_runs"]), np.asarray(pll["std_runs"])
    aided = ("aided-kf", "aided-pll")
    per = {lp: np.asarray(lock[lp]["losses_per_run"], np.int64) if lock
           else np.zeros(a.shape[0], np.int64) for lp in aided}
    for lp in aided:
        if per[lp].shape != (a.shape[0],):
            raise ValueError(f"{lp}: {per[lp].size} per-run loss counts for {a.shape[0]} runs")
    bad = (per["aided-kf"] > 0) | (per["aided-pll"] > 0)
    keep = ~bad
    lost = "; ".join(f"{lp} lost lock {int(per[lp].sum())} time(s) in run(s) "
                     f"{_runs_text(np.flatnonzero(per[lp]))}" for lp in aided if per[lp].any())
    out = []
    for c in CLAIMS:
        axes = []
        for ax in c["axes"]:
            i = AXES.index(ax)
            d = 100 * (1 - a[:, i] / b[:, i])
            v_all, dm, se = _claim_verdict(d, c["min_pct"])
            v0, dm0, se0 = _claim_verdict(d[keep], c["min_pct"]) if bad.any() else (v_all, dm, se)
            v = v_all
            both = (f"{dm:+.1f} +- {se:.1f} % on all {d.size} runs, {dm0:+.1f} +- {se0:.1f} % on "
                    f"the {int(keep.sum())} without a loss")
            if v is None:
                v, why = "not comparable", "fewer than 2 runs: no Monte Carlo uncertainty"
            elif bad.any() and v0 is None:
                v, why = "not comparable", (f"{lost}: {int(keep.sum())} run(s) without a loss, "
                                            f"fewer than 2 to judge the claim without them")
            elif bad.any() and v0 != v:
                left = _runs_text(np.flatnonzero(bad))
                v, why = "not comparable", (f"{lost}; the losses decide the verdict: {v} on all "
                                            f"runs, {v0} without runs {left} "
                                            f"(aided KF std lower by {both})")
            elif v == "held":
                why = f"aided KF std {dm:.1f} +- {se:.1f} % lower (claimed >= {c['min_pct']:g} %)"
            else:
                why = (f"aided KF std {dm:+.1f} +- {se:.1f} % lower than the aided PLL's; the "
                       f"claim needs >= {c['min_pct']:g} % beyond 2 se")
            if bad.any() and v != "not comparable":
                why += (f"; {lost}: the same verdict without runs "
                        f"{_runs_text(np.flatnonzero(bad))} (lower by {both})")
            axes.append({"axis": ax, "improvement_pct": dm, "se_pct": se, "verdict": v,
                         "reason": why, "runs": int(d.size),
                         "improvement_pct_no_loss": dm0, "se_pct_no_loss": se0,
                         "runs_no_loss": int(keep.sum()),
                         "verdict_all_runs": v_all, "verdict_no_loss": v0})
        out.append({**{k: c[k] for k in ("name", "text", "min_pct")}, "axes": axes,
                    "runs_left_out": np.flatnonzero(bad).tolist()})
    return out


def lock_counts(r, settle_s: float) -> dict:
    """Lock of a :func:`run_fast` run after ``settle_s`` (module doc); ``losses_per_run``:
    the losses of each Monte Carlo run (summed over its channels)."""
    lk = r.series["locked"][r.t_s >= settle_s]                      # (M, runs, S)
    per_run = np.sum(lk[:-1] & ~lk[1:], axis=(0, 2))
    err = fix_errors(r)[r.t_s >= settle_s]
    return {"losses": int(per_run.sum()), "losses_per_run": [int(x) for x in per_run],
            "unlocked_channel_epochs": int(np.sum(~lk)),
            "channel_epochs": int(lk.size),
            "fixes_missing": int(np.sum(~np.isfinite(err[..., 0]))),
            "epochs_with_unlocked_channel": int(np.sum(~lk.all(axis=2)))}


def config_record(cfg: Table2Config) -> dict:
    return {**asdict(cfg), "ins_errors": asdict(InsErrors())}
