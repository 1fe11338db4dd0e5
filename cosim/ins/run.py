"""The INS paper's loops on the GNSS channel: the INS-aided Kalman loop, the aided PLL or the unaided
Kalman loop closing the loop of the GPS L1 channel (``golden`` correlators, the bit-exact
``model``, ``pysim`` or ``verilator``) over the INS paper's trajectory.

The scenario is :mod:`cosim.ins.trajectory`'s (user on the paper's trajectory, satellite on
its orbit): the line-of-sight range on a 1 ms grid (plus the trajectory's knots) becomes the
signal generator's range table (:class:`cosim.gnss.dynamics.CsvProfile`, a cubic spline:
its error is < 1e-6 m in range), with the receiver oscillator's phase noise and no
navigation data (a pilot-like signal, as on the fast path: a 10 ms PLI sum over a data-bit
edge would measure the data, not the lock). The GNSS run (:func:`cosim.gnss.run.run_gnss`:
acquisition, hand-over, FIFO, DSP service, the one-epoch loop latency) runs the loop as its
tracker, told the INS Doppler rate (:class:`cosim.ins.ins_error.InsAiding`, the paper's
INS errors) at the midpoint of every tracked epoch: the channel dumps on the received code's
epochs, which drift from the receiver's millisecond by the code Doppler (~3 ms over 150 s),
so the aiding is indexed by the epochs' times (:class:`cosim.ins.ins_error.EpochAiding`),
which the DSP would read from the channel's sample counter; here they are the received
code's epochs after the first tracked dump (within the code tracking error, < 1 us, of
the channel's own).

Time: the scenario (trajectory, INS, signal) starts with the acquisition's first sample;
tracking starts where the acquisition stopped (:mod:`cosim.gnss.handover`, up to
``--acq-limit-ms`` plus the refinement later), and ``duration_s``, ``settle_s`` and the
series' times are the tracking's, from there (the aiding is read at scenario time).

Figures (records after ``settle_s``): velocity error along the line of sight (the loop's
Doppler estimate against the LOS Doppler plus the clock's frequency error, times
-lambda), range error (code error x 293.05 m), PLI (prompt summed over ``pli_epochs``)
mean / min and the fraction above ``pli_threshold`` (``lock_fraction``), cycle slips and
phase RMSE of the GNSS run's scoring, discriminator RMS over the jerk segments, and the
run's digest and FIFO counters.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, CODE_PERIOD_S

from ..core.validate import check_float, check_int
from dsp.gnss.ephemeris import CHIP_M, L1_WAVELENGTH_M
from .study import LOOPS
from cosim.gnss.signal import check_cn0

from .trajectory import Geometry, Scenario, PaperTrajectory

OSCILLATORS = ("tcxo", "ocxo")
#: The fields that shape the built-in profile (not a CSV's).
PROFILE_FIELDS = ("start_s", "jerk_g_s", "accel_g", "v_max_mps")


@dataclass(frozen=True)
class InsRunConfig:
    """One INS paper run on the GNSS channel (the channel and DSP options are
    :class:`cosim.gnss.config.GnssRunConfig`'s).

    Parameters
    ----------
    loop : str
        ``aided-kf``, ``aided-pll`` or ``unaided-kf``.
    cn0_dbhz : float
        C/N0 (dB-Hz).
    oscillator : str or None
        Receiver oscillator (``tcxo``, ``ocxo``; None: ideal).
    duration_s : float
        Record length (s); the paper's trajectory is 150 s.
    seed : int
        Noise, oscillator and INS sensor noise.
    start_s, jerk_g_s, accel_g, v_max_mps : float or None
        The profile (:class:`cosim.ins.trajectory.PaperTrajectory`; None: its defaults);
        refused with ``trajectory_csv``, which replaces the profile.
    trajectory_csv : str or None
        A CSV of (time s, along-track distance m) instead of the profile.
    pli_epochs : int
        Prompt epochs summed for one PLI value.
    pli_threshold : float
        PLI above this counts as locked.
    """

    loop: str = field(default="aided-kf", metadata={
        "help": "carrier loop: aided-kf (INS-aided Kalman), aided-pll (INS-aided 3rd-order "
                "PLL, Bn 15 Hz), unaided-kf", "choices": LOOPS, "case": "lower"})
    cn0_dbhz: float = field(default=40.0, metadata={"help": "C/N0 (dB-Hz)"})
    oscillator: str | None = field(default="ocxo", metadata={
        "help": "receiver oscillator phase noise: tcxo, ocxo, none (ideal)",
        "choices": OSCILLATORS + (None,), "case": "lower", "none": ("none",)})
    duration_s: float = field(default=150.0, metadata={
        "help": "record length (s; the INS paper's trajectory is 150 s)"})
    seed: int = field(default=1, metadata={"help": "random seed (>= 0): noise, clock, INS"})
    start_s: float | None = field(default=None, metadata={
        "help": "start of the profile's first jerk ramp (s; default 5)"})
    jerk_g_s: float | None = field(default=None, metadata={
        "help": "jerk of the profile's ramps (g/s; default 5)"})
    accel_g: float | None = field(default=None, metadata={
        "help": "peak acceleration of the profile (g; default 50)"})
    v_max_mps: float | None = field(default=None, metadata={
        "help": "cruise speed of the profile (m/s; default 8300)"})
    trajectory_csv: str | None = field(default=None, metadata={
        "help": "CSV of (time s, along-track distance m), time strictly increasing, instead "
                "of the profile", "metavar": "PATH"})
    pli_epochs: int = field(default=10, metadata={"help": "prompt epochs per PLI value"})
    pli_threshold: float = field(default=0.5, metadata={"help": "PLI lock threshold"})

    def __post_init__(self):
        if self.loop not in LOOPS:
            raise ValueError(f"loop must be one of {', '.join(LOOPS)}, not {self.loop!r}")
        if self.oscillator not in OSCILLATORS + (None,):
            raise ValueError(f"oscillator must be tcxo, ocxo or None, not {self.oscillator!r}")
        check_cn0("--cn0-dbhz", self.cn0_dbhz)
        check_float("duration_s", self.duration_s, 0.0, lo_open=True, unit="s")
        check_int("seed", self.seed, 0)
        check_int("pli_epochs", self.pli_epochs, 1, 1000)
        check_float("pli_threshold", self.pli_threshold, -1.0, 1.0, lo_open=True, hi_open=True)
        given = [k for k in PROFILE_FIELDS if getattr(self, k) is not None]
        if given and self.trajectory_csv is not None:
            raise ValueError(f"{', '.join('--' + k.replace('_', '-') for k in given)} "
                             f"{'shapes' if len(given) == 1 else 'shape'} the built-in profile; --trajectory-csv replaces it (the option "
                             f"would change nothing)")
        tr = self.trajectory()       # the trajectory's own checks (ramps, CSV) before any work
        if self.trajectory_csv is not None:
            a = tr._table()
            if a[0, 0] > 0 or a[-1, 0] < self.duration_s + 0.05:
                raise ValueError(f"trajectory_csv {self.trajectory_csv!r} ends at {a[-1, 0]:g} s: "
                                 f"it must cover duration_s + 0.05 s (from t <= 0)")

    def trajectory(self) -> PaperTrajectory:
        prof = {k: getattr(self, k) for k in PROFILE_FIELDS if getattr(self, k) is not None}
        return PaperTrajectory(duration_s=self.duration_s, csv_path=self.trajectory_csv, **prof)


def ins_signal(cfg: InsRunConfig, scenario: Scenario, acq_span_s: float = 0.0):
    """The GNSS signal of the scenario: its LOS range as the generator's range table, over
    ``duration_s`` of tracking after ``acq_span_s`` of acquisition at most."""
    from cosim.gnss.dynamics import CsvProfile
    from cosim.gnss.signal import GnssSignalConfig
    end = cfg.duration_s + acq_span_s + 0.05
    t = np.arange(0.0, end + 1e-3 / 2, 1e-3)
    if cfg.trajectory_csv is None:
        knots = np.array([k for seg in scenario.traj.jerk_segments() for k in seg])
        t = np.union1d(t, knots[knots < end])
        t = t[np.r_[True, np.diff(t) > 1e-6]]
    rho = scenario.los(t)[0]
    prof = CsvProfile(t_s=tuple(t.tolist()), range_m=tuple(rho.tolist()))
    return GnssSignalConfig(cn0_dbhz=float(cfg.cn0_dbhz), duration_s=float(cfg.duration_s),
                            dynamics=prof, nav_data=False, oscillator=cfg.oscillator,
                            seed=int(cfg.seed))


def first_tracked_boundary_s(backend: str, p, hand: dict, inverted: bool) -> float:
    """Receiver time (s) of the dump that starts the first tracked epoch: on the HDL
    channel the end of record ``SKIP_RECORDS`` (the channel model replayed on the
    hand-over writes), on the golden chain the end of its first record (its local code
    starts at the acquired code phase)."""
    from cosim.gnss.handover import handover_writes
    from cosim.gnss.tracking import SKIP_RECORDS, record_boundaries
    if backend == "golden":
        kf = CHIP_RATE_HZ * (1 + hand["doppler_hz"] / 1575.42e6)
        return (CODE_LENGTH - hand["code_phase_chips"]) / kf
    w = [(c, p.registers.address(r), v)
         for c, r, v in handover_writes(p, hand["doppler_hz"], hand["code_phase_chips"],
                                        inverted)]
    n = int((SKIP_RECORDS + 2) * CODE_PERIOD_S * p.fs_hz)
    return float(record_boundaries(p, w, SKIP_RECORDS, n)[-1]) / p.fs_hz


def received_epoch_boundaries(gen, t0_s: float, n: int) -> np.ndarray:
    """``n + 1`` times (s) from ``t0_s``, one received code epoch (1023 chips) apart."""
    tg = np.arange(0.0, gen.cfg.duration_s + 0.01, 1e-3)
    chips = gen.truth_at(tg)["code_chips_total"]
    c0 = np.interp(t0_s, tg, chips)
    return np.interp(c0 + CODE_LENGTH * np.arange(n + 1), chips, tg)


def record_epoch_boundaries(gen, t0_s: float) -> np.ndarray:
    """The received code epochs' boundaries (s) from ``t0_s`` to two epochs past the
    record's end: every epoch the channel can dump in the record and the next one (a loop
    asks for the next epoch's rate). Their count is the received code's, not the record's
    milliseconds: the code Doppler makes them a few more or fewer (27 ppm at the paper's
    8300 m/s: 4 over 150 s)."""
    chips = gen.truth_at([t0_s, gen.cfg.duration_s])["code_chips_total"]
    n = int(math.ceil((chips[1] - chips[0]) / CODE_LENGTH)) + 2
    return received_epoch_boundaries(gen, t0_s, n)


def run_ins(cfg: InsRunConfig, run_cfg=None) -> dict:
    """One closed-loop run (module doc); the JSON-safe result (``_series`` for plots)."""
    from cosim.gnss.config import GnssRunConfig, check_run_size
    from cosim.gnss.handover import acquisition_span_ms
    from cosim.gnss.run import run_gnss
    from .ins_error import EpochAiding, InsAiding, InsErrors
    if not isinstance(cfg, InsRunConfig):
        raise ValueError(f"cfg must be an InsRunConfig, not {type(cfg).__name__}")
    run = replace(run_cfg or GnssRunConfig(), tracker=cfg.loop)
    # before the range table, the INS solution and the record (all per epoch): the same
    # duration and rate as the scenario's signal, its dynamics not yet built
    # (the scenario's time runs from the acquisition's first sample; the tracking and its
    # scoring from where the acquisition stopped, t_acq later: gen.t0_s below)
    from cosim.gnss.signal import GnssSignalConfig
    span_ms = acquisition_span_ms(run)
    size = GnssSignalConfig(duration_s=float(cfg.duration_s) + span_ms * 1e-3, seed=int(cfg.seed))
    check_run_size(size, run)
    run.check_loop_timing(size.fs_hz)
    traj = cfg.trajectory()
    sc = Scenario(traj, Geometry(), None, seed=cfg.seed)
    if cfg.trajectory_csv is not None:
        a = traj._table()
        if a[-1, 0] < cfg.duration_s + span_ms * 1e-3 + 0.05:
            raise ValueError(f"trajectory_csv {cfg.trajectory_csv!r} ends at {a[-1, 0]:g} s: "
                             f"it must cover the acquisition (up to {span_ms} ms with "
                             f"--acq-limit-ms {run.acq_limit_ms}) + duration_s + 0.05 s")
    sig = ins_signal(cfg, sc, span_ms * 1e-3)
    ins = InsAiding(sc, InsErrors(), 1e-3, int(round(cfg.duration_s / 1e-3)) + span_ms + 20,
                    seed=cfg.seed)
    held = {}

    def setup(gen, p, hand, backend):
        t0 = first_tracked_boundary_s(backend, p, hand, sig.spectrum_inverted)
        b = record_epoch_boundaries(gen, t0)            # tracking time
        b = b[b + gen.t0_s <= ins.t[-1]]
        held.update(gen=gen, boundaries=b)
        opts = {"pli_epochs": cfg.pli_epochs}
        if cfg.loop != "aided-pll":
            opts["oscillator"] = cfg.oscillator
        return {"aiding": EpochAiding(ins, b + gen.t0_s)}, opts

    r = run_gnss(sig, run, tracker_setup=setup, keep_track=True)
    track, n_b = r.pop("_track")
    r.pop("_series")
    gen, fs = held["gen"], sig.fs_hz
    obs = np.array([o[1:] for o in track.obs], np.float64).reshape(-1, 4)
    k = min(len(n_b), len(obs))
    t = np.asarray(n_b[:k], np.float64) / fs
    h = track.tracker.history.arrays()
    dop = np.asarray(track.doppler[:k])
    # the loop's Doppler estimate stands for the end of the epoch (KF) or half an epoch
    # later (PLL); the carrier frequency there, LOS Doppler plus clock drift
    T = CODE_PERIOD_S
    te = t + getattr(track.tracker, "doppler_offset_epochs", 0.0) * T
    f_true = (gen.truth_at(te + T / 2)["carrier_phase_cycles"]
              - gen.truth_at(te - T / 2)["carrier_phase_cycles"]) / T
    verr = -(dop - f_true) * L1_WAVELENGTH_M
    code = np.mod(gen.truth_at(t)["code_phase_chips"] - obs[:, 1] + CODE_LENGTH / 2,
                  CODE_LENGTH) - CODE_LENGTH / 2
    rerr = code * CHIP_M
    keep = t >= run.settle_s
    s0 = int(np.argmax(keep))
    pli = np.asarray(h["pli"]).ravel()
    ps = int(math.ceil(s0 / cfg.pli_epochs))
    jerk = np.zeros(k, bool)       # the profile's jerk segments (a CSV has none named)
    for a, b in (traj.jerk_segments() if cfg.trajectory_csv is None else ()):
        jerk |= (t >= a - gen.t0_s) & (t < b - gen.t0_s)
    disc = np.asarray(h["disc_cycles"]).ravel()[:k]
    out = {"loop": cfg.loop, "cn0_dbhz": cfg.cn0_dbhz, "oscillator": cfg.oscillator,
           "duration_s": cfg.duration_s, "backend": run.backend, "dsp": run.dsp,
           "seed": cfg.seed, "acquired": r["acquired"], "t_track_start_s": gen.t0_s,
           "n_records": int(k),
           "n_scored": int(keep.sum()),
           "vel_err_mean_mps": float(verr[keep].mean()), "vel_err_std_mps": float(verr[keep].std()),
           "range_err_mean_m": float(rerr[keep].mean()), "range_err_std_m": float(rerr[keep].std()),
           "pli_mean": float(pli[ps:].mean()), "pli_min": float(pli[ps:].min()),
           "lock_fraction": float((pli[ps:] > cfg.pli_threshold).mean()),
           "pli_threshold": cfg.pli_threshold,
           "cycle_slips": r["cycle_slips"], "phase_rmse_deg": r["phase_rmse_deg"],
           "disc_rms_jerk_deg": (float(np.sqrt(np.mean(disc[jerk] ** 2)) * 360)
                                 if jerk.any() else None),
           "fifo_dropped": r["fifo_dropped"], "dropped_reported": r["dropped_reported"],
           "digest": r["digest"]}
    for key in ("writes", "broken_records"):
        if key in r:
            out[key] = r[key]
    rep = track.tracker.report() if hasattr(track.tracker, "report") else {}
    out["tracker"] = rep
    out["_series"] = {"t_s": t, "disc_cycles": disc, "pli": pli, "vel_err_mps": verr,
                      "range_err_m": rerr, "aiding_boundaries_s": held["boundaries"]}
    return out
