"""dsp.qops: the integer helpers are exact, and each operator has a float and a fixed form."""
import numba
import numpy as np
import pytest

from dsp import qops


def test_float_division_helper_is_exact_floor_division():
    rng = np.random.default_rng(0)
    n = np.concatenate([rng.integers(-(1 << 62), 1 << 62, 20000, dtype=np.int64),
                        np.array([0, 1, -1, (1 << 62) - 1, -(1 << 62), (1 << 53) + 1])])
    d = np.concatenate([rng.integers(1, 1 << 40, 20000, dtype=np.int64),
                        np.array([1, 3, 7, (1 << 29) - 1, (1 << 40) - 1, 3])])
    got = np.array([qops.fdiv(int(a), int(b)) for a, b in zip(n, d)])
    want = np.array([int(a) // int(b) for a, b in zip(n, d)])
    np.testing.assert_array_equal(got, want)


def test_bit_length_helper_matches_python():
    vals = [1, 2, 3]
    for k in range(2, 63):
        vals += [(1 << k) - 1, 1 << k, (1 << k) + 1] if k < 62 else [(1 << k) - 1, 1 << k]
    vals += [int(v) for v in np.random.default_rng(1).integers(1, 1 << 62, 5000, dtype=np.int64)]
    assert [qops._bitlen(v) for v in vals] == [v.bit_length() for v in vals]


@numba.njit
def _ops(v, w, ev):
    Sn, nb = qops.snorm(w)
    return (qops.rs(v * w, 4, 1), qops.sat(v, -8, 8, ev, 0), qops.mac2(v, w, w, v, 4, 2, 1),
            qops.div_norm(v, Sn, nb, 6, 1, -(1 << 40), 1 << 40, ev, 1))


def test_operators_compile_for_int_and_float():
    # The event array must have the range-log slots (new_event_array): the operators write
    # ev[RANGE_BASE + 2 i] unchecked, and a bare np.zeros(2) here once corrupted the heap.
    ev = qops.new_event_array(())
    r_int = _ops(np.int64(100), np.int64(48), ev)
    assert r_int == ((100 * 48 + 8) >> 4, 8, (2 * 100 * 48 + 8) >> 4, round(100 / 48 * 64))
    assert ev[:2].tolist() == [1, 0]
    q = round(100 / 48 * 64)
    assert ev[qops.RANGE_BASE:qops.RANGE_BASE + 4].tolist() == [100, 100, q, q]  # pre-saturation
    before = ev.copy()
    r_flt = _ops(100.0, 48.0, ev)
    assert r_flt == pytest.approx((4800.0, 100.0, 9600.0, 100 / 48))
    np.testing.assert_array_equal(ev, before)   # floats never saturate, nor log ranges


def test_python_call_is_refused():
    with pytest.raises(RuntimeError, match="for numba kernels"):
        qops.rs(1, 1, 1)
