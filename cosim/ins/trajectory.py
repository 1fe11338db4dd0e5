"""The INS paper's trajectory, satellite geometry and the line-of-sight carrier truth.

User trajectory (derived from the INS paper's limits, docs/explanation/ins.md): a straight
line heading east, level (roll = pitch = 0), from rest; from ``start_s`` a +``jerk_g_s`` ramp of ``ramp_s`` (to
``accel_g``), a hold at ``accel_g``, a -``jerk_g_s`` ramp back to 0 g, then cruise to
``duration_s``. The hold is sized so the cruise speed is ``v_max_mps``: with the defaults
(5 g/s, 10 s, 50 g, 8300 m/s) the hold lasts 6.93 s. :class:`PaperTrajectory` also reads a
CSV (time s, along-track distance m) whose time must increase strictly and whose motion is
plausible (:func:`read_trajectory_csv`).

Geometry (a documented simplification): one inertial Cartesian frame whose origin is the
Earth's centre (Earth rotation neglected: it adds < 0.5 m/s^2 to both user and
satellite, the same for the truth and for the INS); the user starts on the surface at
``lat0_deg`` (longitude 0) and moves along the local east; the satellite is on a circular
orbit of radius ``orbit_radius_m`` placed so that it is seen at ``elevation_deg`` /
``azimuth_deg`` at t = 0 with its orbit plane containing the local east (so the flight is
roughly along the satellite's ground track, the strongest line-of-sight dynamics).

Line of sight: ``rho = |Rs - Ru|``, ``rho' = (Vs - Vu) . e``, ``e = (Rs - Ru) / rho``,
``rho'' = (As - Au) . e + (|Vs - Vu|^2 - rho'^2) / rho``; carrier Doppler ``-rho' / lambda``
and Doppler rate ``-rho'' / lambda``. The INS paper's formula, as reconstructed
(docs/explanation/ins.md), keeps only the acceleration term; the second (centripetal) term is ~0.6 % of it
at 8300 m/s and is needed for the derivative check (B4) at 1e-6.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.core.csv_table import read_csv_table
from dsp.gnss.ephemeris import L1_WAVELENGTH_M
from cosim.gnss.oscillator import OscillatorPhase
from dsp.gnss.oscillator import oscillator
from dsp.gnss.ca_code import CHIP_RATE_HZ

G_MPS2 = 9.80665
EARTH_RADIUS_M = 6378137.0
GPS_ORBIT_RADIUS_M = 26560e3
GM_EARTH = 3.986004418e14


def _pos(name, v, allow_zero=False):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        rule = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be a finite number {rule}, not {v!r}")
    return float(v)


#: A trajectory CSV's plausible motion between rows: faster than the Earth's escape
#: velocity is no flight along the scenario's straight line near the surface, and twice the
#: INS paper's peak acceleration (50 g) is beyond what the loops are built for; a position
#: step in the file shows as both (and would otherwise fail deep in the aiding).
CSV_MAX_SPEED_MPS = 11_200.0
CSV_MAX_ACCEL_G = 100.0


@functools.lru_cache(maxsize=8)
def read_trajectory_csv(path: str, mtime_ns: int = 0, size: int = 0) -> np.ndarray:
    """The ``(n, 2)`` table (time s, along-track distance m, read only) of a trajectory CSV,
    read by :func:`cosim.core.csv_table.read_csv_table` (two numeric columns, no header, at
    least 4 rows, time strictly increasing) and checked for motion within
    :data:`CSV_MAX_SPEED_MPS` and :data:`CSV_MAX_ACCEL_G`; a refusal names the file, its line
    and column. ``mtime_ns``, ``size``: the cache's key (a changed file is read again)."""
    name = f"--trajectory-csv {path!r}"
    table = read_csv_table(path, name, [("time_s", "distance_m")], min_rows=4,
                           rows_need="the spline")
    a, lines = table.values, table.lines
    dt = np.diff(a[:, 0])
    v = np.diff(a[:, 1]) / dt
    bad = np.nonzero(np.abs(v) > CSV_MAX_SPEED_MPS)[0]
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"{name} line {lines[i + 1]}, column 2: {a[i + 1, 1]:g} m after "
                         f"{a[i, 1]:g} m {dt[i]:g} s earlier (line {lines[i]}) is "
                         f"{abs(v[i]):.3g} m/s, faster than {CSV_MAX_SPEED_MPS:g} m/s: a "
                         f"position step?")
    acc = np.diff(v) / ((a[2:, 0] - a[:-2, 0]) / 2)
    bad = np.nonzero(np.abs(acc) > CSV_MAX_ACCEL_G * G_MPS2)[0]
    if bad.size:
        i = int(bad[0]) + 1
        raise ValueError(f"{name} line {lines[i]}, column 2: the speed changes from "
                         f"{v[i - 1]:.4g} to {v[i]:.4g} m/s around {a[i, 0]:g} s, "
                         f"{abs(acc[i - 1]) / G_MPS2:.3g} g, more than {CSV_MAX_ACCEL_G:g} g: "
                         f"a position step?")
    return a


