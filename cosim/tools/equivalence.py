"""Equivalence of the bit-exact model and the three simulators of the design (the Amaranth
simulation, the Verilog under Verilator and under Icarus Verilog): the generic part of
``python -m cosim check-equivalence``.

A receiver's check (``Receiver.equivalence``, e.g.
:func:`cosim.tacan.equivalence.check_equivalence`) runs its front end on every backend
(:data:`BACKENDS`) on the same stimulus and hands the outputs to :func:`compare_backends`,
which compares every FIFO word, its cycle and the overflow counter against the model and
states a verdict; :func:`skip_reason` says why a backend does not run (too long a record for
the slow simulators, a tool not installed) and :func:`simulators_line` sums the run up in one
line (``model == pysim == verilator == icarus``, the cycles, each one's wall time).
:func:`stall_pattern` is the seeded DSP ``ready`` pattern with long stalls (drops, markers);
:func:`check_record_size` refuses a record that cannot fit this machine.
"""
from __future__ import annotations

import numpy as np

__all__ = ["check_record_size", "check_samples_backends", "compare_backends", "count_differences", "stall_pattern",
           "skip_reason", "simulators_line", "PYSIM_MAX_SAMPLES", "ICARUS_MAX_SAMPLES",
           "BACKENDS"]

#: Longest record the Amaranth simulator is run on (~1e3 cycles/s for the whole top).
PYSIM_MAX_SAMPLES = 40_000
#: Longest record Icarus Verilog is run on (~1e3..2e3 cycles/s for a whole top under cocotb).
ICARUS_MAX_SAMPLES = 40_000
#: The backends compared, the first (the bit-exact model) the reference.
BACKENDS = ("model", "pysim", "verilator", "icarus")


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


def check_samples_backends(samples, backends) -> None:
    """A check's record length (an integer >= 1) and backends (among :data:`BACKENDS`)."""
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1:
        raise ValueError(f"samples must be an integer >= 1, not {samples!r}")
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"backends must be among {BACKENDS}, not {unknown}")


