"""GPS broadcast ephemerides and the IS-GPS-200 user algorithm (satellite position, velocity
and clock), vectorised over satellites and times.

Ephemeris
---------
:class:`Ephemeris` holds the LNAV subframe 1-3 parameters of one satellite (IS-GPS-200 Tables
20-I and 20-III) in SI units: angles in radians (the standard broadcasts semicircles; the
conversion uses ``PI_GPS``), rates in rad/s, times in seconds of the GPS week (``toe``,
``toc``) with ``week`` the full (not modulo 1024) GPS week of ``toe``. ``quantised()`` rounds
every scaled field to its LNAV grid (:mod:`dsp.gnss.lnav_fields`): what a receiver decodes
from the broadcast bits, so a signal generator that computes its satellite positions from the
quantised ephemeris and a receiver that decodes its message agree bit for bit.

User algorithm (IS-GPS-200 section 20.3.3.4.3, Table 20-IV)
------------------------------------------------------------
For GPS system time ``t`` (seconds of the week; any real number, a week crossover is handled):
``tk = t - toe`` folded into [-302400, 302400) s; ``A = sqrtA^2``, ``n = sqrt(mu / A^3) +
deltaN``; ``Mk = M0 + n tk``; Kepler ``Mk = Ek - e sin Ek`` solved by Newton's method to
machine precision; true anomaly ``nu_k``; argument of latitude ``Phi_k = nu_k + omega``;
second-harmonic corrections ``du = Cus sin 2Phi + Cuc cos 2Phi`` (and ``dr`` with Crs/Crc,
``di`` with Cis/Cic) evaluated at the *uncorrected* ``Phi_k``; ``u = Phi + du``, ``r = A (1 - e
cos E) + dr``, ``i = i0 + di + IDOT tk``; ``Omega_k = Omega0 + (OmegaDot - OmegaE_dot) tk -
OmegaE_dot toe``; ECEF ``x = x' cos Omega - y' cos i sin Omega`` and so on. Velocity: the
time derivatives of the same equations (the velocity rows of Table 20-IV).

Clock (section 20.3.3.3.3.1, 20.3.3.3.3.2): ``dtsv = af0 + af1 (t - toc) + af2 (t - toc)^2 +
dtr`` with the relativistic term ``dtr = F e sqrtA sin Ek``, ``F = -2 sqrt(mu) / c^2``; an L1
C/A (single-frequency) user subtracts ``TGD``. ``t - toc`` is folded like ``tk``.

Earth rotation during signal travel (IS-GPS-200 20.3.3.4.3.4, geometric range: the Earth's
rotation during the propagation time is to be accounted for): :func:`sagnac_rotate` turns the
position from the ECEF frame of the transmission time into that of the reception time, a
rotation by ``OmegaE_dot * tau`` about z.

The constants are those of IS-GPS-200 (WGS-84 values the standard fixes for the user
algorithm): ``MU_GPS = 3.986005e14 m^3/s^2``, ``OMEGA_E_DOT = 7.2921151467e-5 rad/s``,
``PI_GPS = 3.1415926535898``, ``F_REL = -4.442807633e-10 s/m^(1/2)``, ``C_LIGHT = 299792458``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import NamedTuple, Sequence, Union

import numpy as np

from .ca_code import CHIP_RATE_HZ, L1_HZ
from .lnav_fields import EPHEMERIS_FIELDS, EPHEMERIS_INTEGERS, IONO_FIELDS, PI_GPS, \
    UTC_FIELDS, check_integer, quantise_value

#: WGS-84 Earth gravitational constant of IS-GPS-200 Table 20-IV (m^3/s^2).
MU_GPS = 3.986005e14
#: WGS-84 Earth rotation rate of IS-GPS-200 Table 20-IV (rad/s).
OMEGA_E_DOT = 7.2921151467e-5
#: Relativistic clock constant F = -2 sqrt(mu) / c^2 of IS-GPS-200 20.3.3.3.3.1 (s/m^(1/2)).
F_REL = -4.442807633e-10
#: Speed of light (m/s), the value of IS-GPS-200 and of WGS-84.
C_LIGHT = 299792458.0
#: The L1 carrier's wavelength and one C/A chip (m).
L1_WAVELENGTH_M = C_LIGHT / L1_HZ
CHIP_M = C_LIGHT / CHIP_RATE_HZ
#: Seconds in a GPS week, and half of it (the tk fold of Table 20-IV).
WEEK_S = 604800.0
HALF_WEEK_S = 302400.0

__all__ = ["PI_GPS", "MU_GPS", "OMEGA_E_DOT", "F_REL", "C_LIGHT", "WEEK_S", "Ephemeris",
           "KlobucharParameters", "UtcParameters", "select_ephemeris", "SatelliteState",
           "fold_time", "satellite_position_velocity", "satellite_clock", "satellite_states",
           "system_time", "sagnac_rotate"]

_FLOATS = tuple(EPHEMERIS_FIELDS)


@dataclass(frozen=True)
class Ephemeris:
    """The LNAV broadcast parameters of one GPS satellite (IS-GPS-200 Tables 20-I, 20-III).

    Units: metres, seconds, radians (angles), rad/s (deltaN, OmegaDot, IDOT); ``toe``, ``toc``
    in seconds of the GPS week; ``week`` the full GPS week of ``toe``. ``ura_index`` is the
    4-bit URA index N (20.3.3.3.1.3), ``health`` the 6-bit subframe-1 health word
    (20.3.3.3.1.4), ``fit_interval_flag`` 0 for a 4-hour curve fit and 1 for a longer one
    (20.3.3.4.3.1), ``aodo`` the 5-bit age of data offset (20.3.3.4.1, units of 900 s).
    """

    prn: int
    week: int
    toe: float
    toc: float
    sqrtA: float
    e: float
    i0: float
    Omega0: float
    omega: float
    M0: float
    deltaN: float
    OmegaDot: float
    IDOT: float
    Cuc: float
    Cus: float
    Crc: float
    Crs: float
    Cic: float
    Cis: float
    af0: float
    af1: float
    af2: float
    TGD: float
    IODE: int
    IODC: int
    health: int = 0
    ura_index: int = 0
    fit_interval_flag: int = 0
    l2_codes: int = 1
    l2p_flag: int = 0
    aodo: int = 0

    def __post_init__(self):
        what = f"Ephemeris(prn={self.prn!r}): "
        if isinstance(self.prn, bool) or not isinstance(self.prn, (int, np.integer)) \
                or not 1 <= self.prn <= 32:
            raise ValueError(f"Ephemeris: prn = {self.prn!r} is not a GPS PRN 1..32")
        if isinstance(self.week, bool) or not isinstance(self.week, (int, np.integer)) \
                or self.week < 0:
            raise ValueError(f"{what}week = {self.week!r} is not a non-negative GPS week")
        for name in _FLOATS:
            v = getattr(self, name)
            if not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
                raise ValueError(f"{what}{name} = {v!r} is not a finite number")
            object.__setattr__(self, name, float(v))
        for name, bits in EPHEMERIS_INTEGERS.items():
            if name != "week":
                object.__setattr__(self, name, check_integer(name, bits, getattr(self, name),
                                                             what=what))
        object.__setattr__(self, "prn", int(self.prn))
        object.__setattr__(self, "week", int(self.week))
        if not 0.0 <= self.e < 1.0:
            raise ValueError(f"{what}e = {self.e!r} is not an eccentricity in [0, 1)")
        if not self.sqrtA > 0.0:
            raise ValueError(f"{what}sqrtA = {self.sqrtA!r} is not positive")
        for name in ("toe", "toc"):
            if not 0.0 <= getattr(self, name) < WEEK_S:
                raise ValueError(f"{what}{name} = {getattr(self, name)!r} is not a time of "
                                 f"week in [0, 604800) s")

    @property
    def fit_interval_hours(self) -> float:
        """The curve-fit interval: 4 h for flag 0; for flag 1 ("greater than 4 hours",
        20.3.3.4.3.1) 6 h, the shortest extended interval of Table 20-XII."""
        return 4.0 if self.fit_interval_flag == 0 else 6.0

    def quantised(self) -> "Ephemeris":
        """This ephemeris with every scaled field rounded to its LNAV grid (Tables 20-I,
        20-III): the parameters a receiver decodes from the broadcast subframes. A
        ``ValueError`` names a field that does not fit its bits."""
        what = f"Ephemeris(prn={self.prn}): "
        return replace(self, **{name: quantise_value(f, getattr(self, name), what=what)
                                for name, f in EPHEMERIS_FIELDS.items()})

    def valid_at(self, week: int, tow: float) -> bool:
        """Whether GPS time (``week``, ``tow``) lies inside the fit interval centred on toe."""
        dt = (week - self.week) * WEEK_S + (tow - self.toe)
        return abs(dt) <= self.fit_interval_hours * 1800.0


@dataclass(frozen=True)
class KlobucharParameters:
    """The single-frequency ionosphere model coefficients of subframe 4 page 18 (IS-GPS-200
    20.3.3.5.1.7, Table 20-X): ``alpha`` (s, s/semicircle, s/semicircle^2, s/semicircle^3)
    and ``beta`` (s, s/semicircle, ...), four each."""

    alpha: tuple
    beta: tuple

    def __post_init__(self):
        for name in ("alpha", "beta"):
            v = tuple(float(x) for x in getattr(self, name))
            if len(v) != 4 or not all(math.isfinite(x) for x in v):
                raise ValueError(f"KlobucharParameters: {name} = {getattr(self, name)!r} is not "
                                 f"four finite numbers")
            object.__setattr__(self, name, v)

    def quantised(self) -> "KlobucharParameters":
        """The coefficients rounded to their 8-bit LNAV grids (Table 20-X)."""
        v = [quantise_value(f, x, what="KlobucharParameters: ")
             for f, x in zip(IONO_FIELDS, self.alpha + self.beta)]
        return KlobucharParameters(tuple(v[:4]), tuple(v[4:]))


@dataclass(frozen=True)
class UtcParameters:
    """GPS-UTC parameters of subframe 4 page 18 (IS-GPS-200 20.3.3.5.1.6, Table 20-IX):
    ``A0`` (s), ``A1`` (s/s), reference time ``tot`` (s of week) and week ``WNt`` (8 bits,
    modulo 256), the leap seconds ``dtLS`` now and ``dtLSF`` after the week ``WNLSF`` (modulo
    256) and day ``DN`` (1..7) of a scheduled change."""

    A0: float
    A1: float
    tot: float
    WNt: int
    dtLS: int
    WNLSF: int
    DN: int
    dtLSF: int

    def __post_init__(self):
        for name in UTC_FIELDS:
            v = getattr(self, name)
            if not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
                raise ValueError(f"UtcParameters: {name} = {v!r} is not a finite number")
        for name in ("WNt", "dtLS", "WNLSF", "DN", "dtLSF"):
            v = getattr(self, name)
            if float(v) != int(v):
                raise ValueError(f"UtcParameters: {name} = {v!r} is not an integer")
            object.__setattr__(self, name, int(v))
        object.__setattr__(self, "A0", float(self.A0))
        object.__setattr__(self, "A1", float(self.A1))
        object.__setattr__(self, "tot", float(self.tot))

    def quantised(self) -> "UtcParameters":
        """The parameters rounded to their LNAV grids (Table 20-IX); a ``ValueError`` names
        one that does not fit its bits."""
        q = {n: quantise_value(f, getattr(self, n), what="UtcParameters: ")
             for n, f in UTC_FIELDS.items()}
        return UtcParameters(**q)


def select_ephemeris(ephemerides: Sequence[Ephemeris], prn: int, week: int, tow: float, *,
                     healthy_only: bool = True):
    """The ephemeris of ``prn`` to use at GPS time (``week``, ``tow``): among those whose fit
    interval covers the time (:meth:`Ephemeris.valid_at`; healthy ones only, ``health == 0``,
    unless ``healthy_only`` is false) the one with the nearest toe (a tie: the later toe,
    then the larger IODC); ``None`` when none covers the time."""
    best, key = None, None
    for x in ephemerides:
        if x.prn != prn or (healthy_only and x.health != 0) or not x.valid_at(week, tow):
            continue
        dt = (week - x.week) * WEEK_S + (tow - x.toe)
        k = (abs(dt), dt, -x.IODC)
        if key is None or k < key:
            best, key = x, k
    return best


class SatelliteState(NamedTuple):
    """Satellite state at GPS system time ``t``: ECEF position (m) and velocity (m/s) in the
    frame of ``t``, clock offset ``clock_bias`` (s: dtsv including the relativistic term, and
    minus TGD for L1 C/A), its rate ``clock_drift`` (s/s), the relativistic part (s)."""

    position: np.ndarray
    velocity: np.ndarray
    clock_bias: np.ndarray
    clock_drift: np.ndarray
    relativistic: np.ndarray


EphemerisLike = Union[Ephemeris, Sequence[Ephemeris]]


def _params(ephs: EphemerisLike) -> dict:
    """The parameters of one ephemeris (scalars) or of several (arrays of shape (S,))."""
    if isinstance(ephs, Ephemeris):
        return {f.name: getattr(ephs, f.name) for f in fields(Ephemeris)}
    ephs = list(ephs)
    if not ephs or not all(isinstance(x, Ephemeris) for x in ephs):
        raise TypeError("ephemerides: expected an Ephemeris or a non-empty sequence of them")
    return {f.name: np.array([getattr(x, f.name) for x in ephs]) for f in fields(Ephemeris)}


def fold_time(dt):
    """A time difference folded into [-302400, 302400) s: the week crossover of Table 20-IV
    (``tk`` and ``t - toc``)."""
    dt = np.asarray(dt, dtype=np.float64)
    return dt - WEEK_S * np.floor((dt + HALF_WEEK_S) / WEEK_S)


def _kepler(M, e):
    """Eccentric anomaly E of ``M = E - e sin E`` by Newton's method until every update is
    within a few ulps of E (machine precision; |e| < 1; at most 30 passes)."""
    E = np.array(M, dtype=np.float64, copy=True)
    tol = 4.0 * np.finfo(np.float64).eps
    for _ in range(30):
        dE = (M - E + e * np.sin(E)) / (1.0 - e * np.cos(E))
        E = E + dE
        if np.all(np.abs(dE) <= tol * np.maximum(1.0, np.abs(E))):
            break
    return E


def _orbit(p, t):
    """Table 20-IV at system time ``t`` (broadcast against the parameter arrays)."""
    t = np.asarray(t, dtype=np.float64)
    A = p["sqrtA"] ** 2
    n0 = np.sqrt(MU_GPS / A ** 3)
    n = n0 + p["deltaN"]
    tk = fold_time(t - p["toe"])
    M = p["M0"] + n * tk
    e = p["e"]
    E = _kepler(M, e)
    sinE, cosE = np.sin(E), np.cos(E)
    one_ecos = 1.0 - e * cosE
    sq = np.sqrt(1.0 - e * e)
    nu = np.arctan2(sq * sinE, cosE - e)
    phi = nu + p["omega"]
    s2, c2 = np.sin(2.0 * phi), np.cos(2.0 * phi)
    u = phi + p["Cus"] * s2 + p["Cuc"] * c2
    r = A * one_ecos + p["Crs"] * s2 + p["Crc"] * c2
    i = p["i0"] + p["Cis"] * s2 + p["Cic"] * c2 + p["IDOT"] * tk
    xp, yp = r * np.cos(u), r * np.sin(u)
    Om = p["Omega0"] + (p["OmegaDot"] - OMEGA_E_DOT) * tk - OMEGA_E_DOT * p["toe"]
    cO, sO, ci, si = np.cos(Om), np.sin(Om), np.cos(i), np.sin(i)
    pos = np.stack([xp * cO - yp * ci * sO, xp * sO + yp * ci * cO, yp * si], axis=-1)
    # Velocity rows of Table 20-IV: the time derivatives of the lines above.
    Edot = n / one_ecos
    nudot = Edot * sq / one_ecos
    idot = p["IDOT"] + 2.0 * nudot * (p["Cis"] * c2 - p["Cic"] * s2)
    udot = nudot + 2.0 * nudot * (p["Cus"] * c2 - p["Cuc"] * s2)
    rdot = e * A * Edot * sinE + 2.0 * nudot * (p["Crs"] * c2 - p["Crc"] * s2)
    Omdot = p["OmegaDot"] - OMEGA_E_DOT
    xpdot = rdot * np.cos(u) - yp * udot
    ypdot = rdot * np.sin(u) + xp * udot
    vel = np.stack([
        -xp * Omdot * sO + xpdot * cO - ypdot * sO * ci - yp * (Omdot * cO * ci - idot * sO * si),
        xp * Omdot * cO + xpdot * sO + ypdot * cO * ci - yp * (Omdot * sO * ci + idot * cO * si),
        ypdot * si + yp * idot * ci], axis=-1)
    return pos, vel, E, Edot


def satellite_position_velocity(ephs: EphemerisLike, t) -> tuple[np.ndarray, np.ndarray]:
    """ECEF position (m) and velocity (m/s) at GPS system time ``t`` (seconds of the week of
    the ephemeris; the ±302400 s fold handles a week crossover), in the ECEF frame of ``t``
    (IS-GPS-200 Table 20-IV). ``ephs`` is one :class:`Ephemeris` or a sequence of S; ``t``
    broadcasts against (S,): shape (T, 1) gives (T, S, 3), shape (S,) one time per satellite."""
    pos, vel, _, _ = _orbit(_params(ephs), t)
    return pos, vel


def _clock(p, t, E, Edot, tgd: bool):
    dt = fold_time(np.asarray(t, dtype=np.float64) - p["toc"])
    rel = F_REL * p["e"] * p["sqrtA"] * np.sin(E)
    bias = p["af0"] + p["af1"] * dt + p["af2"] * dt * dt + rel
    if tgd:
        bias = bias - p["TGD"]
    drift = p["af1"] + 2.0 * p["af2"] * dt + F_REL * p["e"] * p["sqrtA"] * np.cos(E) * Edot
    return bias, drift, rel


def satellite_clock(ephs: EphemerisLike, t, *, l1_ca: bool = True):
    """Satellite clock offset ``dtsv`` (s) and its rate (s/s) at GPS system time ``t``
    (IS-GPS-200 20.3.3.3.3.1, with the relativistic term ``F e sqrtA sin Ek``); for an L1 C/A
    single-frequency user (``l1_ca``) minus TGD (20.3.3.3.3.2). Shapes as
    :func:`satellite_position_velocity`."""
    p = _params(ephs)
    _, _, E, Edot = _orbit(p, t)
    bias, drift, _ = _clock(p, t, E, Edot, l1_ca)
    return bias, drift


def satellite_states(ephs: EphemerisLike, t, *, l1_ca: bool = True) -> SatelliteState:
    """Position, velocity and clock of :func:`satellite_position_velocity` and
    :func:`satellite_clock` in one pass."""
    p = _params(ephs)
    pos, vel, E, Edot = _orbit(p, t)
    bias, drift, rel = _clock(p, t, E, Edot, l1_ca)
    return SatelliteState(pos, vel, bias, drift, rel)


def system_time(ephs: EphemerisLike, t_sv, *, l1_ca: bool = True, iterations: int = 2):
    """GPS system time ``t = t_sv - dtsv(t)`` of a satellite time ``t_sv`` (the transmission
    time read from the signal), IS-GPS-200 20.3.3.3.3.1; ``dtsv`` is evaluated at ``t`` by
    fixed-point iteration (two passes reach double precision: dtsv changes by < 1e-11 s/s)."""
    t_sv = np.asarray(t_sv, dtype=np.float64)
    t = t_sv
    for _ in range(iterations):
        bias, _ = satellite_clock(ephs, t, l1_ca=l1_ca)
        t = t_sv - bias
    return t


def sagnac_rotate(position, travel_time, velocity=None):
    """Satellite position (and velocity, if given) turned from the ECEF frame of the
    transmission time into that of the reception time ``travel_time`` seconds later: a
    rotation by ``theta = OMEGA_E_DOT * travel_time`` about the z axis (``x' = x cos theta +
    y sin theta``, ``y' = -x sin theta + y cos theta``). ``position`` (..., 3), ``travel_time``
    broadcasting against (...)."""
    pos = np.asarray(position, dtype=np.float64)
    if pos.shape[-1:] != (3,):
        raise ValueError(f"sagnac_rotate: position of shape {pos.shape} is not (..., 3)")
    th = OMEGA_E_DOT * np.asarray(travel_time, dtype=np.float64)
    c, s = np.cos(th), np.sin(th)

    def rot(v):
        return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1],
                         np.broadcast_to(v[..., 2], np.broadcast(c, v[..., 2]).shape)], axis=-1)

    if velocity is None:
        return rot(pos)
    return rot(pos), rot(np.asarray(velocity, dtype=np.float64))
