"""The master of the adaptive UKF carrier tracker (:mod:`dsp.gnss.aukf`): the AUKF patent's
closed form of the augmented UKF update on the carrier phase (:func:`master_update`, a numba
kernel; :func:`master_update_generic` runs the same update through the generic augmented UKF
of :mod:`dsp.estimation.ukf`), its weights (:func:`ut_weights`) and the formats of its fixed-point
emulation (:class:`AukfFormats`)."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..estimation.ukf import UnscentedKalmanFilter
from ..estimation.ukf_formats import sigma_weights
from ..estimation.nonlinear import NonlinearModel
from ..jit import njit_cached

TWO_PI = 2.0 * np.pi
#: Augmented state of the master's UKF: 4 states, 4 process noise, 2 measurement noise.
N_AUG = 10


@dataclass(frozen=True)
class QFormat:
    """Signed fixed-point format: ``bits`` total, ``frac`` fraction bits."""

    bits: int
    frac: int

    def __post_init__(self):
        if not (isinstance(self.bits, int) and 2 <= self.bits <= 62):
            raise ValueError(f"format bits must be an integer in 2..62, not {self.bits!r}")
        if not (isinstance(self.frac, int) and 0 <= self.frac < self.bits + 40):
            raise ValueError(f"format frac must be an integer >= 0, not {self.frac!r}")

    @property
    def max_value(self) -> float:
        return (2.0 ** (self.bits - 1) - 1) * 2.0 ** -self.frac


@dataclass(frozen=True)
class AukfFormats:
    """Word lengths of the fixed-point master and slave (each a :class:`QFormat`).

    theta, w0, w1, w2 : state elements (rad, rad/s, rad/s^2, rad/s^3)
    P : covariance entries; y : normalised I/Q and the innovation; trig : sin/cos values;
    gain : ``Pyy^-1`` entries and the gain terms; q : the slave's ``q_hat`` and its variance.
    """

    theta: QFormat = QFormat(24, 20)
    w0: QFormat = QFormat(48, 30)
    w1: QFormat = QFormat(40, 28)
    w2: QFormat = QFormat(32, 22)
    P: QFormat = QFormat(48, 36)
    y: QFormat = QFormat(24, 18)
    trig: QFormat = QFormat(20, 18)
    gain: QFormat = QFormat(32, 22)
    q: QFormat = QFormat(32, 16)

    def __post_init__(self):
        for f in fields(self):
            if not isinstance(getattr(self, f.name), QFormat):
                raise ValueError(f"AukfFormats.{f.name} must be a QFormat, not {getattr(self, f.name)!r}")

    def table(self) -> np.ndarray:
        """``(9, 2)`` float array ``[frac, max]`` in field order (kernel input)."""
        return np.array([[getattr(self, f.name).frac, getattr(self, f.name).max_value]
                         for f in fields(self)], np.float64)


_ITH, _IW0, _IW1, _IW2, _IP, _IY, _ITRIG, _IGAIN, _IQ = range(9)


@njit_cached
def _qs(v, mode, fm, i, ev):
    """Store ``v`` into signal ``i``: mode 0 float64, 1 float32, 2 fixed (round half up to
    ``fm[i, 0]`` fraction bits, saturate at ``fm[i, 1]``, count in ``ev[2]``)."""
    if mode == 0:
        return v
    if mode == 1:
        return float(np.float32(v))
    s = 2.0 ** fm[i, 0]
    r = math.floor(v * s + 0.5) / s
    if r > fm[i, 1]:
        ev[2] += 1
        return fm[i, 1]
    if r < -fm[i, 1]:
        ev[2] += 1
        return -fm[i, 1]
    return r


@njit_cached
def _pyy_terms(p11, th, A, W, mode, fm, ev):
    """``(a, u, v, Pyy without R (3 entries), c)`` of the closed form for ``P-_11``."""
    W1, W2, W3, cL = W[0], W[1], W[2], W[3]
    c = _qs(math.sqrt(cL * p11), mode, fm, _ITH, ev)
    cc = _qs(math.cos(c), mode, fm, _ITRIG, ev)
    sc = _qs(math.sin(c), mode, fm, _ITRIG, ev)
    a = _qs(W1 + 18.0 * W2 + 2.0 * cc * W2, mode, fm, _ITRIG, ev)
    W6 = W3 + 18.0 * W2
    W4 = W6 * (1.0 - a) * (1.0 - a)
    m = 2.0 * W2 * sc * sc
    nn = 2.0 * W2 * (cc - a) * (cc - a)
    l_ = m - nn
    u0 = _qs(math.cos(th), mode, fm, _ITRIG, ev)
    u1 = _qs(math.sin(th), mode, fm, _ITRIG, ev)
    A2 = A * A
    g = W4 - l_
    s00 = _qs(A2 * (g * u0 * u0 + m), mode, fm, _IP, ev)
    s01 = _qs(A2 * g * u0 * u1, mode, fm, _IP, ev)
    s11 = _qs(A2 * (g * u1 * u1 + m), mode, fm, _IP, ev)
    return a, u0, u1, s00, s01, s11, sc


@njit_cached
def master_kernel(x, P, y, ok, dphi, qhat, Phi, Qbar, R, A, W, pfloor, mode, fm, ev, nu_out,
                   predict):
    """One epoch for every trial: prediction (``predict``) then the closed-form update.
    ``x (B, 4)``, ``P (B, 4, 4)`` updated in place; ``nu_out (B, 2)`` the innovation."""
    B = x.shape[0]
    xp = np.empty(4)
    Pp = np.empty((4, 4))
    tmp = np.empty((4, 4))
    fx = np.array([_ITH, _IW0, _IW1, _IW2])
    for b in range(B):
        eb = ev[b]
        if predict:
            for i in range(4):
                acc = 0.0
                for j in range(4):
                    acc += Phi[i, j] * x[b, j]
                xp[i] = acc
            xp[0] -= dphi[b]
            for i in range(4):
                xp[i] = _qs(xp[i], mode, fm, fx[i], eb)
            for i in range(4):
                for j in range(4):
                    acc = 0.0
                    for k in range(4):
                        acc += Phi[i, k] * P[b, k, j]
                    tmp[i, j] = acc
            for i in range(4):
                for j in range(i, 4):
                    acc = qhat[b] * Qbar[i, j]
                    for k in range(4):
                        acc += tmp[i, k] * Phi[j, k]
                    Pp[i, j] = _qs(acc, mode, fm, _IP, eb)
                    Pp[j, i] = Pp[i, j]
        else:
            for i in range(4):
                xp[i] = x[b, i]
                for j in range(4):
                    Pp[i, j] = P[b, i, j]
        if not Pp[0, 0] > 0.0:                     # Cholesky of P- fails at its first pivot
            eb[0] += 1
            for i in range(4):
                d = Pp[i, i]
                if not d > pfloor:
                    d = pfloor
                for j in range(4):
                    Pp[i, j] = 0.0
                Pp[i, i] = d
        nu_out[b, 0] = 0.0
        nu_out[b, 1] = 0.0
        if ok[b]:
            a, u0, u1, s00, s01, s11, sc = _pyy_terms(Pp[0, 0], xp[0], A, W, mode, fm, eb)
            s00 += R[0, 0]
            s01 += R[0, 1]
            s11 += R[1, 1]
            det = s00 * s11 - s01 * s01
            if s00 > 0.0 and det > 0.0:
                i00 = _qs(s11 / det, mode, fm, _IGAIN, eb)
                i01 = _qs(-s01 / det, mode, fm, _IGAIN, eb)
                i11 = _qs(s00 / det, mode, fm, _IGAIN, eb)
                e0 = _qs(y[b, 0] - A * a * u0, mode, fm, _IY, eb)
                e1 = _qs(y[b, 1] - A * a * u1, mode, fm, _IY, eb)
                nu_out[b, 0] = e0
                nu_out[b, 1] = e1
                v0, v1 = -u1, u0
                # Pxy = g s0 v^T, s0 = sqrt(cL / P-11) P-[:, 0], g = 2 A W2 sin c
                g = 2.0 * A * W[1] * sc * math.sqrt(W[3] / Pp[0, 0])
                g = _qs(g, mode, fm, _IGAIN, eb)
                wv0 = v0 * i00 + v1 * i01               # Pyy^-1 v
                wv1 = v0 * i01 + v1 * i11
                r = _qs(wv0 * e0 + wv1 * e1, mode, fm, _IGAIN, eb)   # v^T Pyy^-1 nu
                vv = _qs(v0 * wv0 + v1 * wv1, mode, fm, _IGAIN, eb)  # v^T Pyy^-1 v
                for i in range(4):
                    x[b, i] = _qs(xp[i] + g * Pp[i, 0] * r, mode, fm, fx[i], eb)
                h = g * g * vv
                for i in range(4):
                    for j in range(i, 4):
                        P[b, i, j] = _qs(Pp[i, j] - h * Pp[i, 0] * Pp[j, 0], mode, fm, _IP, eb)
                        P[b, j, i] = P[b, i, j]
                continue
            eb[1] += 1
        for i in range(4):
            x[b, i] = xp[i]
            for j in range(4):
                P[b, i, j] = Pp[i, j]


@njit_cached
def pyy_diag_kernel(p11, th, A, W, R, out):
    """``diag Pyy`` for ``P-_11`` values ``p11 (B, J)`` (the patent's slave's ``h_q``)."""
    ev = np.zeros(3, np.int64)
    fm = np.zeros((9, 2))
    for b in range(p11.shape[0]):
        for j in range(p11.shape[1]):
            a, u0, u1, s00, s01, s11, sc = _pyy_terms(max(p11[b, j], 0.0), th[b], A, W, 0, fm, ev)
            out[b, j, 0] = s00 + R[0, 0]
            out[b, j, 1] = s11 + R[1, 1]


def ut_weights(epsilon: float = 1.027, beta: float = 2.0, kappa: float = 0.0, L: int = N_AUG):
    """``[W1 = Wm0, W2 = Wi, W3 = Wc0, n + lambda]`` of the patent's scaled UT."""
    wm, wc, c = sigma_weights(L, epsilon, beta, kappa)
    return np.array([wm[0], wm[1], wc[0], c])


