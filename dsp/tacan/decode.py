"""Reference-burst decoding and pulse-pair validation on the list of pulse peaks.

Done on the DSP side (not in the FPGA) on purpose: a decoder that is robust to missing and
extra pulses needs to look back over a whole burst (up to 342 us) and vote over alignments;
at 7200 peaks/s that is a few microseconds of DSP time per peak, whereas in the FPGA it
would need a peak history buffer and a voting network for each code. The FPGA ships every
peak with its timestamp; nothing is lost by deciding here.

Algorithm: every peak ``t_i`` and each of the first ``align`` template pulses ``j`` give a
hypothesis "the burst started at ``t_i - off_j``"; its score is how many template pulses
find a peak within ``tol_s``. Hypotheses scoring at least ``min_fraction`` of the template
are clustered (one burst per ``span``), the best of each cluster wins, and the burst time is
refined as the mean of ``t_match - off`` over the matched pulses.

Codes are periodic, so a burst whose first or last pulse is lost matches equally well one
code step early or late. Every reference lies on the 135 Hz grid (main ones too), so each
burst time is compared with the grid phase of its neighbours (median over +-8 bursts);
an offset that is a whole number of code steps (within ``tol_s``) is corrected, and a burst
off the grid by anything else is a false decode and is dropped (counted).

Below ~5 dB the main burst, which at some bearings sits in the envelope trough, is rarely
decoded on its own (bearing 90 deg, 4 dB: 1 main in 45) although the auxiliary bursts around
it are. What the signal guarantees then decides instead (:func:`_infer_main`, on with
``infer_main``): the references lie on one 135 Hz grid and the main burst takes exactly one
of the nine grid slots of a rotation. The grid is fitted to the decoded references (its
period gives the beacon's rotation rate, not assumed to be 15 Hz); at every grid position the
main and auxiliary templates are scored and accumulated per slot (grid index mod 9), rotation
by rotation, as the main template's share ``M / (M + A)`` of the matched fractions -- a
share that does not depend on how many pulses the detector catches (~0.2 in an auxiliary
slot, ~0.67 in the main slot in X mode, 0.5 on random peaks). The main slot is declared when
the best slot's share leads the runner-up's by ``slot_margin`` with ``min_slot_pulses``
matched pulses in it, after at least ``min_rotations`` rotations; from then on every rotation
gets its main reference at the grid time (a decoded auxiliary burst in that slot is relabelled,
a decoded main burst elsewhere is dropped and counted). References inferred before the
declaration are known only at the declaration (``ref_done_s``), so the DSP stays causal and
reports no bearing before it. False references: on noise alone no grid forms (too few decoded
references on one 135 Hz grid: ``min_grid_refs``); a beacon of the other mode gives no
template a lead. A record where the mains are all decoded (>= 5 dB) is left as it was.

Rotation rate: the beacon's antenna may turn slightly off 15 Hz (the references then lie
on a grid of period ``1 / (9 f)``). The grid's period is estimated from the decoded
references (:func:`dsp.tacan.rotation.estimate_rotation`: median of the gaps, then a
least-squares grid with indices counted gap by gap, so a beacon 5 % off still fits) and
rounded to :data:`dsp.tacan.rotation.RATE_QUANTUM` (a nominal beacon gives exactly 15 Hz).
The block's estimate sets the grid of :func:`_snap_to_grid` and of the rotation-slot
detector; the receiver tracks the rate causally (:func:`dsp.tacan.rotation.rotation_track`)
for its Kalman model and phase advances.

Near the noise floor (0 dB, references in the envelope trough) even the auxiliary bursts
rarely pass ``min_fraction`` alone, so no grid forms. When fewer than ``acquire_below`` of
the grid positions have a burst decoded alone, the references come from
:mod:`dsp.tacan.acquire` instead: a burst-code matched detector folded on the 135 Hz grid
(evidence summed over dozens of bursts), confirmed against the noise-peak rate (no grid on
noise or on a beacon of the other mode), tracked through missed bursts, with the main slot
declared by a likelihood-ratio test (see there). Its references are known from the
declaration on, so the bearing stays unreported until the reference timing is confirmed.

Measurements near the noise floor: when the decoded bursts are on average
``burst_complete_min`` complete or less, and always on the acquisition path, the pulses
within the bursts' spans are not amplitude measurements (a burst decodes there because noise
lifted its pulses over the threshold, or its template positions catch noise peaks: either
way amplitudes biased at one 135 Hz phase); the pulse pairs elsewhere are.

``min_fraction`` = 0.5 lets the main burst be found when the references sit in the envelope
trough at low SNR (bearing 90 deg: half the trough pulses fall under the detection
threshold at 6 dB). It cannot create main bursts from random pairs: those are at least
``min_pair_gap_s`` (50 us) apart, so at most a few template pairs (30 us apart) can match.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .acquire import AcquireConfig, acquire_references
from .rotation import estimate_rotation, fit_grid, period_median, quantize_rotation
from .scoring import REF_AUX, REF_MAIN, burst_scores, match_nearest
from .standard import F15, F135, burst_offsets, pair_spacing_s

@dataclass(frozen=True)
class DecoderConfig:
    mode: str = "X"
    tol_s: float = 1.0e-6
    min_fraction: float = 0.5
    align: int = 4
    infer_main: bool = True
    slot_margin: float = 0.2
    min_rotations: int = 3
    min_slot_pulses: int = 30
    min_pairs_x: int = 3
    min_grid_refs: int = 8
    #: Integrate evidence across bursts (:mod:`dsp.tacan.acquire`) when fewer than
    #: ``acquire_below`` of the grid's positions (9 per rotation) have a burst decoded alone.
    acquire: bool = True
    acquire_below: float = 0.5
    #: The pulses of the reference bursts are amplitude measurements only while the
    #: decoded bursts are on average more than this complete (measured: 0.99 at 6 dB, 270
    #: deg; 0.82 at 6 dB, 90 deg; 0.58 at 3 dB, 90 deg; 0.68 at 0 dB, 270 deg).
    burst_complete_min: float = 0.7
    #: Every pulse outside the reference bursts is a measurement, not only those of
    #: complete pairs, when fewer than this fraction of them are paired (0: never). For
    #: amplitudes that are the pair partner's envelope (``python -m cosim tacan --amplitude
    #: partner``), whose noise is not the one that made the detection: a pair qualification
    #: selects on the partner's noise again. The noise peaks among the single pulses read
    #: noise, at a constant rate (the modulation depth is diluted, the bearing not biased).
    #: The paired fraction measures the SNR whatever the bearing (golden chain, 2 s: 0.08 at
    #: -3 dB, 0.31 at 0 dB, 0.50 at 2 dB, 0.59 at 3 dB, 0.80 at 6 dB, 0.91 at 10 dB); single
    #: pulses were better at 0 dB (RMSE 0.56 / 0.62 deg against 0.83 / 1.22 at 90 / 270 deg)
    #: and worse at 3 dB (0.46 against 0.28 at 90 deg).
    single_pulses_below: float = 0.0

    def __post_init__(self):
        if self.mode not in ("X", "Y"):
            raise ValueError(f"mode must be 'X' or 'Y', not {self.mode!r}")
        if not self.tol_s > 0:
            raise ValueError(f"decoder tol_s must be > 0, not {self.tol_s}")
        if not 0 < self.min_fraction <= 1:
            raise ValueError(f"decoder min_fraction must be in (0, 1], not {self.min_fraction}")
        if int(self.align) < 1:
            raise ValueError(f"decoder align must be >= 1, not {self.align}")
        if not isinstance(self.acquire, bool):
            raise ValueError(f"decoder acquire must be True or False, not {self.acquire!r}")
        if not 0 <= self.acquire_below <= 1:
            raise ValueError(f"decoder acquire_below must be in [0, 1], not {self.acquire_below}")
        if not 0 <= self.single_pulses_below <= 1:
            raise ValueError(f"decoder single_pulses_below must be in [0, 1], not "
                             f"{self.single_pulses_below}")
        if not 0 <= self.burst_complete_min <= 1:
            raise ValueError(f"decoder burst_complete_min must be in [0, 1], not "
                             f"{self.burst_complete_min}")
        if not 0 < self.slot_margin <= 2:
            raise ValueError(f"decoder slot_margin must be in (0, 2], not {self.slot_margin}")
        if int(self.min_rotations) < 1:
            raise ValueError(f"decoder min_rotations must be >= 1, not {self.min_rotations}")
        if int(self.min_slot_pulses) < 1:
            raise ValueError(f"decoder min_slot_pulses must be >= 1, not {self.min_slot_pulses}")
        if not 1 <= int(self.min_pairs_x) <= 12:
            raise ValueError(f"decoder min_pairs_x must be in 1..12, not {self.min_pairs_x}")
        if int(self.min_grid_refs) < 3:
            raise ValueError(f"decoder min_grid_refs must be >= 3, not {self.min_grid_refs}")


@dataclass
class Decoded:
    """Decoded references and the pulses fit to be amplitude measurements."""

    ref_times_s: np.ndarray    # refined burst times (first-pulse time), sorted
    ref_kinds: np.ndarray      # REF_MAIN / REF_AUX
    ref_scores: np.ndarray     # matched pulses
    ref_done_s: np.ndarray     # time the burst's last pulse arrived (when a DSP knows it)
    measurement_mask: np.ndarray  # per input peak: belongs to a burst or a valid pair
    n_off_grid: int = 0        # decoded bursts dropped for being off the 135 Hz grid
    n_wrong_mode: int = 0      # main bursts of the other mode (X vs Y), dropped
    n_inferred_main: int = 0   # main references placed by the rotation-slot detector
    n_main_off_slot: int = 0   # decoded main bursts outside the declared slot (dropped)
    main_slot_s: float | None = None   # when the main slot was declared (None: never/not needed)
    rotation_hz: float | None = None   # beacon rotation rate of the block (estimate_rotation)
    acquired_s: float | None = None    # grid confirmed by dsp.tacan.acquire (None: not used)
    near_floor: bool = False   # near the noise floor: acquisition used or bursts incomplete


def _bursts(t: np.ndarray, offs: np.ndarray, cfg: DecoderConfig):
    n_al = min(int(cfg.align), len(offs))
    starts = (t[:, None] - offs[None, :n_al]).ravel()
    starts = np.unique(np.round(starts, 12))
    score = burst_scores(t, starts, offs, cfg.tol_s)
    need = int(np.ceil(cfg.min_fraction * len(offs)))
    good = np.flatnonzero(score >= need)
    if good.size == 0:
        return np.empty(0), np.empty(0, int), np.empty(0, int), np.zeros(len(t), bool)
    span = offs[-1]
    # Cluster hypotheses closer than the burst length; keep the best-scoring (earliest on ties).
    gs = starts[good]
    cluster = np.concatenate([[0], np.cumsum(np.diff(gs) > span)])
    order = np.lexsort((gs, -score[good], cluster))
    first = np.ones(order.size, bool)
    first[1:] = cluster[order][1:] != cluster[order][:-1]
    win = good[order[first]]
    targets = starts[win][:, None] + offs[None, :]
    idx, ok = match_nearest(t, targets.ravel(), cfg.tol_s)
    idx, ok = idx.reshape(targets.shape), ok.reshape(targets.shape)
    times = np.empty(win.size)
    used = np.zeros(len(t), bool)
    for k in range(win.size):
        m = ok[k]
        times[k] = np.mean(t[idx[k][m]] - offs[m])
        used[idx[k][m]] = True
    return times, score[win], np.full(win.size, 0), used


def decode(times_s, mode: str = "X", cfg: DecoderConfig | None = None) -> Decoded:
    """Decode main/auxiliary references and mark the peaks usable as measurements.

    Parameters
    ----------
    times_s : array of float
        Peak times (s), sorted ascending.
    """
    cfg = cfg or DecoderConfig(mode=mode)
    t = np.asarray(times_s, dtype=np.float64)
    if not np.all(np.isfinite(t)):
        raise ValueError("peak times must be finite (NaN/inf from the front end)")
    if t.size and np.any(np.diff(t) < 0):
        raise ValueError("peak times must be sorted ascending")
    if t.size == 0:
        z = np.empty(0)
        return Decoded(z, np.empty(0, np.int8), np.empty(0, int), z, np.zeros(0, bool))
    main_off = burst_offsets(cfg.mode, "main")
    aux_off = burst_offsets(cfg.mode, "aux")
    tm, sm, _, um = _bursts(t, main_off, cfg)
    tm, sm, n_wrong_mode = _mode_check(t, tm, sm, cfg)
    ta, sa, _, ua = _bursts(t, aux_off, cfg)
    # A burst found by both templates (overlapping spans) keeps the better fractional score.
    if tm.size and ta.size:
        span = max(main_off[-1], aux_off[-1])
        j, close = match_nearest(tm, ta, span)
        a_worse = close & (sa / len(aux_off) <= sm[j] / len(main_off))
        i, close_m = match_nearest(ta, tm, span)
        m_worse = close_m & (sm / len(main_off) < sa[i] / len(aux_off))
        ta, sa = ta[~a_worse], sa[~a_worse]
        tm, sm = tm[~m_worse], sm[~m_worse]
    ref_t = np.concatenate([tm, ta])
    kinds = np.concatenate([np.full(tm.size, REF_MAIN, np.int8), np.full(ta.size, REF_AUX, np.int8)])
    scores = np.concatenate([sm, sa])
    done = np.concatenate([tm + main_off[-1], ta + aux_off[-1]])
    o = np.argsort(ref_t, kind="stable")
    ref_t, kinds, scores, done = ref_t[o], kinds[o], scores[o], done[o]
    # The block's rotation rate (the 135 Hz grid's period; exactly 15 Hz on a nominal beacon,
    # see RATE_QUANTUM): the grid the references are snapped to and fitted with.
    f_rot = estimate_rotation(ref_t, cfg.tol_s, int(cfg.min_grid_refs))
    if f_rot is None:
        p_med = period_median(ref_t) if ref_t.size >= cfg.min_grid_refs else None
        f_rot = quantize_rotation(1.0 / (9.0 * p_med)) if p_med is not None else F15
    ref_t, on_grid = _snap_to_grid(ref_t, kinds, cfg, 1.0 / (9.0 * f_rot))
    n_off = int(np.count_nonzero(~on_grid))
    ref_t, kinds, scores, done = ref_t[on_grid], kinds[on_grid], scores[on_grid], done[on_grid]
    # again on the snapped references (the raw ones may hold too many mis-aligned bursts)
    f_est = estimate_rotation(ref_t, cfg.tol_s, int(cfg.min_grid_refs))
    f_rot = f_rot if f_est is None else f_est
    info = {}
    if cfg.infer_main:
        ref_t, kinds, scores, done, used, info = _infer_main(t, ref_t, kinds, scores, done,
                                                              main_off, aux_off, cfg, f_rot)
        um = um | used

    pair = pair_spacing_s(cfg.mode)
    _, fwd = match_nearest(t, t + pair, cfg.tol_s)
    _, back = match_nearest(t, t - pair, cfg.tol_s)
    n_rot = (t[-1] - t[0]) * (f_est or F15)
    if cfg.acquire and ref_t.size < cfg.acquire_below * 9 * n_rot:
        # Too few bursts decoded alone (near the noise floor): integrate across bursts
        # (dsp/tacan/acquire.py). Used only when it confirms a grid and a main slot.
        acq = acquire_references(t, cfg.mode, AcquireConfig(tol_s=cfg.tol_s))
        if acq is not None:
            sc = np.zeros(acq.ref_t.size, np.int64)
            # Measurements: the pulses of pairs outside the bursts. Near the noise floor a
            # burst's pulses are not: its template positions catch noise peaks too (their
            # amplitudes sit at the threshold), at one 135 Hz phase (measured at 0 dB,
            # bearing 90 deg, 8 records: RMSE 2.74 -> 0.87 deg without them).
            mask = _measurements(t, fwd | back, acq.ref_t, acq.kinds, main_off, aux_off, cfg)
            return Decoded(acq.ref_t, acq.kinds, sc, acq.done, mask, n_off,
                           n_wrong_mode=n_wrong_mode,
                           n_inferred_main=int(np.count_nonzero(acq.kinds == REF_MAIN)),
                           main_slot_s=acq.main_slot_s, acquired_s=acq.grid_s,
                           rotation_hz=quantize_rotation(1.0 / (9.0 * acq.period_s)),
                           near_floor=True)
    mask = um | ua | fwd | back
    near_floor = False
    if ref_t.size:
        n_tpl = np.where(kinds == REF_MAIN, main_off.size, aux_off.size)
        if np.mean(scores / n_tpl) < cfg.burst_complete_min:
            # Near the noise floor a burst is decoded when noise lifted enough of its
            # pulses over the threshold: its pulses' amplitudes are biased up, at one 135
            # Hz phase (bearing 90 deg, 3 dB, 8 records: mean error -0.23 -> -0.13 deg,
            # RMSE 0.34 -> 0.25 deg without them). The pairs outside the bursts remain.
            mask = _measurements(t, fwd | back, ref_t, kinds, main_off, aux_off, cfg)
            near_floor = True
    return Decoded(ref_t, kinds, scores, done, mask, n_off, n_wrong_mode=n_wrong_mode,
                   rotation_hz=f_est, near_floor=near_floor, **info)


def _measurements(t, paired, ref_t, kinds, main_off, aux_off, cfg: DecoderConfig):
    """Near the noise floor: the pulses outside the bursts, those of complete pairs unless
    fewer than ``cfg.single_pulses_below`` of them are paired."""
    out = ~_in_bursts(t, ref_t, kinds, main_off, aux_off)
    if out.any() and np.mean(paired[out]) < cfg.single_pulses_below:
        return out
    return paired & out


def outside_bursts(times_s, dec: Decoded, mode: str) -> np.ndarray:
    """Per peak time: not within the span of one of ``dec``'s reference bursts."""
    t = np.asarray(times_s, dtype=np.float64)
    if dec.ref_times_s.size == 0:
        return np.ones(t.size, bool)
    return ~_in_bursts(t, dec.ref_times_s, dec.ref_kinds, burst_offsets(mode, "main"),
                       burst_offsets(mode, "aux"))


