"""Complex mixer parameters and the bit-exact numpy model.

The mixer computes ``y = x * exp(-j*phi)`` from the LO pair ``(cos phi, sin phi)``:

* real input:    ``y.i = x*cos``,                ``y.q = -x*sin``
* complex input: ``y.i = x.i*cos + x.q*sin``,    ``y.q = x.q*cos - x.i*sin``

Scaling (which product bits are kept)
-------------------------------------
Read every integer as a fraction of its full scale: ``x / 2**(in_width-1)``,
``lo / 2**(lo_width-1)``, ``y / 2**(out_width-1)``. The mixer has unity gain in those
units divided by ``2**headroom_bits``: the exact product (``frac_bits = in_width + lo_width
- 2`` fraction bits) is shifted right by

    drop_bits = in_width + lo_width - 1 - out_width + headroom_bits

with the configured rounding (a negative ``drop_bits`` is an exact left shift), then brought
into ``out_width`` bits by the overflow mode. So the kept bits are product bits
``[drop_bits, drop_bits + out_width)``. With ``headroom_bits = 0`` only the full-scale
corners overflow: real ``(-1)*(-1) = +1`` (never produced by the NCO, whose peak is
symmetric) and complex values beyond ``+-1``; ``headroom_bits = 1`` makes every real
and complex result fit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dsp.fixed import OVERFLOWS, ROUNDINGS, FixedFormat, check_width, shift_right

#: Rounding modes the HDL implements (all of dsp.fixed's).
MIXER_ROUNDINGS = ROUNDINGS


@dataclass(frozen=True)
class MixerParams:
    """Parameters of the complex mixer.

    Parameters
    ----------
    in_width : int
        Signed input width in bits (2..32), per component for complex input.
    complex_input : bool
        Input is ``{"i","q"}`` (True) or a real signed word (False).
    lo_width : int
        Signed width of the LO ``cos``/``sin`` inputs in bits (2..32).
    out_width : int
        Signed width of each output component in bits (2..48).
    rounding : {"floor", "half_up", "half_even", "zero"}
        Rounding of the dropped product LSBs (see :mod:`dsp.fixed`).
    overflow : {"wrap", "saturate"}
        What an out-of-range result becomes.
    headroom_bits : int
        Extra right shift (0..8): output gain ``2**-headroom_bits`` of full scale.
    input_stages : int
        Register stages between the input port and the multipliers (1..4; HDL Coder's
        "input pipeline"). More than one lets place-and-route put the last one beside the
        DSP block when the inputs come from far away (a shared NCO feeding several
        channels); each adds a cycle of latency and nothing else.
    """

    in_width: int = 12
    complex_input: bool = False
    lo_width: int = 16
    out_width: int = 18
    rounding: str = "half_up"
    overflow: str = "saturate"
    headroom_bits: int = 0
    input_stages: int = 1

    def __post_init__(self):
        check_width("mixer in_width", self.in_width, minimum=2, maximum=32)
        check_width("mixer lo_width", self.lo_width, minimum=2, maximum=32)
        check_width("mixer out_width", self.out_width, minimum=2, maximum=48)
        check_width("mixer headroom_bits", self.headroom_bits, minimum=0, maximum=8)
        check_width("mixer input_stages", self.input_stages, minimum=1, maximum=4)
        if not isinstance(self.complex_input, bool):
            raise ValueError(f"mixer complex_input must be a bool, not {self.complex_input!r}")
        if self.rounding not in MIXER_ROUNDINGS:
            raise ValueError(f"mixer rounding must be one of {MIXER_ROUNDINGS}, not {self.rounding!r}")
        if self.overflow not in OVERFLOWS:
            raise ValueError(f"mixer overflow must be one of {OVERFLOWS}, not {self.overflow!r}")

    # -- derived -------------------------------------------------------------------------
    @property
    def product_width(self) -> int:
        """Signed width of one exact product (the -1*-1 corner needs all of it)."""
        return self.in_width + self.lo_width

    @property
    def sum_width(self) -> int:
        """Signed width of the exact result before rounding (complex: sum of two products)."""
        return self.product_width + (1 if self.complex_input else 0)

    @property
    def frac_bits(self) -> int:
        """Fraction bits of the exact product (``in_width - 1 + lo_width - 1``)."""
        return self.in_width + self.lo_width - 2

    @property
    def drop_bits(self) -> int:
        """Product LSBs removed by rounding (negative: output LSBs padded with zeros)."""
        return self.in_width + self.lo_width - 1 - self.out_width + self.headroom_bits

    @property
    def out_format(self) -> FixedFormat:
        """Output format, in units where the full-scale product is 1."""
        return FixedFormat(self.out_width, self.out_width - 1 - self.headroom_bits,
                           True, self.rounding, self.overflow)

    @property
    def latency(self) -> int:
        """Cycles from an accepted input to its ``o.valid``: input (``input_stages``),
        product, (complex: sum,) rounding and output registers."""
        return (5 if self.complex_input else 4) + self.input_stages - 1


def check_int_range(name: str, v, width: int) -> np.ndarray:
    """``v`` as int64, refusing non-integers and values outside signed ``width`` bits (the
    hardware would silently drop their upper bits)."""
    a = np.asarray(v)
    if a.dtype.kind not in "iu":
        raise ValueError(f"{name} must be an integer array, not dtype {a.dtype}")
    a = a.astype(np.int64)
    lo, hi = -(1 << (width - 1)), (1 << (width - 1)) - 1
    if a.size and (a.min() < lo or a.max() > hi):
        bad = a[(a < lo) | (a > hi)][0]
        raise ValueError(f"{name} must be signed {width}-bit integers in [{lo}, {hi}], found {bad}")
    return a


class MixerModel:
    """Bit-exact model of :class:`hdl.mixer.Mixer` (stateless)."""

    def __init__(self, params: MixerParams):
        self.params = params

    def products(self, x, cos, sin) -> tuple[np.ndarray, np.ndarray]:
        """Exact (i, q) before rounding; ``x`` is an array, or an ``(i, q)`` pair when
        ``complex_input``."""
        p = self.params
        c = check_int_range("mixer LO cos", cos, p.lo_width)
        s = check_int_range("mixer LO sin", sin, p.lo_width)
        if p.complex_input:
            xi, xq = (check_int_range("mixer input x", v, p.in_width) for v in x)
            return xi * c + xq * s, xq * c - xi * s
        x = check_int_range("mixer input x", x, p.in_width)
        return x * c, -(x * s)

    def requantize(self, v) -> np.ndarray:
        """Exact product(s) to the output: round ``drop_bits`` LSBs, then overflow."""
        p = self.params
        return p.out_format.fit(shift_right(v, p.drop_bits, p.rounding))[0]

    def run(self, x, cos, sin) -> tuple[np.ndarray, np.ndarray]:
        """Output (i, q) int64 arrays for input ``x`` and LO ``cos``, ``sin``."""
        pi, pq = self.products(x, cos, sin)
        return self.requantize(pi), self.requantize(pq)
