"""The block slave's measurement model of the adaptive UKF carrier tracker
(:mod:`dsp.gnss.aukf`): the moments of the block measurement ``z`` against the true process
noise scale ``q`` for a master running with ``q_hat`` (:func:`block_moments`, tabulated by
:func:`block_table`), from the mismatched-filter Lyapunov equation of the linearised loop."""
from __future__ import annotations

import math

import numpy as np



def _linear_gain(Phi, Q, Rph):
    import scipy.linalg as sl
    H = np.array([[1.0, 0, 0, 0]])
    Pm = sl.solve_discrete_are(Phi.T, H.T, Q, np.array([[Rph]]))
    return (Pm @ H.T / (Pm[0, 0] + Rph))[:, 0]


def wipe_gain(r_true: float) -> float:
    """Mean discriminator gain ``k_d = 1 - 2 p`` of the data-wiped prompt: the bit is removed
    by the sign of the in-phase component (unit amplitude, noise variance ``r_true`` per
    component), wrong with probability ``p = Phi(-1 / sqrt(r_true))``; a wrong sign flips the
    quadrature signal (the phase information) but not the statistics of its noise, which is
    independent of the in-phase noise: ``E[v^T y] = k_d sin(theta_err)``, variance still
    ``r_true`` (0.925 at 32 dB-Hz, 0.985 at 36, 0.77 at 28)."""
    if not r_true > 0:
        return 1.0
    return 1.0 - 2.0 * 0.5 * math.erfc(1.0 / math.sqrt(2.0 * r_true))


def block_moments(q_hat, Phi, Qbar, r_phase: float, M: int, kd: float = 1.0):
    """``(a, b)`` with ``E[z] = a q + b`` for ``z = (w2_hat_end - s^M w2_hat_start)^2`` over
    ``M`` epochs, the linearised master in steady state with the gain of ``q_hat`` and the
    truth's intensity ``q`` (phase-measurement variance ``r_phase`` rad^2). ``kd``: the
    discriminator's mean gain (:func:`wipe_gain`), which the master's gain does not know:
    the loop sees ``kd theta_err`` plus the full noise (without it the noise floor ``b`` was
    20-40 % low at 32 dB-Hz and biased ``q_hat`` up at low ``q``, A4)."""
    import scipy.linalg as sl
    K = _linear_gain(Phi, q_hat * Qbar, r_phase)
    H = np.array([1.0, 0, 0, 0])
    IKH = np.eye(4) - kd * np.outer(K, H)
    Ae = IKH @ Phi
    s = Phi[3, 3]
    A = np.zeros((5, 5))
    A[:4, :4] = Ae
    A[4, :4] = kd * K[3] * (H @ Phi)
    A[4, 4] = s
    Bw = np.vstack([IKH, kd * K[3] * H[None, :]])
    Bv = np.concatenate([-K, [K[3]]])
    out = []
    for Qn, Rn in ((Qbar, 0.0), (np.zeros((4, 4)), r_phase)):
        Se = sl.solve_discrete_lyapunov(Ae, IKH @ Qn @ IKH.T + Rn * np.outer(K, K))
        C = np.zeros((5, 5))
        C[:4, :4] = Se
        N = Bw @ Qn @ Bw.T + Rn * np.outer(Bv, Bv)
        for _ in range(M):
            C = A @ C @ A.T + N
        out.append(C[4, 4])
    return out[0], out[1]


_MOMENTS: dict = {}
#: Range of q (rad^2/s^7) the block slave's table covers; q_hat is kept inside it.
Q_TABLE = (1e-3, 1e4)


def block_table(Phi, Qbar, r_phase, M, q_lo=None, q_hi=None, n=57, kd=1.0):
    q_lo = Q_TABLE[0] if q_lo is None else q_lo
    q_hi = Q_TABLE[1] if q_hi is None else q_hi
    key = (Phi.tobytes(), Qbar.tobytes(), float(r_phase), int(M), q_lo, q_hi, n, float(kd))
    t = _MOMENTS.get(key)
    if t is None:
        g = np.geomspace(q_lo, q_hi, n)
        ab = np.array([block_moments(v, Phi, Qbar, r_phase, M, kd) for v in g])
        t = _MOMENTS[key] = (np.log(g), ab[:, 0], ab[:, 1])
    return t
