"""The process and measurement model of the unscented filter (:class:`NonlinearModel`):
numba functions ``f`` and ``h`` written once with the operators of :mod:`dsp.qops`, their
parameter arrays and the noise covariances, with the linear and carrier-phase I/Q models
built in."""
from __future__ import annotations


import numpy as np

from ..jit import njit_cached
from .models import MAX_STATES, check_psd
from ..qops import align, cos_q, rs, sin_q


@njit_cached
def _f_linear(x, w, prm, q, out):
    """``F x + w`` (fixed point: ``q = [frac x, frac w, frac prm, frac out, half]``)."""
    n = x.shape[0]
    for i in range(n):
        acc = align(w[i], q[0] + q[2] - q[1])
        for j in range(n):
            acc += prm[i, j] * x[j]
        out[i] = rs(acc, q[0] + q[2] - q[3], q[4])


@njit_cached
def _h_linear(x, v, prm, q, out):
    """``H x + v``."""
    for r in range(out.shape[0]):
        acc = align(v[r], q[0] + q[2] - q[1])
        for j in range(x.shape[0]):
            acc += prm[r, j] * x[j]
        out[r] = rs(acc, q[0] + q[2] - q[3], q[4])


@njit_cached
def _h_iq(x, v, prm, q, out):
    """``A [cos x0, sin x0] + v`` (``A = prm[0, 0]``): the I/Q of a carrier phase."""
    acc = prm[0, 0] * cos_q(x[0], q[0], q[3], q[4]) + align(v[0], q[2] + q[3] - q[1])
    out[0] = rs(acc, q[2], q[4])
    acc = prm[0, 0] * sin_q(x[0], q[0], q[3], q[4]) + align(v[1], q[2] + q[3] - q[1])
    out[1] = rs(acc, q[2], q[4])


class NonlinearModel:
    """``x[k+1] = f(x[k], w)``, ``z[k] = h(x[k], v)`` with ``w ~ N(0, Q)``, ``v ~ N(0, R)``.

    Parameters
    ----------
    f, h : numba ``@njit`` functions
        ``f(x, w, prm_f, q, out)`` writes the next state (``n``) into ``out``; ``h(x, v,
        prm_h, q, out)`` the measurement (``m``). With additive noise ``w`` and ``v`` are zero
        and the noise is added by the filter; augmented, they are the noise sigma points.
        Write them once with the operators of :mod:`dsp.qops` (``align``, ``rs``,
        ``sin_q``, ``cos_q``) and the dtype of ``x`` (no float64 literals): they then run in
        float64, float32 and fixed point. ``q`` is an int64 array ``[frac x, frac w (or v),
        frac prm, frac out, half]`` (all 0 for floats): in fixed point ``x``, ``w`` and ``v``
        are in the ``X`` format, ``out`` in ``X`` (``f``) or ``Y`` (``h``), ``prm`` in
        ``prm``; the model rounds (``rs``), the filter saturates and counts.
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

    @classmethod
    def phase_iq(cls, F, Q, R, amplitude: float = 1.0) -> "NonlinearModel":
        """A carrier-phase model (the AUKF patent's shape): linear dynamics ``x[k+1] = F x + w`` of a
        state whose first element is the phase (rad), measured as the I/Q pair ``A [cos
        x0, sin x0] + v``. Runs in every arithmetic."""
        F = np.asarray(F, np.float64)
        if F.ndim != 2 or F.shape[0] != F.shape[1]:
            raise ValueError(f"F must be square (n x n), not {F.shape}")
        return cls(_f_linear, _h_iq, Q, R, F, [[amplitude]])
