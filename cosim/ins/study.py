"""INS paper Monte Carlo on the correlation-domain fast path: the three loops through the
trajectory, velocity / range error along the line of sight, PLI, lock, cycle slips.

One run = ``trials`` Monte Carlo trials of one loop, batched through
:func:`cosim.gnss.loopsim.track_fast` with the tracker built by
:func:`dsp.gnss.trackers.make_tracker` (its ``TrackerContext.aiding`` the INS Doppler rate
of :class:`cosim.ins.ins_error.InsAiding`). The scenario (trajectory, satellite, receiver
oscillator phase noise, INS errors) is drawn once per seed and shared by the loops, so the
comparison is paired; the thermal noise is drawn by ``track_fast`` from ``seed``.

Figures (per trial, after ``skip_s``; then mean / std over epochs and trials):
velocity error along the line of sight ``-(f_hat - f) lambda`` (m/s; ``f_hat`` the loop's
Doppler estimate, ``f`` the LOS Doppler plus the clock's frequency error), range error ``code error x 293.05 m`` (the DLL's pseudorange error: no
PVT is solved here), discriminator RMS over the jerk segments, PLI
(prompt summed over ``pli_epochs``) and the fraction of PLI values above ``pli_threshold``,
cycle slips of the true phase error (``cosim.gnss.loopsim.cycle_slips``, Costas); and what a
user sees (``shown``, :func:`shown_loop`: accuracy of the valid velocity estimates,
availability, misleading estimates), pooled over the trials.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cosim.gnss.loopsim import cycle_slips, track_fast
from dsp.gnss.ephemeris import CHIP_M, L1_WAVELENGTH_M
from dsp.gnss.loops_fixed import FLOAT, FixedArith
from dsp.gnss.trackers import TrackerContext, make_tracker
from hdl.gnss.params import DEFAULT_FS_HZ

from .ins_error import InsAiding, InsErrors
from .trajectory import Geometry, Scenario, PaperTrajectory

LOOPS = ("aided-kf", "aided-pll", "unaided-kf")


@dataclass(frozen=True)
class InsStudyConfig:
    """One Monte Carlo point.

    Parameters
    ----------
    cn0_dbhz : float
    oscillator : str or None
        ``"tcxo"``, ``"ocxo"`` or None (ideal clock).
    trials : int
        Monte Carlo trials per loop (>= 1).
    duration_s : float
        Scenario length (s); the paper's is 150.
    skip_s : float
        Pull-in excluded from the statistics (s).
    pli_epochs : int
        Prompt epochs summed for one PLI value.
    pli_threshold : float
        PLI above this counts as locked.
    dsp : str
        ``"float"`` or ``"fixed"``.
    seed : int
    start_s, accel_g, v_max_mps : float
        The trajectory (:class:`PaperTrajectory`; the paper's by default, smaller for short
        runs).
    """

    cn0_dbhz: float = 40.0
    oscillator: str | None = "tcxo"
    trials: int = 20
    duration_s: float = 150.0
    skip_s: float = 1.0
    pli_epochs: int = 10
    pli_threshold: float = 0.5
    dsp: str = "float"
    seed: int = 1
    start_s: float = 5.0
    accel_g: float = 50.0
    v_max_mps: float = 8300.0

    def __post_init__(self):
        if isinstance(self.trials, bool) or not isinstance(self.trials, int) or self.trials < 1:
            raise ValueError(f"trials must be an integer >= 1, not {self.trials!r}")
        if self.dsp not in ("float", "fixed"):
            raise ValueError(f"dsp must be 'float' or 'fixed', not {self.dsp!r}")
        if not -1.0 < self.pli_threshold < 1.0:
            raise ValueError(f"pli_threshold must be in (-1, 1), not {self.pli_threshold!r}")
        if not 0 <= self.skip_s < self.duration_s:
            raise ValueError(f"skip_s must be in [0, duration_s), not {self.skip_s!r}")


def scenario_for(cfg: InsStudyConfig):
    tr = PaperTrajectory(duration_s=cfg.duration_s, start_s=cfg.start_s, accel_g=cfg.accel_g,
                        v_max_mps=cfg.v_max_mps)
    sc = Scenario(tr, Geometry(), cfg.oscillator, seed=cfg.seed)
    ins = InsAiding(sc, InsErrors(), 1e-3, int(round(cfg.duration_s / 1e-3)) + 2, seed=cfg.seed)
    return sc, ins


def run_loop(loop: str, cfg: InsStudyConfig, scenario=None, keep: bool = False, **opts) -> dict:
    """Run one loop over ``cfg.trials`` trials; the figures of the module docstring."""
    sc, ins = scenario or scenario_for(cfg)
    T = 1e-3
    n = int(round(cfg.duration_s / T))
    t0 = sc.truth_at(np.zeros(1))
    shape = (cfg.trials,)
    ones = np.ones(shape)
    ctx = TrackerContext(fs_hz=DEFAULT_FS_HZ, T_s=T, doppler0_hz=t0["doppler_hz"][0] * ones,
                         doppler_rate0_hz_s=t0["doppler_rate_hz_s"][0] * ones,
                         cn0_dbhz=cfg.cn0_dbhz, aiding=ins)
    arith = FLOAT if cfg.dsp == "float" else FixedArith()
    if loop not in LOOPS:
        raise ValueError(f"loop must be one of {', '.join(LOOPS)}, not {loop!r}")
    opts.setdefault("pli_epochs", cfg.pli_epochs)
    if loop != "aided-pll":
        opts.setdefault("oscillator", cfg.oscillator)
    trk = make_tracker(loop, ctx, arith, **opts)
    r = track_fast(sc.truth_at, cfg.cn0_dbhz, n, T, shape=shape, seed=cfg.seed + 1000, tracker=trk)
    h = trk.history.arrays()
    # the estimate after epoch k stands for the end of interval k (KF) or later (PLL)
    tm = (np.arange(n) + 1.0 + getattr(trk, "doppler_offset_epochs", 0.0)) * T
    # the carrier frequency the loop sees: LOS Doppler plus the receiver clock's drift (a
    # PVT solution takes the common clock drift out; the velocity error excludes it)
    f_true = (sc.truth_at(tm + T / 2)["carrier_phase_cycles"]
              - sc.truth_at(tm - T / 2)["carrier_phase_cycles"]) / T
    verr = -(h["doppler_hz"] - f_true[:, None]) * L1_WAVELENGTH_M
    rerr = r.code_err_chips * CHIP_M
    s = int(round(cfg.skip_s / T))
    jm = np.zeros(n, bool)
    for a, b in sc.traj.jerk_segments():
        jm[int(a / T):int(b / T)] = True
    pli = h["pli"]
    ps = int(np.ceil(s / cfg.pli_epochs))
    lockf = (pli[ps:] > cfg.pli_threshold).mean(axis=0)
    out = {"loop": loop, "cn0_dbhz": cfg.cn0_dbhz, "oscillator": cfg.oscillator,
           "trials": cfg.trials, "dsp": cfg.dsp,
           "vel_err_mean_mps": float(verr[s:].mean()), "vel_err_std_mps": float(verr[s:].std()),
           "range_err_mean_m": float(rerr[s:].mean()), "range_err_std_m": float(rerr[s:].std()),
           "disc_rms_jerk_deg": float(np.sqrt(np.mean(h["disc_cycles"][jm] ** 2)) * 360),
           "phase_err_rms_deg": float(np.sqrt(np.mean(r.phase_err_cycles[s:] ** 2)) * 360),
           "pli_mean": float(pli[ps:].mean()), "pli_min": float(pli[ps:].min()),
           "lock_fraction_min": float(lockf.min()), "lock_fraction_mean": float(lockf.mean()),
           "cycle_slips": int(cycle_slips(r.phase_err_cycles[s:]).sum()),
           "shown": shown_loop(cfg, tm, verr, pli, r.phase_err_cycles),
           "tracker": trk.report()}
    if keep:
        out["series"] = {"t_s": tm, "disc_cycles": h["disc_cycles"], "pli": pli,
                         "vel_err_mps": verr, "phase_err_cycles": r.phase_err_cycles}
    return out


#: A velocity estimate shown valid further than this from the truth along the line of
#: sight is misleading (m/s): 5 Hz of Doppler at L1, the GNSS studies' bound.
MISLEADING_VEL_MPS = 5.0 * L1_WAVELENGTH_M


def shown_loop(cfg: InsStudyConfig, t_s, vel_err, pli, phase_err_cycles) -> dict:
    """What a user sees of a loop's trials (:mod:`cosim.studies.shown`), pooled: one LOS
    velocity estimate per 1 ms epoch (error in m/s), valid while the latest complete PLI
    value is above ``pli_threshold`` (none yet: not valid); display epoch 1 ms; scored after
    ``skip_s``; misleading = shown valid after a cycle slip (the true phase error's nearest
    Costas lock point moved from where it locked) or more than :data:`MISLEADING_VEL_MPS`
    off."""
    from cosim.studies.shown import pool
    from dsp.shown import shown_figures
    n, B = vel_err.shape
    k = np.arange(n)
    j = (k + 1) // cfg.pli_epochs - 1              # the latest complete PLI value
    lock = np.rint(np.asarray(phase_err_cycles) / 0.5)
    figs = []
    for b in range(B):
        valid = np.where(j >= 0, pli[np.clip(j, 0, None), b] > cfg.pli_threshold, False)
        bad = (lock[:, b] != lock[0, b]) | (np.abs(vel_err[:, b]) > MISLEADING_VEL_MPS)
        figs.append(shown_figures(t_s, vel_err[:, b], valid, settle_s=cfg.skip_s,
                                  end_s=cfg.duration_s, epoch_s=1e-3, misleading=bad))
    return pool(figs)


def run_study(cfg: InsStudyConfig, loops=LOOPS, **opts) -> dict:
    """All loops on the same scenario; ``{loop: figures}``."""
    scn = scenario_for(cfg)
    return {lp: run_loop(lp, cfg, scn, **opts) for lp in loops}


def holds_lock(r: dict) -> bool:
    """The lock rule of B3 on a :func:`run_loop` result: every trial has its PLI above the
    threshold in >= 99 % of the PLI values and no cycle slip."""
    return r["lock_fraction_min"] >= 0.99 and r["cycle_slips"] == 0


def lock_threshold(loop: str, cfg: InsStudyConfig, lo_dbhz: float, hi_dbhz: float,
                   resolution_db: float = 0.5) -> dict:
    """Lowest C/N0 at which ``loop`` holds lock (:func:`holds_lock`, every trial) through
    ``cfg``'s trajectory, by bisection between ``lo_dbhz`` (must fail) and ``hi_dbhz``
    (must hold), to ``resolution_db``. Every point runs on the same scenario (trajectory,
    clock, INS) and thermal-noise seed. Returns the bracket and every point run."""
    if not (lo_dbhz < hi_dbhz and resolution_db > 0):
        raise ValueError(f"need lo_dbhz < hi_dbhz and resolution_db > 0, not {lo_dbhz}, "
                         f"{hi_dbhz}, {resolution_db}")
    from dataclasses import replace
    scn = scenario_for(cfg)
    points = {}

    def ok(c):
        r = run_loop(loop, replace(cfg, cn0_dbhz=float(c)), scn)
        points[float(c)] = {"holds": holds_lock(r), "lock_fraction_min": r["lock_fraction_min"],
                            "cycle_slips": r["cycle_slips"]}
        return points[float(c)]["holds"]

    if not ok(hi_dbhz):
        return {"loop": loop, "threshold_dbhz": None, "note": f"no lock at {hi_dbhz} dB-Hz",
                "points": points}
    if ok(lo_dbhz):
        return {"loop": loop, "threshold_dbhz": float(lo_dbhz),
                "note": f"holds at the lower bound {lo_dbhz} dB-Hz", "points": points}
    lo, hi = float(lo_dbhz), float(hi_dbhz)
    while hi - lo > resolution_db:
        mid = round((lo + hi) / 2 / 0.25) * 0.25
        if mid in (lo, hi):
            break
        if ok(mid):
            hi = mid
        else:
            lo = mid
    return {"loop": loop, "threshold_dbhz": hi, "fails_at_dbhz": lo, "points": points}
