"""The monopulse front end's stream case (:mod:`cosim.tools.top_cases`): the record of
``check-equivalence --top monopulse`` (:func:`cosim.monopulse.equivalence.stimulus`: random
ADC codes and replica bits, seeded writes of the channel coefficients and the steering words,
one every 500 cycles) under seeded stalls into a FIFO of one record and a marker, on the
front end's model session. Registered top: one record's block and 2,000 samples (84,372
cycles). Short: the 12-snapshot block of the equivalence check (:data:`cosim.monopulse.
equivalence.EQUIV_PARAMS`), 1,500 samples.
"""
from __future__ import annotations

from dataclasses import replace

__all__ = ["monopulse_case"]


def monopulse_case(make_top, seed: int, size: int | None, short: bool) -> dict:
    """The case of ``monopulse_frontend`` (module doc; the keys of
    :func:`cosim.tools.top_cases.top_case`)."""
    from hdl.model.bus import bus_writes
    from ..core.receivers import frontend_for
    from ..tools.equivalence import stall_pattern
    from ..tools.top_cases import FLUSH_CYCLES, elaborated, port_width, session_run
    from .equivalence import EQUIV_PARAMS, stimulus
    p = EQUIV_PARAMS if short else elaborated(make_top()).params
    fe = frontend_for(p)
    p = replace(p, fifo_depth=p.record_words + 2)
    n = int(size or (1500 if short else p.snapshots * p.snapshot_decimation + 2000))
    x, regs = stimulus(p, n, seed)
    n_cycles = n + p.latency + FLUSH_CYCLES
    ready = stall_pattern(n_cycles, seed, burst=max(n_cycles // 8, 1))
    writes = bus_writes(regs, data_width=port_width(elaborated(fe.component(p)), "reg_data"))
    words, cycles = session_run(fe, p, x, ready, n_cycles, writes)
    return dict(make=lambda: fe.component(p), in_words=x, out_ready=ready, n_cycles=n_cycles,
                words=words, cycles=cycles, writes=writes)
