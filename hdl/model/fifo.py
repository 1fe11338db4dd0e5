"""FIFO towards the DSP: parameters, word format and a cycle-level model.

Word format (``word_width = width + 2`` bits, ``+ 1`` with ``parity``, LSB first)::

    bits [0, width)          payload
    bits [width, width + 2)  tag: 0 = data word (payload = the input word)
                                   2 = marker: payload = words dropped in the gap just
                                       before it (saturates at 2**width - 1)
                                   1, 3 reserved
    bit  width + 2           parity (optional): even parity over the whole word, computed
                             where the word is written, so it covers the queue memory and
                             the link to the DSP

Records (``record_words = n > 1``): the input port carries a whole record of ``n`` payloads
(``n * width`` bits, word 0 in the low bits) in one cycle; it leaves as ``n`` consecutive
words, the first tagged 1 (start of record), the others 0; a marker's payload then counts
*records* dropped. A record is queued whole or dropped whole. With ``n == 1`` (the default)
every word is a record, tagged 0, and the format and the policy below are exactly those of
single words.

Nothing is lost silently: a record that arrives while the queue has no room for it is
dropped, counted in ``overflow_count`` (saturating, ``count_width`` bits) and in the pending
gap count; the gap is reported by a marker word written before the next record. Drop/marker
policy (the HDL and :func:`fifo_model` implement exactly this, per write-domain cycle,
``free`` being the words the queue memory can take this cycle -- ``w_rdy`` is ``free > 0``
-- and a record *fits* when ``free >= n``):

1. the *hold* register (one record, written a word per cycle) has priority: if ``w_rdy``
   its next word is written; an input record that arrives in the same cycle takes its
   place if this write empties it, no drops are pending and it *fits behind* the word
   written now, else it is dropped;
2. else, if drops are pending and ``w_rdy``: the marker is written (pending cleared) and an
   input record arriving in the same cycle goes to the hold register if it fits behind the
   marker (else it is dropped and pending becomes 1);
3. else an input record is taken if it fits: its first word is written, the others go to
   the hold register;
4. otherwise an input record is dropped (pending += 1, overflow_count += 1, both
   saturating).

With ``n == 1``, "fits" and "fits behind" are ``w_rdy`` and the hold register holds one word
(it may wait for room). With ``n > 1`` a record fits when ``free >= n`` and fits behind a
word written in the same cycle when ``free >= n + 1``, so once taken it is written whole, a
word per cycle, without waiting (the HDL's hold register then never looks at ``w_rdy``: a
timing decision). The queue must therefore hold a record and a marker: ``depth >= n + 2``.

The queue is ``amaranth.lib.fifo.SyncFIFOBuffered`` (or ``AsyncFIFOBuffered``); the model
reproduces SyncFIFOBuffered cycle by cycle (``w_rdy``, the output register, ``r_en``). Which
word gets dropped depends on the queue level, which depends on every earlier read and write,
so there is no vectorised form. :func:`fifo_model` is a compiled (numba) per-cycle state
machine that jumps over the cycles where nothing can change: no input word this cycle, and
either everything is empty, or the output register is full while ``ready`` is low and the
front end has nothing it could write (no hold/pending, or the memory full). Its cost is per
event (input word, ``ready`` cycle with a word waiting), not per clock cycle, so a second of
signal (20M cycles, ~15k peak words) takes milliseconds.

The ``ready`` pattern is a per-cycle bool array or a :class:`ReadySchedule` (periodic
service windows, e.g. a DSP's timer interrupt: see :mod:`cosim.link`), and
:func:`fifo_model_events` takes the input as write cycles, so long runs need no per-cycle
array at all. Both take and return a :class:`FifoState`, so a run can be split into chunks
with the same bits. The compiled kernel is in :mod:`hdl.model.fifo_kernel`;
:func:`hdl.model.fifo_reference.fifo_model_reference` is the original pure-Python loop, kept
as the reference the tests compare the compiled model with.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dsp.fixed import check_int as _check_int, check_width, parity_bit

from .fifo_kernel import (SV_CNT, SV_HEAD, SV_HOLD_V, SV_MAXLVL, SV_OUT_FULL, SV_OUT_REG, SV_OVF,
                          SV_PENDING, run_fifo_kernel)

TAG_DATA = 0
TAG_START = 1     # first word of a record (record_words > 1 only)
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
    parity : bool
        Append an even-parity bit to every word (width <= 60, so the word fits in int64):
        the DSP detects any odd number of flipped bits in the memory or on the link.
    record_words : int
        Words per record (1..64; default 1, single words). With ``n > 1`` the input port is
        ``n * width`` bits wide, a record leaves as ``n`` words (the first tagged
        :data:`TAG_START`), is dropped whole, and markers count records. Synchronous FIFO
        only, ``depth >= n + 2`` (a record and a marker).
    """

    width: int = 51
    depth: int = 512
    asynchronous: bool = False
    count_width: int = 16
    w_domain: str = "sync"
    r_domain: str = "dsp"
    parity: bool = False
    record_words: int = 1

    def __post_init__(self):
        if not isinstance(self.parity, bool):
            raise ValueError(f"FIFO parity must be a bool, not {self.parity!r}")
        check_width("FIFO width", self.width, minimum=1, maximum=60 if self.parity else 61)
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
        check_width("FIFO record_words", self.record_words, minimum=1, maximum=64)
        if self.record_words > 1:
            if self.asynchronous:
                raise ValueError("FIFO records (record_words > 1) need the synchronous FIFO "
                                 "(asynchronous=False)")
            if self.depth < self.record_words + 2:
                raise ValueError(f"FIFO depth must be at least record_words + 2 "
                                 f"({self.record_words + 2}: a record and a gap marker), "
                                 f"not {self.depth}")

    @property
    def in_width(self) -> int:
        """Bits of the input port: one record, ``record_words * width``."""
        return self.record_words * self.width

    @property
    def word_width(self) -> int:
        return self.width + 2 + int(self.parity)

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
        return [("payload", self.width, False), ("tag", 2, False)] + \
            ([("parity", 1, False)] if self.parity else [])

    @property
    def count_latency(self) -> str:
        """When ``overflow_count`` shows a drop."""
        if self.asynchronous:
            return "<= 1 write-clock + 3 read-clock cycles (Gray code, 2-flop synchroniser)"
        return "the cycle after the drop"


