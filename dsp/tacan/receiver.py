"""TACAN bearing processor: peaks -> reference decoding -> Kalman filter -> bearings.

Input is what the FPGA hands over (peak times and amplitudes); several trials that share
one pulse timeline run as a batch. Bearings are produced when each reference burst has been
decoded (up to 135 per second), from the filter state at the latest pulse.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..fixed import FixedFormat
from ..shown import valid_figures
from .bearing import (ANGLE_BITS, TWO_PI, bangle_to_deg, bearing_from_state, combine_coarse_fine,
                      deg_to_bangle, reference_advances, track_sector, wrap_deg)
from .decode import DecoderConfig, decode, outside_bursts
from .rotation import rotation_track
from .scoring import REF_MAIN
from .kalman import EnvelopeKalman
from .kalman_config import KalmanConfig, KalmanFixedConfig
from .standard import F15, F135
from .pairsource import choose_pairs, pair_centres
from .peakbias import PeakBias
from .standard import SOURCE_PAIR, SOURCE_PULSE, burst_offsets, pair_spacing_s


@dataclass
class BearingTrack:
    """Bearing outputs of a run (one row per trial)."""

    times_s: np.ndarray        # (M,) when each bearing was produced
    ref_kinds: np.ndarray      # (M,) reference that triggered it
    bearing_deg: np.ndarray    # (B, M) combined bearing in [0, 360)
    coarse_deg: np.ndarray     # (B, M) from the 15 Hz component alone
    n_updates: int             # Kalman measurement updates
    n_peaks: int               # peaks received
    n_measurements: int        # peaks accepted as amplitude measurements
    n_main_refs: int
    n_aux_refs: int
    n_refs_off_grid: int       # decoded bursts dropped as off the 135 Hz grid (false decodes)
    gated: np.ndarray          # (B,) measurements rejected by the innovation gate
    reinit: np.ndarray         # (B,) divergence re-initialisations
    r_est: np.ndarray          # (B,) estimated amplitude noise variance
    events: dict = field(default_factory=dict)  # DSP core event counters, name -> (B,)
    state: "ReceiverState | None" = None        # to continue with the next block
    valid: np.ndarray | None = None  # (B, M) fit for use: not flagged (see ReceiverConfig)
    produced_s: np.ndarray | None = None  # (M,) when each bearing became available (the
    #: reference known and the pulses up to it filtered; >= times_s)
    coarse_sigma_deg: np.ndarray | None = None  # (B, M) the filter's coarse-bearing std (deg)
    #: what the amplitude measurements were (:data:`dsp.tacan.pairsource.MEASURED_ON`) and,
    #: with both searches, the share of pair reports whose two pulses the single-pulse
    #: search reported (:func:`dsp.tacan.pairsource.paired_fraction`; None otherwise)
    measured_on: str = "pulses"
    paired_fraction: float | None = None

    def first_valid_s(self) -> np.ndarray:
        """Per trial: when the first valid (not flagged) bearing became available (s from
        the start of the record; NaN: none) -- the time to first bearing."""
        B = self.bearing_deg.shape[0]
        out = np.full(B, np.nan)
        if self.valid is None or self.produced_s is None or not self.produced_s.size:
            return out
        for b in range(B):
            i = np.flatnonzero(self.valid[b])
            if i.size:
                out[b] = float(self.produced_s[i[0]])
        return out


@dataclass(frozen=True)
class ReceiverConfig:
    """The bearing DSP.

    ``kalman`` chooses the arithmetic of the filter (the one source of
    :mod:`dsp.tacan.kalman`): a :class:`KalmanConfig` runs it in float64 (golden), a
    :class:`KalmanFixedConfig` in fixed point with its word lengths.
    """

    mode: str = "X"
    kalman: KalmanConfig | KalmanFixedConfig = field(default_factory=KalmanConfig)
    decoder: DecoderConfig | None = None
    density_weighting: bool = True
    #: A bearing is flagged (``BearingTrack.valid`` False, counted as ``flagged_bearings``)
    #: -- what a bearing indicator shows as its warning flag -- when
    #:
    #: * the filter is still warming up after its (re)initialisation (fewer than ``warmup``
    #:   updates);
    #: * the latest ``flag_gated`` or more measurements in a row were rejected by the
    #:   innovation gate (the state disagrees with the signal: corrupted state, lost track);
    #: * the 15 Hz (coarse) bearing and the combined one differ by more than
    #:   ``flag_sector_deg``: the 40 deg sector of the 135 Hz (fine) phase is ambiguous
    #:   (it is chosen wrongly beyond 20 deg; in normal operation the difference stays below
    #:   ~9 deg down to -3 dB SNR);
    #: * the estimated amplitude noise ``sqrt(r)`` exceeds ``flag_noise_ratio`` times the
    #:   pulse level ``dc``: the filter has fitted something that is not the signal (its
    #:   ``r`` estimate grows from the misfit; ~0.44 at -3 dB SNR in normal operation);
    #: * the reference timing is not confirmed yet: no rotation-rate estimate so far (with
    #:   ``track_rotation``; a 135 Hz grid through ``DecoderConfig.min_grid_refs`` references
    #:   spanning ``rotation_span_s``). Main references inferred by the rotation-slot
    #:   detector give no bearing at all before its declaration;
    #: * the filter was re-initialised because its state moved between two references by
    #:   more than the measurements can move it, twice in a row (``flag_state_jump``):
    #:   flagged through the warm-up that follows.
    #:
    #: Input beyond the DSP's input range is never measured (``KalmanConfig.input_limit``)
    #: and flags the bearings while it lasts. Known limit: garbage *within* the range that
    #: lasts long enough to re-initialise the filter (``max_rejects`` gated in a row) and is
    #: still arriving enters the new fit; late in that refit the 15 Hz phase can be 25-35
    #: deg off with a plausible noise estimate, and the resulting 40 deg sector slip is not
    #: flagged (see ``tests/dsp/test_tacan_receiver.py``; the fault study reports it as
    #: *misleading*). The state-continuity check below does not see it: those moves are the
    #: filter's own, on measurements it was given.
    flag_gated: int = 1
    flag_sector_deg: float = 12.0
    flag_noise_ratio: float = 0.5
    #: Rotation-rate tracking: the beacon's rotation rate is estimated from the references
    #: known so far (:func:`dsp.tacan.rotation.rotation_track`: the 135 Hz grid's period over
    #: the latest 2 s, once they span ``rotation_span_s``: early, so that little of the fit
    #: is made at a wrong rate), and the Kalman model and the
    #: bearing's phase advances turn at it (15 Hz exactly on a nominal beacon: the
    #: estimate's resolution is 1e-5). False: 15 Hz assumed.
    track_rotation: bool = True
    rotation_span_s: float = 0.05
    #: Near the noise floor (``Decoded.near_floor``: references acquired across bursts, or
    #: bursts decoded incomplete) the 40 deg sector is tracked from output to output and
    #: changed only when the coarse bearing disagrees on average
    #: (:func:`dsp.tacan.bearing.track_sector`); elsewhere, and with False, each output
    #: takes the sector nearest its own coarse bearing.
    sector_track: bool = True
    #: Near the noise floor (``Decoded.near_floor``) a bearing is also flagged when the
    #: filter's own standard deviation of the coarse bearing
    #: (:meth:`EnvelopeKalman.coarse_sigma_deg`) exceeds this: the 40 deg sector is then
    #: uncertain (a 2-sigma margin on the 20 deg that resolve it; the filter's value is
    #: conservative: 7-9 deg at 0 dB, where the coarse error measured 4.9 deg rms; 15-19 deg
    #: at -3 dB, where it measured 20-39 deg and, unflagged, a record gave 15 bearings 38
    #: deg off as valid). None: off.
    flag_coarse_sigma_deg: float | None = 10.0
    #: State continuity: at each reference the filter's state is compared with the one at
    #: the previous reference turned by the model (:meth:`EnvelopeKalman.state_jump`); a
    #: block that moved more than this many standard deviations of what the measurements
    #: since can move it was changed by something else -- a corrupted DSP memory word. So
    #: is a covariance that grew faster than the process noise or is no covariance
    #: (:meth:`EnvelopeKalman.covariance_fault`). Either puts the state and covariance
    #: back to the previous reference's, predicted to now (:meth:`EnvelopeKalman.recover`:
    #: the measurements between are lost; counted as ``state_faults``); a second failed
    #: check in a row re-initialises the filter (its bearings flagged through the
    #: warm-up). Normal operation: median ~1.6; the largest over 80 clean 3 s records from
    #: -3 to 20 dB (golden and model/fixed chains) 4.6 with the single-pulse search, 7.0
    #: with both. Without it a corrupted state inside the innovation gate goes unseen: a
    #: 15 Hz term moved 60 deg makes a 40 deg sector slip that the sector check passes
    #: while the filter creeps back; a covariance word raised by 2**13 makes the filter
    #: refit one term from a few pulses (a bearing 128 deg off, shown valid). DSP-state
    #: upsets at 1e-6 per bit and update (``faults tacan --target dsp-state``, 100
    #: records): 2.44 % of the bearings misleading without it, none with it. None: off.
    flag_state_jump: float | None = 12.0
    #: Each peak is a pulse *pair* (the FPGA's pulse-pair detection,
    #: :attr:`dsp.tacan.peak_params.PeakParams.pair_offset`; ``python -m cosim tacan --detector pair``):
    #: timestamped at its second pulse, with the pair's mean envelope. The decoder reads
    #: the pairs' two pulses, the mode's pair spacing apart (:func:`expand_pairs`); the
    #: filter takes each report once, at its pair's centre
    #: (:func:`dsp.tacan.pairsource.pair_centres`), as with both searches -- not as two
    #: pulses at that amplitude, which biases the bearing by a constant (ideal front end:
    #: +0.0035 deg X, +0.0056 deg Y against the single pulses, every bearing).
    pair_reports: bool = False
    #: The front end's peak-amplitude bias near its threshold
    #: (:class:`dsp.tacan.peakbias.PeakBias`, e.g. ``PAIR_PEAK_BIAS`` for the pair
    #: detector): the threshold is estimated from each block's reports and the filter
    #: expects each report at its predicted amplitude plus that bias. None: reports are
    #: taken as unbiased.
    peak_bias: PeakBias | None = None
    #: With both searches (``source``): when at least this share of the block's pair
    #: reports has both its pulses among the single-pulse reports (the paired fraction, ~0.24
    #: at 0 dB, ~0.54 at 3 dB, ~0.81 at 6 dB), the DSP measures on those confirmed pair
    #: reports only, leaving out the noise pairs and half pairs that bend the envelope;
    #: below it, near the floor, on every pair report (:mod:`dsp.tacan.pairsource`). None:
    #: always on every pair report.
    confirm_pairs_above: float | None = 0.45

    def __post_init__(self):
        if self.mode not in ("X", "Y"):
            raise ValueError(f"mode must be 'X' or 'Y', not {self.mode!r}")
        if isinstance(self.flag_gated, bool) or not isinstance(self.flag_gated, int) \
                or self.flag_gated < 1:
            raise ValueError(f"flag_gated must be an integer >= 1, not {self.flag_gated!r}")
        if not 0 < float(self.flag_sector_deg) <= 20:
            raise ValueError(f"flag_sector_deg must be in (0, 20] (half a fine-phase sector), "
                             f"not {self.flag_sector_deg!r}")
        if self.flag_state_jump is not None and not float(self.flag_state_jump) > 0:
            raise ValueError(f"flag_state_jump must be > 0 (standard deviations) or None, not "
                             f"{self.flag_state_jump!r}")
        if self.flag_coarse_sigma_deg is not None and not float(self.flag_coarse_sigma_deg) > 0:
            raise ValueError(f"flag_coarse_sigma_deg must be > 0 or None, not "
                             f"{self.flag_coarse_sigma_deg!r}")
        if not isinstance(self.sector_track, bool):
            raise ValueError(f"sector_track must be True or False, not {self.sector_track!r}")
        if self.peak_bias is not None and not isinstance(self.peak_bias, PeakBias):
            raise ValueError(f"peak_bias must be a PeakBias or None, not {self.peak_bias!r}")
        if self.confirm_pairs_above is not None and not 0 < float(self.confirm_pairs_above) <= 1:
            raise ValueError(f"confirm_pairs_above must be in (0, 1] or None, not "
                             f"{self.confirm_pairs_above!r}")
        if not isinstance(self.pair_reports, bool):
            raise ValueError(f"pair_reports must be True or False, not {self.pair_reports!r}")
        if not isinstance(self.track_rotation, bool):
            raise ValueError(f"track_rotation must be True or False, not {self.track_rotation!r}")
        if not 0 < float(self.rotation_span_s) <= 10:
            raise ValueError(f"rotation_span_s must be in (0, 10] s, not {self.rotation_span_s!r}")
        if not float(self.flag_noise_ratio) > 0:
            raise ValueError(f"flag_noise_ratio must be > 0, not {self.flag_noise_ratio!r}")
        if not isinstance(self.kalman, (KalmanConfig, KalmanFixedConfig)):
            raise ValueError(f"kalman must be a KalmanConfig (float) or KalmanFixedConfig "
                             f"(fixed point), not {self.kalman!r}")

    @property
    def dsp(self) -> str:
        """``"float"`` or ``"fixed"``."""
        return "fixed" if isinstance(self.kalman, KalmanFixedConfig) else "float"


@dataclass
class ReceiverState:
    """What the bearing processor carries from one block of peaks to the next (streaming):
    the filter, the latest main reference and the last pulse fed to the filter."""

    kf: EnvelopeKalman
    last_main_s: float | None = None
    last_t_s: float | None = None
    last_tick: int | None = None
    recent_refs_s: np.ndarray = field(default_factory=lambda: np.empty(0))  # rate tracker input
    rotation_hz: float | None = None   # the rate tracker's latest estimate (None: none yet)
    sector: tuple | None = None        # the sector tracker's state (bearing.track_sector)


def process_peaks(times_s, amplitudes, cfg: ReceiverConfig | None = None, *,
                  ticks=None, state: ReceiverState | None = None, source=None) -> BearingTrack:
    """Run the bearing DSP on pulse peaks.

    Parameters
    ----------
    times_s : array (N,)
        Peak times (s), ascending.
    amplitudes : array (N,) or (B, N)
        Peak amplitudes, one row per trial (any common scale), or -- fixed-point DSP only --
        integer codes in the core's ``y`` format (see :func:`amplitude_codes`).
    ticks : array of int (N,), optional
        The same times as integer clock ticks (the FPGA timestamps, unwrapped): the filter
        then steps by exact tick differences instead of rounded seconds. Their clock is the
        filter configuration's (``cfg.kalman.tick_hz``, :attr:`KalmanConfig.tick_hz`).
    state : ReceiverState, optional
        Continue from an earlier block (streaming); the updated state is returned in
        ``track.state``. A reference burst split across two blocks is not decoded.
    source : array of int (N,), optional
        Two searches in the front end (:attr:`dsp.tacan.frontend.FrontendConfig.pair_peak`):
        which one reported each peak (``SOURCE_PULSE`` / ``SOURCE_PAIR``; each search's
        peaks ascending, the two interleaved in any order). The single pulses are decoded
        (references, acquisition, the mode check, which needs the pairs' partners); the
        pair reports, each at its pair's centre (:func:`dsp.tacan.pairsource.pair_centres`),
        are the amplitude measurements -- near the noise floor those outside the reference
        bursts -- with ``cfg.peak_bias`` (its ``confirmed`` model on the confirmed ones)
        estimated on them. Not with ``cfg.pair_reports``.
    """
    cfg = cfg or ReceiverConfig()
    t = np.asarray(times_s, dtype=np.float64)
    if ticks is not None:
        ticks = np.asarray(ticks)
        if ticks.dtype.kind not in "iu" or ticks.shape != t.shape:
            raise ValueError("ticks must be integers, one per peak time")
    amps = np.atleast_2d(np.asarray(amplitudes))
    if amps.dtype.kind in "iu":
        if cfg.dsp != "fixed":
            raise ValueError("integer amplitude codes need the fixed-point DSP "
                             "(ReceiverConfig(kalman=KalmanFixedConfig(...)))")
        amps = amps.astype(np.int64)
    else:
        amps = amps.astype(np.float64)
    if amps.shape[1] != t.size:
        raise ValueError(f"{amps.shape[1]} amplitudes for {t.size} peak times")
    if not (np.all(np.isfinite(t)) and (amps.dtype.kind == "i" or np.all(np.isfinite(amps)))):
        raise ValueError("peak times and amplitudes must be finite (NaN/inf from the front end)")
    dcfg = cfg.decoder or DecoderConfig(mode=cfg.mode)
    n_peaks = int(t.size)
    paired, measured_on = None, "pairs" if cfg.pair_reports else "pulses"
    bias = cfg.peak_bias         # the bias model of the reports measured on
    if source is not None:
        src = np.asarray(source)
        if src.shape != t.shape or src.dtype.kind not in "iu" \
                or not np.isin(src, (SOURCE_PULSE, SOURCE_PAIR)).all():
            raise ValueError(f"source must be one search per peak ({SOURCE_PULSE} = single "
                             f"pulses, {SOURCE_PAIR} = pairs)")
        if cfg.pair_reports:
            raise ValueError("source splits the peaks into single pulses and pair reports; "
                             "pair_reports says every peak is a pair: not both")
        dec = decode(t[src == SOURCE_PULSE], cfg.mode, dcfg)
        pm = src == SOURCE_PAIR
        keep, paired, measured_on = choose_pairs(t[pm], t[src == SOURCE_PULSE], cfg.mode,
                                                 dcfg.tol_s, cfg.confirm_pairs_above)
        if measured_on == "confirmed pairs" and bias is not None and bias.confirmed is not None:
            bias = bias.confirmed      # the confirmed reports' own bias (PeakBias.confirmed)
        # the threshold from every pair report (the noise pairs make its low quantile)
        thr = bias.threshold(amps[:, pm]) if bias is not None else None
        pm[pm] = keep
        t, amps = t[pm], amps[:, pm]
        ticks = ticks[pm] if ticks is not None else None
    else:
        thr = bias.threshold(amps) if bias is not None else None
    if cfg.pair_reports:       # the decoder reads the pairs' pulses (their times)
        dec = decode(expand_pairs(t, amps, cfg.mode, ticks=ticks, tick_hz=cfg.kalman.tick_hz,
                                  tol_s=dcfg.tol_s)[0], cfg.mode, dcfg)
    if source is None and not cfg.pair_reports:
        dec = decode(t, cfg.mode, dcfg)
        sel = np.flatnonzero(dec.measurement_mask)
    else:                      # pair reports: one measurement each, at its pair's centre
        t, amps, ticks = pair_centres(t, amps, cfg.mode, ticks=ticks, tick_hz=cfg.kalman.tick_hz)
        # near the floor those outside the bursts (measured, both searches, 0 dB, 8
        # records: RMSE 0.461 / 0.420 deg at 90 / 270 deg; with the bursts' 0.519 / 0.388)
        sel = np.flatnonzero(outside_bursts(t, dec, cfg.mode) if dec.near_floor
                             else np.ones(t.size, bool))
    tm, ym = t[sel], amps[:, sel]
    r_mult = burst_r_mult(tm, dec, cfg.mode) if cfg.density_weighting else None
    B = amps.shape[0]
    if state is None:
        state = ReceiverState(kf=EnvelopeKalman(cfg.kalman, batch=B))
    elif state.kf.batch != B or state.kf.cfg != cfg.kalman:
        raise ValueError("state belongs to a receiver with another batch size or filter")
    kf = state.kf
    if thr is not None:      # amplitude codes: their threshold in signal units
        thr = math.ldexp(thr, -cfg.kalman.y.frac) if amps.dtype.kind == "i" else thr
        kf.set_peak_bias(*bias.table(thr), noise=bias.noise_rule(thr))

    n_ref = dec.ref_times_s.size
    out_t, out_k, out_b, out_c = [], [], [], []
    # Fixed-point DSP with integer timestamps: the bearing is computed with integers only
    # (CORDIC atan2 and magnitudes, binary angles), after the loop for all outputs at once.
    integer_bearing = cfg.dsp == "fixed" and ticks is not None
    out_x, out_dt = [], []
    out_ok = []
    out_ready = []                   # the sector tracker's: warmed up, timing confirmed
    out_sig = []                     # the coarse bearing's standard deviation (deg)
    last_main = state.last_main_s
    # Reference bursts become known when their last pulse has arrived.
    ref_order = np.argsort(dec.ref_done_s, kind="stable")
    ref_done = dec.ref_done_s[ref_order]
    ref_t = dec.ref_times_s[ref_order]
    ref_k = dec.ref_kinds[ref_order]
    if cfg.track_rotation:
        # known before this block, then each reference in the order it becomes known
        prior = state.recent_refs_s
        rates, confirmed = rotation_track(np.concatenate([prior, ref_t]), dcfg.tol_s,
                                          int(dcfg.min_grid_refs), float(cfg.rotation_span_s),
                                          prior_rate=state.rotation_hz)
        rates, confirmed = rates[prior.size:], confirmed[prior.size:]
        state.recent_refs_s = np.concatenate([prior, ref_t])[-4 * int(2.0 * F135):]
        if confirmed.any():
            state.rotation_hz = float(rates[-1])
    else:
        rates, confirmed = np.full(n_ref, F15), np.ones(n_ref, bool)
    out_done = []
    out_f = []
    # Segments of pulses between the moments a reference burst becomes known.
    if ticks is not None:
        tk = ticks.astype(np.int64)[sel]
        prev = tk[:1] if state.last_tick is None else np.array([state.last_tick], np.int64)
        dts = np.diff(tk, prepend=prev) if tk.size else tk
    else:
        prev = tm[:1] if state.last_t_s is None else np.array([state.last_t_s])
        dts = np.diff(tm, prepend=prev) if tm.size else tm
    stops = np.searchsorted(tm, ref_done - 1e-9, side="left") + 1  # pulses up to the done time
    k = 0
    for r in range(n_ref):
        stop = min(int(stops[r]), tm.size)
        if stop > k:
            kf.run(dts[k:stop], ym[:, k:stop], None if r_mult is None else r_mult[k:stop])
            k = stop
        if cfg.flag_state_jump is not None and k > 0:
            # the state may only have turned and taken its corrections since the last
            # reference: moved further, it is corrupted -- back to the last reference's
            # (twice in a row: start again, flagged through the warm-up)
            kf.recover((kf.state_jump() > cfg.flag_state_jump) | kf.covariance_fault())
            kf.checkpoint()
        if rates[r] != kf.rotation_hz:       # the rate known once this reference is
            kf.set_rotation(rates[r])
        f_rot = kf.rotation_hz
        if k == 0:
            continue
        last_t = tm[k - 1]
        T = ref_t[r]
        if ref_k[r] == REF_MAIN:
            last_main = T
        if last_main is None:
            continue
        out_t.append(T)
        out_k.append(ref_k[r])
        out_done.append(max(float(ref_done[r]), float(last_t)))
        n_up, n_gated, noise = kf.health()
        out_sig.append(kf.coarse_sigma_deg())
        out_ok.append((n_up >= kf.kalman.warmup) & (n_gated < cfg.flag_gated)
                      & (noise <= cfg.flag_noise_ratio) & bool(confirmed[r]))
        out_ready.append((n_up >= kf.kalman.warmup) & bool(confirmed[r]))
        if integer_bearing:
            # the fixed-point DSP: integer state, integer tick differences (see below)
            t_hz = kf.tick_hz
            out_x.append(kf.x.copy())
            out_dt.append((int(tk[k - 1]) - int(round(last_main * t_hz)),
                           int(tk[k - 1]) - int(round(T * t_hz))))
            out_f.append(f_rot)
            continue
        a, b, m1, m2, _ = kf.phases()
        coarse = TWO_PI * f_rot * (last_t - last_main) - a
        fine9 = TWO_PI * (9 * f_rot) * (last_t - T) - b
        out_b.append(np.degrees(combine_coarse_fine(coarse, fine9, m1 * m1, 81.0 * m2 * m2)))
        out_c.append(np.degrees(coarse % TWO_PI))
    if k < tm.size:
        kf.run(dts[k:], ym[:, k:], None if r_mult is None else r_mult[k:])
    if tm.size:
        state.last_t_s = float(tm[-1])
        state.last_tick = int(tk[-1]) if ticks is not None else None
    state.last_main_s = last_main
    M = len(out_t)
    n_invalid = np.zeros(B, np.int64)
    ok = np.stack(out_ok, axis=1) if M else np.zeros((B, 0), bool)
    if integer_bearing and M:
        dt = np.array(out_dt, dtype=np.int64)
        fr = np.array(out_f)
        adv15, adv135 = np.empty(M, np.int64), np.empty(M, np.int64)
        for f in np.unique(fr):              # one pair of frequency words per rate
            m = fr == f
            adv15[m], adv135[m] = reference_advances(dt[m, 0], dt[m, 1], kf.tick_hz,
                                                     rotation_hz=float(f))
        sb = bearing_from_state(np.stack(out_x), cfg.kalman.x, adv15[:, None], adv135[:, None],
                                adv_bits=ANGLE_BITS)
        out_b = list(bangle_to_deg(sb.bearing))
        out_c = list(bangle_to_deg(sb.coarse))
        n_invalid = np.count_nonzero(~sb.valid, axis=0).astype(np.int64)
        ok = ok & sb.valid.T
    bearing = np.array(out_b).T.reshape(B, M) if M else np.zeros((B, 0))
    coarse = np.array(out_c).T.reshape(B, M) if M else np.zeros((B, 0))
    sig = np.stack(out_sig, axis=1) if M else np.zeros((B, 0))
    if cfg.sector_track and dec.near_floor and M:
        # the tracker starts once the filter has warmed up, the timing is confirmed and
        # the coarse bearing is trusted (its sigma within flag_coarse_sigma_deg): started
        # on a converging filter's coarse bearing it held a wrong sector for ~1 s
        ready = np.broadcast_to(np.stack(out_ready, axis=-1), (B, M))
        if cfg.flag_coarse_sigma_deg is not None:
            ready = ready & (sig <= cfg.flag_coarse_sigma_deg)
        if integer_bearing:                      # integers only: the core's binary angles
            tb, state.sector = track_sector(sb.bearing.T, sb.coarse.T, state.sector, ready=ready)
            bearing = bangle_to_deg(tb)
        else:                                    # the same decisions, whole sectors in float
            bb = deg_to_bangle(bearing)
            tb, state.sector = track_sector(bb, deg_to_bangle(coarse), state.sector, ready=ready)
            half = np.int64(1) << np.int64(ANGLE_BITS - 1)
            w = ((tb - bb + half) & ((half << np.int64(1)) - 1)) - half
            k = (9 * w + half) >> np.int64(ANGLE_BITS)
            bearing = (bearing + 40.0 * k) % 360.0
    ok = ok & (np.abs(wrap_deg(coarse - bearing)) <= cfg.flag_sector_deg)
    if dec.near_floor and cfg.flag_coarse_sigma_deg is not None:
        ok = ok & (sig <= cfg.flag_coarse_sigma_deg)
    n_flagged = np.count_nonzero(~ok, axis=1).astype(np.int64)
    return BearingTrack(
        times_s=np.array(out_t), ref_kinds=np.array(out_k, np.int8),
        bearing_deg=bearing, coarse_deg=coarse,
        n_updates=kf.n_updates, n_peaks=n_peaks, n_measurements=int(sel.size),
        n_main_refs=int(np.sum(dec.ref_kinds == REF_MAIN)),
        n_aux_refs=int(np.sum(dec.ref_kinds != REF_MAIN)), n_refs_off_grid=dec.n_off_grid,
        gated=kf.events["gated"], reinit=kf.events["reinit"], r_est=kf.r.copy(),
        events={**kf.events, "invalid_bearings": n_invalid, "flagged_bearings": n_flagged},
        state=state, valid=ok, produced_s=np.array(out_done),
        coarse_sigma_deg=sig, measured_on=measured_on, paired_fraction=paired)


def expand_pairs(times_s, amplitudes, mode: str, *, ticks=None, tick_hz: float | None = None,
                 tol_s: float = 1e-6):
    """Pulse-pair reports -> the pairs' pulses: each report at ``t`` becomes pulses at
    ``t - pair_spacing_s(mode)`` and ``t`` with the report's amplitude (columns of
    ``amplitudes``, (B, N)), in time order; a pulse within ``tol_s`` after the previous one
    is the same pulse reported by two pairs and is dropped. With ``ticks`` the spacing is
    ``round(spacing * tick_hz)`` ticks and the times follow the ticks. Returns ``(times_s,
    amplitudes, ticks)``."""
    sp = pair_spacing_s(mode)
    t = np.asarray(times_s, dtype=np.float64)
    if ticks is not None:
        d = int(round(sp * tick_hz))
        tk = np.stack([ticks - d, ticks], axis=1).ravel()
        order = np.argsort(tk, kind="stable")
        tk = tk[order]
        t2 = tk / tick_hz
    else:
        t2 = np.stack([t - sp, t], axis=1).ravel()
        order = np.argsort(t2, kind="stable")
        t2, tk = t2[order], None
    amps = np.repeat(amplitudes, 2, axis=1)[:, order]
    # a pulse reported by two pairs (a train of pulses one spacing apart: the X-mode
    # auxiliary burst) is one pulse: the first report's
    keep = np.r_[True, np.diff(t2) > tol_s] if t2.size else np.zeros(0, bool)
    t2, amps = t2[keep], amps[:, keep]
    if tk is not None:
        tk = tk[keep]
    return t2, amps, tk


def amplitude_codes(amp_lsb, scale_to_fs: float, y: FixedFormat, gain_frac: int = 24):
    """DSP input stage: front-end amplitude LSBs -> the core's ``y`` codes, in integers.

    One constant multiply, as the DSP does it: ``y = round(amp * g / 2**gain_frac)`` with
    ``g = round(scale_to_fs * 2**(y.frac + gain_frac))`` (the float is used once, to build
    ``g``). Relative error of ``g`` < ``2**-(gain_frac)`` / ``scale``; values beyond the
    ``y`` range are not measurements for the core (counted as ``implausible``, see
    ``KalmanConfig.input_limit``).
    """
    a = np.asarray(amp_lsb)
    if a.dtype.kind not in "iu":
        raise ValueError(f"amplitudes must be integer LSBs, not dtype {a.dtype}")
    if not (math.isfinite(scale_to_fs) and scale_to_fs > 0):
        raise ValueError(f"scale_to_fs must be a finite number > 0, not {scale_to_fs}")
    g = int(round(scale_to_fs * 2.0 ** (y.frac + gain_frac)))
    a = a.astype(np.int64)
    if a.size and (int(np.abs(a).max()) * g).bit_length() > 62:
        raise ValueError(f"amplitude x gain does not fit 63 bits (gain_frac={gain_frac} too large)")
    return (a * np.int64(g) + (np.int64(1) << (gain_frac - 1))) >> gain_frac


def burst_r_mult(tm: np.ndarray, dec, mode: str) -> np.ndarray:
    """Measurement-noise multipliers that make the pulse density look uniform in time.

    A quarter of the pulses come in reference bursts (12-24 pulses within 144-342 us, at
    the same rotation phases every time), with a pulse-free guard around them. That density
    pattern is periodic with the rotation, so the envelope harmonics the 5-state model does
    not carry (from any amplitude nonlinearity: the Rician bias of the envelope, peak
    picking) leak into the 15 and 135 Hz states with a fixed phase: a bearing bias of a few
    hundredths of a degree at 10 dB. Giving the pulses of each burst together the weight of
    the random pulses their pulse-free window would have held (window = from the last
    non-burst pulse before to the first one after) restores a uniform effective density.
    """
    r = np.ones(tm.size)
    if dec.ref_times_s.size == 0 or tm.size < 2:
        return r
    in_burst = np.zeros(tm.size, bool)
    spans = []
    for T, kind in zip(dec.ref_times_s, dec.ref_kinds):
        span = burst_offsets(mode, "main" if kind == REF_MAIN else "aux")[-1]
        lo, hi = np.searchsorted(tm, [T - 2e-6, T + span + 2e-6])
        in_burst[lo:hi] = True
        spans.append((lo, hi))
    free = np.flatnonzero(~in_burst)
    if free.size < 2:
        return r
    rate = (free.size - 1) / (tm[free[-1]] - tm[free[0]])   # density of non-burst pulses
    for lo, hi in spans:
        n = hi - lo
        if n == 0:
            continue
        j = np.searchsorted(free, lo)
        if j == 0 or j >= free.size:
            continue
        gap = tm[free[j]] - tm[free[j - 1]]
        weight = max(rate * gap - 1.0, 0.5)
        r[lo:hi] = n / weight
    return r


#: A bearing shown valid but further than this from the truth is *misleading* (a 40 deg
#: sector slip the flag missed).
MISLEADING_DEG = 20.0


def bearing_stats(track: BearingTrack, bearing_true_deg, settle_s: float) -> dict:
    """Error statistics of the bearings produced after ``settle_s`` (per trial arrays), and
    of those the receiver shows valid, as a user sees them (:func:`dsp.shown.valid_figures`
    of the bearings that became available from ``settle_s`` on, ``produced_s``, as
    :func:`cosim.tacan.run.shown_bearings` scores them): their count ``n_valid``, RMSE
    ``valid_rmse_deg`` (NaN without any) and how many are ``misleading`` (more than
    :data:`MISLEADING_DEG` off)."""
    keep = track.times_s >= settle_s
    truth = np.atleast_1d(np.asarray(bearing_true_deg, dtype=np.float64))[:, None]
    err = wrap_deg(track.bearing_deg[:, keep] - truth)
    B = track.bearing_deg.shape[0]
    shown = np.ones(track.bearing_deg.shape, bool) if track.valid is None else track.valid
    t = track.produced_s if track.produced_s is not None else track.times_s
    order = np.argsort(t, kind="stable")
    scored = order[t[order] >= settle_s]
    e_all = wrap_deg(track.bearing_deg - truth)
    v_all = np.broadcast_to(shown, e_all.shape)
    figs = [valid_figures(e_all[r, scored], v_all[r, scored], bound=MISLEADING_DEG)
            for r in range(e_all.shape[0])]
    vstats = {"n_valid": np.array([f["n_valid"] for f in figs], np.int64),
              "valid_rmse_deg": np.array([np.nan if f["rmse"] is None else f["rmse"]
                                          for f in figs]),
              "misleading": np.array([f["misleading"] for f in figs], np.int64)}
    if err.shape[1] == 0:
        nan = np.full(B, np.nan)
        return {"n": 0, "rmse_deg": nan, "mean_error_deg": nan, "max_abs_error_deg": nan,
                "final_deg": nan, **vstats}
    return {"n": int(err.shape[1]), "rmse_deg": np.sqrt(np.mean(err ** 2, axis=1)),
            "mean_error_deg": np.mean(err, axis=1), "max_abs_error_deg": np.max(np.abs(err), axis=1),
            "final_deg": track.bearing_deg[:, -1], **vstats}
