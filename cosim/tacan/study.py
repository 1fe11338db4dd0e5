"""TACAN's side of the generic studies (:mod:`cosim.studies.sweep`): its parameter space,
the run of one sweep point (signal, front end, FIFO and fixed-point DSP on the bit-exact
fast path) and of the paired float golden chain, and the cycle-accurate re-check.

Parameters (``--param NAME=VALUES``)
-----------------------------------
``adc_bits``              ADC word length (the signal is digitised once per record for every
                          value, :func:`cosim.tacan.signal.generate_adc_variants`).
``<field>``               any field of :class:`hdl.tacan.params.TacanFrontendParams`
                          (``nco_amp_bits``, ``mixer_out_bits``, ``cic_out_bits``,
                          ``fir_coef_bits``, ``fir_out_bits``, ``env_iterations``,
                          ``mixer_rounding``, ...).
``dsp.<fmt>``             total width of a format of the fixed-point core (``y``, ``x``, ``P``,
                          ``K``, ``cs``, ``innov``, ``r``), integer bits kept: fraction bits
                          change.
``dsp.<fmt>.rounding``    rounding of that format (``floor`` / ``half_up``).
``kalman.<field>``        a :class:`dsp.tacan.kalman_config.KalmanConfig` field.
``detector``              what the FPGA detects (``both``, the default; ``pulse``; ``pair``):
                          one value per study, since the golden chain detects the same way
                          (the single-pulse receiver's study: ``detector=pulse``).
"""
from __future__ import annotations

import time
from dataclasses import fields, replace

import numpy as np

from ..core.receivers import SweepModel

__all__ = ["GOLDEN_ADC_BITS", "FORMATS", "check_param", "trial_signal", "run_config",
           "study_detector", "recheck_point", "TacanSweepRecord", "SWEEP_MODEL"]

#: ADC word length of the float golden chain's record.
GOLDEN_ADC_BITS = 16
#: Formats of the fixed-point Kalman core a sweep may resize (``dsp.<fmt>``).
FORMATS = ("y", "x", "P", "K", "cs", "innov", "r")


def check_param(name: str) -> None:
    """Refuse a swept parameter name TACAN does not know (ValueError)."""
    from dsp.tacan.kalman_config import KalmanConfig
    from hdl.tacan.params import TacanFrontendParams
    hdl_fields = {f.name for f in fields(TacanFrontendParams) if f.init and f.name != "config"}
    if name in ("adc_bits", "detector") or name in hdl_fields:
        return
    parts = name.split(".")
    if parts[0] == "dsp" and len(parts) in (2, 3) and parts[1] in FORMATS and \
            (len(parts) == 2 or parts[2] == "rounding"):
        return
    if parts[0] == "kalman" and len(parts) == 2 and parts[1] in {f.name for f in fields(KalmanConfig)}:
        return
    raise ValueError(
        f"unknown parameter {name!r}: use adc_bits, detector, a TacanFrontendParams field "
        f"({', '.join(sorted(hdl_fields))}), dsp.<fmt>[.rounding] with fmt in {FORMATS}, "
        f"or kalman.<field>")


def trial_signal(cfg, snr_db: float, trial: int, adc_bits: int = 12):
    """The :class:`~cosim.tacan.signal.TacanSignalConfig` of a record (SNR, trial seed)."""
    from .signal import TacanSignalConfig
    rng = np.random.default_rng([cfg.seed, trial, 7919])
    bearing = float(np.round(rng.uniform(0, 360), 3))
    # SeedSequence entropy must be non-negative: a negative SNR gets a key of its own length
    # (no collision with a positive one); SNR >= 0 keeps the seeds of the published studies
    milli = int(round(snr_db * 1000))
    key = [cfg.seed, trial, milli] if milli >= 0 else [cfg.seed, trial, -milli, 1]
    seed = int(np.random.default_rng(key).integers(1 << 31))
    return TacanSignalConfig(snr_db=float(snr_db), duration_s=cfg.duration_s, seed=seed,
                             bearing_deg=bearing, adc_bits=adc_bits)


def run_config(cfg, combo: tuple, sig):
    """The :class:`cosim.tacan.config.TacanRunConfig` of a point (raises ValueError if invalid)."""
    from dsp.fixed import FixedFormat
    from dsp.tacan.kalman_config import KalmanConfig, KalmanFixedConfig
    from ..core.validate import check_choice, check_int
    from .config import TacanRunConfig
    from dsp.tacan.frontend import DETECTORS
    hdl, kal, fmts, opts = {}, {"memory_s": cfg.memory_s}, {}, {}
    base = KalmanFixedConfig()
    for name, v in combo:
        if name == "adc_bits":
            sig = replace(sig, adc_bits=check_int("adc_bits", v, 1, 24))
        elif name == "detector":
            opts["detector"] = check_choice("detector", v, tuple(DETECTORS))
        elif name.startswith("dsp."):
            parts = name.split(".")
            f = fmts.get(parts[1], getattr(base, parts[1]))
            if len(parts) == 2:
                w = check_int(name, v, 2, 62)
                f = FixedFormat(w, f.frac + (w - f.width), f.signed, f.rounding, f.overflow)
            else:
                check_choice(name, v, ("floor", "half_up"))
                f = FixedFormat(f.width, f.frac, f.signed, v, f.overflow)
            fmts[parts[1]] = f
        elif name.startswith("kalman."):
            kal[name.split(".")[1]] = v
        else:
            hdl[name] = v
    kalman = KalmanConfig(**kal)
    fixed = KalmanFixedConfig(kalman=kalman, **fmts)
    run = TacanRunConfig(signal=sig, backend="model", dsp="fixed", kalman=kalman, fixed=fixed,
                         hdl_changes=tuple(sorted(hdl.items())), **opts)
    run.hdl_params  # validates the word lengths (headroom, widths)
    return run


