"""The seed's 5-state Kalman filter for the TACAN envelope (seed eqs. 6-14), float golden form.

State ``x = [m1 sin a, m1 cos a, m2 sin b, m2 cos b, u]`` (15 Hz and 135 Hz components and
the DC level), transition from the *non-uniform* time ``dt`` between pulse peaks (eq. 12)::

    A = blkdiag(R(2 pi 15 dt), R(2 pi 135 dt), 1),  R(d) = [[cos d, sin d], [-sin d, cos d]]

measurement ``y = x1 + x3 + x5 + v`` (eq. 14). Batched: ``x`` is ``(B, 5)`` and ``P``
``(B, 5, 5)`` so Monte Carlo trials sharing one pulse timeline run in one pass.

Design choices (the seed leaves them open)
------------------------------------------
* The filter works in units of the measurement noise variance (``R = 1``); ``P``
  and ``Q`` are scaled by ``r``, so the gains do not depend on the signal level and only
  the outlier gate needs ``r``, which is estimated from the innovations.
* ``Q`` is set by the filter's *memory* ``memory_s``: random-walk process noise on each
  state per second such that the steady-state gain equals that of an exponential window of
  ``N = rate * memory_s`` pulses (``K = 2 / (N + 1)``; scalar random walk
  ``q = K^2 r_eff / (1 - K)`` per pulse, with ``r_eff = 2 r`` for a rotating sin/cos pair,
  which only sees half of each measurement on average).
* Innovation gate (``gate`` sigmas) after a warm-up; gated measurements are counted; a run
  of ``max_rejects`` consecutive gated measurements means divergence: the trial is
  re-initialised and the event counted. Nothing here can produce a NaN from finite input.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

F15, F135 = 15.0, 135.0
H = np.array([1.0, 0.0, 1.0, 0.0, 1.0])
_DIAG = np.arange(5)


@dataclass(frozen=True)
class KalmanConfig:
    """Parameters of the envelope Kalman filter.

    Parameters
    ----------
    memory_s : float
        Equivalent exponential-window length (s) that sets the process noise.
    pulse_rate_hz : float
        Nominal measurement rate (7200 pulses/s) used to turn ``memory_s`` into ``Q``.
    p0 : float
        Initial state variance in units of ``r`` (uninformative prior).
    gate : float
        Innovation gate in standard deviations.
    warmup : int
        Updates before the gate and the ``r`` estimator start.
    max_rejects : int
        Consecutive gated measurements that count as divergence (re-initialise).
    r_smooth : int
        Time constant (updates) of the innovation-based ``r`` estimate.
    """

    memory_s: float = 0.5
    pulse_rate_hz: float = 7200.0
    p0: float = 1.0e4
    gate: float = 5.0
    warmup: int = 400
    max_rejects: int = 64
    r_smooth: int = 512

    def __post_init__(self):
        for name in ("memory_s", "pulse_rate_hz", "p0", "gate"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, not {v!r}")
        for name in ("warmup", "max_rejects", "r_smooth"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, not {v!r}")
        if self.memory_s * self.pulse_rate_hz < 4:
            raise ValueError(f"memory_s={self.memory_s} is shorter than a few pulses "
                             f"at {self.pulse_rate_hz:g} pulses/s")

    @property
    def n_eff(self) -> float:
        """Equivalent number of pulses in the filter's memory."""
        return self.memory_s * self.pulse_rate_hz

    @property
    def gain_ss(self) -> float:
        return 2.0 / (self.n_eff + 1.0)

    def q_rates(self) -> tuple[float, float]:
        """Process noise density (per second, units of r): (sin/cos states, DC state)."""
        k = self.gain_ss
        q_rot = k * k * 2.0 / (1.0 - k)
        q_dc = k * k * 1.0 / (1.0 - k)
        return q_rot * self.pulse_rate_hz, q_dc * self.pulse_rate_hz


@dataclass
class KalmanEvents:
    gated: np.ndarray
    reinit: np.ndarray


