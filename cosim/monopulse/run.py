"""The monopulse closed beam-steering loop end to end: measurement -> tracker -> steering of
the next measurement, on the snapshot fast path (Monte Carlo) or the golden IF chain.

Loop (one step per measurement block of N snapshots, ``T = N / chip_rate``): the block is
measured at the steering in force (the calibration applied with the steering correction),
the sum beam is detected against a threshold, the monopulse gives ``(u, v)``; a trial is
*searching* (:class:`dsp.monopulse.tracker.SearchCapture`: the dwell positions are the
steering), *capturing* (steered at a detection's measurement, waiting for its confirmation)
or *tracking* (the tracker's update, then its prediction ``1 + latency_blocks`` blocks ahead is
the command). A command issued after block k steers block ``k + 1 + latency_blocks``; the
blocks in between keep the commands already issued. ``miss_limit`` undetected blocks in a row
while tracking is a lost-track event: the search restarts around the last prediction.

Backends: ``fast`` -- the fast path's model (``cosim.monopulse.fastpath``: corrected outputs
``k_i [exp(j theta_c) h_i + n_i]``, its noise variance), with ``h_i`` evaluated at the block
centre instead of averaged over the block's snapshots (the smear over one 0.8 ms block is
~1e-7 relative at the default rates; ``test_mono_run`` checks it against
``fastpath.mean_outputs``), batched over ``trials``; ``golden`` -- the IF generator and the
float golden chain, block by block (one trial; slow: ~N D samples x 4 per block). The HDL
backends (``model``, ``pysim``, ``verilator``, ``icarus``) are refused until the front end of
``hdl/monopulse`` exists (:func:`_hdl_frontend` is the hook). No FIFO on these paths:
``fifo_dropped`` is 0 by construction and says so (``fifo``).

Checks before work (:class:`MonopulseRunConfig`): :mod:`cosim.monopulse.checks` (the run's
size per backend, options without effect, meaningless values, the record).

Calibration: before the run a calibration source at the initial pointing is measured over
``cal_snapshots`` snapshots at ``cal_snr_db`` (fast path, noisy), ``c = calibration_from_measurement``; the
report gives the noise-free angle bias at the initial truth before and after it.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np

from dsp.monopulse.angles import angles, crb_angles, crb_uv
from dsp.monopulse.golden import beams, golden_chain
from dsp.monopulse.tracker import (MONOPULSE_FORMATS, AngleTracker, SearchCapture, TrackerConfig,
                                   calibration_from_measurement, measure_uv)

from ..core.validate import check_float, check_int
from .array import ArrayConfig
from .checks import check_run
from .fastpath import mean_outputs, noise_variance, snapshot_snr
from .signal import STREAM_FAST, MonopulseSignalConfig, generate
from .trajectory import ConstantRate, Manoeuvre

BACKENDS = ("fast", "golden", "model", "pysim", "verilator", "icarus")
HDL_BACKENDS = ("model", "pysim", "verilator", "icarus")
SEARCH, CAPTURE, TRACK = 0, 1, 2


def _h(text, **kw):
    return dict(help=text, **kw)


@dataclass(frozen=True)
class MonopulseRunConfig:
    """One closed-loop monopulse scenario (defaults: the monopulse paper's -8 dB, 8192 snapshots,
    2 s)."""

    snr_db: float = field(default=-8.0, metadata=_h("per-subarray SNR in the snapshot band (dB)"))
    snapshots: int = field(default=8192, metadata=_h("snapshots per measurement N (>= 1)"))
    duration_s: float = field(default=2.0, metadata=_h("scenario length (s)"))
    tracker: str = field(default="adaptive", metadata=_h(
        "adaptive (Kalata index from the last innovations) or fixed gains",
        choices=("adaptive", "fixed"), case="lower"))
    eq36: str = field(default="repaired", metadata=_h(
        "adaptive index: repaired or literal (the paper's eq. 36 as printed)",
        choices=("repaired", "literal"), case="lower"))
    floor_scaling: str = field(default="gain", metadata=_h(
        "adaptive noise floor: gain (tau sigma_v^2 / (1 - alpha)) or fixed (tau sigma_v^2)",
        choices=("gain", "fixed"), case="lower"))
    noise_floor: float = field(default=6.0, metadata=_h(
        "adaptive: tau, the innovation power (x sigma_v^2) taken as noise"))
    alpha_relax: float = field(default=1.1, metadata=_h(
        "adaptive: 1 - alpha grows at most by this factor a step (0: no limit)"))
    sigma_a: float = field(default=2.0, metadata=_h(
        "fixed tracking index as acceleration std of the direction cosines (1/s^2)"))
    latency_blocks: int = field(default=1, metadata=_h(
        "measurement blocks between a steering command and the beam moving (>= 0)"))
    backend: str = field(default="fast", metadata=_h(
        "fast (snapshot fast path), golden (IF + float chain), model/pysim/verilator/icarus "
        "(HDL)",
        choices=BACKENDS, case="lower"))
    dsp: str = field(default="float", metadata=_h("tracker arithmetic", choices=("float", "fixed"),
                                                  case="lower"))
    trials: int = field(default=1, metadata=_h("Monte Carlo runs (fast backend)"))
    seed: int = field(default=1, metadata=_h("random seed (>= 0)"))
    u0: float = field(default=0.3, metadata=_h("target direction cosine u at t = 0"))
    v0: float = field(default=0.2, metadata=_h("target direction cosine v at t = 0"))
    du_dt: float = field(default=0.02, metadata=_h("target rate in u (1/s)"))
    dv_dt: float = field(default=-0.015, metadata=_h("target rate in v (1/s)"))
    accel_u: float = field(default=0.0, metadata=_h("manoeuvre acceleration in u (1/s^2)"))
    accel_v: float = field(default=0.0, metadata=_h("manoeuvre acceleration in v (1/s^2)"))
    manoeuvre_start_s: float = field(default=0.8, metadata=_h("manoeuvre start (s)"))
    manoeuvre_end_s: float = field(default=1.2, metadata=_h("manoeuvre end (s)"))
    pointing_u: float | None = field(default=None, metadata=_h(
        "guided pointing u (default: the target's u0)", none=("none",)))
    pointing_v: float | None = field(default=None, metadata=_h(
        "guided pointing v (default: the target's v0)", none=("none",)))
    spacing_wl: float | None = field(default=None, metadata=_h(
        "subarray spacing D (wavelengths; default elements x element spacing = 4)",
        none=("none",)))
    phase_bits: int = field(default=6, metadata=_h("element phase-shifter bits (>= 1)"))
    adc_bits: int = field(default=12, metadata=_h("ADC bits (2-16)"))
    gain_spread_db: float = field(default=0.3, metadata=_h(
        "channel gain mismatch: channels 2-4 drawn in +- this (dB, seeded)"))
    phase_spread_deg: float = field(default=3.0, metadata=_h(
        "channel phase mismatch: channels 2-4 drawn in +- this (deg, seeded)"))
    skip_calibration: bool = field(default=False, metadata=_h(
        "do not calibrate the channels before the run"))
    cal_snapshots: int = field(default=1 << 20, metadata=_h("snapshots of the calibration measurement"))
    cal_snr_db: float | None = field(default=10.0, metadata=_h(
        "SNR per snapshot of the calibration source (dB; none: noise-free)", none=("none",)))
    detect_db: float = field(default=13.0, metadata=_h(
        "sum-beam detection threshold over its noise power (dB)"))
    miss_limit: int = field(default=3, metadata=_h("undetected blocks in a row = lost track"))
    settle_s: float = field(default=0.1, metadata=_h("start of the scored window (s)"))
    service_period_cycles: int = field(default=20_000, metadata=_h(
        "HDL backends: the DSP's FIFO service period (cycles)"))
    service_latency_cycles: int = field(default=200, metadata=_h(
        "HDL backends: interrupt latency before the DSP reads (cycles)"))
    service_batch_words: int = field(default=16, metadata=_h(
        "HDL backends: FIFO words the DSP reads per service at most"))
    compute_cycles: int = field(default=200, metadata=_h(
        "HDL backends: DSP processing cycles from its read window to its writes"))
    control_latency_cycles: int = field(default=40, metadata=_h(
        "HDL backends: cycles from the DSP issuing a register write to the register holding it"))
    #: Overrides of :class:`hdl.monopulse.params.MonopulseFrontendParams`, (name, value) pairs
    #: (HDL backends; studies).
    hdl_changes: tuple = ()
    #: Total widths of the fixed-point tracker's formats, (format, width) pairs (``dsp``
    #: fixed; integer bits kept, fraction bits change; studies).
    dsp_changes: tuple = ()
    #: Refuse a record too short to score anything (:func:`cosim.monopulse.checks.check_record`);
    #: False for runs compared on their bits only (the sweep's cycle-accurate re-check).
    require_score: bool = True

    def __post_init__(self):
        for name in ("snr_db", "duration_s", "sigma_a", "noise_floor", "alpha_relax", "u0", "v0",
                     "du_dt", "dv_dt", "accel_u", "accel_v", "manoeuvre_start_s",
                     "manoeuvre_end_s", "gain_spread_db", "phase_spread_deg", "detect_db",
                     "settle_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number, not {v!r}")
        if self.duration_s <= 0:
            raise ValueError(f"duration_s must be > 0, not {self.duration_s!r}")
        for name, lo in (("trials", 1), ("miss_limit", 1), ("cal_snapshots", 1), ("seed", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ValueError(f"{name} must be an integer >= {lo}, not {v!r}")
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, not {self.backend!r}")
        if self.dsp not in ("float", "fixed"):
            raise ValueError(f"dsp must be float or fixed, not {self.dsp!r}")
        if self.backend in ("golden",) + HDL_BACKENDS and self.trials != 1:
            raise ValueError(f"the {self.backend} backend runs one trial, not trials = "
                             f"{self.trials}")
        if self.backend in HDL_BACKENDS and self.latency_blocks != 1:
            raise ValueError(f"the HDL front end's steering registers take effect at the next "
                             f"block boundary (latency_blocks 1), not latency_blocks = "
                             f"{self.latency_blocks}")
        if self.accel_u or self.accel_v:
            if not 0 <= self.manoeuvre_start_s < self.manoeuvre_end_s:
                raise ValueError(f"a manoeuvre needs 0 <= manoeuvre_start_s < manoeuvre_end_s, "
                                 f"not {self.manoeuvre_start_s!r}..{self.manoeuvre_end_s!r}")
        for name in ("pointing_u", "pointing_v", "cal_snr_db"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))
                                  or not math.isfinite(v)):
                raise ValueError(f"{name} must be a finite number or none, not {v!r}")
        if self.spacing_wl is not None:
            check_float("spacing_wl", self.spacing_wl, 0, lo_open=True)
        check_int("phase_bits", self.phase_bits, 1, 24)
        check_int("adc_bits", self.adc_bits, 2, 16)
        # The parts validate their own fields (snapshots, initial visible region).
        self.tracker_config()
        sig = self.signal_config()
        check_run(self, sig)        # ignored options, meaningless values, record, size
        from .array import check_visible
        check_visible(*self.pointing, "guided pointing")
        if self.backend in HDL_BACKENDS:
            from .hdl_loop import check_hdl_run
            check_hdl_run(self, sig)

    @property
    def pointing(self):
        pu = self.u0 if self.pointing_u is None else self.pointing_u
        pv = self.v0 if self.pointing_v is None else self.pointing_v
        return (pu, pv)

    def mismatch(self):
        rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(7,)))
        g = np.concatenate([[0.0], rng.uniform(-1, 1, 3)]) * self.gain_spread_db
        p = np.concatenate([[0.0], rng.uniform(-1, 1, 3)]) * self.phase_spread_deg
        return tuple(g), tuple(p)

    def array_config(self) -> ArrayConfig:
        g, p = self.mismatch()
        return ArrayConfig(subarray_spacing_x_wl=self.spacing_wl, subarray_spacing_y_wl=self.spacing_wl,
                           phase_bits=self.phase_bits, gain_db=g, phase_deg=p)

    def trajectory(self):
        if self.accel_u or self.accel_v:
            return Manoeuvre(self.u0, self.v0, self.du_dt, self.dv_dt,
                             ((self.manoeuvre_start_s, self.manoeuvre_end_s, self.accel_u, self.accel_v),))
        return ConstantRate(self.u0, self.v0, self.du_dt, self.dv_dt)

    def signal_config(self) -> MonopulseSignalConfig:
        return MonopulseSignalConfig(array=self.array_config(), trajectory=self.trajectory(),
                                     snapshots=self.snapshots, snr_db=self.snr_db,
                                     adc_bits=self.adc_bits, seed=self.seed)

    def dsp_formats(self):
        """The fixed-point tracker's formats: :data:`MONOPULSE_FORMATS` with ``dsp_changes``."""
        from dataclasses import replace
        from dsp.fixed import FixedFormat
        ch = {}
        for kv in self.dsp_changes:
            if not (isinstance(kv, tuple) and len(kv) == 2 and kv[0] in
                    MONOPULSE_FORMATS.signals()):
                raise ValueError(f"dsp_changes are (format, width) pairs with format in "
                                 f"{', '.join(MONOPULSE_FORMATS.signals())}, not {kv!r}")
            name, w = kv
            f = getattr(MONOPULSE_FORMATS, name)
            if isinstance(w, bool) or not isinstance(w, int) or not 2 <= w <= 62:
                raise ValueError(f"dsp.{name} width must be an integer in [2, 62], not {w!r}")
            ch[name] = FixedFormat(w, f.frac + (w - f.width), f.signed, f.rounding, f.overflow)
        fm = replace(MONOPULSE_FORMATS, **ch)
        fm.check(self.tracker_config().window)
        return fm

    def tracker_config(self) -> TrackerConfig:
        return TrackerConfig(mode=self.tracker, eq36=self.eq36, sigma_a=self.sigma_a,
                             floor_scaling=self.floor_scaling, noise_floor=self.noise_floor,
                             alpha_relax=self.alpha_relax, latency_blocks=self.latency_blocks)


