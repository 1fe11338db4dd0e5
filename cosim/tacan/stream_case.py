"""The TACAN front end's stream case (:mod:`cosim.tools.top_cases`): seeded noise bursts over
a noise floor (:func:`bursts`: a peak report every few hundred samples after the noise floor's
first block; the equivalence check's TACAN record has a pulse pair every ~5,600 samples) with
writes of the NCO word ``freq`` (the IF retuned by up to +-40 kHz and back) under seeded
stalls (:func:`cosim.tools.equivalence.stall_pattern`), on the front end's model session.
Registered top: 10,000 samples. Short: noise-floor blocks of 256 envelope samples
(:data:`TACAN_SHORT_BLOCK_LOG2`: the first report after ~1,300 cycles, not ~4,400) and a
FIFO of 4 words, 3,000 samples.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

__all__ = ["tacan_case", "bursts", "TACAN_SHORT_BLOCK_LOG2"]

#: ``block_log2`` of the TACAN short case's peak searches (noise-floor blocks of 256 envelope
#: samples; the registered front end's 1,024 hold its first report back ~4,300 cycles).
TACAN_SHORT_BLOCK_LOG2 = 8


def bursts(rng, width: int, n: int) -> np.ndarray:
    """Signed ``width``-bit ADC codes: a noise floor (2 % of full scale rms) with bursts of
    strong noise (30 % rms, clipped at full scale), 70 samples long, 100..400 samples apart:
    broadband energy in any pass band, switched on and off (a peak report every few hundred
    samples, where the TACAN record has a pulse pair every ~5,600)."""
    x = rng.normal(0.0, 0.02, n)
    t = int(rng.integers(0, 100))
    while t < n:
        x[t:t + 70] += rng.normal(0.0, 0.3, len(x[t:t + 70]))
        t += int(rng.integers(100, 400))
    full = 1 << (width - 1)
    return np.clip(np.round(x * full), -full, full - 1).astype(np.int64)


def tacan_case(make_top, seed: int, size: int | None, short: bool) -> dict:
    """The case of ``tacan_frontend`` (module doc; the keys of
    :func:`cosim.tools.top_cases.top_case`)."""
    from hdl.model.nco import nco_freq_word
    from ..core.receivers import frontend_for
    from ..tools.equivalence import stall_pattern
    from ..tools.top_cases import FLUSH_CYCLES, elaborated, port_width, session_run
    comp = elaborated(make_top())
    p = comp.params
    fe = frontend_for(p)
    if short:           # noise-floor blocks of 256 samples (1,024 cycles), not 4,096 cycles
        cfg = p.config
        blocks = {k: replace(getattr(cfg, k), block_log2=TACAN_SHORT_BLOCK_LOG2)
                  for k in ("peak", "pair_peak") if getattr(cfg, k) is not None}
        p = replace(p, fifo_depth=4, config=replace(cfg, **blocks))
    n = int(size or (3000 if short else 10_000))
    rng = np.random.default_rng([seed, 1])
    x = bursts(rng, port_width(comp, "i__payload"), n)
    n_cycles = n + FLUSH_CYCLES
    ready = stall_pattern(n_cycles, seed, burst=max(n_cycles // 8, 1))
    # the NCO retuned by up to +-40 kHz at a seeded cycle in each quarter of the record, the
    # last write back on the IF
    cyc = [max(1, k * n // 4 + int(rng.integers(0, max(n // 4, 1)))) for k in range(4)]
    writes = [(int(c), "freq", nco_freq_word(p.config.if_hz + float(rng.uniform(-4e4, 4e4)),
                                             f_clk_hz=p.config.fs_hz,
                                             phase_bits=p.nco_phase_bits).word)
              for c in cyc[:-1]] + [(int(cyc[-1]), "freq", p.nco_freq_word)]
    inputs = fe.reset_inputs(p)
    words, cycles = session_run(fe, p, x, ready, n_cycles, writes)
    return dict(make=lambda: fe.component(p), in_words=x, out_ready=ready, n_cycles=n_cycles,
                words=words, cycles=cycles, inputs=inputs, writes=writes)
