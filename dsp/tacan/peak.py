"""Pulse-peak search: the algorithm, its parameters and the numpy implementation (integer and float64).

The golden DSP runs the float64 variant (:func:`peak_search_float`); the HDL block
(:class:`hdl.tacan.peak.PeakSearch`) and its bit-exact compiled model
(:func:`hdl.tacan.peak_model.peak_search`) implement the integer one, which
:func:`peak_search_numpy` is the reference of. The DSP owns the algorithm; the HDL model
imports it from here (the golden DSP imports nothing from ``hdl``).

Algorithm (the HDL, this model and the lead's float golden receiver share it)
-----------------------------------------------------------------------------
Input: unsigned envelope samples ``e[n]``; ``n`` counts valid samples since reset.

Noise floor, in blocks of ``L = 2**block_log2`` samples (block ``b`` is
``n in [b*L, (b+1)*L)``):

* block 0: no detection (threshold = infinity); ``nu_1 = sum(e) >> block_log2``;
* block ``b >= 1``: ``clip_b = nu_b << clip_log2``,
  ``m_b = sum(min(e, clip_b)) >> block_log2`` -- or, with ``clip_to_floor``,
  ``m_b = sum(e if e <= clip_b else nu_b) >> block_log2`` (a sample over the clip level
  counts as the floor itself: a censored mean, see :class:`PeakParams`),
  ``nu_{b+1} = nu_b + ((m_b - nu_b) >> smooth_log2)`` (arithmetic shift = floor);
* threshold of block ``b >= 1``: ``T_b = max(thr_min, (nu_b * thr_mult) >> thr_frac)``.

This floor has a truncation bias: any ``m - nu`` in ``[0, 2**smooth_log2)`` adds nothing and
any negative one subtracts at least 1, so ``nu`` settles up to ``2**smooth_log2`` LSB *below*
the mean of ``m`` (with ``smooth_log2`` 10 and a floor of a few thousand LSB, ~14 % of the
threshold). With ``floor_frac`` the floor keeps ``smooth_log2`` fraction bits, ``F_b``, and
settles within ~1 LSB of the mean of ``m``:

* block 0: ``F_1 = m_0 << smooth_log2`` (so ``nu_1 = m_0`` as above);
* block ``b >= 1``: ``F_{b+1} = F_b - (F_b >> smooth_log2) + m_b``;
* ``nu_b = F_b >> smooth_log2``, used for the clip level, the censored substitute and the
  threshold exactly where ``nu_b`` is used above. ``0 <= F_b < 2**(amp_width + smooth_log2)``.

Float variant: sums times ``2**-block_log2``, ``nu + (m - nu) * 2**-smooth_log2``,
``T = max(thr_min, nu * thr_mult * 2**-thr_frac)``, no rounding anywhere (``floor_frac`` has
no effect on it: it has no truncation bias to remove).

Pulses (``T`` is the threshold of the sample's own block):

* closed: a sample with ``e >= T`` opens a pulse (max = e, below = 0, len = 1);
* open, for each further sample: ``e > max`` (strictly; the first occurrence wins ties)
  updates max and its ``n``; ``e >= T`` resets the below-counter, ``e < T`` increments it;
  len += 1. When below reaches ``hold``, or len reaches ``max_len``, the pulse is emitted
  (amplitude = max, timestamp = ``(n_max * ts_step) mod 2**ts_bits``) and closed *at that
  sample*: the closing sample never opens a new pulse (it matters only for a ``max_len`` cut,
  a ``hold`` close is below threshold anyway).

Pair-partner readout (``partner_offset = D > 0``): each pulse also carries the envelope
``D`` samples after and before its peak, ``ahead = e[n_max + D]`` and ``behind = e[n_max - D]``
(0 before the first sample), as ``partner = max(ahead, behind)`` and ``partner_late =
(ahead >= behind)``. With ``D`` the pulse-pair spacing this is the amplitude of the pair's
other pulse whether or not *it* crossed the threshold: a measurement whose noise is not the
noise that made the detection (the peak amplitude is censored by the threshold, the
partner's is not). The search itself is unchanged; a pulse is emitted once input sample
``end_index + D`` has arrived (the HDL runs the search ``D`` samples behind its input, on a
``2 D``-word delay line).

Pulse-pair detection (``pair_offset = D > 0``; excludes the partner readout): the search
runs on the pair sum ``s[n] = e[n] + e[n - D]`` (``e`` = 0 before the first sample), one bit
wider (``amp_width + 1``), with the partner readout at the same ``D`` on ``s``, and a peak
of ``s`` is kept unless a side lobe is clearly higher: ``8 s[n_max] >= pair_keep *
max(s[n_max - D], s[n_max + D])`` (``pair_keep`` eighths, default 6). A lone pair at
``(n - D, n)`` also gives ``s`` peaks of about half its height at ``n - D`` and ``n + D``
(one pulse each): dropped. A train of pulses ``D`` apart (the X-mode auxiliary burst: 12
pulses 12 us apart) gives equal peaks at every pulse: all kept, each pulse then reported
by two pairs (a strict maximum rule keeps a random third of them and loses bursts).
The reported amplitude is ``s >> 1`` (float: ``s / 2``), the mean of the two pulses' envelopes,
in ``amp_width`` bits; the timestamp is the pair's second pulse. With ``D`` the TACAN pair
spacing the detection integrates both pulses of a pair -- what a TACAN/DME pulse decoder
does: the threshold applies to their sum, whose noise is smaller relative to its mean, and
the amplitude measures both pulses. Its spacing tolerance is the pulse width: a single
pulse gives two equal sums (both kept, a train of one) and two pulses a little more or less
than ``D`` apart sum on their flanks; nothing here checks that both pulses are there at the
spacing (see :data:`dsp.tacan.frontend.PAIR_DETECTOR`). The noise floor and threshold are those of ``s`` (``thr_mult`` relative to its
floor, ``thr_min`` in units of ``s``). A pulse is emitted once input sample
``end_index + D`` has arrived, as with the partner readout.

Pair checks (with ``pair_offset``; both off by default; in the HDL one cycle of latency more
and ``ts_step`` a power of two, see :attr:`PeakParams.pair_check_depth`). The sum accepts anything that puts energy ``D`` apart within a pulse width: a
single pulse (equal sums at ``c`` and ``c + D``, both kept by the side-lobe rule) and two
pulses a few microseconds further apart than ``D`` (the other TACAN mode's 15-us auxiliary
pulses at ``D`` = 12 us: both halves on a flank, ``s`` ~ 1.2 A). A kept peak of ``s`` at
``n_max`` must then also pass, on the envelope around it (``e`` = 0 before the first sample):

* ``pair_balance = k`` (both pulses there): ``16 min(e[n_max], e[n_max - D]) >= k s[n_max]``;
* ``pair_spread = w`` (the pulses ``D +- w`` apart): ``s[n_max] >= max(e[n_max + w] +
  e[n_max - D - w], e[n_max - w] + e[n_max - D + w])`` -- the sum at spacing ``D`` through the
  pair's centre is not below those at ``D + 2 w`` and ``D - 2 w``. Two pulses ``D + d`` apart
  peak ``s`` half-way between, each half ``d / 2`` off its pulse's peak: kept (noise-free) iff
  ``|d| <= w``. Four envelope taps and two adders; ``w`` must reach the pulse's flank (TACAN:
  19 samples at half amplitude at 5 MHz; ``w`` = 8 is 0.6 of the peak) or the noise on the
  flat top decides.

In hardware both read the envelope at fixed offsets from the peak out of an envelope
history (:attr:`PeakParams.pair_check_depth` words, addressed by the peak's index, which the
timestamp carries) when the search emits the peak; the models read them from an envelope
history of ``2 D + max_len + w`` samples kept across chunks (:attr:`PeakParams.pair_history`).

The integer model (:func:`hdl.tacan.peak_model.peak_search`) is a compiled (numba) per-sample loop
that follows the steps above as written; :func:`peak_search_numpy` is an independent vectorised
implementation (a loop over blocks for the thresholds and over the sub-pulses of groups
longer than ``max_len``), kept as its reference and shared with the float variant. Both run
in chunks with a :class:`PeakState` and give the same bits as one long run.
"""
from __future__ import annotations

