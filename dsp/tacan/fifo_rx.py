"""DSP side of the FPGA->DSP FIFO: tagged words -> peaks, with plausibility checks.

Word format (:mod:`hdl.model.fifo`): ``payload | tag << width``; tag 0 = data (payload =
``amplitude | timestamp << amp_width``, timestamp = ADC tick mod ``2**ts_bits``; with two
searches in the front end, ``source_bits = 1``, also ``| source << (amp_width + ts_bits)``),
tag 2 = gap marker (payload = peaks the FPGA dropped just before it), tags 1 and 3 reserved.

Nothing is taken on trust, because the link may carry bit errors:

* with ``parity`` (the FIFO's optional even-parity bit above the tag), a word whose bits do
  not have even parity is counted (``parity_errors``) and skipped: any odd number of
  flipped bits is caught before the word is interpreted;
* reserved tags are counted (``bad_tags``) and the word skipped;
* timestamps are unwrapped against the last *accepted* one (with two searches, of the same
  source: each search's timestamps ascend, the merged stream's do not): a data word is
  accepted when its tick advances by ``1 .. max_gap_ticks`` (peaks are strictly increasing
  in time and a beacon sends thousands per second) and the next data word (of its source)
  does not contradict it (one word of look-ahead); otherwise it is rejected
  (``ts_rejected``). A corrupted timestamp
  costs its own word; after ``resync_after`` consecutive rejections the receiver
  re-synchronises (``ts_resyncs``): a real outage longer than ``max_gap_ticks`` costs
  ``resync_after`` peaks. With two searches a timeline re-synchronises on the other's
  (the references come from one, the measurements from the other: an offset between them
  would be a bearing error), and its words behind a tick already handed on -- after a
  corrupted word that got through, up to its error -- are held back and counted as
  rejected;
* marker payloads add to ``dropped_reported``; a marker claiming more drops than the link
  can produce (``max_marker``) is counted as ``bad_markers`` instead.

The data word's fields are :func:`peak_record`, the front end's record layout (the model
packs its words with it, :attr:`hdl.tacan.params.TacanFrontendParams.record`). Parity, tags
and markers are the generic receiver's (:func:`dsp.records.receive_records`, one-word
records); this module adds the timestamp checks on the data words it hands over.
The loops are compiled (numba): a word costs a few nanoseconds.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dsp.jit import njit_cached
from dsp.record_layout import RecordLayout
from dsp.records import receive_records

def peak_record(amp_width: int, ts_bits: int, source_bits: int = 0) -> RecordLayout:
    """The TACAN front end's FIFO record, LSB first: ``amplitude`` (``amp_width`` bits),
    ``timestamp`` (``ts_bits``: the ADC tick mod ``2**ts_bits``) and, with two searches
    (``source_bits = 1``), ``source`` (:data:`dsp.tacan.standard.SOURCE_PULSE` or
    ``SOURCE_PAIR``)."""
    f = [("amplitude", int(amp_width), False), ("timestamp", int(ts_bits), False)]
    if source_bits:
        f.append(("source", int(source_bits), False))
    return RecordLayout(tuple(f))


STAT_NAMES = ("words", "data", "markers", "dropped_reported", "bad_tags", "ts_rejected",
              "ts_resyncs", "bad_markers", "parity_errors")


@dataclass
class RxTrack:
    """One search's timeline (with ``source_bits = 1`` there is one per source)."""

    last_wrapped: int = -1      # -1: nothing accepted yet
    last_tick: int = 0
    rejects: int = 0
    pending: tuple | None = None   # (wrapped timestamp, amplitude, data word number)
    #: the last tick handed on; after a re-anchoring behind it, words are held back until
    #: the timeline passes it (the ticks handed on only ascend)
    emitted_tick: int = -(1 << 62)


@dataclass
class RxState:
    """Carried between batches of words: a timeline per source (``tracks``), the number of
    data words seen (``n_data``, numbering the words across batches) and the cumulative
    ``stats``."""

    tracks: list = field(default_factory=lambda: [RxTrack()])
    n_data: int = 0
    stats: dict = field(default_factory=lambda: dict.fromkeys(STAT_NAMES, 0))

    @property
    def pending(self):
        """The words still awaiting their successor (``final=False``), None when none."""
        p = [t.pending for t in self.tracks if t.pending is not None]
        return p or None


# Columns of the kernel's per-track state rows.
_LAST_W, _LAST_T, _REJ, _HAVE_C, _C_TS, _C_AMP, _C_SEQ, _EMIT_T = range(8)


@njit_cached(nogil=True)
def _anchor(st, s, c_ts, tmask):
    """With two searches: ``(True, tick)`` of the wrapped timestamp ``c_ts`` of track ``s``
    unwrapped next to the other track's timeline when that one is running (the two
    searches' timestamps are close in time, far less than half a wrap apart), else
    ``(False, 0)``."""
    o = 1 - s
    if st.shape[0] == 2 and st[o, _LAST_W] >= 0:
        d = (c_ts - st[o, _LAST_W]) & tmask
        if d > (tmask >> 1):
            d -= tmask + 1
        return True, st[o, _LAST_T] + d
    return False, np.int64(0)


