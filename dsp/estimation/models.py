"""Models: what the system is (F, B, H, Q, R or f, h), apart from how a filter combines them.

A :class:`LinearGaussianModel` holds the matrices of ``x[k+1] = F x[k] + B u[k] + w``,
``z[k] = H x[k] + v``, ``w ~ N(0, Q)``, ``v ~ N(0, R)``. Each matrix is either constant
(2-D) or time-varying (3-D, leading axis = step ``k``). :func:`white_acceleration` is the
discretised white-acceleration (piecewise-constant acceleration, Bar-Shalom's DWNA) model
that Kalata's alpha-beta filter is the steady state of; :func:`white_jerk` its 3-state
sibling. Validation states the rule and repeats the bad value.
"""
from __future__ import annotations

import numpy as np

#: Largest state dimension the filters accept (the fixed-point word checks assume it).
MAX_STATES = 8


def _mat(name: str, a, *, time_varying: bool = True) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim not in ((2, 3) if time_varying else (2,)):
        raise ValueError(f"{name} must be a 2-D matrix{' or a 3-D stack (step, ...)' if time_varying else ''}, "
                         f"not an array of shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, not {a[~np.isfinite(a)][:3].tolist()}...")
    return a if a.ndim == 3 else a[None]


def check_psd(name: str, a, *, strict: bool = False, tol: float = 1e-12) -> None:
    """Symmetric and positive semi-definite (``strict``: definite) for every step."""
    for k, m in enumerate(a):
        if not np.array_equal(m, m.T) and not np.allclose(m, m.T, rtol=0, atol=tol * max(1.0, np.abs(m).max())):
            raise ValueError(f"{name} must be symmetric, not {m.tolist()}" + (f" (step {k})" if len(a) > 1 else ""))
        ev = np.linalg.eigvalsh((m + m.T) / 2)
        bad = ev.min() <= 0 if strict else ev.min() < -tol * max(1.0, abs(ev).max())
        if bad:
            raise ValueError(f"{name} must be positive {'definite' if strict else 'semi-definite'}, "
                             f"not a matrix with eigenvalue {ev.min():.6g}" + (f" (step {k})" if len(a) > 1 else ""))


class LinearGaussianModel:
    """Linear transition and measurement with additive Gaussian noise.

    Parameters
    ----------
    F : (n, n) or (T, n, n) array
        State transition.
    H : (m, n) or (T, m, n) array
        Measurement matrix (``m <= n``).
    Q : (n, n) or (T, n, n) array
        Process noise covariance (symmetric PSD).
    R : (m, m) or (T, m, m) array
        Measurement noise covariance (symmetric positive definite).
    B : (n, p) or (T, n, p) array, optional
        Control input matrix.
    """

    def __init__(self, F, H, Q, R, B=None):
        F = _mat("F", F)
        if F.shape[1] != F.shape[2]:
            raise ValueError(f"F must be square (n x n), not {F.shape[1]} x {F.shape[2]}")
        n = F.shape[1]
        if not 1 <= n <= MAX_STATES:
            raise ValueError(f"the state dimension must be 1..{MAX_STATES}, not {n}")
        H = _mat("H", H)
        if H.shape[2] != n:
            raise ValueError(f"H must have n = {n} columns, not {H.shape[2]}")
        m = H.shape[1]
        if not 1 <= m <= n:
            raise ValueError(f"the measurement dimension must be 1..n = {n}, not {m}")
        Q = _mat("Q", Q)
        if Q.shape[1:] != (n, n):
            raise ValueError(f"Q must be {n} x {n}, not {Q.shape[1]} x {Q.shape[2]}")
        R = _mat("R", R)
        if R.shape[1:] != (m, m):
            raise ValueError(f"R must be {m} x {m}, not {R.shape[1]} x {R.shape[2]}")
        check_psd("Q", Q)
        check_psd("R", R, strict=True)
        if B is None:
            B = np.zeros((1, n, 0))
        else:
            B = _mat("B", B)
            if B.shape[1] != n:
                raise ValueError(f"B must have n = {n} rows, not {B.shape[1]}")
        self.F, self.H, self.Q, self.R, self.B = F, H, Q, R, B
        steps = {len(a) for a in (F, H, Q, R, B) if len(a) > 1}
        if len(steps) > 1:
            raise ValueError(f"time-varying matrices must share one length, not {sorted(steps)}")
        #: Steps a time-varying model covers (``None``: constant).
        self.steps = steps.pop() if steps else None

    @property
    def n(self) -> int:
        return self.F.shape[1]

    @property
    def m(self) -> int:
        return self.H.shape[1]

    @property
    def p(self) -> int:
        return self.B.shape[2]

    def at(self, k: int):
        """``(F, H, Q, R, B)`` of step ``k`` (2-D arrays)."""
        pick = lambda a: a[k if len(a) > 1 else 0]
        return tuple(pick(a) for a in (self.F, self.H, self.Q, self.R, self.B))


def white_acceleration(T_s: float, q: float, r: float) -> LinearGaussianModel:
    """Position-velocity model driven by piecewise-constant white acceleration.

    ``F = [[1, T], [0, 1]]``, ``Q = q [[T^4/4, T^3/2], [T^3/2, T^2]]`` (acceleration
    variance ``q``), position measured with variance ``r``. Kalata's tracking index is
    ``lambda = sqrt(q) T^2 / sqrt(r)``.
    """
    for name, v in (("T_s", T_s), ("q", q), ("r", r)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a finite number > 0, not {v!r}")
    G = np.array([[T_s * T_s / 2], [T_s]])
    return LinearGaussianModel([[1.0, T_s], [0.0, 1.0]], [[1.0, 0.0]], q * (G @ G.T), [[r]])


def white_jerk(T_s: float, q: float, r: float) -> LinearGaussianModel:
    """Position-velocity-acceleration model driven by piecewise-constant white jerk."""
    for name, v in (("T_s", T_s), ("q", q), ("r", r)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a finite number > 0, not {v!r}")
    G = np.array([[T_s ** 3 / 6], [T_s * T_s / 2], [T_s]])
    F = [[1.0, T_s, T_s * T_s / 2], [0.0, 1.0, T_s], [0.0, 0.0, 1.0]]
    return LinearGaussianModel(F, [[1.0, 0.0, 0.0]], q * (G @ G.T), [[r]])
