"""GPS L1 C/A observables: their container, how a receiver forms them, and their prediction.

Per measurement epoch and PRN the receiver reports (RINEX 3 codes):

* ``C1C`` pseudorange (m): ``P = c (t_rx - t_tx)``.
* ``L1C`` carrier phase (cycles), the RINEX sign: it changes in the same sense as the range,
  ``dL/dt = -D``; i.e. ``L = -(accumulated Doppler cycles) + L_0``. Its loss-of-lock
  indicator ``LLI`` (bit 0: lock lost since the previous epoch, a cycle slip possible;
  bit 1: half-cycle ambiguity not resolved).
* ``D1C`` Doppler (Hz): the received carrier frequency minus 1575.42 MHz, positive for an
  approaching satellite (``D = -(d rho/dt) / lambda_L1`` plus the clock terms).
* ``S1C`` C/N0 (dB-Hz).

Pseudorange formation (:func:`transmit_time`, :func:`pseudoranges_from_channels`). All
channels are sampled at one **common receiver epoch** ``t_rx`` (GPS seconds of week as kept
by the receiver clock: it includes the receiver clock bias ``dt_r`` that the PVT solves
for). At that instant channel ``i`` reports, from its frame synchroniser and its code NCO:

* ``tow_sf`` (s): the satellite-clock time of week at which it transmitted the leading edge
  of the current subframe (the HOW of a subframe carries the TOW count of the *next*
  subframe, ``tow_sf = 6 (TOW_count - 1)`` for the subframe whose HOW was read);
* ``n_bits``: whole 20 ms data bits received since that edge (0..299);
* ``n_codes``: whole 1 ms C/A code periods since the last bit edge (0..19);
* ``chips``: the code phase (chips, ``[0, 1023)``) of the prompt replica at ``t_rx``,
  counted from the start of the current code period.

The satellite-clock time of transmission of the signal received at ``t_rx`` is then

``t_tx = tow_sf + 0.020 n_bits + 0.001 n_codes + chips / 1.023e6``

(the chips are transmitted chips: the division by the nominal rate is exact in satellite
time whatever the Doppler), and ``P = c (t_rx - t_tx)`` with ``t_rx - t_tx`` wrapped into
``[-302400, 302400)`` s across the week. A ground receiver sees 64-89 ms of travel time
plus its clock bias; the PVT removes the bias and the satellite clock ``dt_s``
(``t_tx`` is satellite time: GPS time is ``t_tx - dt_s``, IS-GPS-200 20.3.3.3.3.1).

:func:`predict_pseudoranges` is the forward model of ``dsp.gnss.pvt`` (same Earth-rotation
convention) for a generator or a test; :func:`sky_geometry` places satellites on
circular 26560 km orbits at given azimuths / elevations seen from a receiver.
"""
from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

import numpy as np
import pymap3d

from .ca_code import CHIP_RATE_HZ, CODE_LENGTH
from .ephemeris import C_LIGHT, L1_WAVELENGTH_M, MU_GPS, OMEGA_E_DOT, WEEK_S
from .pvt import rotate_z

#: Data-bit and code periods (s).
BIT_S = 0.020
CODE_S = 0.001
#: The GPS epoch (1980-01-06 00:00:00 GPS time).
GPS_EPOCH = dt.datetime(1980, 1, 6)
#: GPS orbit radius (m).
GPS_ORBIT_RADIUS_M = 26_560_000.0


def gps_datetime(week: int, tow_s: float) -> dt.datetime:
    """Calendar date and time (GPS time scale, naive) of GPS ``week`` and ``tow_s``,
    rounded to the microsecond."""
    if isinstance(week, bool) or not isinstance(week, (int, np.integer)) or week < 0:
        raise ValueError(f"week must be a non-negative integer, not {week!r}")
    if not (np.isfinite(tow_s) and 0 <= tow_s < WEEK_S):
        raise ValueError(f"tow_s must be in [0, {WEEK_S}) s, not {tow_s!r}")
    return GPS_EPOCH + dt.timedelta(weeks=int(week), microseconds=round(tow_s * 1e6))


