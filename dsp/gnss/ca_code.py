"""GPS L1 C/A Gold codes per IS-GPS-200 (section 3.3.2.3, Table 3-Ia).

The single source of the standard for the DSP, the signal generator and the HDL model.

G1 and G2 are 10-stage shift registers, both set to all ones at the start of every code
period (1023 chips, 1 ms at 1.023 Mcps):

* G1 = 1 + x^3 + x^10:   new stage 1 = stage 3 XOR stage 10; output stage 10;
* G2 = 1 + x^2 + x^3 + x^6 + x^8 + x^9 + x^10: new stage 1 = XOR of stages 2, 3, 6, 8, 9,
  10; the PRN's G2i is the XOR of the two phase-selector stages of :data:`G2_TAPS`, which
  equals G2's output (stage 10) delayed by :data:`G2_DELAY_CHIPS` chips;
* C/A = G1 XOR G2i, as logic levels; logic 0 is the +1 signal level, logic 1 is -1.

:data:`FIRST_10_CHIPS_OCTAL` is the standard's check column ("first 10 chips, octal", the
first chip is the MSB); tests regenerate it from the registers.
"""
from __future__ import annotations

import numpy as np

#: Chips per code period.
CODE_LENGTH = 1023
#: Chipping rate, chip/s.
CHIP_RATE_HZ = 1.023e6
#: Code period, s.
CODE_PERIOD_S = 1e-3
#: L1 carrier, Hz; carrier Doppler / code Doppler = L1 / chip rate = 1540.
L1_HZ = 1575.42e6
#: Valid PRN numbers.
PRN_MIN, PRN_MAX = 1, 32

#: G1 and G2 feedback stages (1-based, stage 10 is the output).
G1_FEEDBACK = (3, 10)
G2_FEEDBACK = (2, 3, 6, 8, 9, 10)

#: IS-GPS-200 Table 3-Ia, PRN 1..32: G2 phase-selector stages (1-based).
G2_TAPS = {
    1: (2, 6), 2: (3, 7), 3: (4, 8), 4: (5, 9), 5: (1, 9), 6: (2, 10), 7: (1, 8), 8: (2, 9),
    9: (3, 10), 10: (2, 3), 11: (3, 4), 12: (5, 6), 13: (6, 7), 14: (7, 8), 15: (8, 9),
    16: (9, 10), 17: (1, 4), 18: (2, 5), 19: (3, 6), 20: (4, 7), 21: (5, 8), 22: (6, 9),
    23: (1, 3), 24: (4, 6), 25: (5, 7), 26: (6, 8), 27: (7, 9), 28: (8, 10), 29: (1, 6),
    30: (2, 7), 31: (3, 8), 32: (4, 9),
}
#: IS-GPS-200 Table 3-Ia: code delay of G2i behind G2, chips.
G2_DELAY_CHIPS = {
    1: 5, 2: 6, 3: 7, 4: 8, 5: 17, 6: 18, 7: 139, 8: 140, 9: 141, 10: 251, 11: 252, 12: 254,
    13: 255, 14: 256, 15: 257, 16: 258, 17: 469, 18: 470, 19: 471, 20: 472, 21: 473, 22: 474,
    23: 509, 24: 512, 25: 513, 26: 514, 27: 515, 28: 516, 29: 859, 30: 860, 31: 861, 32: 862,
}
#: IS-GPS-200 Table 3-Ia: first 10 chips of each code, octal (first chip = MSB).
FIRST_10_CHIPS_OCTAL = {
    1: 0o1440, 2: 0o1620, 3: 0o1710, 4: 0o1744, 5: 0o1133, 6: 0o1455, 7: 0o1131, 8: 0o1454,
    9: 0o1626, 10: 0o1504, 11: 0o1642, 12: 0o1750, 13: 0o1764, 14: 0o1772, 15: 0o1775,
    16: 0o1776, 17: 0o1156, 18: 0o1467, 19: 0o1633, 20: 0o1715, 21: 0o1746, 22: 0o1763,
    23: 0o1063, 24: 0o1706, 25: 0o1743, 26: 0o1761, 27: 0o1770, 28: 0o1774, 29: 0o1127,
    30: 0o1453, 31: 0o1625, 32: 0o1712,
}


def check_prn(prn) -> int:
    """``prn`` as an int, or ``ValueError`` if it is not a GPS PRN 1-32."""
    if isinstance(prn, bool) or not isinstance(prn, (int, np.integer)) \
            or not PRN_MIN <= int(prn) <= PRN_MAX:
        raise ValueError(f"PRN must be an integer in [{PRN_MIN}, {PRN_MAX}], not {prn!r}")
    return int(prn)


def lfsr_sequence(feedback, n: int = CODE_LENGTH, taps=(10,)) -> np.ndarray:
    """``n`` outputs (uint8) of a 10-stage register from all ones: each output is the XOR of
    the stages ``taps`` before the shift; ``feedback`` are the stages XORed into stage 1."""
    s = [1] * 10  # s[k] is stage k+1
    out = np.empty(n, dtype=np.uint8)
    for j in range(n):
        v = 0
        for t in taps:
            v ^= s[t - 1]
        out[j] = v
        fb = 0
        for t in feedback:
            fb ^= s[t - 1]
        s = [fb] + s[:9]
    return out


def g1() -> np.ndarray:
    """One period of G1 (logic levels, uint8)."""
    return lfsr_sequence(G1_FEEDBACK)


def g2i(prn: int) -> np.ndarray:
    """One period of the PRN's G2i from the phase selector (logic levels, uint8)."""
    return lfsr_sequence(G2_FEEDBACK, taps=G2_TAPS[check_prn(prn)])


def ca_code(prn: int) -> np.ndarray:
    """One period (1023 chips) of the PRN's C/A code as logic levels 0/1 (uint8)."""
    return g1() ^ g2i(prn)


def ca_code_levels(prn: int) -> np.ndarray:
    """One period as signal levels (int8): logic 0 -> +1, logic 1 -> -1."""
    return (1 - 2 * ca_code(prn).astype(np.int8)).astype(np.int8)


def ca_code_table() -> np.ndarray:
    """``(33, 1023)`` uint8: row ``p`` is PRN ``p``'s code, row 0 is G1 alone (what the HDL
    generator puts out for a PRN register value outside 1-32)."""
    t = np.empty((PRN_MAX + 1, CODE_LENGTH), dtype=np.uint8)
    t[0] = g1()
    for p in range(PRN_MIN, PRN_MAX + 1):
        t[p] = ca_code(p)
    return t


def first_10_chips_octal(code: np.ndarray) -> int:
    """The standard's check value of a code: its first 10 chips read as a binary number."""
    v = 0
    for c in np.asarray(code)[:10]:
        v = (v << 1) | int(c)
    return v
