"""End-to-end TACAN scenario: IF signal -> front end (a backend) -> bearing DSP -> scores.

Backends produce pulse peaks from the ADC samples:

``golden``  float64 model of the front end (:mod:`dsp.tacan.frontend`).

Later backends (bit-exact model, Amaranth simulation, Verilator) plug in through
:data:`BACKENDS` with the same contract: ``fn(samples, signal_cfg, frontend_cfg) -> Peaks``.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from dsp.tacan.frontend import FrontendConfig, Peaks, run_golden_frontend
from dsp.tacan.kalman import KalmanConfig
from dsp.tacan.receiver import ReceiverConfig, bearing_stats, crb_deg, process_peaks
from .tacan_signal import TacanSignalConfig, generate


def _golden(samples, sig: TacanSignalConfig, fe: FrontendConfig) -> Peaks:
    return run_golden_frontend(samples, fe, sig.adc_bits)


BACKENDS = {"golden": _golden}


@dataclass(frozen=True)
class TacanRunConfig:
    """A whole run: the scenario, the front end, the DSP and how it is scored."""

    signal: TacanSignalConfig = field(default_factory=TacanSignalConfig)
    backend: str = "golden"
    kalman: KalmanConfig = field(default_factory=KalmanConfig)
    settle_s: float | None = None   # default: 2 x the filter memory
    frontend_changes: tuple = ()     # (name, value) overrides of FrontendConfig

    def __post_init__(self):
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {sorted(BACKENDS)}, not {self.backend!r}")
        if self.settle_s is not None and not (math.isfinite(self.settle_s) and self.settle_s >= 0):
            raise ValueError(f"settle_s must be >= 0, not {self.settle_s}")
        if self.settle + 0.1 > self.signal.duration_s:
            raise ValueError(
                f"duration_s={self.signal.duration_s:g} leaves no time after the filter settles "
                f"({self.settle:g} s); use a duration of at least {self.settle + 0.5:g} s "
                f"or a shorter settle time")

    @property
    def settle(self) -> float:
        return 2.0 * self.kalman.memory_s if self.settle_s is None else float(self.settle_s)

    @property
    def frontend(self) -> FrontendConfig:
        return FrontendConfig.for_signal(self.signal, **dict(self.frontend_changes))


def run_tacan(run: TacanRunConfig) -> dict:
    """Run one scenario end to end; returns the result record (JSON-serialisable)."""
    sig = run.signal
    t0 = time.perf_counter()
    s = generate(sig)
    t1 = time.perf_counter()
    fe = run.frontend
    peaks = BACKENDS[run.backend](s.samples, sig, fe)
    t2 = time.perf_counter()
    track = process_peaks(peaks.times_s, peaks.amplitudes,
                          ReceiverConfig(mode=sig.mode, kalman=run.kalman))
    t3 = time.perf_counter()
    st = bearing_stats(track, s.truth.bearing_deg, run.settle)
    rel_sigma = sig.matched_filter_rel_sigma()
    crb = crb_deg(rel_sigma, sig.mod_15, sig.mod_135, run.kalman.n_eff)
    if st["n"] == 0:
        raise RuntimeError(
            "no bearing was produced after the filter settled: no reference bursts were "
            f"decoded ({track.n_main_refs} main, {track.n_aux_refs} auxiliary from "
            f"{track.n_peaks} peaks); the signal may be too weak or the mode wrong")
    rmse = float(st["rmse_deg"][0])
    return {
        "bearing_true_deg": s.truth.bearing_deg,
        "bearing_est_deg": float(st["final_deg"][0]),
        "rmse_deg": rmse,
        "mean_error_deg": float(st["mean_error_deg"][0]),
        "max_abs_error_deg": float(st["max_abs_error_deg"][0]),
        "crb_deg": crb,
        "rmse_over_crb": rmse / crb if crb > 0 else math.inf,
        "crb_window_s": run.kalman.memory_s,
        "n_updates": int(track.n_updates),
        "n_bearings": int(st["n"]),
        "n_peaks": int(track.n_peaks),
        "n_measurements": int(track.n_measurements),
        "n_main_refs": int(track.n_main_refs),
        "n_aux_refs": int(track.n_aux_refs),
        "refs_off_grid": int(track.n_refs_off_grid),
        "gated": int(track.gated[0]),
        "reinit": int(track.reinit[0]),
        "adc_clipped": int(s.truth.n_clipped),
        "backend": run.backend,
        "mode": sig.mode,
        "snr_db": sig.snr_db,
        "duration_s": sig.duration_s,
        "seed": sig.seed,
        "settle_s": run.settle,
        "elapsed_s": {"signal": t1 - t0, "frontend": t2 - t1, "dsp": t3 - t2},
    }
