"""Small-matrix operators in the one-source form: matrix product, Cholesky factor and the
two triangular solves a Kalman gain needs, for float64, float32 and fixed point by the dtype
of the arrays (the element operators of :mod:`dsp.qops`).

Fixed point: every output element is *one* rounding of an exact int64 accumulator (the
caller checks the word lengths, :func:`dsp.estimation.formats.need_bits`):

``matmul_q(A, B, out, trans_b, s, ...)``
    ``out = A B`` (or ``A B^T``): exact sum of products, shifted by ``s`` (``fA + fB -
    fout``), rounded, saturated.
``chol_q(S, L, a, ...)``
    lower ``L`` with ``L L^T = S``: ``S`` aligned left by ``a`` (= ``2 fL - fS``), minus the
    exact sum of products; the diagonal is one square root, the others one division by it.
    Returns False (nothing else written) at a non-positive pivot.
``solve_lower_q(L, B, X, a, ...)``
    ``X = L^-1 B^T`` (``B`` is ``n x m``, ``X`` ``m x n``): forward substitution, ``B``
    aligned by ``a`` (= ``fL + fX - fB``), one division per element.
``solve_upper_t_q(L, W, X, a, ...)``
    ``X = (L^-T W)^T`` (``X`` is ``n x m``): back substitution, ``W`` aligned by ``a``
    (= ``fL + fX - fW``), one division per element.

Floats: the same loops in the same order with the plain operations. Each takes the
saturation/range index ``i`` of its output signal, the event index ``ineg`` counted by a
failed square root or division, and the registry ``base`` (:mod:`dsp.estimation.events`).
"""
from __future__ import annotations

from ..jit import njit_cached

from ..qops import align, div_q, sqrt_q, store


@njit_cached
def matmul_q(A, B, out, trans_b, s, half, lo, hi, ev, i, base):
    """``out = A B`` (``trans_b``: ``A B^T``), one rounding per element."""
    n, k = A.shape
    p = out.shape[1]
    z0 = A[0, 0] - A[0, 0]
    for r in range(n):
        for c in range(p):
            acc = z0
            for l in range(k):
                acc += A[r, l] * (B[c, l] if trans_b else B[l, c])
            out[r, c] = store(acc, s, half, lo, hi, ev, i, base)


@njit_cached
def chol_q(S, L, a, half, lo, hi, ev, i, ineg, base):
    """Lower Cholesky factor of ``S`` into ``L``; False at a non-positive pivot."""
    m = S.shape[0]
    z0 = S[0, 0] - S[0, 0]
    for j in range(m):
        acc = align(S[j, j], a)
        for l in range(j):
            acc -= L[j, l] * L[j, l]
        if not acc > z0:
            return False
        L[j, j] = sqrt_q(acc, 0, half, hi, ev, i, ineg, base)
        for r in range(j + 1, m):
            acc = align(S[r, j], a)
            for l in range(j):
                acc -= L[r, l] * L[j, l]
            L[r, j] = div_q(acc, L[j, j], 0, half, lo, hi, ev, i, ineg, base)
    return True


@njit_cached
def solve_lower_q(L, B, X, a, half, lo, hi, ev, i, ineg, base):
    """``X = L^-1 B^T`` by forward substitution (``B`` n x m, ``X`` m x n)."""
    m = L.shape[0]
    n = B.shape[0]
    for r in range(m):
        for j in range(n):
            acc = align(B[j, r], a)
            for l in range(r):
                acc -= L[r, l] * X[l, j]
            X[r, j] = div_q(acc, L[r, r], 0, half, lo, hi, ev, i, ineg, base)


@njit_cached
def solve_upper_t_q(L, W, X, a, half, lo, hi, ev, i, ineg, base):
    """``X = (L^-T W)^T`` by back substitution (``W`` m x n, ``X`` n x m)."""
    m = L.shape[0]
    n = W.shape[1]
    for r in range(m - 1, -1, -1):
        for j in range(n):
            acc = align(W[r, j], a)
            for l in range(r + 1, m):
                acc -= L[l, r] * X[j, l]
            X[j, r] = div_q(acc, L[r, r], 0, half, lo, hi, ev, i, ineg, base)
