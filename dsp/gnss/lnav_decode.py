"""Decoding the GPS LNAV message (IS-GPS-200 section 20.3) from a bit stream of unknown
polarity: frame synchronisation, parity, subframes -> ephemeris, ionosphere, UTC, health.

Input
-----
``symbols``: hard bits (``bool`` or integers, all 0 or 1) or soft values (any other real
array: the sign carries the bit, positive -> 0, negative -> 1, the BPSK map; a soft value of
exactly 0 has no sign and is refused). The polarity of a tracked carrier phase is ambiguous
by 180 degrees, so the stream may arrive complemented; the decoder finds out which.

Synchronisation (20.3.2, 20.3.5)
--------------------------------
A candidate subframe start is a preamble 10001011 (or its complement: the inverted
polarity; the TLM word is never complemented by parity, since every word 10 ends in
D29 = D30 = 0) whose TLM and HOW words pass parity, with a HOW ending in 00 and a subframe
ID 1..5. It is confirmed by the next subframe 300 bits (6 s) later: a preamble again, TLM
and HOW passing parity, the subframe ID following (5 -> 1) and the TOW count one more
(modulo 100800). The first confirmed candidate (lowest bit index over both polarities) fixes
the subframe grid and the polarity.

Use of the words
----------------
Every word of every subframe on the grid is parity-checked with D29*, D30* of the word
before it (Table 20-XIV); a word that fails is recorded in ``parity_failures`` and never
used. A subframe is used only when all ten words pass and its HOW's subframe ID is the one
the grid expects. Subframes 1-3 make an ephemeris only when IODC's 8 LSBs, subframe 2's IODE
and subframe 3's IODE agree (20.3.4.4: the three subframes are of one data set); the latest
such triple is returned; otherwise no ephemeris is returned and ``withheld`` says why.
Subframe 4 page 18 (SV ID 56) gives the Klobuchar coefficients and the UTC parameters,
subframe 5 page 25 (SV ID 51) the health of SVs 1-24.

The week: WN is the transmission week modulo 1024; ``reference_week`` (a full GPS week
within 512 weeks of the truth, e.g. from a RINEX file or the receiver's clock) resolves
it. The ephemeris's ``week`` is the week of toe: the transmission week, one more or one less
when toe lies more than half a week after or before the transmission time.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .ephemeris import HALF_WEEK_S, Ephemeris, KlobucharParameters, UtcParameters
from .lnav import PAGE18_SV_ID, PAGE25_SV_ID, PREAMBLE, SUBFRAME_BITS, SUBFRAME_LAYOUT, \
    TOW_COUNT_MAX, WORD_BITS, bits_to_words, check_word, unpack_fields
from .lnav_fields import EPHEMERIS_FIELDS, IONO_FIELDS, UTC_FIELDS, from_unsigned, \
    integer_value


@dataclass(frozen=True)
class WordFailure:
    """A word whose parity failed: its first bit's index in the input, the subframe ID the
    grid expects there, the word number 1..10."""

    bit_index: int
    subframe_id: int
    word: int


@dataclass(frozen=True)
class Subframe:
    """A parity-clean subframe: first bit's index, ID, the HOW TOW count (the next subframe
    starts at ``6 * tow_count`` s of the week) and the source data of words 1-10."""

    bit_index: int
    subframe_id: int
    tow_count: int
    data: tuple

    @property
    def tow_start(self) -> float:
        """Seconds of the week at which this subframe's first bit was sent."""
        return float((self.tow_count - 1) % TOW_COUNT_MAX * 6)


@dataclass(frozen=True)
class LnavDecodeResult:
    """What :func:`decode_lnav` found (``sync_bit`` is ``None`` when no frame sync was
    confirmed, and then everything else is empty)."""

    sync_bit: int | None
    inverted: bool | None
    subframes: tuple
    parity_failures: tuple
    rejected_subframes: int
    ephemeris: Ephemeris | None
    withheld: str | None
    iono: KlobucharParameters | None
    utc: UtcParameters | None
    sv_health: tuple | None


