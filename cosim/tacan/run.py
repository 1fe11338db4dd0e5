"""End-to-end TACAN scenario: IF signal -> front end (a backend) -> FIFO link -> bearing DSP.

:func:`run_tacan` generates the record (:mod:`cosim.tacan.signal`), runs the front end of
``run.backend`` on it (:mod:`cosim.tacan.frontends`: ``golden``, ``model``, ``pysim``,
``verilator``), then the bearing DSP (:func:`run_dsp`: :func:`dsp.tacan.receiver.process_peaks`
in float or fixed point, the amplitudes converted to its input format), and scores the
bearings against the truth into a JSON-serialisable record (figures, range log, digests of
the peaks, FIFO words and bearings). :func:`check_run_size` refuses, before any work, a run
the machine cannot hold or simulate in time.

``compare="golden"`` also runs the golden chain (golden front end + float DSP) on the same
samples and reports ``vs_golden_rms_deg``: the RMS difference of the bearings produced at the
same references after settling.
"""
from __future__ import annotations

import hashlib
import math
import time
from dataclasses import replace

import numpy as np

from dsp.tacan.receiver import (MISLEADING_DEG, BearingTrack, amplitude_codes, bearing_stats,
                                ReceiverState, process_peaks)
from dsp.tacan.standard import F15
from dsp.tacan.bounds import crb_deg
from dsp.tacan.bearing import wrap_deg
from .config import TacanRunConfig
from .frontends import (FRONTENDS, FrontendOutput, frontend_key, golden_frontend,
                        recheck_cycle_accurate)
from .signal import generate

#: Memory a run holds per ADC sample (bytes; measured ~14 on the model backend: the IF
#: record, the ADC codes and the front end's working arrays), with margin.
BYTES_PER_SAMPLE = {"golden": 32, "model": 32, "pysim": 48, "verilator": 48, "icarus": 48}
#: Simulation speed of the cycle-accurate backends (cycles/s, whole TACAN top; the longest
#: run they are started for is :data:`cosim.core.validate.MAX_RUN_S`).
CYCLES_PER_S = {"pysim": 3e3, "verilator": 5e6, "icarus": 1.5e3}


# ---------------------------------------------------------------------------------------
def run_dsp(fo: FrontendOutput, run: TacanRunConfig,
            state: ReceiverState | None = None) -> BearingTrack:
    """The bearing DSP on a front end's output (float or fixed by ``run.dsp``), from
    ``state`` when given (e.g. a core with scheduled upsets, :mod:`cosim.tacan.faults`); the
    timestamps' clock is the receiver configuration's (the signal's ``fs_hz``)."""
    rc = run.receiver
    times = fo.ticks / rc.kalman.tick_hz
    if rc.dsp == "fixed" and fo.amplitude_lsb is not None:
        amps = amplitude_codes(fo.amplitude_lsb, fo.scale_to_fs, rc.kalman.y)
    else:
        amps = fo.amplitude_fs
    return process_peaks(times, amps, rc, ticks=fo.ticks, source=fo.source, state=state)


def _match_rms(track: BearingTrack, ref: BearingTrack, settle: float, tol_s: float = 50e-6):
    """RMS difference (deg) of the bearings of two tracks at the same references."""
    keep = track.times_s >= settle
    t, b = track.times_s[keep], track.bearing_deg[0, keep]
    if t.size == 0 or ref.times_s.size == 0:
        return math.nan, 0
    j = np.clip(np.searchsorted(ref.times_s, t), 1, ref.times_s.size - 1)
    j = np.where(np.abs(ref.times_s[j - 1] - t) < np.abs(ref.times_s[j] - t), j - 1, j)
    ok = np.abs(ref.times_s[j] - t) <= tol_s
    if not ok.any():
        return math.nan, 0
    d = wrap_deg(b[ok] - ref.bearing_deg[0, j[ok]])
    return float(np.sqrt(np.mean(d ** 2))), int(ok.sum())


