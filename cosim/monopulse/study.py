"""The monopulse side of the generic sweep (:mod:`cosim.studies.sweep`, ``python -m cosim
sweep monopulse``): its parameter space, one sweep point (the closed beam-steering loop on
the bit-exact HDL front end with the fixed-point tracker) and its paired golden run (the
float IF chain and float tracker on the same record).

Parameters (``--param NAME=VALUES``)
-----------------------------------
``adc_bits``      ADC word length (signal generator and front end).
``<field>``       a :class:`hdl.monopulse.params.MonopulseFrontendParams` field the scenario
                  does not fix: ``cordic_iterations``, ``cordic_in_bits`` (the normalised
                  accumulator width entering the ratio), ``corr_out_bits`` (the corrected
                  snapshot the accumulator sums), ``angle_bits``, ``dc_frac_bits``,
                  ``nco_table_bits``, ``mixer_out_bits``, ``cic_out_bits``, ...
``dsp.<fmt>``     total width of a format of the fixed-point tracker
                  (:data:`dsp.monopulse.tracker.MONOPULSE_FORMATS`: ``z``, ``x``, ``e``, ``c``,
                  ``s``, ``l``), integer bits kept.

A record is one (SNR, trial): the scenario of ``python -m cosim monopulse`` (target, rates,
channel mismatch, calibration) with the trial's seed; ``duration_s`` long, scored from
``2 memory_s``. The primary figure is the azimuth tracking RMS (deg) of the blocks in track
(:func:`shown_tracking`: what a user sees -- accuracy, availability, integrity).
"""
from __future__ import annotations

import time
from dataclasses import fields

import numpy as np

from ..core.receivers import SweepModel

__all__ = ["GOLDEN_ADC_BITS", "FIXED_BY_SCENARIO", "check_param", "run_config", "check_point",
           "MonopulseSweepRecord", "SWEEP_MODEL"]

#: ADC word length of the golden record.
GOLDEN_ADC_BITS = 16
#: Front-end fields the scenario sets (rates, block, geometry): not swept.
FIXED_BY_SCENARIO = ("fs_hz", "if_hz", "snapshot_decimation", "cic_rate", "snapshots",
                     "spacing_x_wl", "spacing_y_wl", "adc_bits")


def _hdl_fields():
    from hdl.monopulse.params import MonopulseFrontendParams
    return sorted(f.name for f in fields(MonopulseFrontendParams)
                  if f.init and f.name not in FIXED_BY_SCENARIO)


def check_param(name: str) -> None:
    """Refuse a parameter name the monopulse sweep does not know (ValueError)."""
    from dsp.monopulse.tracker import MONOPULSE_FORMATS
    if name == "adc_bits" or name in _hdl_fields():
        return
    parts = name.split(".")
    if len(parts) == 2 and parts[0] == "dsp" and parts[1] in MONOPULSE_FORMATS.signals():
        return
    raise ValueError(f"unknown parameter {name!r}: use adc_bits, a MonopulseFrontendParams "
                     f"field ({', '.join(_hdl_fields())}) or dsp.<fmt> with fmt in "
                     f"{MONOPULSE_FORMATS.signals()}")


def trial_seed(cfg, snr_db: float, trial: int) -> int:
    # (SeedSequence entropy must be >= 0: the SNR in milli-dB offset by 10**6)
    return int(np.random.default_rng([cfg.seed, trial, int(round(snr_db * 1000)) + 10 ** 6, 17])
               .integers(1 << 31))


def run_config(cfg, combo: tuple, snr_db: float, trial: int, **kw):
    """The :class:`~cosim.monopulse.run.MonopulseRunConfig` of a point (ValueError if
    refused): the model backend, fixed-point tracker, the swept values."""
    from ..core.validate import check_int
    from .run import MonopulseRunConfig
    hdl, dsp, adc = {}, {}, 12
    for name, v in combo:
        if name == "adc_bits":
            adc = check_int("adc_bits", v, 2, 16)
        elif name.startswith("dsp."):
            dsp[name[4:]] = check_int(name, v, 2, 62)
        else:
            hdl[name] = v
    args = dict(snr_db=float(snr_db), duration_s=cfg.duration_s, settle_s=2 * cfg.memory_s,
                seed=trial_seed(cfg, snr_db, trial), backend="model", dsp="fixed",
                adc_bits=adc, hdl_changes=tuple(sorted(hdl.items())),
                dsp_changes=tuple(sorted(dsp.items())))
    return MonopulseRunConfig(**{**args, **kw})


def check_point(cfg, combo: tuple) -> None:
    run_config(cfg, combo, cfg.snr_db[0], 0)


_KEEP = ("az_track_rms_deg", "el_track_rms_deg", "az_meas_rms_deg", "el_meas_rms_deg",
         "az_meas_over_crb", "el_meas_over_crb", "pointing_error_max_fraction",
         "lost_track_events", "acquired_trials", "fifo_dropped", "dsp_events", "digest")


