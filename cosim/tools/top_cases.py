"""The receiver tops' stream cases: seeded stimulus with register writes mid-run and the
bit-exact model's answer (:func:`cosim.tools.stream_cases.stream_case` of a top).

Each receiver registers a case per exported top (:attr:`cosim.core.receivers.Receiver.
stream_cases`; a test fails if an exported top has none): the stimulus of the top's
equivalence check with the register writes its closed loop makes, set at seeded cycles
through the whole record, seeded stalls, run from reset on the bit-exact model --
:mod:`cosim.tacan.stream_case` (noise bursts, NCO retuning), :mod:`cosim.gnss.stream_case`
(the GPS record, hand-overs and every register of every channel rewritten),
:mod:`cosim.monopulse.stream_case` (coefficients and steering). This module holds what they
share and :func:`top_case`, which dispatches to them.

Two sizes. ``short=False`` (``python -m cosim verilog --cocotb``): the registered top with
its own parameters (the exported Verilog), a record long enough for its closed-loop
behaviour. ``short=True`` (the Icarus check in ``make test``): the same top's HDL at reduced
parameters on a record of a few thousand cycles, and a FIFO that records overflow, so records
are dropped and counted.

A case is a dict: ``make`` (the component), ``in_words``, ``out_ready``, ``n_cycles``, the
model's ``words`` and ``cycles``, ``inputs`` (constant input ports) and ``writes``
(port-level ``(cycle, port, value)``).
"""
from __future__ import annotations

import numpy as np

__all__ = ["top_case", "top_cases", "FLUSH_CYCLES", "elaborated", "port_width",
           "session_run", "one_write_a_cycle"]

#: Cycles run after the last ADC sample (the last record leaves the pipeline and the FIFO).
FLUSH_CYCLES = 400


def elaborated(comp):
    """``comp``, elaborated (only asked for its parameters and ports here)."""
    from amaranth.hdl import Fragment
    Fragment.get(comp, None)
    return comp


def port_width(comp, port: str) -> int:
    """The width of ``comp``'s port of Verilog name ``port`` (e.g. ``i__payload``)."""
    return next(len(v) for path, _, v in comp.signature.flatten(comp)
                if "__".join(map(str, path)) == port)


def session_run(fe, params, x, ready, n_cycles, writes):
    """Front end ``fe``'s bit-exact model session (:class:`cosim.core.receivers.Frontend`)
    from reset: port writes ``(cycle, port, value)``, then one step of ``n_cycles``; the
    output words and their cycles."""
    with fe.model(params) as s:
        for c, port, v in writes:
            s.write(port, int(v), int(c))
        r = s.step(x, ready, n_cycles=n_cycles)
    return np.asarray(r.words), np.asarray(r.cycles, np.int64)


def one_write_a_cycle(writes):
    """Register writes ``(cycle, address, value)``, in order, one bus write a cycle: a write
    on a busy cycle goes out on the next free one."""
    out, last = [], -1
    for c, a, v in sorted(writes, key=lambda w: w[0]):
        last = max(int(c), last + 1)
        out.append((last, int(a), int(v)))
    return out


def top_cases() -> dict:
    """Top name -> its case, over every registered receiver."""
    from ..core.receivers import receivers
    out = {}
    for r in receivers():
        out.update(r.stream_cases)
    return out


def top_case(name: str, make_top, seed: int, size: int | None, short: bool) -> dict:
    """The case of top ``name`` (module doc); ``make_top()`` builds the registered top,
    ``size``: ADC samples (None: the case's own)."""
    return top_cases()[name](make_top, int(seed), size, bool(short))
