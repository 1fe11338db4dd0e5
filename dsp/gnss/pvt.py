"""GPS single-point position, velocity and time (PVT) from one epoch of measurements.

Float64 throughout, not fixed point: the solution spans ranges of 2.6e7 m to millimetres
(45 bits of dynamic range before any product), its normal equations are inverted and
iterated, and it runs once per measurement epoch (1-10 Hz) on the DSP's general-purpose
side, not in the per-sample or per-millisecond loops that the fixed-point kernels serve.

Inputs per epoch, one row per satellite (arrays, so the PVT does not depend on where the
satellite states come from): ECEF position (m) and velocity (m/s) of each satellite at its
time of transmission, in the ECEF frame of that instant (not corrected for the Earth's
rotation during the travel time: :func:`solve` does it); its clock offset ``dt_s`` (s), the
``Delta t_sv`` of IS-GPS-200 20.3.3.3.3.1 (``t_GPS = t_sv - dt_s``; relativistic term and
group delay included by the caller) and its drift (s/s); the pseudorange ``P`` (m); the Doppler ``D`` (Hz,
positive for an approaching satellite) or the pseudorange rate (m/s); C/N0 (dB-Hz).

Measurement models (``b = c dt_r`` the receiver clock bias, ``b' = c d(dt_r)/dt`` its
drift, both in metres and m/s; ``R(a)`` the rotation of ECEF about z by ``a``):

* ``P_i = |R(w_E tau_i) r_i - r| + b - c dt_s,i + I_i + T_i + e_i``, with the travel time
  ``tau_i = |R(w_E tau_i) r_i - r| / c`` re-solved in every iteration (the Sagnac, or Earth
  rotation, correction: the satellite's position is rotated into the ECEF frame of the
  reception instant), ``I_i`` the Klobuchar ionosphere and ``T_i`` the Saastamoinen
  troposphere (``dsp.gnss.atmosphere``, both optional).
* ``-lambda_L1 D_i = u_i . (R v_i - v) + b' - c ddt_s,i`` with ``u_i`` the receiver-to-satellite
  unit vector in the rotated frame.

Position and clock bias: iterated (Gauss-Newton) weighted least squares from the Earth's
centre until the update is below ``tol_m``. Velocity and drift: the linear weighted least
squares of the rate equations at the final position, same satellites, same weights.

Weights (the stated model): the pseudorange standard deviation of satellite ``i`` is
``sigma_i = sigma_0 * 10^((cn0_ref - cn0_i) / 20) / sin(max(el_i, el_floor))``: the code
tracking noise scales with ``1/sqrt(C/N0)`` (thermal noise of the delay-lock loop) and the
multipath and atmosphere residuals grow as ``1/sin el``; ``W = diag(1/sigma_i^2)``. Without
C/N0 the first factor is 1. Elevations come from the current estimate (pymap3d); until it is
near the Earth's surface they are taken as 90 degrees and no atmosphere is applied.

Integrity (RAIM-style): the weighted sum of squared residuals ``SSE = sum r_i^2/sigma_i^2``
is chi-square with ``n - 4`` degrees of freedom when the ``sigma_i`` are right; the test
fails when it exceeds the ``1 - p_fa`` quantile. The satellite with the largest
standardised residual ``|r_i| / sqrt((C - H (H^T W H)^-1 H^T)_ii)`` (``C = W^-1``) is then
excluded and the solution and test repeated, as long as at least 5 satellites would remain
(fewer cannot be tested). Fewer than 4 usable satellites: no fix, NaN position, a status
saying so.

DOPs: from the unweighted geometry in the local east-north-up frame,
``Q = (G^T G)^-1`` with rows ``G_i = [-e_i, -n_i, -u_i, 1]`` the line-of-sight unit vectors
(pymap3d azimuth / elevation); ``GDOP = sqrt(tr Q)``, ``PDOP = sqrt(Q_ee + Q_nn + Q_uu)``,
``HDOP = sqrt(Q_ee + Q_nn)``, ``VDOP = sqrt(Q_uu)``, ``TDOP = sqrt(Q_tt)``.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
import pymap3d

from .ephemeris import C_LIGHT, L1_WAVELENGTH_M, OMEGA_E_DOT
from .atmosphere import (TROPO_HEIGHT_RANGE_M, TROPO_MIN_ELEVATION_DEG,
                         klobuchar_delay_m, saastamoinen_delay_m)

#: Heights (m) between which an estimate counts as near the surface (elevations, atmosphere).
SURFACE_HEIGHT_RANGE_M = (-5_000.0, 100_000.0)


class PvtStatus(str, enum.Enum):
    """What a :class:`PvtSolution` is."""

    FIX = "fix"                                  #: >= 5 satellites, residual test passed
    FIX_EXCLUDED = "fix_fault_excluded"          #: a faulty satellite excluded, the rest passed
    FIX_UNCHECKED = "fix_unchecked"              #: exactly 4 satellites: no residual test
    FAULT_DETECTED = "fault_detected"            #: the test failed and nothing can be excluded
    NO_FIX_TOO_FEW = "no_fix_too_few_satellites"  #: fewer than 4 usable satellites
    NO_FIX_GEOMETRY = "no_fix_singular_geometry"  #: the normal equations are singular
    NO_FIX_DIVERGED = "no_fix_not_converged"     #: no convergence in ``max_iterations``


#: The statuses whose position is a fix to use.
VALID = (PvtStatus.FIX, PvtStatus.FIX_EXCLUDED, PvtStatus.FIX_UNCHECKED)


@dataclass(frozen=True)
class PvtConfig:
    """Solver settings (module doc for the models)."""

    sigma0_m: float = 3.0            #: pseudorange sigma at ``cn0_ref_dbhz`` and zenith
    cn0_ref_dbhz: float = 45.0
    elevation_floor_deg: float = 5.0  #: lowest elevation the weight model uses
    elevation_mask_deg: float = 5.0  #: satellites below it are not used
    p_false_alarm: float = 1e-5      #: of the residual test, per epoch
    max_iterations: int = 20
    tol_m: float = 1e-6              #: convergence: norm of the position + bias update
    raim: bool = True

    def __post_init__(self):
        if not (self.sigma0_m > 0 and 0 < self.p_false_alarm < 1 and self.tol_m > 0
                and self.max_iterations >= 1 and 0 < self.elevation_floor_deg <= 90
                and -90 <= self.elevation_mask_deg < 90):
            raise ValueError(f"invalid PvtConfig: {self}")


@dataclass(frozen=True)
class Dop:
    """Dilutions of precision (unweighted, ENU)."""

    gdop: float
    pdop: float
    hdop: float
    vdop: float
    tdop: float

    @classmethod
    def nan(cls) -> "Dop":
        return cls(*(np.nan,) * 5)


@dataclass(frozen=True)
class PvtSolution:
    """One epoch's solution. Positions and velocities are NaN when there is no fix."""

    status: PvtStatus
    message: str
    position_ecef_m: np.ndarray
    lat_deg: float
    lon_deg: float
    height_m: float                 #: above the WGS-84 ellipsoid
    velocity_ecef_mps: np.ndarray
    velocity_enu_mps: np.ndarray
    clock_bias_m: float             #: ``c dt_r``
    clock_drift_mps: float          #: ``c d(dt_r)/dt``
    dop: Dop
    used_prns: tuple
    excluded_prns: tuple            #: excluded by the residual test
    unusable_prns: tuple            #: non-finite inputs or below the elevation mask
    residuals_m: np.ndarray         #: pseudorange residuals of ``used_prns``
    sigmas_m: np.ndarray            #: their weight-model sigmas
    elevation_deg: np.ndarray
    azimuth_deg: np.ndarray
    test_statistic: float           #: SSE of the final set (NaN without redundancy)
    test_threshold: float
    covariance_m2: np.ndarray       #: ``(H^T W H)^-1`` of x, y, z, b (ECEF, m^2)
    iterations: int                 #: Gauss-Newton iterations, all solves added up
    gps_week: int | None = None
    gps_tow_s: float | None = None  #: GPS time of the fix: receiver time - ``b / c``
    corrections: tuple = field(default_factory=tuple)

    @property
    def valid(self) -> bool:
        return self.status in VALID

    @property
    def clock_bias_s(self) -> float:
        return self.clock_bias_m / C_LIGHT

    @property
    def clock_drift_s_per_s(self) -> float:
        return self.clock_drift_mps / C_LIGHT


