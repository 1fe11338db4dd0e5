"""GNSS's side of the generic sweep engine (:mod:`cosim.studies.sweep`): the word lengths of
the fixed-point AUKF core (:class:`dsp.gnss.aukf_master.AukfFormats`) swept on the
correlation-domain fast path, each point paired with the float64 (golden) AUKF on the same
truth and the same correlator noise.

``python -m cosim sweep gnss --param dsp.P=32:48:4 --param dsp.gain=16:32:4 --design oat``

Parameters (``--param NAME=VALUES``)
-----------------------------------
``dsp.<fmt>``   total width of a format of the core (``theta``, ``w0``, ``w1``, ``w2``, ``P``,
                ``y``, ``trig``, ``gain``, ``q``), integer bits kept: the fraction bits change
                with the width (as TACAN's ``dsp.<fmt>``).

A record is one (C/N0, trial): the engine's ``snr_db`` values are **C/N0 in dB-Hz** here
(the report's "SNR dB" column), one jerk-process truth (the AUKF patent's model,
``q_true = q0 = 5``, seeded by the study seed, the trial and the C/N0), ``duration_s`` long, the AUKF started on
the truth (fast path). Figures: ``phase_rmse_deg`` (the receiver's primary figure, second
half of the record, wrapped to the Costas lock point), ``doppler_rmse_hz``, ``cycle_slips``,
the core's events (Cholesky failures, P not PD,
saturations), and what a user sees (:func:`shown_tracking`: accuracy, availability,
integrity). No cycle-accurate re-check: the core is DSP software (its word lengths are an
emulation, docs/explanation/gnss_aukf.md); the HDL channel's bits are checked by the closed-loop tests.
"""
from __future__ import annotations

from dataclasses import fields, replace

import numpy as np

from hdl.gnss.params import DEFAULT_FS_HZ

from ..core.receivers import SweepModel

__all__ = ["FORMATS", "check_param", "formats_of", "check_point", "GnssSweepRecord", "SWEEP_MODEL"]

#: q0 of the AUKF patent (the truth's intensity in the sweep) and the records' true C/N0 unit.
Q_TRUE = 5.0


def _format_names() -> tuple:
    from dsp.gnss.aukf_master import AukfFormats
    return tuple(f.name for f in fields(AukfFormats))


FORMATS = _format_names()


def check_param(name: str) -> None:
    """Refuse a swept parameter name the GNSS sweep does not know (ValueError)."""
    parts = name.split(".")
    if len(parts) == 2 and parts[0] == "dsp" and parts[1] in FORMATS:
        return
    raise ValueError(f"unknown parameter {name!r}: use dsp.<fmt> with fmt in "
                     f"{', '.join(FORMATS)} (a format's total width of the AUKF core)")


def formats_of(combo: tuple):
    """The :class:`~dsp.gnss.aukf_master.AukfFormats` of a point: each swept width with its
    format's integer bits kept (ValueError if refused)."""
    from dsp.gnss.aukf_master import AukfFormats
    from dsp.gnss.aukf_master import QFormat
    from ..core.validate import check_int
    base = AukfFormats()
    kw = {}
    for name, v in combo:
        check_param(name)
        f = getattr(base, name.split(".")[1])
        w = check_int(name, v, 2, 62)
        frac = f.frac + (w - f.bits)
        if frac < 0:
            raise ValueError(f"{name} = {w} bits leaves no fraction bits (the format keeps "
                             f"{f.bits - f.frac} integer bits)")
        kw[name.split(".")[1]] = QFormat(w, frac)
    return replace(base, **kw)


def _truth_and_ctx(cfg, cn0_dbhz: float, trial: int):
    from dsp.gnss.trackers import TrackerContext
    from .dynamics import aukf_patent_dynamics
    from .loopsim import truth_for
    seed = int(np.random.default_rng([cfg.seed, trial, int(round(cn0_dbhz * 1000))]).integers(1 << 31))
    truth = truth_for(aukf_patent_dynamics(q=Q_TRUE), cfg.duration_s + 0.01, seed=seed)
    a0 = truth(np.array([0.0]))
    ctx = TrackerContext(fs_hz=DEFAULT_FS_HZ, doppler0_hz=a0["doppler_hz"][:1],
                         doppler_rate0_hz_s=a0["doppler_rate_hz_s"][:1], cn0_dbhz=float(cn0_dbhz))
    return truth, ctx, seed


def _build(cfg, combo: tuple) -> None:
    from dsp.gnss.trackers import TrackerContext, make_tracker
    from dsp.gnss.aukf import PATENT_X0
    fm = formats_of(combo)
    ctx = TrackerContext(fs_hz=DEFAULT_FS_HZ, doppler0_hz=np.array([PATENT_X0[1] / (2 * np.pi)]),
                         doppler_rate0_hz_s=np.array([PATENT_X0[2] / (2 * np.pi)]),
                         cn0_dbhz=float(cfg.snr_db[0]))
    make_tracker("aukf", ctx, fm)


