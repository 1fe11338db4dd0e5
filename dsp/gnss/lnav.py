"""The GPS LNAV navigation message (IS-GPS-200 section 20.3): parity and the encoder.

Structure (20.3.2, Figure 20-1)
-------------------------------
A frame is 1500 bits at 50 bit/s (30 s): five subframes of ten 30-bit words, transmitted
MSB (bit 1) first. Each word carries 24 data bits and 6 parity bits. Word 1 of every subframe
is the TLM word (the preamble 10001011, a 14-bit TLM message, the integrity status flag, a
reserved bit), word 2 the HOW (the 17-bit truncated TOW count of the *next* subframe's start
in 6 s units, the alert and anti-spoof flags, the 3-bit subframe ID, two non-information bits
``t``). Subframes 1-3 carry the clock and ephemeris of the transmitting satellite (Tables
20-I and 20-III, :mod:`dsp.gnss.lnav_fields`); subframes 4 and 5 carry 25 pages each. This
encoder transmits page 18 of subframe 4 (ionosphere and UTC, 20.3.3.5.1.6/7, data ID 01, SV ID
56) and page 25 of subframe 5 (almanac reference time and the 6-bit health of SVs 1-24,
20.3.3.5.1.3, SV ID 51) in every frame: a simulator's subset of the 12.5-minute superframe (no
almanac pages). Reserved bits are sent as zeros.

Words 3-10 of a subframe hold 8 x 24 = 192 data bits; a field split across words (M0, e,
sqrtA, Omega0, i0, omega, A0: 8 MSBs ending one word, 24 LSBs filling the next) is
contiguous in that 192-bit string, so each subframe is described here as its fields in
transmission order, with the IODC of subframe 1 (2 MSBs in word 3, 8 LSBs in word 8) as two
fields.

Parity (20.3.5.2, Table 20-XIV)
-------------------------------
``D25..D30`` are sums modulo 2 of the source data bits ``d1..d24`` and of bit 29 or 30 of the
previous transmitted word (``D29*``, ``D30*``); the transmitted data bits are ``D_i = d_i XOR
D30*`` (complemented when ``D30* = 1``). The two ``t`` bits (bits 23, 24) of words 2 and 10 are
solved so that the word's ``D29`` and ``D30`` are 0: the next word, and the next subframe's TLM
word (so its preamble), are then never complemented.

Bits are ``uint8`` arrays of 0/1 in transmission order; a word is an ``int`` of 30 bits with
bit 1 as its MSB.
"""
from __future__ import annotations

import numpy as np

from .ephemeris import WEEK_S, Ephemeris, KlobucharParameters, UtcParameters
from .lnav_fields import EPHEMERIS_FIELDS, IONO_FIELDS, UTC_FIELDS, check_integer, \
    field_integer, to_unsigned

PREAMBLE = 0b10001011
WORD_BITS = 30
SUBFRAME_BITS = 300
FRAME_BITS = 1500
#: The HOW TOW count wraps at the end of the week: 604800 s / 6 s.
TOW_COUNT_MAX = 100800
#: Subframe 4 page 18 and subframe 5 page 25 SV (page) IDs, 20.3.3.5.1 (Table 20-V).
PAGE18_SV_ID = 56
PAGE25_SV_ID = 51
#: The LNAV data ID (20.3.3.5.1.1).
DATA_ID = 1

#: Table 20-XIV: (D29* or D30*, the source data bits summed) for parity bits D25 .. D30.
PARITY_TAPS = (
    (29, (1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23)),
    (30, (2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24)),
    (29, (1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22)),
    (30, (2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23)),
    (30, (1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24)),
    (29, (3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24)),
)


def _mask(taps) -> int:
    m = 0
    for i in taps:
        m |= 1 << (24 - i)
    return m


_MASKS = tuple((star, _mask(taps)) for star, taps in PARITY_TAPS)

