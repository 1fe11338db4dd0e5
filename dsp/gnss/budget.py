"""The thermal-noise error budget of a GPS L1 C/A fix: per channel the pseudorange and
range-rate noise of the tracking loops actually run, then through the PVT's weighted
least squares to position and velocity.

Per channel (C/N0 ``c`` in Hz, dump ``T``, the tracker of :class:`dsp.gnss.loops_fixed.
ChannelCore`: a Costas PLL of order 2/3 and a carrier-aided 1st-order DLL):

* **Code.** The DLL discriminator is the normalised early-minus-late envelope
  (:func:`dsp.gnss.discriminators.dll_nelp`) with E-L spacing ``d`` chips. With the
  prompt amplitude ``A`` and per-component noise ``s^2`` (``A^2 / 2 s^2 = c T``), early
  and late noise correlated by ``1 - d`` (a sampled replica ``d`` chips apart), its
  output noise per dump is ``d / (4 c T) (1 + 1 / (c T))`` chips^2
  (:func:`nelp_discriminator_variance`): the first factor is the linearised
  ``(n_E - n_L) / 2A``, the second the quadrature (squaring) term, which a Monte Carlo of
  the discriminator matches to 0.5 % at 40-48 dB-Hz (the unit test checks it; the
  early-minus-late *power* form ``2 / ((2 - d) c T)`` of Betz & Kolodziejski reads 1-2 %
  low there). The loop is ``f_code = f_chip + f_D / 1540 + 4 Bn_dll tau``: the carrier
  aiding removes the dynamics (its own noise, the PLL's frequency noise / 1540, is below
  1e-3 of the DLL's and left out), and the replica code phase's variance is the
  discriminator variance times ``sum h^2``, ``h`` the loop's impulse response with the
  channel's timing (:func:`dsp.gnss.loops.loop_impulse_response`; the analogue limit is
  ``2 Bn_dll T``). Times the chip length: the pseudorange sigma.
* **Carrier.** The Costas ``atan(Q/I)`` discriminator's noise per dump is
  ``1 / (2 c T) (1 + 1 / (2 c T)) / (2 pi)^2`` cycles^2 (:func:`costas_discriminator_variance`,
  Kaplan's PLL jitter before the loop); the Doppler the tracker reports is the PLL's
  frequency state ``v1`` (:meth:`~dsp.gnss.loops_fixed.ChannelCore.doppler_hz`), whose
  variance is that times ``sum h_v1^2`` (:func:`dsp.gnss.loops.carrier_loop_response`,
  the tracker's own coefficients and latency). Times the L1 wavelength: the range-rate sigma.
* **Geometry.** The PVT (:mod:`dsp.gnss.pvt`) solves ``x = A y`` with
  ``A = (G^T W G)^-1 G^T W``, ``G`` the east/north/up/clock rows
  (:func:`dsp.gnss.pvt.enu_geometry`) and ``W = diag(1 / sigma_w^2)`` its weight model; with
  the true measurement noise ``R = diag(sigma^2)`` the solution's covariance is
  ``A R A^T`` (:func:`solution_covariance`), position from pseudoranges and velocity from
  range rates (the same ``G`` and weights). Noise that is independent between channels and
  between fixes is assumed: true for the pseudoranges when the fixes are further apart than
  the DLL's time constant ``1 / (4 Bn_dll)`` and for the range rates than the PLL's.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .ephemeris import CHIP_M, L1_WAVELENGTH_M
from .loops import carrier_loop_response, loop_impulse_response
from .pvt import enu_geometry

__all__ = ["TrackingLoops", "nelp_discriminator_variance", "costas_discriminator_variance",
           "betz_dll_sigma_chips", "dll_response", "code_sigma_chips", "doppler_sigma_hz",
           "channel_sigmas", "solution_covariance", "predicted_errors"]



def _cn0(cn0_dbhz):
    c = np.asarray(cn0_dbhz, dtype=np.float64)
    if not np.all(np.isfinite(c)):
        raise ValueError(f"cn0_dbhz must be finite, not {cn0_dbhz!r}")
    return 10.0 ** (c / 10.0)


@dataclass(frozen=True)
class TrackingLoops:
    """The loops of a tracking channel the budget is evaluated for (module doc):
    PLL ``order`` and ``bn_hz``, DLL ``dll_bn_hz``, E-L ``spacing_chips`` (``d``), dump
    ``T_s``, and ``latency`` (epochs between a dump and its write taking effect: 1 on the
    FPGA channel)."""

    order: int = 3
    bn_hz: float = 15.0
    dll_bn_hz: float = 1.0
    spacing_chips: float = 0.5
    T_s: float = 1e-3
    latency: int = 1

    def __post_init__(self):
        if self.order not in (2, 3):
            raise ValueError(f"order must be 2 or 3, not {self.order!r}")
        for name, lo, hi in (("bn_hz", 0.0, 100.0), ("dll_bn_hz", 0.0, 20.0),
                             ("spacing_chips", 0.0, 1.0), ("T_s", 0.0, 0.02)):
            v = getattr(self, name)
            if not (np.isfinite(v) and lo < v <= hi):
                raise ValueError(f"{name} must be within ({lo:g}, {hi:g}], not {v!r}")
        if self.latency not in (0, 1, 2):
            raise ValueError(f"latency must be 0, 1 or 2 epochs, not {self.latency!r}")


def nelp_discriminator_variance(cn0_dbhz, T_s: float, spacing_chips: float):
    """Noise variance (chips^2) of one dump's normalised E-L envelope at ``tau = 0``
    (module doc)."""
    cT = _cn0(cn0_dbhz) * T_s
    return spacing_chips / (4.0 * cT) * (1.0 + 1.0 / cT)


def costas_discriminator_variance(cn0_dbhz, T_s: float):
    """Noise variance (cycles^2) of one dump's Costas ``atan(Q/I)`` (module doc)."""
    cT = _cn0(cn0_dbhz) * T_s
    return 1.0 / (2.0 * cT) * (1.0 + 1.0 / (2.0 * cT)) / (2.0 * np.pi) ** 2


