"""Bearing from the envelope phases at the references, and the coarse/fine combination.

With the convention of :mod:`cosim.tacan_signal` (the 15 Hz component is
``A sin(2 pi 15 (t - t_M) - theta)``), the Kalman state at a pulse at ``t_k`` has 15 Hz
phase ``alpha_k = 2 pi 15 (t_k - t_M) - theta``, hence the seed's eq. 15
``theta = theta_a - theta_b`` with ``theta_a = 2 pi 15 (t_k - t_M)`` (phase of the pulse
after the reference) and ``theta_b = alpha_k = atan2(x1, x2)`` (eq. 16). The 135 Hz
component gives ``9 theta mod 2 pi`` the same way from the latest auxiliary (or main)
reference.

Coarse/fine combination: the seed's eq. 17, ``40 floor(theta_15 / 40) + theta_135 / 9``,
takes the 40-degree sector from the coarse bearing alone, so it slips a whole sector
whenever the true bearing is near a sector edge and the coarse error crosses it. Here the
fine bearing's nine candidates ``(phi + 360 i) / 9`` are compared with the coarse bearing and
the nearest (circular distance) is taken: correct whenever the coarse error is below 20
degrees, at every bearing. The resolved fine bearing and the coarse bearing are then
combined with weights ``m1^2 : 81 m2^2`` (their Fisher information).
"""
from __future__ import annotations

import numpy as np

TWO_PI = 2 * np.pi


def wrap_pi(a):
    """Wrap angles (rad) to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % TWO_PI - np.pi


def wrap_deg(a):
    """Wrap angles (deg) to [-180, 180)."""
    return (np.asarray(a, dtype=np.float64) + 180.0) % 360.0 - 180.0


def combine_coarse_fine(coarse_rad, fine9_rad, w_coarse=None, w_fine=None):
    """Bearing (rad, [0, 2 pi)) from the coarse bearing and the fine phase ``9 theta``.

    Parameters
    ----------
    coarse_rad : array
        Coarse bearing from the 15 Hz component.
    fine9_rad : array
        ``9 * theta mod 2 pi`` from the 135 Hz component.
    w_coarse, w_fine : array, optional
        Information weights (``m1**2`` and ``81 m2**2``); default: fine only.
    """
    coarse = np.asarray(coarse_rad, dtype=np.float64) % TWO_PI
    base = (np.asarray(fine9_rad, dtype=np.float64) % TWO_PI) / 9.0
    # Candidate i = base + i * 40 deg; nearest to coarse, circularly.
    i = np.rint(wrap_pi(coarse - base) / (TWO_PI / 9.0))
    fine = base + i * (TWO_PI / 9.0)
    if w_coarse is None or w_fine is None:
        return fine % TWO_PI
    wc = np.asarray(w_coarse, dtype=np.float64)
    wf = np.asarray(w_fine, dtype=np.float64)
    tot = wc + wf
    frac = np.divide(wc, tot, out=np.zeros_like(tot), where=tot > 0)
    return (fine + frac * wrap_pi(coarse - fine)) % TWO_PI


def seed_eq17(coarse_deg, fine135_deg):
    """The seed's eq. 17 as printed (kept to show the sector slip it suffers)."""
    return 40.0 * np.floor(np.asarray(coarse_deg) / 40.0) + np.asarray(fine135_deg) / 9.0
