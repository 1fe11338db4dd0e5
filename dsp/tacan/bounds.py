"""Bounds on the TACAN bearing: what the signal allows, and what a pulse detector's output allows.

Two bounds, both for the joint coarse + fine bearing from ``n_pulses`` pulses of amplitude
``a = a0 (1 + A sin(u) + B sin(9 u))`` (``u`` the 15 Hz rotation phase less the bearing):

* :func:`crb_deg`, the Cramer-Rao bound with every pulse's position known and its amplitude
  measured by a matched filter (noise ``sigma``, relative to ``a0``): docs/explanation/bounds.md. It is
  the bound the benchmarks divide by.
* :func:`detection_bound_deg`, the Fisher-information bound of the **output of a threshold
  detector**: the times and peak amplitudes of the envelope maxima over a threshold, with the
  pulse positions unknown (the random pulse pairs fill the free time at random). The
  detections form a marked point process: real pulses at the pulse rate thinned by the
  detection probability ``Pd(a)``, each with a Rician peak amplitude over the threshold, plus
  noise peaks at a constant rate with Rayleigh amplitudes over the threshold. Its Fisher
  information per pulse about ``a`` is ``integral over y > th of (d/da f(y|a))**2 / (f(y|a) +
  r g(y)) dy`` (``f`` the Rician density, ``g`` the noise peaks' amplitude density, ``r``
  noise peaks per pulse), and it splits exactly into

  - the *rate* part ``Pd'(a)**2 / (Pd(a) + r)``: how many detections there are, which the
    modulation changes through ``Pd``;
  - the *marks* part: the amplitudes given that a detection happened -- all that a DSP
    fitting the detected amplitudes (as every TACAN receiver, ours included) can use.

  Near the noise floor more of the information is in the rate than in the marks (0 dB, the
  default detector: threshold 3.93 sigma, 0.10 noise peaks per pulse: rate alone 2.10x the
  CRB, marks alone 2.61x, both 1.64x): a DSP that fits amplitudes only cannot get within
  2.6x of the Cramer-Rao bound there, whatever its filter; at 3 dB, 1.53x.

  The model is the ideal matched-filter pulse (the CRB's ``sigma``) with Rician peak
  amplitudes; the FPGA's peak picking (the largest of a few envelope samples) and its
  non-ideal filter make real peaks a little larger and noisier, so measured RMSE can sit
  above this bound by more than an efficient estimator's margin. The benchmark
  ``python -m cosim bench tacan-detector`` measures the operating point (threshold over
  ``sigma``, noise peaks per pulse, fraction of pulses detected against the model's) and
  prints the bounds beside the RMSE.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import special

#: Points of the rotation phase ``u`` (the 135 Hz term turns 9 times over it) and of the
#: peak amplitude in the information integrals.
_N_PHASE = 1440
_N_AMPL = 1200

USES = ("both", "rate", "marks")


def crb_deg(rel_sigma: float, mod_15: float, mod_135: float, n_pulses: float) -> float:
    """Cramer-Rao bound (deg) of the joint coarse+fine bearing from ``n_pulses`` amplitudes.

    ``var >= 2 sigma^2 / (N (A^2 + 81 B^2))`` rad^2 (docs/explanation/bounds.md), sigma relative to the
    unmodulated amplitude.
    """
    den = n_pulses * (mod_15 ** 2 + 81.0 * mod_135 ** 2)
    if den <= 0:
        return math.inf
    return math.degrees(math.sqrt(2.0 * rel_sigma ** 2 / den))


def _check(rel_sigma, mod_15, mod_135, threshold_sigma, false_peaks_per_pulse=0.0):
    for name, v, lo in (("rel_sigma", rel_sigma, 0.0), ("mod_15", mod_15, 0.0),
                        ("mod_135", mod_135, 0.0), ("threshold_sigma", threshold_sigma, 0.0),
                        ("false_peaks_per_pulse", false_peaks_per_pulse, 0.0)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < lo:
            raise ValueError(f"{name} must be a finite number >= {lo:g}, not {v!r}")
    if rel_sigma == 0:
        raise ValueError("rel_sigma must be > 0 (a noiseless record has no detection bound)")
    if mod_15 + mod_135 >= 1:
        raise ValueError(f"mod_15 + mod_135 = {mod_15 + mod_135:g} must be < 1 (the pulse "
                         f"amplitude would reach zero)")


def _amplitudes(mod_15: float, mod_135: float):
    """Pulse amplitudes over one rotation (units of a0) and d a / d bearing there."""
    u = np.arange(_N_PHASE) * (2.0 * np.pi / _N_PHASE)
    a = 1.0 + mod_15 * np.sin(u) + mod_135 * np.sin(9.0 * u)
    da = -(mod_15 * np.cos(u) + 9.0 * mod_135 * np.cos(9.0 * u))
    return a, da


def _rice_terms(a: np.ndarray, s: float, th: float):
    """Rician density ``f(y|a)`` of the peak amplitude and ``d f / d a`` on a grid of ``y`` over
    the threshold (rows: amplitudes ``a``), with the grid weights (trapezoid)."""
    top = float(np.max(a)) + 12.0 * s
    lo = max(th, 1e-9 * s)
    y = np.linspace(lo, max(top, lo + 12.0 * s), _N_AMPL)
    w = np.full(y.size, y[1] - y[0])
    w[0] = w[-1] = 0.5 * (y[1] - y[0])
    yy, aa = y[None, :], a[:, None]
    z = yy * aa / (s * s)
    # f = y/s^2 exp(-(y^2 + a^2)/2s^2) I0(y a/s^2) = y/s^2 exp(-(y - a)^2/2s^2) I0e(z)
    f = yy / (s * s) * np.exp(-(yy - aa) ** 2 / (2 * s * s)) * special.i0e(z)
    ratio = special.i1e(z) / special.i0e(z)
    df = f * (-aa + yy * ratio) / (s * s)
    return y, w, f, df


def _noise_peak_density(y: np.ndarray, s: float, th: float) -> np.ndarray:
    """Amplitude density of noise peaks over the threshold: Rayleigh, normalised over y > th."""
    return y / (s * s) * np.exp(-(y * y - th * th) / (2 * s * s))


def information_per_pulse(a, rel_sigma: float, threshold_sigma: float,
                          false_peaks_per_pulse: float = 0.0) -> dict:
    """Fisher information about a pulse's amplitude ``a`` (units of a0) in a threshold
    detector's output, per transmitted pulse: ``{"both", "rate", "marks", "pd"}`` arrays
    (information in 1/a0^2; ``pd`` the detection probability). ``threshold_sigma``: the
    threshold over the matched-filter noise ``rel_sigma``; ``false_peaks_per_pulse``: noise
    peaks per transmitted pulse."""
    _check(rel_sigma, 0.0, 0.0, threshold_sigma, false_peaks_per_pulse)
    a = np.atleast_1d(np.asarray(a, dtype=np.float64))
    if not (np.all(np.isfinite(a)) and np.all(a >= 0)):
        raise ValueError("pulse amplitudes must be finite and >= 0")
    s, th, r = float(rel_sigma), float(threshold_sigma) * float(rel_sigma), float(false_peaks_per_pulse)
    y, w, f, df = _rice_terms(a, s, th)
    lam = f + r * _noise_peak_density(y, s, th)[None, :]
    both = np.sum(w * np.where(lam > 0, df * df / np.where(lam > 0, lam, 1.0), 0.0), axis=1)
    pd = np.sum(w * f, axis=1)
    dpd = np.sum(w * df, axis=1)
    tot = pd + r
    rate = np.where(tot > 0, dpd * dpd / np.where(tot > 0, tot, 1.0), 0.0)
    return {"both": both, "rate": rate, "marks": np.maximum(both - rate, 0.0), "pd": pd}


def detection_bound_deg(rel_sigma: float, mod_15: float, mod_135: float, n_pulses: float,
                        threshold_sigma: float, false_peaks_per_pulse: float = 0.0,
                        use: str = "both") -> float:
    """Bound (deg) on the bearing from a threshold detector's output (module docstring).

    Parameters
    ----------
    rel_sigma, mod_15, mod_135, n_pulses
        As :func:`crb_deg`.
    threshold_sigma : float
        The detection threshold over the matched-filter amplitude noise ``rel_sigma * a0``.
    false_peaks_per_pulse : float
        Noise peaks over the threshold per transmitted pulse.
    use : str
        ``"both"`` (times and amplitudes of the detections), ``"rate"`` (how many detections,
        not their amplitudes) or ``"marks"`` (the amplitudes given the detections: what a DSP
        fitting detected amplitudes can reach at best).
    """
    _check(rel_sigma, mod_15, mod_135, threshold_sigma, false_peaks_per_pulse)
    if use not in USES:
        raise ValueError(f"use must be one of {USES}, not {use!r}")
    if not (isinstance(n_pulses, (int, float)) and math.isfinite(n_pulses) and n_pulses > 0):
        raise ValueError(f"n_pulses must be a finite number > 0, not {n_pulses!r}")
    a, da = _amplitudes(mod_15, mod_135)
    info = information_per_pulse(a, rel_sigma, threshold_sigma, false_peaks_per_pulse)[use]
    j = float(np.mean(da * da * info))
    if j <= 0:
        return math.inf
    return math.degrees(math.sqrt(1.0 / (n_pulses * j)))


def detected_fraction(rel_sigma: float, mod_15: float, mod_135: float,
                      threshold_sigma: float) -> float:
    """The model's fraction of pulses detected (mean ``Pd`` over a rotation), to set against
    the measured one."""
    _check(rel_sigma, mod_15, mod_135, threshold_sigma)
    a, _ = _amplitudes(mod_15, mod_135)
    return float(np.mean(information_per_pulse(a, rel_sigma, threshold_sigma)["pd"]))
