"""Small-matrix operators: fixed point bit for bit against unbounded integers, float64
against numpy."""
from __future__ import annotations

import math

import numpy as np
import pytest

from dsp.estimation.events import EventRegistry
from dsp.estimation.linalg import chol_q, matmul_q, solve_lower_q, solve_upper_t_q

REG = EventRegistry(("y",), ("fail",))
FAIL, BASE = REG.index("fail"), REG.base
LO, HI = -(1 << 39), (1 << 39) - 1


def _rnd(v, s):
    return (v + (1 << (s - 1))) >> s if s > 0 else v << -s


def _sat(v):
    return min(max(v, LO), HI)


def _div(n, d):
    q = n // d
    return q + (2 * (n - q * d) >= d)


def _spd(rng, m, scale):
    A = rng.standard_normal((m, m))
    return A @ A.T + m * np.eye(m) * scale


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_fixed_matmul_and_cholesky_solves_match_unbounded_integers(seed):
    rng = np.random.default_rng(seed)
    m, n, fS, fL, fB, fX = 3, 4, 24, 20, 24, 20
    S = np.round(_spd(rng, m, 1.0) * 2 ** fS).astype(np.int64)
    S = np.triu(S) + np.triu(S, 1).T
    B = np.round(rng.standard_normal((n, m)) * 2 ** fB).astype(np.int64)
    ev = REG.new()
    L = np.zeros((m, m), np.int64)
    assert chol_q(S, L, 2 * fL - fS, 1, LO, HI, ev, 0, FAIL, BASE)
    Lr = [[0] * m for _ in range(m)]
    for j in range(m):
        acc = int(S[j, j]) << (2 * fL - fS)
        acc -= sum(Lr[j][l] ** 2 for l in range(j))
        r = math.isqrt(acc)
        Lr[j][j] = _sat(r + (acc - r * r > r))
        for i in range(j + 1, m):
            acc = (int(S[i, j]) << (2 * fL - fS)) - sum(Lr[i][l] * Lr[j][l] for l in range(j))
            Lr[i][j] = _sat(_div(acc, Lr[j][j]))
    np.testing.assert_array_equal(L, Lr, err_msg=f"seed {seed}")
    X = np.zeros((m, n), np.int64)
    solve_lower_q(L, B, X, fL + fX - fB, 1, LO, HI, ev, 0, FAIL, BASE)
    Xr = [[0] * n for _ in range(m)]
    for r in range(m):
        for j in range(n):
            acc = (int(B[j, r]) << (fL + fX - fB)) - sum(Lr[r][l] * Xr[l][j] for l in range(r))
            Xr[r][j] = _sat(_div(acc, Lr[r][r]))
    np.testing.assert_array_equal(X, Xr)
    K = np.zeros((n, m), np.int64)
    solve_upper_t_q(L, X, K, fL + fX - fX, 1, LO, HI, ev, 0, FAIL, BASE)
    Kr = [[0] * m for _ in range(n)]
    for r in range(m - 1, -1, -1):
        for j in range(n):
            acc = (Xr[r][j] << fL) - sum(Lr[l][r] * Kr[j][l] for l in range(r + 1, m))
            Kr[j][r] = _sat(_div(acc, Lr[r][r]))
    np.testing.assert_array_equal(K, Kr)
    # K = B S^-1 in real terms, to the rounding of the formats
    np.testing.assert_allclose(K / 2 ** fX, (B / 2 ** fB) @ np.linalg.inv(S / 2 ** fS), atol=1e-4)
    out = np.zeros((n, n), np.int64)
    matmul_q(B, B, out, True, 2 * fB - fX, 1, LO, HI, ev, 0, BASE)
    want = [[_sat(_rnd(sum(int(B[i, l]) * int(B[j, l]) for l in range(m)), 2 * fB - fX))
             for j in range(n)] for i in range(n)]
    np.testing.assert_array_equal(out, want)
    assert ev[FAIL] == 0


def test_fixed_cholesky_refuses_an_indefinite_matrix():
    S = np.array([[1 << 20, 2 << 20], [2 << 20, 1 << 20]], np.int64)
    L = np.zeros((2, 2), np.int64)
    assert not chol_q(S, L, 0, 1, LO, HI, REG.new(), 0, FAIL, BASE)


@pytest.mark.parametrize("seed", [4, 5])
def test_float64_forms_match_numpy(seed):
    rng = np.random.default_rng(seed)
    m, n = 4, 6
    S = _spd(rng, m, 0.5)
    B = rng.standard_normal((n, m))
    ev = REG.new()
    L = np.zeros((m, m))
    assert chol_q(S, L, 0, 1, 0, 0, ev, 0, FAIL, BASE)
    np.testing.assert_allclose(L, np.linalg.cholesky(S), rtol=1e-12, atol=1e-12)
    X = np.zeros((m, n))
    solve_lower_q(L, B, X, 0, 1, 0, 0, ev, 0, FAIL, BASE)
    np.testing.assert_allclose(X, np.linalg.solve(L, B.T), rtol=1e-12, atol=1e-12)
    K = np.zeros((n, m))
    solve_upper_t_q(L, X, K, 0, 1, 0, 0, ev, 0, FAIL, BASE)
    np.testing.assert_allclose(K, B @ np.linalg.inv(S), rtol=1e-12, atol=1e-12)
    out = np.zeros((n, n))
    matmul_q(B, B, out, True, 0, 1, 0, 0, ev, 0, BASE)
    np.testing.assert_allclose(out, B @ B.T, rtol=1e-12, atol=1e-12)
