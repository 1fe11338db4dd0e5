"""Equivalence of the TACAN front end's bit-exact model, Amaranth simulation and its Verilog
under Verilator and Icarus Verilog (``python -m cosim check-equivalence --top tacan``).

:func:`check_equivalence` feeds one realistic TACAN IF record (seeded
:func:`cosim.tacan.signal.generate`, SNR 10 dB; :func:`tacan_record`) through every backend
and compares every FIFO word (amplitude, timestamp, tag) and the cycle it leaves on. With
``stall=True`` the DSP side's ``ready`` follows a seeded on/off pattern
(:func:`cosim.tools.equivalence.stall_pattern`) and the FIFO is made shallow, so drops,
markers and the overflow counter are exercised too.
"""
from __future__ import annotations

import time

import numpy as np

from ..tools.equivalence import (BACKENDS, ICARUS_MAX_SAMPLES, PYSIM_MAX_SAMPLES,
                                 check_samples_backends,
                                 simulators_line, skip_reason, stall_pattern)
from .signal import TacanSignalConfig, generate

__all__ = ["check_equivalence", "tacan_record", "TOPS"]

#: Cycles run after the last ADC sample so that every peak leaves the pipeline.
FLUSH_CYCLES = 400
#: The tops this check runs.
TOPS = ("tacan",)


def tacan_record(samples: int, seed: int, snr_db: float | None = 10.0) -> np.ndarray:
    """``samples`` ADC codes of the default TACAN scenario (X mode, bearing 90 deg)."""
    cfg = TacanSignalConfig(duration_s=samples / 20e6 + 1e-6, snr_db=snr_db, seed=seed)
    return generate(cfg).samples[:samples].astype(np.int64)


