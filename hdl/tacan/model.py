"""TACAN FPGA front end: the bit-exact model of :class:`hdl.tacan.frontend.TacanFrontEnd`.

Chain (one ``sync`` clock, the ADC rate): ADC -> DDC (NCO + real mixer) -> CIC -> FIR ->
envelope (CORDIC ``|z|``) -> pulse-peak search(es) -> FIFO -> DSP. The parameters and word
lengths are :class:`hdl.tacan.params.TacanFrontendParams`; the design rationale is in
``docs/explanation/tacan_frontend_design.md``.

:class:`TacanFrontendModel` chains the block models (vectorised, chunkable with a
:class:`TacanFrontendState`), or composes the blocks' compiled single-threaded kernels
(:class:`hdl.model.ddc.DdcCicKernel`, :class:`hdl.model.fir.FirKernel`,
:func:`hdl.model.envelope.envelope_model`; :meth:`TacanFrontendModel.envelope`, the default
when the word lengths allow); :meth:`TacanFrontendModel.fifo_output` adds the FIFO cycle
model for a given DSP ``ready`` pattern, with the two searches merged into the one FIFO
input by :func:`hdl.tacan.fifo_merge.fifo_write_cycles`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from dsp.tacan.frontend import Peaks
from dsp.tacan.peak_params import PeakState
from dsp.tacan.standard import SOURCE_PAIR

from ..model.cic import cic_model
from ..model.ddc import DdcCicKernel, DdcModel
from ..model.envelope import envelope_model
from ..model.fifo import fifo_model
from ..model.fir import FirKernel, fir_model
from ..model.nco import NcoState
from .envelope_memo import EnvelopeMemo, chain_key
from .fifo_merge import FifoRun, fifo_write_cycles
from .params import TacanFrontendParams
from .peak_model import peak_search

__all__ = ["TacanFrontendState", "TacanFrontendModel", "FrontendPeaks"]


def _check_changes(freq_changes, phase_bits: int):
    """Validated ``freq`` writes as (index, word) int64 arrays (None: no writes)."""
    if freq_changes is None or isinstance(freq_changes, tuple) and len(freq_changes) == 2 \
            and isinstance(freq_changes[0], np.ndarray):
        return freq_changes
    pairs = list(freq_changes)
    if any(len(c) != 2 for c in pairs):
        raise ValueError("freq_changes must be (index, word) pairs")
    idx = np.array([int(c[0]) for c in pairs], dtype=np.int64)
    val = np.array([int(c[1]) for c in pairs], dtype=np.int64)
    if idx.size and (np.any(np.diff(idx) <= 0) or idx[0] < 0):
        raise ValueError(f"freq_changes indices must be >= 0 and strictly increasing, not "
                         f"{idx.tolist()[:8]}")
    if val.size and (val.min() < 0 or val.max() >= 1 << phase_bits):
        raise ValueError(f"freq words must lie in [0, 2**{phase_bits})")
    return idx, val


def _changes_in(changes, start: int, stop: int):
    """The changes with ``start <= index < stop``, indices made relative to ``start``."""
    if changes is None:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    idx, val = changes
    a, b = np.searchsorted(idx, [start, stop])
    return np.ascontiguousarray(idx[a:b] - start), np.ascontiguousarray(val[a:b])


@dataclass
class TacanFrontendState:
    """Model state between chunks (``None`` = just after reset)."""

    nco: NcoState | None = None
    cic: object = None         #: CicState (block path) or (integrators, combs) arrays (fast)
    fir: object = None         #: FirState (block path) or (2, taps-1) history array (fast)
    peak: PeakState | None = None
    pair_peak: PeakState | None = None   #: the pair search's (``config.pair_peak``)
    n_adc: int = 0            #: ADC samples consumed
    pending: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    #: ADC samples left over (fewer than one decimation group: the CIC/FIR consume whole
    #: groups per chunk so that the integer models' chunks line up).
    freq: int | None = None   #: NCO word in force at the next sample (None: the model's)
    #: Pair-search peaks held back by ``run(..., final=False)`` (a pulse of the next call may
    #: be written before them; see :meth:`TacanFrontendModel.run`).
    held: "FrontendPeaks | None" = None


@dataclass
class FrontendPeaks:
    """Peaks as the hardware reports them (before the FIFO).

    amplitudes : int64 envelope LSBs (the peak's, with the pair-partner readout the
    partner's envelope, with the pair detection the pair's mean, as the FIFO word carries
    it); timestamps : int64 ADC ticks, unwrapped (``timestamps mod 2**ts_bits`` is the
    hardware field); index / end_index : envelope sample of the peak / whose arrival emits
    the pulse (the closing sample, ``PeakParams.emit_delay`` later with the readout or the
    pair detection); source : with two searches (``config.pair_peak``) the search of each
    peak, int8 :data:`~dsp.tacan.standard.SOURCE_PULSE` / ``SOURCE_PAIR`` (None: one search).
    """

    amplitudes: np.ndarray
    timestamps: np.ndarray
    index: np.ndarray
    end_index: np.ndarray
    source: np.ndarray | None = None

    def __len__(self):
        return len(self.amplitudes)

    def take(self, idx) -> "FrontendPeaks":
        """The peaks at ``idx`` (indices or a mask), in that order."""
        return FrontendPeaks(self.amplitudes[idx], self.timestamps[idx], self.index[idx],
                             self.end_index[idx], None if self.source is None else self.source[idx])

    @staticmethod
    def concat(parts) -> "FrontendPeaks":
        """The peaks of ``parts`` one after the other (all with a source, or none)."""
        parts = list(parts)
        cat = [np.concatenate([getattr(q, f) for q in parts])
               for f in ("amplitudes", "timestamps", "index", "end_index")]
        src = None if parts[0].source is None else np.concatenate([q.source for q in parts])
        return FrontendPeaks(*cat, source=src)


class TacanFrontendModel:
    """Bit-exact model of :class:`hdl.tacan.frontend.TacanFrontEnd`.

    Parameters
    ----------
    params : TacanFrontendParams
    freq_word : int, optional
        NCO word held on the ``freq`` port (default: the IF word).
    fast : bool, optional
        Use the compiled fused path when the parameters allow it (default), or force the
        chained block models (``False``); both give the same bits.
    """

    CHUNK = 1 << 18   # ADC samples per internal step (cache-sized temporaries)

    def __init__(self, params: TacanFrontendParams | None = None, *, freq_word: int | None = None,
                 fast: bool | None = None, log_ranges: bool = False):
        self.params = params if params is not None else TacanFrontendParams()
        self.log_ranges = bool(log_ranges)
        #: Range log (``log_ranges=True``): signal -> [min, max] in LSBs over every call.
        self.range_log: dict[str, list[int]] = {}
        self.freq_word = self.params.nco_freq_word if freq_word is None else int(freq_word)
        self.ddc = DdcModel(self.params.ddc)
        #: An :class:`~hdl.tacan.envelope_memo.EnvelopeMemo` shared with other models on
        #: the same record (fast path only): the envelope chunks it holds are taken back.
        self.envelope_memo: EnvelopeMemo | None = None
        self._notes: list | None = None    # range-log entries of the chunk being kept
        self._fast = self._fast_ok() if fast is None else bool(fast and self._fast_ok())
        p = self.params
        if self._fast:
            self._ddc_cic = DdcCicKernel(p.ddc, p.cic)
            self._fir = FirKernel(p.fir)

    @property
    def fast(self) -> bool:
        """Whether :meth:`envelope` takes the compiled fast path (see there)."""
        return self._fast

    def _fast_ok(self) -> bool:
        p = self.params
        # Exact when nothing saturates (check_headroom) or wraps (no pruning: the CIC sum is
        # exact) and the FIR's float64 accumulation holds integers below 2**53.
        return (p.check_headroom and DdcCicKernel.exact(p.ddc, p.cic)
                and FirKernel.exact(p.fir))

    def envelope(self, adc_codes, state: TacanFrontendState | None = None, *,
                 freq_changes=None) -> tuple[np.ndarray, TacanFrontendState]:
        """Envelope samples (envelope LSBs) of the next ADC codes, and the new state
        (the peak searches' states are carried unchanged).

        ``freq_changes``: ``(index, word)`` pairs, the ``freq`` port taking ``word`` from the
        ADC sample ``index`` on (counted from reset, strictly increasing); the pairs outside
        the samples processed by this call are ignored (see :meth:`run`).

        Two implementations with the same bits: the block models chained
        (``fast=False``), and compiled numba kernels used when the parameters allow it
        (:attr:`fast`), single-threaded: NCO, mixer and CIC fused in one pass over the ADC
        samples in int64 (integrators and combs as the hardware, wrapping mod 2**64, which
        is exact because the unpruned CIC's result fits its full width), the FIR at the
        CIC rate accumulating in float64 (every product and partial sum is an integer below
        ``2**50``, so exact in any order), then the envelope CORDIC. Every rounding is the
        integer ``shift_right`` of :mod:`dsp.fixed`. The tests check the two paths against
        each other and the HDL against both.
        """
        p = self.params
        st = TacanFrontendState() if state is None else state
        x = np.asarray(adc_codes)
        if x.dtype.kind not in "iu":
            raise ValueError(f"ADC codes must be integers, not dtype {x.dtype}")
        if len(st.pending):
            x = np.concatenate([st.pending.astype(x.dtype), x])
        r = p.cic.rate * p.fir.decimation
        usable = len(x) - len(x) % r
        rest = x[usable:].astype(np.int64)
        x = x[:usable]
        fw0 = self.freq_word if st.freq is None else st.freq
        ch_idx, ch_val = _changes_in(freq_changes, st.n_adc, st.n_adc + usable)
        fw_end = int(ch_val[-1]) if ch_val.size else fw0
        memo = self.envelope_memo if self._fast else None
        if memo is not None:
            key, state_in = chain_key(self), (st.nco, st.cic, st.fir, fw0)
            hit = memo.lookup(key, st.n_adc, state_in, x, (ch_idx, ch_val))
            if hit is not None:
                e, nco, cic, fir, notes = hit
                for name, lo, hi in notes:
                    self._note(name, np.array([lo, hi]))
                return e, replace(st, nco=nco, cic=cic, fir=fir, n_adc=st.n_adc + usable,
                                  pending=rest, freq=fw_end)
            self._notes = []
        if self.log_ranges and x.size:
            self._note("adc", x)
        if self._fast:
            e, nco, cic, fir = self._fast_chain(x, st, fw0, ch_idx, ch_val)
        else:
            fw = fw0
            if ch_idx.size:
                fw = np.full(usable, fw0, dtype=np.int64)
                for k, v in zip(ch_idx, ch_val):
                    fw[k:] = v
            i, q, nco = self.ddc.run(x.astype(np.int64), fw, st.nco)
            c, cic = cic_model(p.cic, np.stack([i, q], axis=-1), st.cic)
            f, fir = fir_model(p.fir, c, st.fir)
            e = envelope_model(f[:, 0], f[:, 1], p.envelope)
            if self.log_ranges and x.size:
                self._note("mixer", np.r_[i.min(), i.max(), q.min(), q.max()])
                self._note("cic", c)
                self._note("fir", f)
        if self.log_ranges and x.size:
            self._note("envelope", e)
        if memo is not None:
            memo.keep(key, st.n_adc, state_in, x, (ch_idx, ch_val), (e, nco, cic, fir),
                      self._notes, p.adc_bits)
            self._notes = None
        return e, replace(st, nco=nco, cic=cic, fir=fir, n_adc=st.n_adc + usable,
                          pending=rest, freq=fw_end)

    def _note(self, name: str, v) -> None:
        v = np.asarray(v)
        if v.size == 0:
            return
        lo, hi = int(v.min()), int(v.max())
        if self._notes is not None:
            self._notes.append((name, lo, hi))
        r = self.range_log.get(name)
        self.range_log[name] = [lo, hi] if r is None else [min(r[0], lo), max(r[1], hi)]

    def ranges(self) -> dict:
        """The range log (``log_ranges=True``) against each signal's word: ``{name: {"min",
        "max", "lo", "hi", "bits", "headroom_bits"}}`` in LSBs; ``headroom_bits`` = unused
        MSBs, ``log2(full scale / max |v|)`` (negative means it would have overflowed,
        which the parameter checks rule out for the default structure)."""
        p = self.params
        words = {"adc": p.adc_bits, "mixer": p.ddc.mixer.out_width, "cic": p.cic.out_width,
                 "fir": p.fir.out_width, "envelope": p.envelope.out_width}
        out = {}
        for name, (lo, hi) in self.range_log.items():
            b = words[name]
            signed = name != "envelope"
            top = (1 << (b - 1)) if signed else (1 << b)
            peak = max(abs(lo), abs(hi), 1)
            out[name] = {"min": lo, "max": hi, "bits": b,
                         "lo": -top if signed else 0, "hi": top - 1,
                         "headroom_bits": math.log2(top / peak)}
        return out

    def _fast_chain(self, x, st: TacanFrontendState, fw0: int, ch_idx, ch_val):
        """Compiled kernels: NCO + mixer + CIC fused (integer, sample by sample), the FIR
        (float64 accumulation, exact), the envelope CORDIC; states are copied, not
        modified."""
        p = self.params
        nco_p, cic = p.ddc.nco, p.cic
        if x.dtype.kind == "u" and x.size and int(x.max()) >= 1 << (p.adc_bits - 1):
            raise ValueError(f"ADC codes must be signed {p.adc_bits}-bit integers")
        x = np.ascontiguousarray(x, dtype=np.int64)   # one kernel signature
        pmask = (1 << nco_p.phase_bits) - 1
        acc0 = 0 if st.nco is None else int(st.nco.acc) & pmask
        fw = int(fw0) & pmask
        if st.cic is None:
            integ = np.zeros((2, cic.stages), np.int64)
            combs = np.zeros((2, cic.stages, cic.diff_delay), np.int64)
        else:
            integ, combs = (a.copy() for a in st.cic)
        L = len(p.fir.taps_int)
        hist = np.zeros((2, L - 1), np.int64) if st.fir is None else st.fir.copy()
        big = np.iinfo(np.int64).max
        mrng = np.array([big, -big, big, -big], np.int64)
        ci, cq, ph = self._ddc_cic.run(x, acc0, fw, integ, combs, ch_idx, ch_val, mrng)
        count = len(ci)
        nco = NcoState(acc=ph, lfsr=int(nco_p.dither_seed) if st.nco is None else st.nco.lfsr)
        nf = count // p.fir.decimation
        fi = self._fir.run(ci, hist[0])
        fq = self._fir.run(cq, hist[1])
        if self.log_ranges and count:
            self._note("mixer", mrng)
            self._note("cic", np.r_[ci.min(), ci.max(), cq.min(), cq.max()])
            if nf:
                self._note("fir", np.r_[fi.min(), fi.max(), fq.min(), fq.max()])
        # In range by construction (check_headroom: the FIR output never saturates).
        e = envelope_model(fi, fq, p.envelope, check=False)
        return e, nco, (integ, combs), hist

    def run(self, adc_codes, state: TacanFrontendState | None = None, *, freq_changes=None,
            final: bool = True) -> tuple[FrontendPeaks, TacanFrontendState]:
        """Peaks of the next ADC codes (valid samples only; gaps in valid do not change the
        values), vectorised, in internal chunks of :attr:`CHUNK`.

        Parameters
        ----------
        adc_codes : array of int
        state : TacanFrontendState, optional
        freq_changes : sequence of (index, word), optional
            Writes of the ``freq`` port (DSP -> FPGA control path): the NCO steps with
            ``word`` from ADC sample ``index`` on (valid samples counted from reset, as
            the state's ``n_adc``; ``index`` strictly increasing). A run split into several
            calls passes the same list to each: a call applies the changes that fall in its
            samples, the state carries the word in force, changes before the call's first
            sample (``state.n_adc``) were applied by the earlier calls.
        final : bool
            Two searches only (``config.pair_peak``): the record ends with this call. With
            ``False`` the pair peaks that a pulse peak of the next call could precede in the
            FIFO are held in the state and come out of the next call (only possible when
            the decimation is <= the pair search's extra latency, 2 or 3 cycles: see below),
            so that the calls' outputs put together equal one call's.

        Returns
        -------
        peaks : FrontendPeaks
            ``amplitudes`` (envelope LSBs) and ``timestamps`` (unwrapped int64 ADC ticks);
            with two searches both searches' peaks with their ``source``, in the order the
            FIFO is written (:func:`fifo_write_cycles`) when the ADC samples arrive on
            consecutive cycles. The order does not depend on gaps in ``valid`` when the
            decimation exceeds ``pair_peak.latency - peak.latency`` (2, 3 with the pair
            checks; the decimation is 4 by default): a pulse word comes first exactly when
            its emitting envelope sample is not later than the pair word's. Otherwise
            :meth:`peak_cycles` gives the cycles for a ``valid`` pattern and
            :meth:`fifo_output` writes in that order.
        state : TacanFrontendState
            Pass it to the next call: the result of several calls equals one long call.
        """
        p = self.params
        x = np.asarray(adc_codes)
        st = TacanFrontendState() if state is None else state
        changes = _check_changes(freq_changes, self.params.nco_phase_bits)
        searches = [("peak", p.peak)] + ([("pair_peak", p.pair_peak)] if p.pair_peak else [])
        found = {name: [] for name, _ in searches}
        for c0 in range(0, max(len(x), 1), self.CHUNK):
            e, st = self.envelope(x[c0:c0 + self.CHUNK], st, freq_changes=changes)
            for name, search in searches:
                res, pk = peak_search(e, search, getattr(st, name))
                setattr(st, name, pk)
                found[name].append(res)
        parts = []
        for k, (name, search) in enumerate(searches):
            res = found[name]
            index = np.concatenate([r.index for r in res]).astype(np.int64)
            amps = [r.partner if search.partner_offset else r.amplitude for r in res]
            parts.append(FrontendPeaks(
                amplitudes=np.concatenate(amps).astype(np.int64),
                timestamps=index * np.int64(search.ts_step), index=index,
                end_index=np.concatenate([r.end_index for r in res]).astype(np.int64)
                + search.emit_delay,
                source=np.full(index.size, k, np.int8) if p.pair_peak else None))
        if p.pair_peak is None:
            return parts[0], st
        if st.held is not None:
            parts.append(st.held)
        peaks = FrontendPeaks.concat(parts)
        emit = self.emit_cycles(peaks)
        peaks = peaks.take(np.argsort(fifo_write_cycles(emit, peaks.source), kind="stable"))
        st = replace(st, held=None)
        if not final:
            # a pulse of a later call leaves the search at this emit cycle or later
            # (the next envelope sample, closing a pulse); pair words from there on wait
            first = (st.peak.n + 1) * np.int64(p.decimation) - 1 + p.peak_latency
            late = self.emit_cycles(peaks) >= first
            if late.any():
                st.held, peaks = peaks.take(late), peaks.take(~late)
        return peaks, st

    # -- conversions --------------------------------------------------------------------------
    def peaks_to_fs(self, peaks: FrontendPeaks) -> Peaks:
        """The golden model's units: amplitudes in ADC full scale, timestamps in the golden's
        convention (the ADC tick that completes the envelope sample: ``ts + D - 1``); the
        ``source`` is carried."""
        p = self.params
        return Peaks(timestamps=peaks.timestamps + (p.decimation - 1),
                     amplitudes=peaks.amplitudes * p.scale_to_fs, fs_hz=p.config.fs_hz,
                     source=None if peaks.source is None else peaks.source.copy())

    def _check_source(self, peaks: FrontendPeaks) -> None:
        if (peaks.source is None) != (self.params.pair_peak is None):
            raise ValueError("peaks must carry a source exactly when the front end has two "
                             "searches (config.pair_peak)")

    def words(self, peaks: FrontendPeaks) -> np.ndarray:
        """Packed FIFO input payloads (:attr:`~TacanFrontendParams.record`): ``amplitude |
        (timestamp mod 2**ts_bits) << amp_width``, with two searches ``| source <<
        (amp_width + ts_bits)``."""
        self._check_source(peaks)
        p = self.params
        cols = [peaks.amplitudes, peaks.timestamps]
        if peaks.source is not None:
            cols.append(peaks.source)
        values = np.stack([np.asarray(c, np.int64) for c in cols], axis=1)
        return p.record.to_word_array(values, p.fifo.width)[:, 0]

    def unpack(self, fifo_words) -> dict[str, np.ndarray]:
        """Split FIFO output words into ``amplitude``, ``timestamp`` (wrapped), ``tag`` and,
        with two searches, ``source`` (the payload's top bit; in a marker word it is part
        of the drop count)."""
        p = self.params
        w = np.asarray(fifo_words, dtype=np.int64)
        width = p.fifo.width
        rec = p.record.from_word_array(w.reshape(-1, 1) & np.int64((1 << width) - 1), width)
        out = {name: rec[:, k].reshape(w.shape) for k, name in enumerate(p.record.names)}
        out["tag"] = (w >> np.int64(width)) & np.int64(3)
        return {k: out[k] for k in ("amplitude", "timestamp", "tag", *p.record.names[2:])}

    def emit_cycles(self, peaks: FrontendPeaks, in_valid=None, *, adc_cycles=None) -> np.ndarray:
        """Clock cycle (from reset, as :func:`cosim.pysim.run_stream` counts) at which each
        peak leaves its search: the cycle of the ADC transfer that completes its emitting
        envelope sample (``end_index``) plus that search's latency
        (:attr:`~TacanFrontendParams.peak_latency`, ``pair_peak_latency``), for ADC samples
        offered with ``in_valid`` (per cycle; every cycle after the pattern ends, as
        ``run_stream``), or mapped to their cycles by ``adc_cycles(adc_index) -> cycle``
        (valid ADC samples counted from reset). Default: one sample per cycle from reset."""
        p = self.params
        adc_idx = (peaks.end_index + 1) * np.int64(p.decimation) - 1
        if adc_cycles is not None:
            acc = np.asarray(adc_cycles(adc_idx), np.int64)
        elif in_valid is not None:
            v = np.flatnonzero(np.asarray(in_valid, dtype=bool))
            n_pat = len(np.asarray(in_valid))
            acc = np.where(adc_idx < len(v), v[np.minimum(adc_idx, max(len(v) - 1, 0))]
                           if len(v) else 0, n_pat + adc_idx - len(v))
        else:
            acc = adc_idx
        if peaks.source is None:
            return acc + np.int64(p.peak_latency)
        self._check_source(peaks)
        return acc + np.where(peaks.source == SOURCE_PAIR, np.int64(p.pair_peak_latency),
                              np.int64(p.peak_latency))

    def peak_cycles(self, peaks: FrontendPeaks, in_valid=None) -> np.ndarray:
        """Clock cycle at which each peak is written to the FIFO: :meth:`emit_cycles`, with
        two searches merged by :func:`fifo_write_cycles`. The peaks must be all of a record
        from reset (the merge looks at every pulse word)."""
        return fifo_write_cycles(self.emit_cycles(peaks, in_valid), peaks.source)

    def fifo_output(self, peaks: FrontendPeaks, n_cycles: int, *, in_valid=None,
                    out_ready=None) -> FifoRun:
        """What the FIFO hands the DSP in ``n_cycles`` cycles from reset, given the DSP's
        ``ready`` per cycle (default always; after the pattern ends: ready). ``dropped``:
        per peak written within ``n_cycles`` (in the order of ``peaks``), whether the FIFO
        dropped it."""
        p = self.params
        cyc = self.peak_cycles(peaks, in_valid)
        order = np.argsort(cyc, kind="stable")        # the FIFO's write order
        order = order[cyc[order] < n_cycles]
        w_valid = np.zeros(n_cycles, dtype=bool)
        w_valid[cyc[order]] = True
        rdy = np.ones(n_cycles, dtype=bool)
        if out_ready is not None:
            r = np.asarray(out_ready, dtype=bool)[:n_cycles]
            rdy[:len(r)] = r
        res = fifo_model(self.words(peaks)[order], w_valid, rdy, p.fifo)
        dropped = np.zeros(len(peaks), dtype=bool)
        dropped[order] = res.dropped
        return FifoRun(words=res.words, cycles=res.cycles,
                       overflow_count=res.overflow_count, dropped=dropped[cyc < n_cycles])