def hard_bits(symbols) -> np.ndarray:
    """Symbols (hard 0/1 bits or soft values, see the module notes) -> bits (uint8 0/1)."""
    x = np.asarray(symbols)
    if x.ndim != 1 or x.size == 0:
        raise ValueError(f"symbols: expected a non-empty 1-D array, got shape {x.shape}")
    if x.dtype == bool:
        return x.astype(np.uint8)
    if not np.issubdtype(x.dtype, np.number) or np.iscomplexobj(x):
        raise ValueError(f"symbols: expected real numbers, got dtype {x.dtype}")
    if np.issubdtype(x.dtype, np.integer) and np.all((x == 0) | (x == 1)):
        return x.astype(np.uint8)
    xf = x.astype(np.float64)
    bad = ~np.isfinite(xf) | (xf == 0.0)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"symbols[{i}] = {x[i].item()!r}: a soft value must be finite and "
                         f"non-zero (its sign is the bit)")
    return (xf < 0).astype(np.uint8)


def _word_at(b: np.ndarray, i: int) -> int:
    return bits_to_words(b[i:i + WORD_BITS])[0]


def _prev_at(b: np.ndarray, i: int) -> int:
    """Bits 29, 30 of the word before bit ``i`` (zeros before the stream's start)."""
    return (int(b[i - 2]) << 1 | int(b[i - 1])) if i >= 2 else 0


def _header(b: np.ndarray, i: int):
    """(subframe ID, TOW count) of a subframe starting at bit ``i`` whose preamble is there and
    whose TLM and HOW pass parity (HOW ending in 00, ID 1..5); else ``None``."""
    if i + 2 * WORD_BITS > b.size:
        return None
    tlm = _word_at(b, i)
    d_tlm = check_word(tlm, _prev_at(b, i))
    if d_tlm is None or d_tlm >> 16 != PREAMBLE:
        return None
    how = _word_at(b, i + WORD_BITS)
    d_how = check_word(how, tlm)
    if d_how is None or how & 0b11:
        return None
    sf_id = (d_how >> 2) & 0b111
    if not 1 <= sf_id <= 5:
        return None
    return sf_id, d_how >> 7


def find_sync(bits: np.ndarray):
    """(first bit index, inverted) of the first confirmed subframe start, or ``None``."""
    pre = np.array([(PREAMBLE >> (7 - k)) & 1 for k in range(8)], dtype=np.uint8)
    best = None
    for inverted in (False, True):
        b = bits ^ np.uint8(inverted)
        if b.size < 8:
            continue
        win = np.lib.stride_tricks.sliding_window_view(b, 8)
        for i in np.flatnonzero(np.all(win == pre, axis=1)):
            i = int(i)
            if best is not None and i >= best[0]:
                break
            h0 = _header(b, i)
            h1 = _header(b, i + SUBFRAME_BITS) if h0 else None
            if h1 and h1[0] == h0[0] % 5 + 1 and h1[1] == (h0[1] + 1) % TOW_COUNT_MAX:
                best = (i, inverted)
                break
    return best


