"""Receiver motion, receiver clock, C/N0 model and the light-time geometry of a GPS
constellation scenario (the physics under :mod:`cosim.gnss.constellation`).

Times
-----
``s`` is receiver time since the record's first sample (seconds of the receiver's clock:
sample ``n`` is at ``s = n / fs``); the receiver's clock reads GPS time ``tow0 + s`` there.
The receiver clock error ``dt_r(s) = bias + drift s + x(s)`` (s) is a function of receiver
time, ``x`` the oscillator's time error (:func:`cosim.gnss.oscillator.clock_error_s`, on a
grid of ``step_s``, linear between its points, 0 at ``s = 0``). True GPS time is
``t = tow0 + s - dt_r(s)`` and the receiver's motion is evaluated at ``u = t - tow0 = s -
dt_r(s)``, seconds of GPS time since the nominal start.

Receiver motion
---------------
An object with ``state(u) -> (position (T, 3), velocity (T, 3))`` in ECEF (WGS-84, m and
m/s, the Earth-fixed frame of time ``u``): :class:`StaticReceiver` (ECEF, or geodetic through
pymap3d) or :class:`TrajectoryReceiver` (two callables; :func:`csv_receiver` reads one from
a table of ECEF rows); :func:`along_track_receiver` flies
an along-track profile (the INS paper's :class:`cosim.ins.trajectory.PaperTrajectory`, or any
object with its ``kinematics(u) -> (4, T)`` of distance, speed, acceleration, jerk) on the
great circle through a stated origin, at the origin's geocentric radius, in a stated
azimuth. :func:`check_motion` refuses, before any work, a motion that is not finite, leaves
the band of heights ``[MIN_HEIGHT_M, MAX_HEIGHT_M]`` above the WGS-84 ellipsoid, moves faster
than ``MAX_SPEED_MPS`` (the escape speed at the surface: nothing that fast stays near the
Earth), accelerates harder than ``MAX_ACCEL_MPS2`` (100 g, twice the INS paper's 50 g
peak) or whose velocity is not the derivative of its position.

Light time (IS-GPS-200 20.3.3.4.3.3.2)
--------------------------------------
For each satellite the geometric travel time ``tau`` solves ``c tau = |R(OMEGA_E_DOT tau)
r_sv(t - tau) - r_rx(t)|``: ``r_sv`` from Table 20-IV in the ECEF frame of the transmission
time ``t_tx = t - tau``, turned into the frame of the reception time by
:func:`dsp.gnss.ephemeris.sagnac_rotate`. Fixed-point iteration from 0.075 s until ``tau``
changes by less than 1e-15 s (a contraction of factor ``|v_sv| / c ~ 1e-5``: four or five
passes). Its rate, with ``e`` the unit line of sight, ``A = e . (R v_sv - v_rx)`` and ``B =
e . (OMEGA_E_DOT R (y_sv, -x_sv, 0) - R v_sv)``: ``dtau/dt = A / (c - B)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np
import pymap3d

from dsp.gnss.ephemeris import C_LIGHT, OMEGA_E_DOT, sagnac_rotate, satellite_states

from ..core.csv_table import read_csv_table
from .oscillator import clock_error_s
from dsp.gnss.oscillator import oscillator as oscillator_model

#: Height band (m above the WGS-84 ellipsoid) a receiver must stay in.
MIN_HEIGHT_M = -1.0e3
MAX_HEIGHT_M = 1.0e5
#: Escape speed at the Earth's surface (m/s): the fastest receiver accepted.
MAX_SPEED_MPS = 11.2e3
#: The hardest acceleration accepted (m/s^2): 100 g.
MAX_ACCEL_MPS2 = 100 * 9.80665
#: Step (s) of the motion check, and the tolerance (m/s) of velocity against the
#: position's central difference (plus 1e-6 of the speed).
MOTION_CHECK_STEP_S = 0.01
MOTION_VELOCITY_TOL_MPS = 0.01


def _finite(name, v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number, not {v!r}")
    return float(v)


class StaticReceiver:
    """A receiver at rest at the ECEF position ``position_m`` (3 values, m)."""

    def __init__(self, position_m):
        p = np.asarray(position_m, dtype=np.float64)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"receiver position must be 3 finite ECEF coordinates (m), "
                             f"not {position_m!r}")
        self.position_m = p

    @classmethod
    def geodetic(cls, lat_deg: float, lon_deg: float, h_m: float) -> "StaticReceiver":
        """At WGS-84 latitude, longitude (degrees) and height (m) (pymap3d.geodetic2ecef)."""
        lat = _finite("lat_deg", lat_deg)
        if not -90.0 <= lat <= 90.0:
            raise ValueError(f"lat_deg must be in [-90, 90], not {lat_deg!r}")
        return cls(pymap3d.geodetic2ecef(lat, _finite("lon_deg", lon_deg),
                                          _finite("h_m", h_m)))

    def state(self, u):
        u = np.atleast_1d(np.asarray(u, dtype=np.float64))
        return np.broadcast_to(self.position_m, u.shape + (3,)).copy(), np.zeros(u.shape + (3,))

    def __repr__(self):
        return f"StaticReceiver({self.position_m.tolist()})"


class TrajectoryReceiver:
    """A moving receiver: ``position(u)`` and ``velocity(u)`` map times ``u`` (s of GPS time
    since the nominal start; an array of shape (T,)) to ECEF arrays of shape (T, 3);
    ``span_s`` the (first, last) time of the table it comes from (None: any time)."""

    def __init__(self, position: Callable, velocity: Callable, name: str = "trajectory",
                 span_s: tuple | None = None):
        if not callable(position) or not callable(velocity):
            raise ValueError("a trajectory receiver needs callables position(u) and velocity(u)")
        self.position, self.velocity, self.name = position, velocity, str(name)
        self.span_s = span_s

    def state(self, u):
        u = np.atleast_1d(np.asarray(u, dtype=np.float64))
        p = np.asarray(self.position(u), dtype=np.float64)
        v = np.asarray(self.velocity(u), dtype=np.float64)
        if p.shape != u.shape + (3,) or v.shape != u.shape + (3,):
            raise ValueError(f"{self.name}: position/velocity of {u.size} times must have shape "
                             f"{u.shape + (3,)}, not {p.shape} / {v.shape}")
        return p, v

    def __repr__(self):
        return f"TrajectoryReceiver({self.name})"


def along_track_receiver(profile, lat_deg: float, lon_deg: float, h_m: float,
                         azimuth_deg: float) -> TrajectoryReceiver:
    """``profile.kinematics(u)`` (distance ``d``, speed ``v``, ...) flown from the origin
    (geodetic, pymap3d) in direction ``azimuth_deg`` (clockwise from north) on the great
    circle through the origin at its geocentric radius ``R``: with ``n0`` the unit origin
    vector and ``e`` the unit horizontal direction (the local azimuth vector, made
    perpendicular to ``n0``), ``theta = d / R``, ``r = R (cos theta n0 + sin theta e)``,
    ``v_ecef = v (-sin theta n0 + cos theta e)``."""
    r0 = np.array(StaticReceiver.geodetic(lat_deg, lon_deg, h_m).position_m)
    R = float(np.linalg.norm(r0))
    n0 = r0 / R
    az = math.radians(_finite("azimuth_deg", azimuth_deg))
    d = np.array(pymap3d.enu2uvw(math.sin(az), math.cos(az), 0.0, lat_deg, lon_deg))
    e = d - (d @ n0) * n0
    e /= np.linalg.norm(e)

    def kin(u):
        k = np.asarray(profile.kinematics(u), dtype=np.float64)
        th = k[0] / R
        return np.cos(th)[:, None], np.sin(th)[:, None], k[1][:, None]

    def position(u):
        c, s, _ = kin(u)
        return R * (c * n0 + s * e)

    def velocity(u):
        c, s, v = kin(u)
        return v * (-s * n0 + c * e)

    return TrajectoryReceiver(position, velocity, name=f"{type(profile).__name__} from "
                              f"({lat_deg:g}, {lon_deg:g}, {h_m:g} m) az {azimuth_deg:g} deg")


#: The columns of a trajectory CSV (:func:`csv_receiver`; the velocities optional).
TRAJECTORY_COLUMNS = ("t", "x", "y", "z", "vx", "vy", "vz")


def csv_receiver(path, name: str = "trajectory") -> TrajectoryReceiver:
    """A :class:`TrajectoryReceiver` from the CSV file ``path``: rows ``t, x, y, z`` or ``t,
    x, y, z, vx, vy, vz`` (``t`` seconds of GPS time since the record's nominal start,
    strictly increasing; ECEF metres and m/s), ``#`` comments and one header line allowed,
    at least 2 rows (4 without velocities), read by
    :func:`cosim.core.csv_table.read_csv_table`. With velocities the motion is the cubic Hermite
    interpolant of the rows (position and velocity met at every row), without them the
    cubic spline through the positions (velocity its derivative); beyond the table the end
    pieces continue. Errors name ``name`` (the option) and the row. A position step that
    does not fit its rows' velocities shows as an acceleration of the interpolant that
    :func:`check_motion` refuses."""
    from scipy.interpolate import CubicHermiteSpline, CubicSpline
    p = Path(path)
    a = read_csv_table(p, f"{name} {str(path)!r}", [TRAJECTORY_COLUMNS[:4], TRAJECTORY_COLUMNS],
                       min_rows=(4, 2), header=True, rows_need="the interpolation").values
    t = a[:, 0]
    sp = CubicHermiteSpline(t, a[:, 1:4], a[:, 4:7], axis=0) if a.shape[1] == 7 else \
        CubicSpline(t, a[:, 1:4], axis=0)
    dsp_ = sp.derivative()
    return TrajectoryReceiver(lambda u: sp(u), lambda u: dsp_(u), name=f"{name} {p.name}",
                              span_s=(float(t[0]), float(t[-1])))


def check_motion(receiver, u0: float, u1: float) -> None:
    """Refuse a receiver motion (module notes) over GPS times ``u0 .. u1`` (s), sampled every
    :data:`MOTION_CHECK_STEP_S`; the error names the first time and what is wrong."""
    n = max(2, int(math.ceil((u1 - u0) / MOTION_CHECK_STEP_S)) + 1)
    u = u0 + np.arange(n) * MOTION_CHECK_STEP_S
    p, v = receiver.state(u)
    what = f"receiver {receiver!r}"
    bad = ~(np.all(np.isfinite(p), axis=1) & np.all(np.isfinite(v), axis=1))
    if bad.any():
        raise ValueError(f"{what}: position or velocity not finite at u = {u[bad][0]:.3f} s")
    _, _, h = pymap3d.ecef2geodetic(p[:, 0], p[:, 1], p[:, 2])
    out = (h < MIN_HEIGHT_M) | (h > MAX_HEIGHT_M)
    if out.any():
        i = int(np.argmax(out))
        raise ValueError(f"{what}: height {h[i]:.0f} m at u = {u[i]:.3f} s leaves the band "
                         f"[{MIN_HEIGHT_M:g}, {MAX_HEIGHT_M:g}] m above the WGS-84 ellipsoid")
    speed = np.linalg.norm(v, axis=1)
    speed[:-1] = np.maximum(speed[:-1], np.linalg.norm(np.diff(p, axis=0), axis=1)
                            / MOTION_CHECK_STEP_S)     # a jump counts as its mean speed
    if np.any(speed > MAX_SPEED_MPS):
        i = int(np.argmax(speed > MAX_SPEED_MPS))
        raise ValueError(f"{what}: speed {speed[i]:.0f} m/s at u = {u[i]:.3f} s exceeds "
                         f"{MAX_SPEED_MPS:g} m/s (the escape speed: no receiver that fast "
                         f"stays near the Earth)")
    acc = np.linalg.norm(np.diff(v, axis=0), axis=1) / MOTION_CHECK_STEP_S
    if np.any(acc > MAX_ACCEL_MPS2):
        i = int(np.argmax(acc > MAX_ACCEL_MPS2))
        raise ValueError(f"{what}: acceleration {acc[i]:.0f} m/s^2 at u = {u[i]:.3f} s "
                         f"exceeds {MAX_ACCEL_MPS2:g} m/s^2 (100 g)")
    fd = np.diff(p, axis=0) / MOTION_CHECK_STEP_S
    vm = 0.5 * (v[1:] + v[:-1])
    err = np.linalg.norm(fd - vm, axis=1)
    tol = MOTION_VELOCITY_TOL_MPS + 1e-6 * np.linalg.norm(vm, axis=1)
    if np.any(err > tol):
        i = int(np.argmax(err > tol))
        raise ValueError(f"{what}: velocity is not the derivative of position at u = "
                         f"{u[i]:.3f} s (they differ by {err[i]:.3g} m/s)")


@dataclass(frozen=True)
class ReceiverClock:
    """Receiver clock error ``dt_r(s) = bias_s + drift + oscillator x(s)`` (module notes):
    ``bias_s`` (|.| <= 1 s), ``drift_s_s`` (|.| <= 1e-4), ``oscillator`` None (ideal),
    ``"tcxo"``, ``"ocxo"`` or a :class:`dsp.gnss.oscillator.Oscillator`, on a grid of
    ``step_s``."""

    bias_s: float = 0.0
    drift_s_s: float = 0.0
    oscillator: object = None
    step_s: float = 1e-3

    def __post_init__(self):
        if not abs(_finite("clock bias_s", self.bias_s)) <= 1.0:
            raise ValueError(f"clock bias_s must be within +-1 s, not {self.bias_s!r}")
        if not abs(_finite("clock drift_s_s", self.drift_s_s)) <= 1e-4:
            raise ValueError(f"clock drift_s_s must be within +-1e-4, not {self.drift_s_s!r}")
        oscillator_model(self.oscillator)
        if not _finite("clock step_s", self.step_s) > 0:
            raise ValueError(f"clock step_s must be > 0, not {self.step_s!r}")


class ClockRealisation:
    """A realised :class:`ReceiverClock` over ``[0, duration_s]`` of receiver time (plus a
    margin): ``c dt_r`` (m) on its grid, evaluated linearly."""

    def __init__(self, clock: ReceiverClock, duration_s: float, rng: np.random.Generator):
        self.step_s = float(clock.step_s)
        n = int(math.ceil(duration_s / self.step_s)) + 2
        osc = oscillator_model(clock.oscillator)
        x = np.zeros(n + 1) if osc is None else clock_error_s(osc, n, self.step_s, rng)
        s = np.arange(n + 1) * self.step_s
        #: c dt_r on the grid (m)
        self.cdt_m = C_LIGHT * (clock.bias_s + clock.drift_s_s * s + x)

    def at(self, s):
        """``(dt_r (s), drift (s/s))`` at receiver times ``s`` (the slope of the grid
        interval holding ``s``)."""
        s = np.asarray(s, dtype=np.float64)
        u = s / self.step_s
        k = np.clip(np.floor(u).astype(np.int64), 0, self.cdt_m.size - 2)
        a, b = self.cdt_m[k], self.cdt_m[k + 1]
        return (a + (u - k) * (b - a)) / C_LIGHT, (b - a) / (self.step_s * C_LIGHT)


@dataclass(frozen=True)
class Cn0Model:
    """C/N0 by elevation: ``C/N0(el) = zenith_dbhz - horizon_loss_db (1 - sin el)`` (dB-Hz):
    the zenith value overhead, ``horizon_loss_db`` less at the horizon (an antenna gain
    roll-off and the longer path, lumped)."""

    zenith_dbhz: float = 47.0
    horizon_loss_db: float = 10.0

    def __post_init__(self):
        if not 10.0 <= _finite("zenith_dbhz", self.zenith_dbhz) <= 80.0:
            raise ValueError(f"zenith_dbhz must be in [10, 80] dB-Hz, not {self.zenith_dbhz!r}")
        if not 0.0 <= _finite("horizon_loss_db", self.horizon_loss_db) <= 40.0:
            raise ValueError(f"horizon_loss_db must be in [0, 40] dB, not "
                             f"{self.horizon_loss_db!r}")

    def __call__(self, el_deg):
        return self.zenith_dbhz - self.horizon_loss_db * (1.0 - np.sin(np.radians(el_deg)))


class Geometry(NamedTuple):
    """The scenario at receiver times ``s`` (T,) for S satellites (arrays (T, S) unless
    noted). Ranges in metres, times in seconds (``t`` and ``t_tx`` GPS seconds of the week
    of ``tow0``), rates per second of receiver time."""

    s: np.ndarray                 # (T,)
    t: np.ndarray                 # (T,) true GPS time of reception
    rx_pos: np.ndarray            # (T, 3)
    rx_vel: np.ndarray            # (T, 3)
    rx_llh: tuple                 # (lat deg, lon deg, h m), each (T,)
    clock_bias_s: np.ndarray      # (T,) dt_r
    clock_drift: np.ndarray       # (T,)
    tau: np.ndarray               # geometric travel time
    t_tx: np.ndarray              # geometric transmission time t - tau
    range_m: np.ndarray           # c tau (the geometric range, Sagnac included)
    range_rate: np.ndarray        # d(c tau)/ds
    sv_pos: np.ndarray            # (T, S, 3) at t_tx, ECEF frame of t
    sv_clock_s: np.ndarray        # dt_sv(t_tx) (relativistic term, -TGD)
    sv_clock_rate: np.ndarray     # d dt_sv / ds
    elevation_deg: np.ndarray
    azimuth_deg: np.ndarray


def light_time(ephs, t, rx_pos, rx_vel):
    """``tau``, ``dtau/dt``, the satellite state at ``t - tau`` (ECEF frame of ``t``) for
    reception times ``t`` (T,) at ``rx_pos``/``rx_vel`` (T, 3) (module notes)."""
    tau = np.full((t.size, len(ephs)), 0.075)
    for _ in range(12):
        st = satellite_states(ephs, t[:, None] - tau)
        pos = sagnac_rotate(st.position, tau)
        new = np.linalg.norm(pos - rx_pos[:, None, :], axis=-1) / C_LIGHT
        done = np.max(np.abs(new - tau)) <= 1e-15
        tau = new
        if done:
            break
    st = satellite_states(ephs, t[:, None] - tau)
    pos, vel = sagnac_rotate(st.position, tau, st.velocity)
    d = pos - rx_pos[:, None, :]
    e = d / np.linalg.norm(d, axis=-1, keepdims=True)
    a = np.sum(e * (vel - rx_vel[:, None, :]), axis=-1)
    turn = OMEGA_E_DOT * np.stack([pos[..., 1], -pos[..., 0], np.zeros(pos.shape[:-1])], -1)
    b = np.sum(e * (turn - vel), axis=-1)
    return tau, a / (C_LIGHT - b), pos, st


def geometry(ephs, tow0: float, receiver, clock: ClockRealisation, s) -> Geometry:
    """The :class:`Geometry` of satellites ``ephs`` at receiver times ``s`` (module notes)."""
    s = np.atleast_1d(np.asarray(s, dtype=np.float64))
    dtr, drift = clock.at(s)
    u = s - dtr
    t = tow0 + u
    rx, vrx = receiver.state(u)
    tau, tau_dot, pos, st = light_time(ephs, t, rx, vrx)
    dt_ds = (1.0 - drift)[:, None]
    lat, lon, h = pymap3d.ecef2geodetic(rx[:, 0], rx[:, 1], rx[:, 2])
    az, el, _ = pymap3d.ecef2aer(pos[..., 0], pos[..., 1], pos[..., 2], lat[:, None],
                                 lon[:, None], h[:, None])
    return Geometry(s=s, t=t, rx_pos=rx, rx_vel=vrx, rx_llh=(lat, lon, h), clock_bias_s=dtr,
                    clock_drift=drift, tau=tau, t_tx=t[:, None] - tau, range_m=C_LIGHT * tau,
                    range_rate=C_LIGHT * tau_dot * dt_ds, sv_pos=pos,
                    sv_clock_s=st.clock_bias,
                    sv_clock_rate=st.clock_drift * (1.0 - tau_dot) * dt_ds,
                    elevation_deg=el, azimuth_deg=az)


def atmosphere(g: Geometry, iono, tropo):
    """``(I, T)``: the L1 ionospheric group delay and tropospheric delay (m, (T, S)) of the
    pluggable models, zero when a model is None. ``iono(lat_deg, lon_deg, az_deg, el_deg,
    tow_s)`` and ``tropo(el_deg, h_m)`` are called with arrays broadcast to (T, S) and must
    return finite metres of that shape."""
    shape = g.range_m.shape
    lat, lon, h = (np.broadcast_to(x[:, None], shape) for x in g.rx_llh)
    out = []
    for name, f, args in (("iono", iono, (lat, lon, g.azimuth_deg, g.elevation_deg,
                                          np.broadcast_to(g.t[:, None], shape))),
                          ("tropo", tropo, (g.elevation_deg, h))):
        if f is None:
            out.append(np.zeros(shape))
            continue
        v = np.asarray(f(*args), dtype=np.float64)
        if v.shape != shape or not np.all(np.isfinite(v)):
            raise ValueError(f"the {name} model returned {v.shape} values (finite: "
                             f"{bool(np.all(np.isfinite(v)))}), expected finite metres of "
                             f"shape {shape}")
        out.append(v)
    return out[0], out[1]
