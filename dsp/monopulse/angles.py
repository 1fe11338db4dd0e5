"""Monopulse angle equations (the monopulse paper's) and the angle Cramer-Rao bound.

Model: after the digital steering correction, channel ``i`` carries ``s exp(j dphi_i)``,
``dphi_i = phi_i0 - phi_i``, ``phi_2 = 2 pi Dy v``, ``phi_3 = 2 pi Dx u``,
``phi_4 = phi_2 + phi_3`` (lengths in wavelengths). Then
``S_dE / S_S = -j tan(dphi_2 / 2)`` and ``S_dA / S_S = -j tan(dphi_3 / 2)``.

Phase from a ratio (decision): ``dphi = -2 atan(Im(S_d / S_S))`` (``phase_im``), not the
arg form ``arg((S_S - S_d) / (S_S + S_d))`` (``phase_arg``, kept as the independent
formulation the tests compare against). Noise-free they are equal; to first order in the
noise they are equal too (both have derivative ``-2 Im(d r) / (1 + tan^2(dphi/2))`` in the
ratio ``r = S_d / S_S``). The Im form is kept because in the model the in-phase part of
``S_d / S_S`` is zero: any real part is noise or channel mismatch, and the Im form discards it
(a projection) where the arg form lets it in at second order; it is the ratio the paper's
board forms and its output is bounded (|dphi| < pi) for any input.

Direction cosines: ``v = v0 - dphi_2 / (2 pi Dy)``, ``u = u0 - dphi_3 / (2 pi Dx)``; azimuth
``phi = atan2(v, u)`` (no arctan +-pi ambiguity), ``theta = arcsin(sqrt(u^2 + v^2))``.
Unambiguous while ``|u - u0| < 1 / (2 Dx)`` and ``|v - v0| < 1 / (2 Dy)``.
"""
from __future__ import annotations

import numpy as np

from .golden import beams


def phase_im(s_sum, s_diff):
    """``dphi = -2 atan(Im(S_d / S_S))``."""
    return -2.0 * np.arctan(np.imag(np.asarray(s_diff) / np.asarray(s_sum)))


def phase_arg(s_sum, s_diff):
    """``dphi = arg((S_S - S_d) / (S_S + S_d))``, computed without a division."""
    s_sum = np.asarray(s_sum)
    s_diff = np.asarray(s_diff)
    return np.angle((s_sum - s_diff) * np.conj(s_sum + s_diff))


def direction_cosines(s, u0, v0, dx_wl, dy_wl, method="im"):
    """Measured ``(u, v)`` from matched-filter outputs S (..., 4) steered at ``(u0, v0)``."""
    s_sum, s_da, s_de = beams(s)
    ph = phase_im if method == "im" else phase_arg
    if method not in ("im", "arg"):
        raise ValueError(f"method must be 'im' or 'arg', not {method!r}")
    dphi2 = ph(s_sum, s_de)
    dphi3 = ph(s_sum, s_da)
    return u0 - dphi3 / (2 * np.pi * dx_wl), v0 - dphi2 / (2 * np.pi * dy_wl)


def angles(u, v):
    """``(az, el) = (atan2(v, u), arcsin(rho))``; ``el`` is NaN where ``rho >= 1`` (a noisy
    measurement outside the visible region)."""
    u = np.asarray(u, float)
    v = np.asarray(v, float)
    rho = np.hypot(u, v)
    with np.errstate(invalid="ignore"):
        el = np.where(rho < 1.0, np.arcsin(np.minimum(rho, 1.0)), np.nan)
    return np.arctan2(v, u), el


def measure(s, u0, v0, dx_wl, dy_wl, method="im"):
    """``(u, v, az, el)`` from S (..., 4)."""
    u, v = direction_cosines(s, u0, v0, dx_wl, dy_wl, method)
    az, el = angles(u, v)
    return u, v, az, el