def pseudorange_sigma_m(cn0_dbhz, elevation_deg, config: PvtConfig = PvtConfig()):
    """The weight model's pseudorange standard deviation (m) (module doc)."""
    el = np.maximum(np.asarray(elevation_deg, dtype=np.float64), config.elevation_floor_deg)
    s = config.sigma0_m / np.sin(np.deg2rad(el))
    if cn0_dbhz is not None:
        s = s * 10.0 ** ((config.cn0_ref_dbhz - np.asarray(cn0_dbhz, dtype=np.float64)) / 20.0)
    return s


def rotate_z(vectors, angle_rad):
    """Rows of ``vectors`` (n, 3) expressed in an ECEF frame that has turned by ``angle_rad``
    (per row) about z since: ``R(a) = [[cos a, sin a, 0], [-sin a, cos a, 0], [0, 0, 1]]``."""
    v = np.asarray(vectors, dtype=np.float64)
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], v[:, 2]])


def enu_geometry(elevation_deg, azimuth_deg) -> np.ndarray:
    """The rows ``G_i = [-e_i, -n_i, -u_i, 1]`` of the module doc (n, 4): the pseudorange's
    partial derivatives in east, north, up and the clock bias."""
    el = np.deg2rad(np.asarray(elevation_deg, dtype=np.float64))
    az = np.deg2rad(np.asarray(azimuth_deg, dtype=np.float64))
    return np.column_stack([-np.cos(el) * np.sin(az), -np.cos(el) * np.cos(az), -np.sin(el),
                            np.ones_like(el)])


