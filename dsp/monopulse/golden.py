"""Float golden monopulse front end: DDC, integrate-and-dump decimation, channel
correction, matched filter, sum/difference beams.

Chain (per channel ``i``; ``x`` real IF samples, global sample index ``m``, ``t = m / fs``)::

    z_i(n) = (1/D) sum_{m in snapshot n} 2 x_i[m] exp(-j 2 pi f_IF t)   mix + low-pass/decimate
    z_i(n) <- k_i z_i(n)                                               correction: steering
                                                                       exp(j phi_i0) x calibration
    S_i = (1/N) sum_n z_i(n) c(n)                                      matched filter (real chips)

The low-pass is an integrate-and-dump over one chip (a first-order CIC of length D): the
filter matched to a rectangular chip, whose decimated noise is white, and which nulls the
``2 f_IF`` image exactly when ``2 f_IF D / fs`` is an integer (the generator's rule).

Beams, with the monopulse paper's quadrant mapping (keep it: the sign of
Delta / Sigma depends on it)::

    S_S = S_1 + S_2 + S_3 + S_4
    S_dE = (S_1 + S_3) - (S_2 + S_4)     elevation difference (the y axis: Dy, dphi_2)
    S_dA = (S_1 + S_2) - (S_3 + S_4)     azimuth difference (the x axis: Dx, dphi_3)
"""
from __future__ import annotations

import numpy as np


def ddc(x, if_hz: float, fs_hz: float, decimation: int, first_sample: int = 0):
    """Mix real IF samples ``x`` (C, M) to baseband and integrate-and-dump by ``decimation``.

    ``first_sample`` is the global index of ``x[:, 0]`` (the LO is referred to sample 0, so
    blocks processed apart give the record's values). Returns (C, M // decimation) complex.
    """
    x = np.asarray(x, float)
    c, m = x.shape
    if m % decimation:
        raise ValueError(f"sample count must be a multiple of the decimation {decimation}, "
                         f"not {m}")
    idx = first_sample + np.arange(m, dtype=np.int64)
    lo = np.exp(-2j * np.pi * np.mod(idx * (if_hz / fs_hz), 1.0))
    return (2.0 * x * lo).reshape(c, m // decimation, decimation).mean(axis=2)


def matched_filter(z, replica):
    """``S_i = (1/N) sum_n z_i(n) conj(c(n))`` per block: ``z`` (C, K N), ``replica`` (K, N).
    Returns (K, C)."""
    replica = np.asarray(replica)
    k, n = replica.shape
    c = z.shape[0]
    zz = z.reshape(c, k, n)
    return np.einsum("ckn,kn->kc", zz, np.conj(replica.astype(float))) / n


def beams(s):
    """Sum, azimuth-difference and elevation-difference beams from S (..., 4)."""
    s = np.asarray(s)
    s1, s2, s3, s4 = s[..., 0], s[..., 1], s[..., 2], s[..., 3]
    return s1 + s2 + s3 + s4, (s1 + s2) - (s3 + s4), (s1 + s3) - (s2 + s4)


def golden_chain(samples, scale, replica, correction, if_hz, fs_hz, decimation,
                 first_sample=0):
    """IF samples (4, K N D) -> corrected matched-filter outputs S (K, 4).

    ``correction`` (4,) or (K, 4): per-channel complex factor ``k_i`` (steering
    ``exp(j phi_i0)`` times calibration) of each block.
    """
    z = ddc(np.asarray(samples, float) * scale, if_hz, fs_hz, decimation, first_sample)
    s = matched_filter(z, replica)
    return s * np.broadcast_to(np.asarray(correction), s.shape)
