"""The envelope chain's output on one record, kept for other front ends on the same ADC
codes: :class:`EnvelopeMemo`.

Two :class:`~hdl.tacan.model.TacanFrontendModel` whose parameters differ in their peak
searches only (a benchmark's ``--detector`` variants) compute the same DDC -> CIC -> FIR ->
envelope chain on a record. Given the same memo (``TacanFrontendModel.envelope_memo``), the
first keeps each chunk's envelope samples, the chain's state after it and its range-log
entries; the second takes them back instead of computing them, when everything the chunk's
result depends on is equal: the chain's parameters, the state before the chunk, the ADC
codes and the ``freq`` writes. The result is then the same bits by construction (the chain
is a function of those); anything different is computed (and kept in place of the old).
"""
from __future__ import annotations

import pickle
from dataclasses import dataclass

import numpy as np

__all__ = ["EnvelopeMemo", "chain_key"]


def chain_key(model) -> bytes:
    """What a model's envelope chain depends on besides its input: the ADC word, the DDC,
    CIC, FIR and envelope parameters, the headroom check, the NCO word at reset, the path
    (fast or block models) and whether ranges are logged."""
    p = model.params
    return pickle.dumps((p.adc_bits, p.ddc, p.cic, p.fir, p.envelope, p.check_headroom,
                         model.freq_word, model.fast, model.log_ranges))


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is b
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.shape == b.shape and np.array_equal(a, b)
    return a == b


def _frozen(v):
    """A read-only copy (arrays, tuples of arrays) of a state part or an output."""
    if isinstance(v, tuple):
        return tuple(_frozen(u) for u in v)
    if isinstance(v, np.ndarray):
        c = v.copy()
        c.flags.writeable = False
        return c
    return v


@dataclass
class _Chunk:
    key: bytes
    state_in: tuple     # (nco, cic, fir, freq) before the chunk
    x: np.ndarray       # the ADC codes (compact copy)
    changes: tuple      # (ch_idx, ch_val)
    out: tuple          # (e, nco, cic, fir) after the chunk
    notes: list         # range-log entries [(name, lo, hi)]


class EnvelopeMemo:
    """One record's envelope chunks, keyed by their first ADC sample (``state.n_adc``).

    ``hits`` / ``misses`` count the chunks taken back / computed. Holds the record's ADC
    codes (as int16 / int32) and envelope samples: drop it with the record.
    """

    def __init__(self):
        self._chunks: dict[int, _Chunk] = {}
        self.hits = 0
        self.misses = 0

    def lookup(self, key: bytes, n_adc: int, state_in: tuple, x, changes):
        """The kept ``(e, nco, cic, fir, notes)`` of this chunk, or None."""
        c = self._chunks.get(int(n_adc))
        if (c is None or c.key != key or c.x.shape != x.shape or not _same(c.state_in, state_in)
                or not _same(c.changes, changes) or not np.array_equal(c.x, x)):
            self.misses += 1
            return None
        self.hits += 1
        return (*c.out, c.notes)

    def keep(self, key: bytes, n_adc: int, state_in: tuple, x, changes, out: tuple,
             notes: list, adc_bits: int) -> None:
        """Keep a computed chunk (its outputs read-only: a consumer cannot change them)."""
        dt = np.int16 if adc_bits <= 16 else np.int32
        self._chunks[int(n_adc)] = _Chunk(key, _frozen(state_in), np.asarray(x).astype(dt),
                                          _frozen(changes), _frozen(out), list(notes))