def block_outputs(sig, steering, u, v, correction, carrier, rng, noise=True):
    """Fast-path outputs S (B, 4) of one block at per-trial steering (B, 2), target (u, v)
    at the block centre; also ``|AF|^2`` (B,). ``rng``: one generator per trial."""
    arr = sig.array
    B = steering.shape[0]
    h = np.empty((B, 4), complex)
    for b in range(B):
        h[b] = arr.channel_response(u, v, steering[b, 0], steering[b, 1])
    k = arr.steering_correction(steering[:, 0], steering[:, 1]) * correction
    s = h * np.exp(1j * carrier)[:, None]
    if noise:
        var = noise_variance(sig)
        w = np.stack([r.standard_normal((4, 2)) for r in rng]) @ np.array([1.0, 1j])
        s = s + np.sqrt(var / 2) * w
    af2 = np.abs(h[:, 0] / arr.channel_gains[0]) ** 2
    return k * s, af2, k


def _bias(sig, correction, pointing):
    """Noise-free (u, v, az, el) error at the initial truth, steered at ``pointing``."""
    s, _ = mean_outputs(sig, pointing, calibration=correction)
    u, v = measure_uv(s, np.array([pointing]), sig.array.dx_wl, sig.array.dy_wl)
    ut, vt = sig.trajectory(sig.block_centre_s(0))
    az, el = angles(u, v)
    azt, elt = angles(ut, vt)
    return {"u": float(u[0] - ut), "v": float(v[0] - vt),
            "az_deg": float(np.rad2deg(az[0] - azt)), "el_deg": float(np.rad2deg(el[0] - elt))}


