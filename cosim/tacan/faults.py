"""TACAN's side of the generic fault study (:mod:`cosim.studies.faults`): its targets, their
word widths, the record of one (BER, trial) run on the bit-exact model (or a cycle-accurate
backend for the register) and its scoring."""
from __future__ import annotations

import traceback
from dataclasses import replace

import numpy as np

from ..core.receivers import FaultModel
from ..studies.faults import flip_signed, flip_bits

__all__ = ["TARGETS", "check", "check_size", "word_width", "record", "FAULT_MODEL"]

#: Where the bits flip.
TARGETS = ("adc", "fifo", "register", "dsp-state")
#: CPU seconds one run costs per second of record.
CPU_S_PER_RECORD_S = 1.5


def check(fc) -> None:
    """TACAN's rules on a fault study (ValueError)."""
    if fc.target != "register" and fc.backend != "model":
        raise ValueError("only the register target runs on a cycle-accurate backend; the "
                         "others use the bit-exact model")
    if fc.fifo_parity and fc.target != "fifo":
        raise ValueError(f"fifo_parity protects the FIFO words: it changes nothing for "
                         f"target {fc.target!r} (use target 'fifo')")


def check_size(fc) -> None:
    """The first trial's record built, its front end validated, its size checked."""
    from .run import check_run_size
    run = _run_cfg(fc, 0)
    run.hdl_params
    check_run_size(replace(run, backend=fc.backend if fc.target == "register" else "model"))


def word_width(fc) -> int:
    """Width (bits) of the words the target's flips hit (``dsp-state``: the widest of
    ``x`` and ``P``)."""
    run = _run_cfg(fc, 0)
    if fc.target == "adc":
        return int(run.signal.adc_bits)
    p = run.hdl_params
    if fc.target == "fifo":
        return int(p.fifo.word_width)
    if fc.target == "register":
        return int(p.nco_phase_bits)
    fx = run.receiver.kalman
    return int(max(fx.x.width, fx.P.width))


def _run_cfg(fc, trial: int):
    from dsp.tacan.kalman_config import KalmanConfig
    from .config import TacanRunConfig
    from .signal import TacanSignalConfig
    rng = np.random.default_rng([fc.seed, trial, 31337])
    sig = TacanSignalConfig(snr_db=fc.snr_db, duration_s=fc.duration_s,
                            seed=int(rng.integers(1 << 31)),
                            bearing_deg=float(np.round(rng.uniform(0, 360), 3)))
    det = {} if fc.detector is None else {"detector": fc.detector}
    return TacanRunConfig(signal=sig, backend="model", dsp="fixed",
                          kalman=KalmanConfig(memory_s=fc.memory_s), require_bearing=False,
                          hdl_changes=(("fifo_parity", True),) if fc.fifo_parity else (),
                          **det)


def _score(fc, run, track, truth_deg) -> dict:
    from dsp.tacan.bearing import wrap_deg
    from .run import shown_bearings
    keep = track.times_s >= run.settle
    b = track.bearing_deg[0, keep]
    t = track.times_s[keep]
    nan = int(np.count_nonzero(~np.isfinite(b)))
    err = wrap_deg(b - truth_deg)
    dist = np.abs(err) > fc.disturbed_deg
    valid = track.valid[0, keep] if track.valid is not None else np.ones(b.size, bool)
    ev_ok = err[valid]
    longest = 0.0
    if dist.any():
        # contiguous disturbed stretches: from the last good bearing before to the first after
        idx = np.flatnonzero(dist)
        starts = idx[np.r_[True, np.diff(idx) > 1]]
        ends = idx[np.r_[np.diff(idx) > 1, True]]
        for s, e in zip(starts, ends):
            t0 = t[s - 1] if s > 0 else run.settle
            t1 = t[e + 1] if e + 1 < t.size else t[e]
            longest = max(longest, float(t1 - t0))
    ev = {k: int(v[0]) for k, v in track.events.items()}
    return {"n_bearings": int(b.size), "nan_bearings": nan,
            "rmse_deg": float(np.sqrt(np.mean(err ** 2))) if b.size else None,
            "max_abs_error_deg": float(np.abs(err).max()) if b.size else None,
            "disturbed_fraction": float(dist.mean()) if b.size else None,
            "longest_disturbance_s": longest, "events": ev,
            "flagged_fraction": float(np.mean(~valid)) if b.size else None,
            "misleading_fraction": float(np.mean(dist & valid)) if b.size else None,
            "valid_rmse_deg": float(np.sqrt(np.mean(ev_ok ** 2))) if ev_ok.size else None,
            "valid_max_abs_error_deg": float(np.abs(ev_ok).max()) if ev_ok.size else None,
            "shown": shown_bearings(track, truth_deg, run.settle, fc.duration_s)}