def _counts(tow_sf, n_bits, n_codes, chips):
    """The validated subframe edges and the time since them (s)."""
    tow_sf = np.asarray(tow_sf, dtype=np.float64)
    n_bits, n_codes = np.asarray(n_bits), np.asarray(n_codes)
    chips = np.asarray(chips, dtype=np.float64)
    for name, a, hi in (("n_bits", n_bits, 300), ("n_codes", n_codes, 20)):
        if not np.issubdtype(a.dtype, np.integer) or np.any(a < 0) or np.any(a >= hi):
            raise ValueError(f"{name} must be integers in [0, {hi}), not {a!r}")
    if np.any(~np.isfinite(chips)) or np.any(chips < 0) or np.any(chips >= CODE_LENGTH):
        raise ValueError(f"chips must be in [0, {CODE_LENGTH}), not {chips!r}")
    if np.any(~np.isfinite(tow_sf)) or np.any(tow_sf < 0) or np.any(tow_sf >= WEEK_S) or \
            np.any(np.mod(tow_sf, 6.0) != 0):
        raise ValueError(f"tow_sf must be a subframe edge (a multiple of 6 s in the week), "
                         f"not {tow_sf!r}")
    return tow_sf, BIT_S * n_bits + CODE_S * n_codes + chips / CHIP_RATE_HZ


def transmit_time(tow_sf, n_bits, n_codes, chips):
    """Satellite time of transmission (s of week) from the channel counts (module doc).
    Raises on counts outside their ranges."""
    tow_sf, since = _counts(tow_sf, n_bits, n_codes, chips)
    return tow_sf + since


def pseudoranges_from_channels(t_rx_s, tow_sf, n_bits, n_codes, chips,
                               travel_range_s=(0.060, 0.100)):
    """Pseudoranges (m) ``c (t_rx - t_tx)`` of the channels at the common receiver epoch
    ``t_rx_s`` (module doc), and a mask of those whose apparent travel time lies in
    ``travel_range_s`` (a ground receiver whose clock is set to within a few ms: 64-89 ms);
    the others are NaN (a wrong frame sync or a clock far off), not made up.

    ``t_rx_s`` is seconds of week, a float or a pair ``(whole_s, fraction_s)``: a float
    near the end of the week resolves only 1.2e-10 s (3.5 cm), the pair keeps the fraction
    exact. The travel time is formed as ``(whole - tow_sf) + fraction - (0.020 n_bits +
    0.001 n_codes + chips / 1.023e6)``, small numbers only, so no further precision is lost.
    """
    tow_sf, since = _counts(tow_sf, n_bits, n_codes, chips)
    if isinstance(t_rx_s, tuple):
        whole, frac = t_rx_s
        if isinstance(whole, bool) or not isinstance(whole, (int, np.integer)) or \
                not (np.isfinite(frac) and 0 <= frac < 1):
            raise ValueError(f"t_rx_s as a pair must be (integer s, fraction in [0, 1)), "
                             f"not {t_rx_s!r}")
    else:
        whole = int(np.floor(t_rx_s)) if np.isfinite(t_rx_s) else -1
        frac = t_rx_s - whole if np.isfinite(t_rx_s) else np.nan
    if not 0 <= whole < WEEK_S:
        raise ValueError(f"t_rx_s must be in [0, {WEEK_S}) s, not {t_rx_s!r}")
    edge = np.mod(whole - tow_sf + WEEK_S / 2, WEEK_S) - WEEK_S / 2    # exact (integers)
    travel = (edge + frac) - since
    ok = (travel >= travel_range_s[0]) & (travel <= travel_range_s[1])
    return np.where(ok, C_LIGHT * travel, np.nan), ok


