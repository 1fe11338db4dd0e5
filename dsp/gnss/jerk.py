"""The jerk (Singer-type) line-of-sight model of the AUKF patent: its exact
transition matrix and discrete process noise. A model both sides use -- the DSP's UKF
predicts with it, the signal generator (:mod:`cosim.gnss.dynamics`) draws truth from it --
so it lives here, below both (the DSP never imports the generator).
"""
from __future__ import annotations

import numpy as np

__all__ = ["jerk_phi", "jerk_q"]


def phi_b(alpha: float, tau):
    """Column ``Phi(tau) B`` of the jerk model, ``B = [0, 0, 0, 1]``: ``(p, q1, r, s)``.

    The closed forms cancel catastrophically for small ``alpha tau``; there the exact series
    ``sum_k (-alpha)^k tau^(k+m) / (k+m)!`` (m = 3, 2, 1) is used instead.
    """
    tau = np.asarray(tau, dtype=np.float64)
    x = alpha * tau
    s = np.exp(-x)
    if np.all(x < 0.1):
        p = np.zeros_like(tau)
        q1 = np.zeros_like(tau)
        r = np.zeros_like(tau)
        term = np.ones_like(tau)     # (-x)^k / k!
        for k in range(16):
            p += term * tau ** 3 / ((k + 1) * (k + 2) * (k + 3))
            q1 += term * tau ** 2 / ((k + 1) * (k + 2))
            r += term * tau / (k + 1)
            term = term * (-x) / (k + 1)
        # The series above carries k!/(k+m)! weights: (-x)^k/k! * k!/(k+m)! = (-x)^k/(k+m)!.
        return p, q1, r, s
    a = alpha
    p = (2 - 2 * x + x * x - 2 * s) / (2 * a ** 3)
    q1 = (s - 1 + x) / a ** 2
    r = (1 - s) / a
    return p, q1, r, s


def jerk_phi(alpha_per_s: float, step_s: float) -> np.ndarray:
    """The exact 4x4 transition matrix of the jerk model over ``step_s``."""
    T = float(step_s)
    p, q1, r, s = (float(v) for v in phi_b(float(alpha_per_s), T))
    return np.array([[1.0, T, T * T / 2, p], [0.0, 1.0, T, q1], [0.0, 0.0, 1.0, r],
                     [0.0, 0.0, 0.0, s]])


def jerk_q(alpha_per_s: float, q: float, step_s: float) -> np.ndarray:
    """The exact discrete process noise ``Q = q int_0^T Phi(tau) B B^T Phi(tau)^T dtau``.

    The integrand is smooth (polynomial times exponential, degree <= 6 in ``tau`` times
    ``exp(-2 alpha tau)``); a 24-point Gauss-Legendre rule integrates it to rounding.
    """
    T = float(step_s)
    x, w = np.polynomial.legendre.leggauss(24)
    tau = T / 2 * (x + 1)
    g = np.array(phi_b(float(alpha_per_s), tau))          # (4, 24)
    return float(q) * (g * (w * T / 2)) @ g.T
