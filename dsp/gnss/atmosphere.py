"""Atmospheric delays of the GPS L1 C/A pseudorange, for the signal generator and the PVT.

Both functions return the delay in metres that the signal suffers on its way from the
satellite to a receiver at geodetic latitude / longitude / height, for a satellite seen at
a given elevation and azimuth (degrees); a measured pseudorange is the geometric range plus
these delays, so the PVT subtracts them and a generator adds them. Float64: they feed the
position solution (``dsp.gnss.pvt``), not the fixed-point loops.

* :func:`klobuchar_delay_m`: the GPS broadcast ionosphere model, IS-GPS-200 20.3.3.5.2.5
  (Klobuchar 1987), from the eight coefficients ``alpha_0..3`` (s, s/semicircle,
  s/semicircle^2, s/semicircle^3) and ``beta_0..3`` (s, ...) of subframe 4 page 18. The
  standard's equations are followed in its units (semicircles, seconds): earth-centred
  angle ``psi = 0.0137 / (E + 0.11) - 0.022``, ionospheric pierce point latitude
  ``phi_i = phi_u + psi cos A`` clipped to +-0.416, longitude
  ``lambda_i = lambda_u + psi sin A / cos(phi_i)``, geomagnetic latitude
  ``phi_m = phi_i + 0.064 cos(lambda_i - 1.617)``, local time
  ``t = 4.32e4 lambda_i + t_GPS`` modulo 86400 s, obliquity ``F = 1 + 16 (0.53 - E)^3``,
  amplitude ``AMP = sum alpha_n phi_m^n`` (>= 0), period ``PER = sum beta_n phi_m^n``
  (>= 72000 s), phase ``x = 2 pi (t - 50400) / PER`` and
  ``T_iono = F (5e-9 + AMP (1 - x^2/2 + x^4/24))`` for ``|x| < 1.57``, ``F 5e-9``
  otherwise. The delay is ``c T_iono`` (L1; the group delay of the code).
* :func:`saastamoinen_delay_m`: the troposphere after Saastamoinen (1972, "Atmospheric
  correction for the troposphere and stratosphere in radio ranging of satellites"): his
  zenith delay mapped with ``1 / cos z`` (``z`` the zenith angle),
  ``d = 0.002277 / cos z * (P / g + (1255 / T + 0.05) e)`` metres (``P``, ``e`` in hPa,
  ``T`` in K), ``g = 1 - 0.00266 cos 2 phi - 0.00028 h_km`` the gravity at the site. His
  bending terms (``- B tan^2 z`` and ``delta R``) are left out: under 2 cm above 30 degrees
  of elevation, about 0.15 m at 15 degrees. The meteorological values come from a standard
  atmosphere unless given: ``P = 1013.25 (1 - 2.2557e-5 h)^5.2568`` hPa,
  ``T = 288.15 - 0.0065 h`` K, relative humidity 50 %, water-vapour pressure
  ``e = RH 6.108 exp(17.15 (T - 273.15) / (T - 38.45))`` hPa (Magnus form). Valid from
  -500 m to 10 km (the standard atmosphere's constant lapse rate holds up to the
  tropopause, ~11 km; its temperature reaches the Magnus form's pole, 38.45 K, at 38.4 km;
  RTKLIB's ``tropmodel`` stops at 10 km too) and above 3 degrees of elevation; outside it
  the function raises.
"""
from __future__ import annotations

import numpy as np

from .ephemeris import C_LIGHT


#: The model's height range (m) for :func:`saastamoinen_delay_m`.
TROPO_HEIGHT_RANGE_M = (-500.0, 10_000.0)
#: The lowest elevation (deg) :func:`saastamoinen_delay_m` accepts.
TROPO_MIN_ELEVATION_DEG = 3.0