def record(fc, ber: float, trial: int, cache: dict) -> dict:
    """One run of the study (BER, trial): the point runner; never raises (an exception is
    reported in the record)."""
    from .frontends import FRONTENDS, dsp_receive
    from .run import run_dsp
    from .signal import TacanSignal, generate
    run = _run_cfg(fc, trial)
    rng = np.random.default_rng([fc.seed, trial, int(round(ber * 1e12)), 99])
    key = ("sig", trial)
    if key not in cache:
        cache[key] = generate(run.signal)
    s = cache[key]
    truth = s.truth.bearing_deg
    rec = {"target": fc.target, "ber": ber, "trial": trial, "bearing_deg": truth,
           "flips": 0, "exception": None}
    try:
        p = run.hdl_params
        if fc.target == "adc":
            x, wi, _ = flip_signed(s.samples, run.signal.adc_bits, ber, rng, fc.bits)
            rec["flips"] = int(wi.size)
            fo = FRONTENDS["model"](x, run)
            track = run_dsp(fo, run)
        elif fc.target == "fifo":
            fkey = ("fo", trial)
            if fkey not in cache:
                cache[fkey] = FRONTENDS["model"](s.samples, run)
            fo0 = cache[fkey]
            w, wi, _ = flip_bits(fo0.words, p.fifo.word_width, ber, rng, fc.bits)
            rec["flips"] = int(wi.size)
            fo = dsp_receive(w, fo0.cycles, p, fo0.n_cycles, fo0.fifo_dropped)
            rec["rx"] = fo.extra.get("rx")
            track = run_dsp(fo, run)
        elif fc.target == "register":
            track, rec["flips"] = _register_run(fc, run, s, p, ber, rng)
        else:
            track, rec["flips"] = _dsp_state_run(fc, run, s, ber, rng, cache, trial)
        rec.update(_score(fc, run, track, truth))
    except Exception as e:   # the study's point: report, never crash
        rec["exception"] = f"{type(e).__name__}: {e}"
        rec["traceback"] = traceback.format_exc(limit=5)
    return rec


def _register_run(fc, run, s, p, ber, rng):
    """NCO frequency register upsets, scrubbed by the DSP every ``scrub_period_s``."""
    from .frontends import FRONTENDS
    from .run import run_dsp
    n = len(s.samples)
    period = max(1, int(round(fc.scrub_period_s * run.signal.fs_hz)))
    good = p.nco_freq_word
    writes, flips = [], 0
    for k0 in range(0, n, period):
        _, wi, bi = flip_bits(np.array([good]), p.nco_phase_bits, ber, rng, fc.bits)
        if bi.size == 0:
            continue
        flips += int(bi.size)
        bad = good
        for b in bi:
            bad ^= 1 << int(b)
        c = k0 + int(rng.integers(0, period))
        writes.append((c, "freq", bad))
        if k0 + period < n:
            writes.append((k0 + period, "freq", good))      # the scrub restores it
    r = replace(run, control_writes=tuple(writes), control_latency_cycles=0,
                backend=fc.backend)
    fo = FRONTENDS[fc.backend](s.samples, r)
    return run_dsp(fo, r), flips


def _dsp_state_run(fc, run, s, ber, rng, cache, trial):
    """Single-event upsets of the Kalman core's stored state (``x`` and the upper triangle
    of ``P``): each bit of each word flips with probability ``ber`` per filter update, in
    the compiled core between two updates (:meth:`EnvelopeKalman.schedule_upsets`)."""
    from .frontends import FRONTENDS
    from .run import run_dsp
    from dsp.tacan.kalman import EnvelopeKalman
    from dsp.tacan.receiver import ReceiverState
    fkey = ("fo", trial)
    if fkey not in cache:
        cache[fkey] = FRONTENDS["model"](s.samples, run)
    fo = cache[fkey]
    rc = run.receiver
    fx = rc.kalman
    widths = np.array([fx.x.width if n == "x" else fx.P.width
                       for n, _, _ in EnvelopeKalman.STATE_WORDS])
    word_of_bit = np.repeat(np.arange(widths.size), widths)
    bit_in_word = np.concatenate([np.arange(w) for w in widths])
    if fc.bits is not None:         # chosen bit positions: only those of each word
        keep = np.isin(bit_in_word, np.asarray(fc.bits))
        word_of_bit, bit_in_word = word_of_bit[keep], bit_in_word[keep]
    # an upper bound on the updates (gated ones included; a pair report is two pulses)
    n_steps = int(fo.ticks.size) * (1 if fo.source is None else 2)
    total = n_steps * word_of_bit.size
    n_flips = int(rng.binomial(total, ber)) if ber > 0 and total else 0
    flat = np.sort(rng.integers(0, total, n_flips)) if n_flips else np.zeros(0, np.int64)
    steps = flat // word_of_bit.size
    sel = flat % word_of_bit.size
    kf = EnvelopeKalman(fx, batch=1)
    kf.schedule_upsets(steps, word_of_bit[sel], bit_in_word[sel])
    track = run_dsp(fo, run, state=ReceiverState(kf=kf))
    return track, int(kf.upsets_applied)


#: What :mod:`cosim.studies.faults` needs of TACAN (``Study.model`` of ``faults tacan``).
FAULT_MODEL = FaultModel(targets=TARGETS, check=check, check_size=check_size,
                         word_width=word_width, record=record,
                         cpu_s_per_record_s=CPU_S_PER_RECORD_S)