def _rms(x):
    x = np.asarray(x, float)
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


def _mean(x):
    x = np.asarray(x, float)
    return float(np.mean(x)) if x.size else float("nan")


class _Loop:
    """The closed loop's DSP state over K blocks of B trials (the module doc): each
    :meth:`block` takes block ``k``'s measurement at the steering ``steer[k]`` and decides
    the steering of block ``k + lead`` (search, capture, tracking; lost-track events)."""

    def __init__(self, run, tracker, search, K):
        B = run.trials
        self.run, self.tracker, self.search, self.K = run, tracker, search, K
        self.lead = lead = tracker.lead
        self.mode = np.full(B, SEARCH)
        self.misses = np.zeros(B, int)
        self.capture_block = np.full(B, -1)
        self.steer = np.empty((K + lead, B, 2))
        for k in range(min(lead, K)):
            for b in range(B):
                self.steer[k, b] = search[b].next_position()
        self.meas = np.full((K, B, 2), np.nan)
        self.est = np.full((K, B, 2), np.nan)
        self.modes = np.empty((K, B), int)
        self.af2s = np.empty((K, B))
        self.lost = 0
        self.acquired = np.full(B, -1)

    def block(self, k, mu, mv, det, af2) -> None:
        """Block ``k`` measured ``(mu, mv)`` (B,), detected ``det`` (B,), ``|AF|^2`` (B,)
        (for the CRB): update the tracker and decide ``steer[k + lead]``."""
        run, tracker, search = self.run, self.tracker, self.search
        B = run.trials
        mode, misses, steer = self.mode, self.misses, self.steer
        st = steer[k]
        self.af2s[k] = af2
        self.meas[k, :, 0], self.meas[k, :, 1] = mu, mv
        self.modes[k] = mode
        tracking = mode == TRACK
        misses[:] = np.where(tracking & ~det, misses + 1, 0)
        fu, fv = tracker.update(mu, mv, valid=tracking & det)
        self.est[k, :, 0] = np.where(tracking, fu, np.nan)
        self.est[k, :, 1] = np.where(tracking, fv, np.nan)
        cu, cv = tracker.command()
        nxt = k + self.lead
        for b in range(B):
            if mode[b] == TRACK:
                if misses[b] >= run.miss_limit:
                    self.lost += 1
                    mode[b] = SEARCH
                    search[b].guide(cu[b], cv[b])
                    misses[b] = 0
                else:
                    steer[nxt, b] = (cu[b], cv[b])
                    continue
            if mode[b] == CAPTURE and k == self.capture_block[b]:
                if search[b].confirmed(st[b], (mu[b], mv[b]), det[b]):
                    mode[b] = TRACK
                    self.acquired[b] = k if self.acquired[b] < 0 else self.acquired[b]
                    tracker.reset(np.arange(B) == b, mu[b], mv[b])
                    pu, pv = tracker.command()
                    steer[nxt, b] = (pu[b], pv[b])
                    continue
                mode[b] = SEARCH
            if mode[b] == SEARCH and det[b] and self.modes[k, b] == SEARCH:
                mode[b] = CAPTURE
                self.capture_block[b] = nxt
                steer[nxt, b] = (mu[b], mv[b]) if mu[b] ** 2 + mv[b] ** 2 < 1 else st[b]
                continue
            if mode[b] == CAPTURE:
                steer[nxt, b] = steer[nxt - 1, b] if nxt > k + 1 else st[b]
                continue
            steer[nxt, b] = search[b].next_position()


