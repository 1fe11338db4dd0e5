"""FixedFormat conversions against fxpmath (bit for bit) and an exact Fraction reference.

fxpmath rounding names: floor -> ``floor``, half_up -> ``nearest_posinf`` (SystemC SC_RND,
present since fxpmath 0.4.10; with an older fxpmath half_up is checked against the exact
Fraction reference instead), half_even -> ``around``, zero -> ``trunc``.
"""
import math
from fractions import Fraction

import numpy as np
import pytest
from fxpmath import Fxp
from fxpmath.objects import Config

from dsp.fixed import FixedFormat, ROUNDINGS, OVERFLOWS

N = 20_000
MODES = [(r, o) for r in ROUNDINGS for o in OVERFLOWS]
FXP_ROUNDING = {"floor": "floor", "half_up": "nearest_posinf", "half_even": "around",
                "zero": "trunc"}
FXP_HAS_HALF_UP = "nearest_posinf" in Config()._rounding_list


# -- references ---------------------------------------------------------------------------
def _exact_round(fr: Fraction, mode: str) -> int:
    if mode == "floor":
        return math.floor(fr)
    if mode == "half_up":
        return math.floor(fr + Fraction(1, 2))
    if mode == "half_even":
        return round(fr)  # Fraction.__round__ is half-to-even
    return math.trunc(fr)


def _exact_overflow(v: int, fmt: FixedFormat) -> int:
    if fmt.overflow == "saturate":
        return min(max(v, fmt.min_int), fmt.max_int)
    return (v - fmt.min_int) % (1 << fmt.width) + fmt.min_int


def exact_ref(values, fmt: FixedFormat) -> tuple[np.ndarray, int]:
    """Exact rationals (real values) into ``fmt``: integers and overflow count."""
    out, nover = [], 0
    for fr in values:
        v = _exact_round(fr * (Fraction(2) ** fmt.frac), fmt.rounding)
        nover += not fmt.min_int <= v <= fmt.max_int
        out.append(_exact_overflow(v, fmt))
    return np.array(out, dtype=np.int64), nover


def fxp_ref(value, fmt: FixedFormat) -> np.ndarray:
    """fxpmath's conversion of ``value`` (floats or an Fxp) into ``fmt`` (raw integers)."""
    return np.asarray(Fxp(value, fmt.signed, fmt.width, fmt.frac,
                          rounding=FXP_ROUNDING[fmt.rounding], overflow=fmt.overflow).val,
                      dtype=np.int64)


def fxp_overflows(value, fmt: FixedFormat) -> int:
    """How many of ``value`` fxpmath rounds to outside ``fmt`` (converted 20 bits wider)."""
    wide = FixedFormat(fmt.width + 20, fmt.frac, True, fmt.rounding if (
        fmt.rounding != "half_up" or FXP_HAS_HALF_UP) else "floor")
    v = fxp_ref(value, wide)
    return int(np.count_nonzero((v < fmt.min_int) | (v > fmt.max_int)))


def fxp_raw(raw, fmt: FixedFormat) -> Fxp:
    return Fxp(np.asarray(raw, dtype=np.int64), fmt.signed, fmt.width, fmt.frac, raw=True)


def rand_ints(rng, fmt: FixedFormat, n=N) -> np.ndarray:
    """Uniform over the format, with both extremes forced in."""
    v = rng.integers(fmt.min_int, fmt.max_int, n, endpoint=True, dtype=np.int64)
    v[:2] = fmt.min_int, fmt.max_int
    return v


def with_ties(rng, v: np.ndarray, shift: int) -> np.ndarray:
    """Make a quarter of ``v`` exact ties (or exact multiples) for a ``shift``-bit drop."""
    v = v.copy()
    k = len(v) // 8
    v[:k] = (v[:k] >> shift << shift) | (1 << (shift - 1))   # exactly half an LSB
    v[k:2 * k] = v[k:2 * k] >> shift << shift                # exactly representable
    return v


