"""End-to-end GNSS run: IF signal -> acquisition -> tracking channel (a backend) -> FIFO ->
tracker -> NCO words back over the control path, closed loop (:func:`run_gnss`).

The acquisition reads the record from its start; tracking starts where it stopped
(:func:`cosim.gnss.handover.acquired_record`), and ``duration_s`` and the scoring's times
are the tracking's, from that sample on.

Acquisition, hand-over and the tracking loop are :mod:`cosim.gnss.tracking`; the run's
configuration is :mod:`cosim.gnss.config`. Backends: ``model`` (bit-exact channel + FIFO),
``pysim`` (Amaranth), ``verilator`` give the same bits (the test checks it); ``golden`` is
the float64 correlator chain (:func:`cosim.gnss.tracking.golden_track`). Every backend
streams the record (:func:`track_record`): the samples are generated and consumed a block at
a time, so a run holds one block and its per-record outputs whatever its duration
(:func:`cosim.gnss.config.run_memory_bytes` estimates that, :func:`check_run_size` refuses
what would not fit).

Scoring (per record, against the generator's truth at the record's dump boundary, after
``settle_s``): carrier phase error = signal minus NCO phase (cycles), unwrapped over the
records; ``cycle_slips`` = changes of its nearest Costas lock point (half cycles,
:func:`cosim.gnss.loopsim.cycle_slips`); ``phase_rmse_deg`` = rms of the error about its lock
point; ``doppler_rmse_hz`` = the tracker's Doppler minus the true one; ``code_rmse_chips`` =
true code phase minus the prompt's, ``code_bias_chips`` its mean; ``lock_fraction`` = share of 100-record windows in
phase lock (narrowband PLI >= 0.8, :class:`dsp.gnss.loops.LockDetector`; the windows start
on a data-bit edge, so its 10-record sums do not straddle one); ``cn0_est_dbhz``
(M2M4 on the prompts).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace

import numpy as np

from dsp.gnss.ca_code import CODE_LENGTH, CODE_PERIOD_S

from .config import GnssRunConfig, check_run_size
from .handover import acquired_record
from .signal import GnssSignalConfig
from .tracking import SKIP_RECORDS, Tracking, adc_words, closed_loop, golden_track, record_boundaries

__all__ = ["run_gnss", "track_record", "TrackedRecord", "tracker_report"]


# -- scoring ---------------------------------------------------------------------------------
def _score(gen, track: Tracking, n_b, settle_s):
    from dsp.gnss.cn0 import cn0_m2m4
    from dsp.gnss.loops import LockDetector
    from .loopsim import cycle_slips
    sig = gen.cfg
    obs = np.array([o[1:] for o in track.obs], np.float64).reshape(-1, 4)
    k = min(len(n_b), len(obs))
    n_b, obs = np.asarray(n_b[:k], np.int64), obs[:k]
    dop = np.array(track.doppler[:k])
    t = n_b / sig.fs_hz
    tr = gen.truth_at(t)
    s = -1.0 if sig.spectrum_inverted else 1.0
    f_ratio = sig.digital_if_hz / sig.fs_hz
    if_ph = np.mod(n_b.astype(np.float64) * f_ratio, 1.0)
    e = if_ph + s * tr["carrier_phase_cycles"] - obs[:, 0]
    e = np.unwrap(2 * np.pi * e) / (2 * np.pi)
    code = np.mod(tr["code_phase_chips"] - obs[:, 1] + CODE_LENGTH / 2, CODE_LENGTH) \
        - CODE_LENGTH / 2
    keep = t >= settle_s
    out = {"n_records": int(k), "n_scored": int(keep.sum())}
    if not keep.any():
        raise ValueError(f"no record after settle_s = {settle_s:g} s: lengthen duration_s "
                         f"({sig.duration_s:g} s) or shorten settle_s")
    es = e[keep]
    resid = es - 0.5 * np.rint(es / 0.5)
    out["phase_rmse_deg"] = float(np.sqrt(np.mean(resid ** 2)) * 360.0)
    out["cycle_slips"] = int(cycle_slips(es, costas=True))
    out["doppler_rmse_hz"] = float(np.sqrt(np.mean((dop[keep] - tr["doppler_hz"][keep]) ** 2)))
    out["code_rmse_chips"] = float(np.sqrt(np.mean(code[keep] ** 2)))
    out["code_bias_chips"] = float(np.mean(code[keep]))
    prompt = obs[keep, 2] + 1j * obs[keep, 3]
    ld = LockDetector(CODE_PERIOD_S, window=100, m=10)
    locks = []
    # the windows start on a data-bit edge (the record integrating the bit's first code
    # period), so the detector's 10-record sums do not straddle one, wherever tracking began
    epoch = np.rint(tr["code_chips_total"][keep] / CODE_LENGTH).astype(np.int64)
    first = np.nonzero(epoch % 20 == 1)[0]
    for pv in prompt[int(first[0]) if first.size else 0:]:
        if ld.update(pv):
            locks.append(bool(ld.phase_lock))
    out["lock_fraction"] = float(np.mean(locks)) if locks else None
    out["cn0_est_dbhz"] = float(cn0_m2m4(prompt, CODE_PERIOD_S))
    out["_series"] = (t, e, dop, code)
    return out


def tracker_report(tracker) -> dict:
    """The tracker's own figures for the JSON: ``q_hat`` (final value, per-block trajectory
    of one stream, the slave's block length) and ``diverged`` (its own loss-of-lock rule) of
    the AUKF patent's trackers (aukf, ukf), None for trackers without them, plus the rest of ``report()``
    under ``tracker_report``."""
    rep = tracker.report() if hasattr(tracker, "report") else {}
    out = {"q_hat": None, "diverged": None}
    if "q_hat" in rep:
        q = rep["q_hat"]
        prm = rep.get("params", {})
        out["q_hat"] = {"final": q["median_final"], "q0": prm.get("q0"),
                        "block_s": prm.get("block_s"), "trajectory": q["trajectory_median"],
                        "min": min(q["trajectory_median"]), "max": max(q["trajectory_median"]),
                        "adaptive": prm.get("adaptive")}
    if "diverged" in rep:
        d = rep["diverged"]
        out["diverged"] = bool(np.any(d))
    if rep:
        out["tracker_report"] = {k: v for k, v in rep.items() if k not in ("q_hat", "diverged")}
    return out


@dataclass
class TrackedRecord:
    """The tracking of a whole record on one backend (:func:`track_record`): the DSP's
    per-record observables (``track``), the dump-boundary sample of every tracked record,
    the FIFO counters, the digests and (HDL backends) the pipeline's result."""

    track: Tracking
    boundaries: np.ndarray
    counters: dict
    digest: dict
    pipeline: object = None


