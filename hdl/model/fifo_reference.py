"""The original pure-Python per-cycle loop of the DSP FIFO, kept as the reference the tests
compare the compiled model (:func:`hdl.model.fifo.fifo_model`) with (slow; tests only)."""
from __future__ import annotations

from collections import deque

import numpy as np

from .fifo import TAG_MARKER, FifoParams, FifoResult, with_parity

__all__ = ["fifo_model_reference"]


def fifo_model_reference(in_words, in_valid, out_ready, params: FifoParams) -> FifoResult:
    """Reference: the original pure-Python per-cycle loop (slow; for the tests only).

    Same result as :func:`fifo_model` from reset (``state`` and ``max_level`` left at their
    defaults).

    Parameters
    ----------
    in_words : array of int
        Input payloads, taken in order on the cycles where ``in_valid`` is set (cycles
        after the last word are idle).
    in_valid, out_ready : array of bool
        Per cycle; their common length is the number of cycles simulated.
    """
    p = params
    if p.asynchronous:
        raise ValueError("fifo_model covers the synchronous FIFO only (asynchronous=False)")
    if p.record_words != 1:
        raise ValueError("the reference loop covers single words only (record_words=1)")
    in_words = np.asarray(in_words, dtype=np.int64)
    in_valid = np.asarray(in_valid, dtype=bool)
    out_ready = np.asarray(out_ready, dtype=bool)
    n_cycles = in_valid.size
    if out_ready.size != n_cycles:
        raise ValueError(f"out_ready must have one entry per cycle ({n_cycles}), "
                         f"not {out_ready.size}")
    valid_cycles = np.flatnonzero(in_valid)[:in_words.size]
    in_v = np.zeros(n_cycles, dtype=bool)
    in_v[valid_cycles] = True
    wmask = p.marker_max
    marker_tag = TAG_MARKER << p.width
    D = p.depth
    inner_depth = D - 1

    out_words: list[int] = []
    out_cycles: list[int] = []
    ovf_trace = np.zeros(n_cycles, dtype=np.int64)
    dropped = np.zeros(in_words.size, dtype=bool)
    inner: deque = deque()
    out_full = False  # SyncFIFOBuffered.r_rdy
    out_reg = 0
    hold_v, hold_d = False, 0
    pending, ovf = 0, 0
    k = 0  # next input word
    words_list = in_words.tolist()
    ready_list = out_ready.tolist()
    inv_list = in_v.tolist()
    c = 0
    while c < n_cycles:
        if not (inv_list[c] or hold_v or pending or out_full or inner):
            # Idle and empty: nothing changes until the next input word.
            nxt = np.searchsorted(valid_cycles, c)
            c_next = int(valid_cycles[nxt]) if nxt < valid_cycles.size else n_cycles
            ovf_trace[c:c_next] = ovf
            c = c_next
            continue
        ovf_trace[c] = ovf
        rdy = ready_list[c]
        if out_full and rdy:
            out_words.append(out_reg)
            out_cycles.append(c)
        w_rdy = (len(inner) != inner_depth) if D > 1 else not out_full
        iv = inv_list[c]
        if iv:
            word = words_list[k] & wmask
        write = None
        drop = False
        if hold_v:
            if w_rdy:
                write = hold_d
                if iv:
                    if pending == 0:
                        hold_d = word
                    else:
                        drop = True
                        hold_v = False
                else:
                    hold_v = False
            elif iv:
                drop = True
        elif pending:
            if w_rdy:
                write = marker_tag | pending
                pending = 0
                if iv:
                    hold_v, hold_d = True, word
            elif iv:
                drop = True
        elif iv:
            if w_rdy:
                write = word
            else:
                drop = True
        if drop:
            dropped[k] = True
            pending = min(pending + 1, wmask)
            ovf = min(ovf + 1, p.count_max)
        if iv:
            k += 1
        # Queue update (SyncFIFOBuffered semantics).
        if D > 1:
            if inner and (not out_full or rdy):
                out_reg = inner.popleft()
                out_full = True
            elif rdy:
                out_full = False
            if write is not None:
                inner.append(write)
        else:
            if write is not None:
                out_reg, out_full = write, True
            elif out_full and rdy:
                out_full = False
        c += 1
    return FifoResult(words=with_parity(np.array(out_words, dtype=np.int64), params),
                      cycles=np.array(out_cycles, dtype=np.int64),
                      overflow_count=ovf_trace, dropped=dropped)
