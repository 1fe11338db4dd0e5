"""Equivalence of the bit-exact model, the Amaranth simulation and the Verilated Verilog.

``check_equivalence(top="tacan", samples=N)`` feeds one realistic TACAN IF record (seeded
:func:`cosim.tacan.signal.generate`, SNR 10 dB) through every backend and compares every
FIFO word (amplitude, timestamp, tag) and the cycle it leaves on. With ``stall=True`` the DSP
side's ``ready`` follows a seeded on/off pattern and the FIFO is made shallow, so drops,
markers and the overflow counter are exercised too.
"""
from __future__ import annotations

import time

import numpy as np

__all__ = ["check_equivalence", "check_record_size", "compare_backends", "PYSIM_MAX_SAMPLES", "TOPS"]

#: Longest record the Amaranth simulator is run on (~1e3 cycles/s for the whole top).
PYSIM_MAX_SAMPLES = 40_000
#: Cycles run after the last ADC sample so that every peak leaves the pipeline.
FLUSH_CYCLES = 400
TOPS = ("tacan",)
BACKENDS = ("model", "pysim", "verilator")


#: Memory per ADC sample of a check (the IF record, the codes, the model's working arrays
#: and the backends' outputs; bytes, with margin).
BYTES_PER_SAMPLE = 64


def check_record_size(samples) -> int:
    """Refuse, before any work, a record that is not a positive integer or cannot fit this
    machine's memory."""
    from .validate import check_int, check_memory
    n = check_int("--samples", samples, 1)
    check_memory(n * BYTES_PER_SAMPLE, f"--samples {n:,}", "--samples")
    return n


def tacan_record(samples: int, seed: int, snr_db: float | None = 10.0) -> np.ndarray:
    """``samples`` ADC codes of the default TACAN scenario (X mode, bearing 90 deg)."""
    from .tacan.signal import TacanSignalConfig, generate
    cfg = TacanSignalConfig(duration_s=samples / 20e6 + 1e-6, snr_db=snr_db, seed=seed)
    return generate(cfg).samples[:samples].astype(np.int64)


def stall_pattern(n_cycles: int, seed: int, *, p_ready: float = 0.5,
                  burst: int = 4000) -> np.ndarray:
    """DSP ``ready`` per cycle: off/on bursts (mean ``burst`` cycles), on with ``p_ready``."""
    rng = np.random.default_rng(seed + 7919)
    on = np.repeat(rng.random(n_cycles // burst + 1) < p_ready, burst)[:n_cycles]
    return on & (rng.random(n_cycles) < 0.5)


def check_equivalence(top: str = "tacan", samples: int = 20_000, *,
                      backends=BACKENDS, seed: int = 1, stall: bool = False,
                      params=None, pysim_max_samples: int = PYSIM_MAX_SAMPLES,
                      progress: bool = False) -> dict:
    """Run the backends on the same stimulus and count mismatching FIFO words.

    Parameters
    ----------
    top : {"tacan"}
    samples : int
        ADC samples (20 MS/s: 20_000 = 1 ms).
    backends : sequence of {"model", "pysim", "verilator"}
        ``model`` is the reference; ``pysim`` is skipped above :data:`PYSIM_MAX_SAMPLES`,
        ``verilator`` when it is not installed (both with a note).
    seed : int
        Signal (and stall pattern) seed.
    stall : bool
        DSP ``ready`` pattern with long off bursts and a 4-word FIFO (drops and markers).
    params : TacanFrontendParams, optional
        Default: the default receiver's front end (``TacanRunConfig().hdl_params``).
    pysim_max_samples : int
        Longest record the Amaranth simulation is run on (default
        :data:`PYSIM_MAX_SAMPLES`: about 15 s at ~3k cycles/s).

    Returns
    -------
    dict
        ``top``, ``samples``, ``mismatches`` (words differing from the model, plus the
        difference in word count, over all backends run), ``backends`` (those run),
        ``skipped`` ({backend: reason}), ``words``, ``peaks``, ``markers``, ``dropped``,
        ``per_backend`` ({backend: {"mismatches", "words", "seconds"}}), ``compared``
        (which backend was compared with the model on how many words), ``equivalent``
        (True only when at least two backends compared a non-empty record and nothing
        differed) and ``verdict`` (why, in words).
    """
    from hdl.tacan.model import TacanFrontendModel
    if top not in TOPS:
        raise ValueError(f"top must be one of {TOPS}, not {top!r}")
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1:
        raise ValueError(f"samples must be an integer >= 1, not {samples!r}")
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"backends must be among {BACKENDS}, not {unknown}")
    if params is None:      # the default receiver's front end
        from dataclasses import replace
        from .tacan.config import TacanRunConfig
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

    if "pysim" in backends:
        if samples > pysim_max_samples:
            skipped["pysim"] = (f"pysim runs only for samples <= {pysim_max_samples} "
                                f"(~3e3 cycles/s for the whole top)")
        else:
            from hdl.tacan.frontend import TacanFrontEnd
            from .pysim import run_stream
            t = time.perf_counter()
            res = run_stream(TacanFrontEnd(params), x, out_ready=ready, n_cycles=n_cycles,
                             inputs={"freq": freq})
            compare("pysim", res, time.perf_counter() - t)
    if "verilator" in backends:
        from .verilator import VerilatorStreamSim, verilator_available
        if not verilator_available():
            from .verilog import verilator_missing_message
            skipped["verilator"] = verilator_missing_message()
        else:
            from hdl.tacan.frontend import TacanFrontEnd
            t = time.perf_counter()
            sim = VerilatorStreamSim(TacanFrontEnd(params), name="tacan_frontend")
            res = sim.run(x, out_ready=ready, n_cycles=n_cycles, inputs={"freq": freq})
            compare("verilator", res, time.perf_counter() - t)

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
    }


