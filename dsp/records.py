"""DSP side of the FPGA->DSP FIFO, generic part: tagged words -> whole records.

Word format (:mod:`hdl.model.fifo`, LSB first): ``width`` payload bits, a 2-bit tag, and
with ``parity`` an even-parity bit over the word. With ``record_words = n``:

* ``n == 1``: tag 0 = a record of one word (data), tag 2 = gap marker, tags 1 and 3
  reserved (today's single-word format, e.g. TACAN's peaks);
* ``n > 1``: tag 1 = first word of a record, tag 0 = its next ``n - 1`` words, tag 2 = gap
  marker, tag 3 reserved.

A marker's payload is the number of records the FPGA dropped just before it. This module
knows nothing of what a record means (TACAN's timestamp checks stay in
:mod:`dsp.tacan.fifo_rx`); it only refuses to hand over a record it cannot vouch for:

* a word whose parity is odd is counted (``parity_errors``) and skipped;
* a reserved tag is counted (``bad_tags``) and the word skipped;
* a record missing words (a start, a marker or an error word before its last word) is
  discarded and counted (``broken_records``); continuation words with no record open are
  counted (``orphan_words``) and skipped: the FIFO never produces either, so they mean bit
  errors on the link;
* marker payloads add to ``dropped_reported``; one claiming more than ``max_marker``
  records is counted as ``bad_markers`` instead.

A record may span two batches (``state`` carries the partial record). The loop is compiled
(numba), one pass over the words.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from dsp.jit import njit_cached

from dsp.fixed import check_width, parity_bit

__all__ = ["STAT_NAMES", "RecordRxState", "RecordBatch", "receive_records"]

STAT_NAMES = ("words", "records", "markers", "dropped_reported", "parity_errors", "bad_tags",
              "broken_records", "orphan_words", "bad_markers")
_W, _REC, _MK, _DROP, _PAR, _TAG, _BROKEN, _ORPHAN, _BADMK = range(len(STAT_NAMES))


@dataclass
class RecordRxState:
    """Carried between batches: the words of a record not yet complete, the markers seen
    since the last record, and the cumulative ``stats``."""

    partial: tuple = ()
    gap: int = 0
    stats: dict = field(default_factory=lambda: dict.fromkeys(STAT_NAMES, 0))


class RecordBatch(NamedTuple):
    """What :func:`receive_records` returns.

    Attributes
    ----------
    records : ndarray of int64, shape (n_records, record_words)
        Payloads of the complete records, in order.
    first_word : ndarray of int64
        Index in this batch's ``words`` of each record's first word (-1 when it started in
        an earlier batch); with the FIFO's read cycles this times the records.
    gap_before : ndarray of int64
        Records the markers reported dropped between the previous record and this one.
    state : RecordRxState
    """

    records: np.ndarray
    first_word: np.ndarray
    gap_before: np.ndarray
    state: RecordRxState


@njit_cached(nogil=True)
def _rx_records(words, odd, width, n, max_marker, part, st, out, out_first, out_gap, stats):
    """``part``: the open record's words so far; ``st`` = [words in ``part``, gap]."""
    pmask = (np.int64(1) << width) - 1
    have = st[0]
    gap = st[1]
    first = np.int64(-1)
    n_out = 0
    for k in range(words.size):
        w = words[k]
        stats[_W] += 1
        if odd[k]:
            stats[_PAR] += 1
            if have > 0:
                stats[_BROKEN] += 1
                have = 0
            continue
        tag = (w >> width) & 3
        pay = w & pmask
        if tag == 2:
            if have > 0:
                stats[_BROKEN] += 1
                have = 0
            if pay > max_marker:
                stats[_BADMK] += 1
            else:
                stats[_MK] += 1
                stats[_DROP] += pay
                gap += pay
            continue
        if n == 1:
            if tag != 0:
                stats[_TAG] += 1
                continue
            out[n_out, 0] = pay
            out_first[n_out] = k
            out_gap[n_out] = gap
            gap = 0
            n_out += 1
            stats[_REC] += 1
            continue
        if tag == 3:
            stats[_TAG] += 1
            if have > 0:
                stats[_BROKEN] += 1
                have = 0
            continue
        if tag == 1:
            if have > 0:
                stats[_BROKEN] += 1
            part[0] = pay
            have = 1
            first = k
        elif have == 0:
            stats[_ORPHAN] += 1
            continue
        else:
            part[have] = pay
            have += 1
        if have == n:
            for j in range(n):
                out[n_out, j] = part[j]
            out_first[n_out] = first
            out_gap[n_out] = gap
            gap = 0
            n_out += 1
            stats[_REC] += 1
            have = 0
            first = -1
    st[0] = have
    st[1] = gap
    return n_out


def receive_records(words, *, width: int, record_words: int = 1, parity: bool = False,
                    max_marker: int | None = None,
                    state: RecordRxState | None = None) -> RecordBatch:
    """Reassemble the records in a batch of FIFO words.

    Parameters
    ----------
    words : array of int
        Packed words as read from the FIFO, in order.
    width : int
        Payload bits per word (``FifoParams.width``; 1..61, 1..60 with parity).
    record_words : int
        Words per record (``FifoParams.record_words``).
    parity : bool
        The words carry the FIFO's even-parity bit: check it.
    max_marker : int, optional
        Largest plausible marker count (default: any ``width``-bit count).
    state : RecordRxState, optional
        Continue from an earlier batch (updated in place and returned).

    Returns
    -------
    RecordBatch
    """
    if not isinstance(parity, (bool, np.bool_)):
        raise ValueError(f"parity must be a bool, not {parity!r}")
    width = check_width("record width", width, minimum=1, maximum=60 if parity else 61)
    n = check_width("record_words", record_words, minimum=1, maximum=64)
    if max_marker is None:
        max_marker = (1 << width) - 1
    if isinstance(max_marker, bool) or not isinstance(max_marker, (int, np.integer)) \
            or max_marker < 1:
        raise ValueError(f"max_marker must be an integer >= 1, not {max_marker!r}")
    w = np.ascontiguousarray(np.asarray(words, dtype=np.int64)).ravel()
    odd = parity_bit(w).astype(bool) if parity else np.zeros(w.size, bool)
    state = state if state is not None else RecordRxState()
    if len(state.partial) >= n:
        raise ValueError(f"state holds {len(state.partial)} words of a {n}-word record")
    part = np.zeros(n, np.int64)
    part[:len(state.partial)] = state.partial
    st = np.array([len(state.partial), state.gap], np.int64)
    cap = w.size // n + 1
    out = np.zeros((cap, n), np.int64)
    out_first = np.zeros(cap, np.int64)
    out_gap = np.zeros(cap, np.int64)
    stats = np.zeros(len(STAT_NAMES), np.int64)
    k = _rx_records(w, odd, width, n, int(max_marker), part, st, out, out_first, out_gap, stats)
    state.partial = tuple(int(v) for v in part[:st[0]])
    state.gap = int(st[1])
    for name, v in zip(STAT_NAMES, stats):
        state.stats[name] += int(v)
    return RecordBatch(out[:k].copy(), out_first[:k].copy(), out_gap[:k].copy(), state)
