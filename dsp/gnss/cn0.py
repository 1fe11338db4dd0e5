"""C/N0 estimators from prompt correlator outputs.

Both take the complex prompt ``P = I_P + j Q_P`` of consecutive coherent intervals of
``T_s`` seconds (last axis = time) and return C/N0 in dB-Hz, with the post-correlation SNR
``|s|^2 / E|n|^2 = (C/N0) T`` (complex noise, ``E|n|^2 = 2 sigma^2``).

* :func:`cn0_m2m4`: the second- and fourth-moment (M2M4) estimator, Pauluzzi & Beaulieu,
  "A comparison of SNR estimation techniques for the AWGN channel", IEEE Trans. Commun. 48
  (10), 2000 (after Matzner 1993); for complex samples ``M2 = E|P|^2``, ``M4 = E|P|^4``,
  ``Ps = sqrt(2 M2^2 - M4)``, ``Pn = M2 - Ps``. Insensitive to the carrier phase and to data
  bits; no alignment needed.
* :func:`cn0_nwpr`: the narrowband-wideband power ratio (A. J. Van Dierendonck, "GPS
  receivers", in Parkinson & Spilker, *GPS: Theory and Applications* vol. I, ch. 8, AIAA
  1996; also in Kaplan & Hegarty, *Understanding GPS/GNSS*): over blocks of ``M``
  intervals, ``NP = |sum P|^2 / sum |P|^2``, ``mu = mean NP``,
  ``C/N0 = (mu - 1) / ((M - mu) T)``. The blocks must not straddle a data-bit edge and the
  residual frequency must be small against ``1 / (M T)``.

Estimates that come out non-positive (noise only, or too few samples) are returned as
``-inf`` dB-Hz, not NaN, so a lock detector's comparison still works.
"""
from __future__ import annotations

import numpy as np


def _db(snr, T_s):
    with np.errstate(divide="ignore", invalid="ignore"):
        v = snr / T_s
        return np.where(v > 0, 10 * np.log10(np.where(v > 0, v, 1.0)), -np.inf)


def _check_T(T_s):
    T = float(T_s)
    if not np.isfinite(T) or T <= 0:
        raise ValueError(f"T_s (coherent interval) must be > 0 s, not {T_s!r}")
    return T


def cn0_m2m4(prompt, T_s: float, axis: int = -1):
    """M2M4 C/N0 (dB-Hz) of the complex prompt along ``axis``."""
    T = _check_T(T_s)
    p = np.asarray(prompt)
    a2 = (p.real ** 2 + p.imag ** 2) if np.iscomplexobj(p) else p * p
    m2 = a2.mean(axis=axis)
    m4 = (a2 * a2).mean(axis=axis)
    ps = np.sqrt(np.clip(2 * m2 * m2 - m4, 0.0, None))
    pn = m2 - ps
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = np.where(pn > 0, ps / np.where(pn > 0, pn, 1.0), np.inf)
    return _db(snr, T)


def cn0_nwpr(prompt, T_s: float, m: int = 20, axis: int = -1):
    """Narrowband-wideband power ratio C/N0 (dB-Hz), blocks of ``m`` intervals along
    ``axis`` (a trailing partial block is dropped)."""
    T = _check_T(T_s)
    if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 2:
        raise ValueError(f"m (intervals per NWPR block) must be an integer >= 2, not {m!r}")
    p = np.moveaxis(np.asarray(prompt, dtype=np.complex128), axis, -1)
    k = p.shape[-1] // m
    if k < 1:
        raise ValueError(f"NWPR needs at least one block of m = {m} intervals, not {p.shape[-1]}")
    b = p[..., :k * m].reshape(p.shape[:-1] + (k, m))
    nbp = np.abs(b.sum(axis=-1)) ** 2
    wbp = (np.abs(b) ** 2).sum(axis=-1)
    mu = (nbp / wbp).mean(axis=-1)
    return _db((mu - 1) / (m - mu), T)
