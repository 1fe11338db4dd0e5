"""The whole GPS receiver on the correlation-domain fast path: every satellite of a
constellation scenario tracked at once, batched over satellites and Monte Carlo trials, the
same trackers and the same back end as the IF path.

Scenario and truth
------------------
A :class:`cosim.gnss.constellation.ConstellationConfig` (ephemerides, a static or moving
receiver -- :class:`~cosim.gnss.constellation_geometry.TrajectoryReceiver`, e.g.
:func:`~cosim.gnss.constellation_geometry.along_track_receiver` -- its clock, C/N0 by
elevation, ionosphere and troposphere) realised by
:class:`~cosim.gnss.constellation.ConstellationSignal`, which is also the IF path's
generator: no samples are made, but the truth is the very function its sample kernel
evaluates (:func:`_ranges_kernel`: per satellite the code and phase ranges ``P``, ``Phi``
cubic-Hermite interpolated from the generator's geometry pages, the receiver clock ``c
dt_r`` linear on its grid, the amplitude linear). The received code phase is ``chi(s) =
chi0 + 1.023e6 s - P / CHIP_M`` chips (unwrapped, counted from the first encoded LNAV frame
``F``), the carrier phase ``-Phi / lambda`` cycles, the navigation bit the generator's LNAV
bit ``floor(chi / 20460)``.

Channels
--------
The satellites above the elevation mask at the start, the ``channels`` strongest, are
tracked from their first code epoch after ``s = 0``, each replica started on the truth
(Doppler, Doppler rate, code and carrier phase: a hot start after a perfect hand-over).
Channel ``(trial, satellite)`` follows its own replica's code epochs, as the FPGA channel
dumps: epoch ``k`` runs from ``s_k`` (replica code phase a multiple of 1023) for ``1023 /
r_k`` s at the code rate ``r_k`` in force. For every epoch the E/P/L correlations are drawn
(:func:`cosim.gnss.fastpath.correlate_fast`) from the truth minus the replica: carrier phase
error at the epoch's midpoint, frequency error from the truth's phase chord over the epoch,
code error at the midpoint, the bit at the midpoint; the C/N0 of the scenario at the
midpoint (floored at :data:`NO_SIGNAL_DBHZ` below the mask: no signal), lowered by the
multiple-access interference of the other satellites in the record (``mai``: their codes
taken as white noise of density ``C_j / R_c``, ``R_c`` the chip rate -- the mean
cross-correlation power of two C/A codes is ``1/1023`` of the peak's -- so ``C/N0_eff =
C_i / (N0 + sum_{j != i} C_j / R_c)``: 0.8 dB at 45 dB-Hz with 8 satellites), and by the IF
path's ADC loss (``adc_bits`` at the generator's AGC step). The tracker
(:func:`cosim.gnss.tracking.make_tracker_for`: any registered tracker, fixed or float, as
the IF path builds it; one per group of channels of one nominal C/N0) closes the loop with
the FPGA channel's one-epoch latency (``TrackerContext.latency_epochs = 1``): the NCO
frequencies issued after epoch ``k`` are in force from epoch ``k + 2``. The lock detector is
the IF path's (:class:`dsp.gnss.loops.LockDetector`, ``TrackConfig``'s windows).

Aiding (INS)
------------
``aiding(k)``: the Doppler rate (Hz/s) of every channel at its epoch ``k`` (an array
broadcasting to ``(trials, satellites)``), handed to the trackers that take it
(``TrackerContext.aiding``: ``aided-kf``, ``aided-pll``); e.g. the INS acceleration
projected on each satellite's line of sight, ``-a_los / lambda``.

Observables and fixes
---------------------
Measurement epochs every ``1 / rate_hz`` s of receiver time (from ``1 / rate_hz`` on, as
the IF path's). At each, per channel: the prompt replica's code phase at that instant (the
replica is linear over its epoch) as the counts ``tow_sf, n_bits, n_codes, chips`` of
:func:`dsp.gnss.observables.pseudoranges_from_channels` (hot start: the TOW of every bit
edge is known from the scenario, ``t_sv = F + chi / 1.023e6``; the LNAV decoding is the IF
path's), the Doppler the tracker reported after the epoch holding the instant (or, with
``doppler_instant``, its last two reports interpolated linearly to the instant, each report
tagged at its epoch's end plus the tracker's ``doppler_offset_epochs`` epochs: under 50 g a
1 ms time-tag error is 0.5 m/s), the C/N0 of
the last closed lock window, the carrier phase (replica Doppler phase accumulated since the
channel's start, RINEX sign), LLI from the lock windows. The receiver time is set and
steered per trial exactly as :func:`cosim.gnss.gps_receiver.navigate` does
(:class:`~cosim.gnss.gps_receiver.ReceiverTime`), each epoch formed and solved by
:func:`~cosim.gnss.gps_receiver.fix_epoch` with the generator's ephemerides and broadcast
Klobuchar coefficients. Result: one :class:`~cosim.gnss.gps_receiver.GpsRun` per trial plus
the per-epoch series and the truth at the epochs.

Random streams: trial noise from ``np.random.default_rng(seed)`` (the scenario's own seed
fixes its clock realisation). Same seed, same result.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields

import numpy as np

from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, L1_HZ
from dsp.gnss.ephemeris import WEEK_S, select_ephemeris
from dsp.jit import njit_cached

from ..core.validate import check_float, check_int
from .config import GnssRunConfig
from dsp.gnss.ephemeris import CHIP_M, L1_WAVELENGTH_M
from .constellation import PAGE_POINTS, ConstellationSignal
from .constellation_kernels import linear, ranges_at
from .fastpath import adc_efficiency, correlate_fast
from .gps_receiver import GpsConfig, GpsEpoch, GpsRun, ReceiverTime, fix_epoch
from .multichannel import TrackConfig
from .signal import CHIPS_PER_BIT

__all__ = ["FastGpsRun", "run_fast", "fixes_from_series", "select_channels", "counts_from_chips",
           "mai_cn0_dbhz", "spacing_for", "NO_SIGNAL_DBHZ"]

#: C/N0 drawn for a satellite below the mask (its amplitude is 0 in the IF path): an
#: amplitude ~1e-7 of a 45 dB-Hz signal.
NO_SIGNAL_DBHZ = -100.0
#: Chips per subframe (6 s).
CHIPS_PER_SUBFRAME = 300 * CHIPS_PER_BIT


@njit_cached(nogil=True)
def _ranges_kernel(s, sat, q, page, s0, h, gcode, dgcode, gphase, dgphase, amp, c_step, cdt,
                   out):
    """``out[i] = (P, Phi, amplitude)`` of satellite ``sat[i]`` at receiver time ``s[i]``
    for the points of page ``page`` (``q[i] == page``), as the sample kernel computes
    them."""
    for i in range(s.shape[0]):
        if q[i] != page:
            continue
        j = sat[i]
        out[i, 0], out[i, 1] = ranges_at(s[i], s0, h, gcode[j], dgcode[j], gphase[j],
                                         dgphase[j], c_step, cdt)
        out[i, 2] = linear(s[i], s0, h, amp[j])


class _Truth:
    """The scenario's code phase, carrier phase, bit and C/N0 at any (channel, time) points,
    from the generator's pages (module doc)."""

    def __init__(self, sig: ConstellationSignal, cols):
        self.sig, self.cols = sig, np.asarray(cols, np.int64)
        self.h = sig.cfg.grid_s
        # the levels the generator modulates: LNAV bit 0 is +1, 1 is -1 (all +1 without data)
        lv = [1.0 - 2.0 * sig.nav_stream(sig.prns[j]).bits.astype(np.float64)
              if sig.cfg.nav_data else np.ones(sig.nav_stream(sig.prns[j]).bits.size)
              for j in self.cols]
        self.levels = np.concatenate(lv)       # every channel's bits, one after the other
        self.offset = np.cumsum([0] + [x.size for x in lv[:-1]]).astype(np.int64)
        self.n_bits = np.array([x.size for x in lv], np.int64)

    def ranges(self, s):
        """``(P, Phi, amplitude)``, each of the shape of ``s`` (..., S)."""
        s = np.asarray(s, np.float64)
        shp = s.shape
        sf = np.ascontiguousarray(s.reshape(-1))
        sat = np.ascontiguousarray(np.broadcast_to(self.cols, shp).reshape(-1))
        q = np.floor(sf / self.h).astype(np.int64) // PAGE_POINTS
        out = np.empty((sf.size, 3))
        ck = self.sig.clock
        for p in range(int(q.min()), int(q.max()) + 1):
            pg = self.sig.page(p)
            _ranges_kernel(sf, sat, q, p, pg["s0"], self.h, pg["gcode"], pg["dgcode"],
                           pg["gphase"], pg["dgphase"], pg["amp"], ck.step_s, ck.cdt_m, out)
        return tuple(out[:, i].reshape(shp) for i in range(3))

    def chips(self, s, P):
        return self.sig.chi0 + CHIP_RATE_HZ * np.asarray(s) - P / CHIP_M

    def bits(self, chi):
        """The LNAV bit (+1/-1) of the code phases ``chi`` (..., S)."""
        b = np.floor(chi / CHIPS_PER_BIT).astype(np.int64)
        if np.any(b < 0) or np.any(b >= self.n_bits):
            raise ValueError("internal: a code phase outside the encoded LNAV bits")
        return self.levels[self.offset + b]

    def cn0(self, amp):
        a = np.maximum(amp / self.sig.amp_per_sqrt_cn0, 10 ** (NO_SIGNAL_DBHZ / 20))
        return 20 * np.log10(a)

    def total_cn0(self, s: float) -> float:
        """``sum_j C_j / N0`` (Hz) of every satellite of the record at receiver time ``s``."""
        p = int(math.floor(s / self.h)) // PAGE_POINTS
        pg = self.sig.page(p)
        u = (s - pg["s0"]) / self.h
        k = min(max(int(math.floor(u)), 0), pg["amp"].shape[1] - 2)
        a = pg["amp"][:, k] + (u - k) * (pg["amp"][:, k + 1] - pg["amp"][:, k])
        return float(np.sum((a / self.sig.amp_per_sqrt_cn0) ** 2))