def dop_enu(elevation_deg, azimuth_deg) -> Dop:
    """DOPs of satellites at these elevations / azimuths (module doc); NaN if singular."""
    el = np.asarray(elevation_deg)
    g = enu_geometry(elevation_deg, azimuth_deg)
    try:
        q = np.linalg.inv(g.T @ g)
    except np.linalg.LinAlgError:
        return Dop.nan()
    d = np.diag(q)
    if len(el) < 4 or np.any(d < 0):
        return Dop.nan()
    return Dop(float(np.sqrt(d.sum())), float(np.sqrt(d[:3].sum())),
               float(np.sqrt(d[:2].sum())), float(np.sqrt(d[2])), float(np.sqrt(d[3])))


def _col(name, a, n, dims=1):
    a = np.asarray(a, dtype=np.float64)
    want = (n,) if dims == 1 else (n, 3)
    if a.shape != want:
        raise ValueError(f"{name} must have shape {want}, not {a.shape}")
    return a


def _az_el(sat_ecef, llh):
    az, el, _ = pymap3d.ecef2aer(sat_ecef[:, 0], sat_ecef[:, 1], sat_ecef[:, 2], *llh)
    return np.asarray(az, dtype=np.float64), np.asarray(el, dtype=np.float64)


def _near_surface(x):
    if not np.all(np.isfinite(x)) or np.linalg.norm(x) < 1e6:
        return None
    lat, lon, h = pymap3d.ecef2geodetic(*x)
    lo, hi = SURFACE_HEIGHT_RANGE_M
    return (float(lat), float(lon), float(h)) if lo <= h <= hi else None


@dataclass
class _Problem:
    """The satellites of one solve and the corrections asked for."""

    pos: np.ndarray
    clk_m: np.ndarray
    pr: np.ndarray
    cn0: np.ndarray | None
    tow: float | None
    alpha: np.ndarray | None
    beta: np.ndarray | None
    tropo: bool
    cfg: PvtConfig


@dataclass
class _Wls:
    x: np.ndarray
    rot: np.ndarray          # satellite positions in the reception frame
    tau: np.ndarray
    el: np.ndarray
    az: np.ndarray
    sigma: np.ndarray
    h: np.ndarray
    resid: np.ndarray
    cov: np.ndarray
    iterations: int
    corrections: tuple


def _geometry(prob, x, tau):
    rot = rotate_z(prob.pos, OMEGA_E_DOT * tau)
    los = rot - x[:3]
    rng = np.linalg.norm(los, axis=1)
    return rot, los, rng