import copy

import numpy as np

from .peak_params import PeakParams, PeakResult, PeakState

__all__ = ["peak_search_numpy", "peak_search_float", "search_pairs", "search_with_partner"]

#: Threshold standing for "infinity" in the integer model (above any envelope value).
_INF_INT = np.int64(1) << np.int64(62)


def peak_search_numpy(env, params: PeakParams, state: PeakState | None = None
                      ) -> tuple[PeakResult, PeakState]:
    """The vectorised numpy implementation of :func:`peak_search` (same results; the
    reference the compiled per-sample loop is tested against)."""
    env = np.asarray(env)
    if env.size and (env.min() < 0 or env.max() >= 1 << params.amp_width):
        raise ValueError(f"peak search input must be unsigned {params.amp_width}-bit integers")
    q = params.search_params
    return search_pairs(env.astype(np.int64), params, state,
                        lambda c, st, a, b: _search(c, q, st, False, q.thr_min, a, b))


def peak_search_float(env, params: PeakParams, state: PeakState | None = None, *,
                      thr_min: float | None = None) -> tuple[PeakResult, PeakState]:
    """The same steps as :func:`peak_search` in float64, without any rounding.

    ``thr_min`` (float, same unit as ``env``) defaults to ``params.thr_min``. Amplitudes and
    thresholds come back as float64; timestamps as int64 as in the integer model.
    """
    env = np.asarray(env, dtype=np.float64)
    if np.isnan(env).any():
        raise ValueError("peak search input must not contain NaN")
    tm = float(params.thr_min if thr_min is None else thr_min)
    q = params.search_params
    return search_pairs(env, params, state, lambda c, st, a, b: _search(c, q, st, True, tm, a, b))