def crb_uv(snr, n_snapshots, dx_wl, dy_wl):
    """Cramer-Rao bound on ``(u, v)`` variance for the 4-channel phase-difference model.

    Model: ``y_i(n) = alpha exp(-j 2 pi P_i.(u, v)) c(n) + w_i(n)``, ``i = 1..4`` at the
    subarray phase centres ``P_i``, ``|c| = 1`` known, ``alpha`` an unknown complex amplitude
    (nuisance), ``w_i`` independent circular white noise, ``snr = |alpha|^2 / E|w|^2`` per
    channel and snapshot (the per-subarray SNR of the target actually seen: the nominal SNR
    times ``|AF|^2``). The subarray pattern's own slope in (u, v) is neglected (it is common
    to the channels and cancels in Delta/Sigma). With the amplitude eliminated
    (``J = 2 N snr Re(d^H P_perp d)``), ``d_i = -j 2 pi P_i a_i``, ``P_perp`` removing ``a``:
    ``J_uu = 2 N snr (2 pi)^2 sum (x_i - xbar)^2 = 8 pi^2 N snr Dx^2``, ``J_uv = 0``::

        var u >= 1 / (8 pi^2 N snr Dx^2),   var v >= 1 / (8 pi^2 N snr Dy^2)

    (``Dx`` in wavelengths). The monopulse estimator attains it at high SNR:
    ``var(dphi) = 1 / (2 N snr)``.
    """
    snr = np.asarray(snr, float)
    base = 8 * np.pi ** 2 * n_snapshots * snr
    return 1.0 / (base * dx_wl ** 2), 1.0 / (base * dy_wl ** 2)


def monopulse_covariance_uv(snr, n_snapshots, dx_wl, dy_wl, du, dv):
    """First-order covariance ``(var u, var v, cov uv)`` of *this* estimator (Im form) at the
    offset ``(du, dv) = (u - u0, v - v0)``::

        var u  = crb_u / cos^2(pi Dy dv),   var v = crb_v / cos^2(pi Dx du),
        cov uv = tan(pi Dx du) tan(pi Dy dv) / (8 pi^2 N snr Dx Dy)

    Derivation: ``S_dA``, ``S_dE`` and ``S_S`` have uncorrelated noises of variance
    ``4 sigma^2 / N``; the error of ``r = S_d / S_S`` is ``(n_d - r n_S) / S_S`` with
    ``|S_S| = 4 |alpha| cos(dphi_2/2) cos(dphi_3/2)``, and ``d dphi = -2 cos^2(dphi/2) Im(d r)``.
    A difference beam sums the channel pairs of the other axis with equal weights, coherent
    only on that axis' boresight (the ``cos^2`` loss); the shared ``n_S`` correlates the two
    axes off boresight (correlation ``sin(dphi_2/2) sin(dphi_3/2)``). On boresight the
    estimator attains the CRB.
    """
    vu, vv = crb_uv(snr, n_snapshots, dx_wl, dy_wl)
    tx = np.tan(np.pi * dx_wl * np.asarray(du, float))
    ty = np.tan(np.pi * dy_wl * np.asarray(dv, float))
    base = 8 * np.pi ** 2 * n_snapshots * np.asarray(snr, float)
    return vu * (1 + ty * ty), vv * (1 + tx * tx), tx * ty / (base * dx_wl * dy_wl)


def angle_variances(u, v, var_u, var_v, cov_uv=0.0):
    """``(var az, var el)`` (rad^2) from the ``(u, v)`` error covariance by the Jacobian of
    ``(atan2, arcsin)`` at ``(u, v)``:
    ``var az = (v^2 var_u + u^2 var_v - 2 u v cov) / rho^4``,
    ``var el = (u^2 var_u + v^2 var_v + 2 u v cov) / (rho^2 cos^2 el)``; inf for az at the
    zenith."""
    u = np.asarray(u, float)
    v = np.asarray(v, float)
    r2 = u * u + v * v
    with np.errstate(divide="ignore", invalid="ignore"):
        return (v * v * var_u + u * u * var_v - 2 * u * v * cov_uv) / (r2 * r2), \
            (u * u * var_u + v * v * var_v + 2 * u * v * cov_uv) / (r2 * (1.0 - r2))


def crb_angles(u, v, snr, n_snapshots, dx_wl, dy_wl):
    """CRB on ``(az, el)`` variance (rad^2): ``crb_uv`` through ``angle_variances`` (the
    az/el covariance, ``u v (var_v - var_u) / (rho^3 cos el)``, is zero when Dx = Dy)."""
    vu, vv = crb_uv(snr, n_snapshots, dx_wl, dy_wl)
    return angle_variances(u, v, vu, vv)