def _in_bursts(t, ref_t, kinds, main_off, aux_off):
    """Peaks within the span of a reference burst (first to last pulse)."""
    o = np.argsort(ref_t)
    starts = ref_t[o]
    ends = (ref_t + np.where(kinds == REF_MAIN, main_off[-1], aux_off[-1]))[o]
    j = np.searchsorted(starts, t, side="right") - 1
    return (j >= 0) & (t <= ends[np.maximum(j, 0)])


def _mode_check(t, tm, sm, cfg: DecoderConfig):
    """Drop main bursts of the other mode. The two main codes share 12 pulses 30 us apart
    (X: pairs 12 us wide; Y: single pulses), so each template finds half or more of the other
    mode's main burst, in X at either alignment of its pairs. Whole pairs tell them apart:
    an X receiver keeps a burst only with at least ``min_pairs_x`` pairs found complete (a Y
    burst has none but by a noise peak 12 us after a pulse); a Y receiver drops a burst
    whose pulses have a partner 12 us later at half the rate they are found or more (an X
    burst's pairs)."""
    if tm.size == 0:
        return tm, sm, 0
    if cfg.mode == "X":
        off = burst_offsets("X", "main")
        _, ok = match_nearest(t, (tm[:, None] + off[None, :]).ravel(), cfg.tol_s)
        ok = ok.reshape(tm.size, off.size)
        keep = np.count_nonzero(ok[:, 0::2] & ok[:, 1::2], axis=1) >= cfg.min_pairs_x
    else:
        off = burst_offsets("Y", "main")
        _, ok = match_nearest(t, (tm[:, None] + off[None, :]).ravel(), cfg.tol_s)
        _, ok12 = match_nearest(t, (tm[:, None] + off[None, :] + pair_spacing_s("X")).ravel(), cfg.tol_s)
        ok, ok12 = ok.reshape(tm.size, off.size), ok12.reshape(tm.size, off.size)
        keep = np.count_nonzero(ok & ok12, axis=1) < 0.5 * np.count_nonzero(ok, axis=1)
    return tm[keep], sm[keep], int(np.count_nonzero(~keep))


