"""GPS L1 C/A bit synchronisation and navigation-bit extraction from 1 ms prompts.

A C/A channel dumps one prompt per code period (1 ms); an LNAV data bit lasts 20 code
periods and its edges fall on code-period boundaries (IS-GPS-200 20.3.2), so the bit edge is
one of 20 positions of the prompt index modulo 20.

Histogram method (:func:`bit_sync`)
-----------------------------------
For consecutive in-phase prompts ``I_k`` (a phase-locked channel: the data sign is in
``I``), a *sign change* at ``k`` is ``sign I_k != sign I_{k-1}``; it is counted in bin
``k mod 20``. A data transition changes the sign at the bit edge; noise changes it anywhere
(at 45 dB-Hz practically never, at 30 dB-Hz about one prompt in 12). The edge is the bin
``e`` with the most changes.

Confidence rule: the edge is declared only when the winning bin holds at least
``min_changes`` sign changes (:data:`MIN_CHANGES`) **and** stands out from the next-best
bin, either by holding at least ``dominance`` times (:data:`DOMINANCE`) as many changes (the
rule for few changes: a strong signal) or by a significant excess, ``win - next >= z
sqrt(win + next)`` with ``z`` = :data:`SIGNIFICANCE` (the two counts taken as Poisson: the
rule for many changes, a weak signal over a long stream). Otherwise the status says why
(``too-short``: fewer than :data:`MIN_PROMPTS` prompts; ``too-few-changes``: the winning bin
is below ``min_changes``, e.g. a satellite with a long run of equal bits; ``ambiguous``: no
dominant bin, e.g. noise only or a channel not in phase lock) and no edge is given. With
random data half the bit edges are transitions, so at high C/N0 ``min_changes = 8`` needs
about 16 bits (0.3 s); pure noise spreads its changes evenly over the 20 bins and fails
both tests; at 27 dB-Hz a minute of prompts passes the significance test.

Bits (:func:`nav_bits`)
-----------------------
Given the edge ``e``, bit ``j`` is the sum of the 20 prompts ``I_{e + 20 j} .. I_{e + 20 j
+ 19}`` (a soft value: its sign is the bit, BPSK map positive -> 0, negative -> 1, the
convention of :func:`dsp.gnss.lnav_decode.decode_lnav`), for every whole bit after the
first edge. The carrier phase ambiguity (180 degrees) may complement all bits; the frame
synchroniser resolves it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BitSync", "bit_sync", "nav_bits", "CODES_PER_BIT", "MIN_CHANGES", "DOMINANCE",
           "MIN_PROMPTS", "SIGNIFICANCE"]

#: Code periods (1 ms prompts) per LNAV data bit.
CODES_PER_BIT = 20
#: Sign changes the winning bin must hold.
MIN_CHANGES = 8
#: How many times the next-best bin the winning bin must hold.
DOMINANCE = 3.0
#: Excess of the winning bin over the next, in Poisson standard deviations.
SIGNIFICANCE = 5.0
#: Fewest prompts bit synchronisation is attempted on (two bits).
MIN_PROMPTS = 2 * CODES_PER_BIT


@dataclass(frozen=True)
class BitSync:
    """The outcome of :func:`bit_sync`.

    ``status``: ``ok``, ``too-short``, ``too-few-changes`` or ``ambiguous`` (module doc);
    ``edge``: the prompt index (0..19) of the first bit edge, None unless ``ok``;
    ``histogram``: sign changes per index mod 20; ``changes``: all sign changes;
    ``message``: the reason in words."""

    status: str
    edge: int | None
    histogram: np.ndarray
    changes: int
    message: str

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def as_dict(self) -> dict:
        return {"status": self.status, "edge": self.edge,
                "histogram": [int(x) for x in self.histogram], "changes": self.changes,
                "message": self.message}


def _prompts(ip) -> np.ndarray:
    x = np.asarray(ip, dtype=np.float64)
    if x.ndim != 1 or not np.all(np.isfinite(x)):
        raise ValueError("prompts must be a 1-D array of finite in-phase values")
    return x


def bit_sync(ip, *, min_changes: int = MIN_CHANGES, dominance: float = DOMINANCE,
             significance: float = SIGNIFICANCE) -> BitSync:
    """The bit edge of the consecutive 1 ms in-phase prompts ``ip`` by the histogram of
    their sign changes over the index modulo 20, with the confidence rule of the module
    doc. Raises ``ValueError`` on a malformed input, never on a weak one (that is a
    status)."""
    x = _prompts(ip)
    if isinstance(min_changes, bool) or not isinstance(min_changes, (int, np.integer)) or \
            min_changes < 1:
        raise ValueError(f"min_changes must be a positive integer, not {min_changes!r}")
    if not (np.isfinite(dominance) and dominance >= 1.0):
        raise ValueError(f"dominance must be >= 1, not {dominance!r}")
    if not (np.isfinite(significance) and significance > 0):
        raise ValueError(f"significance must be > 0, not {significance!r}")
    hist = np.zeros(CODES_PER_BIT, dtype=np.int64)
    if x.size < MIN_PROMPTS:
        return BitSync("too-short", None, hist, 0,
                       f"{x.size} prompts: bit synchronisation needs at least {MIN_PROMPTS}")
    s = np.signbit(x)
    ch = np.nonzero(s[1:] != s[:-1])[0] + 1
    hist = np.bincount(ch % CODES_PER_BIT, minlength=CODES_PER_BIT).astype(np.int64)
    order = np.argsort(hist, kind="stable")[::-1]
    k, second = int(order[0]), int(hist[order[1]])
    if hist[k] < min_changes:
        return BitSync("too-few-changes", None, hist, int(ch.size),
                       f"the most sign changes at one bit position is {int(hist[k])}, fewer "
                       f"than {min_changes}")
    win = int(hist[k])
    if win < dominance * second and win - second < significance * np.sqrt(win + second):
        return BitSync("ambiguous", None, hist, int(ch.size),
                       f"no dominant bit position: {win} sign changes at {k}, {second} at "
                       f"the next (needs {dominance:g} times, or {significance:g} sigma more)")
    return BitSync("ok", k, hist, int(ch.size),
                   f"bit edge at prompt {k} mod 20: {int(hist[k])} of {int(ch.size)} sign "
                   f"changes, next position {second}")


def nav_bits(ip, edge: int) -> tuple[np.ndarray, np.ndarray]:
    """Soft navigation bits of the prompts ``ip`` whose bit edge is at index ``edge``
    (0..19): ``(sums, first)``, the sum of each whole bit's 20 prompts and the prompt index
    of its first code period."""
    x = _prompts(ip)
    if isinstance(edge, bool) or not isinstance(edge, (int, np.integer)) or \
            not 0 <= edge < CODES_PER_BIT:
        raise ValueError(f"edge must be an integer 0..19, not {edge!r}")
    nb = max(0, (x.size - edge) // CODES_PER_BIT)
    sums = x[edge:edge + CODES_PER_BIT * nb].reshape(nb, CODES_PER_BIT).sum(axis=1)
    return sums, edge + CODES_PER_BIT * np.arange(nb, dtype=np.int64)