def compare_backends(top: str, samples: int, backends, run, *, seed: int, stall: bool,
                     empty_hint: str, record_words: int = 1,
                     pysim_max_samples: int = PYSIM_MAX_SAMPLES) -> dict:
    """The comparison and verdict of a session-based check (a receiver's
    ``Receiver.equivalence``): ``run(backend) -> (words, cycles, overflow_count, seconds)``
    for the same stimulus on each backend; the model is the reference, every FIFO word, its
    cycle and the overflow counter are compared. ``pysim`` is skipped above
    ``pysim_max_samples``, ``verilator`` when it is not installed (both noted).
    ``empty_hint`` ends the verdict when the model gave no word. Returns the keys of
    :func:`check_equivalence` (``peaks``: the model's records, ``markers``: 0,
    ``dropped``: the model's overflow count)."""
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"backends must be among {BACKENDS}, not {unknown}")
    ref_w, ref_c, ref_ovf, secs = run("model")
    per = {"model": {"mismatches": 0, "words": int(len(ref_w)), "seconds": secs}}
    ran, skipped = ["model"], {}
    for name in [b for b in BACKENDS if b in backends and b != "model"]:
        if name == "pysim" and samples > pysim_max_samples:
            skipped["pysim"] = f"pysim runs only for samples <= {pysim_max_samples}"
            continue
        if name == "verilator":
            from .verilator import verilator_available
            if not verilator_available():
                from .verilog import verilator_missing_message
                skipped["verilator"] = verilator_missing_message()
                continue
        w, c, ovf, secs = run(name)
        n = min(len(w), len(ref_w))
        bad = int(np.count_nonzero(w[:n] != ref_w[:n]) + np.count_nonzero(c[:n] != ref_c[:n]))
        bad += abs(len(w) - len(ref_w)) + int(ovf != ref_ovf)
        per[name] = {"mismatches": bad, "words": int(len(w)), "seconds": secs}
        ran.append(name)
    compared = [f"{k} vs model: {v['words']} vs {per['model']['words']} FIFO words, "
                f"{v['mismatches']} mismatches" for k, v in per.items() if k != "model"]
    total = int(sum(v["mismatches"] for v in per.values()))
    if len(ran) < 2:
        verdict = (f"nothing was compared: only {', '.join(ran)} ran"
                   + "".join(f"; {k} skipped: {w}" for k, w in skipped.items()))
    elif len(ref_w) == 0:
        verdict = f"nothing was compared: the {samples} samples gave no FIFO word ({empty_hint})"
    elif total:
        verdict = f"{total} mismatches ({'; '.join(compared)})"
    else:
        verdict = f"equivalent: {'; '.join(compared)}"
    return {"top": top, "samples": int(samples), "mismatches": total,
            "equivalent": bool(len(ran) >= 2 and len(ref_w) > 0 and total == 0),
            "verdict": verdict, "compared": compared, "backends": ran, "skipped": skipped,
            "stall": bool(stall), "seed": int(seed),
            "peaks": int(len(ref_w) // record_words), "words": int(len(ref_w)),
            "markers": 0, "dropped": int(ref_ovf), "per_backend": per}
