"""The FPGA -> DSP link at cycle level: the DSP reading the FIFO.

Two pieces, in FPGA clock cycles counted from reset (as :func:`cosim.backends.pysim.run_stream`
counts them); the DSP -> FPGA register path is :mod:`cosim.core.control`:

* :class:`DspServiceConfig` -- how the DSP services the FIFO (timer period, interrupt
  latency, batch size, read rate). It yields a ``ready`` pattern that does not depend on
  the FIFO state, so the very same pattern drives the bit-exact model
  (:func:`hdl.model.fifo.fifo_model_events`, as a compact :class:`~hdl.model.fifo.ReadySchedule`)
  and the Amaranth/Verilator simulations (as a per-cycle bool array).
* :func:`run_link` -- peak words written at given cycles go through the FIFO model and are
  read by that DSP; the result has the words read and when, the data in order, the drops
  as the FPGA counted them and as the DSP learnt them from the gap markers, the peak queue
  level and per-service statistics.

Dimensioning the link
---------------------
A DSP that reads at most ``batch_words`` per ``period_cycles`` sustains at most
``batch_words / period_cycles`` words per cycle (:meth:`DspServiceConfig.sustainable_rate_hz`);
above that the queue grows until the FIFO drops. Below it, the FIFO must hold what
arrives between two reads: about ``rate * period`` words in steady state, plus bursts. A
burst arriving while the DSP is not reading is absorbed up to the FIFO depth
(:meth:`DspServiceConfig.max_burst_words`: memory + output register; the hold register only
ever holds a word behind a marker). The default DSP (1 ms timer at 20 MHz, 200-cycle
latency, 256 words per service at 4 cycles/word) sustains 256k words/s; a TACAN beacon
gives ~3.6k..15k peak words/s, i.e. <= 15 words per service against 512 of FIFO depth.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dsp.fixed import check_int as _int
from hdl.model.fifo import (TAG_DATA, TAG_MARKER, FifoParams, FifoResult, FifoState, ReadySchedule,
                            decode_stream, fifo_model_events, unpack_word)

__all__ = ["DspServiceConfig", "DSP_PRESETS", "LinkResult", "run_link"]


# -- DSP side of the FIFO ----------------------------------------------------------------------
@dataclass(frozen=True)
class DspServiceConfig:
    """How the DSP reads the FIFO, in FPGA clock cycles.

    A timer interrupt fires at cycles ``k * period_cycles`` (``k = 0, 1, ...``). After
    ``latency_cycles`` the handler starts reading: it raises ``ready`` on
    ``batch_words`` cycles, ``cycles_per_word`` apart, i.e. at::

        k * period_cycles + latency_cycles + j * cycles_per_word,   0 <= j < batch_words

    and ``ready`` is low at every other cycle. A ``ready`` cycle reads the word the FIFO
    offers if there is one (``o.valid``), and nothing if the FIFO is empty: the service
    window is fixed in time (a handler that polls ``valid`` for a fixed budget of reads), so
    the pattern does not depend on the FIFO state and the same pattern can be fed to the
    Amaranth or Verilator simulation for a bit-exact comparison. A word written during the
    window can still be read in it (the FIFO offers a word written to an empty queue 2
    cycles later).

    Parameters
    ----------
    period_cycles : int
        Timer interrupt / polling period (cycles, >= 1).
    latency_cycles : int
        Interrupt latency: cycles from the timer tick to the first read (>= 0).
    batch_words : int
        Maximum words read per service (>= 1).
    cycles_per_word : int
        Cycles per read while servicing (>= 1; 1 = one word per cycle, e.g. DMA).

    stalls : tuple of (start, stop)
        Cycle windows ``start <= c < stop`` in which the DSP does not service the FIFO at
        all (``ready`` low): a long non-interruptible task, a halted core, a DSP overloaded
        for a while. Sorted, non-overlapping. The FIFO fills, the FPGA drops and counts,
        and the DSP learns the count from the gap marker when it reads again.

    The window (latency + reads) must end before the next tick:
    ``latency_cycles + (batch_words - 1) * cycles_per_word + 1 <= period_cycles``.
    """

    period_cycles: int = 20_000
    latency_cycles: int = 200
    batch_words: int = 256
    cycles_per_word: int = 4
    stalls: tuple = ()

    def __post_init__(self):
        _int("DSP service period_cycles", self.period_cycles, 1)
        _int("DSP service latency_cycles", self.latency_cycles, 0)
        _int("DSP service batch_words", self.batch_words, 1)
        _int("DSP service cycles_per_word", self.cycles_per_word, 1)
        end = self.latency_cycles + self.window_cycles
        if end > self.period_cycles:
            raise ValueError(
                f"DSP service window (latency_cycles + (batch_words - 1) * cycles_per_word "
                f"+ 1 = {end} cycles) must end before the next timer tick (period_cycles = "
                f"{self.period_cycles})")
        stalls = []
        for w in self.stalls:
            if not (isinstance(w, (tuple, list)) and len(w) == 2):
                raise ValueError(f"DSP service stalls are (start, stop) cycle pairs, not {w!r}")
            a = _int("DSP stall start", w[0], 0)
            b = _int("DSP stall stop", w[1], a + 1)
            if stalls and a < stalls[-1][1]:
                raise ValueError(f"DSP service stalls must be sorted and must not overlap: "
                                 f"{tuple(w)} after {stalls[-1]}")
            stalls.append((a, b))
        object.__setattr__(self, "stalls", tuple(stalls))

    @property
    def window_cycles(self) -> int:
        """Cycles from the first to the last read of a service, inclusive."""
        return (self.batch_words - 1) * self.cycles_per_word + 1

    @property
    def schedule(self) -> ReadySchedule:
        """The ``ready`` pattern in the compact form :mod:`hdl.model.fifo` takes."""
        return ReadySchedule(period=self.period_cycles, offset=self.latency_cycles,
                             count=self.batch_words, stride=self.cycles_per_word)

    def ready_mask(self, n_cycles: int) -> np.ndarray:
        """``ready`` for cycles ``0 .. n_cycles - 1`` (bool array; for ``run_stream`` and
        ``VerilatorStreamSim.run``, which take the ``out_ready`` pattern per cycle)."""
        m = self.schedule.mask(n_cycles)
        for a, b in self.stalls:
            m[a:b] = False
        return m

    def segments(self, n_cycles: int, start: int = 0) -> list[tuple[int, int, ReadySchedule]]:
        """``[start, start + n_cycles)`` cut at the stalls: ``(a, b, schedule)`` where
        ``schedule`` (cycles from reset) gives ``ready`` inside ``[a, b)``; a stall's
        schedule is never ready inside its segment."""
        n_cycles = _int("n_cycles", n_cycles, 0)
        c = _int("start", start, 0)
        stop = c + n_cycles
        out = []
        for a, b in self.stalls:
            if b <= c:
                continue
            if a >= stop:
                break
            if a > c:
                out.append((c, a, self.schedule))
            b = min(b, stop)
            out.append((max(a, c), b, ReadySchedule(period=1, offset=b)))
            c = b
        if stop > c:
            out.append((c, stop, self.schedule))
        return out

    def n_services(self, n_cycles: int) -> int:
        """Services whose first read falls before ``n_cycles``."""
        n_cycles = _int("n_cycles", n_cycles, 0)
        return max(0, -(-(n_cycles - self.latency_cycles) // self.period_cycles))

    def service_starts(self, n_cycles: int) -> np.ndarray:
        """Cycle of the first read of each service starting before ``n_cycles``."""
        k = np.arange(self.n_services(n_cycles), dtype=np.int64)
        return k * self.period_cycles + self.latency_cycles

    @property
    def sustainable_words_per_cycle(self) -> float:
        """Highest long-run input rate the DSP keeps up with: ``batch_words / period_cycles``."""
        return self.batch_words / self.period_cycles

    def sustainable_rate_hz(self, clk_hz: float = 20e6) -> float:
        """:attr:`sustainable_words_per_cycle` in words/s for the FPGA clock ``clk_hz``."""
        return self.sustainable_words_per_cycle * clk_hz

    @staticmethod
    def max_burst_words(fifo_params: FifoParams) -> int:
        """Longest burst of back-to-back words absorbed while the DSP is not reading: the
        FIFO depth (memory + output register)."""
        return fifo_params.actual_depth

    @classmethod
    def from_seconds(cls, period_s: float, latency_s: float, batch_words: int,
                     word_time_s: float, clk_hz: float = 20e6,
                     stalls_s: tuple = ()) -> DspServiceConfig:
        """Build from times in seconds (rounded to whole cycles, ``cycles_per_word >= 1``);
        ``stalls_s``: ``(start_s, stop_s)`` windows."""
        cyc = (lambda t: int(round(t * clk_hz)))
        return cls(period_cycles=cyc(period_s), latency_cycles=cyc(latency_s),
                   batch_words=batch_words, cycles_per_word=max(1, cyc(word_time_s)),
                   stalls=tuple((cyc(a), cyc(b)) for a, b in stalls_s))

    def with_stalls(self, *stalls) -> DspServiceConfig:
        """This service with the given ``(start, stop)`` cycle windows stalled."""
        return DspServiceConfig(self.period_cycles, self.latency_cycles, self.batch_words,
                                self.cycles_per_word, tuple(stalls))


#: Presets (20 MHz FPGA clock). ``default``: 1 ms timer interrupt, 10 us latency, 256 words
#: per service at 4 cycles/word (256k words/s sustainable). ``dma``: a DMA engine drains up to
#: 512 words at 1 word/cycle every 100 us (5.1M words/s). ``undersized``: a 10 ms polling
#: loop reading 64 words (6.4k words/s) -- too slow for a busy TACAN beacon (~15k words/s),
#: for overload studies.
DSP_PRESETS: dict[str, DspServiceConfig] = {
    "default": DspServiceConfig(),
    "dma": DspServiceConfig(period_cycles=2_000, latency_cycles=40, batch_words=512,
                            cycles_per_word=1),
    "undersized": DspServiceConfig(period_cycles=200_000, latency_cycles=2_000,
                                   batch_words=64, cycles_per_word=16),
}


@dataclass
class LinkResult:
    """What the DSP read, and what the FPGA dropped (see :func:`run_link`).

    Attributes
    ----------
    words : ndarray of int64
        Packed words read (``payload | tag << width``), data and markers, in order.
    read_cycles : ndarray of int64
        Cycle at which each word was read.
    data : ndarray of int64
        Payloads of the data words, in order (:func:`hdl.model.fifo.decode_stream`).
    data_cycles : ndarray of int64
        Cycle at which each data word was read.
    data_index : ndarray of int64
        Index of each data word in this call's input (``write_cycles``); -1 for words
        written by an earlier call (still queued at the start: ``carried_in``).
    wait_cycles : ndarray of int64
        Cycles each data word spent in the FPGA: read cycle - write cycle (>= 2; -1 for
        words written by an earlier call).
    dropped_mask : ndarray of bool
        Per input word, True if the FPGA dropped it.
    dropped : int
        The FPGA's ``overflow_count`` at the end (saturates at ``2**count_width - 1``).
    dropped_reported : int
        Drops the DSP learnt from the gap markers it read (each saturates at
        ``2**width - 1``). Equals :attr:`dropped` unless a counter saturated or markers
        are still in the FPGA at the end (:attr:`state`).
    n_markers : int
        Gap markers read.
    max_level : int
        Highest FIFO occupancy (memory + output register).
    reads_per_service : ndarray of int64
        Words read (data + markers) in each service whose first read falls in this call's
        cycles (stalled services read 0).
    n_written : int
        Input words written to the FIFO.
    state : FifoState
        FIFO state at the end (words still queued: ``state.level``, ``state.hold_valid``;
        drops not yet reported: ``state.pending``); pass it to the next call.
    service : DspServiceConfig
    carried_in : int
        Data words queued in the FPGA at the start of this call (from an earlier call).
    """

    words: np.ndarray
    read_cycles: np.ndarray
    data: np.ndarray
    data_cycles: np.ndarray
    data_index: np.ndarray
    wait_cycles: np.ndarray
    dropped_mask: np.ndarray
    dropped: int
    dropped_reported: int
    n_markers: int
    max_level: int
    reads_per_service: np.ndarray
    n_written: int
    state: FifoState
    service: DspServiceConfig
    carried_in: int = 0

    @property
    def n_dropped(self) -> int:
        """Words actually dropped (not saturating)."""
        return int(self.dropped_mask.sum())

    @property
    def undelivered(self) -> int:
        """Data words in the FPGA at the end (written, not dropped, not yet read)."""
        return self.carried_in + self.n_written - self.n_dropped - len(self.data)

    @property
    def full_services(self) -> int:
        """Services that read a whole batch: the DSP was at its limit (possibly behind)."""
        return int((self.reads_per_service >= self.service.batch_words).sum())


def run_link(write_cycles, payloads, n_cycles: int, fifo_params: FifoParams,
             service: DspServiceConfig, *, state: FifoState | None = None) -> LinkResult:
    """Peak words through the FPGA FIFO, read by a DSP servicing it periodically.

    Bit-exact with :class:`hdl.fifo.DspFifo` driven with ``i.valid`` high at
    ``write_cycles`` and ``o.ready = service.ready_mask(n_cycles)``; the model steps per event
    (:func:`hdl.model.fifo.fifo_model_events`), so a second of signal at 20 MHz takes
    milliseconds.

    Parameters
    ----------
    write_cycles : array of int
        Cycle (from reset) at which each word is written: strictly increasing, in
        ``[start, start + n_cycles)`` with ``start = state.cycle`` (0 without a state);
        e.g. :meth:`hdl.tacan.model.TacanFrontendModel.peak_cycles`.
    payloads : array of int
        One payload per write, ``0 <= payload < 2**fifo_params.width`` (e.g.
        ``TacanFrontendModel.words``).
    n_cycles : int
        Cycles simulated in this call.
    fifo_params : FifoParams
        A synchronous FIFO.
    service : DspServiceConfig
        How the DSP reads (its timer and stalls count cycles from reset).
    state : FifoState, optional
        Continue a run where an earlier call stopped (``LinkResult.state``): a long run in
        blocks gives the same bits as one call.

    Returns
    -------
    LinkResult
    """
    if not isinstance(service, DspServiceConfig):
        raise ValueError(f"service must be a DspServiceConfig, not {type(service).__name__}")
    if state is not None and not isinstance(state, FifoState):
        raise ValueError(f"state must be a FifoState, not {type(state).__name__}")
    p = fifo_params
    if p.record_words != 1:
        # Its data/cycle/index bookkeeping is per word; records: fifo_model_events with
        # service.ready_mask, and dsp.records.receive_records on the DSP side.
        raise ValueError(f"run_link carries single words (record_words=1), not "
                         f"record_words={p.record_words}")
    wc = np.asarray(write_cycles)
    if wc.size and wc.dtype.kind not in "iu":
        raise ValueError(f"write_cycles must be integers, not dtype {wc.dtype}")
    pl = np.asarray(payloads)
    if pl.size and pl.dtype.kind not in "iu":
        raise ValueError(f"payloads must be integers, not dtype {pl.dtype}")
    pl = pl.astype(np.int64).ravel()
    if pl.size and (pl.min() < 0 or pl.max() > p.marker_max):
        bad = pl[(pl < 0) | (pl > p.marker_max)][0]
        raise ValueError(f"payloads must fit in the FIFO width ({p.width} bits), "
                         f"not {int(bad)}")
    wc = wc.astype(np.int64).ravel()
    if wc.size != pl.size:
        raise ValueError(f"one payload per write cycle: {wc.size} cycles, {pl.size} payloads")
    n_cycles = _int("n_cycles", n_cycles, 0)
    start = 0 if state is None else state.cycle
    stop = start + n_cycles
    if wc.size and (np.any(np.diff(wc) <= 0) or wc[0] < start or wc[-1] >= stop):
        raise ValueError(f"write_cycles must be strictly increasing and lie in "
                         f"[{start}, {stop}), not [{wc.min()}, {wc.max()}]")
    st0 = state
    out_w, out_c, drops = [], [], []
    for a, b, sched in service.segments(n_cycles, start):
        i0, i1 = np.searchsorted(wc, [a, b])
        r = fifo_model_events(wc[i0:i1], pl[i0:i1], b - a, sched, p, state=state)
        state = r.state
        out_w.append(r.words)
        out_c.append(r.cycles)
        drops.append(r.dropped)
    if not out_w:           # n_cycles == 0
        r = fifo_model_events(wc, pl, 0, service.schedule, p, state=state)
        state, out_w, out_c, drops = r.state, [r.words], [r.cycles], [r.dropped]
    words, cycles = np.concatenate(out_w), np.concatenate(out_c)
    dropped_mask = np.concatenate(drops)
    data, reported = decode_stream(words, p)
    _, tag = unpack_word(words, p)
    is_data = tag == TAG_DATA
    data_cycles = cycles[is_data]
    # Data words leave in order: the k-th data word read is the k-th word not dropped --
    # counting the words of earlier calls still queued at the start.
    st_in = st0 if st0 is not None else FifoState()
    carried = _queued_data(st_in, p)
    kept = np.flatnonzero(~dropped_mask).astype(np.int64)
    n_new = max(0, data.size - carried)
    data_index = np.r_[np.full(min(carried, data.size), -1, np.int64), kept[:n_new]]
    wait = np.where(data_index >= 0, data_cycles - wc[np.maximum(data_index, 0)], -1) \
        if wc.size else np.full(data.size, -1, np.int64)
    # Services whose first read falls in [start, stop)
    k0 = max(0, -(-(start - service.latency_cycles) // service.period_cycles))
    k1 = max(0, -(-(stop - service.latency_cycles) // service.period_cycles))
    sidx = (cycles - service.latency_cycles) // service.period_cycles - k0
    reads = np.bincount(sidx, minlength=k1 - k0).astype(np.int64)[:k1 - k0] if k1 > k0 else \
        np.zeros(0, np.int64)
    return LinkResult(words=words, read_cycles=cycles, data=data,
                      data_cycles=data_cycles, data_index=data_index,
                      wait_cycles=wait.astype(np.int64), dropped_mask=dropped_mask,
                      dropped=state.overflow, dropped_reported=int(reported),
                      n_markers=int((tag == TAG_MARKER).sum()), max_level=state.max_level,
                      reads_per_service=reads, n_written=int(wc.size), state=state,
                      service=service, carried_in=carried)


def _queued_data(st: FifoState, p: FifoParams) -> int:
    """Data words inside the FPGA (memory, output register, hold register) in ``st``."""
    queued = list(st.queue) + ([st.out_reg] if st.out_full else [])
    return sum(1 for w in queued if (int(w) >> p.width) == TAG_DATA) + int(st.hold_valid)
