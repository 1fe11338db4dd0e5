"""The int64 fixed-point kernels against fxpmath (bit for bit) and an exact Fraction reference.

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

from dsp.fixed import (Counters, FixedFormat, ROUNDINGS, OVERFLOWS, add, div, dot, matmul,
                       mul, quantize, requantize, sub)

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
    log = Counters()
    v, nover = fmt.quantize(x, log=log, name="x")
    check_against(v, fmt, x, lambda: [Fraction(f) for f in x], seed)
    assert nover == fxp_overflows(x, fmt) == log["x"].overflows > 0
    np.testing.assert_array_equal(quantize(x, fmt), v)


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
    log = Counters()
    r, nover = out.requantize(v, src.frac, log=log, name="r")
    check_against(r, out, fxp_raw(v, src), lambda: [Fraction(int(i), 1 << src.frac)
                                                     for i in v], seed)
    assert nover == fxp_overflows(fxp_raw(v, src), out) == log["r"].overflows
    np.testing.assert_array_equal(requantize(v, src, out), r)


# -- add / sub / mul ------------------------------------------------------------------------
FA, FB = FixedFormat(20, 12), FixedFormat(18, 5)


@pytest.mark.parametrize("rounding,overflow", MODES)
@pytest.mark.parametrize("op", ["add", "sub", "mul"])
def test_kernels_match_fxpmath(op, rounding, overflow):
    seed = 13
    rng = np.random.default_rng(seed)
    fa, fb = FA, FB
    a, b = rand_ints(rng, fa), rand_ints(rng, fb)
    if op == "mul":
        out = FixedFormat(16, 8, True, rounding, overflow)
        b = with_ties(rng, b, 9)  # products with 9 exact zero/half LSBs below the output
        got = mul(a, fa, b, fb, out)
        ref = fxp_raw(a, fa) * fxp_raw(b, fb)
        def exact(n=None):
            return [Fraction(int(x) * int(y), 1 << (fa.frac + fb.frac))
                    for x, y in zip(a[:n], b[:n])]
    else:
        out = FixedFormat(14, 3, True, rounding, overflow)
        a = with_ties(rng, a, 9)
        got = (add if op == "add" else sub)(a, fa, b, fb, out)
        ref = fxp_raw(a, fa) + fxp_raw(b, fb) if op == "add" else fxp_raw(a, fa) - fxp_raw(b, fb)
        sign = 1 if op == "add" else -1
        def exact(n=None):
            return [Fraction(int(x), 1 << fa.frac) + sign * Fraction(int(y), 1 << fb.frac)
                    for x, y in zip(a[:n], b[:n])]
    check_against(got, out, ref, exact, seed)
    # And an independent exact cross-check on a subset.
    np.testing.assert_array_equal(got[:2000], exact_ref(exact(2000), out)[0],
                                  err_msg=f"seed {seed}")


def test_mul_unsigned_by_signed_matches_fxpmath():
    seed = 14
    rng = np.random.default_rng(seed)
    fu, fs = FixedFormat(12, 12, signed=False), FixedFormat(16, 15)
    out = FixedFormat(16, 15, rounding="half_even", overflow="saturate")
    u, s = rand_ints(rng, fu), rand_ints(rng, fs)
    np.testing.assert_array_equal(mul(u, fu, s, fs, out), fxp_ref(fxp_raw(u, fu) * fxp_raw(s, fs), out))


def test_kernels_broadcast_over_batch_dims():
    rng = np.random.default_rng(15)
    f = FixedFormat(16, 12, rounding="half_even", overflow="saturate")
    a = rng.integers(-2**15, 2**15, (4, 3, 5))
    b = rng.integers(-2**15, 2**15, (3, 5))
    for k in (add, sub, mul, div):
        np.testing.assert_array_equal(k(a, f, b, f, f),
                                      k(a, f, np.broadcast_to(b, a.shape), f, f).reshape(4, 3, 5))
    d = dot(a, f, b, f, f)
    assert d.shape == (4, 3)
    np.testing.assert_array_equal(d[2, 1], dot(a[2, 1], f, b[1], f, f))


# -- dot / matmul / div against the exact reference ---------------------------------------
@pytest.mark.parametrize("rounding,overflow", MODES)
def test_dot_one_final_rounding(rounding, overflow):
    seed = 16
    rng = np.random.default_rng(seed)
    f = FixedFormat(16, 14)
    out = FixedFormat(16, 13, True, rounding, overflow)
    a, b = rng.integers(-2**15, 2**15, (2000, 5)), rng.integers(-2**15, 2**15, (2000, 5))
    got = dot(a, f, b, f, out, acc_width=40)
    exact = [Fraction(int(x @ y), 1 << 28) for x, y in zip(a, b)]
    np.testing.assert_array_equal(got, exact_ref(exact, out)[0], err_msg=f"seed {seed}")


def test_matmul_equals_dots():
    rng = np.random.default_rng(17)
    f = FixedFormat(18, 15, rounding="half_even", overflow="saturate")
    A = rng.integers(-2**17, 2**17, (7, 5, 5))
    P = rng.integers(-2**17, 2**17, (7, 5, 4))
    got = matmul(A, f, P, f, f)
    exact = np.einsum("bij,bjk->bik", A, P)  # 5 * 2**34 fits int64
    ref = exact_ref([Fraction(int(v), 1 << 30) for v in exact.ravel()], f)[0]
    np.testing.assert_array_equal(got, ref.reshape(7, 5, 4))


@pytest.mark.parametrize("rounding,overflow", MODES)
@pytest.mark.parametrize("fa,fb,out", [
    (FixedFormat(16, 12), FixedFormat(16, 8), FixedFormat(20, 14)),
    (FixedFormat(24, 20), FixedFormat(12, 4), FixedFormat(16, 22)),
])
def test_div_matches_exact(rounding, overflow, fa, fb, out):
    seed = 18
    rng = np.random.default_rng(seed)
    out = out.with_(rounding=rounding, overflow=overflow)
    a, b = rand_ints(rng, fa, 10_000), rand_ints(rng, fb, 10_000)
    b[b == 0] = 1
    b[:100] = rng.integers(1, 4, 100) * np.sign(a[:100] | 1)  # tiny divisors: overflows
    # Exact ties: a * 2**s / b = q + 1/2 with b = B * 2**(s+1), a = (2q+1) * B.
    s = out.frac + fb.frac - fa.frac
    big_b = rng.integers(1, 4, 2000) * rng.choice([-1, 1], 2000)
    b[100:2100] = big_b << (s + 1)
    a[100:2100] = (2 * rng.integers(-40, 40, 2000) + 1) * big_b
    log = Counters()
    got = div(a, fa, b, fb, out, log=log)
    exact = [Fraction(int(x), 1 << fa.frac) / Fraction(int(y), 1 << fb.frac)
             for x, y in zip(a, b)]
    ref, nover = exact_ref(exact, out)
    np.testing.assert_array_equal(got, ref, err_msg=f"seed {seed}")
    assert log["div"].overflows == nover > 0
    assert log["div"].div_by_zero == 0


# -- directed overflow corners and events ---------------------------------------------------
@pytest.mark.parametrize("overflow,expect", [("wrap", [-128, 127]), ("saturate", [127, -128])])
def test_add_sub_corners(overflow, expect):
    f = FixedFormat(8, 0, overflow=overflow)
    one = FixedFormat(2, 0)
    log = Counters()
    hi = add([127], f, [1], one, f, log=log, name="inc")   # max + 1
    lo = sub([-128], f, [1], one, f, log=log, name="dec")  # min - 1
    assert [hi[0], lo[0]] == expect
    assert log["inc"].overflows == log["dec"].overflows == 1
    assert (log["inc"].max, log["dec"].min) == (128.0, -129.0)
    assert log.overflows == 2
    # In range: no event.
    add([126], f, [1], one, f, log=log, name="inc")
    assert log["inc"].overflows == 1 and log["inc"].samples == 2


@pytest.mark.parametrize("overflow,expect", [("wrap", -128), ("saturate", 127)])
def test_most_negative_squared(overflow, expect):
    f = FixedFormat(8, 7, rounding="half_even", overflow=overflow)  # [-1, 1)
    log = Counters()
    assert mul([-128, 64], f, [-128, 64], f, f, log=log)[0] == expect
    assert log["mul"].overflows == 1 and log["mul"].max == 1.0


def test_quantize_corners_counted():
    f = FixedFormat(8, 4, overflow="saturate")
    log = Counters()
    v = quantize([f.max_value, f.max_value + f.lsb, f.min_value, f.min_value - f.lsb,
                  np.inf, -np.inf], f, log=log, name="q")
    np.testing.assert_array_equal(v, [127, 127, -128, -128, 127, -128])
    assert log["q"].overflows == 4


def test_quantize_refuses_nan():
    with pytest.raises(ValueError, match=r"cannot quantise NaN to sQ3.4\(floor,wrap\)"):
        quantize([0.0, np.nan], FixedFormat(8, 4))


@pytest.mark.parametrize("overflow", OVERFLOWS)
def test_div_by_zero_saturates_and_counts(overflow):
    f = FixedFormat(16, 8, rounding="half_even", overflow=overflow)
    log = Counters()
    got = div([256, -256, 0, 512], f, [0, 0, 0, 256], f, f, log=log)  # warnings are errors
    np.testing.assert_array_equal(got, [f.max_int, f.min_int, f.max_int, 512])
    assert log["div"].div_by_zero == 3 and log["div"].overflows == 0
    assert log["div"].samples == 4 and log["div"].min == log["div"].max == 2.0
    assert log.div_by_zero == 3
    u = FixedFormat(8, 0, signed=False)
    np.testing.assert_array_equal(div([-3, 3], f, [0, 0], f, u), [0, 255])


@pytest.mark.parametrize("acc_overflow", OVERFLOWS)
def test_dot_accumulator_overflow(acc_overflow):
    f = FixedFormat(16, 0)
    out = FixedFormat(24, 0, overflow="saturate")
    big = 2**15 - 1
    # 16-bit accumulator: 24000 + 24000 - 24000. The second term leaves [-32768, 32767];
    # wrapped (-17536), the third term crosses back (-41536 wraps to 24000: two events, the
    # right answer); saturated, it sticks at 32767 and ends wrong (one event).
    a = np.array([[1, 1, -1]]) * 120
    b = np.array([[1, 1, 1]]) * 200
    log = Counters()
    got = dot(a, f, b, f, out, acc_width=16, acc_overflow=acc_overflow, log=log)
    assert log["dot.acc"].overflows == (2 if acc_overflow == "wrap" else 1)
    assert log["dot.acc"].max == 48000.0
    assert got[0] == (24000 if acc_overflow == "wrap" else 32767 - 24000)
    exact = dot(a, f, b, f, out, acc_width=None)
    assert exact[0] == 24000
    assert dot([[big, big]], f, [[big, big]], f, out, acc_width=40)[0] == out.max_int


def test_counters_summary():
    log = Counters()
    f = FixedFormat(12, 4)
    quantize([-3.0, 5.5, 100.0, 200.0], f, log=log, name="y")
    quantize([7.0], f, log=log, name="y")
    log.count("kalman_reinit")
    log.count("kalman_reinit", 2)
    s = log["y"]
    assert (s.samples, s.overflows, s.min, s.max) == (5, 1, -3.0, 200.0)
    assert s.int_bits_needed() == 8
    d = log.as_dict()
    assert d["events"] == {"kalman_reinit": 3} and d["overflows"] == 1
    assert d["signals"]["y"]["max"] == 200.0
    assert "y" in log
    log.reset()
    assert log.as_dict() == {"signals": {}, "events": {}, "overflows": 0, "div_by_zero": 0}


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


def test_kernel_argument_errors():
    f = FixedFormat(16, 8)
    with pytest.raises(ValueError, match=r"fb must be a FixedFormat, not 16"):
        add([1], f, [1], 16, f)
    with pytest.raises(ValueError, match=r"a must be an integer array \(use quantize\(\) for "
                                         r"real values\), not dtype float64"):
        mul([1.5], f, [1], f, f)
    w = FixedFormat(32, 31)
    with pytest.raises(ValueError, match=r"product of sQ0.31\(floor,wrap\) and sQ0.31\(floor,"
                                         r"wrap\) needs 64 bits, more than the 63 the int64 "
                                         r"kernels hold; use narrower operands"):
        mul([1], w, [1], w, w)
    mul([1], w, [1], FixedFormat(31, 30), w)  # 32 x 31 fits
    with pytest.raises(ValueError, match=r"sum of .* needs 73 bits"):
        add([1], FixedFormat(62, 0), [1], FixedFormat(62, 10), f)
    with pytest.raises(ValueError, match=r"dividend .* needs \d+ bits"):
        div([1], FixedFormat(40, 0), [1], f, FixedFormat(40, 30))
    with pytest.raises(ValueError, match=r"acc_width must be an integer in \[2, 62\], not 63"):
        dot([[1]], f, [[1]], f, f, acc_width=63)
    with pytest.raises(ValueError, match=r"exact sum of 4 products .* needs 65 bits"):
        dot([[1] * 4], FixedFormat(31, 0), [[1] * 4], FixedFormat(32, 0), f, acc_width=None)
    with pytest.raises(ValueError, match=r"matmul needs \(\.\.\., m, n\) and \(\.\.\., n, p\) "
                                         r"arrays, not shapes \(2, 3\) and \(2, 3\)"):
        matmul(np.ones((2, 3), int), f, np.ones((2, 3), int), f, f)
