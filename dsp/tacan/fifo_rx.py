"""DSP side of the FPGA->DSP FIFO: tagged words -> peaks, with plausibility checks.

Word format (:mod:`hdl.model.fifo`): ``payload | tag << width``; tag 0 = data (payload =
``amplitude | timestamp << amp_width``, timestamp = ADC tick mod ``2**ts_bits``), tag 2 =
gap marker (payload = peaks the FPGA dropped just before it), tags 1 and 3 reserved.

Nothing is taken on trust, because the link may carry bit errors:

* reserved tags are counted (``bad_tags``) and the word skipped;
* timestamps are unwrapped against the last *accepted* one: a data word is accepted when
  its tick advances by ``1 .. max_gap_ticks`` (peaks are strictly increasing in time and a
  beacon sends thousands per second); otherwise it is rejected (``ts_rejected``). After
  ``resync_after`` consecutive rejections the receiver re-synchronises on the current word
  (``ts_resyncs``): a real outage longer than ``max_gap_ticks`` costs ``resync_after`` peaks,
  a corrupted timestamp costs at most that many;
* marker payloads add to ``dropped_reported``.

The loop is compiled (numba): a word costs a few nanoseconds.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

STAT_NAMES = ("words", "data", "markers", "dropped_reported", "bad_tags", "ts_rejected",
              "ts_resyncs")


@dataclass
class RxState:
    """Carried between batches of words."""

    last_wrapped: int = -1      # -1: nothing accepted yet
    last_tick: int = 0
    rejects: int = 0
    stats: dict = field(default_factory=lambda: dict.fromkeys(STAT_NAMES, 0))


@numba.njit(cache=True, nogil=True)
def _rx(words, width, amp_width, ts_bits, max_gap, resync_after, st, out_t, out_a, stats):
    pmask = (np.int64(1) << width) - 1
    amask = (np.int64(1) << amp_width) - 1
    tmask = (np.int64(1) << ts_bits) - 1
    last_w, last_t, rej = st[0], st[1], st[2]
    n = 0
    for k in range(words.size):
        w = words[k]
        stats[0] += 1
        tag = (w >> width) & 3
        pay = w & pmask
        if tag == 2:
            stats[2] += 1
            stats[3] += pay
            continue
        if tag != 0:
            stats[4] += 1
            continue
        stats[1] += 1
        ts = (pay >> amp_width) & tmask
        amp = pay & amask
        if last_w < 0:
            t = ts
        else:
            d = (ts - last_w) & tmask
            if 0 < d <= max_gap:
                t = last_t + d
                rej = 0
            else:
                rej += 1
                stats[5] += 1
                if rej < resync_after:
                    continue
                stats[6] += 1
                rej = 0
                t = last_t + (d if d > 0 else tmask + 1)
        last_w, last_t = ts, t
        out_t[n] = t
        out_a[n] = amp
        n += 1
    st[0], st[1], st[2] = last_w, last_t, rej
    return n


def receive_words(words, *, width: int, amp_width: int, ts_bits: int,
                  max_gap_ticks: int = 1 << 22, resync_after: int = 8,
                  state: RxState | None = None):
    """Decode FIFO words.

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
    state : RxState, optional
        Continue from an earlier batch (updated in place and returned).

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
    if not (isinstance(max_gap_ticks, (int, np.integer)) and 1 <= max_gap_ticks < (1 << ts_bits) // 2):
        raise ValueError(f"max_gap_ticks must be in 1..2**(ts_bits-1), not {max_gap_ticks!r}")
    w = np.ascontiguousarray(np.asarray(words, dtype=np.int64))
    state = state or RxState()
    st = np.array([state.last_wrapped, state.last_tick, state.rejects], np.int64)
    out_t = np.empty(w.size, np.int64)
    out_a = np.empty(w.size, np.int64)
    stats = np.zeros(len(STAT_NAMES), np.int64)
    n = _rx(w, int(width), int(amp_width), int(ts_bits), int(max_gap_ticks), int(resync_after),
            st, out_t, out_a, stats)
    state.last_wrapped, state.last_tick, state.rejects = (int(v) for v in st)
    for name, v in zip(STAT_NAMES, stats):
        state.stats[name] += int(v)
    return out_t[:n], out_a[:n], state