def with_parity(words, params: FifoParams) -> np.ndarray:
    """Output words: the stored ``payload | tag`` plus the parity bit when enabled."""
    w = np.asarray(words, dtype=np.int64)
    if not params.parity:
        return w
    return w | (parity_bit(w) << np.int64(params.width + 2))


def pack_word(payload, tag, params: FifoParams) -> np.ndarray:
    return with_parity((np.asarray(payload, dtype=np.int64) & np.int64(params.marker_max)) |
                       (np.asarray(tag, dtype=np.int64) << np.int64(params.width)), params)


def unpack_word(words, params: FifoParams) -> tuple[np.ndarray, np.ndarray]:
    """``(payload, tag)`` of packed output words."""
    w = np.asarray(words, dtype=np.int64)
    return w & np.int64(params.marker_max), (w >> np.int64(params.width)) & np.int64(3)


def pack_records(records, params: FifoParams) -> np.ndarray:
    """Records ``(n_records, record_words)`` of payloads -> values of the wide input port
    (word 0 in the low bits; object array of Python ints when wider than 63 bits)."""
    r = np.asarray(records, dtype=np.int64)
    n = params.record_words
    if r.ndim == 1 and n == 1:
        r = r[:, None]
    if r.ndim != 2 or r.shape[1] != n:
        raise ValueError(f"records must have shape (n_records, {n}), not {r.shape}")
    r = r & np.int64(params.marker_max)
    if params.in_width <= 63:
        out = np.zeros(r.shape[0], np.int64)
        for j in range(n):
            out |= r[:, j] << np.int64(j * params.width)
        return out
    out = np.zeros(r.shape[0], dtype=object)
    for j in range(n):
        out += np.array([int(v) << (j * params.width) for v in r[:, j]], dtype=object)
    return out


def unpack_records(values, params: FifoParams) -> np.ndarray:
    """Inverse of :func:`pack_records`: port values -> ``(n_records, record_words)``."""
    n, w = params.record_words, params.width
    mask = (1 << w) - 1
    vals = [int(v) for v in np.asarray(values).ravel()]
    return np.array([[(v >> (j * w)) & mask for j in range(n)] for v in vals],
                    dtype=np.int64).reshape(len(vals), n)


def decode_stream(words, params: FifoParams) -> tuple[np.ndarray, int]:
    """DSP side: the data payloads in order and the total words reported dropped."""
    payload, tag = unpack_word(words, params)
    return payload[tag == TAG_DATA], int(payload[tag == TAG_MARKER].sum())


