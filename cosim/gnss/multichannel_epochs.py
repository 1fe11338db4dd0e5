"""Where a channel's dump boundaries fall, from its records alone (no replay of the HDL).

A record carries ``code_phase``: the code NCO accumulator ``a_k`` at its generator boundary
(:mod:`hdl.gnss.model`). Between two boundaries the accumulator advances by the code word
``cf_k`` in force (written before the boundary, active from it) on every sample except the
``hold_k`` samples of a slew applied at it, and wraps ``1023 * dump_epochs`` times, so::

    (n_{k+1} - n_k - hold_k) * cf_k = 1023 K 2**B + a_{k+1} - a_k       (exactly)

with ``n_k`` the sample (= cycle: one sample per cycle from reset) whose accumulator update
closed the boundary, ``B = code_phase_bits``, and at reset ``n_0 = -1``, ``a_0 = 0``, the reset
word, no hold. :class:`CodeEpochs` applies this record by record, with the words in force
taken from the channel's bus writes (a write in cycle ``b`` is applied at the first boundary
whose cycle is later than ``b``); a remainder is an internal error (the records and the
writes disagree). :meth:`CodeEpochs.next_boundary` predicts the next boundary and its
accumulator exactly, which is what a hand-over in the middle of a run needs
(:func:`rehandover_writes`).
"""
from __future__ import annotations

from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, L1_HZ

from hdl.gnss.params import REG_CODE_FREQ, REG_SLEW

__all__ = ["CodeEpochs", "rehandover_writes"]


class CodeEpochs:
    """The code NCO's boundaries of one channel, record by record (module doc)."""

    def __init__(self, p):
        self.p = p
        self.span = p.dump_epochs * CODE_LENGTH << p.code_phase_bits
        self.cf = self.sh_code = p.code_word()
        self.sh_slew, self.slew_pend = 0, False
        self.n_w, self.acc, self.hold = -1, 0, 0
        self.prev_cf = self.cf
        self.pending: list[tuple[int, int, int]] = []

    def bus(self, cycle: int, reg: int, value: int) -> None:
        """A bus write to this channel's register ``reg`` (0-3) in ``cycle``."""
        if reg in (REG_CODE_FREQ, REG_SLEW):
            self.pending.append((int(cycle), int(reg), int(value)))

    def record(self, acc_next: int) -> int:
        """The next record's accumulator -> its boundary sample ``n_k`` (module doc)."""
        num = self.span + int(acc_next) - self.acc
        if num <= 0 or num % self.cf:
            raise RuntimeError(f"internal: a record's code phase {acc_next} is not a whole "
                               f"number of samples of the code word {self.cf} after the "
                               f"previous boundary (records and bus writes disagree)")
        n = self.n_w + self.hold + num // self.cf
        keep = []
        for b, reg, v in self.pending:
            if b < n:
                if reg == REG_CODE_FREQ:
                    self.sh_code = v
                else:
                    self.sh_slew, self.slew_pend = v, True
            else:
                keep.append((b, reg, v))
        self.pending = keep
        self.prev_cf = self.cf
        self.cf = self.sh_code
        self.hold = self.sh_slew if self.slew_pend else 0
        self.slew_pend = False
        self.n_w, self.acc = n, int(acc_next)
        return n

    def next_boundary(self) -> tuple[int, int]:
        """The next boundary's sample and accumulator (the word in force now, exact)."""
        j = -(-(self.span - self.acc) // self.cf)
        return self.n_w + self.hold + j, self.acc + j * self.cf - self.span


def rehandover_writes(p, n_w: int, acc: int, doppler_hz: float, code_phase_chips: float,
                      n_ref: int, inverted: bool = False) -> list[tuple[str, int]]:
    """Register writes ``[(reg, value)]`` that start a channel on a new satellite at its
    boundary ``n_w`` (accumulator ``acc`` there, :meth:`CodeEpochs.next_boundary`): carrier
    word (IF + Doppler), code word (chip rate + Doppler / 1540) and the slew that puts the
    prompt on the received code phase, ``code_phase_chips`` at sample ``n_ref`` advancing
    at the Doppler-shifted chip rate. The PRN write is the caller's. After the boundary the
    generator restarts at chip 0 (fraction ``acc``) after ``slew`` held samples, so the prompt
    (``d`` samples behind) has the phase ``acc / 2**B`` at sample ``n_w + 1 + slew + d``."""
    s = -1.0 if inverted else 1.0
    rate = CHIP_RATE_HZ * (1 + doppler_hz / L1_HZ)
    r = rate / p.fs_hz                                   # chips per sample
    n_code = CODE_LENGTH / r
    tau = code_phase_chips + (n_w + 1 + p.half_spacing - n_ref) * r
    slew = int(round(((acc / 2.0 ** p.code_phase_bits - tau) % CODE_LENGTH) / r))
    if slew >= round(n_code):
        slew -= int(round(n_code))
    slew = max(slew, 0)
    if slew >= 1 << p.slew_bits:
        raise ValueError(f"the code slew of {slew} samples does not fit slew_bits "
                         f"{p.slew_bits}: use slew_bits >= {slew.bit_length()}")
    return [("carr_freq", p.carr_word(p.if_hz + s * doppler_hz)),
            ("code_freq", p.code_word(rate)), ("slew", slew)]