def counts_from_chips(chips_total, frame_tow_s: float):
    """``(tow_sf, n_bits, n_codes, chips)`` of :func:`dsp.gnss.observables.transmit_time`
    for a code phase ``chips_total`` (chips since the LNAV frame that starts at satellite
    time ``frame_tow_s``, s of week; >= 0)."""
    c = np.asarray(chips_total, np.float64)
    if np.any(~np.isfinite(c)) or np.any(c < 0):
        raise ValueError(f"chips_total must be finite and >= 0, not {chips_total!r}")
    sf = np.floor(c / CHIPS_PER_SUBFRAME)
    r = c - sf * CHIPS_PER_SUBFRAME
    nb = np.floor(r / CHIPS_PER_BIT)
    r = r - nb * CHIPS_PER_BIT
    nc = np.floor(r / CODE_LENGTH)
    ch = np.clip(r - nc * CODE_LENGTH, 0.0, np.nextafter(CODE_LENGTH, 0.0))
    return (np.mod(frame_tow_s + 6.0 * sf, WEEK_S), nb.astype(np.int64), nc.astype(np.int64),
            ch)


def select_channels(sig: ConstellationSignal, channels: int) -> np.ndarray:
    """Indices (into ``sig.prns``, ascending) of the satellites the receiver tracks: above
    the mask at the start, the ``channels`` strongest (C/N0) of them."""
    t0 = sig.truth_at(np.array([0.0]))
    up = np.flatnonzero(t0.sounding[0])
    if up.size == 0:
        raise ValueError("no satellite above the elevation mask at the start of the scenario")
    return np.sort(up[np.argsort(-t0.cn0_dbhz[0, up], kind="stable")][:int(channels)])


