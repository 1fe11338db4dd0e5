"""Filter design from the rates: CIC responses and the CIC-compensating pulse-matched FIR.

Pure numpy/scipy; the golden front end uses the float taps, the HDL FIR quantises them.
"""
from __future__ import annotations

import functools

import numpy as np


def cic_response(f_hz, fs_in_hz: float, stages: int, rate: int, diff_delay: int = 1) -> np.ndarray:
    """Magnitude response of an N-stage CIC decimator, normalised to 1 at DC.

    ``|sin(pi f R M / fs) / (R M sin(pi f / fs))|**N`` with ``f`` at the input rate ``fs``.
    """
    f = np.asarray(f_hz, dtype=np.float64) / fs_in_hz
    rm = rate * diff_delay
    num = np.sin(np.pi * f * rm)
    den = rm * np.sin(np.pi * f)
    with np.errstate(invalid="ignore", divide="ignore"):
        h = np.where(np.abs(den) < 1e-15, 1.0, num / np.where(den == 0, 1, den))
    return np.abs(h) ** stages


def cic_taps(stages: int, rate: int, diff_delay: int = 1) -> np.ndarray:
    """The CIC's impulse response as an FIR (boxcar of R*M convolved N times), DC gain 1."""
    box = np.ones(rate * diff_delay)
    h = np.array([1.0])
    for _ in range(stages):
        h = np.convolve(h, box)
    return h / h.sum()


def gaussian_pulse_spectrum(f_hz, sigma_s: float) -> np.ndarray:
    """Fourier magnitude of ``exp(-t^2 / (2 sigma^2))`` normalised to 1 at DC."""
    f = np.asarray(f_hz, dtype=np.float64)
    return np.exp(-2.0 * (np.pi * sigma_s * f) ** 2)


def design_pulse_fir(*, fs_in_hz: float, cic_stages: int, cic_rate: int, cic_delay: int = 1,
                     numtaps: int = 33, pulse_sigma_s: float = 3.5e-6 / (2 * np.sqrt(2 * np.log(2))),
                     window: str = "hamming") -> np.ndarray:
    """Symmetric FIR after the CIC so that CIC * FIR is the Gaussian pulse's matched filter.

    The desired response at the FIR's input rate ``fs_in/R`` is ``G(f) / H_cic(f)``: the
    pulse spectrum with the CIC droop divided out. Designed by frequency sampling
    (``scipy.signal.firwin2``) and scaled so that an ideal pulse of peak amplitude 1 comes
    out of CIC + FIR with peak 1 (the envelope then reads pulse amplitudes directly).

    Parameters
    ----------
    fs_in_hz : float
        Sample rate at the CIC input (Hz).
    cic_stages, cic_rate, cic_delay : int
        The CIC in front (N, R, M).
    numtaps : int
        Odd number of taps (type-I linear phase, symmetric).
    pulse_sigma_s : float
        Standard deviation of the Gaussian pulse (s); TACAN 3.5 us half-amplitude width.
    """
    if numtaps < 3 or numtaps % 2 == 0:
        raise ValueError(f"FIR numtaps must be an odd integer >= 3, not {numtaps}")
    if pulse_sigma_s <= 0:
        raise ValueError(f"pulse_sigma_s must be > 0, not {pulse_sigma_s}")
    return _design_pulse_fir(float(fs_in_hz), int(cic_stages), int(cic_rate), int(cic_delay),
                             int(numtaps), float(pulse_sigma_s), str(window)).copy()


@functools.lru_cache(maxsize=64)
def _design_pulse_fir(fs_in_hz, cic_stages, cic_rate, cic_delay, numtaps, pulse_sigma_s, window):
    fs = fs_in_hz / cic_rate
    freq = np.linspace(0.0, fs / 2, 513)
    hcic = cic_response(freq, fs_in_hz, cic_stages, cic_rate, cic_delay)
    gain = gaussian_pulse_spectrum(freq, pulse_sigma_s) / np.maximum(hcic, 1e-3)
    from scipy.signal import firwin2
    taps = firwin2(numtaps, freq, gain, fs=fs, window=window)
    return taps / pulse_peak_gain(taps, fs_in_hz=fs_in_hz, cic_stages=cic_stages,
                                  cic_rate=cic_rate, cic_delay=cic_delay,
                                  pulse_sigma_s=pulse_sigma_s)


def pulse_peak_gain(taps, *, fs_in_hz: float, cic_stages: int, cic_rate: int, cic_delay: int,
                    pulse_sigma_s: float) -> float:
    """Peak of (Gaussian pulse of amplitude 1) through CIC and FIR, at the best sampling phase.

    Computed on the continuous-time output (dense frequency integral of the zero-phase
    response), so it does not depend on where samples fall.
    """
    fs = fs_in_hz / cic_rate
    f = np.linspace(-fs_in_hz / 2, fs_in_hz / 2, 1 << 16, endpoint=False)
    df = f[1] - f[0]
    # Pulse spectrum (continuous FT of exp(-t^2/2s^2)) = s*sqrt(2 pi) * G(f).
    p = pulse_sigma_s * np.sqrt(2 * np.pi) * gaussian_pulse_spectrum(f, pulse_sigma_s)
    hc = cic_response(f, fs_in_hz, cic_stages, cic_rate, cic_delay)
    taps = np.asarray(taps, dtype=np.float64)
    k = np.arange(len(taps)) - (len(taps) - 1) / 2
    hf = np.real(np.exp(-2j * np.pi * np.outer(f, k) / fs) @ taps)  # zero-phase FIR
    # Output at the pulse centre: integral of P(f) H(f) df; the CIC and FIR at their rates
    # have gains 1 and sum(taps) at DC; the 1/T of sampling cancels as both are DC-normalised.
    return float(np.sum(p * hc * hf) * df)