def run_monopulse(run: MonopulseRunConfig, *, keep_series: bool = False, faults=None) -> dict:
    """Run the closed loop; the figures of the module docstring (angles in degrees, pointing
    in direction cosines and as a fraction of the unambiguous offset). ``faults`` (HDL
    backends): a :class:`cosim.monopulse.hdl_loop.FaultHooks` (bit errors injected in the
    ADC samples or the FIFO words; the DSP then counts bad records instead of raising)."""
    sig = run.signal_config()
    arr = sig.array
    dx, dy = arr.dx_wl, arr.dy_wl
    unamb = np.array(arr.unambiguous_offset)
    T = sig.block_s
    K = max(1, int(round(run.duration_s / T)))
    B = run.trials
    blocks = np.arange(K)
    tc = sig.block_centre_s(blocks)
    ut, vt = (np.asarray(x, float) for x in sig.trajectory(tc))   # refuses an invisible target
    pointing = np.array(run.pointing, float)
    snr = snapshot_snr(sig)
    sigma_v = math.sqrt(crb_uv(snr, sig.snapshots, dx, dy)[0]) if math.isfinite(snr) else 1e-6
    # Calibration (before the run), and its effect on the noise-free bias.
    cal = np.ones(4, complex)
    cal_sig = MonopulseSignalConfig(array=arr, trajectory=ConstantRate(*pointing, 0.0, 0.0),
                                    snapshots=run.cal_snapshots, snr_db=run.cal_snr_db,
                                    adc_bits=run.adc_bits, seed=run.seed)
    if not run.skip_calibration:
        # A fixed source: the block-centre response is the exact block mean (no 2^20-point sum).
        cal_rng = [np.random.default_rng(np.random.SeedSequence(run.seed, spawn_key=(STREAM_FAST, 2)))]
        s_cal, _, _ = block_outputs(cal_sig, pointing[None, :], float(pointing[0]),
                                    float(pointing[1]), np.ones(4), np.array([cal_sig.carrier_phase]),
                                    cal_rng, noise=run.cal_snr_db is not None)
        cal = calibration_from_measurement(s_cal)
    bias_before = _bias(sig, None, tuple(pointing))
    bias_after = _bias(sig, cal, tuple(pointing))
    # Loop state.
    rngs = [np.random.default_rng(np.random.SeedSequence(run.seed, spawn_key=(STREAM_FAST, 1, b)))
            for b in range(B)]
    carrier = np.array([r.uniform(-np.pi, np.pi) for r in rngs])
    arith = run.dsp_formats() if run.dsp == "fixed" else "float64"
    tracker = AngleTracker(run.tracker_config(), T, sigma_v, arithmetic=arith, trials=B,
                           u0=pointing[0], v0=pointing[1])
    loop = _Loop(run, tracker, [SearchCapture(pointing, unamb) for _ in range(B)], K)
    thr = 10 ** (run.detect_db / 10)
    hdl = None
    if run.backend in HDL_BACKENDS:
        from .hdl_loop import hdl_closed_loop
        hdl = hdl_closed_loop(run, sig, loop, cal, ut, vt, thr, faults=faults)
    for k in range(K if hdl is None else 0):
        st = loop.steer[k]
        if run.backend == "golden":
            rec = generate(sig, st[0], first_block=k, n_blocks=1)
            kc = arr.steering_correction(st[:, 0], st[:, 1]) * cal
            s = golden_chain(rec.samples, rec.scale, rec.replica, kc, sig.if_hz, sig.fs_hz,
                             sig.decimation, first_sample=k * sig.samples_per_block)
            _, af2, kc = block_outputs(sig, st, ut[k], vt[k], cal, carrier, rngs, noise=False)
        else:
            s, af2, kc = block_outputs(sig, st, ut[k], vt[k], cal, carrier, rngs)
        ssum = beams(s)[0]
        var_sum = np.sum(np.abs(kc) ** 2 * noise_variance(sig), axis=1)
        det = np.abs(ssum) ** 2 > thr * np.maximum(var_sum, 1e-300) if np.any(var_sum > 0) \
            else np.abs(ssum) > 0
        mu, mv = measure_uv(s, st, dx, dy)
        loop.block(k, mu, mv, det, af2)
    steer, meas, est, modes, af2s = loop.steer, loop.meas, loop.est, loop.modes, loop.af2s
    search, acquired, lost = loop.search, loop.acquired, loop.lost
    # Figures over the scored window, tracking blocks only.
    scored = (tc >= run.settle_s)[:, None] & (modes == TRACK)
    truth = np.stack([np.broadcast_to(ut[:, None], (K, B)), np.broadcast_to(vt[:, None], (K, B))], -1)
    az_t, el_t = angles(truth[..., 0], truth[..., 1])

    def ang_err(x):
        az, el = angles(x[..., 0], x[..., 1])
        daz = np.angle(np.exp(1j * (az - az_t)))
        return np.rad2deg(daz), np.rad2deg(el - el_t)

    maz, mel = ang_err(np.where(scored[..., None], meas, truth))
    taz, tel = ang_err(np.where(scored[..., None], est, truth))
    crb_az, crb_el = crb_angles(truth[..., 0], truth[..., 1], snr * af2s, sig.snapshots, dx, dy)
    pe = np.abs(steer[:K] - truth)
    pe_frac = np.max(pe / unamb, axis=-1)
    tracked_pe = np.where(modes == TRACK, pe_frac, 0.0)
    r = {"receiver": "monopulse", "backend": run.backend, "dsp": run.dsp, "tracker": run.tracker,
         "eq36": run.eq36, "snr_db": run.snr_db, "snapshots": sig.snapshots,
         "duration_s": K * T, "blocks": K, "block_s": T, "trials": B, "seed": run.seed,
         "sigma_v": sigma_v, "scored_blocks": int(scored.sum())}
    for name, e in (("az_meas", maz), ("el_meas", mel), ("az_track", taz), ("el_track", tel)):
        r[f"{name}_rms_deg"] = _rms(e[scored])
        r[f"{name}_mean_deg"] = _mean(e[scored])
    nan = float("nan")
    r["az_crb_deg"] = float(np.rad2deg(np.sqrt(np.mean(crb_az[scored])))) if scored.any() else nan
    r["el_crb_deg"] = float(np.rad2deg(np.sqrt(np.mean(crb_el[scored])))) if scored.any() else nan
    r["az_meas_over_crb"] = r["az_meas_rms_deg"] / r["az_crb_deg"]
    r["el_meas_over_crb"] = r["el_meas_rms_deg"] / r["el_crb_deg"]
    r["pointing_error_rms"] = _rms(pe[scored])
    r["pointing_error_max"] = float(np.max(np.where(modes == TRACK, np.max(pe, -1), 0.0)))
    r["pointing_error_max_fraction"] = float(np.max(tracked_pe))
    r["outside_unambiguous_blocks"] = int(np.sum(tracked_pe >= 1.0))
    r["lost_track_events"] = lost
    r["acquired_trials"] = int(np.sum(acquired >= 0))
    r["acquisition_block_max"] = int(np.max(acquired)) if np.all(acquired >= 0) else None
    r["search_cycles"] = int(sum(s.cycles for s in search))
    r["calibration"] = {"applied": not run.skip_calibration, "gain_db": list(arr.gain_db),
                        "phase_deg": list(arr.phase_deg), "bias_before": bias_before,
                        "bias_after": bias_after}
    r["dsp_events"] = tracker.counts()
    r["fifo"] = "none on the fast and golden paths"
    r["fifo_dropped"] = 0
    dg = hashlib.sha256()
    for a in (steer[:K], meas, modes):
        dg.update(np.ascontiguousarray(a).tobytes())
    r["digest"] = {"steering_and_measurements": dg.hexdigest()[:16]}
    if hdl is not None:
        r["digest"].update(hdl.pop("digest"))
        r.update(hdl)
    if keep_series:
        r["series"] = {"t_s": tc, "truth": truth, "meas": meas, "est": est, "steer": steer[:K],
                       "modes": modes, "scored": scored}
    return r


__all__ = ["BACKENDS", "MonopulseRunConfig", "block_outputs", "run_monopulse", "snapshot_snr"]