def mai_cn0_dbhz(cn0_dbhz, total_cn0_hz: float):
    """The C/N0 (dB-Hz) a channel sees with the other satellites' codes as white noise of
    density ``C_j / R_c`` (module doc): ``C_i / (N0 + sum_{j != i} C_j / R_c)``, where
    ``total_cn0_hz = sum_j C_j / N0`` over all satellites, the channel's own included."""
    c = 10 ** (np.asarray(cn0_dbhz, np.float64) / 10)
    return 10 * np.log10(c / (1 + np.maximum(total_cn0_hz - c, 0.0) / CHIP_RATE_HZ))


def spacing_for(fs_hz: float) -> float:
    """Early-minus-late spacing (chips) of the FPGA channel at ``fs_hz``: about half a chip,
    an even number (>= 2) of samples (:func:`cosim.gnss.multichannel.channel_params_for`)."""
    el = max(2, 2 * round(fs_hz / CHIP_RATE_HZ / 4))
    return el * CHIP_RATE_HZ / fs_hz


@dataclass
class FastGpsRun:
    """The fast path's receiver run (module doc).

    ``prns`` (S,) the channels' satellites; ``t_s`` (M,) the measurement epochs (s of the
    record); ``series``: arrays (M, trials, S) -- ``code_chips`` (replica code phase,
    unwrapped, at the epoch), ``doppler_hz``, ``cn0_dbhz``, ``carrier_cycles`` (RINEX
    sign), ``locked`` (last lock window: phase and C/N0 lock); ``truth``: the
    :class:`~cosim.gnss.constellation.ConstellationTruth` at ``t_s`` (columns ``prns``);
    ``runs``: one :class:`~cosim.gnss.gps_receiver.GpsRun` per trial; ``trackers``: the
    ``(channel indices, tracker)`` groups (batch ``(trials, len(indices))``: their own
    figures, e.g. the INS loops' ``history``)."""

    prns: tuple
    t_s: np.ndarray
    series: dict
    truth: object
    runs: list
    trials: int
    signal_s: float
    wall_s: float
    track_wall_s: float
    config: dict = field(default_factory=dict)
    trackers: list = field(default_factory=list)

    def truth_chips(self) -> np.ndarray:
        """(M, S): the received code phase (chips, unwrapped) at the epochs."""
        tr = self.truth
        sig_chi0 = self.config["chi0"]
        return sig_chi0 + CHIP_RATE_HZ * tr.s[:, None] - tr.pseudorange_m / CHIP_M

    def range_error_m(self) -> np.ndarray:
        """(M, trials, S): pseudorange error (m) of each channel, its replica's code phase
        against the truth's (the receiver clock is in both and cancels)."""
        return (self.truth_chips()[:, None, :] - self.series["code_chips"]) * CHIP_M

    def doppler_error_hz(self) -> np.ndarray:
        """(M, trials, S): reported Doppler minus the true Doppler at the epochs."""
        return self.series["doppler_hz"] - self.truth.doppler_hz[:, None, :]

    def position_error_m(self) -> np.ndarray:
        """(M, trials): 3-D distance (m) of each epoch's fix from the truth (NaN: no fix)."""
        out = np.full((self.t_s.size, self.trials), np.nan)
        for k, g in enumerate(self.runs):
            for m, e in enumerate(g.epochs):
                if e.solution is not None and e.solution.valid:
                    out[m, k] = np.linalg.norm(np.asarray(e.solution.position_ecef_m)
                                               - self.truth.rx_position_m[m])
        return out