def study_detector(cfg) -> str:
    """The detector of every point and of the golden chain (``detector`` swept with one
    value, else the default); ValueError for several values: each record's golden run is
    shared by all its points, so they must detect alike."""
    from .config import TacanRunConfig
    vals = dict(cfg.params).get("detector")
    if vals is None:
        return TacanRunConfig().detector
    if len(vals) != 1:
        raise ValueError(f"detector={','.join(map(str, vals))}: one detector per study (the "
                         f"golden chain of each record detects the same way); run one study "
                         f"per detector")
    return vals[0]


def check_point(cfg, combo: tuple) -> None:
    """Build and validate a point's run configuration (ValueError if refused)."""
    study_detector(cfg)
    run_config(cfg, combo, trial_signal(cfg, cfg.snr_db[0], 0))


def _score(r: dict) -> dict:
    keep = ("shown", "rmse_deg", "mean_error_deg", "max_abs_error_deg", "crb_deg",
            "n_bearings", "n_valid_bearings", "misleading_bearings", "first_valid_bearing_s",
            "gated", "reinit", "adc_clipped", "fifo_dropped", "dsp_events", "ranges", "digest")
    return {k: r.get(k) for k in keep}


def recheck_point(cfg, run, signal) -> dict:
    """Re-run the first samples of a point cycle-accurately (``cfg.recheck_plan``) and
    compare the FIFO words and their cycles with the bit-exact model."""
    from .frontends import FRONTENDS
    backend, n = cfg.recheck_plan
    x = signal.samples[:n]
    t0 = time.perf_counter()
    a = FRONTENDS["model"](x, run)
    try:
        b = FRONTENDS[backend](x, run)
    except RuntimeError as e:           # e.g. Verilator missing
        return {"backend": backend, "error": str(e)}
    same = (np.array_equal(a.words, b.words) and np.array_equal(a.cycles, b.cycles)
            and a.fifo_dropped == b.fifo_dropped)
    return {"backend": backend, "samples": int(len(x)), "words": int(len(a.words)),
            "same_bits": bool(same), "seconds": time.perf_counter() - t0,
            **({"error": "no FIFO words in the re-checked samples: inconclusive"}
               if len(a.words) == 0 else {})}


def confirm_recheck(cfg, combo: tuple) -> dict:
    """The cycle-accurate re-check of the confirmed combination (first SNR, trial 0)."""
    from .signal import generate
    sig = trial_signal(cfg, cfg.snr_db[0], 0)
    run = replace(run_config(cfg, combo, sig), require_bearing=False)
    return recheck_point(cfg, run, generate(run.signal))


class TacanSweepRecord:
    """One (SNR, trial) record of a sweep: the signal generated once (digitised at every ADC
    width the points need and at the golden one), the front end's run shared by the points
    that differ only in the DSP (the front-end cache, keyed by ``run_tacan``)."""

    def __init__(self, cfg, snr_db: float, trial: int, combos: list):
        from .signal import generate_adc_variants
        self.cfg = cfg
        self.sig = sig = trial_signal(cfg, snr_db, trial)
        bits = sorted({int(dict(c).get("adc_bits", sig.adc_bits)) for c in combos} |
                      {GOLDEN_ADC_BITS})
        self.signals = generate_adc_variants(sig, bits)
        self.fe_cache: dict = {}
        #: what every row of this record carries
        self.base = {"bearing_deg": sig.bearing_deg}

    def golden(self) -> dict:
        from dsp.tacan.kalman_config import KalmanConfig
        from . import run as tr
        from .config import TacanRunConfig
        gs = self.signals[GOLDEN_ADC_BITS]
        grun = TacanRunConfig(signal=gs.truth.config, backend="golden", dsp="float",
                              kalman=KalmanConfig(memory_s=self.cfg.memory_s),
                              detector=study_detector(self.cfg), require_bearing=False)
        return _score(tr.run_tacan(grun, gs))

    def point(self, combo: tuple, recheck: bool = False) -> dict:
        from . import run as tr
        run = run_config(self.cfg, combo, self.sig)
        run = replace(run, require_bearing=False)
        s = self.signals[run.signal.adc_bits]
        out = _score(tr.run_tacan(run, s, frontend_cache=self.fe_cache))
        if recheck:
            out["recheck"] = recheck_point(self.cfg, run, s)
        return out


#: What :mod:`cosim.studies.sweep` needs of TACAN (``Study.model`` of ``sweep tacan``).
SWEEP_MODEL = SweepModel(check_param=check_param, check_point=check_point,
                         record=TacanSweepRecord, confirm_recheck=confirm_recheck,
                         default_params=(("adc_bits", tuple(range(4, 15))),),
                         cpu_s_per_record_s=1.5, title="TACAN quantisation sweep",
                         description=f"Path: bit-exact front-end model, FIFO/link model, "
                                     f"fixed-point DSP core. Golden: float front end + float "
                                     f"DSP on the same records (ADC {GOLDEN_ADC_BITS} bits).",
                         shown_note="TACAN: the estimates are the bearings (deg), each when it "
                                    "became available; valid = not flagged by the receiver; "
                                    "display epoch one antenna revolution (1/15 s); "
                                    "misleading = shown valid and more than 20 deg off (a "
                                    "sector error); scored after 2 x the filter memory.")