def search_pairs(e, p: PeakParams, state: PeakState | None, run):
    """:func:`search_with_partner` on the input (``run`` an implementation of the search with
    ``p.search_params``), or with ``pair_offset`` on the pair sum, dropping the peaks a side
    lobe clearly exceeds and (``pair_balance``, ``pair_spread``) those whose two pulses are
    not both there or not ``D`` apart (the module doc)."""
    D = p.pair_offset
    if not D:
        return search_with_partner(e, p, state, run)
    st = copy.copy(state) if state is not None else PeakState()
    H = p.pair_history
    n_in0 = st.n_in                                  # input index of e[0]
    prev = np.asarray(st.pair_hist, dtype=e.dtype)
    if prev.size < H:
        prev = np.concatenate([np.zeros(H - prev.size, dtype=e.dtype), prev])
    buf = np.concatenate([prev, e])                  # buf[i] = e[n_in0 - H + i] (0 before 0)
    s = e + buf[H - D:H - D + e.size]
    res, st = search_with_partner(s, p.search_params, st, run)
    st.pair_hist = tuple(buf[buf.size - H:].tolist())
    a, b = res.amplitude, res.partner
    keep = 8 * a >= p.pair_keep * b
    if p.pair_balance or p.pair_spread:
        m = res.index - (n_in0 - H)                  # the peaks in buf

        def env(k):
            return buf[m + k]
        if p.pair_balance:
            keep &= 16 * np.minimum(env(0), env(-D)) >= p.pair_balance * a
        if p.pair_spread:
            w = p.pair_spread
            keep &= a >= np.maximum(env(w) + env(-D - w), env(-w) + env(-D + w))
    amp = a[keep] * 0.5 if e.dtype.kind == "f" else a[keep] >> 1
    return PeakResult(amplitude=amp, timestamp=res.timestamp[keep], index=res.index[keep],
                      end_index=res.end_index[keep], thresholds=res.thresholds), st


def search_with_partner(e, p: PeakParams, state: PeakState | None, run):
    """Run ``run(centre, state, ahead, behind) -> (PeakResult, PeakState)`` (one of the
    implementations) on a chunk of input samples ``e``. Without the pair-partner readout the
    centre is ``e`` itself; with it (``partner_offset = D``) the centre samples are those
    whose sample ``D`` later has arrived, ``ahead``/``behind`` their samples ``D`` after and
    before (0 before the first), and the state keeps the input samples still needed."""
    D = p.partner_offset
    if not D:
        return run(e, state, None, None)
    st = copy.copy(state) if state is not None else PeakState()
    hist = np.asarray(st.hist, dtype=e.dtype)
    buf = np.concatenate([hist, e]) if hist.size else e
    buf_start = st.n_in - hist.size                  # input index of buf[0]
    n_in = st.n_in + e.size
    m = st.n + np.arange(max(0, n_in - D - st.n), dtype=np.int64)
    centre = buf[m - buf_start]
    ahead = buf[m + D - buf_start]
    behind = np.where(m >= D, buf[np.maximum(m - D - buf_start, 0)], 0).astype(e.dtype)
    res, st = run(np.ascontiguousarray(centre), st, np.ascontiguousarray(ahead),
                  np.ascontiguousarray(behind))
    keep = max(0, st.n - D)                          # x[n - D] on is still needed
    st.n_in = n_in
    st.hist = tuple(buf[keep - buf_start:].tolist())
    return res, st