def check_against(result, fmt: FixedFormat, fxp_value, exact_values, seed):
    """Compare with fxpmath, or with the exact reference where fxpmath lacks the mode."""
    if fmt.rounding != "half_up" or FXP_HAS_HALF_UP:
        expect = fxp_ref(fxp_value, fmt)
    else:
        expect = exact_ref(exact_values(), fmt)[0]
    np.testing.assert_array_equal(result, expect, err_msg=f"seed {seed}, {fmt}")


# -- conversions --------------------------------------------------------------------------
@pytest.mark.parametrize("rounding,overflow", MODES)
@pytest.mark.parametrize("width,frac,signed", [(16, 10, True), (12, 4, False), (8, 9, True)])
def test_quantize_matches_fxpmath(rounding, overflow, width, frac, signed):
    seed = 11
    rng = np.random.default_rng(seed)
    fmt = FixedFormat(width, frac, signed, rounding, overflow)
    span = fmt.max_value - fmt.min_value
    x = rng.uniform(fmt.min_value - span, fmt.max_value + span, N)
    # Exact ties and exact grid points, where the rounding modes differ.
    k = N // 4
    x[:k] = (np.floor(x[:k] * 2.0 ** frac) + 0.5) * 2.0 ** -frac
    x[k:2 * k] = np.floor(x[k:2 * k] * 2.0 ** frac) * 2.0 ** -frac
    v, nover = fmt.quantize(x)
    check_against(v, fmt, x, lambda: [Fraction(f) for f in x], seed)
    assert nover == fxp_overflows(x, fmt) > 0


@pytest.mark.parametrize("rounding,overflow", MODES)
@pytest.mark.parametrize("src,out", [
    (FixedFormat(24, 18), FixedFormat(12, 8)),                 # drop 10 LSBs, lose 2 MSBs
    (FixedFormat(20, 4, signed=False), FixedFormat(14, 1, signed=False)),
    (FixedFormat(16, 12), FixedFormat(18, 16)),                # shift left, overflows
])
def test_requantize_matches_fxpmath(rounding, overflow, src, out):
    seed = 12
    rng = np.random.default_rng(seed)
    out = out.with_(rounding=rounding, overflow=overflow)
    v = rand_ints(rng, src)
    if src.frac > out.frac:
        v = with_ties(rng, v, src.frac - out.frac)
    r, nover = out.requantize(v, src.frac)
    check_against(r, out, fxp_raw(v, src), lambda: [Fraction(int(i), 1 << src.frac)
                                                     for i in v], seed)
    assert nover == fxp_overflows(fxp_raw(v, src), out)


# -- corners ------------------------------------------------------------------------------
def test_quantize_corners_counted():
    f = FixedFormat(8, 4, overflow="saturate")
    v, n = f.quantize([f.max_value, f.max_value + f.lsb, f.min_value, f.min_value - f.lsb,
                       np.inf, -np.inf])
    np.testing.assert_array_equal(v, [127, 127, -128, -128, 127, -128])
    assert n == 4


def test_quantize_refuses_nan():
    with pytest.raises(ValueError, match=r"cannot quantise NaN to sQ3.4\(floor,wrap\)"):
        FixedFormat(8, 4).quantize([0.0, np.nan])


def test_format_methods_keep_tuple_returns():
    f = FixedFormat(8, 4, overflow="saturate")
    v, n = f.quantize([100.0])
    assert (v.tolist(), n) == ([127], 1)
    v, n = f.requantize([1 << 12], 8)
    assert (v.tolist(), n) == ([127], 1)


# -- parameters and errors ------------------------------------------------------------------
@pytest.mark.parametrize("kwargs,msg", [
    (dict(width=1), r"width must be an integer in \[2, 62\], not 1"),
    (dict(width=63), r"width must be an integer in \[2, 62\], not 63"),
    (dict(width=8.0), r"width must be an integer, not 8.0"),
    (dict(width=8, frac=1.5), r"frac must be an integer, not 1.5"),
    (dict(width=8, rounding="round"), r"rounding must be one of .*'half_even'.*, not 'round'"),
    (dict(width=8, overflow="clip"), r"overflow must be one of \('wrap', 'saturate'\), not 'clip'"),
])
def test_bad_formats(kwargs, msg):
    with pytest.raises(ValueError, match=msg):
        FixedFormat(**kwargs)
