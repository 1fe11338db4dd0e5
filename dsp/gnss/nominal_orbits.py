"""The nominal GPS 24-slot constellation as broadcast ephemerides, for scenarios without a
RINEX navigation file.

Slots (GPS SPS Performance Standard, 3rd edition, October 2001, Table 3-1 "Reference Orbit
Slot Assignments as of the Defined Epoch"; the same 24 baseline slots as Table 3.2-1 of the
2008 edition): six planes A-F with right ascensions of the ascending node (RAAN) 272.847,
332.847, 32.847, 92.847, 152.847, 212.847 degrees and four slots per plane at the arguments of
latitude of :data:`SLOTS`, at the epoch 1 July 1993 0000Z, Greenwich hour angle 18 h 36 min
14.4 s. Reference orbit: circular (e = 0), inclination 55 degrees, semi-major axis
26,559.7 km.

From slot to :class:`dsp.gnss.ephemeris.Ephemeris` at GPS time (week, toe):

* the node regresses at the J2 secular rate ``OmegaDot = -3/2 n J2 (a_E / a)^2 cos i``
  (WGS-84 ``J2 = 1.08262983226e-3``, ``a_E = 6378137 m``; -7.8e-9 rad/s, the
  -4.4874e-7 deg/s of the SPS PS 2001 Table A-2-1 almanac);
* the Greenwich hour angle advances at ``OMEGA_E_DOT`` (no precession or nutation: a nominal
  geometry); the node longitude at toe is ``RAAN(toe) - GHA(toe)`` and, with the LNAV
  convention ``Omega_k = Omega0 + (OmegaDot - OMEGA_E_DOT) tk - OMEGA_E_DOT toe``,
  ``Omega0 = RAAN(toe) - GHA(toe) + OMEGA_E_DOT toe``;
* on a circular orbit the argument of perigee is 0 and the mean anomaly equals the argument of
  latitude: ``M0 = u0 + n (t_toe - t_epoch)``, ``n = sqrt(MU_GPS / a^3)``;
* every harmonic correction, deltaN, IDOT and the clock terms are zero; IODE = IODC =
  ``iod``; health 0, URA index 0, fit interval flag 0;
* the epoch 1993-07-01 00:00 is taken as GPS time (the 9 s GPS-UTC offset of that date moves
  the slots by 0.04 degree of orbit; a nominal geometry).

The SPS PS assigns no PRNs to slots; here slot A1 is PRN 1, A2 PRN 2, ..., F4 PRN 24
(:data:`SLOT_NAMES` in PRN order). Angles are wrapped to [-pi, pi) so the LNAV fields hold
them (``Ephemeris.quantised()`` gives the broadcast grid).
"""
from __future__ import annotations

import math

import numpy as np

from .ephemeris import MU_GPS, OMEGA_E_DOT, WEEK_S, Ephemeris

#: SPS PS (2001) Table 3-1: slot -> (RAAN, argument of latitude), degrees, at the epoch.
SLOTS = {
    "A1": (272.847, 268.126), "A2": (272.847, 161.786), "A3": (272.847, 11.676),
    "A4": (272.847, 41.806),
    "B1": (332.847, 80.956), "B2": (332.847, 173.336), "B3": (332.847, 309.976),
    "B4": (332.847, 204.376),
    "C1": (32.847, 111.876), "C2": (32.847, 11.796), "C3": (32.847, 339.666),
    "C4": (32.847, 241.556),
    "D1": (92.847, 135.226), "D2": (92.847, 265.446), "D3": (92.847, 35.156),
    "D4": (92.847, 167.356),
    "E1": (152.847, 197.046), "E2": (152.847, 302.596), "E3": (152.847, 66.066),
    "E4": (152.847, 333.686),
    "F1": (212.847, 238.886), "F2": (212.847, 345.226), "F3": (212.847, 105.206),
    "F4": (212.847, 135.346),
}
#: Slot names in PRN order (PRN = index + 1).
SLOT_NAMES = tuple(SLOTS)
#: The reference orbit of the SPS PS: semi-major axis (m), inclination (deg).
SEMI_MAJOR_AXIS_M = 26_559_700.0
INCLINATION_DEG = 55.0
#: The slot epoch, 1993-07-01 00:00 (GPS time), as seconds since the GPS epoch, and its
#: Greenwich hour angle 18 h 36 min 14.4 s (degrees).
EPOCH_GPS_S = float((np.datetime64("1993-07-01T00:00:00") - np.datetime64("1980-01-06T00:00:00"))
                    / np.timedelta64(1, "s"))
EPOCH_GHA_DEG = (18.0 + 36.0 / 60.0 + 14.4 / 3600.0) * 15.0
#: WGS-84 second zonal harmonic and equatorial radius (NIMA TR8350.2).
J2_WGS84 = 1.08262983226e-3
A_WGS84_M = 6378137.0


def _wrap(x: float) -> float:
    return (x + math.pi) % (2.0 * math.pi) - math.pi


def nodal_rate() -> float:
    """The J2 secular regression rate of the node of the reference orbit (rad/s)."""
    a = SEMI_MAJOR_AXIS_M
    n = math.sqrt(MU_GPS / a ** 3)
    return -1.5 * n * J2_WGS84 * (A_WGS84_M / a) ** 2 * math.cos(math.radians(INCLINATION_DEG))


def nominal_constellation(week: int, toe: float, *, iod: int = 0) -> list[Ephemeris]:
    """The 24 nominal satellites (PRN 1..24 = slots A1..F4) as ephemerides with reference
    time (``week``, ``toe``) (see the module notes). ``toe`` must be a multiple of 16 s (the
    LNAV toe grid) in [0, 604800)."""
    if isinstance(week, bool) or not isinstance(week, (int, np.integer)) or week < 0:
        raise ValueError(f"week = {week!r} is not a GPS week number")
    if not (0.0 <= toe < WEEK_S and float(toe) % 16.0 == 0.0):
        raise ValueError(f"toe = {toe!r} is not a multiple of 16 s in the week")
    a = SEMI_MAJOR_AXIS_M
    n = math.sqrt(MU_GPS / a ** 3)
    odot = nodal_rate()
    dt = int(week) * WEEK_S + float(toe) - EPOCH_GPS_S
    gha = math.radians(EPOCH_GHA_DEG) + OMEGA_E_DOT * dt
    out = []
    for k, name in enumerate(SLOT_NAMES):
        raan0, u0 = (math.radians(x) for x in SLOTS[name])
        omega0 = _wrap(raan0 + odot * dt - gha + OMEGA_E_DOT * float(toe))
        m0 = _wrap(u0 + n * dt)
        out.append(Ephemeris(
            prn=k + 1, week=int(week), toe=float(toe), toc=float(toe), sqrtA=math.sqrt(a),
            e=0.0, i0=math.radians(INCLINATION_DEG), Omega0=omega0, omega=0.0, M0=m0,
            deltaN=0.0, OmegaDot=odot, IDOT=0.0, Cuc=0.0, Cus=0.0, Crc=0.0, Crs=0.0, Cic=0.0,
            Cis=0.0, af0=0.0, af1=0.0, af2=0.0, TGD=0.0, IODE=iod, IODC=iod))
    return out
