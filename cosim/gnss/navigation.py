"""From a tracked channel to its navigation message and its counts at any receiver sample.

Input: one :class:`cosim.gnss.multichannel.Assignment` (a PRN on a channel, its records: per
1 ms record the prompt boundary time, Doppler, the prompt code phase at the recording's last
whole-ms sample before the boundary, the prompt I/Q; per lock window the C/N0) and the
run's bus writes (:attr:`cosim.gnss.multichannel.MultiTrack.bus_writes`).

Per channel (:func:`channel_navigation`)
----------------------------------------
* The records used: from the window that confirmed lock (``lock_sample``) to the
  assignment's end; a channel that never locked has no navigation (status ``not-locked``).
  The records must be consecutive code periods (one per ~1 ms); otherwise an internal error.
* Bit synchronisation on their in-phase prompts (:func:`dsp.gnss.bitsync.bit_sync`, the
  histogram method with its confidence rule), the soft bits (sum of 20 prompts,
  :func:`dsp.gnss.bitsync.nav_bits`), frame synchronisation and decoding by
  :func:`dsp.gnss.lnav_decode.decode_lnav` (a word failing parity is never used; only
  parity-clean subframes carry a TOW). Statuses: ``no-bit-sync``, ``no-frame-sync``,
  ``ok``.
* The time of week of every bit edge: the subframe grid is ``sync_bit + 300 m``; a decoded
  subframe (``Subframe.tow_start``, from its HOW) dates its grid point, and the others follow
  at 6 s per subframe (the grid is confirmed by the decoder). Record ``k`` (index among the
  records used) then lies ``n_codes = (k - e) mod 20`` code periods after the edge of bit
  ``j = floor((k - e) / 20)`` (``e`` the bit edge), which is ``n_bits = (j - sync_bit) mod
  300`` bits after the edge of subframe ``m = floor((j - sync_bit) / 300)``.
* When the counts become known to a causal receiver: the TOW at the end of the first
  decoded subframe plus the next TLM and HOW (60 bits: the decoder's confirmation),
  ``tow_sample``; the decoded ephemeris at the end of the first clean subframe by which
  subframes 1, 2 and 3 have all been clean, ``eph_sample``. (The decoder returns the latest
  complete data set; on a record whose data set changes after that point the new one is
  used from ``eph_sample`` on, a little early: a cutover is not modelled.)

Counts at a receiver sample (:meth:`ChannelNav.counts`)
-------------------------------------------------------
At a whole-ms sample ``N`` of the recording the record ``k`` whose grid sample ``g_k`` (the
last whole-ms sample before its prompt boundary) is ``N`` gives the prompt code phase at
``N`` exactly (the code NCO's accumulator and word, :mod:`cosim.gnss.multichannel_epochs`);
the sample belongs to the code period of the record ``k`` with ``n_p[k-1] <= N < n_p[k]``
(a boundary sample starts the next period). When no record has ``g_k = N`` (the code period and
the ms grid slip by one every few minutes) the phase of the last record before is carried
forward at its Doppler-shifted chip rate. Result: ``tow_sf, n_bits, n_codes, chips`` for
:func:`dsp.gnss.observables.pseudoranges_from_channels`.

Carrier phase (:meth:`ChannelNav.carrier_cycles`): the carrier NCO's phase minus the IF's,
summed exactly sample by sample from the carrier words the tracker wrote (double-buffered:
a word written in cycle ``b`` is in force from the first generator boundary after ``b``),
in cycles from the first record used, signed as Doppler (``s (f_NCO - f_IF)``, ``s = -1``
for an inverted spectrum). RINEX's ``L1C`` is its negative.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dsp.gnss.bitsync import CODES_PER_BIT, BitSync, bit_sync, nav_bits
from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, L1_HZ
from dsp.gnss.ephemeris import WEEK_S
from dsp.gnss.lnav import SUBFRAME_BITS
from dsp.gnss.lnav_decode import LnavDecodeResult, decode_lnav

from hdl.gnss.params import REG_CARR_FREQ

__all__ = ["ChannelNav", "channel_navigation", "CONFIRM_BITS"]

#: Bits after a subframe's end the decoder reads to confirm its frame sync (TLM + HOW).
CONFIRM_BITS = 60


@dataclass
class ChannelNav:
    """One channel's navigation (module doc). Arrays are over the records used."""

    prn: int
    channel: int
    status: str
    message: str
    fs_hz: float
    n_ms: int
    inverted: bool
    if_hz: float
    n_p: np.ndarray                       #: prompt boundary samples
    g: np.ndarray                         #: last whole-ms sample before each boundary
    code_phase: np.ndarray                #: prompt code phase (chips) at ``g``
    doppler: np.ndarray
    win_t: np.ndarray
    win_cn0: np.ndarray
    win_ok: np.ndarray
    carrier_words: list                   #: [(generator boundary sample from which, word)]
    carr_bits: int
    half_spacing: int
    bitsync: BitSync | None = None
    decode: LnavDecodeResult | None = None
    edge: int | None = None
    tow_ref: tuple | None = None          #: (subframe grid index m, tow_start) of a decoded one
    tow_sample: int | None = None
    eph_sample: int | None = None
    end_sample: int = 0

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def ephemeris(self):
        return None if self.decode is None else self.decode.ephemeris

    def record_at(self, n: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For whole-ms samples ``n``: the record index ``k``, the prompt code phase (chips)
        at ``n`` in record ``k``'s code period, and a mask of the samples inside the records
        used (module doc)."""
        n = np.asarray(n, dtype=np.int64)
        j = np.searchsorted(self.g, n, side="left")        # the first record with g >= n
        exact = (j < self.g.size) & (self.g[np.minimum(j, self.g.size - 1)] == n)
        j = np.where(exact, j, j - 1)                       # else the last before
        inside = (j >= 0) & (n < self.n_p[-1])
        j = np.clip(j, 0, max(self.g.size - 1, 0))
        rate = CHIP_RATE_HZ * (1 + self.doppler[j] / L1_HZ) / self.fs_hz
        chips = np.mod(self.code_phase[j] + (n - self.g[j]) * rate, CODE_LENGTH)
        k = np.searchsorted(self.n_p, n, side="right")     # n_p[k - 1] <= n < n_p[k]
        return k, chips, inside

    def counts(self, n):
        """``(tow_sf, n_bits, n_codes, chips, ok)`` at whole-ms samples ``n`` (module doc);
        ``ok`` false where the channel has no TOW or ``n`` is outside its records."""
        k, chips, ok = self.record_at(n)
        if not self.ok:
            z = np.zeros(k.shape, np.int64)
            return z.astype(float), z, z, np.zeros(k.shape), np.zeros(k.shape, bool)
        d = k - self.edge
        j, n_codes = np.divmod(d, CODES_PER_BIT)
        m, n_bits = np.divmod(j - self.decode.sync_bit, SUBFRAME_BITS)
        m_ref, tow_ref = self.tow_ref
        tow_sf = np.mod(tow_ref + 6.0 * (m - m_ref), WEEK_S)
        return tow_sf, n_bits, n_codes, chips, ok

    def carrier_cycles(self, n) -> np.ndarray:
        """The accumulated Doppler phase (cycles) at samples ``n`` since the first record
        used (module doc)."""
        n = np.asarray(n, dtype=np.int64)
        starts = np.array([s for s, _ in self.carrier_words], dtype=np.int64)
        per_sample = np.array([w / 2.0 ** self.carr_bits for _, w in self.carrier_words]) - \
            self.if_hz / self.fs_hz
        seg = np.diff(starts) * per_sample[:-1]
        cum = np.concatenate(([0.0], np.cumsum(seg)))
        i = np.clip(np.searchsorted(starts, n, side="right") - 1, 0, starts.size - 1)
        s = -1.0 if self.inverted else 1.0
        return s * (cum[i] + (n - starts[i]) * per_sample[i])

    def cn0_at(self, n) -> np.ndarray:
        """The C/N0 (dB-Hz) of the last lock window ending at or before samples ``n``."""
        t = np.asarray(n, dtype=np.float64) / self.fs_hz
        i = np.searchsorted(self.win_t, t, side="right") - 1
        return np.where(i >= 0, self.win_cn0[np.clip(i, 0, None)], np.nan) \
            if self.win_t.size else np.full(t.shape, np.nan)

    def as_dict(self) -> dict:
        d = self.decode
        return {"prn": self.prn, "channel": self.channel, "status": self.status,
                "message": self.message, "records": int(self.g.size),
                "bit_sync": None if self.bitsync is None else self.bitsync.as_dict(),
                "frame_sync_bit": None if d is None else d.sync_bit,
                "inverted": None if d is None else d.inverted,
                "subframes": [] if d is None else [
                    {"bit": s.bit_index, "id": s.subframe_id, "tow_start": s.tow_start}
                    for s in d.subframes],
                "parity_failures": 0 if d is None else len(d.parity_failures),
                "subframes_withheld": 0 if d is None else d.rejected_subframes,
                "ephemeris_decoded": d is not None and d.ephemeris is not None,
                "ephemeris_withheld": None if d is None else d.withheld,
                "tow_known_s": None if self.tow_sample is None else
                self.tow_sample / self.fs_hz,
                "ephemeris_known_s": None if self.eph_sample is None else
                self.eph_sample / self.fs_hz}


def _carrier_words(bus_writes, ch: int, n_w: np.ndarray, p):
    """[(sample from which, word)] of the carrier words in force over the generator
    boundaries ``n_w`` (module doc)."""
    addr = ch * 4 + REG_CARR_FREQ
    writes = sorted((int(b), int(v)) for b, a, v in bus_writes if int(a) == addr)
    cyc = np.array([b for b, _ in writes], dtype=np.int64)
    val = np.array([p.carr_word(p.if_hz)] + [v for _, v in writes], dtype=np.int64)
    w = val[np.searchsorted(cyc, n_w, side="left")]     # the last write before each boundary
    keep = np.concatenate(([True], w[1:] != w[:-1]))
    out = [(int(n) + 1, int(v)) for n, v in zip(n_w[keep], w[keep])]
    out.append((int(n_w[-1]) + 1 + 2 * int(np.median(np.diff(n_w))), out[-1][1]))
    return out


def channel_navigation(a, track, p, *, reference_week: int, inverted: bool,
                       if_hz: float) -> ChannelNav:
    """The navigation of assignment ``a`` of the run ``track`` on the array channel
    parameters ``p`` (module doc); never raises on weak data: the status says why."""
    fs = float(track.fs_hz)
    n_ms = int(round(fs * 1e-3))
    t = np.asarray(a.t, dtype=np.float64)
    n_p = np.round(t * fs).astype(np.int64)
    lock = a.lock_sample
    use = (n_p >= lock) if lock is not None else np.zeros(n_p.size, bool)
    if a.end_sample is not None:
        use &= n_p <= a.end_sample
    idx = np.flatnonzero(use)
    win_t = np.asarray(a.win_t, dtype=np.float64)
    win_ok = np.asarray(a.win_phase_lock, bool) & np.asarray(a.win_cn0_lock, bool)
    base = dict(prn=a.prn, channel=a.channel, fs_hz=fs, n_ms=n_ms, inverted=inverted,
                if_hz=float(if_hz), win_t=win_t, win_cn0=np.asarray(a.win_cn0, float),
                win_ok=win_ok, carr_bits=p.carr_phase_bits, half_spacing=p.half_spacing,
                end_sample=int(a.end_sample or 0))
    if idx.size < 2:
        return ChannelNav(status="not-locked", message="the channel never locked",
                          n_p=n_p[:0], g=n_p[:0], code_phase=np.zeros(0),
                          doppler=np.zeros(0), carrier_words=[], **base)
    n_p = n_p[idx]
    step = np.diff(n_p)
    if np.any(np.abs(step - n_ms) > n_ms // 10 + 2):
        raise RuntimeError(f"internal: PRN {a.prn}'s records are not consecutive code "
                           f"periods (steps {step.min()}..{step.max()} samples)")
    g = (n_p // n_ms) * n_ms
    nav = ChannelNav(status="", message="", n_p=n_p, g=g,
                     code_phase=np.asarray(a.code_phase, float)[idx],
                     doppler=np.asarray(a.doppler, float)[idx],
                     carrier_words=_carrier_words(track.bus_writes, a.channel,
                                                  n_p - 1 - p.half_spacing, p), **base)
    ip = np.asarray(a.ip, float)[idx]
    nav.bitsync = bit_sync(ip)
    if not nav.bitsync.ok:
        nav.status, nav.message = "no-bit-sync", nav.bitsync.message
        return nav
    nav.edge = nav.bitsync.edge
    sums, first = nav_bits(ip, nav.edge)
    sums = np.where(sums == 0.0, 1e-9, sums)          # no sign: parity decides
    nav.decode = d = decode_lnav(sums, a.prn, reference_week=reference_week)
    if d.sync_bit is None or not d.subframes:
        nav.status = "no-frame-sync"
        nav.message = "no confirmed frame sync" if d.sync_bit is None else \
            "frame sync but no parity-clean subframe"
        return nav
    sf0 = d.subframes[0]
    nav.tow_ref = ((sf0.bit_index - d.sync_bit) // SUBFRAME_BITS, sf0.tow_start)

    def bit_end_sample(bit: int) -> int:
        r = min(int(first[0]) + CODES_PER_BIT * bit, n_p.size - 1)
        return int(n_p[r])

    nav.tow_sample = bit_end_sample(sf0.bit_index + SUBFRAME_BITS + CONFIRM_BITS)
    seen = set()
    for s in d.subframes:
        seen.add(s.subframe_id)
        if d.ephemeris is not None and {1, 2, 3} <= seen:
            nav.eph_sample = bit_end_sample(s.bit_index + SUBFRAME_BITS)
            break
    nav.status = "ok"
    nav.message = (f"{len(d.subframes)} subframes decoded, "
                   f"{len(d.parity_failures)} words failed parity")
    return nav