@dataclass(frozen=True)
class PaperTrajectory:
    """Along-track kinematics ``s(t), s', s'', s'''`` (m, m/s, m/s^2, m/s^3).

    Parameters
    ----------
    duration_s : float
        Length of the scenario (s).
    start_s : float
        Start of the first jerk ramp (s).
    jerk_g_s, accel_g, v_max_mps : float
        Ramp jerk (g/s), peak acceleration (g), cruise speed (m/s).
    csv_path : str or None
        A table (time s, distance m) used instead of the profile (cubic spline).
    """

    duration_s: float = 150.0
    start_s: float = 5.0
    jerk_g_s: float = 5.0
    accel_g: float = 50.0
    v_max_mps: float = 8300.0
    csv_path: str | None = None

    def __post_init__(self):
        _pos("duration_s", self.duration_s)
        _pos("start_s", self.start_s, allow_zero=True)
        _pos("jerk_g_s", self.jerk_g_s)
        _pos("accel_g", self.accel_g)
        _pos("v_max_mps", self.v_max_mps)
        if self.csv_path is None:
            ramp_v = self.accel_g ** 2 * G_MPS2 / self.jerk_g_s     # both ramps together
            if ramp_v > self.v_max_mps:
                raise ValueError(f"v_max_mps must be >= the two ramps' {ramp_v:.1f} m/s "
                                 f"(accel_g^2 g / jerk_g_s), not {self.v_max_mps}")
            if self.start_s + self.manoeuvre_s > self.duration_s:
                raise ValueError(f"duration_s must cover the manoeuvre (start_s + "
                                 f"{self.manoeuvre_s:.2f} s), not {self.duration_s}")
        else:
            self._table()

    # -- the profile's segments
    @property
    def ramp_s(self) -> float:
        return self.accel_g / self.jerk_g_s

    @property
    def hold_s(self) -> float:
        a = self.accel_g * G_MPS2
        return (self.v_max_mps - a * self.ramp_s) / a

    @property
    def manoeuvre_s(self) -> float:
        return 2 * self.ramp_s + self.hold_s

    def jerk_segments(self) -> list[tuple[float, float]]:
        """(t0, t1) of the segments with non-zero jerk."""
        t0, r, h = self.start_s, self.ramp_s, self.hold_s
        return [(t0, t0 + r), (t0 + r + h, t0 + 2 * r + h)]

    def _table(self):
        p = Path(self.csv_path)
        if not p.is_file():
            raise ValueError(f"--trajectory-csv must name a file, not {self.csv_path!r}")
        st = p.stat()
        return read_trajectory_csv(str(p), st.st_mtime_ns, st.st_size)

    def kinematics(self, t_s) -> np.ndarray:
        """``(4, n)``: distance, speed, acceleration, jerk along track at ``t_s``."""
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        if self.csv_path is not None:
            from scipy.interpolate import CubicSpline
            a = self._table()
            sp = CubicSpline(a[:, 0], a[:, 1])
            return np.stack([sp(t, k) for k in range(4)])
        J = self.jerk_g_s * G_MPS2
        t0, r, h = self.start_s, self.ramp_s, self.hold_s
        knots = np.array([t0, t0 + r, t0 + r + h, t0 + 2 * r + h])
        jerks = np.array([J, 0.0, -J, 0.0])
        # state (s, v, a) at each knot
        st = np.zeros((4, 3))
        s = v = a = 0.0
        tp = 0.0
        for i, tk in enumerate(knots):
            dt = tk - tp
            jp = jerks[i - 1] if i else 0.0
            s, v, a = s + v * dt + a * dt ** 2 / 2 + jp * dt ** 3 / 6, v + a * dt + jp * dt ** 2 / 2, a + jp * dt
            st[i] = s, v, a
            tp = tk
        out = np.zeros((4, t.size))
        k = np.searchsorted(knots, t, side="right") - 1
        on = k >= 0
        kk = k[on]
        dt = t[on] - knots[kk]
        s0, v0, a0 = st[kk].T
        j = jerks[kk]
        out[0, on] = s0 + v0 * dt + a0 * dt ** 2 / 2 + j * dt ** 3 / 6
        out[1, on] = v0 + a0 * dt + j * dt ** 2 / 2
        out[2, on] = a0 + j * dt
        out[3, on] = j
        return out


