"""Correlation-domain fast path: E/P/L correlator outputs drawn directly, for Monte Carlo.

Model (one coherent interval of ``T`` s, batched over any leading axes = trials)::

    X = sigma sqrt(2 eta (C/N0) T) d R(tau - o_X) / sqrt(R(0)) sinc(df T) exp(j 2 pi dphi) + n_X

for ``X`` in E, P, L with replica offsets ``o_E = +d/2, o_P = 0, o_L = -d/2`` (the golden
correlator's convention, ``dsp.gnss.correlator``), where

* ``dphi`` (cycles) is the carrier phase error (signal minus replica) at the interval's
  midpoint and ``df`` (Hz) the frequency error over it: the phase error is linear over the
  interval (its curvature from the Doppler rate, ``pi fdot T^2 / 4``, is neglected:
  1e-5 cycle at 1 g);
* ``tau`` (chips) is the code phase error (signal minus prompt replica) at the midpoint;
* ``R`` is the C/A code autocorrelation, an ideal infinite-bandwidth triangle
  ``max(0, 1 - |tau|)`` (``bandwidth_hz=None``; the IF path has no front-end filter and
  rectangular chips), or the one seen through an ideal two-sided brick-wall filter of
  ``bandwidth_hz``: ``R_B(tau) = int_{-b/2}^{b/2} sinc^2(u) cos(2 pi u tau) du``,
  ``b = B / 1.023 MHz`` (the spectrum of a long Gold code taken as the chip's ``sinc^2``);
  or, given ``prn``, that PRN's own autocorrelation with rectangular chips (the triangle
  plus ``|tau| R[1]``, ``R[1]`` the code's one-chip autocorrelation: -1/1023, -65/1023 or
  +63/1023 for the Gold codes), which is what the IF path actually correlates with;
* ``d`` is the navigation bit (+1/-1);
* ``eta`` is the correlation efficiency of the IF path's ADC (:func:`adc_efficiency`; 1
  without an ADC, ``adc_bits=None``): the generator's ``b``-bit mid-rise quantiser at its
  AGC step (``cosim.gnss.signal.agc_step_sigma``) on noise-dominated samples passes the
  signal with gain ``g`` and white noise of variance ``Var Q(n)``, so the post-correlation
  SNR is multiplied by ``eta = g^2 sigma^2 / Var Q(n)`` (Bussgang; the theory and the
  Gaussian cell sums are :mod:`dsp.quantizer`): 2 bits at Max's step 0.8812
  (0.549 dB), 1 bit ``2/pi`` (1.961 dB). The quantised noise stays white, so the E/P/L
  noise correlation is the replicas' overlap as without the ADC;
* ``sigma`` is the rms of each real noise component (1 by default); the noise is complex
  Gaussian, I and Q independent and identically distributed, and across E, P, L each
  component has the correlation ``rho(o_X - o_Y) = R(o_X - o_Y) / R(0)``: with the
  triangle ``1 - |Delta|`` for a replica separation ``Delta`` (E-P and P-L: ``1 - d/2``,
  E-L: ``1 - d``). Noise is independent from one interval to the next.

With ``sigma = 1`` the post-correlation SNR is ``|P|^2 / (2 sigma^2) = (C/N0) T R(tau)^2 /
R(0) sinc^2`` (C/N0 as defined in ``cosim.gnss.signal``), times ``eta`` with an ADC.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, ca_code_levels, check_prn


def adc_efficiency(adc_bits: int | None,
                   agc_full_scale_sigma: float | None = None) -> float:
    """``eta``: the post-correlation SNR factor of the IF path's ``adc_bits``-bit ADC at the
    generator's AGC step (module docstring; weak-signal limit); 1.0 for ``None`` (no ADC).
    ``-10 log10(eta)`` is the quantisation loss in dB (0.549 dB at 2 bits)."""
    if adc_bits is None:
        return 1.0
    from dsp.quantizer import quantizer_efficiency
    from .signal import agc_step_sigma
    b = adc_bits
    if isinstance(b, bool) or not isinstance(b, (int, np.integer)) or not 1 <= b <= 16:
        raise ValueError(f"adc_bits must be None (no ADC) or an integer in [1, 16], not {b!r}")
    if agc_full_scale_sigma is not None and not (
            isinstance(agc_full_scale_sigma, (int, float, np.integer, np.floating))
            and math.isfinite(agc_full_scale_sigma) and agc_full_scale_sigma > 0):
        raise ValueError(f"agc_full_scale_sigma must be > 0, not {agc_full_scale_sigma!r}")
    return quantizer_efficiency(int(b), agc_step_sigma(int(b), agc_full_scale_sigma),
                                quantizer="mid_rise")


def _code_acf(prn: int) -> np.ndarray:
    """The periodic autocorrelation ``R[k] = (1/1023) sum c_i c_{i+k}``, k = 0..1022."""
    c = ca_code_levels(check_prn(prn)).astype(np.float64)
    f = np.fft.fft(c)
    return np.fft.ifft(f * np.conj(f)).real / CODE_LENGTH


def code_correlation(tau_chips, bandwidth_hz: float | None = None, prn: int | None = None) -> np.ndarray:
    """``R(tau)``: the triangle, or through an ideal filter of two-sided ``bandwidth_hz``;
    with ``prn`` (infinite bandwidth only) the PRN's own rectangular-chip autocorrelation,
    linear between its integer-lag values (e.g. ``1 - tau (1 - R[1])``, ``R[1] = 63/1023``
    for PRN 7, instead of ``1 - tau``)."""
    tau = np.asarray(tau_chips, dtype=np.float64)
    if prn is not None:
        if bandwidth_hz is not None:
            raise ValueError("code_correlation: a PRN's own autocorrelation is for infinite "
                             f"bandwidth only, not bandwidth_hz={bandwidth_hz!r}")
        R = _code_acf(prn)
        u = np.mod(tau, CODE_LENGTH)
        k = np.floor(u).astype(np.int64)
        f = u - k
        return (1 - f) * R[k % CODE_LENGTH] + f * R[(k + 1) % CODE_LENGTH]
    if bandwidth_hz is None:
        return np.clip(1.0 - np.abs(tau), 0.0, None)
    B = float(bandwidth_hz)
    if not math.isfinite(B) or B <= 0:
        raise ValueError(f"bandwidth_hz must be > 0 or None (infinite), not {bandwidth_hz!r}")
    half = B / CHIP_RATE_HZ / 2
    # Gauss-Legendre per unit of u (sinc^2 has zeros at the integers).
    n_seg = max(1, int(math.ceil(half)))
    x, w = np.polynomial.legendre.leggauss(32)
    edges = np.linspace(0.0, half, n_seg + 1)
    u = ((edges[1:] - edges[:-1])[:, None] * (x + 1) / 2 + edges[:-1, None]).ravel()
    wu = ((edges[1:] - edges[:-1])[:, None] / 2 * w).ravel()
    g = np.sinc(u) ** 2 * wu
    return 2.0 * (np.cos(2 * np.pi * np.multiply.outer(tau, u)) @ g)


def noise_correlation(spacing_chips: float = 0.5, bandwidth_hz: float | None = None,
                      prn: int | None = None) -> np.ndarray:
    """The 3x3 correlation of the E, P, L noise (either arm), model above."""
    h = spacing_chips / 2
    off = np.array([h, 0.0, -h])
    r = code_correlation(off[:, None] - off[None, :], bandwidth_hz, prn) / \
        code_correlation(0.0, bandwidth_hz, prn)
    # the zero-lag terms are 1 by definition; the band-limited quadrature's matrix product
    # may round them differently from the scalar zero-lag value (BLAS blocking)
    np.fill_diagonal(r, 1.0)
    return r


@functools.lru_cache(maxsize=64)
def _noise_factor(spacing_chips: float, bandwidth_hz, prn) -> np.ndarray:
    """``L`` with ``L L^T`` = :func:`noise_correlation` (its eigen-decomposition; read-only,
    kept per spacing, bandwidth and PRN)."""
    w, V = np.linalg.eigh(noise_correlation(spacing_chips, bandwidth_hz, prn))
    L = V * np.sqrt(np.clip(w, 0.0, None))
    L.setflags(write=False)
    return L


@dataclass
class FastCorrelations:
    """Complex E, P, L, each of the broadcast shape of the inputs."""

    early: np.ndarray
    prompt: np.ndarray
    late: np.ndarray

    def iq(self) -> np.ndarray:
        """``(..., 3)`` complex E, P, L (the layout of ``CorrelatorOutput.iq``)."""
        return np.stack([self.early, self.prompt, self.late], axis=-1)


def correlate_fast(cn0_dbhz, phase_err_cycles=0.0, freq_err_hz=0.0, code_err_chips=0.0,
                   nav_bit=1.0, T_s: float = 1e-3, spacing_chips: float = 0.5,
                   bandwidth_hz: float | None = None, sigma: float = 1.0,
                   rng: np.random.Generator | None = None, shape=None,
                   prn: int | None = None, adc_bits: int | None = None,
                   agc_full_scale_sigma: float | None = None) -> FastCorrelations:
    """Draw E/P/L for every interval; inputs broadcast together (and with ``shape``).

    ``cn0_dbhz=None`` gives the noise-free correlations. ``adc_bits`` (and
    ``agc_full_scale_sigma``, as in ``GnssSignalConfig``): the IF path's ADC, whose
    quantisation loss scales the signal by ``sqrt(eta)`` (:func:`adc_efficiency`);
    None: no ADC.
    """
    eta = adc_efficiency(adc_bits, agc_full_scale_sigma)
    if not (math.isfinite(T_s) and T_s > 0):
        raise ValueError(f"T_s must be > 0 s, not {T_s!r}")
    d = float(spacing_chips)
    if not 0 < d <= 2:
        raise ValueError(f"spacing_chips must be in (0, 2], not {spacing_chips!r}")
    if cn0_dbhz is not None and not np.all(np.isfinite(cn0_dbhz)):
        raise ValueError(f"cn0_dbhz must be finite, not {cn0_dbhz!r}")
    arrs = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in
                                 (0.0 if cn0_dbhz is None else cn0_dbhz, phase_err_cycles,
                                  freq_err_hz, code_err_chips, nav_bit)))
    full = np.broadcast_shapes(arrs[0].shape, () if shape is None else tuple(shape))
    cn0, dphi, df, tau, bit = (np.broadcast_to(a, full) for a in arrs)
    r0 = float(code_correlation(0.0, bandwidth_hz, prn))
    if cn0_dbhz is None:
        amp = np.ones(full)
    else:
        amp = sigma * np.sqrt(2 * eta * 10 ** (cn0 / 10) * T_s)
    common = amp * bit * np.sinc(df * T_s) * np.exp(2j * np.pi * dphi) / math.sqrt(r0)
    h = d / 2
    sig = [common * code_correlation(tau - o, bandwidth_hz, prn) for o in (h, 0.0, -h)]
    if cn0_dbhz is not None:
        rng = np.random.default_rng() if rng is None else rng
        L = _noise_factor(d, bandwidth_hz, prn)
        z = rng.standard_normal(full + (2, 3)) @ L.T
        n = sigma * (z[..., 0, :] + 1j * z[..., 1, :])
        sig = [s + n[..., i] for i, s in enumerate(sig)]
    return FastCorrelations(*sig)


def epoch_errors(truth_at, t0_s, T_s, replica_phase_cycles, replica_doppler_hz,
                 replica_code_chips, replica_code_rate_hz):
    """The fast path's inputs from the truth and a replica held over each interval.

    ``truth_at`` is ``GnssSignalGenerator.truth_at``; the replica's carrier phase (cycles,
    IF excluded) and prompt code phase (chips, unwrapped) are given at the interval starts
    ``t0_s`` and advance at ``replica_doppler_hz`` and ``replica_code_rate_hz``.
    Returns ``(phase_err_cycles, freq_err_hz, code_err_chips, nav_bit)`` at the midpoints.
    """
    t0 = np.asarray(t0_s, dtype=np.float64)
    T = float(T_s)
    a, m, b = truth_at(t0), truth_at(t0 + T / 2), truth_at(t0 + T)
    ph_r_mid = np.asarray(replica_phase_cycles) + np.asarray(replica_doppler_hz) * T / 2
    code_r_mid = np.asarray(replica_code_chips) + np.asarray(replica_code_rate_hz) * T / 2
    # Mean frequency over the interval from the phase chord, not the midpoint Doppler.
    df = (b["carrier_phase_cycles"] - a["carrier_phase_cycles"]) / T - replica_doppler_hz
    return (m["carrier_phase_cycles"] - ph_r_mid, df,
            m["code_chips_total"] - code_r_mid, m["nav_bit"])
