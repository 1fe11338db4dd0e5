"""Vectoring integer CORDIC: documented error bounds against numpy over the full circle,
edge cases, bit-exactness against the per-element Python-integer reference, validation."""
import math
from decimal import Decimal, getcontext

import numpy as np
import pytest

from dsp.cordic import (CordicConfig, CordicResult, _atan_pow2_turns, cordic_atan2,
                        cordic_atan2_reference)

CONFIGS = [
    dict(width=16, iterations=24, angle_bits=32),
    dict(width=12, iterations=8, angle_bits=16),
    dict(width=24, iterations=20, angle_bits=20, guard_bits=3),
    dict(width=36, iterations=34, angle_bits=32, guard_bits=20, magnitude_frac=20),
    dict(width=18, iterations=40, angle_bits=62),
    dict(width=8, iterations=1, angle_bits=8),
    dict(width=20, iterations=16, angle_bits=24, signed_angle=True, compensate_gain=False),
]


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def _random_inputs(width, n, seed):
    """Random vectors over the full circle with log-uniform magnitudes up to full scale."""
    rng = np.random.default_rng(seed)
    full = 2.0 ** (width - 1) - 1
    r = full * 2.0 ** -rng.uniform(0, min(width - 2, 20), n)
    phi = rng.uniform(-np.pi, np.pi, n)
    x = np.clip(np.rint(r * np.cos(phi)), -full, full).astype(np.int64)
    y = np.clip(np.rint(r * np.sin(phi)), -full, full).astype(np.int64)
    return y, x


def _edge_inputs(width):
    lo, hi = -(1 << (width - 1)), (1 << (width - 1)) - 1
    vals = [lo, lo + 1, -1, 0, 1, hi - 1, hi]
    y, x = np.meshgrid(vals, vals, indexing="ij")
    return y.ravel().astype(np.int64), x.ravel().astype(np.int64)


def _angle_error(cfg, angle, y, x):
    got = angle.astype(np.float64) / 2.0 ** cfg.angle_bits * 2 * np.pi
    return np.abs(_wrap(got - np.arctan2(y, x)))


@pytest.mark.parametrize("kw", CONFIGS)
def test_angle_and_magnitude_within_documented_bounds(kw):
    cfg = CordicConfig(**kw)
    y, x = _random_inputs(cfg.width, 20000, seed=cfg.width + cfg.iterations)
    y = np.concatenate([y, _edge_inputs(cfg.width)[0]])
    x = np.concatenate([x, _edge_inputs(cfg.width)[1]])
    a, m = cfg(y, x)
    nz = (x != 0) | (y != 0)
    r = np.hypot(x.astype(np.float64), y.astype(np.float64))
    err = _angle_error(cfg, a, y, x)[nz]
    # float64 arctan2 itself is good to ~1e-16 rad
    assert np.all(err <= cfg.angle_error_bound(r[nz]) + 1e-15)
    mag = m.astype(np.float64) / 2.0 ** cfg.magnitude_frac
    target = r if cfg.compensate_gain else cfg.gain * r
    assert np.all(np.abs(mag - target)[nz] <= cfg.magnitude_error_bound(r[nz]) * (1 + 1e-12))
    # the output range of the binary angle
    if cfg.signed_angle:
        assert a.min() >= -(1 << (cfg.angle_bits - 1)) and a.max() < 1 << (cfg.angle_bits - 1)
    else:
        assert a.min() >= 0 and a.max() < 1 << cfg.angle_bits


def test_residual_term_is_what_limits_a_short_cordic():
    """With few iterations the error reaches a good part of atan(2**-(n-1)): the bound is
    not vacuous."""
    cfg = CordicConfig(width=20, iterations=8, angle_bits=32)
    y, x = _random_inputs(20, 20000, seed=4)
    err = _angle_error(cfg, cfg(y, x).angle, y, x)
    big = np.hypot(x, y) > 2 ** 16
    assert err[big].max() > 0.5 * math.atan(2.0 ** -7)
    assert err[big].max() <= cfg.angle_error_bound(2 ** 16)


def test_accuracy_at_32_bits_with_enough_iterations():
    """32-bit angles, 34 iterations, 20 guard bits: within 0.75 LSB for |v| >= 2**16."""
    cfg = CordicConfig(width=36, iterations=34, angle_bits=32, guard_bits=20)
    y, x = _random_inputs(36, 50000, seed=7)
    keep = np.hypot(x, y) >= 2 ** 16
    err = _angle_error(cfg, cfg(y, x).angle, y, x)[keep]
    lsb = 2 * np.pi / 2 ** 32
    assert err.max() < 0.75 * lsb
    assert cfg.angle_error_bound(2 ** 20) < 0.8 * lsb


def test_zero_vector_gives_zero_angle_and_magnitude():
    cfg = CordicConfig(width=16, iterations=16, angle_bits=32, signed_angle=True)
    a, m = cfg(np.zeros(3, np.int64), np.zeros(3, np.int64))
    np.testing.assert_array_equal(a, 0)
    np.testing.assert_array_equal(m, 0)
    assert cordic_atan2_reference(0, 0, cfg) == (0, 0)
    assert np.isinf(cfg.angle_error_bound(0.0))