def betz_dll_sigma_chips(cn0_dbhz, bn_hz: float, spacing_chips: float, T_s: float):
    """The textbook analogue DLL thermal noise of an early-minus-late power discriminator
    with infinite front-end bandwidth (Betz & Kolodziejski 2000; Kaplan & Hegarty):
    ``sqrt(Bn d / (2 c) (1 + 2 / ((2 - d) T c)))`` chips."""
    c = _cn0(cn0_dbhz)
    d = spacing_chips
    return np.sqrt(bn_hz * d / (2.0 * c) * (1.0 + 2.0 / ((2.0 - d) * T_s * c)))


@functools.lru_cache(maxsize=32)
def dll_response(dll_bn_hz: float, T_s: float, latency: int) -> np.ndarray:
    """The replica code phase's impulse response to the DLL discriminator (chips per chip
    of error), loop ``f = 4 Bn_dll tau`` with the channel timing."""
    k = 4.0 * dll_bn_hz
    n = max(2000, int(40 / (k * T_s)))
    h, _ = loop_impulse_response(lambda e: (k * e, 0.0), T_s, latency, n)
    if abs(h[-20:]).max() > 1e-9:
        raise ValueError(f"the DLL (Bn {dll_bn_hz} Hz, T {T_s} s, latency {latency}) is "
                         f"unstable")
    return h


@functools.lru_cache(maxsize=32)
def _carrier_sums(order: int, bn_hz: float, T_s: float, latency: int) -> tuple:
    h_r, h_v = carrier_loop_response(order, bn_hz, T_s, latency)
    return float(np.sum(h_r ** 2)), float(np.sum(h_v ** 2))


def code_sigma_chips(cn0_dbhz, loops: TrackingLoops):
    """Thermal noise (1 sigma, chips) of the DLL's replica code phase (module doc)."""
    h = dll_response(loops.dll_bn_hz, loops.T_s, loops.latency)
    return np.sqrt(nelp_discriminator_variance(cn0_dbhz, loops.T_s, loops.spacing_chips)
                   * float(np.sum(h ** 2)))


def doppler_sigma_hz(cn0_dbhz, loops: TrackingLoops):
    """Thermal noise (1 sigma, Hz) of the PLL's Doppler state ``v1`` (module doc)."""
    _, s_v = _carrier_sums(loops.order, loops.bn_hz, loops.T_s, loops.latency)
    return np.sqrt(costas_discriminator_variance(cn0_dbhz, loops.T_s) * s_v)


def channel_sigmas(cn0_dbhz, loops: TrackingLoops) -> tuple[np.ndarray, np.ndarray]:
    """``(pseudorange sigma (m), range-rate sigma (m/s))`` per C/N0 (module doc)."""
    return (np.asarray(code_sigma_chips(cn0_dbhz, loops) * CHIP_M),
            np.asarray(doppler_sigma_hz(cn0_dbhz, loops) * L1_WAVELENGTH_M))


def solution_covariance(g, weight_sigma, noise_sigma) -> np.ndarray:
    """``A R A^T`` with ``A = (G^T W G)^-1 G^T W`` (module doc): ``g`` (n, 4) rows,
    ``weight_sigma`` (n,) the solver's sigmas (``W = diag(1/sigma^2)``), ``noise_sigma`` (n,)
    the measurements' true sigmas."""
    g = np.asarray(g, dtype=np.float64)
    ws = np.asarray(weight_sigma, dtype=np.float64)
    ns = np.asarray(noise_sigma, dtype=np.float64)
    n = g.shape[0]
    if g.ndim != 2 or g.shape[1] != 4 or ws.shape != (n,) or ns.shape != (n,):
        raise ValueError(f"g must be (n, 4) with weight_sigma and noise_sigma (n,), not "
                         f"{g.shape}, {ws.shape}, {ns.shape}")
    if n < 4 or not (np.all(ws > 0) and np.all(ns >= 0)):
        raise ValueError("solution_covariance needs >= 4 rows and positive sigmas")
    w = 1.0 / ws ** 2
    a = np.linalg.solve(g.T @ (w[:, None] * g), (g * w[:, None]).T)
    return a @ (ns[:, None] ** 2 * a.T)


def predicted_errors(elevation_deg, azimuth_deg, weight_sigma, noise_sigma) -> dict:
    """1-sigma east, north, up, 3-D and clock errors (units of ``noise_sigma``) of one
    epoch's solution (module doc)."""
    cov = solution_covariance(enu_geometry(elevation_deg, azimuth_deg), weight_sigma,
                              noise_sigma)
    d = np.diag(cov)
    return {"east": float(np.sqrt(d[0])), "north": float(np.sqrt(d[1])),
            "up": float(np.sqrt(d[2])), "3d": float(np.sqrt(d[:3].sum())),
            "clock": float(np.sqrt(d[3]))}
