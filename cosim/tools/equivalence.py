"""Equivalence of the bit-exact model, the Amaranth simulation and the Verilated Verilog:
the generic part of ``python -m cosim check-equivalence``.

A receiver's check (``Receiver.equivalence``, e.g.
:func:`cosim.tacan.equivalence.check_equivalence`) runs its front end on every backend (:data:`BACKENDS`) on the same stimulus and hands the
outputs to :func:`compare_backends`, which compares every FIFO word, its cycle and the
overflow counter against the model and states a verdict. :func:`stall_pattern` is the seeded
DSP ``ready`` pattern with long stalls (drops, markers); :func:`check_record_size` refuses a
record that cannot fit this machine.
"""
from __future__ import annotations

import numpy as np

__all__ = ["check_record_size", "compare_backends", "stall_pattern", "PYSIM_MAX_SAMPLES",
           "BACKENDS"]

#: Longest record the Amaranth simulator is run on (~1e3 cycles/s for the whole top).
PYSIM_MAX_SAMPLES = 40_000
#: The backends compared, the first (the bit-exact model) the reference.
BACKENDS = ("model", "pysim", "verilator")


#: Memory per ADC sample of a check (the IF record, the codes, the model's working arrays
#: and the backends' outputs; bytes, with margin).
BYTES_PER_SAMPLE = 64


def check_record_size(samples) -> int:
    """Refuse, before any work, a record that is not a positive integer or cannot fit this
    machine's memory."""
    from ..core.validate import check_int, check_memory
    n = check_int("--samples", samples, 1)
    check_memory(n * BYTES_PER_SAMPLE, f"--samples {n:,}", "--samples")
    return n


def stall_pattern(n_cycles: int, seed: int, *, p_ready: float = 0.5,
                  burst: int = 4000) -> np.ndarray:
    """DSP ``ready`` per cycle: off/on bursts (mean ``burst`` cycles), on with ``p_ready``."""
    rng = np.random.default_rng(seed + 7919)
    on = np.repeat(rng.random(n_cycles // burst + 1) < p_ready, burst)[:n_cycles]
    return on & (rng.random(n_cycles) < 0.5)


def compare_backends(top: str, samples: int, backends, run, *, seed: int, stall: bool,
                     empty_hint: str, record_words: int = 1,
                     pysim_max_samples: int = PYSIM_MAX_SAMPLES) -> dict:
    """The comparison and verdict of a session-based check (a receiver's
    ``Receiver.equivalence``): ``run(backend) -> (words, cycles, overflow_count, seconds)``
    for the same stimulus on each backend; the model is the reference, every FIFO word, its
    cycle and the overflow counter are compared. ``pysim`` is skipped above
    ``pysim_max_samples``, ``verilator`` when it is not installed (both noted).
    ``empty_hint`` ends the verdict when the model gave no word. Returns the keys of
    :func:`cosim.tacan.equivalence.check_equivalence` (``peaks``: the model's records,
    ``markers``: 0, ``dropped``: the model's overflow count)."""
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
            from ..backends.verilator_harness import verilator_available
            if not verilator_available():
                from ..backends.verilog import verilator_missing_message
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