def _main_slot_vote(ref_t, kinds, cfg: DecoderConfig, f_rot: float):
    """Decoded mains outside the 135 Hz grid slot that two thirds of them share become
    auxiliaries (the main burst repeats once per rotation in one slot of nine). Returns the
    kinds and how many mains were moved."""
    fit = fit_grid(ref_t, 1.0 / (9.0 * f_rot), cfg.tol_s, int(cfg.min_grid_refs))
    main = kinds == REF_MAIN
    if fit is None or not main.any():
        return kinds, 0
    slot = fit[2] % 9
    votes = np.bincount(slot[main], minlength=9)
    s_main = int(np.argmax(votes))
    if votes[s_main] < max(int(cfg.min_rotations), np.ceil(2.0 * main.sum() / 3.0)):
        return kinds, 0
    off = main & (slot != s_main)
    return np.where(off, REF_AUX, kinds).astype(kinds.dtype), int(np.count_nonzero(off))


def _infer_main(t, ref_t, kinds, scores, done, main_off, aux_off, cfg: DecoderConfig,
                f_rot: float = F15):
    """The rotation-slot detector (module docstring). Returns the references, the peaks the
    inferred bursts matched, and the counts for :class:`Decoded`."""
    none = np.zeros(t.size, bool)
    n_rot = t.size and (t[-1] - t[0]) * f_rot
    if ref_t.size < cfg.min_grid_refs or n_rot < cfg.min_rotations:
        return ref_t, kinds, scores, done, none, {}
    # A record whose main bursts were all decoded needs no inference -- but a decoded main
    # off the slot most of them share is an auxiliary burst the main template took (Y mode
    # near 0 dB: 7 of 13 pulses; kept as a main, it moved the bearing 80 deg, valid).
    main_n = np.count_nonzero(kinds == REF_MAIN)
    if main_n >= np.floor(n_rot) - 1 and main_n >= cfg.min_rotations:
        kinds2, n_off_slot = _main_slot_vote(ref_t, kinds, cfg, f_rot)
        return ref_t, kinds2, scores, done, none, {"n_main_off_slot": n_off_slot}
    fit = fit_grid(ref_t, 1.0 / (9.0 * f_rot), cfg.tol_s, int(cfg.min_grid_refs))
    if fit is None:
        return ref_t, kinds, scores, done, none, {}
    a, p, n_ref = fit
    span = max(main_off[-1], aux_off[-1])
    lo = int(np.ceil((t[0] - a) / p))
    hi = int(np.floor((t[-1] - span - a) / p))
    if hi - lo + 1 < 9 * cfg.min_rotations:
        return ref_t, kinds, scores, done, none, {}
    n_all = np.arange(lo, hi + 1)
    starts = a + p * n_all
    sm = burst_scores(t, starts, main_off, cfg.tol_s)
    sa = burst_scores(t, starts, aux_off, cfg.tol_s)
    fm, fa = sm / main_off.size, sa / aux_off.size
    slot = n_all % 9
    # Rotation by rotation: per slot, the share of the main template in the matched template
    # fractions so far, M / (M + A). It does not depend on how many pulses the detector
    # catches: ~0.2 in an auxiliary slot (the main template finds 6 of 24 pulses of an
    # auxiliary burst), ~0.67 in the main slot (X mode), 0.5 on random peaks. Declared at the
    # first rotation end where the best slot leads the runner-up by slot_margin with at least
    # min_slot_pulses matched pulses in it.
    rot = (n_all - lo) // 9
    declared = None
    for r in range(int(cfg.min_rotations) - 1, int(rot[-1]) + 1):
        m = rot <= r
        M = np.bincount(slot[m], weights=fm[m], minlength=9)
        A = np.bincount(slot[m], weights=fa[m], minlength=9)
        pulses = np.bincount(slot[m], weights=(sm + sa)[m], minlength=9)
        share = np.where(M + A > 0, M / np.where(M + A > 0, M + A, 1.0), 0.0)
        order = np.argsort(share)
        if (share[order[-1]] - share[order[-2]] >= cfg.slot_margin
                and pulses[order[-1]] >= cfg.min_slot_pulses):
            declared = (int(order[-1]), int(n_all[m][-1]))
            break
    info = {}
    if declared is None:
        return ref_t, kinds, scores, done, none, info
    s_main, n_decl = declared
    t_decl = float(a + p * n_decl + span)
    ref_slot = n_ref % 9
    # Decoded mains outside the slot are false; auxiliaries inside it are mislabelled mains.
    off_slot = (kinds == REF_MAIN) & (ref_slot != s_main)
    in_slot = ref_slot == s_main
    keep = ~(off_slot | in_slot)
    have = {int(k) for k in n_ref[in_slot & (kinds == REF_MAIN)]}
    n_main = n_all[(slot == s_main)]
    main_t = np.where(np.isin(n_main, n_ref[in_slot]),
                      np.interp(n_main, n_ref, ref_t), a + p * n_main)
    # (a decoded burst in the slot keeps its own refined time; the others take the grid's)
    m_idx, m_ok = match_nearest(t, (main_t[:, None] + main_off[None, :]).ravel(), cfg.tol_s)
    m_ok = m_ok.reshape(main_t.size, main_off.size)
    used = np.zeros(t.size, bool)
    used[m_idx.reshape(m_ok.shape)[m_ok]] = True
    m_done = np.maximum(main_t + main_off[-1], t_decl)
    m_score = m_ok.sum(axis=1)
    inferred = int(sum(1 for k in n_main if int(k) not in have))
    ref_t = np.concatenate([ref_t[keep], main_t])
    kinds = np.concatenate([kinds[keep], np.full(main_t.size, REF_MAIN, np.int8)])
    scores = np.concatenate([scores[keep], m_score])
    done = np.concatenate([done[keep], m_done])
    o = np.argsort(ref_t, kind="stable")
    info.update(n_inferred_main=inferred, n_main_off_slot=int(np.count_nonzero(off_slot)),
                main_slot_s=t_decl)
    return ref_t[o], kinds[o], scores[o], done[o], used, info


#: Code steps (s) by which a burst with a lost end pulse can be mis-aligned.
_CODE_STEPS = {("X", REF_MAIN): 30e-6, ("X", REF_AUX): 12e-6,
               ("Y", REF_MAIN): 30e-6, ("Y", REF_AUX): 15e-6}


def _snap_to_grid(ref_t: np.ndarray, kinds: np.ndarray, cfg: DecoderConfig,
                  period: float = 1.0 / F135, half: int = 8):
    ok = np.ones(ref_t.size, bool)
    if ref_t.size < 3:
        return ref_t, ok
    dev = (ref_t - ref_t[0] + period / 2) % period - period / 2
    out = ref_t.copy()
    for i in range(ref_t.size):
        lo, hi = max(0, i - half), min(ref_t.size, i + half + 1)
        nb = np.delete(dev[lo:hi], i - lo)
        ref = np.median(nb)
        off = dev[i] - ref
        step = _CODE_STEPS[(cfg.mode, int(kinds[i]))]
        k = np.rint(off / step)
        if k != 0 and abs(off - k * step) <= cfg.tol_s and abs(k) <= 3:
            out[i] = ref_t[i] - k * step
        elif abs(off) > cfg.tol_s:
            ok[i] = False
    return out, ok