@njit_cached(nogil=True)
def _decide(st, s, n_ts, last, tmask, max_gap, resync_after, out_t, out_a, out_i, out_s,
            n, stats):
    """Decide track ``s``'s pending word C knowing its successor's timestamp ``n_ts`` (or
    alone, ``last``); append it to the outputs if accepted; return the new output count."""
    c_ts = st[s, _C_TS]
    last_w, last_t, rej = st[s, _LAST_W], st[s, _LAST_T], st[s, _REJ]
    counted = False             # already counted as rejected (the word that resynchronises)
    d_cn = (n_ts - c_ts) & tmask
    p_cn = last or (0 < d_cn <= max_gap)
    if last_w < 0:
        accept, t = p_cn, c_ts
        other, ta = _anchor(st, s, c_ts, tmask)
        if other:               # the other search's timeline is running: unwrap next to it
            t = ta
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
                counted = True
                other, ta = _anchor(st, s, c_ts, tmask)
                if other:
                    # Two searches: re-anchor on the other's timeline. An offset between
                    # the two would put the measurements (pairs) off the references'
                    # timing (single pulses): a constant bearing error, shown valid (the
                    # FIFO fault study at 1e-3 without parity: 40 % misleading).
                    t = ta
                elif tmask + 1 - d_ac <= max_gap:
                    # C is a little *behind* A: A itself was a corrupted word that
                    # got through. Re-anchor just after it rather than jump a wrap
                    # ahead; later ticks keep a constant offset (harmless: the DSP
                    # only uses tick differences), the step across gets dt = 1.
                    t = last_t + 1
                else:           # a real outage: forward distance modulo the wrap
                    t = last_t + (d_ac if d_ac > 0 else tmask + 1)
    st[s, _REJ] = rej
    if accept:
        st[s, _LAST_W], st[s, _LAST_T] = c_ts, t
        if t <= st[s, _EMIT_T]:
            # behind a tick already handed on (re-anchored behind a corrupted word that got
            # through): held back, counted as rejected, until the timeline passes it
            if not counted:
                stats[5] += 1
            return n
        st[s, _EMIT_T] = t
        out_t[n] = t
        out_a[n] = st[s, _C_AMP]
        out_i[n] = st[s, _C_SEQ]
        out_s[n] = s
        n += 1
    return n


@njit_cached(nogil=True)
def _rx(amp, ts, src, seq0, ts_bits, max_gap, resync_after, final, st, out_t, out_a,
        out_i, out_s, stats):
    """``amp``, ``ts``: the amplitudes and (wrapped) timestamps of the data words, in order
    (parity, tags and markers already handled), ``src`` their sources (track numbers),
    ``seq0`` the number of the first; ``st``
    one row per track (the ``_LAST_W`` ... ``_C_SEQ`` columns); see :func:`receive_words`
    for the rules. Outputs in the order decided, with the word numbers in ``out_i`` and the
    tracks in ``out_s``."""
    tmask = (np.int64(1) << ts_bits) - 1
    n = 0
    for k in range(ts.size):
        s = src[k]
        n_ts = ts[k]
        if st[s, _HAVE_C] != 0:
            n = _decide(st, s, n_ts, False, tmask, max_gap, resync_after, out_t, out_a, out_i,
                        out_s, n, stats)
        st[s, _HAVE_C], st[s, _C_TS], st[s, _C_AMP] = 1, n_ts, amp[k]
        st[s, _C_SEQ] = seq0 + k
    if final:                   # end of the stream: decide the pending words alone
        for s in range(st.shape[0]):
            if st[s, _HAVE_C] != 0:
                n = _decide(st, s, st[s, _C_TS], True, tmask, max_gap, resync_after, out_t,
                            out_a, out_i, out_s, n, stats)
                st[s, _HAVE_C] = 0
    return n