def _finite_or_none(v) -> float | None:
    return float(v) if math.isfinite(float(v)) else None


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def check_run_size(run: TacanRunConfig) -> None:
    """Refuse, before any work, a run that cannot fit this machine
    (:func:`cosim.core.validate.check_budget`): the memory its record needs
    (:data:`BYTES_PER_SAMPLE`) and, on a cycle-accurate backend (the run's, the
    ``--recheck``'s), the simulation time (:data:`CYCLES_PER_S`). The message names the
    option."""
    from ..core.validate import check_budget
    sig = run.signal
    n = sig.duration_s * sig.fs_hz
    per = BYTES_PER_SAMPLE[run.backend] + (16 if run.compare else 0)
    check_budget(f"{n:.3g} ADC samples (--duration-s {sig.duration_s:g} x --fs-hz "
                 f"{sig.fs_hz:g})", "--duration-s or --fs-hz", memory_bytes=n * per)
    for be, cycles in ((run.backend, n), (run.recheck, run.recheck_samples or 0)):
        if be in CYCLES_PER_S:
            opt = "--duration-s" if be == run.backend else "--recheck-samples"
            check_budget(f"{cycles:,.0f} cycles on the {be} backend (about "
                         f"{CYCLES_PER_S[be]:.0e} cycles/s)",
                         opt + ("; long records run on --backend model (with --recheck for "
                                "the cycle-accurate proof of its start)"
                                if be == run.backend and be in ("pysim", "icarus") else ""),
                         seconds=cycles / CYCLES_PER_S[be])


#: The display epoch of the studies' availability: one antenna revolution (15 Hz).
EPOCH_S = 1.0 / F15


def shown_bearings(track: BearingTrack, bearing_true_deg: float, settle_s: float,
                   end_s: float) -> dict:
    """What a user sees of trial 0's bearings (:func:`dsp.shown.shown_figures`):
    each bearing when it became available, its error, its valid flag; display epoch one
    revolution (:data:`EPOCH_S`); a bearing shown valid more than
    :data:`dsp.tacan.receiver.MISLEADING_DEG` (20 deg: a sector error) off is misleading."""
    from dsp.shown import shown_figures
    t = track.produced_s if track.produced_s is not None else track.times_s
    b = track.bearing_deg[0] if track.bearing_deg.shape[0] else np.zeros(0)
    err = wrap_deg(b - float(bearing_true_deg))
    valid = np.ones(b.size, bool) if track.valid is None else track.valid[0]
    order = np.argsort(t, kind="stable")
    return shown_figures(np.asarray(t)[order], err[order], valid[order], settle_s=settle_s,
                         end_s=end_s, epoch_s=EPOCH_S, bound=MISLEADING_DEG)