def _coeffs(name, values):
    a = np.asarray(values, dtype=np.float64)
    if a.shape != (4,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 4 finite Klobuchar coefficients, not {values!r}")
    return a


def klobuchar_delay_m(lat_deg, lon_deg, elevation_deg, azimuth_deg, gps_tow_s,
                      alpha, beta):
    """L1 ionospheric delay (m) of IS-GPS-200 20.3.3.5.2.5 (module doc) for a receiver at
    ``lat_deg``, ``lon_deg`` (geodetic) and satellites at ``elevation_deg`` (>= 0),
    ``azimuth_deg`` (arrays broadcast), at GPS time of week ``gps_tow_s``. ``alpha``,
    ``beta``: the broadcast coefficients (4 each, in the standard's units: seconds and
    semicircles)."""
    a, b = _coeffs("alpha", alpha), _coeffs("beta", beta)
    el = np.asarray(elevation_deg, dtype=np.float64)
    if np.any(~np.isfinite(el)) or np.any(el < 0) or np.any(el > 90):
        raise ValueError(f"elevation must be in [0, 90] deg, not {elevation_deg!r}")
    if not np.isfinite(gps_tow_s):
        raise ValueError(f"gps_tow_s must be finite, not {gps_tow_s!r}")
    E = el / 180.0                                       # semicircles
    A = np.deg2rad(np.asarray(azimuth_deg, dtype=np.float64))
    phi_u = np.asarray(lat_deg, dtype=np.float64) / 180.0
    lam_u = np.asarray(lon_deg, dtype=np.float64) / 180.0
    psi = 0.0137 / (E + 0.11) - 0.022
    phi_i = np.clip(phi_u + psi * np.cos(A), -0.416, 0.416)
    lam_i = lam_u + psi * np.sin(A) / np.cos(np.pi * phi_i)
    phi_m = phi_i + 0.064 * np.cos(np.pi * (lam_i - 1.617))
    t = np.mod(4.32e4 * lam_i + gps_tow_s, 86400.0)
    F = 1.0 + 16.0 * (0.53 - E) ** 3
    powers = np.stack([np.ones_like(phi_m), phi_m, phi_m ** 2, phi_m ** 3])
    amp = np.maximum(np.tensordot(a, powers, axes=1), 0.0)
    per = np.maximum(np.tensordot(b, powers, axes=1), 72000.0)
    x = 2.0 * np.pi * (t - 50400.0) / per
    day = 5e-9 + amp * (1.0 - x ** 2 / 2.0 + x ** 4 / 24.0)
    t_iono = F * np.where(np.abs(x) < 1.57, day, 5e-9)
    return C_LIGHT * t_iono


def standard_atmosphere(height_m, relative_humidity: float = 0.5):
    """Pressure (hPa), temperature (K) and water-vapour pressure (hPa) of the standard
    atmosphere at ``height_m`` (module doc)."""
    h = np.asarray(height_m, dtype=np.float64)
    if not 0.0 <= relative_humidity <= 1.0:
        raise ValueError(f"relative_humidity must be in [0, 1], not {relative_humidity!r}")
    p = 1013.25 * (1.0 - 2.2557e-5 * h) ** 5.2568
    t = 288.15 - 0.0065 * h
    e = relative_humidity * 6.108 * np.exp(17.15 * (t - 273.15) / (t - 38.45))
    return p, t, e


def saastamoinen_delay_m(lat_deg, height_m, elevation_deg, *, pressure_hpa=None,
                         temperature_k=None, vapour_hpa=None):
    """Tropospheric delay (m) of Saastamoinen's model (module doc) for a receiver at
    ``lat_deg``, ``height_m`` (ellipsoidal, taken for the orthometric height) and satellites at
    ``elevation_deg`` (array). Meteorological values default to the standard atmosphere."""
    h = float(height_m)
    lo, hi = TROPO_HEIGHT_RANGE_M
    if not np.isfinite(h) or not lo <= h <= hi:
        raise ValueError(f"height {height_m!r} m is outside the troposphere model's "
                         f"range [{lo:g}, {hi:g}] m")
    el = np.asarray(elevation_deg, dtype=np.float64)
    if np.any(~np.isfinite(el)) or np.any(el < TROPO_MIN_ELEVATION_DEG) or np.any(el > 90):
        raise ValueError(f"elevation must be in [{TROPO_MIN_ELEVATION_DEG:g}, 90] deg for "
                         f"the troposphere model, not {elevation_deg!r}")
    p, t, e = standard_atmosphere(h)
    p = p if pressure_hpa is None else float(pressure_hpa)
    t = t if temperature_k is None else float(temperature_k)
    e = e if vapour_hpa is None else float(vapour_hpa)
    if not (p > 0 and t > 0 and e >= 0):
        raise ValueError(f"meteorological values must be P > 0, T > 0, e >= 0, "
                         f"not {p!r}, {t!r}, {e!r}")
    z = np.deg2rad(90.0 - el)
    g = 1.0 - 0.00266 * np.cos(2.0 * np.deg2rad(float(lat_deg))) - 0.00028 * h / 1000.0
    return 0.002277 / np.cos(z) * (p / g + (1255.0 / t + 0.05) * e)