# -- numpy implementation (integer and float) -------------------------------------------------
def _clipped(seg, clip, nu, to_floor: bool):
    """A block's samples as the noise floor counts them: over ``clip``, the clip level or
    (``clip_to_floor``) the floor ``nu`` itself."""
    return np.where(seg > clip, nu, seg) if to_floor else np.minimum(seg, clip)


def _thresholds(e, p: PeakParams, st: PeakState, is_float: bool, thr_min):
    """Per-sample threshold; updates ``st.nu``/``st.nuf``/``st.bsum`` (loop over blocks)."""
    N = e.size
    L = p.block_len
    inf = np.inf if is_float else _INF_INT
    T = np.empty(N, dtype=np.float64 if is_float else np.int64)
    pos = 0
    n = st.n
    while pos < N:
        b = n >> p.block_log2
        take = min(L - (n - b * L), N - pos)
        seg = e[pos:pos + take]
        if b == 0:
            T[pos:pos + take] = inf
            st.bsum = st.bsum + (float(seg.sum()) if is_float else int(seg.sum()))
        else:
            if is_float:
                clip = st.nu * 2.0 ** p.clip_log2
                T[pos:pos + take] = max(thr_min, st.nu * p.thr_factor)
                st.bsum = st.bsum + float(_clipped(seg, clip, st.nu, p.clip_to_floor).sum())
            else:
                clip = np.int64(st.nu << p.clip_log2)
                T[pos:pos + take] = p.threshold(st.nu)
                st.bsum = st.bsum + int(_clipped(seg, clip, np.int64(st.nu), p.clip_to_floor).sum())
        pos += take
        n += take
        if (n & (L - 1)) == 0:  # block complete
            if is_float:
                m = st.bsum * 2.0 ** -p.block_log2
                st.nu = m if b == 0 else st.nu + (m - st.nu) * 2.0 ** -p.smooth_log2
            else:
                m = int(st.bsum) >> p.block_log2
                if p.floor_frac:    # F keeps smooth_log2 fraction bits, nu = F >> s
                    f = m << p.smooth_log2 if b == 0 else st.nuf - (st.nuf >> p.smooth_log2) + m
                    st.nuf, st.nu = f, f >> p.smooth_log2
                else:
                    st.nu = m if b == 0 else st.nu + ((m - st.nu) >> p.smooth_log2)
            st.bsum = 0.0 if is_float else 0
    return T


def _segment_max(e, s, t):
    """Max over each inclusive segment ``[s_k, t_k]`` and its first index (ties: first)."""
    lengths = t - s + 1
    total = int(lengths.sum())
    offs = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    idx = np.arange(total, dtype=np.int64) - np.repeat(offs, lengths) + np.repeat(s, lengths)
    vals = e[idx]
    smax = np.maximum.reduceat(vals, offs)
    match = vals == np.repeat(smax, lengths)
    first = np.minimum.reduceat(np.where(match, idx, np.int64(1) << 62), offs)
    return smax, first