def run_tacan(run: TacanRunConfig, signal=None, frontend_cache: dict | None = None,
              progress: bool = False) -> dict:
    """Run one scenario end to end; returns the result record (JSON-serialisable).

    ``signal`` (a :class:`cosim.tacan.signal.TacanSignal` of ``run.signal``) skips the
    generation (studies digitise one record with several ADCs). ``frontend_cache`` (a dict
    the caller keeps) reuses the front end's output between runs that differ only in the
    DSP (:func:`frontend_key`), e.g. a sweep of DSP word lengths. ``progress`` shows the
    stages of the run on stderr (a tqdm bar; the cycle-accurate backends with their
    estimated time).
    """
    sig = run.signal
    t0 = time.perf_counter()
    if signal is not None and signal.truth.config != sig:
        raise ValueError("signal was generated for another configuration than run.signal")
    check_run_size(run)
    bar = _Stages(run, progress)
    bar.stage("signal")
    s = generate(sig) if signal is None else signal
    t1 = time.perf_counter()
    bar.stage(f"front end ({run.backend})")
    key = frontend_key(run) if frontend_cache is not None and run.trace is None else None
    if key is not None and key in frontend_cache:
        fo = frontend_cache[key]
    else:
        fo = FRONTENDS[run.backend](s.samples, run)
        if key is not None:
            frontend_cache[key] = fo
    t2 = time.perf_counter()
    bar.stage(f"DSP ({run.dsp})")
    track = run_dsp(fo, run)
    t3 = time.perf_counter()
    st = bearing_stats(track, s.truth.bearing_deg, run.settle)
    rel_sigma = sig.matched_filter_rel_sigma()
    crb = crb_deg(rel_sigma, sig.mod_15, sig.mod_135, run.kalman.n_eff)
    if st["n"] == 0 and run.require_bearing:
        raise RuntimeError(
            "no bearing was produced after the filter settled: no reference bursts were "
            f"decoded ({track.n_main_refs} main, {track.n_aux_refs} auxiliary from "
            f"{track.n_peaks} peaks); the signal may be too weak or the mode wrong")
    locked = st["n"] > 0
    rmse = float(st["rmse_deg"][0]) if locked else None
    events = {k: int(v[0]) for k, v in track.events.items()}
    r = {
        "bearing_true_deg": s.truth.bearing_deg,
        "bearing_est_deg": float(st["final_deg"][0]) if locked else
        (float(track.bearing_deg[0, -1]) if track.bearing_deg.shape[1] else None),
        "rmse_deg": rmse,
        "mean_error_deg": float(st["mean_error_deg"][0]) if locked else None,
        "max_abs_error_deg": float(st["max_abs_error_deg"][0]) if locked else None,
        "crb_deg": crb if math.isfinite(crb) else None,
        "rmse_over_crb": (rmse / crb if 0 < crb < math.inf else None) if locked else None,
        "crb_window_s": run.kalman.memory_s,
        "n_updates": int(track.n_updates),
        "n_bearings": int(st["n"]),
        # what a user sees: the bearings shown valid after settling, and the misleading
        # ones among them (bearing_stats)
        "n_valid_bearings": int(st["n_valid"][0]),
        "valid_rmse_deg": _finite_or_none(st["valid_rmse_deg"][0]),
        "misleading_bearings": int(st["misleading"][0]),
        # the three figures every study judges by (accuracy, availability, integrity)
        "shown": shown_bearings(track, s.truth.bearing_deg, run.settle, sig.duration_s),
        "n_peaks": int(track.n_peaks),
        "n_measurements": int(track.n_measurements),
        # what the DSP measured on, and with both searches the paired fraction it chose by
        # (dsp.tacan.pairsource)
        "measured_on": track.measured_on,
        "paired_fraction": track.paired_fraction,
        "n_main_refs": int(track.n_main_refs),
        "n_aux_refs": int(track.n_aux_refs),
        "refs_off_grid": int(track.n_refs_off_grid),
        "first_valid_bearing_s": _finite_or_none(track.first_valid_s()[0]),
        "rotation_hz": track.state.rotation_hz if track.state is not None else None,
        "gated": int(track.gated[0]),
        "reinit": int(track.reinit[0]),
        "adc_clipped": int(s.truth.n_clipped),
        "fifo_dropped": int(fo.fifo_dropped),
        "fifo_dropped_reported": int(fo.dropped_reported),
        "fifo_max_level": fo.extra.get("fifo_max_level"),
        "dsp_events": events,
        "backend": run.backend,
        "dsp": run.dsp,
        "mode": sig.mode,
        "snr_db": sig.snr_db,
        "duration_s": sig.duration_s,
        "seed": sig.seed,
        "settle_s": run.settle,
        "n_cycles": int(fo.n_cycles),
        "ranges": _ranges(fo, track, s.truth.n_clipped),
        "digest": {"peaks": _digest(fo.ticks, fo.amplitude_fs),
                   "fifo": _digest(fo.words) if fo.words is not None else None,
                   "bearings": _digest(track.times_s, track.bearing_deg)},
        "elapsed_s": {"signal": t1 - t0, "frontend": t2 - t1, "dsp": t3 - t2},
    }
    if run.recheck is not None:
        bar.stage(f"re-check ({run.recheck})")
        r["recheck"] = recheck_cycle_accurate(run, s.samples, run.recheck,
                                              run.recheck_samples)
    if run.compare == "golden":
        bar.stage("golden chain")
        t4 = time.perf_counter()
        gfo = golden_frontend(s.samples, run)
        gold = run_dsp(gfo, replace(run, backend="golden", dsp="float", compare=None,
                                    recheck=None))
        rms, n = _match_rms(track, gold, run.settle)
        r["vs_golden_rms_deg"] = rms
        r["vs_golden_n"] = n
        gst = bearing_stats(gold, s.truth.bearing_deg, run.settle)
        r["golden_rmse_deg"] = float(gst["rmse_deg"][0]) if gst["n"] else None
        r["elapsed_s"]["golden"] = time.perf_counter() - t4
    bar.close()
    return r


