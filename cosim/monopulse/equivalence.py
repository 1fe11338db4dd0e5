"""Equivalence of the monopulse front end's bit-exact model, Amaranth simulation and its Verilog
under Verilator and Icarus Verilog (``python -m cosim check-equivalence --top monopulse``): the
same seeded record through the four sessions (:func:`cosim.backends.factory.open_frontend`), every FIFO word and the cycle it
leaves on compared with the model's.

The record: full-scale random ADC codes on the 4 channels and random replica bits, with
seeded register writes (channel coefficients, steering u0/v0) spread over it; the reduced
block (:data:`EQUIV_PARAMS`: 12 snapshots of 4 samples) gives one measurement every 48
samples so a 20,000-sample record holds about 400. ``stall=True``: the DSP ``ready`` follows
:func:`cosim.tools.equivalence.stall_pattern` and the FIFO holds one record and a marker
(``record_words + 2`` words: records dropped, the overflow counter compared too)."""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from hdl.monopulse.params import (REG_COEF, REG_U0, REG_V0, MonopulseFrontendParams, coef_word,
                                  dc_word, pack_input)

from ..core.session import write_register
from ..tools.equivalence import (BACKENDS, PYSIM_MAX_SAMPLES, check_samples_backends,
                                 compare_backends, stall_pattern)

__all__ = ["check_monopulse_equivalence", "stimulus", "EQUIV_PARAMS"]

#: Reduced block for the check (4 samples a snapshot, 12 snapshots a block).
EQUIV_PARAMS = MonopulseFrontendParams(snapshots=12, cic_rate=4, snapshot_decimation=4,
                                       cordic_iterations=12, angle_bits=16, fifo_depth=16)
#: Mean cycles between two register writes of the record.
WRITE_SPACING = 500


def stimulus(p, samples, seed):
    """``(words, writes)``: the check's packed input words (4 ADC channels, replica bit) and
    its register writes ``(cycle, register address, value)``, seeded."""
    rng = np.random.default_rng(seed)
    lo = -(1 << (p.adc_bits - 1))
    x = rng.integers(lo, -lo, (samples, 4))
    chips = rng.integers(0, 2, samples)
    n_w = max(1, samples // WRITE_SPACING)
    cyc = np.sort(rng.choice(np.arange(1, samples + 1), min(n_w, samples), replace=False))
    writes = []
    for c in cyc:
        reg = int(rng.choice([REG_COEF, REG_COEF + 1, REG_COEF + 2, REG_COEF + 3, REG_U0, REG_V0]))
        v = (dc_word(float(rng.uniform(-0.9, 0.9)), p) if reg in (REG_U0, REG_V0) else
             coef_word(complex(*rng.uniform(-1, 1, 2)), p))
        writes.append((int(c), reg, v))
    return pack_input(x, chips, p), writes


def check_monopulse_equivalence(samples: int = 20_000, *, backends=BACKENDS, seed: int = 1,
                                stall: bool = False, params=None,
                                pysim_max_samples: int = PYSIM_MAX_SAMPLES,
                                progress: bool = False) -> dict:
    """The keys of :func:`cosim.tacan.equivalence.check_equivalence` (``peaks``: measurement records
    of the model; ``markers``: 0, the monopulse FIFO drops whole records and counts them in
    ``overflow_count``, which is compared; ``dropped``: the model's overflow count)."""
    from ..backends.factory import open_frontend
    check_samples_backends(samples, backends)
    if params is None:
        params = (replace(EQUIV_PARAMS, fifo_depth=EQUIV_PARAMS.record_words + 2) if stall
                  else EQUIV_PARAMS)
    words, writes = stimulus(params, int(samples), seed)
    n_cycles = int(samples) + params.latency + 400
    ready = stall_pattern(n_cycles, seed) if stall else np.ones(n_cycles, bool)

    def run(backend):
        t = time.perf_counter()
        with open_frontend(backend, params) as fe:
            for c, reg, v in writes:
                write_register(fe, reg, v, c)
            r = fe.step(words, ready, n_cycles=n_cycles)
            ovf = int(fe.read("overflow_count"))
        return np.asarray(r.words, np.int64), np.asarray(r.cycles), ovf, time.perf_counter() - t

    return compare_backends("monopulse", int(samples), backends, run, seed=seed, stall=stall,
                            record_words=params.record_words,
                            pysim_max_samples=pysim_max_samples, n_cycles=n_cycles,
                            empty_hint=f"a record every "
                                       f"{params.snapshots * params.snapshot_decimation} "
                                       f"samples at most")
