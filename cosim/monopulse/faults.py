"""The monopulse side of the generic fault study (:mod:`cosim.studies.faults`, ``python -m
cosim faults monopulse``): bit errors in the ADC samples or the FIFO words of the closed
beam-steering loop on the bit-exact front end (:mod:`cosim.monopulse.hdl_loop`).

``adc``   each bit of each ADC code (two's complement, ``adc_bits``) of the 4 channels flips
          with probability ``ber``, before the front end.
``fifo``  each bit of each FIFO word the DSP reads flips with probability ``ber``; the DSP
          checks every record (its block counter and the steering words it ran on, which
          it knows), treats a bad one as an undetected block and re-synchronises after a
          lost record (:class:`~cosim.monopulse.hdl_loop.FaultHooks`).

Scores (the engine's columns): ``rmse_deg`` the azimuth tracking RMS (deg) over the scored
tracking blocks, ``max_abs_error_deg`` its worst, ``disturbed_fraction`` the share of tracking
blocks whose pointing error passes half the unambiguous offset, ``longest_disturbance_s``,
``nan_bearings`` tracking estimates that are NaN (must be 0); events: ``reinit`` lost-track
events (the search restarted), ``gated`` bad records, plus the tracker's counters; ``rx`` the
record receiver's counters.
"""
from __future__ import annotations

import traceback

import numpy as np

from ..core.receivers import FaultModel
from ..studies.faults import flip_bits, flip_signed

__all__ = ["TARGETS", "check", "check_size", "word_width", "record", "FAULT_MODEL"]

TARGETS = ("adc", "fifo")
#: CPU seconds a run costs per second of record (the model closed loop at ~0.7 M cycles/s).
CPU_S_PER_RECORD_S = 150.0


def check(fc) -> None:
    if fc.backend != "model":
        raise ValueError("the monopulse fault study runs on the bit-exact model (backend "
                         "model)")
    if fc.fifo_parity:
        raise ValueError("the monopulse FIFO words carry no parity bit (fifo_parity False)")
    if fc.detector is not None:
        raise ValueError("detector chooses the TACAN front end's peak searches: the "
                         "monopulse receiver has none")


def _run_cfg(fc, trial: int):
    from .run import MonopulseRunConfig
    seed = int(np.random.default_rng([fc.seed, trial, 4242]).integers(1 << 31))
    return MonopulseRunConfig(snr_db=fc.snr_db, duration_s=fc.duration_s,
                              settle_s=2 * fc.memory_s, seed=seed, backend="model",
                              dsp="fixed")


def check_size(fc) -> None:
    _run_cfg(fc, 0)     # validates the scenario, the front end and the run's size


def word_width(fc) -> int:
    from .hdl_loop import hdl_params
    run = _run_cfg(fc, 0)
    if fc.target == "adc":
        return int(run.adc_bits)
    return int(hdl_params(run, run.signal_config()).fifo.word_width)


def _score(r: dict, fc) -> dict:
    s = r["series"]
    track = s["modes"][:, 0] == 2
    sc = s["scored"][:, 0]
    est, truth = s["est"][:, 0], s["truth"][:, 0]
    from dsp.monopulse.angles import angles
    az_e, _ = angles(est[:, 0], est[:, 1])
    az_t, _ = angles(truth[:, 0], truth[:, 1])
    err = np.rad2deg(np.angle(np.exp(1j * (az_e - az_t))))
    nan = int(np.count_nonzero(track & ~np.isfinite(err)))
    e = err[sc & np.isfinite(err)]
    unamb = np.array(r["pointing_unambiguous"])
    pe = np.max(np.abs(s["steer"][:, 0] - truth) / unamb, axis=-1)
    dist = track & (pe >= 0.5)
    longest, run_len = 0, 0
    for d in dist[sc] if sc.any() else ():
        run_len = run_len + 1 if d else 0
        longest = max(longest, run_len)
    ev = {"reinit": int(r["lost_track_events"]), "gated": int(r.get("bad_records", 0)),
          "missing_records": int(r.get("missing_blocks", 0)),
          **{k: int(v) for k, v in r["dsp_events"].items()}}
    return {"n_bearings": int(e.size), "nan_bearings": nan,
            "rmse_deg": float(np.sqrt(np.mean(e ** 2))) if e.size else None,
            "max_abs_error_deg": float(np.abs(e).max()) if e.size else None,
            "disturbed_fraction": float(dist[sc].mean()) if sc.any() else None,
            "longest_disturbance_s": longest * r["block_s"], "events": ev,
            "rx": r.get("rx", {}), "acquired": bool(r["acquired_trials"] == 1),
            "fifo_dropped": int(r["fifo_dropped"])}


def record(fc, ber: float, trial: int, cache: dict) -> dict:
    """One (BER, trial) run; never raises (an exception is reported in the record)."""
    from .hdl_loop import FaultHooks, hdl_params
    from .run import run_monopulse
    rec = {"target": fc.target, "ber": ber, "trial": trial, "flips": 0, "exception": None}
    try:
        run = _run_cfg(fc, trial)
        p = hdl_params(run, run.signal_config())
        rng = np.random.default_rng([fc.seed, trial, int(round(ber * 1e12)), 99])
        flips = [0]

        def adc(k, codes):      # (4, N D): flipped as one flat word array
            c = np.asarray(codes)
            x, wi, _ = flip_signed(c.ravel(), run.adc_bits, ber, rng, fc.bits)
            flips[0] += int(wi.size)
            return x.reshape(c.shape)

        def fifo(words):
            w, wi, _ = flip_bits(words, p.fifo.word_width, ber, rng, fc.bits)
            flips[0] += int(wi.size)
            return w

        hooks = FaultHooks(adc=adc) if fc.target == "adc" else FaultHooks(fifo=fifo)
        r = run_monopulse(run, keep_series=True, faults=hooks)
        r["pointing_unambiguous"] = run.signal_config().array.unambiguous_offset
        rec["flips"] = flips[0]
        rec.update(_score(r, fc))
        from .study import shown_tracking
        rec["shown"] = shown_tracking(r, run)
    except Exception as e:   # the study's point: report, never crash
        rec["exception"] = f"{type(e).__name__}: {e}"
        rec["traceback"] = traceback.format_exc(limit=5)
    return rec


#: What :mod:`cosim.studies.faults` needs of the monopulse receiver.
FAULT_MODEL = FaultModel(targets=TARGETS, check=check, check_size=check_size,
                         word_width=word_width, record=record,
                         cpu_s_per_record_s=CPU_S_PER_RECORD_S,
                         quantity="azimuth tracking estimate",
                         plot_title="Monopulse azimuth tracking",
                         scores_note=(
                             "Scores over the tracking blocks after settling: RMSE and worst "
                             "error of the azimuth tracking estimate (deg); disturbed = the "
                             "share of tracking blocks whose pointing error passes half the "
                             "unambiguous offset, and the longest such run (s); re-inits = "
                             "lost-track events (the search restarted); gated = FIFO records "
                             "the DSP rejected (block counter or steering words not the ones "
                             "it sent). The tracker raises no integrity flag, so the flagged, "
                             "misleading and unflagged columns are '-'; in what a user sees "
                             "(the second table) an estimate is valid while the loop is in "
                             "track, and misleading when in track with the beam's pointing "
                             "error beyond the unambiguous half-width."))