def _atmosphere(prob, llh, el, az):
    """Delays (m) and the names of the corrections applied at ``llh``."""
    d, names = np.zeros(len(el)), []
    if llh is None:
        return d, ()
    lat, lon, h = llh
    if prob.alpha is not None and np.all(el >= 0):
        d = d + klobuchar_delay_m(lat, lon, el, az, prob.tow, prob.alpha, prob.beta)
        names.append("klobuchar")
    lo, hi = TROPO_HEIGHT_RANGE_M
    if prob.tropo and lo <= h <= hi and np.all(el >= TROPO_MIN_ELEVATION_DEG):
        d = d + saastamoinen_delay_m(lat, h, el)
        names.append("saastamoinen")
    return d, tuple(names)


def _wls(prob: _Problem, x0) -> _Wls | tuple:
    """The converged solve, or (status, iterations) when there is none."""
    n = len(prob.pr)
    x = np.array(x0, dtype=np.float64)
    tau = np.full(n, 0.075)
    for it in range(1, prob.cfg.max_iterations + 1):
        for _ in range(2):                   # the travel time: a fast contraction
            rot, los, rng = _geometry(prob, x, tau)
            tau = rng / C_LIGHT
        llh = _near_surface(x[:3])
        if llh is None:
            el, az = np.full(n, 90.0), np.zeros(n)
        else:
            az, el = _az_el(rot, llh)
        delay, names = _atmosphere(prob, llh, el, az)
        sigma = pseudorange_sigma_m(prob.cn0, el, prob.cfg)
        w = 1.0 / sigma ** 2
        h = np.column_stack([-los / rng[:, None], np.ones(n)])
        resid = prob.pr + prob.clk_m - delay - (rng + x[3])
        normal = h.T @ (w[:, None] * h)
        try:
            cov = np.linalg.inv(normal)
        except np.linalg.LinAlgError:
            return PvtStatus.NO_FIX_GEOMETRY, it
        if not np.all(np.isfinite(cov)) or np.linalg.cond(normal) > 1e14:
            return PvtStatus.NO_FIX_GEOMETRY, it
        dx = cov @ (h.T @ (w * resid))
        x = x + dx
        if np.linalg.norm(dx) < prob.cfg.tol_m:
            resid = resid - h @ dx            # the residuals at the final estimate
            return _Wls(x, rot, tau, el, az, sigma, h, resid, cov, it, names)
    return PvtStatus.NO_FIX_DIVERGED, prob.cfg.max_iterations


def _standardised(sol: _Wls):
    c = np.diag(sol.sigma ** 2)
    qr = c - sol.h @ sol.cov @ sol.h.T
    return np.abs(sol.resid) / np.sqrt(np.clip(np.diag(qr), 1e-30, None))


def _subset(prob: _Problem, keep):
    return _Problem(prob.pos[keep], prob.clk_m[keep], prob.pr[keep],
                    None if prob.cn0 is None else prob.cn0[keep], prob.tow, prob.alpha,
                    prob.beta, prob.tropo, prob.cfg)


def _no_fix(status, message, unusable, iterations, week, tow):
    nan3 = np.full(3, np.nan)
    return PvtSolution(status, message, nan3, np.nan, np.nan, np.nan, nan3.copy(),
                       nan3.copy(), np.nan, np.nan, Dop.nan(), (), (), tuple(unusable),
                       np.empty(0), np.empty(0), np.empty(0), np.empty(0), np.nan, np.nan,
                       np.full((4, 4), np.nan), iterations, week, tow)


def _rates(prr, sat_vel, sat_drift, sol: _Wls, w):
    """Velocity (ECEF) and clock drift (m/s) from the range rates at the solution, or
    NaNs with the reason."""
    ok = np.isfinite(prr) & np.all(np.isfinite(sat_vel), axis=1) & np.isfinite(sat_drift)
    if ok.sum() < 4:
        return np.full(3, np.nan), np.nan, f"no velocity: {ok.sum()} satellites with rates"
    vel = rotate_z(sat_vel[ok], OMEGA_E_DOT * sol.tau[ok])
    u = -sol.h[ok, :3]                                   # receiver -> satellite
    y = prr[ok] + C_LIGHT * sat_drift[ok] - np.einsum("ij,ij->i", u, vel)
    h = sol.h[ok]
    normal = h.T @ (w[ok, None] * h)
    try:
        v = np.linalg.solve(normal, h.T @ (w[ok] * y))
    except np.linalg.LinAlgError:
        return np.full(3, np.nan), np.nan, "no velocity: singular geometry"
    return v[:3], float(v[3]), ""


