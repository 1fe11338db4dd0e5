"""The two peak searches of the TACAN front end into its one FIFO: the cycle each peak is
written (:func:`fifo_write_cycles`, the HDL's ``TacanFrontEnd._merge``) and the FIFO output
predicted for a DSP ``ready`` pattern (:class:`FifoRun`). The merge rule and why one hold
register suffices: ``docs/explanation/tacan_frontend_design.md``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dsp.tacan.standard import SOURCE_PAIR


__all__ = ["FifoRun", "fifo_write_cycles"]


def fifo_write_cycles(emit_cycles, source=None, *, last_pulse: int = -1) -> np.ndarray:
    """The merge of the two searches into the one FIFO input
    (:class:`~hdl.tacan.frontend.TacanFrontEnd` with ``config.pair_peak``): the cycle each
    peak is written to the FIFO, from the cycle it leaves its search (``emit_cycles``) and
    its ``source``.

    The pulse search has priority: a pulse word is written in the cycle it is emitted; a pair
    word too, unless a pulse word is emitted in the same cycle, then it waits in a one-word
    hold register and is written the next cycle. Each search emits at most one word per
    envelope sample, i.e. at least ``decimation >= 2`` cycles apart, so that cycle has no
    pulse word and the register is free again before the next pair word: one register
    suffices and no word is lost or reordered within its search.

    ``source`` None (one search): the emit cycles. ``last_pulse``: the emit cycle of the
    last pulse word written before these (a caller that hands the FIFO the words of one
    stretch of cycles at a time, keeping the later ones).
    """
    c = np.asarray(emit_cycles, dtype=np.int64)
    if source is None:
        return c.copy()
    pair = np.asarray(source) == SOURCE_PAIR
    pulses = np.r_[c[~pair], np.int64(last_pulse)]
    w = c + (pair & np.isin(c, pulses))
    if np.unique(w).size != w.size:
        raise RuntimeError("two FIFO writes in one cycle: each search's words must be >= 2 "
                           "cycles apart (decimation >= 2, one word per envelope sample)")
    return w


@dataclass
class FifoRun:
    """FIFO output predicted for a ready pattern: packed words and their cycles, the
    ``overflow_count`` port per cycle, and which peaks were dropped."""

    words: np.ndarray
    cycles: np.ndarray
    overflow_count: np.ndarray
    dropped: np.ndarray