def check_equivalence(top: str = "tacan", samples: int = 20_000, *,
                      backends=BACKENDS, seed: int = 1, stall: bool = False,
                      params=None, pysim_max_samples: int = PYSIM_MAX_SAMPLES,
                      icarus_max_samples: int = ICARUS_MAX_SAMPLES,
                      progress: bool = False) -> dict:
    """Run the backends on the same stimulus and count mismatching FIFO words.

    Parameters
    ----------
    top : {"tacan"}
    samples : int
        ADC samples (20 MS/s: 20_000 = 1 ms).
    backends : sequence of {"model", "pysim", "verilator", "icarus"}
        ``model`` is the reference; ``pysim`` is skipped above :data:`PYSIM_MAX_SAMPLES`,
        ``icarus`` above :data:`ICARUS_MAX_SAMPLES`, ``verilator`` and ``icarus`` when not
        installed (all with a note: :func:`cosim.tools.equivalence.skip_reason`).
    seed : int
        Signal (and stall pattern) seed.
    stall : bool
        DSP ``ready`` pattern with long off bursts and a 4-word FIFO (drops and markers).
    params : TacanFrontendParams, optional
        Default: the default receiver's front end (``TacanRunConfig().hdl_params``).
    pysim_max_samples : int
        Longest record the Amaranth simulation is run on (default
        :data:`PYSIM_MAX_SAMPLES`: about 15 s at ~3k cycles/s).
    icarus_max_samples : int
        Longest record Icarus Verilog is run on (default :data:`ICARUS_MAX_SAMPLES`).

    Returns
    -------
    dict
        ``top``, ``samples``, ``mismatches`` (words differing from the model, plus the
        difference in word count, over all backends run), ``backends`` (those run),
        ``skipped`` ({backend: reason}), ``words``, ``peaks``, ``markers``, ``dropped``,
        ``per_backend`` ({backend: {"mismatches", "words", "seconds"}}), ``compared``
        (which backend was compared with the model on how many words), ``equivalent``
        (True only when at least two backends compared a non-empty record and nothing
        differed), ``verdict`` (why, in words), ``n_cycles`` (cycles each backend ran) and
        ``simulators`` (:func:`cosim.tools.equivalence.simulators_line`).
    """
    from hdl.tacan.model import TacanFrontendModel
    if top not in TOPS:
        raise ValueError(f"top must be one of {TOPS}, not {top!r}")
    check_samples_backends(samples, backends)
    if params is None:      # the default receiver's front end
        from dataclasses import replace
        from .config import TacanRunConfig
        params = TacanRunConfig().hdl_params
        if stall:
            params = replace(params, fifo_depth=4)
    x = tacan_record(int(samples), seed)
    n_cycles = len(x) + FLUSH_CYCLES
    ready = stall_pattern(n_cycles, seed) if stall else None
    freq = params.nco_freq_word

    import sys
    from tqdm import tqdm
    bar = tqdm(total=len(set(backends) | {"model"}), desc="check-equivalence", unit="backend",
               file=sys.stderr, disable=not progress or not sys.stderr.isatty(),
               leave=False)
    t0 = time.perf_counter()
    model = TacanFrontendModel(params)
    peaks, _ = model.run(x)
    ref = model.fifo_output(peaks, n_cycles, out_ready=ready)
    per = {"model": {"mismatches": 0, "words": int(len(ref.words)),
                     "seconds": time.perf_counter() - t0}}
    skipped = {}
    run = ["model"]
    bar.update()

    def compare(name, res, seconds):
        n = min(len(res.words), len(ref.words))
        bad = int(np.count_nonzero(res.words[:n] != ref.words[:n]))
        bad += int(np.count_nonzero(res.cycles[:n] != ref.cycles[:n]))
        bad += abs(len(res.words) - len(ref.words))
        per[name] = {"mismatches": bad, "words": int(len(res.words)), "seconds": seconds}
        run.append(name)
        bar.update()

    from hdl.tacan.frontend import TacanFrontEnd
    for name in [b for b in BACKENDS if b in backends and b != "model"]:
        why = skip_reason(name, int(samples), pysim_max_samples=pysim_max_samples,
                          icarus_max_samples=icarus_max_samples)
        if why is not None:
            skipped[name] = why
            continue
        t = time.perf_counter()
        if name == "pysim":
            from ..backends.pysim import run_stream
            res = run_stream(TacanFrontEnd(params), x, out_ready=ready, n_cycles=n_cycles,
                             inputs={"freq": freq})
        elif name == "verilator":
            from ..backends.verilator import VerilatorStreamSim
            sim = VerilatorStreamSim(TacanFrontEnd(params), name="tacan_frontend")
            res = sim.run(x, out_ready=ready, n_cycles=n_cycles, inputs={"freq": freq})
        else:
            from ..backends.icarus import IcarusStreamSim
            sim = IcarusStreamSim(TacanFrontEnd(params), name="tacan_frontend")
            res = sim.run(x, out_ready=ready, n_cycles=n_cycles, inputs={"freq": freq})
        compare(name, res, time.perf_counter() - t)

    bar.close()
    fields = model.unpack(ref.words)
    markers = fields["tag"] == 2
    compared = [f"{name} vs model: {v['words']} vs {per['model']['words']} FIFO words, "
                f"{v['mismatches']} mismatches" for name, v in per.items() if name != "model"]
    total = int(sum(v["mismatches"] for v in per.values()))
    if len(run) < 2:
        verdict = (f"nothing was compared: only {', '.join(run)} ran"
                   + "".join(f"; {k} skipped: {w}" for k, w in skipped.items()))
    elif len(ref.words) == 0:
        verdict = (f"nothing was compared: the {samples} samples gave no FIFO word (use "
                   f"--samples of a few 10,000 at least, a pulse pair every ~280 us)")
    elif total:
        verdict = f"{total} mismatches ({'; '.join(compared)})"
    else:
        verdict = f"equivalent: {'; '.join(compared)}"
    return {
        "top": top,
        "samples": int(samples),
        "mismatches": total,
        "equivalent": bool(len(run) >= 2 and len(ref.words) > 0 and total == 0),
        "verdict": verdict,
        "compared": compared,
        "backends": run,
        "skipped": skipped,
        "stall": bool(stall),
        "seed": int(seed),
        "peaks": int(len(peaks)),
        "words": int(len(ref.words)),
        "markers": int(markers.sum()),
        "dropped": int(ref.dropped.sum()),
        "per_backend": per,
        "n_cycles": int(n_cycles),
        "simulators": simulators_line(per, n_cycles),
    }