def track_record(gen, run: GnssRunConfig, hand: dict, tracker_extra=None, *,
                 keep_words: bool = False) -> TrackedRecord:
    """Track the record of ``gen`` on ``run.backend`` from the hand-over ``hand``, streamed:
    the golden chain reads it through a :class:`~cosim.gnss.signal.SampleStream`, the HDL
    backends are fed it ``run.block_samples`` at a time and their dump boundaries are
    replayed in blocks (:func:`~cosim.gnss.tracking.record_boundaries`), so what is held
    is one block and the per-record outputs, whatever the duration."""
    sig = gen.cfg
    if run.backend == "golden":
        track, n_b = golden_track(gen, run, hand, run.dsp, tracker_extra)
        return TrackedRecord(track, n_b, {"fifo_dropped": 0, "dropped_reported": 0},
                             {"dsp": track.digest()})
    p = run.hdl_params(sig)
    n = sig.n_samples
    blocks = (adc_words(gen.samples(k, min(run.block_samples, n - k))[0])
              for k in range(0, n, run.block_samples))
    cl = closed_loop(run.backend, p, run, blocks, hand["doppler_hz"], hand["code_phase_chips"],
                     inverted=sig.spectrum_inverted, cn0_dbhz=sig.cn0_dbhz,
                     keep_words=keep_words, tracker_extra=tracker_extra)
    track, pres, rx = cl.track, cl.pipeline, cl.rx_stats
    n_b = record_boundaries(p, cl.bus_writes, track.n_seen, n)[SKIP_RECORDS:]
    counters = {"fifo_dropped": int(pres.overflow_count),
                "dropped_reported": int(rx["dropped_reported"]),
                "broken_records": int(rx["broken_records"])}
    digest = dict(pres.digest)
    digest["dsp"] = track.digest()
    return TrackedRecord(track, n_b, counters, digest, pres)


