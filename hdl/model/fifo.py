"""FIFO towards the DSP: parameters, word format and a cycle-level model.

Word format (``word_width = width + 2`` bits, LSB first)::

    bits [0, width)          payload
    bits [width, width + 2)  tag: 0 = data word (payload = the input word)
                                   2 = marker: payload = words dropped in the gap just
                                       before it (saturates at 2**width - 1)
                                   1, 3 reserved

Nothing is lost silently: a word that arrives while the queue is full is dropped, counted in
``overflow_count`` (saturating, ``count_width`` bits) and in the pending gap count; the gap
is reported by a marker word written before the next data word. Drop/marker policy (the HDL
and :func:`fifo_model` implement exactly this, per write-domain cycle, ``w_rdy`` being the
queue's "has space" this cycle):

1. a *hold* register (one word) has priority: if ``w_rdy`` it is written; an input word that
   arrives in the same cycle takes its place if no drops are pending, else it is dropped;
2. else, if drops are pending and ``w_rdy``: the marker is written (pending cleared) and an
   input word arriving in the same cycle goes to the hold register (written next);
3. else an input word is written if ``w_rdy``;
4. otherwise an input word is dropped (pending += 1, overflow_count += 1, both saturating).

The queue is ``amaranth.lib.fifo.SyncFIFOBuffered`` (or ``AsyncFIFOBuffered``); the model
reproduces SyncFIFOBuffered cycle by cycle (``w_rdy``, the output register, ``r_en``). It
is a Python loop over cycles, skipping idle stretches: which word gets dropped depends on the
queue level, which depends on every earlier read and write, so there is no practical
vectorised form. The input is the peak stream (a few thousand words/s), so the loop only
runs per event in practice.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from dsp.fixed import check_width

TAG_DATA = 0
TAG_MARKER = 2


@dataclass(frozen=True)
class FifoParams:
    """Parameters of :class:`hdl.fifo.DspFifo`.

    Parameters
    ----------
    width : int
        Payload bits of one input word (1..61, so a tagged word fits in int64).
    depth : int
        Queue depth in words (>= 1; >= 3 for the asynchronous queue, which rounds it up to
        ``2**k + 1``, see :attr:`actual_depth`).
    asynchronous : bool
        Clock-domain crossing (``AsyncFIFOBuffered``) from ``w_domain`` to ``r_domain``.
    count_width : int
        Width of the saturating ``overflow_count`` (1..32 bits).
    w_domain, r_domain : str
        Clock domains of the write (FPGA) and read (DSP) sides; asynchronous only.
    """

    width: int = 51
    depth: int = 512
    asynchronous: bool = False
    count_width: int = 16
    w_domain: str = "sync"
    r_domain: str = "dsp"

    def __post_init__(self):
        check_width("FIFO width", self.width, minimum=1, maximum=61)
        if isinstance(self.depth, bool) or not isinstance(self.depth, (int, np.integer)) \
                or self.depth < 1:
            raise ValueError(f"FIFO depth must be >= 1, not {self.depth!r}")
        if not isinstance(self.asynchronous, bool):
            raise ValueError(f"FIFO asynchronous must be a bool, not {self.asynchronous!r}")
        if self.asynchronous and self.depth < 3:
            raise ValueError(f"asynchronous FIFO depth must be >= 3, not {self.depth}")
        check_width("FIFO count_width", self.count_width, minimum=1, maximum=32)
        if self.asynchronous and self.w_domain == self.r_domain:
            raise ValueError(f"asynchronous FIFO needs two different domains, not "
                             f"{self.w_domain!r} twice")

    @property
    def word_width(self) -> int:
        return self.width + 2

    @property
    def actual_depth(self) -> int:
        """Words the queue holds (AsyncFIFOBuffered rounds up to ``2**k + 1``)."""
        if not self.asynchronous:
            return self.depth
        return (1 << (self.depth - 2).bit_length()) + 1

    @property
    def marker_max(self) -> int:
        return (1 << self.width) - 1

    @property
    def count_max(self) -> int:
        return (1 << self.count_width) - 1

    @property
    def out_layout(self) -> list[tuple[str, int, bool]]:
        """Output word, LSB first (for ``cosim.pysim.unpack_fields``)."""
        return [("payload", self.width, False), ("tag", 2, False)]

    @property
    def count_latency(self) -> str:
        """When ``overflow_count`` shows a drop."""
        if self.asynchronous:
            return "<= 1 write-clock + 3 read-clock cycles (Gray code, 2-flop synchroniser)"
        return "the cycle after the drop"


def pack_word(payload, tag, params: FifoParams) -> np.ndarray:
    return (np.asarray(payload, dtype=np.int64) & np.int64(params.marker_max)) | \
        (np.asarray(tag, dtype=np.int64) << np.int64(params.width))


def unpack_word(words, params: FifoParams) -> tuple[np.ndarray, np.ndarray]:
    """``(payload, tag)`` of packed output words."""
    w = np.asarray(words, dtype=np.int64)
    return w & np.int64(params.marker_max), (w >> np.int64(params.width)) & np.int64(3)


def decode_stream(words, params: FifoParams) -> tuple[np.ndarray, int]:
    """DSP side: the data payloads in order and the total words reported dropped."""
    payload, tag = unpack_word(words, params)
    return payload[tag == TAG_DATA], int(payload[tag == TAG_MARKER].sum())


@dataclass
class FifoResult:
    """What :func:`fifo_model` predicts.

    words : packed output words (payload | tag << width), in order
    cycles : read-domain cycle of each output transfer
    overflow_count : per cycle, the value of the ``overflow_count`` port during that cycle
    dropped : per input word, True if it was dropped
    """

    words: np.ndarray
    cycles: np.ndarray
    overflow_count: np.ndarray
    dropped: np.ndarray


def fifo_model(in_words, in_valid, out_ready, params: FifoParams) -> FifoResult:
    """Cycle-level model of the synchronous :class:`hdl.fifo.DspFifo`.

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
    return FifoResult(words=np.array(out_words, dtype=np.int64),
                      cycles=np.array(out_cycles, dtype=np.int64),
                      overflow_count=ovf_trace, dropped=dropped)
