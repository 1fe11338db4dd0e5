"""Unscented Kalman filter (scaled unscented transform), one source for float64 and float32,
batched over trials.

The model says ``f`` and ``h`` (:class:`NonlinearModel`: numba functions
``f(x, w, prm, out)`` and ``h(x, v, prm, out)`` with their parameter arrays, plus Q and R);
the filter says how they are combined; the arithmetic is a configuration. The sigma points
are van der Merwe's scaled set (as filterpy's ``MerweScaledSigmaPoints``)::

    lambda = alpha^2 (L + kappa) - L,  X = [x, x + U_i, x - U_i],  U^T U = (L + lambda) P
    Wm_0 = lambda / (L + lambda), Wc_0 = Wm_0 + 1 - alpha^2 + beta, W_i = 1 / (2 (L + lambda))

(``alpha`` is the seed's UT scaling ``epsilon``). Noise is *additive* (``L = n``; Q added to
the predicted covariance, R to the innovation covariance) or *augmented* (``L = n + n + m``:
the sigma points also span ``w ~ N(0, Q)`` and ``v ~ N(0, R)``, which ``f`` and ``h`` take
as arguments; the augmented factor is block diagonal, its constant noise blocks factored once
by :func:`psd_sqrt`, so a rank-deficient Q is fine). With additive noise the sigma points are redrawn from the prediction before
``h`` (``redraw=True``, the default, as filterpy 2.0 does); ``redraw=False`` passes the
propagated points to ``h`` (cheaper, but the innovation covariance then misses ``H Q H^T``, so
it is not the KF on a linear model). Augmented noise propagates the augmented points through both (exact on a
linear model). Update ``K = Pxz S^-1`` (Cholesky solves), ``P = Pp - K S K^T``
mirrored to the upper triangle.

A Cholesky of ``(L + lambda) P`` that fails (a non-positive pivot: P lost definiteness) is
counted (``chol_fail``) and recovered by replacing P with its diagonal, each entry raised to
at least ``p_floor``, and factoring again (a diagonal with positive entries always factors).
An innovation covariance that does not factor skips the update (``s_not_pd``). NaN,
infinite or implausible (``z_limit``) measurements only predict (``implausible``).

Fixed point is not offered for the UKF: with the usual ``alpha`` of 1e-3..1 the centre
weight ``Wm_0`` ranges over 1..1e6 in magnitude with alternating signs, which no single
format of a fixed-point core holds without the cancellation dominating; the fixed-point
cores use the linear filter (:mod:`dsp.estimation.kalman`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .events import EventRegistry
from .formats import arithmetic_name
from .models import MAX_STATES, check_psd

EVENTS = EventRegistry((), ("implausible", "chol_fail", "s_not_pd"))
_EV_IMPL = EVENTS.index("implausible")
_EV_CHOL = EVENTS.index("chol_fail")
_EV_SNPD = EVENTS.index("s_not_pd")


@njit(cache=True)
def _f_linear(x, w, prm, out):
    n = x.shape[0]
    for i in range(n):
        acc = w[i]
        for j in range(n):
            acc += prm[i, j] * x[j]
        out[i] = acc


@njit(cache=True)
def _h_linear(x, v, prm, out):
    for r in range(out.shape[0]):
        acc = v[r]
        for j in range(x.shape[0]):
            acc += prm[r, j] * x[j]
        out[r] = acc


class NonlinearModel:
    """``x[k+1] = f(x[k], w)``, ``z[k] = h(x[k], v)`` with ``w ~ N(0, Q)``, ``v ~ N(0, R)``.

    Parameters
    ----------
    f, h : numba ``@njit`` functions
        ``f(x, w, prm_f, out)`` writes the next state (``n``) into ``out``; ``h(x, v, prm_h,
        out)`` the measurement (``m``). With additive noise ``w`` and ``v`` are zero and the
        noise is added by the filter; augmented, they are the noise sigma points. Write them
        with the dtype of ``x`` (no float64 literals) to keep a float32 run in float32.
    Q, R : arrays
        Noise covariances (``n x n`` PSD, ``m x m`` positive definite).
    prm_f, prm_h : 2-D float arrays
        Parameters passed to ``f`` and ``h`` (cast to the filter's dtype).
    """

    def __init__(self, f, h, Q, R, prm_f=None, prm_h=None):
        Q = np.atleast_2d(np.asarray(Q, dtype=np.float64))
        R = np.atleast_2d(np.asarray(R, dtype=np.float64))
        if Q.ndim != 2 or Q.shape[0] != Q.shape[1]:
            raise ValueError(f"Q must be square (n x n), not {Q.shape}")
        if not 1 <= Q.shape[0] <= MAX_STATES:
            raise ValueError(f"the state dimension must be 1..{MAX_STATES}, not {Q.shape[0]}")
        if R.ndim != 2 or R.shape[0] != R.shape[1]:
            raise ValueError(f"R must be square (m x m), not {R.shape}")
        check_psd("Q", Q[None])
        check_psd("R", R[None], strict=True)
        self.f, self.h, self.Q, self.R = f, h, Q, R
        self.prm_f = np.atleast_2d(np.zeros((1, 1)) if prm_f is None else np.asarray(prm_f, np.float64))
        self.prm_h = np.atleast_2d(np.zeros((1, 1)) if prm_h is None else np.asarray(prm_h, np.float64))

    @property
    def n(self) -> int:
        return self.Q.shape[0]

    @property
    def m(self) -> int:
        return self.R.shape[0]

    @classmethod
    def linear(cls, F, H, Q, R) -> "NonlinearModel":
        """The linear-Gaussian model ``f = F x + w``, ``h = H x + v`` (for tests: the UKF on
        it equals the Kalman filter)."""
        F, H = np.asarray(F, np.float64), np.atleast_2d(np.asarray(H, np.float64))
        if F.ndim != 2 or F.shape[0] != F.shape[1]:
            raise ValueError(f"F must be square (n x n), not {F.shape}")
        return cls(_f_linear, _h_linear, Q, R, F, H)


def sigma_weights(L: int, alpha: float, beta: float, kappa: float):
    """``(Wm, Wc, c)`` of the scaled unscented transform, ``c = L + lambda``."""
    lam = alpha * alpha * (L + kappa) - L
    c = L + lam
    wm = np.full(2 * L + 1, 0.5 / c)
    wc = wm.copy()
    wm[0] = lam / c
    wc[0] = lam / c + (1.0 - alpha * alpha + beta)
    return wm, wc, c


def psd_sqrt(A) -> np.ndarray:
    """A lower-triangular ``S`` with ``S S^T = A`` for a PSD ``A``: the Cholesky factor when
    ``A`` is definite, else the triangular factor of the symmetric eigen square root (a
    rank-deficient process noise such as ``q G G^T`` has no Cholesky factor)."""
    try:
        return np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(A)
        root = V * np.sqrt(np.clip(w, 0.0, None))
        # an orthogonal change (QR of root^T) makes it triangular without changing S S^T
        r = np.linalg.qr(root.T, mode="r")
        S = r.T
        return S * np.where(np.diag(S) < 0, -1.0, 1.0)


@njit(cache=True)
def _chol(A, L):
    """Lower Cholesky factor of A into L; False if a pivot is not positive."""
    n = A.shape[0]
    z0 = A[0, 0] - A[0, 0]
    for i in range(n):
        for j in range(n):
            L[i, j] = z0
    for j in range(n):
        acc = A[j, j]
        for l in range(j):
            acc -= L[j, l] * L[j, l]
        if not acc > z0:
            return False
        L[j, j] = np.sqrt(acc)
        for i in range(j + 1, n):
            acc = A[i, j]
            for l in range(j):
                acc -= L[i, l] * L[j, l]
            L[i, j] = acc / L[j, j]
    return True


@njit(cache=True)
def _ukf_kernel(f, h, x, P, z, zok, Q, R, Lq, Lr, pf, ph, wm, wc, c, pfloor, aug, redraw, ev, xs, Ps, keep_P):
    nb, n = x.shape
    T, m = z.shape[1], z.shape[2]
    L = n + (n + m if aug else 0)
    ns = 2 * L + 1
    z0 = x[0, 0] - x[0, 0]
    Pa = np.zeros((n, n), x.dtype)
    La = np.zeros((L, L), x.dtype)
    Ln = np.zeros((n, n), x.dtype)
    X = np.empty((ns, L), x.dtype)
    Xf = np.empty((ns, n), x.dtype)
    Zs = np.empty((ns, m), x.dtype)
    wz = np.zeros(n, x.dtype)
    vz = np.zeros(m, x.dtype)
    xm = np.empty(n, x.dtype)
    Pp = np.empty((n, n), x.dtype)
    zp = np.empty(m, x.dtype)
    S = np.empty((m, m), x.dtype)
    Ls = np.empty((m, m), x.dtype)
    Pxz = np.empty((n, m), x.dtype)
    W = np.empty((m, n), x.dtype)
    K = np.empty((n, m), x.dtype)
    for b in range(nb):
        eb = ev[b]
        for k in range(T):
            for i in range(n):
                for j in range(n):
                    Pa[i, j] = c[0] * P[b, i, j]
            if not _chol(Pa, Ln):
                eb[_EV_CHOL] += 1
                for i in range(n):
                    d = P[b, i, i]
                    if not d > pfloor[0]:
                        d = pfloor[0]
                    for j in range(n):
                        P[b, i, j] = z0
                    P[b, i, i] = d
                    for j in range(n):
                        Pa[i, j] = c[0] * P[b, i, j]
                _chol(Pa, Ln)
            for i in range(n):
                for j in range(n):
                    La[i, j] = Ln[i, j]
            if aug:  # the noise blocks of the augmented factor are constant: sqrt(c) Lq, sqrt(c) Lr
                for i in range(L):
                    for j in range(L):
                        if i >= n or j >= n:
                            La[i, j] = z0
                for i in range(n):
                    for j in range(n):
                        La[n + i, n + j] = Lq[i, j]
                for i in range(m):
                    for j in range(m):
                        La[2 * n + i, 2 * n + j] = Lr[i, j]
            for j in range(L):
                X[0, j] = x[b, j] if j < n else z0
            for i in range(L):
                for j in range(L):
                    base = x[b, j] if j < n else z0
                    X[1 + i, j] = base + La[j, i]
                    X[1 + L + i, j] = base - La[j, i]
            for s in range(ns):
                if aug:
                    f(X[s, :n], X[s, n:2 * n], pf, Xf[s])
                else:
                    f(X[s, :n], wz, pf, Xf[s])
            for i in range(n):
                acc = z0
                for s in range(ns):
                    acc += wm[s] * Xf[s, i]
                xm[i] = acc
            for i in range(n):
                for j in range(i, n):
                    acc = z0
                    for s in range(ns):
                        acc += wc[s] * (Xf[s, i] - xm[i]) * (Xf[s, j] - xm[j])
                    if not aug:
                        acc += Q[i, j]
                    Pp[i, j] = acc
                    Pp[j, i] = acc
            if redraw and not aug:  # sigma points of the prediction (xm, Pp) for h
                for i in range(n):
                    for j in range(n):
                        Pa[i, j] = c[0] * Pp[i, j]
                if not _chol(Pa, Ln):
                    eb[_EV_CHOL] += 1
                    for i in range(n):
                        d = Pp[i, i]
                        if not d > pfloor[0]:
                            d = pfloor[0]
                        for j in range(n):
                            Pa[i, j] = z0
                        Pa[i, i] = c[0] * d
                    _chol(Pa, Ln)
                for j in range(n):
                    Xf[0, j] = xm[j]
                for i in range(n):
                    for j in range(n):
                        Xf[1 + i, j] = xm[j] + Ln[j, i]
                        Xf[1 + n + i, j] = xm[j] - Ln[j, i]
            done = False
            if not zok[b, k]:
                eb[_EV_IMPL] += 1
            else:
                for s in range(ns):
                    if aug:
                        h(Xf[s], X[s, 2 * n:], ph, Zs[s])
                    else:
                        h(Xf[s], vz, ph, Zs[s])
                for r in range(m):
                    acc = z0
                    for s in range(ns):
                        acc += wm[s] * Zs[s, r]
                    zp[r] = acc
                for r in range(m):
                    for q in range(r, m):
                        acc = z0
                        for s in range(ns):
                            acc += wc[s] * (Zs[s, r] - zp[r]) * (Zs[s, q] - zp[q])
                        if not aug:
                            acc += R[r, q]
                        S[r, q] = acc
                        S[q, r] = acc
                for i in range(n):
                    for r in range(m):
                        acc = z0
                        for s in range(ns):
                            acc += wc[s] * (Xf[s, i] - xm[i]) * (Zs[s, r] - zp[r])
                        Pxz[i, r] = acc
                if not _chol(S, Ls):
                    eb[_EV_SNPD] += 1
                else:
                    for r in range(m):           # W = Ls^-1 Pxz^T
                        for j in range(n):
                            acc = Pxz[j, r]
                            for l in range(r):
                                acc -= Ls[r, l] * W[l, j]
                            W[r, j] = acc / Ls[r, r]
                    for r in range(m - 1, -1, -1):   # K^T = Ls^-T W
                        for j in range(n):
                            acc = W[r, j]
                            for l in range(r + 1, m):
                                acc -= Ls[l, r] * K[j, l]
                            K[j, r] = acc / Ls[r, r]
                    for i in range(n):
                        acc = xm[i]
                        for r in range(m):
                            acc += K[i, r] * (z[b, k, r] - zp[r])
                        x[b, i] = acc
                    for i in range(n):
                        for j in range(i, n):
                            acc = Pp[i, j]
                            for r in range(m):
                                for q in range(m):
                                    acc -= K[i, r] * S[r, q] * K[j, q]
                            P[b, i, j] = acc
                            P[b, j, i] = acc
                    done = True
            if not done:
                for i in range(n):
                    x[b, i] = xm[i]
                    for j in range(n):
                        P[b, i, j] = Pp[i, j]
            for i in range(n):
                xs[b, k, i] = x[b, i]
            if keep_P:
                for i in range(n):
                    for j in range(n):
                        Ps[b, k, i, j] = P[b, i, j]


@dataclass
class UKFRun:
    """States after each step ``(B, T, n)``, covariances if kept, events."""

    x: np.ndarray
    P: np.ndarray | None
    events: dict


class UnscentedKalmanFilter:
    """Unscented Kalman filter, batched over trials.

    Parameters
    ----------
    model : NonlinearModel
    x0 : (n,) or (B, n) array
    P0 : (n, n) or (B, n, n) array, symmetric PSD
    alpha : float
        Spread of the sigma points, in (0, 1] (the seed's ``epsilon`` may exceed 1: allowed
        up to 10).
    beta : float
        Prior-distribution term (2 for a Gaussian), >= 0.
    kappa : float
        Secondary scaling; ``L + kappa`` must be > 0.
    noise : {"additive", "augmented"}
    arithmetic : {"float64", "float32"}
    trials : int
    p_floor : float
        Smallest diagonal kept by the Cholesky recovery.
    z_limit : float, optional
    redraw : bool
        Additive noise: draw new sigma points from the prediction ``(xm, Pp)`` before ``h``
        (default; the UT of the whole step is then exact on a linear model, i.e. the filter
        equals the Kalman filter). ``False`` passes the propagated points to ``h``,
        which leaves ``H Q H^T`` out of the innovation covariance.
    """

    def __init__(self, model: NonlinearModel, x0, P0, *, alpha: float = 1e-3, beta: float = 2.0,
                 kappa: float = 0.0, noise: str = "additive", arithmetic="float64", trials: int = 1,
                 p_floor: float = 1e-12, z_limit: float | None = None, redraw: bool = True):
        if not isinstance(model, NonlinearModel):
            raise ValueError(f"model must be a NonlinearModel, not {model!r}")
        kind = arithmetic_name(arithmetic)
        if kind == "fixed":
            raise ValueError("the unscented filter runs in 'float64' or 'float32' (see the module "
                             "docstring for why no fixed-point form)")
        if noise not in ("additive", "augmented"):
            raise ValueError(f"noise must be 'additive' or 'augmented', not {noise!r}")
        if not (isinstance(alpha, (int, float)) and 0 < alpha <= 10):
            raise ValueError(f"alpha must be in (0, 10], not {alpha!r}")
        if not (isinstance(beta, (int, float)) and beta >= 0):
            raise ValueError(f"beta must be >= 0, not {beta!r}")
        if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials < 1:
            raise ValueError(f"trials must be an integer >= 1, not {trials!r}")
        if not (p_floor > 0):
            raise ValueError(f"p_floor must be > 0, not {p_floor!r}")
        n, m = model.n, model.m
        L = n + (n + m if noise == "augmented" else 0)
        if not (isinstance(kappa, (int, float)) and L + kappa > 0):
            raise ValueError(f"kappa must make L + kappa > 0 (L = {L}), not {kappa!r}")
        wm, wc, c = sigma_weights(L, float(alpha), float(beta), float(kappa))
        if not c > 0:
            raise ValueError(f"alpha and kappa give L + lambda = {c:g}; it must be > 0")
        self.model, self.trials, self.kind, self.z_limit = model, int(trials), kind, z_limit
        self.aug = noise == "augmented"
        self.redraw = bool(redraw)
        dt = np.float64 if kind == "float64" else np.float32
        x0 = np.asarray(x0, np.float64)
        P0 = np.asarray(P0, np.float64)
        if x0.shape not in ((n,), (self.trials, n)):
            raise ValueError(f"x0 must have shape ({n},) or ({self.trials}, {n}), not {x0.shape}")
        if P0.shape not in ((n, n), (self.trials, n, n)):
            raise ValueError(f"P0 must have shape ({n}, {n}) or ({self.trials}, {n}, {n}), not {P0.shape}")
        check_psd("P0", np.broadcast_to(P0, (self.trials, n, n)))
        self.x = np.array(np.broadcast_to(x0, (self.trials, n)), dtype=dt, order="C")
        self.P = np.array(np.broadcast_to(P0, (self.trials, n, n)), dtype=dt, order="C")
        self._w = (wm.astype(dt), wc.astype(dt), np.array([c], dt), np.array([p_floor], dt))
        Lq, Lr = (np.sqrt(c) * psd_sqrt(a) for a in (model.Q, model.R))
        self._mats = tuple(np.ascontiguousarray(a, dtype=dt) for a in
                           (model.Q, model.R, Lq, Lr, model.prm_f, model.prm_h))
        self.ev = EVENTS.new((self.trials,))

    def counts(self) -> dict:
        return EVENTS.counts(self.ev)

    def run(self, z, *, keep_P: bool = False) -> UKFRun:
        """Filter ``T`` steps; ``z`` ``(T, m)`` or ``(B, T, m)`` (``(T,)`` for m = 1)."""
        m, n = self.model.m, self.model.n
        z = np.asarray(z, np.float64)
        shape = z.shape
        if z.ndim == 1 and m == 1:
            z = z[:, None]
        if z.ndim == 2:
            z = np.broadcast_to(z, (self.trials,) + z.shape)
        if z.ndim != 3 or z.shape[0] != self.trials or z.shape[2] != m:
            raise ValueError(f"z must have shape (T, {m}) or ({self.trials}, T, {m}), not {shape}")
        ok = np.all(np.isfinite(z), axis=2)
        if self.z_limit is not None:
            ok &= np.all(np.abs(np.where(np.isfinite(z), z, 0.0)) <= self.z_limit, axis=2)
        zc = np.ascontiguousarray(np.where(ok[..., None], z, 0.0).astype(self.x.dtype))
        T = z.shape[1]
        xs = np.empty((self.trials, T, n), self.x.dtype)
        Ps = np.empty((self.trials, T if keep_P else 0, n, n), self.x.dtype)
        Q, R, Lq, Lr, pf, ph = self._mats
        wm, wc, c, pfl = self._w
        _ukf_kernel(self.model.f, self.model.h, self.x, self.P, zc, ok, Q, R, Lq, Lr, pf, ph, wm, wc, c, pfl,
                    self.aug, self.redraw, self.ev, xs, Ps, keep_P)
        return UKFRun(xs.astype(np.float64), Ps.astype(np.float64) if keep_P else None, self.counts())