#: Words 3-10 of each subframe as (field, bits) in transmission order (192 bits). Fields
#: named "reserved*" are zeros; "t" are the parity-solving bits of word 10.
SUBFRAME_LAYOUT = {
    1: (("week", 10), ("l2_codes", 2), ("ura_index", 4), ("health", 6), ("IODC_msb", 2),
        ("l2p_flag", 1), ("reserved", 23), ("reserved", 24), ("reserved", 24),
        ("reserved", 16), ("TGD", 8), ("IODC_lsb", 8), ("toc", 16), ("af2", 8),
        ("af1", 16), ("af0", 22), ("t", 2)),
    2: (("IODE", 8), ("Crs", 16), ("deltaN", 16), ("M0", 32), ("Cuc", 16), ("e", 32),
        ("Cus", 16), ("sqrtA", 32), ("toe", 16), ("fit_interval_flag", 1), ("aodo", 5),
        ("t", 2)),
    3: (("Cic", 16), ("Omega0", 32), ("Cis", 16), ("i0", 32), ("Crc", 16), ("omega", 32),
        ("OmegaDot", 24), ("IODE", 8), ("IDOT", 14), ("t", 2)),
    4: (("data_id", 2), ("sv_id", 6)) + tuple((f.name, 8) for f in IONO_FIELDS)
       + (("A1", 24), ("A0", 32), ("tot", 8), ("WNt", 8), ("dtLS", 8), ("WNLSF", 8),
          ("DN", 8), ("dtLSF", 8), ("reserved", 14), ("t", 2)),
    5: (("data_id", 2), ("sv_id", 6), ("toa", 8), ("WNa", 8))
       + tuple((f"health{k}", 6) for k in range(1, 25)) + (("reserved", 22), ("t", 2)),
}
for _sf, _lay in SUBFRAME_LAYOUT.items():
    assert sum(b for _, b in _lay) == 192, _sf


def parity(d24: int, d29s: int, d30s: int) -> int:
    """The six parity bits D25..D30 (as a 6-bit int, D25 the MSB) of source data ``d24``
    (d1 the MSB) after a word ending in ``D29*``, ``D30*`` (Table 20-XIV)."""
    p = 0
    for star, m in _MASKS:
        b = (d29s if star == 29 else d30s) ^ (bin(d24 & m).count("1") & 1)
        p = (p << 1) | b
    return p


def encode_word(d24: int, prev_word: int) -> int:
    """The transmitted 30-bit word of source data ``d24`` after the transmitted word
    ``prev_word`` (only its bits 29, 30 matter): data complemented when ``D30* = 1``, then the
    parity of Table 20-XIV."""
    d29s, d30s = (prev_word >> 1) & 1, prev_word & 1
    data = d24 ^ (0xFFFFFF if d30s else 0)
    return (data << 6) | parity(d24, d29s, d30s)


def check_word(word: int, prev_word: int) -> int | None:
    """The source data (24 bits) of a received 30-bit ``word`` after ``prev_word``, or ``None``
    when its parity fails."""
    d30s = prev_word & 1
    d24 = (word >> 6) ^ (0xFFFFFF if d30s else 0)
    if parity(d24, (prev_word >> 1) & 1, d30s) != word & 0x3F:
        return None
    return d24


def encode_word_solved(d22: int, prev_word: int) -> int:
    """Word 2 or 10: 22 data bits, the two ``t`` bits (23, 24) chosen so the transmitted word
    ends in D29 = D30 = 0 (20.3.5.2)."""
    for t in range(4):
        w = encode_word((d22 << 2) | t, prev_word)
        if w & 0b11 == 0:
            return w
    raise AssertionError("no t bits zero D29, D30")  # Table 20-XIV always has a solution


def words_to_bits(words) -> np.ndarray:
    """30-bit words -> their bits (uint8 0/1), MSB first."""
    w = np.asarray(words, dtype=np.int64)[:, None]
    return ((w >> np.arange(29, -1, -1)) & 1).astype(np.uint8).ravel()


def bits_to_words(bits) -> list[int]:
    """Bits (a multiple of 30) -> 30-bit words, MSB first."""
    b = np.asarray(bits, dtype=np.int64).reshape(-1, WORD_BITS)
    return [int(x) for x in b @ (1 << np.arange(29, -1, -1, dtype=np.int64))]