class EnvelopeKalman:
    """Batched float64 envelope Kalman filter (the golden form).

    Parameters
    ----------
    cfg : KalmanConfig
    batch : int
        Number of independent trials run side by side.
    """

    def __init__(self, cfg: KalmanConfig | None = None, batch: int = 1):
        self.cfg = cfg or KalmanConfig()
        self.batch = int(batch)
        self.q_rot, self.q_dc = self.cfg.q_rates()
        self.x = np.zeros((self.batch, 5))
        self.P = np.zeros((self.batch, 5, 5))
        self.r = np.ones(self.batch)          # estimated measurement variance (signal units)
        self.n = np.zeros(self.batch, np.int64)
        self.rejects = np.zeros(self.batch, np.int64)
        self.events = KalmanEvents(np.zeros(self.batch, np.int64), np.zeros(self.batch, np.int64))
        self.n_updates = 0
        self.reset()

    def reset(self, which: np.ndarray | None = None) -> None:
        w = np.ones(self.batch, bool) if which is None else which
        self.x[w] = 0.0
        self.P[w] = np.eye(5) * self.cfg.p0
        self.n[w] = 0
        self.rejects[w] = 0

    # -- the filter -------------------------------------------------------------------------
    @staticmethod
    def transition(dt) -> np.ndarray:
        """Eq. 12 for each ``dt`` (s): array ``(B, 5, 5)``."""
        dt = np.atleast_1d(np.asarray(dt, dtype=np.float64))
        a = 2 * np.pi * F15 * dt
        b = 2 * np.pi * F135 * dt
        A = np.zeros(dt.shape + (5, 5))
        ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
        A[..., 0, 0], A[..., 0, 1], A[..., 1, 0], A[..., 1, 1] = ca, sa, -sa, ca
        A[..., 2, 2], A[..., 2, 3], A[..., 3, 2], A[..., 3, 3] = cb, sb, -sb, cb
        A[..., 4, 4] = 1.0
        return A

    def step(self, dt, y, valid=None) -> None:
        """Predict over ``dt`` (s) and update with measurement ``y`` (per trial).

        ``dt`` is a scalar (trials share the pulse timeline) or one value per trial.
        ``valid`` (bool per trial) masks trials without a measurement at this step.
        """
        y = np.broadcast_to(np.asarray(y, dtype=np.float64), (self.batch,))
        if not np.isfinite(y).all():
            raise ValueError("measurement is NaN or infinite: the front end must not send it")
        if np.ndim(dt) == 0:
            dt = float(dt)
            A = self.transition(dt)[0]
            xp = self.x @ A.T
            Pp = A @ self.P @ A.T
            qd = np.array([self.q_rot * dt] * 4 + [self.q_dc * dt])
        else:
            dt = np.broadcast_to(np.asarray(dt, dtype=np.float64), (self.batch,))
            A = self.transition(dt)
            xp = np.einsum("bij,bj->bi", A, self.x)
            Pp = A @ self.P @ np.swapaxes(A, 1, 2)
            qd = np.stack([self.q_rot * dt] * 4 + [self.q_dc * dt], axis=1)
        self._update(xp, Pp, qd, y, None if valid is None else np.asarray(valid, bool))

    def run(self, dts, ys, r_mult=None) -> None:
        """Run a sequence of steps on a shared timeline: ``dts`` (N,), ``ys`` (B, N).

        Transitions and process noise for the whole sequence are computed at once, and the
        loop only does the covariance recursion. ``r_mult`` (N,) scales the measurement
        noise of each pulse (default 1): the receiver uses it to de-weight the clustered
        pulses of reference bursts.
        """
        dts = np.asarray(dts, dtype=np.float64)
        ys = np.asarray(ys, dtype=np.float64).reshape(self.batch, -1)
        if not np.isfinite(ys).all():
            raise ValueError("measurement is NaN or infinite: the front end must not send it")
        if dts.size == 0:
            return
        As = self.transition(dts)
        AsT = np.swapaxes(As, 1, 2).copy()
        qs = np.empty((dts.size, 5))
        qs[:, :4] = (self.q_rot * dts)[:, None]
        qs[:, 4] = self.q_dc * dts
        rm = np.ones(dts.size) if r_mult is None else np.asarray(r_mult, dtype=np.float64)
        if rm.shape != dts.shape or not (np.isfinite(rm).all() and (rm > 0).all()):
            raise ValueError("r_mult must hold one finite value > 0 per step")
        for k in range(dts.size):
            self._update(self.x @ AsT[k], As[k] @ self.P @ AsT[k], qs[k], ys[:, k], r_mult=rm[k])

    def _update(self, xp, Pp, qd, y, valid=None, r_mult: float = 1.0) -> None:
        cfg = self.cfg
        Pp[:, _DIAG, _DIAG] += qd
        # Scalar update (P and Q are in units of r, so S is too).
        PH = Pp[:, :, 0] + Pp[:, :, 2] + Pp[:, :, 4]
        S = PH[:, 0] + PH[:, 2] + PH[:, 4] + r_mult
        innov = y - (xp[:, 0] + xp[:, 2] + xp[:, 4])
        e2 = innov * innov / S
        warm = self.n >= cfg.warmup
        gated = warm & (e2 > cfg.gate ** 2 * self.r)
        if valid is not None:
            gated &= valid
            use = valid & ~gated
        else:
            use = ~gated
        K = PH / S[:, None]
        # P - K S K^T (the scalar-update Joseph form reduces to this), then symmetrise.
        Pn = Pp - (S[:, None, None] * K[:, :, None]) * K[:, None, :]
        Pn += np.swapaxes(Pn, 1, 2)
        Pn *= 0.5
        any_gated = gated.any()
        if any_gated or valid is not None:
            self.x = np.where(use[:, None], xp + K * innov[:, None], xp)
            self.P = np.where(use[:, None, None], Pn, Pp)
        else:
            self.x = xp + K * innov[:, None]
            self.P = Pn
        # Innovation-based estimate of r (signal units): running mean over the second half
        # of the warm-up, then an EWMA of innovations clipped at the gate.
        upd = use & (self.n >= cfg.warmup // 2)
        acc = np.minimum(e2, np.where(warm, cfg.gate ** 2 * self.r, np.inf))
        alpha = np.where(warm, 1.0 / cfg.r_smooth, 1.0 / np.maximum(1, self.n - cfg.warmup // 2 + 1))
        self.r = np.where(upd, self.r + alpha * (acc - self.r), self.r)
        self.n += use | gated
        if any_gated:
            self.events.gated += gated
            self.rejects = np.where(gated, self.rejects + 1, np.where(use, 0, self.rejects))
            diverged = self.rejects >= cfg.max_rejects
            if diverged.any():
                self.events.reinit += diverged
                self.reset(diverged)
        elif self.rejects.any():
            self.rejects[use] = 0
        if not np.isfinite(self.x).all():
            bad = ~np.isfinite(self.x).all(axis=1)
            self.events.reinit += bad
            self.reset(bad)
        self.n_updates += 1

    # -- outputs ---------------------------------------------------------------------------
    def phases(self):
        """(alpha, beta, m1, m2, dc): envelope phases (rad) at the last update and amplitudes."""
        x = self.x
        return (np.arctan2(x[:, 0], x[:, 1]), np.arctan2(x[:, 2], x[:, 3]),
                np.hypot(x[:, 0], x[:, 1]), np.hypot(x[:, 2], x[:, 3]), x[:, 4])