def shown_tracking(r: dict, run) -> dict:
    """What a user sees of a run's trial 0 (:func:`dsp.shown.shown_figures`; the run
    made with ``keep_series``): one azimuth estimate per block (the tracker's, error in
    deg), valid while the loop is in track; display epoch one block; misleading = in track
    with the beam's pointing error beyond the unambiguous half-width (``lambda / 2D``, either
    axis), where the monopulse ratio no longer points back to the target."""
    from dsp.monopulse.angles import angles
    from dsp.shown import shown_figures
    from .run import TRACK
    s = r["series"]
    est, truth = s["est"][:, 0], s["truth"][:, 0]
    az_e, _ = angles(est[:, 0], est[:, 1])
    az_t, _ = angles(truth[:, 0], truth[:, 1])
    err = np.rad2deg(np.angle(np.exp(1j * (az_e - az_t))))
    unamb = np.array(run.signal_config().array.unambiguous_offset)
    beyond = np.max(np.abs(s["steer"][:, 0] - truth) / unamb, axis=-1) >= 1.0
    return shown_figures(s["t_s"], err, s["modes"][:, 0] == TRACK, settle_s=run.settle_s,
                         end_s=r["duration_s"], epoch_s=r["block_s"], misleading=beyond)


def _score(r: dict, run) -> dict:
    out = {k: r.get(k) for k in _KEEP}
    for k, v in out.items():
        if isinstance(v, float) and v != v:
            out[k] = None
    out["shown"] = shown_tracking(r, run)
    return out


def recheck(cfg, combo: tuple, snr_db: float, trial: int) -> dict:
    """The point's closed loop over the first ``recheck_samples`` ADC samples (at least 3
    blocks) on the cycle-accurate backend against the model: the same FIFO words, cycles,
    register writes and DSP bits (the digests)."""
    from .run import run_monopulse
    backend, n = cfg.recheck_plan
    base = run_config(cfg, combo, snr_db, trial)
    sig = base.signal_config()
    blocks = max(3, n // sig.samples_per_block)
    t0 = time.perf_counter()
    short = dict(duration_s=blocks * sig.block_s, settle_s=0.0, require_score=False)
    a = run_monopulse(run_config(cfg, combo, snr_db, trial, **short))
    try:
        b = run_monopulse(run_config(cfg, combo, snr_db, trial, backend=backend, **short))
    except RuntimeError as e:           # e.g. Verilator missing
        return {"backend": backend, "error": str(e)}
    return {"backend": backend, "samples": int(blocks * sig.samples_per_block),
            "words": int(a["records"]), "same_bits": a["digest"] == b["digest"],
            "seconds": time.perf_counter() - t0}


def confirm_recheck(cfg, combo: tuple) -> dict:
    return recheck(cfg, combo, cfg.snr_db[0], 0)


class MonopulseSweepRecord:
    """One (SNR, trial) record: the golden float run and the points on the bit-exact loop
    (each point's closed loop steers its own beam, so no front-end run is shared)."""

    def __init__(self, cfg, snr_db: float, trial: int, combos: list):
        self.cfg, self.snr_db, self.trial = cfg, float(snr_db), int(trial)
        self.fe_cache: dict = {}
        self.base = {"seed": trial_seed(cfg, snr_db, trial)}

    def golden(self) -> dict:
        from .run import run_monopulse
        run = run_config(self.cfg, (), self.snr_db, self.trial, backend="golden", dsp="float",
                         adc_bits=GOLDEN_ADC_BITS)
        return _score(run_monopulse(run, keep_series=True), run)

    def point(self, combo: tuple, recheck: bool = False) -> dict:
        from .run import run_monopulse
        run = run_config(self.cfg, combo, self.snr_db, self.trial)
        out = _score(run_monopulse(run, keep_series=True), run)
        if recheck:
            out["recheck"] = globals()["recheck"](self.cfg, combo, self.snr_db, self.trial)
        return out


#: What :mod:`cosim.studies.sweep` needs of the monopulse receiver.
SWEEP_MODEL = SweepModel(check_param=check_param, check_point=check_point,
                         record=MonopulseSweepRecord, confirm_recheck=confirm_recheck,
                         default_params=(("cordic_iterations", (8, 12, 16, 20)),),
                         cpu_s_per_record_s=250.0, title="Monopulse word-length sweep",
                         description=f"Path: the closed beam-steering loop on the bit-exact "
                                     f"front-end model (FIFO records, register writes), "
                                     f"fixed-point tracker. Golden: float IF chain + float "
                                     f"tracker on the same record (ADC {GOLDEN_ADC_BITS} bits). "
                                     f"Figure: azimuth tracking RMS (deg).",
                         shown_note="Monopulse: one azimuth estimate per block (the "
                                    "tracker's, deg); valid = the loop in track; display "
                                    "epoch one block; misleading = in track with the beam's "
                                    "pointing error beyond the unambiguous half-width "
                                    "(lambda / 2D on either axis).")
