"""Integer rounding for the compiled (numba) block kernels: one place.

The rounding modes are specified once, by :func:`dsp.fixed.shift_right` (numpy, used by the
block models); the HDL builds them in :func:`hdl.arith.round_shift`. Inside numba kernels,
:func:`rnd` applies the same ``shift_right`` to one int64 without branches, with the
constants from :func:`round_consts` (computed once per parameter set, outside the kernel).
The kernels that inline :func:`rnd` are cached with :func:`dsp.jit.njit_cached`, keyed on
every source file, so an edit here recompiles them.
"""
from __future__ import annotations

import numba

from dsp.fixed import ROUNDINGS, shift_right

__all__ = ["round_consts", "rnd", "shift_right", "ROUNDINGS"]


def round_consts(shift: int, rounding: str) -> tuple[int, int, int, int, int]:
    """Constants that make :func:`rnd` equal ``dsp.fixed.shift_right(v, shift, rounding)``:
    ``(left shift, right shift, bias, even mask, negative bias)``."""
    if rounding not in ROUNDINGS:
        raise ValueError(f"rounding must be one of {ROUNDINGS}, not {rounding!r}")
    if shift <= 0:
        return -shift, 0, 0, 0, 0
    half = 1 << (shift - 1)
    return {"floor": (0, shift, 0, 0, 0),
            "half_up": (0, shift, half, 0, 0),
            # half to even: carry out of rem + half - 1 + (q & 1)
            "half_even": (0, shift, half - 1, 1, 0),
            # toward zero: floor(v + 2**s - 1) = ceil for v < 0
            "zero": (0, shift, 0, 0, (1 << shift) - 1)}[rounding]


@numba.njit(inline="always")
def rnd(v, rc):
    """``shift_right`` of one int64, branch-free; ``rc`` from :func:`round_consts`."""
    ls, rs, c0, em, za = rc
    v <<= ls
    return (v + c0 + ((v >> rs) & em) + ((v >> 63) & za)) >> rs
