"""Line-of-sight dynamics profiles for the GNSS signal generator.

A *profile* is a frozen specification (validated on construction); ``realise(duration_s,
rng)`` turns it into a :class:`Trajectory`, the line-of-sight range ``r(t)`` (m) and its
first three derivatives at any times. Only the jerk process draws from ``rng``.

Sign convention (used by the generator and its truth): the range grows when the satellite
recedes; the received carrier phase is ``-(r(t) - r(0)) / lambda`` cycles (plus the initial
phase), the carrier Doppler ``-r'(t) / lambda`` Hz, the Doppler rate ``-r''(t) / lambda``
Hz/s, ``lambda = c / L1``. A closing velocity of 1000 m/s is a Doppler of +5255.0 Hz.

Profiles
--------
* :class:`PolynomialProfile`: initial range, range rate and range acceleration, jerk
  segments (piecewise-constant jerk) and acceleration steps; :func:`constant` is its
  no-segment case.
* :class:`JerkProcess`: the AUKF patent's model (docs/explanation/gnss_aukf.md), on the
  carrier-phase state
  ``X = [theta rad, w0 rad/s, w1 rad/s^2, w2 rad/s^3]`` at L1:
  ``dtheta/dt = w0, dw0/dt = w1, dw1/dt = w2, dw2/dt = -alpha w2 + w``, ``w`` white with
  intensity ``q`` (rad^2/s^7), ``q = 2 alpha sigma_j^2``. It is propagated exactly
  (:func:`jerk_phi`, :func:`jerk_q`) on a grid of ``step_s``; between grid points the phase
  is the quintic Hermite interpolant of ``(theta, w0, w1)`` at both ends, so phase,
  frequency and frequency rate are continuous. The default ``x0`` is the patent's
  ``[0, 32995.519, 323.356, 0]``; those numbers are 1000 m/s and 1 g for c = 3e8 m/s and
  g = 9.8 m/s^2 (with the exact c they are 999.31 m/s and 0.9993 x 9.80 m/s^2); we keep the
  patent's radian values.
* :class:`CsvProfile`: a user table of time (s) / range (m), interpolated by a cubic spline
  (not-a-knot), derivatives from the spline.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dsp.gnss.ephemeris import L1_WAVELENGTH_M
from dsp.gnss.jerk import phi_b, jerk_phi, jerk_q  # noqa: F401  (the model lives with the DSP)

from ..core.csv_table import read_csv_table

#: The AUKF patent's initial state [theta rad, w0 rad/s, w1 rad/s^2, w2 rad/s^3].
PATENT_X0 = (0.0, 32995.519, 323.356, 0.0)
#: Default range at t = 0 (m): a typical GPS satellite range, ~20 000 km.
DEFAULT_RANGE_M = 2.2e7


def _finite(name, v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number, not {v!r}")
    return float(v)


class Trajectory:
    """A realised line-of-sight trajectory: :meth:`evaluate` gives ``(r, r', r'', r''')``."""

    def evaluate(self, t_s) -> np.ndarray:  # pragma: no cover - interface
        """``(4, n)`` array: range (m), range rate (m/s), acceleration, jerk at ``t_s``."""
        raise NotImplementedError

    def excess_phase_cycles(self, t_s) -> np.ndarray:
        """Carrier phase from the motion, ``-(r(t) - r(0)) / lambda`` (cycles)."""
        return -self.delta_range_m(t_s) / L1_WAVELENGTH_M

    def delta_range_m(self, t_s) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64)
        return self.evaluate(t)[0] - self.evaluate(np.zeros(1))[0, 0]


# ---------------------------------------------------------------------------------------------
# Polynomial segments
# ---------------------------------------------------------------------------------------------
class _PiecewiseCubic(Trajectory):
    """Range as a cubic per segment (constant jerk), knots at the event times."""

    def __init__(self, knots, states, jerks):
        self.knots = np.asarray(knots, dtype=np.float64)     # segment starts, knots[0] = 0
        self.states = np.asarray(states, dtype=np.float64)   # (n, 3): r, v, a at each knot
        self.jerks = np.asarray(jerks, dtype=np.float64)     # (n,) jerk on each segment

    def evaluate(self, t_s):
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        k = np.clip(np.searchsorted(self.knots, t, side="right") - 1, 0, len(self.knots) - 1)
        dt = t - self.knots[k]
        r0, v0, a0 = self.states[k].T
        j = self.jerks[k]
        out = np.empty((4, t.size))
        out[0] = r0 + dt * (v0 + dt * (a0 / 2 + dt * j / 6))
        out[1] = v0 + dt * (a0 + dt * j / 2)
        out[2] = a0 + dt * j
        out[3] = j
        return out

    def delta_range_m(self, t_s):
        # r(0) is subtracted per segment, not from the ~2e7 m total, to keep the bits.
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        dr = self.states[:, 0] - self.states[0, 0]
        if t.size > 1 and np.all(t[1:] >= t[:-1]):
            # Sorted times (a block of samples): one Horner pass per segment, scalars only.
            out = np.empty(t.size)
            cut = np.searchsorted(t, self.knots[1:], side="left")
            lo = 0
            for k, hi in enumerate(list(cut) + [t.size]):
                if hi > lo:
                    dt = t[lo:hi] - self.knots[k]
                    _, v0, a0 = self.states[k]
                    j = self.jerks[k]
                    out[lo:hi] = dr[k] + dt * (v0 + dt * (a0 / 2 + dt * (j / 6)))
                lo = max(lo, hi)
            return out
        k = np.clip(np.searchsorted(self.knots, t, side="right") - 1, 0, len(self.knots) - 1)
        dt = t - self.knots[k]
        _, v0, a0 = self.states[k].T
        j = self.jerks[k]
        return dr[k] + dt * (v0 + dt * (a0 / 2 + dt * (j / 6)))


@dataclass(frozen=True)
class PolynomialProfile:
    """Range, range rate and acceleration at t = 0, then piecewise-constant jerk.

    Parameters
    ----------
    range_m, range_rate_mps, range_accel_mps2 : float
        State at t = 0 (m, m/s, m/s^2). Negative range rate = closing (positive Doppler).
    jerk_segments : tuple of (t_start_s, jerk_mps3)
        From ``t_start_s`` on, the jerk is ``jerk_mps3`` (until the next segment starts);
        before the first segment the jerk is 0.
    accel_steps : tuple of (t_s, delta_accel_mps2)
        Steps of the range acceleration at ``t_s``.
    """

    range_m: float = DEFAULT_RANGE_M
    range_rate_mps: float = 0.0
    range_accel_mps2: float = 0.0
    jerk_segments: tuple = ()
    accel_steps: tuple = ()

    def __post_init__(self):
        if _finite("range_m", self.range_m) <= 0:
            raise ValueError(f"range_m must be > 0, not {self.range_m}")
        _finite("range_rate_mps", self.range_rate_mps)
        _finite("range_accel_mps2", self.range_accel_mps2)
        for name in ("jerk_segments", "accel_steps"):
            for item in getattr(self, name):
                if len(item) != 2:
                    raise ValueError(f"{name} entries must be (t_s, value) pairs, not {item!r}")
                if _finite(f"{name} time", item[0]) < 0:
                    raise ValueError(f"{name} times must be >= 0 s, not {item[0]}")
                _finite(f"{name} value", item[1])

    def realise(self, duration_s: float, rng=None) -> Trajectory:
        events = sorted({0.0} | {float(t) for t, _ in self.jerk_segments}
                        | {float(t) for t, _ in self.accel_steps})
        jerk_at = sorted(self.jerk_segments)
        knots, states, jerks = [], [], []
        r, v, a, j, t_prev = float(self.range_m), float(self.range_rate_mps), \
            float(self.range_accel_mps2), 0.0, 0.0
        for t in events:
            dt = t - t_prev
            r, v, a = r + dt * (v + dt * (a / 2 + dt * j / 6)), v + dt * (a + dt * j / 2), a + dt * j
            a += sum(float(da) for ts, da in self.accel_steps if float(ts) == t)
            for ts, jv in jerk_at:
                if float(ts) == t:
                    j = float(jv)
            knots.append(t)
            states.append((r, v, a))
            jerks.append(j)
            t_prev = t
        return _PiecewiseCubic(knots, states, jerks)


def constant(range_rate_mps: float = 0.0, range_m: float = DEFAULT_RANGE_M) -> PolynomialProfile:
    """Constant range rate (constant Doppler ``-range_rate / lambda``)."""
    return PolynomialProfile(range_m=range_m, range_rate_mps=range_rate_mps)


def from_doppler(doppler_hz: float, doppler_rate_hz_s: float = 0.0,
                 range_m: float = DEFAULT_RANGE_M) -> PolynomialProfile:
    """A polynomial profile with the given carrier Doppler and Doppler rate at t = 0."""
    return PolynomialProfile(range_m=range_m,
                             range_rate_mps=-_finite("doppler_hz", doppler_hz) * L1_WAVELENGTH_M,
                             range_accel_mps2=-_finite("doppler_rate_hz_s", doppler_rate_hz_s)
                             * L1_WAVELENGTH_M)


# ---------------------------------------------------------------------------------------------
# The AUKF patent's jerk (Singer) process
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class JerkProcess:
    """The AUKF patent's Singer-type jerk process on the L1 carrier phase (module docstring).

    Parameters
    ----------
    x0 : 4 floats
        Initial ``[theta rad, w0 rad/s, w1 rad/s^2, w2 rad/s^3]`` (the patent's by default).
    alpha_per_s : float
        Jerk decorrelation rate (1/s), >= 0 (0 = integrated random-walk jerk). Not in the
        patent; default 0.1 /s (10 s correlation time, the length of a run).
    q : float
        True process-noise intensity (rad^2/s^7), >= 0. Default 5, the patent's initial slave
        estimate q0.
    step_s : float
        Propagation grid (s); the code period by default.
    range_m : float
        Range at t = 0 (m).
    """

    x0: tuple = PATENT_X0
    alpha_per_s: float = 0.1
    q: float = 5.0
    step_s: float = 1e-3
    range_m: float = DEFAULT_RANGE_M

    def __post_init__(self):
        if len(self.x0) != 4:
            raise ValueError(f"x0 must have 4 entries [theta, w0, w1, w2], not {self.x0!r}")
        for v in self.x0:
            _finite("x0 entry", v)
        if _finite("alpha_per_s", self.alpha_per_s) < 0:
            raise ValueError(f"alpha_per_s must be >= 0, not {self.alpha_per_s}")
        if _finite("q", self.q) < 0:
            raise ValueError(f"q (process-noise intensity, rad^2/s^7) must be >= 0, not {self.q}")
        if _finite("step_s", self.step_s) <= 0:
            raise ValueError(f"step_s must be > 0, not {self.step_s}")
        if _finite("range_m", self.range_m) <= 0:
            raise ValueError(f"range_m must be > 0, not {self.range_m}")

    @staticmethod
    def q_from_sigma(alpha_per_s: float, sigma_jerk: float) -> float:
        """``q = 2 alpha sigma_j^2`` (sigma_j in rad/s^3, the jerk's stationary std)."""
        return 2.0 * alpha_per_s * sigma_jerk ** 2

    def states(self, duration_s: float, rng: np.random.Generator) -> np.ndarray:
        """``(n + 1, 4)`` states on the grid ``k step_s``, ``k = 0..n``, covering the duration
        (plus one step of margin)."""
        n = int(math.ceil(duration_s / self.step_s)) + 1
        phi = jerk_phi(self.alpha_per_s, self.step_s)
        Q = jerk_q(self.alpha_per_s, self.q, self.step_s)
        # Scale before the Cholesky factor: Q's entries span T^7 .. T.
        d = self.step_s ** -(np.arange(3, -1, -1) + 0.5)
        Qs = Q * np.outer(d, d)
        w, V = np.linalg.eigh(Qs)
        L = (V * np.sqrt(np.clip(w, 0.0, None))) / d[:, None]
        noise = rng.standard_normal((n, 4)) @ L.T
        X = np.empty((n + 1, 4))
        X[0] = self.x0
        # A linear recursion; one small matrix-vector product per step (n = 1000 per second).
        for k in range(n):
            X[k + 1] = phi @ X[k] + noise[k]
        return X

    def realise(self, duration_s: float, rng: np.random.Generator) -> Trajectory:
        return _HermiteTrajectory(self.step_s, self.states(duration_s, rng), self.range_m)


class _HermiteTrajectory(Trajectory):
    """Quintic Hermite interpolation of the phase state on a uniform grid."""

    def __init__(self, step_s, X, range_m):
        self.h = float(step_s)
        self.X = X
        self.range_m = float(range_m)
        self.k_ = 1.0 / (2 * np.pi) * L1_WAVELENGTH_M  # rad of L1 phase -> m of range (sign -)
        h = self.h
        y0, y1 = X[:-1, 0], X[1:, 0]
        d0, d1 = X[:-1, 1], X[1:, 1]
        a0, a1 = X[:-1, 2], X[1:, 2]
        dy = y1 - y0
        self.c = np.stack([
            y0, d0, a0 / 2,
            (20 * dy - (8 * d1 + 12 * d0) * h - (3 * a0 - a1) * h * h) / (2 * h ** 3),
            (-30 * dy + (14 * d1 + 16 * d0) * h + (3 * a0 - 2 * a1) * h * h) / (2 * h ** 4),
            (12 * dy - 6 * (d1 + d0) * h - (a0 - a1) * h * h) / (2 * h ** 5)])

    def theta(self, t_s, phase_only=False):
        """``(4, n)``: theta and its three derivatives (rad, rad/s, ...); with ``phase_only``
        just ``theta(t) - theta(0)``."""
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        k = np.clip(np.floor(t / self.h).astype(np.int64), 0, self.c.shape[1] - 1)
        u = t - k * self.h
        if phase_only:
            c0, c1, c2, c3, c4, c5 = (np.take(row, k) for row in self.c)
            return (c0 - self.X[0, 0]) + u * (c1 + u * (c2 + u * (c3 + u * (c4 + u * c5))))
        c = self.c[:, k]
        out = np.empty((4, t.size))
        out[0] = c[0] + u * (c[1] + u * (c[2] + u * (c[3] + u * (c[4] + u * c[5]))))
        out[1] = c[1] + u * (2 * c[2] + u * (3 * c[3] + u * (4 * c[4] + u * 5 * c[5])))
        out[2] = 2 * c[2] + u * (6 * c[3] + u * (12 * c[4] + u * 20 * c[5]))
        out[3] = 6 * c[3] + u * (24 * c[4] + u * 60 * c[5])
        return out

    def evaluate(self, t_s):
        th = self.theta(t_s)
        out = -th * self.k_
        out[0] += self.range_m + self.X[0, 0] * self.k_
        return out

    def delta_range_m(self, t_s):
        return -self.theta(t_s, phase_only=True) * self.k_


# ---------------------------------------------------------------------------------------------
# User table
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CsvProfile:
    """A user table of time (s) and range (m): a CSV file with two columns (``,`` or ``;``
    separated, further columns ignored; ``#`` comments and a non-numeric header line
    allowed; read by :func:`cosim.core.csv_table.read_csv_table`), or the arrays directly.

    The times must be strictly increasing, start at or before 0 and cover the record; at
    least 4 rows.
    """

    path: str | None = None
    t_s: tuple | None = None
    range_m: tuple | None = None

    def __post_init__(self):
        if (self.path is None) == (self.t_s is None):
            raise ValueError("CsvProfile needs either path or (t_s, range_m), not both or neither")
        t, r = self._table()
        if t.ndim != 1 or t.shape != r.shape or t.size < 4:
            raise ValueError(f"the range table needs >= 4 rows of (time, range), "
                             f"not shapes {t.shape} and {r.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(r))):
            raise ValueError("the range table must hold finite numbers")
        if np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0))
            raise ValueError(f"the table's times must be strictly increasing, not "
                             f"{t[k]} then {t[k + 1]} (rows {k}, {k + 1})")
        if t[0] > 0:
            raise ValueError(f"the table must start at t <= 0 s, not {t[0]}")

    def _table(self):
        if self.path is not None:
            a = read_csv_table(self.path, f"range table {str(self.path)!r}",
                               [("time_s", "range_m")], min_rows=4, header=True,
                               separators=",;", extra_columns=True,
                               rows_need="the spline").values
            return a[:, 0], a[:, 1]
        return np.asarray(self.t_s, dtype=np.float64), np.asarray(self.range_m, dtype=np.float64)

    def realise(self, duration_s: float, rng=None) -> Trajectory:
        from scipy.interpolate import CubicSpline
        t, r = self._table()
        if t[-1] < duration_s:
            raise ValueError(f"the range table ends at {t[-1]} s, before the record's end "
                             f"{duration_s} s")
        return _SplineTrajectory(CubicSpline(t, r - r[0]), r[0], t)


class _SplineTrajectory(Trajectory):
    def __init__(self, spline, r_ref, t):
        self.s = spline
        self.r_ref = float(r_ref)
        self.r0 = float(spline(0.0))

    def evaluate(self, t_s):
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        out = np.stack([self.s(t, nu) for nu in range(4)])
        out[0] += self.r_ref
        return out

    def delta_range_m(self, t_s):
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        return self.s(t) - self.r0


def aukf_patent_dynamics(q: float = 5.0, alpha_per_s: float = 0.1, jerk_g_per_s: float = 0.0,
                         jerk_start_s: float | None = None, jerk_duration_s: float | None = None):
    """The AUKF patent's dynamics: the jerk process from x0 (``q > 0``), or, with ``q = 0`` and a
    jerk segment, the deterministic x0 dynamics (1000 m/s, 1 g) plus a ``jerk_g_per_s`` jerk
    from ``jerk_start_s`` for ``jerk_duration_s`` (issue 14's 5 g/s case)."""
    if q > 0 and jerk_g_per_s == 0:
        return JerkProcess(q=q, alpha_per_s=alpha_per_s)
    x = PATENT_X0
    k = L1_WAVELENGTH_M / (2 * np.pi)
    segs = ()
    if jerk_g_per_s:
        t0 = 0.0 if jerk_start_s is None else float(jerk_start_s)
        segs = ((t0, -jerk_g_per_s * 9.80665),)
        if jerk_duration_s is not None:
            segs += ((t0 + float(jerk_duration_s), 0.0),)
    return PolynomialProfile(range_rate_mps=-x[1] * k, range_accel_mps2=-x[2] * k,
                             jerk_segments=segs)