def pack_fields(layout, values: dict) -> list[int]:
    """The 192 data bits of words 3-10 from field integers (two's complement patterns
    already applied) as eight 24-bit ints; ``t`` and reserved fields are zero."""
    acc = 0
    for name, bits in layout:
        v = 0 if name == "t" or name.startswith("reserved") else values[name]
        if not 0 <= v < (1 << bits):
            raise ValueError(f"LNAV field {name} = {v} does not fit {bits} bits")
        acc = (acc << bits) | v
    return [(acc >> (24 * (7 - k))) & 0xFFFFFF for k in range(8)]


def unpack_fields(layout, data: list[int]) -> dict:
    """Field bit patterns (unsigned) of words 3-10 (eight 24-bit ints) by ``layout``."""
    acc = 0
    for d in data:
        acc = (acc << 24) | d
    out, pos = {}, 192
    for name, bits in layout:
        pos -= bits
        out[name] = (acc >> pos) & ((1 << bits) - 1)
    return out


def _scaled(fields_, obj, names, what):
    return {n: to_unsigned(field_integer(fields_[n], getattr(obj, n), what=what),
                           fields_[n].bits) for n in names}


def subframe_values(eph: Ephemeris, iono: KlobucharParameters, utc: UtcParameters | None,
                    week: int, sv_health=None, almanac_ref=None) -> dict:
    """Field bit patterns of subframes 1-5 (subframe ID -> {field: unsigned int})."""
    what = f"LNAV G{eph.prn:02d}: "
    sf1 = _scaled(EPHEMERIS_FIELDS, eph, ("TGD", "toc", "af2", "af1", "af0"), what)
    sf1.update(week=week % 1024, l2_codes=eph.l2_codes, ura_index=eph.ura_index,
               health=eph.health, IODC_msb=eph.IODC >> 8, IODC_lsb=eph.IODC & 0xFF,
               l2p_flag=eph.l2p_flag)
    sf2 = _scaled(EPHEMERIS_FIELDS, eph, ("Crs", "deltaN", "M0", "Cuc", "e", "Cus", "sqrtA",
                                          "toe"), what)
    sf2.update(IODE=eph.IODE, fit_interval_flag=eph.fit_interval_flag, aodo=eph.aodo)
    sf3 = _scaled(EPHEMERIS_FIELDS, eph, ("Cic", "Omega0", "Cis", "i0", "Crc", "omega",
                                          "OmegaDot", "IDOT"), what)
    sf3.update(IODE=eph.IODE)
    sf4 = {"data_id": DATA_ID, "sv_id": PAGE18_SV_ID}
    for f, x in zip(IONO_FIELDS, iono.alpha + iono.beta):
        sf4[f.name] = to_unsigned(field_integer(f, x, what="LNAV ionosphere: "), f.bits)
    if utc is None:
        sf4.update({n: 0 for n in UTC_FIELDS})
    else:
        sf4.update(_scaled(UTC_FIELDS, utc, tuple(UTC_FIELDS), "LNAV UTC: "))
    toa_s, wna = almanac_ref if almanac_ref is not None else \
        (4096.0 * np.floor(eph.toe / 4096.0), week)
    health = [0] * 24 if sv_health is None else list(sv_health)
    if len(health) != 24:
        raise ValueError(f"sv_health: {len(health)} values, expected 24 (SVs 1-24)")
    sf5 = {"data_id": DATA_ID, "sv_id": PAGE25_SV_ID, "toa": check_integer(
        "toa / 4096 s", 8, float(toa_s) / 4096.0), "WNa": int(wna) % 256}
    for k, h in enumerate(health, start=1):
        sf5[f"health{k}"] = check_integer(f"sv_health[{k - 1}]", 6, h)
    return {1: sf1, 2: sf2, 3: sf3, 4: sf4, 5: sf5}