def stall_pattern(n_cycles: int, seed: int, *, p_ready: float = 0.5,
                  burst: int = 4000) -> np.ndarray:
    """DSP ``ready`` per cycle: off/on bursts (mean ``burst`` cycles), on with ``p_ready``."""
    rng = np.random.default_rng(seed + 7919)
    on = np.repeat(rng.random(n_cycles // burst + 1) < p_ready, burst)[:n_cycles]
    return on & (rng.random(n_cycles) < 0.5)


def skip_reason(name: str, samples: int, *, pysim_max_samples: int = PYSIM_MAX_SAMPLES,
                icarus_max_samples: int = ICARUS_MAX_SAMPLES) -> str | None:
    """Why backend ``name`` does not run on a record of ``samples`` (None: it runs):
    ``pysim`` above ``pysim_max_samples``, ``icarus`` above ``icarus_max_samples`` or when
    Icarus/cocotb is not installed, ``verilator`` when it is not installed."""
    if name == "pysim" and samples > pysim_max_samples:
        return f"pysim runs only for samples <= {pysim_max_samples} (~3e3 cycles/s)"
    if name == "icarus":
        if samples > icarus_max_samples:
            return (f"icarus runs only for samples <= {icarus_max_samples} (~1e3 cycles/s "
                    f"under cocotb)")
        from ..backends.icarus import icarus_available, icarus_missing_message
        if not icarus_available():
            return icarus_missing_message()
    if name == "verilator":
        from ..backends.verilator_harness import verilator_available
        if not verilator_available():
            from ..backends.verilog import verilator_missing_message
            return verilator_missing_message()
    return None


def simulators_line(per: dict, n_cycles: int | None = None) -> str:
    """One line on the backends that ran (``per``: backend -> ``mismatches``, ``seconds``
    and optionally its own ``cycles``): ``model == pysim == verilator == icarus`` (``!=``
    before a backend that differs from the model), the cycles they ran (``n_cycles``, the
    same for all, or each one's ``cycles``) and each one's wall time, with its cycles per
    second."""
    chain = "model"
    for name, v in per.items():
        if name != "model":
            chain += f" {'==' if v['mismatches'] == 0 else '!='} {name}"
    times = []
    for name, v in per.items():
        cyc = v.get("cycles", n_cycles)
        t = f"{name} {v['seconds']:.3g} s"
        if cyc and v["seconds"] > 0:
            own = "" if n_cycles else f"{cyc:,} cycles, "
            t += f" ({own}{cyc / v['seconds']:,.0f} cycles/s)"
        times.append(t)
    over = f"{n_cycles:,} cycles" if n_cycles else (
        "the same stimulus" if all("cycles" not in v for v in per.values()) else
        "the same stimulus, each its own length")
    return f"{chain} over {over}: {', '.join(times)}"


def compare_backends(top: str, samples: int, backends, run, *, seed: int, stall: bool,
                     empty_hint: str, record_words: int = 1,
                     pysim_max_samples: int = PYSIM_MAX_SAMPLES,
                     icarus_max_samples: int = ICARUS_MAX_SAMPLES,
                     n_cycles: int | None = None) -> dict:
    """The comparison and verdict of a session-based check (a receiver's
    ``Receiver.equivalence``): ``run(backend) -> (words, cycles, overflow_count, seconds)``
    for the same stimulus on each backend; the model is the reference, every FIFO word, its
    cycle and the overflow counter are compared. ``run`` may return a fifth element, a dict
    of further outputs by name (a sequence of rows, e.g. the bus writes ``(cycle, address,
    value)``, or one value such as a digest), each compared with the model's row by row
    (:func:`count_differences`) and counted in the mismatches. A backend that cannot run is
    skipped with a note (:func:`skip_reason`). ``empty_hint`` ends the verdict when the model
    gave no word; ``n_cycles``, the cycles each backend ran, goes into ``simulators``.
    Returns the keys of :func:`cosim.tacan.equivalence.check_equivalence` (``peaks``: the
    model's records, ``markers``: 0, ``dropped``: the model's overflow count)."""
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"backends must be among {BACKENDS}, not {unknown}")
    ref_w, ref_c, ref_ovf, secs, ref_x = _outputs(run("model"))
    per = {"model": {"mismatches": 0, "words": int(len(ref_w)), "seconds": secs}}
    if ref_x:
        per["model"]["outputs"] = {k: {"n": _length(v), "mismatches": 0}
                                   for k, v in ref_x.items()}
    ran, skipped = ["model"], {}
    for name in [b for b in BACKENDS if b in backends and b != "model"]:
        why = skip_reason(name, samples, pysim_max_samples=pysim_max_samples,
                          icarus_max_samples=icarus_max_samples)
        if why is not None:
            skipped[name] = why
            continue
        w, c, ovf, secs, x = _outputs(run(name))
        n = min(len(w), len(ref_w))
        bad = int(np.count_nonzero(w[:n] != ref_w[:n]) + np.count_nonzero(c[:n] != ref_c[:n]))
        bad += abs(len(w) - len(ref_w)) + int(ovf != ref_ovf)
        per[name] = {"mismatches": bad, "words": int(len(w)), "seconds": secs}
        if ref_x:
            outs = {k: {"n": _length(x.get(k)), "mismatches": count_differences(x.get(k), v)}
                    for k, v in ref_x.items()}
            per[name]["outputs"] = outs
            per[name]["mismatches"] += sum(o["mismatches"] for o in outs.values())
        ran.append(name)
    compared = [f"{k} vs model: {v['words']} vs {per['model']['words']} FIFO words"
                + "".join(f", {o['n']} vs {per['model']['outputs'][key]['n']} {key}"
                          for key, o in v.get("outputs", {}).items())
                + f", {v['mismatches']} mismatches" for k, v in per.items() if k != "model"]
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
            "markers": 0, "dropped": int(ref_ovf), "per_backend": per,
            "n_cycles": None if n_cycles is None else int(n_cycles),
            "simulators": simulators_line(per, n_cycles)}


def count_differences(got, want) -> int:
    """Differences of an output from the model's (:func:`compare_backends`): rows of two
    sequences (lists or arrays, compared row by row, plus the difference of their lengths),
    or two single values (0 or 1). A missing output (``got`` None) differs in every row."""
    if want is None or isinstance(want, (str, bytes, int, float, np.generic)):
        return int(got != want)
    w = _rows(want)
    if got is None:
        return max(1, len(w))
    g = _rows(got)
    return sum(a != b for a, b in zip(g, w)) + abs(len(g) - len(w))


def _rows(v) -> list:
    """A sequence output as a list of rows, each row a tuple (an array's, a list's, a
    tuple's alike) or a single value."""
    v = v.tolist() if isinstance(v, np.ndarray) else list(v)
    return [tuple(r) if isinstance(r, (list, tuple)) else r for r in v]


def _length(v) -> int:
    """Rows of an output (1 for a single value, 0 for a missing one)."""
    if v is None:
        return 0
    return 1 if isinstance(v, (str, bytes, int, float, np.generic)) else len(v)


def _outputs(out) -> tuple:
    """``run``'s result as ``(words, cycles, overflow, seconds, further outputs)``."""
    if len(out) not in (4, 5):
        raise ValueError(f"an equivalence run returns (words, cycles, overflow, seconds[, "
                         f"outputs]), not {len(out)} values")
    return (*out[:4], dict(out[4]) if len(out) == 5 else {})
