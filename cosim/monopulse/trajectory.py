"""Target trajectories in direction cosines ``(u(t), v(t))``.

Three kinds, all evaluated vectorised at any times (so any block can be generated alone):

* ``ConstantRate(u0, v0, du_dt, dv_dt)``: ``u = u0 + du_dt t``.
* ``Manoeuvre(u0, v0, du_dt, dv_dt, segments)``: piecewise-constant acceleration in
  direction cosines; ``segments`` is ``((t_start_s, t_end_s, a_u, a_v), ...)`` (1/s^2),
  non-overlapping; zero acceleration outside them. Position and rate are continuous.
* ``CsvTrajectory.from_csv(path)`` (columns ``time_s,u,v``, header optional) or
  ``CsvTrajectory(t, u, v)``: linear interpolation; times strictly increasing; evaluating
  outside ``[t[0], t[-1]]`` is refused.

Every evaluation checks the visible region ``u^2 + v^2 < 1`` and refuses a target outside it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.csv_table import read_csv_table
from .array import check_visible


def _num(name, v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number, not {v!r}")
    return float(v)


@dataclass(frozen=True)
class ConstantRate:
    """Constant-rate motion in direction cosines (rates in 1/s)."""

    u0: float = 0.3
    v0: float = 0.2
    du_dt: float = 0.0
    dv_dt: float = 0.0

    def __post_init__(self):
        for n in ("u0", "v0", "du_dt", "dv_dt"):
            _num(n, getattr(self, n))
        check_visible(self.u0, self.v0, "initial target direction")

    def unchecked(self, t_s):
        """``(u, v)`` at ``t_s`` without the visible-region check (the caller's own)."""
        t = np.asarray(t_s, float)
        return self.u0 + self.du_dt * t, self.v0 + self.dv_dt * t

    def __call__(self, t_s):
        u, v = self.unchecked(t_s)
        check_visible(u, v, "target direction")
        return u, v


@dataclass(frozen=True)
class Manoeuvre:
    """Constant rate plus constant-acceleration segments ``(t_start, t_end, a_u, a_v)``."""

    u0: float = 0.3
    v0: float = 0.2
    du_dt: float = 0.0
    dv_dt: float = 0.0
    segments: tuple = ()

    def __post_init__(self):
        for n in ("u0", "v0", "du_dt", "dv_dt"):
            _num(n, getattr(self, n))
        check_visible(self.u0, self.v0, "initial target direction")
        segs = []
        for s in self.segments:
            if not isinstance(s, (tuple, list)) or len(s) != 4:
                raise ValueError(f"a manoeuvre segment must be (t_start_s, t_end_s, a_u, a_v), "
                                 f"not {s!r}")
            t0, t1, au, av = (_num("segment value", x) for x in s)
            if not 0 <= t0 < t1:
                raise ValueError(f"a manoeuvre segment needs 0 <= t_start < t_end, not "
                                 f"{t0!r}..{t1!r}")
            segs.append((t0, t1, au, av))
        segs.sort()
        for a, b in zip(segs, segs[1:]):
            if b[0] < a[1]:
                raise ValueError(f"manoeuvre segments must not overlap, not {a!r} and {b!r}")
        object.__setattr__(self, "segments", tuple(segs))

    def unchecked(self, t_s):
        """``(u, v)`` at ``t_s`` without the visible-region check (the caller's own)."""
        t = np.asarray(t_s, float)
        u = self.u0 + self.du_dt * t
        v = self.v0 + self.dv_dt * t
        for t0, t1, au, av in self.segments:
            # Integral twice of a box acceleration: 0 before, (t-t0)^2/2 inside, then linear.
            tin = np.clip(t - t0, 0.0, t1 - t0)
            disp = 0.5 * tin * tin + (t1 - t0) * np.maximum(t - t1, 0.0)
            u = u + au * disp
            v = v + av * disp
        return u, v

    def __call__(self, t_s):
        u, v = self.unchecked(t_s)
        check_visible(u, v, "target direction")
        return u, v


class CsvTrajectory:
    """A user trajectory ``(time_s, u, v)``, linearly interpolated."""

    def __init__(self, t_s, u, v):
        t = np.asarray(t_s, float)
        u = np.asarray(u, float)
        v = np.asarray(v, float)
        if t.ndim != 1 or t.shape != u.shape or t.shape != v.shape or t.size < 2:
            raise ValueError(f"a trajectory needs >= 2 rows of time, u, v of equal length, not "
                             f"shapes {t.shape}, {u.shape}, {v.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(u)) and np.all(np.isfinite(v))):
            raise ValueError("trajectory values must be finite")
        if np.any(np.diff(t) <= 0):
            k = int(np.flatnonzero(np.diff(t) <= 0)[0])
            raise ValueError(f"trajectory times must be strictly increasing, not "
                             f"{float(t[k])!r} then {float(t[k + 1])!r} (row {k + 1})")
        check_visible(u, v, "trajectory point")
        self.t, self.u, self.v = t, u, v

    @classmethod
    def from_csv(cls, path):
        """Columns ``time_s,u,v`` (comma separated, ``#`` comments and one optional header
        line; read by :func:`cosim.core.csv_table.read_csv_table`)."""
        data = read_csv_table(path, f"trajectory CSV {str(path)!r}", [("time_s", "u", "v")],
                              min_rows=2, header=True, rows_need="the interpolation").values
        return cls(data[:, 0], data[:, 1], data[:, 2])

    def __call__(self, t_s):
        t = np.asarray(t_s, float)
        if np.any(t < self.t[0]) or np.any(t > self.t[-1]):
            raise ValueError(f"trajectory covers {float(self.t[0])!r}..{float(self.t[-1])!r} s, not "
                             f"{float(np.min(t))!r}..{float(np.max(t))!r} s")
        # Interpolated chords of a visible polyline stay visible (the disc is convex).
        return np.interp(t, self.t, self.u), np.interp(t, self.t, self.v)