def _aiding_for(aiding, shape, idx):
    if aiding is None:
        return None

    def a(k):
        return np.broadcast_to(np.asarray(aiding(k), np.float64), shape)[..., idx]
    return a


def run_fast(cfg, *, run: GnssRunConfig = GnssRunConfig(), gps: GpsConfig = GpsConfig(),
             track: TrackConfig = TrackConfig(), trials: int = 1, seed: int = 0,
             duration_s: float | None = None, adc_bits: int | None = 2, aiding=None,
             hot_ephemerides=None, iono="broadcast", signal: ConstellationSignal | None = None,
             mai: bool = True, tracker_options: dict | None = None,
             doppler_instant: bool = False, progress=None) -> FastGpsRun:
    """Run the receiver on the fast path over the scenario ``cfg``
    (:class:`~cosim.gnss.constellation.ConstellationConfig`; or its realised ``signal``)
    for ``duration_s`` (default the scenario's), ``trials`` Monte Carlo trials from
    ``seed`` (module doc). ``run``: the tracker, its arithmetic and bandwidths (its
    backend is not used); ``gps``: measurement rate and PVT; ``track``: channels and lock
    windows; ``adc_bits``: the IF path's ADC (the generated recording's 2 bits; None: no
    ADC loss); ``mai``: the other satellites' signals as noise (module doc); ``aiding``:
    per-channel Doppler rate (module doc); ``hot_ephemerides``: the ephemerides the
    receiver uses (default the generator's); ``iono``: Klobuchar parameters for the PVT
    (``"broadcast"``: the scenario's, None: none); ``tracker_options``: keyword options of
    the tracker's factory (e.g. ``oscillator``, ``pli_epochs`` of the INS paper's loops);
    ``doppler_instant``: each measurement's Doppler is the tracker's reports interpolated
    linearly to the measurement instant (module doc; False: the report after the epoch
    holding the instant, as the IF path); ``progress(done, total)`` every 1000 epochs. Bad input is refused (``ValueError`` naming it) before the tracking starts."""
    t_wall = time.perf_counter()
    trials = check_int("trials", trials, 1, 100_000)
    seed = check_int("seed", seed, 0)
    if not isinstance(run, GnssRunConfig) or not isinstance(gps, GpsConfig) \
            or not isinstance(track, TrackConfig):
        raise ValueError("run, gps and track must be GnssRunConfig, GpsConfig and TrackConfig")
    if not isinstance(mai, bool):
        raise ValueError(f"mai must be True or False, not {mai!r}")
    if not isinstance(doppler_instant, bool):
        raise ValueError(f"doppler_instant must be True or False, not {doppler_instant!r}")
    if tracker_options is not None and not isinstance(tracker_options, dict):
        raise ValueError(f"tracker_options must be a dict or None, not {tracker_options!r}")
    if aiding is not None and not callable(aiding):
        raise ValueError("aiding must be a callable aiding(k) -> Doppler rate (Hz/s) or None")
    from dsp.gnss.trackers import needs_aiding
    if needs_aiding(run.tracker) and aiding is None:
        raise ValueError(f"tracker {run.tracker} needs an aiding source: give aiding")
    eta = adc_efficiency(adc_bits)
    cfg = signal.cfg if signal is not None else cfg
    dur = cfg.duration_s if duration_s is None else \
        check_float("duration_s", duration_s, 0.0, cfg.duration_s, lo_open=True, unit="s")
    t_m = np.arange(1, int(math.floor(dur * gps.rate_hz + 1e-9)) + 1) / gps.rate_hz
    t_m = t_m[t_m < dur]
    M = t_m.size
    if M == 0:
        raise ValueError(f"duration_s {dur:g} s holds no measurement epoch at {gps.rate_hz:g} Hz "
                         f"(the first is at {1 / gps.rate_hz:g} s)")
    sig = signal if signal is not None else ConstellationSignal(cfg)
    fs = float(cfg.fs_hz)
    T = 1e-3
    if adc_bits is not None:               # at the generator's AGC step, in noise sigmas
        from .signal import agc_step_sigma
        eta = adc_efficiency(adc_bits, agc_step_sigma(int(adc_bits)) * sig.rms
                             * 2 ** (int(adc_bits) - 1))
    eta_db = 10 * math.log10(eta)
    spacing = spacing_for(fs)
    t0 = sig.truth_at(np.array([0.0]))
    cols = select_channels(sig, track.channels)
    prns = tuple(sig.prns[j] for j in cols)
    S = cols.size
    tr = _Truth(sig, cols)
    shape = (trials, S)
    ones = np.ones(shape)
    # start on each satellite's first code epoch after s = 0 (two Newton steps)
    P0, _, _ = tr.ranges(np.zeros(S))
    chi_0 = tr.chips(0.0, P0)
    target = CODE_LENGTH * np.ceil(chi_0 / CODE_LENGTH)
    s_start = (target - chi_0) / CHIP_RATE_HZ
    for _ in range(2):
        P, _, _ = tr.ranges(s_start)
        s_start = s_start + (target - tr.chips(s_start, P)) / CHIP_RATE_HZ
    e = 5e-3
    _, Pha, _ = tr.ranges(np.stack([s_start - e, s_start, s_start + e]))
    th = -Pha / L1_WAVELENGTH_M
    dop0 = (th[2] - th[0]) / (2 * e)
    rate0 = (th[2] - 2 * th[1] + th[0]) / e ** 2
    s = s_start * ones
    chi = target * ones
    phi = th[1] * ones
    phi_start = phi.copy()
    f = dop0 * ones
    cr = CHIP_RATE_HZ + f / (L1_HZ / CHIP_RATE_HZ)
    # trackers: one per nominal C/N0 (1 dB groups), as the IF path tells each channel's
    from .tracking import make_tracker_for
    nominal = np.round(t0.cn0_dbhz[0, cols])
    groups = []
    for c in np.unique(nominal):
        idx = np.flatnonzero(nominal == c)
        ctx = {"doppler0_hz": f[:, idx], "doppler_rate0_hz_s": rate0[idx] * ones[:, idx],
               "aiding": _aiding_for(aiding, shape, idx)}
        trk, _ = make_tracker_for(run, fs, 0.0, False, float(c), 0.0, spacing, run.dsp,
                                  (ctx, dict(tracker_options or {})))
        groups.append((idx, trk))
    from dsp.gnss.loops import LockDetector
    det = LockDetector(T, window=track.lock_window_ms, m=track.pli_block_ms,
                       pli_min=track.pli_min, cn0_min_dbhz=track.cn0_min_dbhz)
    rng = np.random.default_rng(seed)
    ser = {k: np.full((M, trials, S), np.nan) for k in
           ("code_chips", "doppler_hz", "cn0_dbhz", "carrier_cycles")}
    ser["locked"] = np.zeros((M, trials, S), bool)
    nxt = np.zeros(shape, np.int64)             # next measurement epoch of each channel
    cn0_now = np.full(shape, np.nan)
    lock_now = np.zeros(shape, bool)
    pending = [(f, cr)]                            # the one-epoch latency
    prev = None                                    # the last Doppler reports and their tags
    th_start = phi.copy()                          # the truth's phase at the epoch start
    n_epochs = int(math.ceil((dur - s_start.min()) / T)) + 2
    t_track = time.perf_counter()
    rows = np.arange(trials)[:, None] * np.ones((1, S), np.int64)
    colsS = np.arange(S)[None, :] * np.ones((trials, 1), np.int64)
    k = 0
    while True:
        Tk = (CODE_LENGTH * np.rint(chi / CODE_LENGTH) + CODE_LENGTH - chi) / cr
        P2, Ph2, a2 = tr.ranges(np.stack([s + Tk / 2, s + Tk]))
        Pm, Phm, am, Phe = P2[0], Ph2[0], a2[0], Ph2[1]
        chi_m = tr.chips(s + Tk / 2, Pm)
        th_m, th_e = -Phm / L1_WAVELENGTH_M, -Phe / L1_WAVELENGTH_M
        dphi = th_m - (phi + f * Tk / 2)
        df = (th_e - th_start) / Tk - f
        tau = chi_m - (chi + cr * Tk / 2)
        # the other satellites' codes as white noise of density C_j / R_c, then the
        # ADC's loss: correlate_fast's sqrt(eta) signal scaling as a C/N0 offset
        cn0 = tr.cn0(am)
        if mai:
            cn0 = mai_cn0_dbhz(cn0, tr.total_cn0(float(s.mean())))
        x = correlate_fast(cn0 + eta_db, dphi, df, tau, tr.bits(chi_m), T, spacing,
                           rng=rng)
        # measurement epochs inside this epoch: the replica at that instant
        s_end = s + Tk
        hits = []
        while True:
            m = nxt
            tm = t_m[np.minimum(m, M - 1)]
            hit = (m < M) & (tm < s_end)
            if not hit.any():
                break
            r, c = rows[hit], colsS[hit]
            mm = m[hit]
            dt = tm[hit] - s[hit]
            ser["code_chips"][mm, r, c] = chi[hit] + cr[hit] * dt
            ser["carrier_cycles"][mm, r, c] = -(phi[hit] + f[hit] * dt - phi_start[hit])
            ser["cn0_dbhz"][mm, r, c] = cn0_now[hit]
            ser["locked"][mm, r, c] = lock_now[hit]
            nxt = np.where(hit, nxt + 1, nxt)
            hits.append((mm, r, c))
        # the loop
        iq = [x.early.real, x.early.imag, x.prompt.real, x.prompt.imag, x.late.real,
              x.late.imag]
        fc, kc, dop = np.empty(shape), np.empty(shape), np.empty(shape)
        tag = np.empty(shape)
        for idx, trk in groups:
            out = trk.frequencies_hz(trk.step(*(v[:, idx] for v in iq)))
            fc[:, idx], kc[:, idx] = out
            dop[:, idx] = np.asarray(trk.doppler_hz(), np.float64)
            tag[:, idx] = s_end[:, idx] + getattr(trk, "doppler_offset_epochs", 0.0) * Tk[:, idx]
        for mm, r, c in hits:
            if doppler_instant and prev is not None:
                d0, t0_ = prev[0][r, c], prev[1][r, c]
                ser["doppler_hz"][mm, r, c] = d0 + (dop[r, c] - d0) * (t_m[mm] - t0_) \
                    / (tag[r, c] - t0_)
            else:
                ser["doppler_hz"][mm, r, c] = dop[r, c]
        prev = (dop, tag)
        if det.update(x.prompt):
            cn0_now = np.broadcast_to(det.cn0_dbhz, shape).copy()
            lock_now = np.asarray(det.phase_lock & det.cn0_lock)
        phi = phi + f * Tk
        chi = chi + cr * Tk
        s = s_end
        th_start = th_e
        pending.append((fc, kc))
        f, cr = pending.pop(0)
        k += 1
        if progress is not None and k % 1000 == 0:
            progress(k, n_epochs)
        if np.all(nxt >= M) or k > n_epochs + 10:
            break
    track_wall = time.perf_counter() - t_track
    runs = fixes_from_series(sig, prns, t_m, ser, gps, hot_ephemerides, iono)
    truth = sig.truth_at(t_m) if M else None
    if truth is not None:
        truth = _columns(truth, cols)
    return FastGpsRun(prns, t_m, ser, truth, runs, trials, float(dur),
                      time.perf_counter() - t_wall, track_wall,
                      {"chi0": sig.chi0, "frame_tow": sig.frame_tow, "tracker": run.tracker,
                       "dsp": run.dsp, "bn_hz": run.tracker_setting("bn_hz"), "dll_bn_hz": run.tracker_setting("dll_bn_hz"),
                       "adc_bits": adc_bits, "eta": eta, "spacing_chips": spacing,
                       "seed": seed, "rate_hz": gps.rate_hz, "mai": mai,
                       "doppler_instant": doppler_instant}, groups)


