"""Unscented Kalman filter (scaled unscented transform), one source for float64, float32 and
fixed point, batched over trials.

The model says ``f`` and ``h`` (:class:`dsp.estimation.nonlinear.NonlinearModel`: numba functions
``f(x, w, prm, q, out)`` and ``h(x, v, prm, q, out)`` with their parameter arrays, plus Q
and R);
the filter says how they are combined; the arithmetic is a configuration. The sigma points
are van der Merwe's scaled set (as filterpy's ``MerweScaledSigmaPoints``)::

    lambda = alpha^2 (L + kappa) - L,  X = [x, x + U_i, x - U_i],  U^T U = (L + lambda) P
    Wm_0 = lambda / (L + lambda), Wc_0 = Wm_0 + 1 - alpha^2 + beta, W_i = 1 / (2 (L + lambda))

(``alpha`` is the AUKF patent's UT scaling ``epsilon``). Noise is *additive* (``L = n``; Q added to
the predicted covariance, R to the innovation covariance) or *augmented* (``L = n + n + m``:
the sigma points also span ``w ~ N(0, Q)`` and ``v ~ N(0, R)``, which ``f`` and ``h`` take
as arguments; the augmented factor is block diagonal, its constant noise blocks factored once
by :func:`psd_sqrt`, so a rank-deficient Q is fine). With additive noise the sigma points are redrawn from the prediction before
``h`` (``redraw=True``, the default, as filterpy 2.0 does); ``redraw=False`` passes the
propagated points to ``h`` (cheaper, but the innovation covariance then misses ``H Q H^T``, so
it is not the KF on a linear model). Augmented noise propagates the augmented points through both (exact on a
linear model). Update ``K = Pxz S^-1`` (Cholesky solves), ``P = Pp - V^T V`` (``V = Ls^-1
Pxz^T``, i.e. ``Pp - K S K^T``) mirrored to the upper triangle.

A Cholesky of ``(L + lambda) P`` that fails (a non-positive pivot: P lost definiteness) is
counted (``chol_fail``) and recovered by replacing P with its diagonal, each entry raised to
at least ``p_floor``, and factoring again (a diagonal with positive entries always factors).
An innovation covariance that does not factor skips the update (``s_not_pd``). NaN,
infinite or implausible (``z_limit``) measurements only predict (``implausible``).

Fixed point (a :class:`dsp.estimation.ukf_formats.UkfFormats` table, the same kernel compiled for int64): every step
above is one rounding into the format of its signal (``c P -> Pc``, its Cholesky by
:func:`~dsp.estimation.linalg.chol_q` ``-> U``, ``x +- U -> X``, ``f -> X``, ``sum Wm X ->
xm``, ``X - xm -> D``, ``Wc D -> D``, ``sum (Wc D) D (+ Q) -> Pp``, ``h -> Y``, ``sum Wm Y ->
Y``, ... ``Pyy``, ``Pxy``, ``chol -> Ls``, ``Ls^-1 Pxy^T -> V``, ``Ls^-T V -> K``, ``z - zp
-> e``, ``xm + K e -> x``, ``Pp - V^T V -> P``), checked bit for bit against Python integers
(``tests/dsp/estimation``). The covariance update is ``P = Pp - V^T V`` with ``V = Ls^-1
Pxy^T`` (equal to ``Pp - K S K^T``; one exact accumulation) in every arithmetic. The UT
weights must suit the ``W`` format (:func:`dsp.estimation.ukf_formats.weight_problem`): with small alpha (1e-3) the
centre weight is ~-1e6 against positive weights of ~+1e5 and the rounding errors cancel
badly, so such parameters are refused, naming the alpha that would do; the AUKF
patent's parameters (alpha = 1.027, beta = 2, kappa = 0, L = 10: Wm0 = 0.0519, Wc0 = 1.997, Wi =
0.0474) are bounded and held to 2^-15 relative.

Compilation: a numba kernel that takes the model functions as arguments is not cached, so
:func:`_kernel_for` makes one kernel per model with ``f`` and ``h`` bound in and caches it
(:func:`dsp.jit.njit_cached`): a new process loads it instead of compiling for ~15 s.
"""
from __future__ import annotations