def _search(e, p: PeakParams, state, is_float: bool, thr_min, ahead=None, behind=None):
    st = copy.copy(state) if state is not None else PeakState()
    if state is None and is_float:
        st.nu, st.bsum, st.pmax = 0.0, 0.0, 0.0
    partner = ahead is not None
    pa_list, pb_list = [], []
    n0 = st.n
    N = e.size
    T = _thresholds(e, p, st, is_float, thr_min)
    above = e >= T
    idx = np.arange(N, dtype=np.int64)

    carry = st.below if st.open else 0
    last_above = np.maximum.accumulate(np.where(above, idx, np.int64(-1 - carry))) if N else idx
    streak = idx - last_above
    H = np.flatnonzero(streak == p.hold)  # candidate hold-closes
    A = np.flatnonzero(above)

    starts: list[np.ndarray] = []
    ends: list[np.ndarray] = []
    carried = None  # (end, or -1 if still open)
    p0 = 0
    if st.open:
        j_cut = p.max_len - st.length - 1
        h = np.searchsorted(H, 0)
        j_hold = int(H[h]) if h < H.size else N
        end = min(j_cut, j_hold)
        carried = end
        p0 = end + 1 if end < N else N

    # Groups of above samples (gaps < hold) from p0 on: each group is one pulse unless cut.
    Ag = A[A >= p0]
    if Ag.size:
        gstart = np.concatenate(([True], np.diff(Ag) - 1 >= p.hold))
        gs = Ag[gstart]
        ge = np.append(H, N)[np.searchsorted(H, gs, side="right")].astype(np.int64)
        long = np.flatnonzero(ge - gs + 1 > p.max_len)
        if long.size == 0:
            starts.append(gs)
            ends.append(ge)
        else:
            # Split groups longer than max_len (sequential by nature; rare).
            keep = np.ones(gs.size, dtype=bool)
            keep[long] = False
            extra_s, extra_e = [], []
            for k in long:
                s, g_end = int(gs[k]), int(ge[k])
                while True:
                    cut = s + p.max_len - 1
                    if cut >= g_end:
                        extra_s.append(s)
                        extra_e.append(g_end)
                        break
                    extra_s.append(s)
                    extra_e.append(cut)
                    a = np.searchsorted(A, cut, side="right")
                    if a >= A.size or A[a] > g_end:
                        break
                    s = int(A[a])
            s_all = np.concatenate((gs[keep], np.array(extra_s, dtype=np.int64)))
            e_all = np.concatenate((ge[keep], np.array(extra_e, dtype=np.int64)))
            order = np.argsort(s_all, kind="stable")
            starts.append(s_all[order])
            ends.append(e_all[order])
    s_arr = np.concatenate(starts) if starts else np.zeros(0, dtype=np.int64)
    t_arr = np.concatenate(ends) if ends else np.zeros(0, dtype=np.int64)

    amp_list, nmax_list, end_list = [], [], []
    # The pulse carried in from the previous chunk.
    if carried is not None:
        t = min(carried, N - 1)
        pmax, nmax = st.pmax, st.nmax
        pa, pb = st.pa, st.pb
        if t >= 0:
            seg = e[:t + 1]
            j = int(np.argmax(seg))
            if seg[j] > pmax:
                pmax, nmax = seg[j], n0 + j
                if partner:
                    pa, pb = ahead[j], behind[j]
        if carried < N:
            amp_list.append(np.array([pmax]))
            nmax_list.append(np.array([nmax], dtype=np.int64))
            end_list.append(np.array([n0 + carried], dtype=np.int64))
            if partner:
                pa_list.append(np.array([pa]))
                pb_list.append(np.array([pb]))
            st.open = False
        else:
            st.pmax, st.nmax = pmax, nmax
            st.pa, st.pb = pa, pb
            st.length += N
            st.below = int(streak[-1]) if N else st.below

    # Pulses starting in this chunk; the last may stay open.
    if s_arr.size:
        closed = t_arr < N
        tt = np.minimum(t_arr, N - 1)
        smax, first = _segment_max(e, s_arr, tt)
        amp_list.append(smax[closed])
        nmax_list.append(n0 + first[closed])
        end_list.append(n0 + t_arr[closed])
        if partner:
            pa_list.append(ahead[first[closed]])
            pb_list.append(behind[first[closed]])
        if not closed[-1]:
            st.open = True
            st.start = n0 + int(s_arr[-1])
            st.pmax = smax[-1].item()
            st.nmax = n0 + int(first[-1])
            if partner:
                st.pa, st.pb = ahead[first[-1]].item(), behind[first[-1]].item()
            st.length = N - int(s_arr[-1])
            st.below = int(streak[-1])
        else:
            st.open = False

    dt = np.float64 if is_float else np.int64
    amp = np.concatenate(amp_list).astype(dt) if amp_list else np.zeros(0, dtype=dt)
    nmax = np.concatenate(nmax_list) if nmax_list else np.zeros(0, dtype=np.int64)
    endi = np.concatenate(end_list) if end_list else np.zeros(0, dtype=np.int64)
    mask = np.int64((1 << p.ts_bits) - 1)
    ts = (nmax * np.int64(p.ts_step)) & mask
    st.n = n0 + N
    if not st.open:  # canonical closed state, so equal histories give equal states
        st.start = st.nmax = st.below = st.length = 0
        st.pmax = 0.0 if is_float else 0
        st.pa = st.pb = 0.0 if is_float else 0
    if not is_float:
        st.pmax, st.pa, st.pb = int(st.pmax), int(st.pa), int(st.pb)
    res = PeakResult(amplitude=amp, timestamp=ts, index=nmax, end_index=endi, thresholds=T)
    if partner:
        a = np.concatenate(pa_list).astype(dt) if pa_list else np.zeros(0, dtype=dt)
        b = np.concatenate(pb_list).astype(dt) if pb_list else np.zeros(0, dtype=dt)
        res.partner, res.partner_late = np.maximum(a, b), a >= b
    return res, st