def _columns(truth, cols):
    """The truth restricted to the channels' satellites."""
    n = len(truth.prns)
    d = {f.name: getattr(truth, f.name) for f in fields(truth)}
    d = {k: v[:, cols] if isinstance(v, np.ndarray) and v.ndim == 2 and v.shape[1] == n else v
         for k, v in d.items()}
    d["prns"] = tuple(truth.prns[j] for j in cols)
    return type(truth)(**d)


def fixes_from_series(sig, prns, t_m, ser, gps: GpsConfig = GpsConfig(),
                      hot_ephemerides=None, iono="broadcast") -> list:
    """Per trial (axis 1 of the ``ser`` arrays, (M, trials, S)): receiver time, observables
    and fixes at the measurement epochs ``t_m`` (module doc) through the IF path's
    :func:`~cosim.gnss.gps_receiver.fix_epoch`; a channel with a NaN code phase or Doppler
    is not used at that epoch. One :class:`~cosim.gnss.gps_receiver.GpsRun` per trial."""
    cfg = sig.cfg
    trials = ser["code_chips"].shape[1]
    ephs = tuple(sig.ephemerides if hot_ephemerides is None else hot_ephemerides)
    kl = cfg.klobuchar if isinstance(iono, str) and iono == "broadcast" else iono
    fs = float(cfg.fs_hz)
    prn_arr = np.array(prns, dtype=np.int64)
    runs = []
    for k in range(trials):
        clock = ReceiverTime(gps.initial_travel_s)
        epochs, ttff, t_set = [], None, None
        first = np.ones(len(prns), bool)
        for m, t in enumerate(t_m):
            n = int(round(t * fs))
            chi = ser["code_chips"][m, k]
            ok = np.isfinite(chi) & np.isfinite(ser["doppler_hz"][m, k])
            if not ok.any():
                epochs.append(GpsEpoch(n, cfg.week, math.nan, None, None))
                continue
            cnt = counts_from_chips(np.where(ok, chi, 0.0), sig.frame_tow)
            if not clock.is_set:
                from dsp.gnss.observables import transmit_time
                clock.set(float(np.max(transmit_time(*cnt)[ok])), t)
                t_set = t
            tw, tf = clock.at(t)
            eph = [select_ephemeris(ephs, int(p), cfg.week, tw + tf) for p in prns]
            lli = (first | ~ser["locked"][m, k]).astype(np.int64)
            first[:] = False
            sel = np.flatnonzero(ok)
            ep = fix_epoch(n, (tw, tf), prn_arr[sel], [c[sel] for c in cnt],
                           [eph[j] for j in sel], ser["doppler_hz"][m, k, sel],
                           ser["cn0_dbhz"][m, k, sel], ser["carrier_cycles"][m, k, sel],
                           lli[sel], reference_week=cfg.week, iono=kl, config=gps)
            epochs.append(ep)
            if ep.solution.valid:
                if ttff is None:
                    ttff = t
                clock.steer(ep.solution.clock_bias_s)
        runs.append(GpsRun([], epochs, fs, "hot", ttff, t_set))
    return runs