def run_gnss(signal_cfg: GnssSignalConfig, run_cfg: GnssRunConfig, *,
             keep_words: bool = False, tracker_setup=None, keep_track: bool = False) -> dict:
    """One GNSS run end to end (module doc); returns the JSON-safe result. With
    ``keep_words`` the result's ``_pipeline`` holds the :class:`PipelineResult` (tests).
    ``_series`` holds the per-record ``(t_s, phase_err_cycles, doppler_hz, code_err_chips)``
    (unscored records included; times from tracking's start).
    ``tracker_setup(gen, p, hand, backend) -> (ctx_changes, options)``, called after the
    acquisition, adds to the tracker's :class:`~dsp.gnss.trackers.TrackerContext` (e.g. an
    INS ``aiding``) and options (the INS-aided loops, :mod:`cosim.ins.run`); with
    ``keep_track`` the result's ``_track`` holds the DSP's per-record observables and
    the records' dump-boundary samples."""
    if not isinstance(signal_cfg, GnssSignalConfig):
        raise ValueError(f"signal_cfg must be a GnssSignalConfig, not "
                         f"{type(signal_cfg).__name__}")
    if not isinstance(run_cfg, GnssRunConfig):
        raise ValueError(f"run_cfg must be a GnssRunConfig, not {type(run_cfg).__name__}")
    sig, run = signal_cfg, run_cfg
    p = run.hdl_params(sig)
    run.service(sig.fs_hz)      # DspServiceConfig's own checks (window inside the period)
    run.check_loop_timing(sig.fs_hz)
    check_run_size(sig, run)
    from dsp.gnss.trackers import needs_aiding
    if needs_aiding(run.tracker) and tracker_setup is None:
        raise ValueError(f"tracker {run.tracker} needs an INS aiding source: run it with "
                         f"`python -m cosim ins --loop {run.tracker}` (the INS paper's trajectory "
                         "and INS error model)")
    if sig.duration_s <= run.settle_s:
        raise ValueError(f"duration_s {sig.duration_s:g} s leaves nothing after settle_s "
                         f"{run.settle_s:g} s")
    acq, hand, gen = acquired_record(sig, run)      # gen: the record from tracking's start
    extra = None if tracker_setup is None else tracker_setup(gen, p, hand, run.backend)
    result = {"prn": sig.prn, "cn0_dbhz": sig.cn0_dbhz, "duration_s": sig.duration_s,
              "tracker": run.tracker, "bn_hz": run.tracker_setting("bn_hz"), "backend": run.backend,
              "dsp": run.dsp, "acquired": acq}
    tr = track_record(gen, run, hand, extra, keep_words=keep_words)
    track, n_b, pres = tr.track, tr.boundaries, tr.pipeline
    result.update(tr.counters)
    digest = dict(tr.digest)
    if pres is not None:
        result["writes"] = len(pres.writes)
    score = _score(gen, track, n_b, run.settle_s)
    series = score.pop("_series")
    result.update(score)
    result.update(tracker_report(track.tracker))
    h = hashlib.sha256("".join(f"{k}={v};" for k, v in sorted(digest.items())).encode())
    digest["all"] = h.hexdigest()[:16]
    result["digest"] = digest
    if run.compare == "golden":
        g = run_gnss(sig, replace(run, backend="golden", dsp="float", compare=None))
        gt, ge, gd, _ = g.pop("_series")
        t, e, d, _ = series
        keep = t >= run.settle_s
        result["golden"] = {k: g[k] for k in ("doppler_rmse_hz", "phase_rmse_deg",
                                              "code_rmse_chips", "cycle_slips",
                                              "lock_fraction", "cn0_est_dbhz")}
        result["vs_golden_doppler_rms_hz"] = float(np.sqrt(np.mean(
            (d[keep] - np.interp(t[keep], gt, gd)) ** 2)))
        result["vs_golden_phase_rms_deg"] = float(360 * np.sqrt(np.mean(
            (e[keep] - 0.5 * np.rint(e[keep] / 0.5)
             - np.interp(t[keep], gt, ge - 0.5 * np.rint(ge / 0.5))) ** 2)))
    result["_series"] = series
    if keep_track:
        result["_track"] = (track, n_b)
    if keep_words:
        result["_pipeline"] = pres
    return result
