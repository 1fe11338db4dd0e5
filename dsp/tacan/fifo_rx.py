"""DSP side of the FPGA->DSP FIFO: tagged words -> peaks, with plausibility checks.

Word format (:mod:`hdl.model.fifo`): ``payload | tag << width``; tag 0 = data (payload =
``amplitude | timestamp << amp_width``, timestamp = ADC tick mod ``2**ts_bits``), tag 2 =
gap marker (payload = peaks the FPGA dropped just before it), tags 1 and 3 reserved.

Nothing is taken on trust, because the link may carry bit errors:

* with ``parity`` (the FIFO's optional even-parity bit above the tag), a word whose bits do
  not have even parity is counted (``parity_errors``) and skipped: any odd number of
  flipped bits is caught before the word is interpreted;
* reserved tags are counted (``bad_tags``) and the word skipped;
* timestamps are unwrapped against the last *accepted* one: a data word is accepted when
  its tick advances by ``1 .. max_gap_ticks`` (peaks are strictly increasing in time and a
  beacon sends thousands per second) and the next data word does not contradict it (one
  word of look-ahead); otherwise it is rejected (``ts_rejected``). A corrupted timestamp
  costs its own word; after ``resync_after`` consecutive rejections the receiver
  re-synchronises (``ts_resyncs``): a real outage longer than ``max_gap_ticks`` costs
  ``resync_after`` peaks;
* marker payloads add to ``dropped_reported``; a marker claiming more drops than the link
  can produce (``max_marker``) is counted as ``bad_markers`` instead.

Parity, tags and markers are the generic receiver's (:func:`dsp.records.receive_records`,
one-word records); this module adds the timestamp checks on the data words it hands over.
The loops are compiled (numba): a word costs a few nanoseconds.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dsp.records import receive_records
from dsp.jit import njit_cached

STAT_NAMES = ("words", "data", "markers", "dropped_reported", "bad_tags", "ts_rejected",
              "ts_resyncs", "bad_markers", "parity_errors")


@dataclass
class RxState:
    """Carried between batches of words."""

    last_wrapped: int = -1      # -1: nothing accepted yet
    last_tick: int = 0
    rejects: int = 0
    pending: tuple | None = None   # (wrapped timestamp, amplitude) awaiting its successor
    stats: dict = field(default_factory=lambda: dict.fromkeys(STAT_NAMES, 0))


@njit_cached(nogil=True)
def _rx(data, amp_width, ts_bits, max_gap, resync_after, final, st, out_t, out_a, stats):
    """``data``: the payloads of the data words, in order (parity, tags and markers already
    handled); ``st`` = [last wrapped ts (-1: none), last tick, consecutive rejects, pending
    flag, pending ts, pending amplitude]; see :func:`receive_words` for the rules."""
    amask = (np.int64(1) << amp_width) - 1
    tmask = (np.int64(1) << ts_bits) - 1
    last_w, last_t, rej = st[0], st[1], st[2]
    have_c, c_ts, c_amp = st[3], st[4], st[5]
    n = 0
    for k in range(data.size + (1 if final else 0)):
        if k < data.size:
            pay = data[k]
            n_ts = (pay >> amp_width) & tmask
            n_amp = pay & amask
            if have_c == 0:
                have_c, c_ts, c_amp = 1, n_ts, n_amp
                continue
            last = False
        else:                       # end of the stream: decide the pending word alone
            if have_c == 0:
                break
            last = True
            n_ts = c_ts
        # decide the candidate C (pending) knowing its successor N
        d_cn = (n_ts - c_ts) & tmask
        p_cn = last or (0 < d_cn <= max_gap)
        if last_w < 0:
            accept, t = p_cn, c_ts
            if not accept:
                stats[5] += 1
        else:
            d_ac = (c_ts - last_w) & tmask
            d_an = (n_ts - last_w) & tmask
            p_ac = 0 < d_ac <= max_gap
            p_an = (not last) and 0 < d_an <= max_gap
            accept = p_ac and (p_cn or not p_an)
            t = last_t + d_ac
            if accept:
                rej = 0
            else:
                rej += 1
                stats[5] += 1
                if rej >= resync_after and p_cn:
                    stats[6] += 1
                    rej = 0
                    accept = True
                    if tmask + 1 - d_ac <= max_gap:
                        # C is a little *behind* A: A itself was a corrupted word that
                        # got through. Re-anchor just after it rather than jump a wrap
                        # ahead; later ticks keep a constant offset (harmless: the DSP
                        # only uses tick differences), the step across gets dt = 1.
                        t = last_t + 1
                    else:           # a real outage: forward distance modulo the wrap
                        t = last_t + (d_ac if d_ac > 0 else tmask + 1)
        if accept:
            last_w, last_t = c_ts, t
            out_t[n] = t
            out_a[n] = c_amp
            n += 1
        if last:
            have_c = 0
        else:
            c_ts, c_amp = n_ts, n_amp
    st[0], st[1], st[2] = last_w, last_t, rej
    st[3], st[4], st[5] = have_c, c_ts, c_amp
    return n


def receive_words(words, *, width: int, amp_width: int, ts_bits: int,
                  max_gap_ticks: int = 1 << 22, resync_after: int = 8,
                  max_marker: int = 1 << 24, state: RxState | None = None,
                  final: bool = True, parity: bool = False):
    """Decode FIFO words.

    A data word is accepted when its timestamp advances by ``1 .. max_gap_ticks`` from the
    last accepted one *and* its successor does not contradict it: a corrupted timestamp is
    recognised because the next word advances from the last accepted one but not from it
    (one word of look-ahead, so one corruption costs one word, and the timeline never jumps).
    A word both neighbours disagree with is rejected (``ts_rejected``); after
    ``resync_after`` consecutive rejections (a real outage longer than ``max_gap_ticks``:
    the FIFO overflowed, the DSP stalled) the receiver re-synchronises on a word that its
    successor confirms (``ts_resyncs``), taking the forward distance modulo the timestamp
    wrap -- unless the words are slightly *behind* the last accepted one (that one was a
    corrupted word that got through, e.g. two corruptions in a row): then it re-anchors one
    tick after it, so the timeline never jumps.

    Parameters
    ----------
    words : array of int
        Packed words as read from the FIFO, in order.
    width, amp_width, ts_bits : int
        Payload width, amplitude width and timestamp width of the front end.
    max_gap_ticks : int
        Largest plausible advance between consecutive peaks (default 2**22 ticks, 0.21 s
        at 20 MHz).
    resync_after : int
        Consecutive implausible timestamps after which the receiver re-synchronises.
    max_marker : int
        Largest plausible gap-marker count (default 2**24: over half an hour of a beacon's
        peaks); a marker claiming more is a corrupted word, counted as ``bad_markers`` and
        not added to ``dropped_reported``.
    state : RxState, optional
        Continue from an earlier batch (updated in place and returned).
    final : bool
        The stream ends with this batch: decide the last data word without a successor
        (default). With ``final=False`` it stays pending in ``state`` until the next batch
        (a DSP streaming batch after batch).
    parity : bool
        The words carry the FIFO's even-parity bit (``FifoParams.parity``): check it.

    Returns
    -------
    ticks : int64 array
        Unwrapped timestamps (ticks; the first accepted word keeps its wrapped value).
    amplitudes : int64 array
        Amplitudes (envelope LSBs).
    state : RxState
        With cumulative ``stats``.
    """
    for name, v, lo, hi in (("width", width, 2, 61), ("amp_width", amp_width, 1, 60),
                            ("ts_bits", ts_bits, 1, 62), ("resync_after", resync_after, 1, 1 << 30)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
            raise ValueError(f"{name} must be an integer in {lo}..{hi}, not {v!r}")
    if amp_width + ts_bits > width:
        raise ValueError(f"amp_width + ts_bits ({amp_width + ts_bits}) exceeds the payload "
                         f"width {width}")
    if isinstance(max_marker, bool) or not isinstance(max_marker, (int, np.integer)) or max_marker < 1:
        raise ValueError(f"max_marker must be an integer >= 1, not {max_marker!r}")
    if not (isinstance(max_gap_ticks, (int, np.integer)) and 1 <= max_gap_ticks < (1 << ts_bits) // 2):
        raise ValueError(f"max_gap_ticks must be in 1..2**(ts_bits-1), not {max_gap_ticks!r}")
    if not isinstance(parity, (bool, np.bool_)):
        raise ValueError(f"parity must be a bool, not {parity!r}")
    if parity and width > 60:
        raise ValueError(f"with parity the payload width must be <= 60, not {width}")
    w = np.ascontiguousarray(np.asarray(words, dtype=np.int64))
    link = receive_records(w, width=int(width), parity=bool(parity), max_marker=int(max_marker))
    data = np.ascontiguousarray(link.records[:, 0])
    state = state or RxState()
    pend = state.pending
    st = np.array([state.last_wrapped, state.last_tick, state.rejects,
                   0 if pend is None else 1, 0 if pend is None else pend[0],
                   0 if pend is None else pend[1]], np.int64)
    out_t = np.empty(data.size + 1, np.int64)
    out_a = np.empty(data.size + 1, np.int64)
    stats = np.zeros(len(STAT_NAMES), np.int64)
    n = _rx(data, int(amp_width), int(ts_bits), int(max_gap_ticks), int(resync_after),
            bool(final), st, out_t, out_a, stats)
    ls = link.state.stats
    for name, generic in (("words", "words"), ("data", "records"), ("markers", "markers"),
                          ("dropped_reported", "dropped_reported"), ("bad_tags", "bad_tags"),
                          ("bad_markers", "bad_markers"), ("parity_errors", "parity_errors")):
        stats[STAT_NAMES.index(name)] = ls[generic]
    state.last_wrapped, state.last_tick, state.rejects = (int(v) for v in st[:3])
    state.pending = (int(st[4]), int(st[5])) if st[3] else None
    for name, v in zip(STAT_NAMES, stats):
        state.stats[name] += int(v)
    return out_t[:n], out_a[:n], state