@dataclass(frozen=True)
class Geometry:
    """User start point, satellite orbit and where the satellite is seen at t = 0."""

    lat0_deg: float = 30.0
    elevation_deg: float = 30.0
    azimuth_deg: float = 90.0
    orbit_radius_m: float = GPS_ORBIT_RADIUS_M
    toward: bool = True

    def __post_init__(self):
        for k in ("lat0_deg", "azimuth_deg"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise ValueError(f"{k} must be a finite number, not {v!r}")
        if not (isinstance(self.elevation_deg, (int, float)) and 0 < self.elevation_deg <= 90):
            raise ValueError(f"elevation_deg must be in (0, 90], not {self.elevation_deg!r}")
        if not (isinstance(self.orbit_radius_m, (int, float)) and self.orbit_radius_m > 2 * EARTH_RADIUS_M):
            raise ValueError(f"orbit_radius_m must be > {2 * EARTH_RADIUS_M:.0f} m, not {self.orbit_radius_m!r}")

    def frame(self):
        """Start position, local east, north, up (ECI at t = 0)."""
        la = math.radians(self.lat0_deg)
        up = np.array([math.cos(la), 0.0, math.sin(la)])
        east = np.array([0.0, 1.0, 0.0])
        north = np.cross(up, east)
        return EARTH_RADIUS_M * up, east, north, up

    def satellite_orbit(self):
        """(Rs0, Vs0 direction, angular rate): circular orbit through the visible point."""
        p0, e, n, u = self.frame()
        el, az = math.radians(self.elevation_deg), math.radians(self.azimuth_deg)
        d = math.cos(el) * (math.sin(az) * e + math.cos(az) * n) + math.sin(el) * u
        # range to the orbit sphere along d
        b = float(p0 @ d)
        rng = -b + math.sqrt(b * b - (p0 @ p0 - self.orbit_radius_m ** 2))
        rs = p0 + rng * d
        rhat = rs / np.linalg.norm(rs)
        # orbit plane containing rs and the user's east; the satellite moves so that it
        # approaches (toward=True) or recedes from the user
        vdir = e - (e @ rhat) * rhat
        vdir /= np.linalg.norm(vdir)
        if not self.toward:
            vdir = -vdir
        w = math.sqrt(GM_EARTH / self.orbit_radius_m ** 3)
        return rs, vdir, w


def los_kinematics(Ru, Vu, Au, Rs, Vs, As):
    """Range, range rate and range acceleration (m, m/s, m/s^2) from the user and satellite
    position, velocity and acceleration (``(3, n)`` arrays)."""
    d = Rs - Ru
    rho = np.linalg.norm(d, axis=0)
    e = d / rho
    dv = Vs - Vu
    rdot = np.sum(dv * e, axis=0)
    rddot = np.sum((As - Au) * e, axis=0) + (np.sum(dv * dv, axis=0) - rdot ** 2) / rho
    return rho, rdot, rddot


def doppler_rate_hz_s(Ru, Vu, Au, Rs, Vs, As, wavelength_m: float = L1_WAVELENGTH_M):
    """The aiding formula: carrier Doppler rate ``-rho'' / lambda`` (Hz/s)."""
    return -los_kinematics(Ru, Vu, Au, Rs, Vs, As)[2] / wavelength_m


class Scenario:
    """User and satellite kinematics at any time, the line of sight and the carrier truth.

    ``truth_at(t)`` gives the keys :func:`cosim.gnss.loopsim.track_fast` reads
    (``carrier_phase_cycles``, ``doppler_hz``, ``doppler_rate_hz_s``, ``code_chips_total``,
    ``nav_bit``; no navigation data: a pilot-like signal, the Costas discriminator is used
    anyway) with the receiver oscillator's phase noise (``oscillator`` ``"tcxo"``,
    ``"ocxo"``, None) drawn from ``seed``.
    """

    def __init__(self, trajectory: PaperTrajectory | None = None, geometry: Geometry | None = None,
                 osc=None, seed: int = 0):
        self.traj = trajectory or PaperTrajectory()
        self.geom = geometry or Geometry()
        self.p0, self.east, _, _ = self.geom.frame()
        self.rs0, self.vdir, self.w = self.geom.satellite_orbit()
        self.osc = OscillatorPhase(oscillator(osc), self.traj.duration_s + 0.1, 1e-3,
                                   np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(3,))))
        self._rho0 = None

    def user(self, t_s):
        k = self.traj.kinematics(t_s)
        e = self.east[:, None]
        return self.p0[:, None] + e * k[0], e * k[1], e * k[2]

    def satellite(self, t_s):
        t = np.atleast_1d(np.asarray(t_s, float))
        R = self.geom.orbit_radius_m
        u1 = self.rs0 / np.linalg.norm(self.rs0)
        c, s = np.cos(self.w * t), np.sin(self.w * t)
        pos = R * (np.outer(u1, c) + np.outer(self.vdir, s))
        vel = R * self.w * (np.outer(-u1, s) + np.outer(self.vdir, c))
        acc = -self.w ** 2 * pos
        return pos, vel, acc

    def los(self, t_s):
        """``(rho, rho', rho'')`` at ``t_s``."""
        return los_kinematics(*self.user(t_s), *self.satellite(t_s))

    def doppler_hz(self, t_s):
        return -self.los(t_s)[1] / L1_WAVELENGTH_M

    def truth_at(self, t_s) -> dict:
        t = np.atleast_1d(np.asarray(t_s, float))
        rho, rd, rdd = self.los(t)
        if self._rho0 is None:
            self._rho0 = self.los(np.zeros(1))[0][0]
        m = -(rho - self._rho0) / L1_WAVELENGTH_M
        osc = self.osc.phase_cycles(t)
        return {"t_s": t, "carrier_phase_cycles": m + osc,
                "doppler_hz": -rd / L1_WAVELENGTH_M, "doppler_rate_hz_s": -rdd / L1_WAVELENGTH_M,
                "code_chips_total": CHIP_RATE_HZ * t + m / 1540.0, "nav_bit": np.ones(t.shape),
                "range_m": rho}