def master_update(xp, Pp, y, R, amplitude: float = 1.0, epsilon: float = 1.027, beta: float = 2.0,
                  kappa: float = 0.0):
    """Closed-form measurement update (float64) of predicted ``xp (B, 4)``, ``Pp (B, 4, 4)``
    with I/Q ``y (B, 2)``; returns ``(x, P, events)``."""
    x = np.array(xp, np.float64, ndmin=2, copy=True)
    P = np.array(Pp, np.float64, ndmin=3, copy=True)
    B = x.shape[0]
    ev = np.zeros((B, 3), np.int64)
    master_kernel(x, P, np.ascontiguousarray(np.reshape(y, (B, 2)), np.float64), np.ones(B, np.bool_),
                   np.zeros(B), np.zeros(B), np.eye(4), np.zeros((4, 4)), np.asarray(R, np.float64),
                   float(amplitude), ut_weights(epsilon, beta, kappa), 1e-12, 0, np.zeros((9, 2)), ev,
                   np.zeros((B, 2)), False)
    return x, P, ev


def master_update_generic(xp, Pp, y, R, amplitude: float = 1.0, epsilon: float = 1.027,
                          beta: float = 2.0, kappa: float = 0.0):
    """The same update by the generic augmented UKF (``dsp.estimation.ukf``, n = 10: the
    identity transition with zero process noise leaves the sigma points of ``P-``)."""
    xp = np.array(xp, np.float64, ndmin=2)
    Pp = np.array(Pp, np.float64, ndmin=3)
    B = xp.shape[0]
    model = NonlinearModel.phase_iq(np.eye(4), np.zeros((4, 4)), R, amplitude)
    f = UnscentedKalmanFilter(model, xp, Pp, alpha=epsilon, beta=beta, kappa=kappa,
                              noise="augmented", trials=B)
    r = f.run(np.reshape(y, (B, 1, 2)), keep_P=True)
    return r.x[:, 0], r.P[:, 0], r.events