@dataclass(frozen=True)
class ObservationEpoch:
    """One epoch of observables, one entry per PRN (NaN: not observed).

    ``week``, ``tow_s``: the receiver time of the epoch (GPS time scale); ``flag``: the
    RINEX epoch flag (0 OK, 1 power failure since the previous epoch); ``clock_offset_s``:
    the receiver clock offset if known (written to RINEX, not applied)."""

    week: int
    tow_s: float
    prns: np.ndarray
    pseudorange_m: np.ndarray
    carrier_cycles: np.ndarray
    doppler_hz: np.ndarray
    cn0_dbhz: np.ndarray
    lli: np.ndarray
    flag: int = 0
    clock_offset_s: float | None = None

    def __post_init__(self):
        gps_datetime(self.week, self.tow_s)
        prns = np.asarray(self.prns)
        if prns.ndim != 1 or not np.issubdtype(prns.dtype, np.integer) or \
                np.any(prns < 1) or np.any(prns > 32) or len(set(prns.tolist())) != len(prns):
            raise ValueError(f"prns must be distinct GPS PRNs 1-32, not {self.prns!r}")
        n = len(prns)
        for name in ("pseudorange_m", "carrier_cycles", "doppler_hz", "cn0_dbhz"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != (n,) or np.any(np.isinf(a)):
                raise ValueError(f"{name} must be {n} finite-or-NaN values, not {a!r}")
            object.__setattr__(self, name, a)
        lli = np.asarray(self.lli)
        if lli.shape != (n,) or not np.issubdtype(lli.dtype, np.integer) or \
                np.any(lli < 0) or np.any(lli > 7):
            raise ValueError(f"lli must be {n} integers 0-7, not {self.lli!r}")
        if self.flag not in (0, 1):
            raise ValueError(f"flag must be 0 or 1 (an observation epoch), not {self.flag!r}")
        object.__setattr__(self, "prns", prns)
        object.__setattr__(self, "lli", lli)

    @property
    def time(self) -> dt.datetime:
        return gps_datetime(self.week, self.tow_s)


def predict_pseudoranges(rx_ecef_m, clock_bias_m: float, sat_pos_m, sat_clock_s,
                         delays_m=0.0):
    """Pseudoranges (m) and travel times (s) of satellites at ``sat_pos_m`` (ECEF of their
    transmission instant) seen from ``rx_ecef_m`` (ECEF of the reception instant):
    ``c tau + b - c dt_s + delays`` with ``tau = |R(w_E tau) r_s - r| / c`` iterated to
    convergence (``dsp.gnss.pvt``'s model)."""
    r = np.asarray(rx_ecef_m, dtype=np.float64)
    pos = np.asarray(sat_pos_m, dtype=np.float64)
    tau = np.linalg.norm(pos - r, axis=1) / C_LIGHT
    for _ in range(10):
        tau = np.linalg.norm(rotate_z(pos, OMEGA_E_DOT * tau) - r, axis=1) / C_LIGHT
    pr = C_LIGHT * tau + clock_bias_m - C_LIGHT * np.asarray(sat_clock_s) + delays_m
    return pr, tau


def predict_range_rates(rx_ecef_m, rx_vel_mps, clock_drift_mps: float, sat_pos_m,
                        sat_vel_mps, sat_clock_drift, tau_s):
    """Pseudorange rates (m/s) ``u . (R v_s - v) + b' - c ddt_s`` (``dsp.gnss.pvt``'s
    model) at travel times ``tau_s``; the Doppler is ``-rate / lambda_L1``."""
    ang = OMEGA_E_DOT * np.asarray(tau_s)
    rot = rotate_z(sat_pos_m, ang)
    u = rot - np.asarray(rx_ecef_m, dtype=np.float64)
    u /= np.linalg.norm(u, axis=1)[:, None]
    rel = rotate_z(sat_vel_mps, ang) - np.asarray(rx_vel_mps, dtype=np.float64)
    return np.einsum("ij,ij->i", u, rel) + clock_drift_mps - \
        C_LIGHT * np.asarray(sat_clock_drift)


def doppler_from_rate(rate_mps):
    """Doppler (Hz) of a pseudorange rate (m/s): ``-rate / lambda_L1``."""
    return -np.asarray(rate_mps) / L1_WAVELENGTH_M


def sky_geometry(lat_deg: float, lon_deg: float, height_m: float, azimuth_deg,
                          elevation_deg, radius_m: float = GPS_ORBIT_RADIUS_M):
    """Satellites on a sphere of ``radius_m`` seen from the receiver at the given azimuths /
    elevations at the reception instant: their ECEF positions at transmission, in the ECEF
    frame of the transmission instant (as an ephemeris gives them), and velocities of the
    circular-orbit speed ``sqrt(GM / radius)`` perpendicular to the radius (eastward in
    inertial space, in the same frame; a nominal geometry, not an ephemeris)."""
    az = np.atleast_1d(np.asarray(azimuth_deg, dtype=np.float64))
    el = np.atleast_1d(np.asarray(elevation_deg, dtype=np.float64))
    if az.shape != el.shape or np.any(el < -90) or np.any(el > 90):
        raise ValueError("azimuth_deg and elevation_deg must match, elevations in [-90, 90]")
    r = np.array(pymap3d.geodetic2ecef(lat_deg, lon_deg, height_m), dtype=np.float64)
    p1 = np.column_stack(pymap3d.aer2ecef(az, el, np.ones_like(az), lat_deg, lon_deg,
                                          height_m))
    u = p1 - r
    u /= np.linalg.norm(u, axis=1)[:, None]
    ru = u @ r
    s = -ru + np.sqrt(ru ** 2 - r @ r + radius_m ** 2)
    rot = r + s[:, None] * u                         # reception frame
    tau = s / C_LIGHT
    pos = rotate_z(rot, -OMEGA_E_DOT * tau)
    east = np.cross([0.0, 0.0, 1.0], pos)
    north = np.cross(pos, east)
    d = east / np.linalg.norm(east, axis=1)[:, None] * 0.8 + \
        north / np.linalg.norm(north, axis=1)[:, None] * 0.6
    vel_inertial = np.sqrt(MU_GPS / radius_m) * d
    vel = vel_inertial - np.cross([0.0, 0.0, OMEGA_E_DOT], pos)  # ECEF velocity
    return pos, vel