import hashlib
import inspect
import types
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..jit import njit_cached
from .events import EventRegistry
from .formats import Arithmetic, fits, to_fixed
from .linalg import chol_q, solve_lower_q, solve_upper_t_q
from .models import check_psd
from ..qops import align, store
from .nonlinear import NonlinearModel
from .ukf_formats import UkfFormats, sigma_weights

SIGNALS = UkfFormats.signals()
EVENTS = EventRegistry(SIGNALS, ("implausible", "chol_fail", "s_not_pd", "div_zero"))
(_Z, _X, _P, _PC, _U, _XS, _W, _XM, _PP, _Y, _D, _PYY, _PXY, _LS, _V, _K, _E, _PRM) = range(len(SIGNALS))
_EV_IMPL = EVENTS.index("implausible")
_EV_CHOL = EVENTS.index("chol_fail")
_EV_SNPD = EVENTS.index("s_not_pd")
_EV_DIV = EVENTS.index("div_zero")
_BASE = EVENTS.base


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


_model_f = _model_h = None   # the model functions of one kernel instance (see _kernel_for)


def _ukf_template(x, P, z, zok, Q, R, Lq, Lr, pf, ph, qf, qh, wm, wc, c, pfloor, fr, lo, hi, hf,
                aug, redraw, ev, xs, Ps, keep_P):
    """One source: float64, float32 or int64 (fixed point, formats ``fr, lo, hi, hf`` in the
    order of :class:`UkfFormats`) by the dtype of ``x``."""
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
    Dx = np.empty((ns, n), x.dtype)
    Dwx = np.empty((ns, n), x.dtype)
    Dz = np.empty((ns, m), x.dtype)
    Dwz = np.empty((ns, m), x.dtype)
    wz = np.zeros(n, x.dtype)
    vz = np.zeros(m, x.dtype)
    xm = np.empty(n, x.dtype)
    Pp = np.empty((n, n), x.dtype)
    zp = np.empty(m, x.dtype)
    e = np.empty(m, x.dtype)
    S = np.empty((m, m), x.dtype)
    Ls = np.zeros((m, m), x.dtype)
    Pxz = np.empty((n, m), x.dtype)
    W = np.empty((m, n), x.dtype)
    K = np.empty((n, m), x.dtype)
    B = _BASE
    aX = max(fr[_X], fr[_U])            # x + U, exact
    aXm = max(fr[_XS], fr[_XM])          # Xf - xm, exact
    aZ = max(fr[_Y], fr[_Z])            # z - zp, exact
    aS = max(fr[_X], fr[_XM])           # x = xm (no update)
    for b in range(nb):
        eb = ev[b]
        for k in range(T):
            for i in range(n):
                for j in range(n):
                    Pa[i, j] = store(c[0] * P[b, i, j], fr[_W] + fr[_P] - fr[_PC], hf[_PC], lo[_PC], hi[_PC],
                                     eb, _PC, B)
            if not chol_q(Pa, Ln, 2 * fr[_U] - fr[_PC], hf[_U], lo[_U], hi[_U], eb, _U, _EV_DIV, B):
                eb[_EV_CHOL] += 1
                for i in range(n):
                    d = P[b, i, i]
                    if not d > pfloor[0]:
                        d = pfloor[0]
                    for j in range(n):
                        P[b, i, j] = z0
                    P[b, i, i] = d
                    for j in range(n):
                        Pa[i, j] = store(c[0] * P[b, i, j], fr[_W] + fr[_P] - fr[_PC], hf[_PC], lo[_PC],
                                         hi[_PC], eb, _PC, B)
                chol_q(Pa, Ln, 2 * fr[_U] - fr[_PC], hf[_U], lo[_U], hi[_U], eb, _U, _EV_DIV, B)
            for i in range(n):
                for j in range(i + 1):
                    La[i, j] = Ln[i, j]
            if aug:  # the noise blocks of the augmented factor are constant: sqrt(c) Lq, sqrt(c) Lr
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
                    if j < n:
                        base = align(x[b, j], aX - fr[_X])
                        u = align(La[j, i], aX - fr[_U])
                        X[1 + i, j] = store(base + u, aX - fr[_XS], hf[_XS], lo[_XS], hi[_XS], eb, _XS, B)
                        X[1 + L + i, j] = store(base - u, aX - fr[_XS], hf[_XS], lo[_XS], hi[_XS], eb, _XS, B)
                    else:  # noise sigma points, in the X format
                        u = store(align(La[j, i], aX - fr[_U]), aX - fr[_XS], hf[_XS], lo[_XS], hi[_XS], eb, _XS, B)
                        X[1 + i, j] = u
                        X[1 + L + i, j] = -u
            for s in range(ns):
                if aug:
                    _model_f(X[s, :n], X[s, n:2 * n], pf, qf, Xf[s])
                else:
                    _model_f(X[s, :n], wz, pf, qf, Xf[s])
                for i in range(n):
                    Xf[s, i] = store(Xf[s, i], 0, 0, lo[_XS], hi[_XS], eb, _XS, B)
            for i in range(n):
                acc = z0
                for s in range(ns):
                    acc += wm[s] * Xf[s, i]
                xm[i] = store(acc, fr[_W] + fr[_XS] - fr[_XM], hf[_XM], lo[_XM], hi[_XM], eb, _XM, B)
            for s in range(ns):
                for i in range(n):
                    Dx[s, i] = store(align(Xf[s, i], aXm - fr[_XS]) - align(xm[i], aXm - fr[_XM]), aXm - fr[_D],
                                     hf[_D], lo[_D], hi[_D], eb, _D, B)
                    Dwx[s, i] = store(wc[s] * Dx[s, i], fr[_W], hf[_D], lo[_D], hi[_D], eb, _D, B)
            for i in range(n):
                for j in range(i, n):
                    acc = z0
                    for s in range(ns):
                        acc += Dwx[s, i] * Dx[s, j]
                    if not aug:
                        acc += align(Q[i, j], 2 * fr[_D] - fr[_PP])
                    Pp[i, j] = store(acc, 2 * fr[_D] - fr[_PP], hf[_PP], lo[_PP], hi[_PP], eb, _PP, B)
                    Pp[j, i] = Pp[i, j]
            if redraw and not aug:  # sigma points of the prediction (xm, Pp) for h
                for i in range(n):
                    for j in range(n):
                        Pa[i, j] = store(c[0] * Pp[i, j], fr[_W] + fr[_PP] - fr[_PC], hf[_PC], lo[_PC],
                                         hi[_PC], eb, _PC, B)
                if not chol_q(Pa, Ln, 2 * fr[_U] - fr[_PC], hf[_U], lo[_U], hi[_U], eb, _U, _EV_DIV, B):
                    eb[_EV_CHOL] += 1
                    for i in range(n):
                        d = Pp[i, i]
                        if not d > pfloor[1]:
                            d = pfloor[1]
                        for j in range(n):
                            Pa[i, j] = z0
                        Pa[i, i] = store(c[0] * d, fr[_W] + fr[_PP] - fr[_PC], hf[_PC], lo[_PC], hi[_PC],
                                         eb, _PC, B)
                    chol_q(Pa, Ln, 2 * fr[_U] - fr[_PC], hf[_U], lo[_U], hi[_U], eb, _U, _EV_DIV, B)
                aR = max(fr[_XM], fr[_U])
                for j in range(n):
                    Xf[0, j] = store(align(xm[j], aR - fr[_XM]), aR - fr[_XS], hf[_XS], lo[_XS], hi[_XS], eb, _XS, B)
                for i in range(n):
                    for j in range(n):
                        base = align(xm[j], aR - fr[_XM])
                        u = align(Ln[j, i] if i <= j else z0, aR - fr[_U])
                        Xf[1 + i, j] = store(base + u, aR - fr[_XS], hf[_XS], lo[_XS], hi[_XS], eb, _XS, B)
                        Xf[1 + n + i, j] = store(base - u, aR - fr[_XS], hf[_XS], lo[_XS], hi[_XS], eb, _XS, B)
                for s in range(ns):
                    for i in range(n):
                        Dx[s, i] = store(align(Xf[s, i], aXm - fr[_XS]) - align(xm[i], aXm - fr[_XM]),
                                         aXm - fr[_D], hf[_D], lo[_D], hi[_D], eb, _D, B)
                        Dwx[s, i] = store(wc[s] * Dx[s, i], fr[_W], hf[_D], lo[_D], hi[_D], eb, _D, B)
            done = False
            if not zok[b, k]:
                eb[_EV_IMPL] += 1
            else:
                for s in range(ns):
                    if aug:
                        _model_h(Xf[s], X[s, 2 * n:], ph, qh, Zs[s])
                    else:
                        _model_h(Xf[s], vz, ph, qh, Zs[s])
                    for r in range(m):
                        Zs[s, r] = store(Zs[s, r], 0, 0, lo[_Y], hi[_Y], eb, _Y, B)
                for r in range(m):
                    acc = z0
                    for s in range(ns):
                        acc += wm[s] * Zs[s, r]
                    zp[r] = store(acc, fr[_W], hf[_Y], lo[_Y], hi[_Y], eb, _Y, B)
                for s in range(ns):
                    for r in range(m):
                        Dz[s, r] = store(Zs[s, r] - zp[r], fr[_Y] - fr[_D], hf[_D], lo[_D], hi[_D], eb, _D, B)
                        Dwz[s, r] = store(wc[s] * Dz[s, r], fr[_W], hf[_D], lo[_D], hi[_D], eb, _D, B)
                for r in range(m):
                    for q in range(r, m):
                        acc = z0
                        for s in range(ns):
                            acc += Dwz[s, r] * Dz[s, q]
                        if not aug:
                            acc += align(R[r, q], 2 * fr[_D] - fr[_PYY])
                        S[r, q] = store(acc, 2 * fr[_D] - fr[_PYY], hf[_PYY], lo[_PYY], hi[_PYY], eb, _PYY, B)
                        S[q, r] = S[r, q]
                for i in range(n):
                    for r in range(m):
                        acc = z0
                        for s in range(ns):
                            acc += Dwx[s, i] * Dz[s, r]
                        Pxz[i, r] = store(acc, 2 * fr[_D] - fr[_PXY], hf[_PXY], lo[_PXY], hi[_PXY], eb, _PXY, B)
                if not chol_q(S, Ls, 2 * fr[_LS] - fr[_PYY], hf[_LS], lo[_LS], hi[_LS], eb, _LS, _EV_DIV, B):
                    eb[_EV_SNPD] += 1
                else:
                    solve_lower_q(Ls, Pxz, W, fr[_LS] + fr[_V] - fr[_PXY], hf[_V], lo[_V], hi[_V], eb, _V,
                                  _EV_DIV, B)                         # W = Ls^-1 Pxz^T
                    solve_upper_t_q(Ls, W, K, fr[_LS] + fr[_K] - fr[_V], hf[_K], lo[_K], hi[_K], eb, _K,
                                    _EV_DIV, B)                       # K^T = Ls^-T W
                    for r in range(m):
                        e[r] = store(align(z[b, k, r], aZ - fr[_Z]) - align(zp[r], aZ - fr[_Y]), aZ - fr[_E],
                                     hf[_E], lo[_E], hi[_E], eb, _E, B)
                    a = fr[_K] + fr[_E]
                    for i in range(n):
                        acc = align(xm[i], a - fr[_XM])
                        for r in range(m):
                            acc += K[i, r] * e[r]
                        x[b, i] = store(acc, a - fr[_X], hf[_X], lo[_X], hi[_X], eb, _X, B)
                    a = 2 * fr[_V]
                    for i in range(n):                # P = Pp - W^T W  (= Pp - K S K^T)
                        for j in range(i, n):
                            acc = align(Pp[i, j], a - fr[_PP])
                            for r in range(m):
                                acc -= W[r, i] * W[r, j]
                            P[b, i, j] = store(acc, a - fr[_P], hf[_P], lo[_P], hi[_P], eb, _P, B)
                            P[b, j, i] = P[b, i, j]
                    done = True
            if not done:
                for i in range(n):
                    x[b, i] = store(align(xm[i], aS - fr[_XM]), aS - fr[_X], hf[_X], lo[_X], hi[_X], eb, _X, B)
                    for j in range(n):
                        P[b, i, j] = store(align(Pp[i, j], max(fr[_P], fr[_PP]) - fr[_PP]),
                                           max(fr[_P], fr[_PP]) - fr[_P], hf[_P], lo[_P], hi[_P], eb, _P, B)
            for i in range(n):
                xs[b, k, i] = x[b, i]
            if keep_P:
                for i in range(n):
                    for j in range(n):
                        Ps[b, k, i, j] = P[b, i, j]