def decode_lnav(symbols, prn: int, *, reference_week: int) -> LnavDecodeResult:
    """Decode the LNAV stream ``symbols`` of satellite ``prn`` (see the module notes):
    synchronise, parity-check every word, and assemble the ephemeris (with ``week`` resolved
    near ``reference_week``), the ionosphere, UTC and health pages."""
    if isinstance(prn, bool) or not isinstance(prn, (int, np.integer)) or not 1 <= prn <= 32:
        raise ValueError(f"prn = {prn!r} is not a GPS PRN 1..32")
    if isinstance(reference_week, bool) or not isinstance(reference_week, (int, np.integer)) \
            or reference_week < 0:
        raise ValueError(f"reference_week = {reference_week!r} is not a GPS week number")
    bits = hard_bits(symbols)
    sync = find_sync(bits)
    if sync is None:
        return LnavDecodeResult(None, None, (), (), 0, None, "no frame sync", None, None, None)
    start, inverted = sync
    b = bits ^ np.uint8(inverted)
    first_id = _header(b, start)[0]
    subframes, failures, rejected = [], [], 0
    for k, i in enumerate(range(start, b.size - SUBFRAME_BITS + 1, SUBFRAME_BITS)):
        expect = (first_id - 1 + k) % 5 + 1
        prev, data = _prev_at(b, i), []
        for w in range(10):
            word = _word_at(b, i + w * WORD_BITS)
            d = check_word(word, prev)
            if d is None:
                failures.append(WordFailure(i + w * WORD_BITS, expect, w + 1))
            data.append(d)
            prev = word
        if any(d is None for d in data) or data[0] >> 16 != PREAMBLE \
                or (data[1] >> 2) & 0b111 != expect:
            rejected += 1
            continue
        subframes.append(Subframe(i, expect, data[1] >> 7, tuple(data)))
    eph, why = _ephemeris(subframes, prn, reference_week)
    iono = utc = health = None
    for sf in subframes:
        v = unpack_fields(SUBFRAME_LAYOUT[sf.subframe_id], list(sf.data[2:]))
        if sf.subframe_id == 4 and v["sv_id"] == PAGE18_SV_ID:
            iono, utc = _page18(v)
        elif sf.subframe_id == 5 and v["sv_id"] == PAGE25_SV_ID:
            health = tuple(v[f"health{k}"] for k in range(1, 25))
    return LnavDecodeResult(start, inverted, tuple(subframes), tuple(failures), rejected,
                            eph, why, iono, utc, health)


def _signed(fields_, v, name):
    f = fields_[name]
    return integer_value(f, from_unsigned(v[name], f.bits, f.signed))


def _page18(v):
    iono_fields = {f.name: f for f in IONO_FIELDS}
    x = [_signed(iono_fields, v, f.name) for f in IONO_FIELDS]
    utc = UtcParameters(**{n: _signed(UTC_FIELDS, v, n) for n in UTC_FIELDS})
    return KlobucharParameters(tuple(x[:4]), tuple(x[4:])), utc


def _ephemeris(subframes, prn: int, reference_week: int):
    """The latest consistent subframe 1-3 triple as an Ephemeris, or (None, reason)."""
    latest = {}
    found = None
    for sf in subframes:
        if sf.subframe_id in (1, 2, 3):
            latest[sf.subframe_id] = sf
            if len(latest) == 3:
                v = {k: unpack_fields(SUBFRAME_LAYOUT[k], list(s.data[2:]))
                     for k, s in latest.items()}
                if v[1]["IODC_lsb"] == v[2]["IODE"] == v[3]["IODE"]:
                    found = (latest[1], v)
    if found is None:
        missing = sorted({1, 2, 3} - set(latest))
        why = (f"no parity-clean subframe {', '.join(map(str, missing))}" if missing
               else "IODC/IODE of subframes 1-3 disagree (data set cut over)")
        return None, why
    sf1, v = found
    wn = v[1]["week"]
    week_tx = reference_week + ((wn - reference_week + 512) % 1024) - 512
    kw = {}
    for k in (1, 2, 3):
        for name in v[k]:
            if name in EPHEMERIS_FIELDS:
                kw[name] = _signed(EPHEMERIS_FIELDS, v[k], name)
    dt = kw["toe"] - sf1.tow_start
    week = week_tx + (1 if dt < -HALF_WEEK_S else -1 if dt >= HALF_WEEK_S else 0)
    eph = Ephemeris(prn=prn, week=week, IODE=v[2]["IODE"],
                    IODC=(v[1]["IODC_msb"] << 8) | v[1]["IODC_lsb"], health=v[1]["health"],
                    ura_index=v[1]["ura_index"], fit_interval_flag=v[2]["fit_interval_flag"],
                    l2_codes=v[1]["l2_codes"], l2p_flag=v[1]["l2p_flag"], aodo=v[2]["aodo"],
                    **kw)
    return eph, None