class _Stages:
    """Progress of one run on stderr: a bar over its stages, and for a cycle-accurate
    backend the estimated simulation time (:data:`CYCLES_PER_S`)."""

    def __init__(self, run: TacanRunConfig, enabled: bool):
        self.bar = None
        import sys
        if not enabled or not sys.stderr.isatty():     # a bar on a terminal, not in logs
            return
        import sys
        from tqdm import tqdm
        n = 3 + (run.recheck is not None) + (run.compare is not None)
        self.bar = tqdm(total=n, desc="tacan", file=sys.stderr, leave=False,
                        bar_format="{desc}: {n_fmt}/{total_fmt} stages [{elapsed}] {postfix}")
        if run.backend in CYCLES_PER_S:
            c = run.signal.duration_s * run.signal.fs_hz
            print(f"{run.backend}: {c:,.0f} cycles, about {c / CYCLES_PER_S[run.backend]:.0f} s",
                  file=sys.stderr)
        self.started = False

    def stage(self, name: str) -> None:
        if self.bar is not None:
            if self.started:
                self.bar.update()
            self.started = True
            self.bar.set_postfix_str(name)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.update()
            self.bar.close()


def _ranges(fo: FrontendOutput, track: BearingTrack, adc_clipped: int) -> dict:
    """Range log of the run (Fixed-Point Designer style): per signal the smallest and largest
    value seen against its word's range, and its overflow/saturation count. Front-end
    signals (``fe.*``, as fractions of the word's full scale, LSBs in ``min_lsb``/``max_lsb``)
    with the bit-exact model backend; the fixed-point DSP's formats (``dsp.*``, real units,
    pre-saturation values)."""
    out = {}
    for name, v in (fo.extra.get("ranges") or {}).items():
        top = v["hi"] + 1          # full scale of the word: 2**(b-1) signed, 2**b unsigned
        out[f"fe.{name}"] = {"min": v["min"] / top, "max": v["max"] / top,
                             "lo": v["lo"] / top, "hi": v["hi"] / top,
                             "min_lsb": v["min"], "max_lsb": v["max"], "bits": v["bits"],
                             "headroom_bits": v["headroom_bits"], "unit": "FS",
                             "overflows": int(adc_clipped) if name == "adc" else 0}
    if track.state is not None:
        for name, v in track.state.kf.ranges().items():
            peak = max(abs(v["min"] or 0.0), abs(v["max"] or 0.0))
            out[f"dsp.{name}"] = {"min": v["min"], "max": v["max"], "lo": v["lo"], "hi": v["hi"],
                                  "headroom_bits": math.log2(v["hi"] / peak) if peak else None,
                                  "unit": "value", "overflows": v["saturations"]}
    return out


def frontend_output(run: TacanRunConfig) -> tuple[FrontendOutput, BearingTrack]:
    """The front end's output and the DSP's track for ``run`` (for tests and studies)."""
    s = generate(run.signal)
    fo = FRONTENDS[run.backend](s.samples, run)
    return fo, run_dsp(fo, run)