def solve(prns, sat_pos_m, sat_clock_s, pseudorange_m, *, cn0_dbhz=None, sat_vel_mps=None,
          sat_clock_drift=None, doppler_hz=None, pseudorange_rate_mps=None,
          gps_week: int | None = None, gps_tow_s: float | None = None, iono_alpha=None,
          iono_beta=None, troposphere: bool = False, config: PvtConfig = PvtConfig(),
          x0=None) -> PvtSolution:
    """Position, velocity and clock of one epoch (module doc).

    ``prns`` (n,) distinct satellite numbers; ``sat_pos_m`` (n, 3) ECEF at transmission;
    ``sat_clock_s`` (n,) satellite clock offsets ``dt_s``; ``pseudorange_m`` (n,); optional
    ``cn0_dbhz`` (n,) for the weights; ``sat_vel_mps`` (n, 3), ``sat_clock_drift`` (n,, s/s)
    and either ``doppler_hz`` (n,) or ``pseudorange_rate_mps`` (n,) for the velocity;
    ``gps_week``, ``gps_tow_s`` the receiver time of the measurements (needed by the
    ionosphere; the fix's time is ``gps_tow_s - b / c``); ``iono_alpha``, ``iono_beta`` the
    Klobuchar coefficients (both or neither); ``troposphere`` applies Saastamoinen. A row
    with a non-finite input is not used and listed in ``unusable_prns``. Bad shapes and
    inconsistent options raise ``ValueError``.
    """
    cfg = config
    prn = np.asarray(prns)
    if prn.ndim != 1 or not np.issubdtype(prn.dtype, np.integer) or \
            len(np.unique(prn)) != len(prn):
        raise ValueError(f"prns must be distinct integers (1-D), not {prns!r}")
    n = len(prn)
    pos = _col("sat_pos_m", sat_pos_m, n, 3)
    clk = _col("sat_clock_s", sat_clock_s, n)
    pr = _col("pseudorange_m", pseudorange_m, n)
    cn0 = None if cn0_dbhz is None else _col("cn0_dbhz", cn0_dbhz, n)
    if (iono_alpha is None) != (iono_beta is None):
        raise ValueError("iono_alpha and iono_beta go together")
    if iono_alpha is not None and (gps_tow_s is None or not np.isfinite(gps_tow_s)):
        raise ValueError("the ionosphere model needs gps_tow_s")
    if doppler_hz is not None and pseudorange_rate_mps is not None:
        raise ValueError("give doppler_hz or pseudorange_rate_mps, not both")
    prr = None
    if doppler_hz is not None:
        prr = -L1_WAVELENGTH_M * _col("doppler_hz", doppler_hz, n)
    elif pseudorange_rate_mps is not None:
        prr = _col("pseudorange_rate_mps", pseudorange_rate_mps, n)
    if prr is not None and (sat_vel_mps is None or sat_clock_drift is None):
        raise ValueError("a velocity needs sat_vel_mps and sat_clock_drift with the rates")
    vel = None if prr is None else _col("sat_vel_mps", sat_vel_mps, n, 3)
    drift = None if prr is None else _col("sat_clock_drift", sat_clock_drift, n)
    alpha = None if iono_alpha is None else np.asarray(iono_alpha, dtype=np.float64)
    beta = None if iono_beta is None else np.asarray(iono_beta, dtype=np.float64)

    finite = np.all(np.isfinite(pos), axis=1) & np.isfinite(clk) & np.isfinite(pr)
    if cn0 is not None:
        finite &= np.isfinite(cn0)
    unusable = [int(p) for p in prn[~finite]]
    idx = np.flatnonzero(finite)
    full = _Problem(pos, clk * C_LIGHT, pr, cn0, gps_tow_s, alpha, beta,
                    bool(troposphere), cfg)
    x = np.zeros(4) if x0 is None else _col("x0", x0, 4)
    iterations, excluded, notes = 0, [], []

    def too_few():
        return _no_fix(PvtStatus.NO_FIX_TOO_FEW,
                       f"{len(idx)} usable satellites, a fix needs 4", unusable,
                       iterations, gps_week, gps_tow_s)

    while True:                                  # solve; drop satellites below the mask
        if len(idx) < 4:
            return too_few()
        sol = _wls(_subset(full, idx), x)
        if isinstance(sol, tuple):
            return _no_fix(sol[0], f"{sol[0].value} with {len(idx)} satellites", unusable,
                           iterations + sol[1], gps_week, gps_tow_s)
        iterations += sol.iterations
        x = sol.x
        low = sol.el < cfg.elevation_mask_deg
        if _near_surface(x[:3]) is None or not low.any():
            break
        unusable += [int(p) for p in prn[idx[low]]]
        notes.append(f"below the {cfg.elevation_mask_deg:g} deg mask: "
                     f"{[int(p) for p in prn[idx[low]]]}")
        idx = idx[~low]

    status = PvtStatus.FIX_UNCHECKED if len(idx) == 4 else PvtStatus.FIX
    stat, thr = np.nan, np.nan
    while cfg.raim and len(idx) >= 5:
        dof = len(idx) - 4
        stat = float(np.sum((sol.resid / sol.sigma) ** 2))
        from scipy.stats import chi2      # here: a command's refusals need no scipy.stats
        thr = float(chi2.isf(cfg.p_false_alarm, dof))
        if stat <= thr:
            break
        if len(idx) - 1 < 5:
            status = PvtStatus.FAULT_DETECTED
            notes.append(f"residual test failed (SSE {stat:.1f} > {thr:.1f}); "
                         f"{len(idx)} satellites leave none to exclude")
            break
        worst = int(np.argmax(_standardised(sol)))
        excluded.append(int(prn[idx[worst]]))
        notes.append(f"residual test failed (SSE {stat:.1f} > {thr:.1f}): "
                     f"PRN {excluded[-1]} excluded")
        idx = np.delete(idx, worst)
        sol2 = _wls(_subset(full, idx), x)
        if isinstance(sol2, tuple):
            return _no_fix(sol2[0], f"{sol2[0].value} after excluding {excluded}",
                           unusable, iterations + sol2[1], gps_week, gps_tow_s)
        sol, x = sol2, sol2.x
        iterations += sol.iterations
        status = PvtStatus.FIX_EXCLUDED

    lat, lon, h = (float(v) for v in pymap3d.ecef2geodetic(*x[:3]))
    az, el = _az_el(sol.rot, (lat, lon, h))       # at the final position, whatever its height
    v_ecef, drift_mps = np.full(3, np.nan), np.nan
    if prr is None:
        notes.append("no velocity: no Doppler or range rates")
    else:
        v_ecef, drift_mps, why = _rates(prr[idx], vel[idx], drift[idx], sol,
                                        1.0 / sol.sigma ** 2)
        if why:
            notes.append(why)
    v_enu = np.array(pymap3d.ecef2enuv(*v_ecef, lat, lon), dtype=np.float64)
    asked = (("klobuchar",) if alpha is not None else ()) + \
        (("saastamoinen",) if troposphere else ())
    missing = [a for a in asked if a not in sol.corrections]
    if missing:
        notes.append(f"not applied at this position / geometry: {missing}")
    used = tuple(int(p) for p in prn[idx])
    message = "; ".join([f"{status.value}: {len(used)} satellites"] + notes)
    tow = None if gps_tow_s is None else float(gps_tow_s) - x[3] / C_LIGHT
    return PvtSolution(status, message, x[:3].copy(), lat, lon, h, v_ecef, v_enu,
                       float(x[3]), drift_mps, dop_enu(el, az), used,
                       tuple(excluded), tuple(unusable), sol.resid, sol.sigma, el,
                       az, stat, thr, sol.cov, iterations, gps_week, tow,
                       sol.corrections)
