"""Tracking discriminators on one epoch's (or two epochs') correlator outputs.

Conventions (``dsp.gnss.correlator``): the prompt is ``P = I_P + j Q_P ~ a exp(j 2 pi e)`` with
``e`` the carrier phase error, *signal minus replica* (cycles); the early replica is ``d/2``
chip ahead, so for a code error ``tau`` (signal minus prompt, chips) ``|E| = R(tau - d/2)``,
``|L| = R(tau + d/2)``. Every discriminator returns the error in those units with that sign
(a positive output asks the NCO to speed up). All functions are numpy-vectorised; on scalar
inputs (one channel's epoch) :func:`costas_atan`, :func:`pll_atan2` and :func:`dll_nelp` call
the same numpy ufuncs on the scalars, without building arrays (same bits, a fraction of the
cost).
"""
from __future__ import annotations

import numpy as np

TWO_PI = 2.0 * np.pi
_SCALAR = (int, float, np.integer, np.floating)


def _scalar(x) -> bool:
    return isinstance(x, _SCALAR) or (isinstance(x, np.ndarray) and x.ndim == 0)


def costas_atan(ip, qp):
    """Costas, two-quadrant ``atan(Q/I) / 2 pi`` (cycles, in [-1/4, 1/4]); data-insensitive.
    ``I = 0`` gives +-1/4 by the sign of ``Q`` (``arctan2`` on ``|I|``)."""
    if _scalar(ip) and _scalar(qp):
        i, q = float(ip), float(qp)
        return np.arctan2(-q if i < 0 else q, abs(i)) / TWO_PI
    ip, qp = np.asarray(ip, float), np.asarray(qp, float)
    return np.arctan2(qp * np.sign(np.where(ip == 0, 1.0, ip)), np.abs(ip)) / TWO_PI


def pll_atan2(ip, qp):
    """Four-quadrant PLL ``atan2(Q, I) / 2 pi`` (cycles, in (-1/2, 1/2]); needs no data
    (or data wiped)."""
    if _scalar(ip) and _scalar(qp):
        return np.arctan2(float(qp), float(ip)) / TWO_PI
    return np.arctan2(np.asarray(qp, float), np.asarray(ip, float)) / TWO_PI


def fll_cross_dot(ip1, qp1, ip2, qp2, T_s: float, four_quadrant: bool = True):
    """FLL from two successive prompts (1 then 2, ``T_s`` apart):
    ``cross = I1 Q2 - I2 Q1``, ``dot = I1 I2 + Q1 Q2``, ``atan2(cross, dot) / (2 pi T)`` Hz
    (range +-1/(2T)); ``four_quadrant=False`` is the data-insensitive ``atan(cross/dot)``
    form (range +-1/(4T))."""
    ip1, qp1, ip2, qp2 = (np.asarray(a, float) for a in (ip1, qp1, ip2, qp2))
    cross = ip1 * qp2 - ip2 * qp1
    dot = ip1 * ip2 + qp1 * qp2
    if four_quadrant:
        return np.arctan2(cross, dot) / (TWO_PI * T_s)
    return np.arctan2(cross * np.sign(np.where(dot == 0, 1.0, dot)), np.abs(dot)) / (TWO_PI * T_s)


def dll_nelp(ie, qe, il, ql, spacing_chips: float = 0.5):
    """Normalised early-minus-late envelope ``(1 - d/2) (|E| - |L|) / (|E| + |L|)`` (chips):
    equal to ``tau`` for ``|tau| <= d/2`` on the ideal triangle (``E - L = 2 tau``,
    ``E + L = 2 - d``); ``(E - L)/(E + L) / 2`` for ``d = 1`` (Kaplan & Hegarty)."""
    if _scalar(ie) and _scalar(qe) and _scalar(il) and _scalar(ql):
        e = np.hypot(float(ie), float(qe))
        l_ = np.hypot(float(il), float(ql))
        s = e + l_
        return (1.0 - spacing_chips / 2) * ((e - l_) / s if s > 0 else np.float64(0.0))
    e = np.hypot(np.asarray(ie, float), np.asarray(qe, float))
    l_ = np.hypot(np.asarray(il, float), np.asarray(ql, float))
    s = e + l_
    return (1.0 - spacing_chips / 2) * np.where(s > 0, (e - l_) / np.where(s > 0, s, 1.0), 0.0)