_KERNELS: dict = {}


def _kernel_for(f, h):
    """The UKF kernel with the model functions ``f`` and ``h`` bound in (one instance per
    model, kept in :data:`_KERNELS`). A kernel that takes the model functions as arguments
    is not cached by numba (it recompiled ~13 s in every process); this one is a copy of
    :func:`_ukf_template` whose globals hold ``f`` and ``h`` and whose name carries a hash
    of their definitions (module, name and the source file of each), cached with
    :func:`dsp.jit.njit_cached` (which keys on the project's sources as well)."""
    key = (f, h)
    k = _KERNELS.get(key)
    if k is None:
        tag = hashlib.sha256()
        for fn in (f, h):
            py = getattr(fn, "py_func", None)
            if py is None:
                raise ValueError(f"model functions must be numba @njit functions, not {fn!r}")
            tag.update(f"{py.__module__}.{py.__qualname__}\0".encode())
            try:
                tag.update(Path(inspect.getfile(py)).read_bytes())
            except (OSError, TypeError):
                tag.update(repr(id(py)).encode())
        g = dict(_ukf_template.__globals__)
        g["_model_f"], g["_model_h"] = f, h
        name = f"_ukf_kernel_{tag.hexdigest()[:16]}"
        fn = types.FunctionType(_ukf_template.__code__, g, name, _ukf_template.__defaults__)
        fn.__qualname__ = name
        fn.__module__ = __name__
        fn.__doc__ = _ukf_template.__doc__
        k = _KERNELS[key] = njit_cached(fn)
    return k


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
        Spread of the sigma points, in (0, 1] (the AUKF patent's ``epsilon`` may exceed 1: allowed
        up to 10).
    beta : float
        Prior-distribution term (2 for a Gaussian), >= 0.
    kappa : float
        Secondary scaling; ``L + kappa`` must be > 0.
    noise : {"additive", "augmented"}
    arithmetic : {"float64", "float32"} or UkfFormats
        Fixed point: the UT weights must suit the ``W`` format (:func:`weight_problem`);
        otherwise a ValueError names the rule, the bad value and the alpha that would do.
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
        ar = Arithmetic.of(arithmetic, UkfFormats, "unscented filter")
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
        self.model, self.trials, self.z_limit = model, int(trials), z_limit
        self.ar, self.kind, self.formats = ar, ar.kind, ar.formats
        self.aug = noise == "augmented"
        self.redraw = bool(redraw)
        if ar.fixed:
            ar.formats.check(n, m, L)
            ar.formats.check_weights(L, float(alpha), float(beta), float(kappa))
        dt = ar.dtype
        x0 = np.asarray(x0, np.float64)
        P0 = np.asarray(P0, np.float64)
        if x0.shape not in ((n,), (self.trials, n)):
            raise ValueError(f"x0 must have shape ({n},) or ({self.trials}, {n}), not {x0.shape}")
        if P0.shape not in ((n, n), (self.trials, n, n)):
            raise ValueError(f"P0 must have shape ({n}, {n}) or ({self.trials}, {n}, {n}), not {P0.shape}")
        check_psd("P0", np.broadcast_to(P0, (self.trials, n, n)))
        x0 = np.broadcast_to(x0, (self.trials, n))
        P0 = np.broadcast_to(P0, (self.trials, n, n))
        Lq, Lr = (np.sqrt(c) * psd_sqrt(a) for a in (model.Q, model.R))
        if ar.fixed:
            fm = ar.formats
            for what, v, f in (("x0", x0, fm.x), ("P0", P0, fm.P), ("Q", model.Q, fm.Pp), ("R", model.R, fm.Pyy),
                               ("sqrt(c) chol(Q)", Lq, fm.U), ("sqrt(c) chol(R)", Lr, fm.U),
                               ("prm_f", model.prm_f, fm.prm), ("prm_h", model.prm_h, fm.prm)):
                fits(what, v, f)
            self.x, self.P = to_fixed(x0, fm.x), to_fixed(P0, fm.P)
            self._w = (to_fixed(wm, fm.W), to_fixed(wc, fm.W), to_fixed([c], fm.W),
                       np.array([max(1, to_fixed(p_floor, fm.P)), max(1, to_fixed(p_floor, fm.Pp))], np.int64))
            self._mats = tuple(np.ascontiguousarray(to_fixed(a, f)) for a, f in
                               ((model.Q, fm.Pp), (model.R, fm.Pyy), (Lq, fm.U), (Lr, fm.U),
                                (model.prm_f, fm.prm), (model.prm_h, fm.prm)))
            r = fm.fracs()
            self._q = (np.array([r["X"], r["X"], r["prm"], r["X"], int(fm.X.rounding == "half_up")], np.int64),
                       np.array([r["X"], r["X"], r["prm"], r["Y"], int(fm.Y.rounding == "half_up")], np.int64))
        else:
            self.x = np.array(x0, dtype=dt, order="C")
            self.P = np.array(P0, dtype=dt, order="C")
            self._w = (wm.astype(dt), wc.astype(dt), np.array([c], dt), np.array([p_floor, p_floor], dt))
            self._mats = tuple(np.ascontiguousarray(a, dtype=dt) for a in
                               (model.Q, model.R, Lq, Lr, model.prm_f, model.prm_h))
            self._q = (np.zeros(5, np.int64), np.zeros(5, np.int64))
        self._fmt = ar.arrays[:4]
        self.events = EVENTS
        self.ev = EVENTS.new((self.trials,))

    def counts(self) -> dict:
        return EVENTS.counts(self.ev)

    def run(self, z, *, keep_P: bool = False) -> UKFRun:
        """Filter ``T`` steps; ``z`` ``(T, m)`` or ``(B, T, m)`` (``(T,)`` for m = 1)."""
        n = self.model.n
        zc, ok, T = self.ar.measurements(z, self.model.m, self.trials, self.z_limit)
        zc = self.ar.words(zc, "z")
        xs = np.empty((self.trials, T, n), self.x.dtype)
        Ps = np.empty((self.trials, T if keep_P else 0, n, n), self.x.dtype)
        Q, R, Lq, Lr, pf, ph = self._mats
        wm, wc, c, pfl = self._w
        fr, lo, hi, hf = self._fmt
        _kernel_for(self.model.f, self.model.h)(self.x, self.P, zc, ok, Q, R, Lq, Lr, pf, ph, self._q[0],
                    self._q[1], wm, wc, c, pfl, fr, lo, hi, hf, self.aug, self.redraw, self.ev, xs, Ps, keep_P)
        return UKFRun(self.ar.physical(xs, "x"), self.ar.physical(Ps, "P") if keep_P else None,
                      self.counts())

    def state(self):
        """Current ``(x, P)`` in physical units (float64)."""
        return self.ar.physical(self.x, "x"), self.ar.physical(self.P, "P")