def test_axes_and_extreme_values():
    w = 16
    cfg = CordicConfig(width=w, iterations=30, angle_bits=32, guard_bits=6)
    lo, hi = -(1 << (w - 1)), (1 << (w - 1)) - 1
    cases = {  # (y, x): exact angle in turns, exact magnitude
        (0, hi): (0.0, hi), (hi, 0): (0.25, hi), (0, lo): (0.5, -lo), (lo, 0): (0.75, -lo),
        (0, 1): (0.0, 1), (1, 0): (0.25, 1), (0, -1): (0.5, 1), (-1, 0): (0.75, 1),
        (lo, lo): (0.625, -lo * math.sqrt(2)), (hi, hi): (0.125, hi * math.sqrt(2)),
        (lo, hi): (math.atan2(lo, hi) / (2 * math.pi) % 1, math.hypot(lo, hi)),
        (hi, lo): (math.atan2(hi, lo) / (2 * math.pi) % 1, math.hypot(lo, hi)),
    }
    y = np.array([k[0] for k in cases], np.int64)
    x = np.array([k[1] for k in cases], np.int64)
    a, m = cfg(y, x)
    lsb_turn = 2.0 ** -32
    for (yy, xx), aa, mm in zip(cases, a, m):
        turns, mag = cases[(yy, xx)]
        d = (aa * lsb_turn - turns + 0.5) % 1 - 0.5
        r = math.hypot(xx, yy)
        assert abs(d) * 2 * math.pi <= cfg.angle_error_bound(r), (yy, xx)
        assert abs(mm - mag) <= cfg.magnitude_error_bound(r), (yy, xx)
    # the negated minimum (-(-2**15)) is held by the extra datapath bit: magnitudes exact
    assert m[list(cases).index((0, lo))] == -lo and m[list(cases).index((lo, 0))] == -lo


@pytest.mark.parametrize("kw", CONFIGS)
def test_vectorised_equals_python_integer_reference(kw):
    cfg = CordicConfig(**kw)
    y, x = _random_inputs(cfg.width, 400, seed=11)
    ye, xe = _edge_inputs(cfg.width)
    y, x = np.concatenate([y, ye]), np.concatenate([x, xe])
    a, m = cfg(y, x)
    ref = [cordic_atan2_reference(int(yy), int(xx), cfg) for yy, xx in zip(y, x)]
    np.testing.assert_array_equal(a, [r[0] for r in ref])
    np.testing.assert_array_equal(m, [r[1] for r in ref])
    assert cfg.reference(int(y[0]), int(x[0])) == ref[0]
    # deterministic, and the same per element as in a batch (length-1 calls)
    a2, m2 = cfg(y, x)
    np.testing.assert_array_equal(a, a2)
    np.testing.assert_array_equal(m, m2)
    for k in (0, 7, len(y) - 1):
        a1, m1 = cfg(y[k:k + 1], x[k:k + 1])
        assert (a1[0], m1[0]) == (a[k], m[k])


def test_function_form_broadcasting_and_dtypes():
    y = np.arange(-6, 6, dtype=np.int32).reshape(3, 4)
    res = cordic_atan2(y, np.int16(5), width=8, iterations=12, angle_bits=16)
    assert isinstance(res, CordicResult)
    assert res.angle.shape == (3, 4) and res.magnitude.shape == (3, 4)
    assert res.angle.dtype == np.int64 and res.magnitude.dtype == np.int64
    cfg = CordicConfig(width=8, iterations=12, angle_bits=16)
    ref = cfg(y.astype(np.int64), np.full((3, 4), 5))
    np.testing.assert_array_equal(res.angle, ref.angle)
    a, m = cordic_atan2(np.array([300]), np.array([-400]), width=12, iterations=20,
                        angle_bits=16)                    # the docstring example
    assert round(float(a[0]) / 2 ** 16 * 360, 2) == 143.13 and m[0] == 500
    # scalars and empty arrays
    a0, m0 = cordic_atan2(1, 1, width=4, iterations=10, angle_bits=8)
    assert a0.shape == () and int(a0) == 32 and int(m0) == 1
    e = cordic_atan2(np.array([], np.int64), np.array([], np.int64), width=8)
    assert e.angle.shape == (0,)


def test_signed_and_unsigned_angles_agree_mod_one_turn():
    y, x = _random_inputs(16, 2000, seed=3)
    u = cordic_atan2(y, x, width=16, angle_bits=24).angle
    s = cordic_atan2(y, x, width=16, angle_bits=24, signed_angle=True).angle
    np.testing.assert_array_equal(s % (1 << 24), u)
    assert s.min() < 0


def test_uncompensated_magnitude_is_gain_times_compensated():
    y, x = _random_inputs(20, 2000, seed=5)
    cfg = CordicConfig(width=20, iterations=24)
    raw = CordicConfig(width=20, iterations=24, compensate_gain=False)
    m, mr = cfg(y, x).magnitude, raw(y, x).magnitude
    assert abs(cfg.gain - 1.6467602581210656) < 1e-12
    assert cfg.gain_word == round(2 ** cfg.gain_frac / cfg.gain)
    np.testing.assert_allclose(mr, cfg.gain * m, atol=2.0)


