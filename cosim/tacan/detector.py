"""The pulse detector's operating point on a scenario, and the bounds it sets on the bearing.

:func:`operating_point` runs the golden front end on a record and scores its detections
against the generator's truth: the threshold over the matched-filter amplitude noise, the
noise peaks per transmitted pulse, and the fraction of pulses detected (set against the
Rician model's, :func:`dsp.tacan.bounds.detected_fraction`, as a check of the model the
bounds use). :func:`detector_bounds` turns that into the bounds of
:mod:`dsp.tacan.bounds` -- what a DSP fed by this detector can reach at best.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from dsp.tacan.bounds import crb_deg, detected_fraction, detection_bound_deg
from dsp.tacan.scoring import match_nearest
from dsp.tacan.frontend import GoldenFrontend, record_chunks

from .config import TacanRunConfig
from .signal import generate

#: A detection within this of a transmitted pulse's peak is that pulse (the peak time of a
#: pulse jitters by ~1 us near 0 dB; pulses of a pair are 12 us apart, random pairs >= 50 us).
MATCH_S = 3e-6


def _measured_search(run: TacanRunConfig):
    """``run``'s front end with the one search whose reports the DSP measures: the pair
    search with both searches (``--detector both``), else the only one."""
    cfg = run.frontend
    return cfg if cfg.pair_peak is None else replace(cfg, peak=cfg.pair_peak, pair_peak=None)


def _detections(run: TacanRunConfig, confirmed: bool = False):
    """The golden front end on ``run``'s scenario (its measured search,
    :func:`_measured_search`): ``(signal, amplitude, threshold, t, (j, near))`` per detection
    -- its reported amplitude, the threshold at it, its time (s, group delay removed) and the
    nearest transmitted pulse (index, within :data:`MATCH_S`). With ``confirmed`` (both
    searches only) the pair reports the DSP confirms (:func:`dsp.tacan.pairsource.
    confirmed_pairs`: the single-pulse search reported both their pulses) and no others."""
    from dsp.tacan.peak import peak_search_float
    full = run.frontend
    if confirmed and full.pair_peak is None:
        raise ValueError("confirmed pair reports need both searches (detector 'both')")
    cfg = _measured_search(run)
    s = generate(run.signal)
    fe = GoldenFrontend(full if confirmed else cfg, run.signal.adc_bits)
    idx, amp, thr, pulses = [], [], [], []
    st = None
    for c0, chunk in record_chunks(s.samples, cfg):
        if confirmed:    # both searches on the one envelope, as the FPGA runs them
            env = fe.envelope(chunk)
            pulses.append(np.asarray(fe.search(chunk, env).index, np.int64))
            res, st = peak_search_float(env, full.pair_peak, st, thr_min=full.thr_min_fs)
        else:
            res = fe.search(chunk)
        n = np.asarray(res.index, np.int64)
        idx.append(n)
        amp.append(np.asarray(res.amplitude, np.float64))
        thr.append(np.asarray(res.thresholds)[n - c0 // cfg.decimation])
    n, a, T = np.concatenate(idx), np.concatenate(amp), np.concatenate(thr)
    t = (n * cfg.decimation - cfg.group_delay_samples) / run.signal.fs_hz
    if confirmed:
        from dsp.tacan.pairsource import confirmed_pairs
        tpu = (np.concatenate(pulses) * cfg.decimation - cfg.group_delay_samples) / run.signal.fs_hz
        dec = run.receiver.decoder
        keep = confirmed_pairs(t, tpu, run.signal.mode, dec.tol_s if dec else 1e-6)
        n, a, T, t = n[keep], a[keep], T[keep], t[keep]
    tp = s.truth.pulse_times_s
    match = match_nearest(tp, t, MATCH_S) if tp.size else (np.zeros(t.size, int), np.zeros(t.size, bool))
    return s, a, T, t, match


def operating_point(run: TacanRunConfig) -> dict:
    """The detector's operating point on ``run``'s scenario (golden chain, direct path).

    Returns ``threshold_sigma`` (median threshold at the detections over ``rel_sigma * a0``),
    ``false_peaks_per_s`` and ``false_peaks_per_pulse`` (detections further than
    :data:`MATCH_S` from every pulse, per second of the time that far from them),
    ``detected_fraction`` (pulses with a detection within :data:`MATCH_S`, less the noise
    peaks expected there) and the model's ``model_detected_fraction``.
    """
    sig = run.signal
    if sig.snr_db is None:
        raise ValueError("the operating point needs a noisy scenario (snr_db is None)")
    s, _, thr, t, (_, near) = _detections(run)
    tp = s.truth.pulse_times_s
    dec = run.frontend.decimation
    duration = (s.samples.size - s.samples.size % dec) / sig.fs_hz
    # time within MATCH_S of a pulse: the union of the windows
    lo, hi = np.clip(tp - MATCH_S, 0, duration), np.clip(tp + MATCH_S, 0, duration)
    t_near = float(np.sum(np.minimum(hi, np.append(lo[1:], np.inf)) - lo)) if tp.size else 0.0
    fa_rate = np.count_nonzero(~near) / max(duration - t_near, 1e-12)
    pulse_rate = tp.size / duration
    rel = sig.matched_filter_rel_sigma()
    th_sigma = float(np.median(thr)) / (rel * s.truth.amplitude) if thr.size else float("inf")
    pd = (np.count_nonzero(near) - fa_rate * t_near) / max(tp.size, 1)
    return {"snr_db": sig.snr_db, "noise_floor": run.noise_floor, "rel_sigma": rel,
            "threshold_sigma": th_sigma, "false_peaks_per_s": float(fa_rate),
            "false_peaks_per_pulse": float(fa_rate / pulse_rate),
            "detected_fraction": float(pd),
            "model_detected_fraction": detected_fraction(rel, sig.mod_15, sig.mod_135, th_sigma),
            "duration_s": duration}


def detector_bounds(op: dict, mod_15: float, mod_135: float, n_pulses: float) -> dict:
    """The Cramer-Rao bound and the detector's bounds (deg) at an operating point."""
    args = (op["rel_sigma"], mod_15, mod_135, n_pulses, op["threshold_sigma"],
            op["false_peaks_per_pulse"])
    return {"crb_deg": crb_deg(op["rel_sigma"], mod_15, mod_135, n_pulses),
            **{f"bound_{u}_deg": detection_bound_deg(*args, use=u) for u in ("both", "rate", "marks")}}