def encode_subframe(sf_id: int, data_words: list[int], tow_start: float, prev_word: int, *,
                    tlm_message: int = 0, integrity: int = 0, alert: int = 0,
                    anti_spoof: int = 0) -> list[int]:
    """The ten transmitted words of the subframe ``sf_id`` starting at second ``tow_start`` of
    the week: TLM, HOW (TOW count of the next subframe), words 3-10 from ``data_words`` (word
    10's two low bits are the ``t`` bits, solved here)."""
    tlm = (PREAMBLE << 16) | (check_integer("tlm_message", 14, tlm_message) << 2) \
        | (check_integer("integrity", 1, integrity) << 1)
    tow_count = (int(round(tow_start / 6.0)) + 1) % TOW_COUNT_MAX
    how22 = (tow_count << 5) | (check_integer("alert", 1, alert) << 4) \
        | (check_integer("anti_spoof", 1, anti_spoof) << 3) | sf_id
    words = [encode_word(tlm, prev_word)]
    words.append(encode_word_solved(how22, words[-1]))
    for k, d in enumerate(data_words):
        words.append(encode_word(d, words[-1]) if k < 7 else
                     encode_word_solved(d >> 2, words[-1]))
    return words


def encode_frames(eph: Ephemeris, iono: KlobucharParameters, week: int, tow: float,
                  n_frames: int = 1, *, utc: UtcParameters | None = None, sv_health=None,
                  almanac_ref=None, tlm_message: int = 0, integrity: int = 0, alert: int = 0,
                  anti_spoof: int = 0, prev_bits=(0, 0)) -> np.ndarray:
    """The LNAV bits (uint8 0/1, ``1500 n_frames``) of ``n_frames`` frames of ``eph`` from GPS
    time (``week``, ``tow``) on: ``week`` is the full GPS week of transmission (WN is sent
    modulo 1024), ``tow`` a multiple of 30 s (subframe 1 starts a frame). Every field is
    rounded to its LNAV grid: the receiver decodes ``eph.quantised()``. ``sv_health``: the 24
    six-bit health codes of subframe 5 page 25 (default all 0), ``almanac_ref``: its (toa in
    s, full week) (default toe rounded down to 4096 s, ``week``). ``prev_bits``: bits 29, 30
    of the word sent before the first TLM word. A ``ValueError`` names the parameter that
    does not fit its field."""
    if not isinstance(eph, Ephemeris):
        raise TypeError(f"eph: expected an Ephemeris, got {type(eph).__name__}")
    if not isinstance(iono, KlobucharParameters):
        raise TypeError(f"iono: expected KlobucharParameters, got {type(iono).__name__}")
    if isinstance(week, bool) or not isinstance(week, (int, np.integer)) or week < 0:
        raise ValueError(f"week = {week!r} is not a GPS week number")
    if not (0.0 <= tow < WEEK_S and float(tow) % 30.0 == 0.0):
        raise ValueError(f"tow = {tow!r} is not a frame start (a multiple of 30 s in the week)")
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) \
            or n_frames < 1:
        raise ValueError(f"n_frames = {n_frames!r} is not a positive integer")
    vals = subframe_values(eph, iono, utc, int(week), sv_health, almanac_ref)
    data = {k: pack_fields(SUBFRAME_LAYOUT[k], v) for k, v in vals.items()}
    prev = ((int(prev_bits[0]) & 1) << 1) | (int(prev_bits[1]) & 1)
    words = []
    t, wk = float(tow), int(week)
    for _ in range(n_frames):
        if t >= WEEK_S:  # the week turns between frames: WN counts on
            t, wk = t - WEEK_S, wk + 1
            data[1] = pack_fields(SUBFRAME_LAYOUT[1], dict(vals[1], week=wk % 1024))
        for sf in range(1, 6):
            w = encode_subframe(sf, data[sf], t, prev, tlm_message=tlm_message,
                                integrity=integrity, alert=alert, anti_spoof=anti_spoof)
            words.extend(w)
            prev = w[-1]
            t += 6.0
    return words_to_bits(words)