def test_lut_entries_are_exactly_rounded():
    """The integer-series LUT against 60-digit decimal arithmetic, up to 62 bits per turn."""
    getcontext().prec = 60

    def datan(t):
        s, term, k = Decimal(0), t, 0
        while abs(term) > Decimal(10) ** -58:
            s += term / (2 * k + 1) * (1 if k % 2 == 0 else -1)
            term *= t * t
            k += 1
        return s

    pi = 4 * (4 * datan(Decimal(1) / 5) - datan(Decimal(1) / 239))
    for bits in (16, 32, 47, 62):
        for i in list(range(0, 12)) + [20, 40, 59]:
            v = (pi / 4 if i == 0 else datan(Decimal(1) / 2 ** i)) / (2 * pi) * 2 ** bits
            want = int((v + Decimal("0.5")).to_integral_value(rounding="ROUND_FLOOR"))
            assert _atan_pow2_turns(i, bits) == want, (bits, i)
    # and float64 agrees where it is precise enough
    lut = CordicConfig(width=16, iterations=30, angle_bits=32, lut_bits=40).lut
    assert lut == tuple(round(math.atan(2.0 ** -i) / (2 * math.pi) * 2 ** 40) for i in range(30))


def test_defaults_and_derived_word_lengths():
    cfg = CordicConfig(width=16)
    assert (cfg.iterations, cfg.angle_bits, cfg.guard_bits, cfg.lut_bits) == (24, 32, 7, 38)
    assert cfg.datapath_bits == 25
    assert cfg.gain_frac == 27                      # (61 - 7) // 2
    big = CordicConfig(width=58, iterations=60, angle_bits=62)
    assert big.guard_bits == 2 and big.lut_bits == 62 and big.datapath_bits == 62
    y, x = _random_inputs(58, 300, seed=9)
    a, m = big(y, x)                                # no int64 overflow at the limits
    r = np.hypot(x.astype(float), y.astype(float))
    assert np.all(_angle_error(big, a, y, x) <= big.angle_error_bound(r) + 1e-15)
    assert np.all(np.abs(m - r) <= big.magnitude_error_bound(r) * (1 + 1e-12) + 1e3)


@pytest.mark.parametrize("kw, msg", [
    (dict(width=1), r"width must be an integer in \[2, 60\], not 1"),
    (dict(width=61), r"width must be an integer in \[2, 60\], not 61"),
    (dict(width=16.0), r"width must be an integer, not 16.0"),
    (dict(width=True), r"width must be an integer, not True"),
    (dict(width=16, iterations=0), r"iterations must be an integer in \[1, 60\], not 0"),
    (dict(width=16, iterations=61), r"iterations must be an integer in \[1, 60\], not 61"),
    (dict(width=16, angle_bits=0), r"angle_bits must be an integer in \[1, 62\], not 0"),
    (dict(width=16, angle_bits=63), r"angle_bits must be an integer in \[1, 62\], not 63"),
    (dict(width=40, guard_bits=21),
     r"width \+ 2 \+ guard_bits must be <= 62 \(the datapath registers\), not 40 \+ 2 \+ 21"),
    (dict(width=16, guard_bits=-1), r"guard_bits must be an integer in \[0, 62\], not -1"),
    (dict(width=16, angle_bits=32, lut_bits=31),
     r"lut_bits must be an integer in \[32, 62\], not 31"),
    (dict(width=16, guard_bits=7, gain_frac=28),
     r"gain_frac must be an integer in \[1, 27\], not 28"),
    (dict(width=16, guard_bits=4, magnitude_frac=5),
     r"magnitude_frac must be an integer in \[0, 4\], not 5"),
    (dict(width=16, compensate_gain=1), r"compensate_gain must be a bool, not 1"),
    (dict(width=16, signed_angle="no"), r"signed_angle must be a bool, not 'no'"),
])
def test_bad_word_lengths(kw, msg):
    with pytest.raises(ValueError, match=msg):
        CordicConfig(**kw)


def test_bad_inputs():
    with pytest.raises(ValueError, match=r"x must be an integer array, not dtype float64"):
        cordic_atan2(np.array([1]), np.array([1.0]), width=8)
    with pytest.raises(ValueError,
                       match=r"1 value\(s\) of y do not fit 8 signed bits \[-128, 127\]"):
        cordic_atan2(np.array([128, 0]), np.array([1, 1]), width=8)
    with pytest.raises(ValueError, match=r"x do not fit 8 signed bits"):
        cordic_atan2(np.array([0]), np.array([-129]), width=8)
    with pytest.raises(ValueError, match="do not fit 8 signed bits"):
        cordic_atan2_reference(0, 200, CordicConfig(width=8))
    with pytest.raises(ValueError, match="must be Python ints"):
        cordic_atan2_reference(0.5, 2, CordicConfig(width=8))