def peak_bias_samples(run: TacanRunConfig, confirmed: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Each detection of a transmitted pulse on ``run``'s scenario (golden chain): the
    pulse's amplitude and its report's bias, both in units of the threshold the report
    passed (:mod:`dsp.tacan.peakbias`; a pair report is half the pair sum, so half the
    sum's threshold). Noise peaks and the floor's first settling (infinite threshold) are
    left out; with ``confirmed``, the pair reports the DSP does not confirm too."""
    s, a, T, _, (j, near) = _detections(run, confirmed)
    T = T * (0.5 if _measured_search(run).peak.pair_offset else 1.0)
    ap = s.truth.pulse_amplitudes
    ok = near & np.isfinite(T) & (T > 0)
    A = ap[j[ok]]
    return A / T[ok], (a[ok] - A) / T[ok]


def calibrate_peak_bias(runs, *, bin_width: float = 0.1, u_fit: float = 1.5,
                        u_max: float = 5.0, min_count: int = 30,
                      confirmed: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The bias curve of :class:`dsp.tacan.peakbias.PeakBias` from the detections of
    ``runs`` (:func:`peak_bias_samples` pooled): the mean bias in ``bin_width`` bins of
    ``u`` below ``u_fit`` (bins of at least ``min_count`` detections), above it a fit ``c0 +
    c1 / u`` (the bias left there is small and its bins noisy) on knots 0.25 apart up to
    ``u_max``; with ``confirmed``, of the confirmed pair reports only. Returns ``(u, beta)``."""
    us, es = zip(*(peak_bias_samples(r, confirmed) for r in runs))
    return fit_peak_bias(np.concatenate(us), np.concatenate(es), bin_width=bin_width,
                         u_fit=u_fit, u_max=u_max, min_count=min_count)


def fit_peak_bias(u, e, *, bin_width: float = 0.1, u_fit: float = 1.5, u_max: float = 5.0,
                  min_count: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """:func:`calibrate_peak_bias`'s curve from pooled samples ``(u, e)`` of
    :func:`peak_bias_samples`."""
    edges = np.arange(0.0, u_fit + 1e-9, bin_width)
    k = np.digitize(u, edges) - 1
    lo_u, lo_b = [], []
    for q in range(edges.size - 1):
        m = k == q
        if np.count_nonzero(m) >= min_count:
            lo_u.append(edges[q] + bin_width / 2)
            lo_b.append(float(e[m].mean()))
    hi = (u >= u_fit) & (u < u_max)
    if np.count_nonzero(hi) < min_count or len(lo_u) < 2:
        raise ValueError("too few detections to calibrate the peak bias: add records")
    c, *_ = np.linalg.lstsq(np.column_stack([np.ones(hi.sum()), 1.0 / u[hi]]), e[hi], rcond=None)
    ku = np.arange(u_fit, u_max + 1e-9, 0.25)
    return np.r_[lo_u, ku], np.r_[lo_b, c[0] + c[1] / ku]


def bias_runs(detector: str = "pair", noise_floor: str = "clipped", seeds=range(3),
              snrs=(-3, -1, 1, 3, 5, 8, 12), duration_s: float = 2.0):
    """The records a :class:`dsp.tacan.peakbias.PeakBias` is calibrated on (``PAIR_PEAK_BIAS``:
    the defaults; ``BOTH_PEAK_BIAS``: ``detector="both"``): each SNR, seed ``9000 + 10 k + snr + 5`` for ``k`` in ``seeds``, a random
    bearing drawn from that seed."""
    from .signal import TacanSignalConfig
    out = []
    for snr in snrs:
        for k in seeds:
            seed = 9000 + 10 * k + int(snr + 5)
            b = float(np.random.default_rng(seed).uniform(0, 360))
            out.append(TacanRunConfig(signal=TacanSignalConfig(
                bearing_deg=b, snr_db=float(snr), duration_s=duration_s, seed=seed),
                detector=detector, noise_floor=noise_floor))
    return out


def pair_report_kinds(run: TacanRunConfig) -> dict:
    """What the pair search reports on ``run``'s scenario with both searches (golden chain,
    direct path), against the generator's truth: each pair report is a *pair* (a transmitted
    pulse within :data:`MATCH_S` of both its pulses, ``t - D`` and ``t``), a *half pair* (of
    one) or a *noise pair* (of neither). Per kind: the count, the median report over the
    threshold estimate the DSP makes (:meth:`dsp.tacan.peakbias.PeakBias.threshold`), the
    median report over the pulse's amplitude (pairs, half pairs), and the share the DSP's
    confirmation keeps (both pulses among the single-pulse reports,
    :func:`dsp.tacan.pairsource.confirmed_pairs`); and the paired fraction. The evidence
    of :mod:`dsp.tacan.pairsource`."""
    from dsp.tacan.frontend import run_golden_frontend
    from dsp.tacan.pairsource import confirmed_pairs, paired_fraction
    from dsp.tacan.standard import SOURCE_PAIR, pair_spacing_s
    if run.detector != "both":
        raise ValueError(f"pair report kinds need both searches (detector 'both'), not "
                         f"{run.detector!r}")
    sig = run.signal
    s = generate(sig)
    cfg = run.frontend
    pk = run_golden_frontend(s.samples, cfg, sig.adc_bits)
    t = (pk.timestamps - cfg.group_delay_samples) / sig.fs_hz
    pr = pk.source == SOURCE_PAIR
    tp = s.truth.pulse_times_s
    D = pair_spacing_s(sig.mode)
    j2, n2 = match_nearest(tp, t[pr], MATCH_S)
    j1, n1 = match_nearest(tp, t[pr] - D, MATCH_S)
    a = pk.amplitudes[pr]
    conf = confirmed_pairs(t[pr], t[~pr], sig.mode, run.receiver.decoder.tol_s
                           if run.receiver.decoder else 1e-6)
    thr = run.receiver.peak_bias.threshold(a)
    ap = s.truth.pulse_amplitudes
    amp_of = np.where(n2, ap[j2], ap[j1])
    out = {"reports": int(a.size), "threshold": thr, "paired_fraction": paired_fraction(conf)}
    for name, m in (("pair", n1 & n2), ("half_pair", n1 ^ n2), ("noise_pair", ~n1 & ~n2)):
        out[name] = {"count": int(m.sum()), "share": float(m.mean()) if m.size else None,
                     "report_over_threshold": float(np.median(a[m] / thr)) if m.any() else None,
                     "report_over_pulse": float(np.median(a[m] / amp_of[m]))
                     if m.any() and name != "noise_pair" else None,
                     "confirmed": float(conf[m].mean()) if m.any() else None}
    return out