@dataclass(frozen=True)
class ReadySchedule:
    """Periodic ``ready`` pattern: windows of ``count`` pulses, ``stride`` cycles apart.

    ``ready`` is high at the cycles ``offset + k * period + j * stride`` for every ``k >= 0``
    and ``0 <= j < count``, low elsewhere (in particular before ``offset``). Cycles are
    counted from reset, as :func:`cosim.pysim.run_stream` counts them.

    Parameters
    ----------
    period : int
        Cycles between window starts (>= 1).
    offset : int
        Cycle of the first window start (>= 0).
    count : int
        ``ready`` pulses per window (>= 1).
    stride : int
        Cycles between the pulses of a window (>= 1); a window spans
        ``(count - 1) * stride + 1 <= period`` cycles (windows must not overlap).

    Examples
    --------
    ``ReadySchedule(period=1)`` is always ready; ``ReadySchedule(period=100, offset=10,
    count=3, stride=2)`` is ready at 10, 12, 14, 110, 112, 114, ...
    """

    period: int
    offset: int = 0
    count: int = 1
    stride: int = 1

    def __post_init__(self):
        _check_int("ReadySchedule period", self.period, 1)
        _check_int("ReadySchedule offset", self.offset, 0)
        _check_int("ReadySchedule count", self.count, 1)
        _check_int("ReadySchedule stride", self.stride, 1)
        if self.span > self.period:
            raise ValueError(f"ReadySchedule window ((count - 1) * stride + 1 = {self.span} "
                             f"cycles) must fit in the period ({self.period})")

    @property
    def span(self) -> int:
        """Cycles from the first to the last pulse of a window, inclusive."""
        return (self.count - 1) * self.stride + 1

    @property
    def duty(self) -> float:
        """Fraction of cycles with ``ready`` high (``count / period``)."""
        return self.count / self.period

    def mask(self, n_cycles: int, start: int = 0) -> np.ndarray:
        """``ready`` for the cycles ``start .. start + n_cycles - 1`` (bool array)."""
        n_cycles = _check_int("n_cycles", n_cycles, 0)
        start = _check_int("start", start, 0)
        q = np.arange(start, start + n_cycles, dtype=np.int64) - self.offset
        r = q % self.period
        return (q >= 0) & (r < self.span) & (r % self.stride == 0)

    def ready_cycles(self, start: int, stop: int) -> np.ndarray:
        """The cycles in ``[start, stop)`` where ``ready`` is high (int64, increasing)."""
        k0 = max(0, (start - self.offset) // self.period)
        k1 = max(0, -(-(stop - self.offset) // self.period))
        c = (self.offset + np.arange(k0, k1, dtype=np.int64)[:, None] * self.period
             + np.arange(self.count, dtype=np.int64)[None, :] * self.stride).ravel()
        return c[(c >= start) & (c < stop)]


@dataclass
class FifoState:
    """Everything the synchronous FIFO holds between two chunks of a run.

    Attributes
    ----------
    cycle : int
        Next cycle to simulate (cycles are counted from reset).
    queue : ndarray of int64
        Packed words in the FIFO memory, oldest first (at most ``depth - 1``; empty for
        ``depth == 1``).
    out_full, out_reg : bool, int
        SyncFIFOBuffered's output register (``o.valid`` and the word offered).
    hold_valid, hold_data : bool, int
        The hold register (a data word waiting behind a marker); single words
        (``record_words == 1``).
    hold_left, hold_record : int, tuple of int
        Records (``record_words > 1``): words of the hold register still to write and the
        record it holds (``hold_valid`` is ``hold_left > 0``).
    pending : int
        Drops not yet reported by a marker (saturating at ``marker_max``).
    overflow : int
        The ``overflow_count`` port (saturating at ``count_max``).
    max_level : int
        Highest occupancy seen so far (memory + output register, sampled at the end of
        each cycle).
    """

    cycle: int = 0
    queue: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    out_full: bool = False
    out_reg: int = 0
    hold_valid: bool = False
    hold_data: int = 0
    hold_left: int = 0
    hold_record: tuple = ()
    pending: int = 0
    overflow: int = 0
    max_level: int = 0

    @property
    def level(self) -> int:
        """Words in the queue (memory + output register), hold register not included."""
        return len(self.queue) + int(self.out_full)


@dataclass
class FifoResult:
    """What :func:`fifo_model` predicts.

    Attributes
    ----------
    words : ndarray of int64
        Packed output words (``payload | tag << width``), in order.
    cycles : ndarray of int64
        Read-domain cycle (from reset) of each output transfer.
    overflow_count : ndarray of int64 or None
        Per cycle of this run, the value of the ``overflow_count`` port during that cycle
        (``None`` when not asked for: ``trace=False``).
    dropped : ndarray of bool
        Per input word (record), True if it was dropped.
    state : FifoState or None
        State after the last cycle (pass it to the next chunk).
    max_level : int
        Highest queue occupancy (memory + output register) since reset.
    """

    words: np.ndarray
    cycles: np.ndarray
    overflow_count: np.ndarray | None
    dropped: np.ndarray
    state: FifoState | None = None
    max_level: int = 0


def _check_sync(p: FifoParams):
    if p.asynchronous:
        raise ValueError("fifo_model covers the synchronous FIFO only (asynchronous=False)")


def _run(write_cycles, in_words, start, n_cycles, out_ready, p: FifoParams,
         st: FifoState, trace: bool, n_words_total: int) -> FifoResult:
    """Validated inputs -> compiled kernel -> result (``write_cycles`` absolute, int64)."""
    D = p.depth
    if len(st.queue) > max(D - 1, 0):
        raise ValueError(f"state queue holds {len(st.queue)} words; depth {D} holds at most "
                         f"{max(D - 1, 0)} in memory")
    if isinstance(out_ready, ReadySchedule):
        rmode, rmask = 1, np.zeros(1, dtype=np.bool_)
        sch = out_ready
    else:
        rmode = 0
        rmask = np.ascontiguousarray(out_ready, dtype=np.bool_)
        sch = ReadySchedule(period=1)
    ring = np.zeros(max(D - 1, 1), dtype=np.int64)
    ring[:len(st.queue)] = st.queue
    n = p.record_words
    hold = np.zeros(n, dtype=np.int64)
    if n == 1:
        left = int(st.hold_valid)
        hold[0] = st.hold_data
    else:
        left = int(st.hold_left)
        hold[:len(st.hold_record)] = st.hold_record
    tagw = np.zeros(n, dtype=np.int64)
    if n > 1:
        tagw[0] = TAG_START << p.width
    sv = np.array([int(st.out_full), st.out_reg, left, st.pending,
                   st.overflow, 0, len(st.queue), st.max_level], dtype=np.int64)
    n_w = write_cycles.size
    cap = (n + 1) * n_w + len(st.queue) + n + 3
    out_w = np.empty(cap, dtype=np.int64)
    out_c = np.empty(cap, dtype=np.int64)
    dropped = np.zeros(n_words_total, dtype=bool)
    ovf0 = st.overflow
    n_out = run_fifo_kernel(write_cycles, in_words, start, start + n_cycles, rmode, rmask, start,
                         sch.period, sch.offset, sch.count, sch.stride, D,
                         p.marker_max, TAG_MARKER << p.width, p.count_max, sv, ring,
                         out_w, out_c, dropped, hold, tagw)
    head, cnt = int(sv[SV_HEAD]), int(sv[SV_CNT])
    queue = np.concatenate([ring[head:], ring[:head]])[:cnt]     # (np.roll, cheaper)
    new = FifoState(cycle=start + n_cycles, queue=queue, out_full=bool(sv[SV_OUT_FULL]),
                    out_reg=int(sv[SV_OUT_REG]), hold_valid=bool(sv[SV_HOLD_V]),
                    hold_data=int(hold[0]) if n == 1 else 0,
                    hold_left=int(sv[SV_HOLD_V]) if n > 1 else 0,
                    hold_record=tuple(int(v) for v in hold) if n > 1 else (),
                    pending=int(sv[SV_PENDING]),
                    overflow=int(sv[SV_OVF]), max_level=int(sv[SV_MAXLVL]))
    ovf_trace = None
    if trace:
        # The counter steps once per drop, the cycle after it, saturating: its trace follows
        # from the drop cycles alone.
        steps = np.zeros(n_cycles + 1, dtype=np.int64)
        steps[write_cycles[dropped[:n_w]] - start + 1] = 1
        ovf_trace = np.minimum(ovf0 + np.cumsum(steps[:n_cycles]), p.count_max)
    return FifoResult(words=with_parity(out_w[:n_out].copy(), p), cycles=out_c[:n_out].copy(),
                      overflow_count=ovf_trace, dropped=dropped, state=new,
                      max_level=new.max_level)


def _in_records(in_words, p: FifoParams) -> np.ndarray:
    """Input as a contiguous ``(n_in, record_words)`` int64 array: single words (1-D), or
    records given as ``(n_in, record_words)`` payloads or as packed port values (1-D)."""
    if p.record_words == 1:
        return np.ascontiguousarray(in_words, dtype=np.int64).reshape(-1, 1)
    a = np.asarray(in_words)
    if a.ndim == 2:
        if a.shape[1] != p.record_words:
            raise ValueError(f"records must have shape (n_records, {p.record_words}), "
                             f"not {a.shape}")
        return np.ascontiguousarray(a, dtype=np.int64)
    return unpack_records(a, p)


def _ready_arg(out_ready, n_cycles: int):
    if isinstance(out_ready, ReadySchedule):
        return out_ready
    r = np.asarray(out_ready, dtype=bool)
    if r.ndim != 1 or r.size != n_cycles:
        raise ValueError(f"out_ready must have one entry per cycle ({n_cycles}), "
                         f"not {r.size}")
    return r


def fifo_model(in_words, in_valid, out_ready, params: FifoParams, *,
               state: FifoState | None = None, trace: bool = True) -> FifoResult:
    """Cycle-level model of the synchronous :class:`hdl.fifo.DspFifo` (compiled).

    Parameters
    ----------
    in_words : array of int
        Input payloads, taken in order on the cycles where ``in_valid`` is set (cycles
        after the last word are idle; words beyond the last valid cycle are not offered).
        Records (``record_words > 1``): ``(n_records, record_words)`` payloads, or the
        packed port values of :func:`pack_records`.
    in_valid : array of bool
        Per cycle; its length is the number of cycles simulated.
    out_ready : array of bool, or ReadySchedule
        The reader's ``ready`` per cycle (same length as ``in_valid``), or a periodic
        schedule (in cycles from reset).
    params : FifoParams
        Synchronous FIFO parameters.
    state : FifoState, optional
        Where a previous chunk stopped (default: reset). Cycle numbers in the result are
        counted from reset (``state.cycle + index``).
    trace : bool
        Return the per-cycle ``overflow_count`` (default True).

    Returns
    -------
    FifoResult
    """
    _check_sync(params)
    st = FifoState() if state is None else state
    in_words = _in_records(in_words, params)
    in_valid = np.asarray(in_valid, dtype=bool).ravel()
    n_cycles = in_valid.size
    ready = _ready_arg(out_ready, n_cycles)
    n_in = in_words.shape[0]
    wc = np.flatnonzero(in_valid)[:n_in].astype(np.int64) + st.cycle
    return _run(wc, np.ascontiguousarray(in_words[:wc.size]), st.cycle, n_cycles, ready,
                params, st, trace, n_in)


def fifo_model_events(write_cycles, in_words, n_cycles: int, out_ready, params: FifoParams, *,
                      state: FifoState | None = None, trace: bool = False) -> FifoResult:
    """:func:`fifo_model` with the input given as write cycles (no per-cycle arrays).

    Parameters
    ----------
    write_cycles : array of int
        Cycle (from reset) at which each input word is offered; strictly increasing, in
        ``[state.cycle, state.cycle + n_cycles)``.
    in_words : array of int
        One payload per write cycle (records: one record per write cycle, as in
        :func:`fifo_model`).
    n_cycles : int
        Cycles to simulate in this call, from ``state.cycle``.
    out_ready : array of bool, or ReadySchedule
        ``ready`` for each of the ``n_cycles`` cycles, or a periodic schedule (cycles from
        reset).
    params, state, trace
        As in :func:`fifo_model` (``trace`` defaults to False here: a per-cycle trace of a
        long run is large; the final count is ``result.state.overflow``).

    Returns
    -------
    FifoResult
    """
    _check_sync(params)
    st = FifoState() if state is None else state
    n_cycles = _check_int("n_cycles", n_cycles, 0)
    wc = np.asarray(write_cycles)
    if wc.size and wc.dtype.kind not in "iu":
        raise ValueError(f"write_cycles must be integers, not dtype {wc.dtype}")
    wc = np.ascontiguousarray(wc, dtype=np.int64).ravel()
    words = _in_records(in_words, params)
    if words.shape[0] != wc.size:
        raise ValueError(f"in_words must have one entry per write cycle ({wc.size}), "
                         f"not {words.shape[0]}")
    if wc.size:
        if np.any(np.diff(wc) <= 0):
            raise ValueError("write_cycles must be strictly increasing (one word per cycle)")
        if wc[0] < st.cycle or wc[-1] >= st.cycle + n_cycles:
            raise ValueError(f"write_cycles must lie in [{st.cycle}, {st.cycle + n_cycles}), "
                             f"not [{wc[0]}, {wc[-1]}]")
    ready = _ready_arg(out_ready, n_cycles)
    return _run(wc, words, st.cycle, n_cycles, ready, params, st, trace, wc.size)
