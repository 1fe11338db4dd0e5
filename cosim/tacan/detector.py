"""The pulse detector's operating point on a scenario, and the bounds it sets on the bearing.

:func:`operating_point` runs the golden front end on a record and scores its detections
against the generator's truth: the threshold over the matched-filter amplitude noise, the
noise peaks per transmitted pulse, and the fraction of pulses detected (set against the
Rician model's, :func:`dsp.tacan.bounds.detected_fraction`, as a check of the model the
bounds use). :func:`detector_bounds` turns that into the bounds of
:mod:`dsp.tacan.bounds` -- what a DSP fed by this detector can reach at best.
"""
from __future__ import annotations

import numpy as np

from dsp.tacan.bounds import crb_deg, detected_fraction, detection_bound_deg
from dsp.tacan.decode import _match
from dsp.tacan.frontend import GoldenFrontend, record_chunks

from .run import TacanRunConfig
from .signal import generate

#: A detection within this of a transmitted pulse's peak is that pulse (the peak time of a
#: pulse jitters by ~1 us near 0 dB; pulses of a pair are 12 us apart, random pairs >= 50 us).
MATCH_S = 3e-6


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
    cfg = run.frontend
    s = generate(sig)
    fe = GoldenFrontend(cfg, sig.adc_bits)
    idx, thr = [], []
    for c0, chunk in record_chunks(s.samples, cfg):
        res = fe.search(chunk)
        n = np.asarray(res.index, np.int64)
        idx.append(n)
        thr.append(np.asarray(res.thresholds)[n - c0 // cfg.decimation])
    n = np.concatenate(idx)
    thr = np.concatenate(thr)
    t = (n * cfg.decimation - cfg.group_delay_samples) / sig.fs_hz
    tp = s.truth.pulse_times_s
    duration = (s.samples.size - s.samples.size % cfg.decimation) / sig.fs_hz
    near = _match(tp, t, MATCH_S)[1] if tp.size else np.zeros(t.size, bool)
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