def check_point(cfg, combo: tuple) -> None:
    """Build the point's formats and the tracker (its range checks: "formats too narrow");
    a refused point's message names the smallest width of a swept format that the core
    accepts with the point's other values (the same checks, tried upwards)."""
    try:
        _build(cfg, combo)
    except ValueError as e:
        for i, (name, v) in enumerate(combo):
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool):
                continue
            for w in range(int(v) + 1, 63):
                try:
                    _build(cfg, combo[:i] + ((name, w),) + combo[i + 1:])
                except ValueError:
                    continue
                raise ValueError(f"{e}; the smallest {name} that passes is {w}") from None
        raise


#: A Doppler estimate shown valid further than this from the truth is misleading (Hz; the
#: "lost" rule of :mod:`cosim.gnss.study_aukf`).
MISLEADING_DOPPLER_HZ = 5.0


def shown_tracking(r, trk, duration_s: float) -> dict:
    """What a user sees of a fast-path run's trial 0 (:func:`dsp.shown.shown_figures`):
    one estimate per 1 ms epoch, its carrier phase error (deg, wrapped to the Costas lock
    point); valid unless the tracker has raised its ``diverged`` flag; display epoch 1 ms;
    scored over the record's second half; misleading = shown valid after a cycle slip (the
    true phase error's nearest lock point moved from where it locked) or with a Doppler
    error beyond :data:`MISLEADING_DOPPLER_HZ`."""
    from dsp.shown import shown_figures
    raw = r.phase_err_cycles[:, 0]
    n = raw.size
    lock = np.rint(raw / 0.5)
    pe = (raw - 0.5 * lock) * 360.0
    df = (r.freq_err_hz + r.doppler_hz - np.array(trk.est))[:, 0]
    valid = ~np.array(trk.flagged)[:, 0] if trk.flagged else np.ones(n, bool)
    bad = (lock != lock[0]) | (np.abs(df) > MISLEADING_DOPPLER_HZ)
    t = (np.arange(n) + 1.0) * 1e-3
    return shown_figures(t, pe, valid, settle_s=(n // 2) * 1e-3, end_s=duration_s,
                         epoch_s=1e-3, misleading=bad)


class GnssSweepRecord:
    """One (C/N0, trial) record: the truth made once; the golden (float64) AUKF and every
    point's fixed-point AUKF on the same truth and correlator noise (the fast path's
    generator seeded alike)."""

    def __init__(self, cfg, snr_db: float, trial: int, combos: list):
        self.cfg, self.cn0 = cfg, float(snr_db)
        self.truth, self.ctx, self.seed = _truth_and_ctx(cfg, self.cn0, trial)
        self.base = {"cn0_dbhz": self.cn0}

    def _run(self, arith) -> dict:
        from dsp.gnss.trackers import make_tracker
        from .loopsim import cycle_slips, track_fast
        from .study_aukf import DopplerRecorder
        n = int(round(self.cfg.duration_s / 1e-3))
        trk = DopplerRecorder(make_tracker("aukf", self.ctx, arith))
        r = track_fast(self.truth, self.cn0, n, shape=(1,), seed=self.seed, tracker=trk)
        h = n // 2
        pe = r.phase_err_cycles[h:, 0]
        pe = pe - 0.5 * np.rint(pe / 0.5)
        df = (r.freq_err_hz + r.doppler_hz - np.array(trk.est))[h:, 0]
        rep = trk.inner.report()
        slips = int(cycle_slips(r.phase_err_cycles)[0])
        return {"phase_rmse_deg": float(np.sqrt(np.mean(pe ** 2)) * 360.0),
                "doppler_rmse_hz": float(np.sqrt(np.mean(df ** 2))), "cycle_slips": slips,
                "q_hat_final": rep["q_hat"]["median_final"], "dsp_events": rep["events"],
                "shown": shown_tracking(r, trk, self.cfg.duration_s)}

    def golden(self) -> dict:
        return self._run("float64")

    def point(self, combo: tuple, recheck: bool = False) -> dict:
        return self._run(formats_of(combo))


#: What :mod:`cosim.studies.sweep` needs of the GNSS AUKF core (``sweep gnss``).
SWEEP_MODEL = SweepModel(check_param=check_param, check_point=check_point, record=GnssSweepRecord,
                         confirm_recheck=None, default_params=(("dsp.P", (32, 36, 40, 44, 48)),),
                         cpu_s_per_record_s=0.5, title="GNSS AUKF core word-length sweep",
                         description="Path: jerk truth (the AUKF patent's model, q = q0 = 5), correlation-domain "
                                     "fast path, fixed-point AUKF core (AukfFormats, word-length "
                                     "emulation). Golden: float64 AUKF on the same truth and noise. "
                                     "'SNR dB' = C/N0 dB-Hz; RMSE = carrier phase RMSE (deg).",
                         shown_note="GNSS: one estimate per 1 ms epoch (carrier phase error, "
                                    "deg, wrapped to the Costas lock point); valid unless the "
                                    "AUKF raised its divergence flag; display epoch 1 ms; "
                                    "scored over the record's second half; misleading = "
                                    "shown valid after a cycle slip or with a Doppler error "
                                    "beyond 5 Hz.")