def receive_words(words, *, width: int, amp_width: int, ts_bits: int,
                  max_gap_ticks: int = 1 << 22, resync_after: int = 8,
                  max_marker: int = 1 << 24, state: RxState | None = None,
                  final: bool = True, parity: bool = False, source_bits: int = 0):
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

    Two searches (``source_bits = 1``, the front end with ``FrontendConfig.pair_peak``):
    the payload's top bit (``amplitude | timestamp << amp_width | source << (amp_width +
    ts_bits)``) says which search reported the word (:data:`dsp.tacan.standard.SOURCE_PULSE`
    / ``SOURCE_PAIR``). Each search's timestamps ascend but the merged stream's do not (a
    pair is timestamped at its second pulse and leaves its search later than a pulse), so
    the rules above run per source, on that source's words alone (its own predecessor and
    successor, its own rejection count). A source's first accepted word is unwrapped next to
    the other source's last accepted tick when that one has started (nearest, either
    direction), so both timelines share one unwrapping; else it keeps its wrapped value.
    A corrupted source bit moves a word to the other timeline, where its timestamp is
    usually still plausible: parity (``parity=True``) is what catches it.

    Parameters
    ----------
    words : array of int
        Packed words as read from the FIFO, in order.
    width, amp_width, ts_bits : int
        Payload width, amplitude width and timestamp width of the front end.
    max_gap_ticks : int
        Largest plausible advance between consecutive peaks of a source (default 2**22
        ticks, 0.21 s at 20 MHz).
    resync_after : int
        Consecutive implausible timestamps after which the receiver re-synchronises.
    max_marker : int
        Largest plausible gap-marker count (default 2**24: over half an hour of a beacon's
        peaks); a marker claiming more is a corrupted word, counted as ``bad_markers`` and
        not added to ``dropped_reported``.
    state : RxState, optional
        Continue from an earlier batch (updated in place and returned).
    final : bool
        The stream ends with this batch: decide the last data word (of each source) without
        a successor (default). With ``final=False`` it stays pending in ``state`` until the
        next batch (a DSP streaming batch after batch).
    parity : bool
        The words carry the FIFO's even-parity bit (``FifoParams.parity``): check it.
    source_bits : {0, 1}
        Bits of the source field at the top of the payload (1: two searches).

    Returns
    -------
    ticks : int64 array
        Unwrapped timestamps (ticks; the first accepted word keeps its wrapped value).
    amplitudes : int64 array
        Amplitudes (envelope LSBs).
    source : int8 array
        With ``source_bits = 1`` only: the source of each accepted word.
    state : RxState
        With cumulative ``stats``.

    The accepted words come in stream order; with ``final=False`` a word decided in a later
    batch (it waited for its successor of the same source) comes out of that batch.
    """
    for name, v, lo, hi in (("width", width, 2, 61), ("amp_width", amp_width, 1, 60),
                            ("ts_bits", ts_bits, 1, 62), ("resync_after", resync_after, 1, 1 << 30)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
            raise ValueError(f"{name} must be an integer in {lo}..{hi}, not {v!r}")
    if isinstance(source_bits, bool) or source_bits not in (0, 1):
        raise ValueError(f"source_bits must be 0 or 1, not {source_bits!r}")
    if amp_width + ts_bits + source_bits > width:
        what = "amp_width + ts_bits" + (" + source_bits" if source_bits else "")
        raise ValueError(f"{what} ({amp_width + ts_bits + source_bits}) exceeds the payload "
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
    rec = peak_record(amp_width, ts_bits, source_bits).from_word_array(link.records[:, :1],
                                                                     int(width))
    amp, ts = np.ascontiguousarray(rec[:, 0]), np.ascontiguousarray(rec[:, 1])
    state = state or RxState()
    n_tracks = 1 << source_bits
    if len(state.tracks) != n_tracks:
        if state.n_data:
            raise ValueError(f"state has {len(state.tracks)} source timelines, not "
                             f"{n_tracks} (source_bits={source_bits})")
        state.tracks = [RxTrack() for _ in range(n_tracks)]
    src = np.ascontiguousarray(rec[:, 2]) if source_bits else np.zeros(ts.size, np.int64)
    st = np.array([[t.last_wrapped, t.last_tick, t.rejects, t.pending is not None,
                    *(t.pending if t.pending is not None else (0, 0, 0)), t.emitted_tick]
                   for t in state.tracks], np.int64)
    cap = ts.size + n_tracks
    out_t, out_a, out_i, out_s = (np.empty(cap, np.int64) for _ in range(4))
    stats = np.zeros(len(STAT_NAMES), np.int64)
    n = _rx(amp, ts, src, np.int64(state.n_data), int(ts_bits), int(max_gap_ticks),
            int(resync_after), bool(final), st, out_t, out_a, out_i, out_s, stats)
    ls = link.state.stats
    for name, generic in (("words", "words"), ("data", "records"), ("markers", "markers"),
                          ("dropped_reported", "dropped_reported"), ("bad_tags", "bad_tags"),
                          ("bad_markers", "bad_markers"), ("parity_errors", "parity_errors")):
        stats[STAT_NAMES.index(name)] = ls[generic]
    for t, row in zip(state.tracks, st):
        t.last_wrapped, t.last_tick, t.rejects = (int(v) for v in row[:3])
        t.pending = tuple(int(v) for v in row[_C_TS:_EMIT_T]) if row[_HAVE_C] else None
        t.emitted_tick = int(row[_EMIT_T])
    state.n_data += int(ts.size)
    for name, v in zip(STAT_NAMES, stats):
        state.stats[name] += int(v)
    # decided in track order per word; the word numbers restore the stream order
    order = np.argsort(out_i[:n], kind="stable")
    ticks, amps = out_t[:n][order], out_a[:n][order]
    if not source_bits:
        return ticks, amps, state
    return ticks, amps, out_s[:n][order].astype(np.int8), state
