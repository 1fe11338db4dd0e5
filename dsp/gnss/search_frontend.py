"""The acquisition search's front end on a recording (:mod:`dsp.gnss.search` and
:mod:`dsp.gnss.search_sequential` run it before their dwells).

Front end
---------
1. Interference that repeats every 1 ms (front-end clock or bus activity; one of the
   PocketSDR recordings has it) is subtracted if present (:func:`remove_periodic`).
2. The samples (real at IF ``f_IF``, or complex at a complex IF) are mixed to zero IF,
   ``y[n] = x[n] exp(-j 2 pi f_IF n / fs)``, conjugated when a real recording's spectrum is
   inverted (so the Doppler sign is right).
3. Narrowband interference is excised in the frequency domain (:func:`excise`).
4. For the dwells: low-pass filtered (``firwin`` FIR, cutoff ``fs / 2D``, ``16 D + 1`` taps,
   centred: no delay) and decimated by ``D``, the largest divisor of the samples per ms with
   ``fs / D >= min_rate_hz`` (2.046 MS/s by default, the C/A main lobe; 12 MS/s -> 2.4 MS/s);
   with ``D = 1`` nothing is filtered (a real recording's image at ``-2 f_IF`` averages out).
   The search cells are ``D`` samples of the recording apart.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import signal as sps

from .ca_code import CHIP_RATE_HZ, CODE_PERIOD_S

#: The C/A main lobe, null to null (Hz): the lowest decimated complex rate by default.
MIN_RATE_HZ = 2 * CHIP_RATE_HZ
#: 1 ms periodic interference is removed above this power ratio (1: noise alone).
PERIODIC_RATIO = 2.0
#: Narrowband interference excision: spectrum bins this far (dB) above the median.
EXCISE_DB = 10.0


def decimation(fs_hz: float, min_rate_hz: float = MIN_RATE_HZ) -> int:
    """The largest divisor ``D`` of the samples per ms with ``fs / D >= min_rate_hz``."""
    n = int(round(fs_hz * CODE_PERIOD_S))
    return max(d for d in range(1, n + 1) if n % d == 0 and fs_hz / d >= min_rate_hz) \
        if fs_hz >= min_rate_hz else 1


def to_baseband(x, fs_hz: float, if_hz: float, inverted: bool = False, decim: int = 1,
                n0: int = 0) -> np.ndarray:
    """Zero-IF complex samples, low-pass filtered and decimated by ``decim`` (module
    docstring). ``n0`` is the first sample's index (the mixer's phase reference)."""
    x = np.asarray(x)
    if if_hz == 0 and np.iscomplexobj(x):
        y = x.astype(np.complex128)
    else:
        n = np.arange(n0, n0 + x.size, dtype=np.float64)
        y = x * np.exp(-2j * np.pi * math.fmod(if_hz / fs_hz, 1.0) * n)
    if inverted:
        y = np.conj(y)
    if decim == 1:
        return y
    h = sps.firwin(16 * decim + 1, 1.0 / decim)
    y = sps.oaconvolve(y, h, mode="same")
    return y[::decim]


def excise(x, fs_hz: float, threshold_db: float = EXCISE_DB):
    """Narrowband interference excision on zero-IF samples: the power spectrum averaged over
    segments of ``L = 2^ceil(log2(fs / 1 kHz))`` samples (about 1 kHz resolution); the
    segment bins more than ``threshold_db`` above the median bin, and their neighbours, are
    zeroed in the FFT of the whole of ``x``. The C/A signal itself lies far below that
    (a 50 dB-Hz satellite puts about -10 dB of the noise into one 1 kHz spectral line).
    Returns ``(x excised, list of the excised frequencies in Hz)``."""
    x = np.asarray(x, dtype=np.complex128)
    L = 1 << int(math.ceil(math.log2(fs_hz / 1000.0)))
    k = x.size // L
    if k < 4:
        return x, []
    P = np.mean(np.abs(np.fft.fft(x[:k * L].reshape(k, L), axis=1)) ** 2, axis=0)
    bad = P > np.median(P) * 10.0 ** (threshold_db / 10.0)
    if not bad.any():
        return x, []
    freqs = np.fft.fftfreq(L, 1.0 / fs_hz)[bad]
    bad = bad | np.roll(bad, 1) | np.roll(bad, -1)
    X = np.fft.fft(x)
    j = np.floor(np.fft.fftfreq(x.size, 1.0 / fs_hz) * L / fs_hz + 0.5).astype(np.int64) % L
    X[bad[j]] = 0.0
    return np.fft.ifft(X), [float(f) for f in np.sort(freqs)]


def remove_periodic(x, fs_hz: float, min_ratio: float = PERIODIC_RATIO):
    """Subtract interference that repeats every 1 ms (and so every 0.5, 0.25 ms ...: a
    front end's clock or bus activity): the mean of the ``k`` whole 1 ms periods of ``x``,
    subtracted from each, if its power exceeds ``min_ratio`` times what noise alone leaves
    in a mean of ``k`` periods (``var / k``). A satellite is 1 ms periodic only with a
    Doppler within about ``1 / (k ms)`` of a multiple of 1 kHz (and its data bits average
    out), so it is mostly kept. Returns ``(x, ratio)`` (``x`` unchanged below the ratio)."""
    x = np.asarray(x)
    N = int(round(fs_hz * CODE_PERIOD_S))
    k = x.size // N
    if k < 4:
        return x, 0.0
    v = x[:k * N].reshape(k, N)
    m = v.mean(axis=0)
    var = float(np.mean(np.abs(v - m) ** 2))
    ratio = float(np.mean(np.abs(m) ** 2) * k / var) if var > 0 else 0.0
    if ratio <= min_ratio:
        return x, ratio
    y = x.astype(np.complex128 if np.iscomplexobj(x) else np.float64)
    y[:k * N] -= np.tile(m, k)
    y[k * N:] -= m[:x.size - k * N]
    return y, ratio


def front_end(read, n: int, fs_hz: float, if_hz: float, inverted: bool, excise_db):
    """Front-end steps 1-3 (module docstring) on the recording's first ``n`` samples:
    ``(zero-IF samples at the full rate, periodic interference ratio, excised Hz)``."""
    raw, periodic = remove_periodic(read(0, n), fs_hz)
    xf = to_baseband(raw, fs_hz, if_hz, inverted, 1)
    xf, excised = excise(xf, fs_hz) if excise_db is not None else (xf, [])
    return xf, periodic, excised
