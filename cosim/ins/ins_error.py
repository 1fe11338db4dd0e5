"""INS error model along the INS paper's trajectory, and the INS-predicted Doppler rate.

A documented simplification of strapdown navigation over 150 s (the Schuler period is
84 min, so the gravity feedback of position error is left out: < 0.1 % of the error over
the run): the INS's navigation-frame specific force is the true one seen through a
misalignment ``psi(t)`` that grows from the gyro drift, plus the accelerometer bias and
white noise,

    f_ins = f - psi x f + b_a + w_a,     psi(t) = eps t + int w_g dt,     f = a + g up,

so the INS acceleration error is ``da = -psi x f + b_a + w_a`` (local east-north-up,
taken fixed along the track: the straight line spans < 1.3 km / 6378 km of arc, and the
frame of :mod:`cosim.ins.trajectory` holds it fixed); the velocity and position errors
are its integrals (trapezoid on the epoch grid). The INS paper's values: gyro drift 10
deg/h on every axis, accelerometer bias 1 mg on every axis; noise: angle random
walk 0.1 deg/sqrt(h) and velocity random walk 0.05 m/s/sqrt(h) by default (tactical grade;
the paper gives none). 1 mg alone is 0.0515 Hz/s of Doppler rate on the line of sight; the
drift's misalignment times the 50 g specific force dominates during the manoeuvre.

The aiding the loops get, :meth:`InsAiding.rate_hz_s`, is the Doppler-rate formula of
:func:`cosim.ins.trajectory.doppler_rate_hz_s` evaluated on the INS's position, velocity
and acceleration and the satellite's (broadcast ephemeris: exact here), at the midpoint of
each epoch.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .trajectory import G_MPS2, Scenario, doppler_rate_hz_s

DEG_PER_H = math.pi / 180.0 / 3600.0


@dataclass(frozen=True)
class InsErrors:
    """INS sensor errors (the INS paper's values by default).

    Parameters
    ----------
    gyro_drift_deg_h : float
        Gyro bias on each axis (deg/h), >= 0.
    accel_bias_mg : float
        Accelerometer bias on each axis (milli-g), >= 0.
    arw_deg_rt_h : float
        Gyro angle random walk (deg/sqrt(h)), >= 0.
    vrw_mps_rt_h : float
        Accelerometer velocity random walk (m/s/sqrt(h)), >= 0.
    signs : tuple of 3 floats
        Sign (or scale) of the biases on east, north, up.
    """

    gyro_drift_deg_h: float = 10.0
    accel_bias_mg: float = 1.0
    arw_deg_rt_h: float = 0.1
    vrw_mps_rt_h: float = 0.05
    signs: tuple = (1.0, -1.0, 1.0)

    def __post_init__(self):
        for k in ("gyro_drift_deg_h", "accel_bias_mg", "arw_deg_rt_h", "vrw_mps_rt_h"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"{k} must be a finite number >= 0, not {v!r}")
        if len(self.signs) != 3 or not all(math.isfinite(float(s)) for s in self.signs):
            raise ValueError(f"signs must be 3 finite numbers, not {self.signs!r}")


def acceleration_error_enu(f_enu, T_s: float, errors: InsErrors, seed: int) -> np.ndarray:
    """The INS acceleration error ``da = -psi x f + b_a + w_a`` (3, n) (local east, north,
    up; module doc) for the specific force ``f_enu`` (3, n) on a uniform grid of step
    ``T_s`` (s) starting at ``T_s / 2``; ``seed`` draws the angle and velocity random walks."""
    f_enu = np.asarray(f_enu, float)
    n = f_enu.shape[1]
    t = (np.arange(n) + 0.5) * T_s
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(7,)))
    sg = np.asarray(errors.signs, float)
    eps = errors.gyro_drift_deg_h * DEG_PER_H * sg
    arw = errors.arw_deg_rt_h * math.pi / 180.0 / 60.0          # rad/sqrt(s)
    vrw = errors.vrw_mps_rt_h / 60.0                            # m/s/sqrt(s)
    psi = eps[:, None] * t + np.cumsum(rng.standard_normal((3, n)) * arw * math.sqrt(T_s), axis=1)
    ba = errors.accel_bias_mg * 1e-3 * G_MPS2 * sg
    wa = rng.standard_normal((3, n)) * vrw / math.sqrt(T_s)
    return -np.cross(psi.T, f_enu.T).T + ba[:, None] + wa


def integrate_errors(da, T_s: float):
    """Velocity and position errors ``(dv, dp)`` (3, n): the acceleration error ``da``
    integrated twice (trapezoid, grid step ``T_s``, zero at the first point)."""
    dv = np.concatenate([np.zeros((3, 1)), np.cumsum((da[:, 1:] + da[:, :-1]) / 2 * T_s, axis=1)], axis=1)
    dp = np.concatenate([np.zeros((3, 1)), np.cumsum((dv[:, 1:] + dv[:, :-1]) / 2 * T_s, axis=1)], axis=1)
    return dv, dp


class InsAiding:
    """The INS solution along a :class:`Scenario` and its Doppler-rate prediction.

    Parameters
    ----------
    scenario : Scenario
    errors : InsErrors
    T_s : float
        Epoch (s): the aiding is given at every epoch's midpoint.
    n_epochs : int
    seed : int
        Draws the sensor noise.
    """

    def __init__(self, scenario: Scenario, errors: InsErrors | None = None, T_s: float = 1e-3,
                 n_epochs: int | None = None, seed: int = 0):
        if not (isinstance(T_s, (int, float)) and math.isfinite(T_s) and T_s > 0):
            raise ValueError(f"T_s must be a finite number > 0 s, not {T_s!r}")
        self.sc, self.err, self.T = scenario, errors or InsErrors(), float(T_s)
        n = int(round(scenario.traj.duration_s / self.T)) if n_epochs is None else int(n_epochs)
        if n < 1:
            raise ValueError(f"n_epochs must be >= 1, not {n}")
        self.n = n
        t = (np.arange(n) + 0.5) * self.T
        self.t = t
        Ru, Vu, Au = scenario.user(t)
        _, e, nn, up = scenario.geom.frame()
        C = np.stack([e, nn, up])                      # ENU -> frame rows
        f_enu = C @ Au + G_MPS2 * np.array([0.0, 0.0, 1.0])[:, None]
        da = C.T @ acceleration_error_enu(f_enu, self.T, self.err, seed)
        dv, dp = integrate_errors(da, self.T)
        self.da, self.dv, self.dp = da, dv, dp
        Rs, Vs, As = scenario.satellite(t)
        self.rate = doppler_rate_hz_s(Ru + dp, Vu + dv, Au + da, Rs, Vs, As)
        self.true_rate = doppler_rate_hz_s(Ru, Vu, Au, Rs, Vs, As)

    def rate_hz_s(self, k):
        """INS-predicted Doppler rate (Hz/s) at the midpoint of epoch ``k``."""
        return self.rate[k]

    __call__ = rate_hz_s

    def rate_at(self, t_s) -> np.ndarray:
        """INS-predicted Doppler rate (Hz/s) at any times ``t_s`` (s) inside the epoch grid:
        the INS errors interpolated linearly between the grid's midpoints, the formula on
        the INS position, velocity and acceleration there."""
        t = np.atleast_1d(np.asarray(t_s, float))
        if not np.all(np.isfinite(t)) or t.min() < self.t[0] or t.max() > self.t[-1]:
            raise ValueError(f"rate_at: times must lie in [{self.t[0]:g}, {self.t[-1]:g}] s "
                             f"(the INS solution's grid), not {t.min():g}..{t.max():g}")
        Ru, Vu, Au = self.sc.user(t)
        Rs, Vs, As = self.sc.satellite(t)
        e = [np.stack([np.interp(t, self.t, x[i]) for i in range(3)]) for x in (self.dp, self.dv, self.da)]
        return doppler_rate_hz_s(Ru + e[0], Vu + e[1], Au + e[2], Rs, Vs, As)


class EpochAiding:
    """The INS Doppler rate per tracked epoch when the epochs are not on a uniform grid
    (the HDL channel dumps on the received code's epochs, which drift from the receiver's
    millisecond by the code Doppler: ~3 ms over the paper's 150 s). ``aiding(k)`` is
    :meth:`InsAiding.rate_at` at the midpoint of epoch ``k``, ``boundaries_s[k]`` to
    ``boundaries_s[k + 1]`` (s, receiver time); past the table it raises."""

    def __init__(self, ins: InsAiding, boundaries_s):
        b = np.asarray(boundaries_s, float)
        if b.ndim != 1 or b.size < 2 or not np.all(np.diff(b) > 0):
            raise ValueError("boundaries_s must be >= 2 strictly increasing times")
        self.mid = (b[1:] + b[:-1]) / 2
        self.rate = ins.rate_at(self.mid)

    def __call__(self, k):
        if not 0 <= k < self.rate.size:
            raise ValueError(f"aiding asked for epoch {k}: the table holds epochs 0..{self.rate.size - 1}")
        return self.rate[k]
