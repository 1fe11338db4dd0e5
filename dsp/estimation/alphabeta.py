"""Alpha-beta and alpha-beta-gamma trackers, fixed or adaptive (Kalata's tracking index),
one source for float64, float32 and fixed point.

The filter runs in *per-sample units*, as a DSP implementation would: the state is
``[x, T v, T^2 a / 2]`` (position, velocity times the sample time, half the acceleration
times its square), so the transition is the integer matrix ``[[1, 1, 1], [0, 1, 2], [0, 0,
1]]`` (adds only) and the gains are the dimensionless ``[alpha, beta, gamma / 4]``
(physical gains ``alpha, beta / T, gamma / (2 T^2)``, the steady-state Kalman gain of the
white-acceleration (jerk) model when the coefficients come from :func:`kalata`
(:func:`steady_state_gains`)). :class:`AlphaBetaRun` returns physical units.

Kalata (1984): tracking index ``lambda = sigma_w T^2 / sigma_v``, ``r = (4 + lambda -
sqrt(lambda^2 + 8 lambda)) / 4``, ``alpha = 1 - r^2``, ``beta = 2 (2 - alpha) - 4 sqrt(1 -
alpha) = 2 (1 - r)^2``.

Adaptive mode (alpha-beta only; the monopulse paper's, with the project's decision, see
docs/explanation/monopulse_tracker.md): the manoeuvre (acceleration) standard deviation is
estimated from the last ``window`` innovations (the paper's 3-5) as ``sigma_a T^2 = k sqrt(max(mean e^2 - tau sigma_v^2, 0))`` (``k =
manoeuvre_gain``, the decision's 2; ``tau = noise_floor``), the tracking index is ``lambda =
sigma_a T^2 / sigma_v`` and alpha, beta are Kalata's: ``r = 4 / (4 + lambda + sqrt(lambda^2
+ 8 lambda))`` (the same r as above, without the cancellation), ``alpha = clip(1 - r^2,
alpha_min, alpha_max)``, ``beta = 2 (1 - sqrt(1 - alpha))^2`` (= ``2 (2 - alpha) - 4 sqrt(1 -
alpha)`` of the clipped alpha). No power beyond the floor: ``alpha_min``. Why ``tau = 4``
by default and not the decision's 1: the mean of 3-5 squared innovations is a chi-square
with 3-5 degrees of freedom (relative spread 0.6-0.8), so with ``tau = 1`` half of the quiet
windows read a "manoeuvre" of ``lambda ~ 1`` and alpha sits at 0.6-0.8 without one
(measured in ``tests/dsp/estimation/test_alphabeta.py``). Fixed point, per step: ``e^2`` ->
s; mean (one division) -> s; minus the floor (exact); ``sqrt`` -> l; ``/ (sigma_v / k)`` ->
l; ``sqrt(l^2 + 8 l)`` -> l; ``4 / (4 + l + sqrt)`` -> c; ``1 - r^2`` -> c; clip; ``sqrt(1 -
alpha)`` -> c; ``2 d^2`` -> c.

Two options against the positive feedback of a fixed floor (measured on the monopulse
manoeuvre scenario of ``tests/dsp/monopulse/test_mono_tracker.py``): a high alpha inflates
the innovation itself (its variance on noise alone is ``sigma_v^2 / (1 - alpha)`` for a
Kalata pair), so with the fixed floor one noisy window raises alpha and the raised alpha
keeps the innovation above the floor: after a manoeuvre, or after a chi-square outlier in a
quiet track, the filter stays agile and noisy. ``floor_scaling="gain"`` divides the floor by
``1 - alpha`` of the gains in use (fixed point: ``floor / (1 - alpha)``, one division, the
denominator's low fraction bits dropped so the shifted floor fits 62 bits); alone, it makes
alpha flip between its limits step by step (each jump to a high alpha kicks the velocity
state, whose error then raises the innovation again), so ``alpha_relax`` lets ``1 - alpha``
grow by at most that factor a step (``al >= 1 - relax (1 - alpha_prev)``, fixed point: one
product, rounded to c). Both off by default here (the library's behaviour is unchanged);
the monopulse tracker turns them on.

Formats (:class:`AlphaBetaFormats`): z measurement, x state (all three per-sample
components), e innovation, c coefficients (alpha, beta, gamma/4 and the adaptive
intermediates), s squared innovations, their mean and the noise floor, l the tracking
index and its intermediates.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..fixed import FixedFormat
from ..jit import njit_cached
from .events import EventRegistry
from .formats import Arithmetic, FormatTable, fits, fmt, need_bits, need_shift, to_fixed
from ..qops import align, div_q, flip, rs, sqrt_q, store


def tracking_index(T_s: float, sigma_w: float, sigma_v: float) -> float:
    """Kalata's tracking index ``sigma_w T^2 / sigma_v`` (``sigma_w``: acceleration noise
    standard deviation, ``sigma_v``: position measurement noise standard deviation)."""
    for name, v in (("T_s", T_s), ("sigma_w", sigma_w), ("sigma_v", sigma_v)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a finite number > 0, not {v!r}")
    return sigma_w * T_s * T_s / sigma_v


def kalata(lam: float) -> tuple[float, float]:
    """``(alpha, beta)`` of Kalata's tracking index ``lam > 0``."""
    if not (isinstance(lam, (int, float)) and math.isfinite(lam) and lam > 0):
        raise ValueError(f"the tracking index must be a finite number > 0, not {lam!r}")
    r = (4.0 + lam - math.sqrt(lam * lam + 8.0 * lam)) / 4.0
    alpha = 1.0 - r * r
    return alpha, 2.0 * (2.0 - alpha) - 4.0 * math.sqrt(1.0 - alpha)


def steady_state_gains(model, iters: int = 100_000, tol: float = 1e-15) -> np.ndarray:
    """Steady-state Kalman gain of a constant scalar-measurement model, by iterating the
    Riccati recursion (predicted covariance) to a fixed point."""
    F, H, Q, R, _ = model.at(0)
    P = np.eye(model.n)
    for _ in range(iters):
        S = H @ P @ H.T + R
        K = P @ H.T / S[0, 0]
        Pn = F @ ((np.eye(model.n) - K @ H) @ P) @ F.T + Q
        Pn = (Pn + Pn.T) / 2
        if np.max(np.abs(Pn - P)) <= tol * np.max(np.abs(P)):
            P = Pn
            break
        P = Pn
    S = H @ P @ H.T + R
    return (P @ H.T / S[0, 0])[:, 0]


def check_coefficients(alpha: float, beta: float, gamma: float | None = None) -> None:
    """The stability region of the alpha-beta(-gamma) tracker."""
    if not (isinstance(alpha, (int, float)) and 0.0 < alpha < 1.0):
        raise ValueError(f"alpha must be in (0, 1), not {alpha!r}")
    if not (isinstance(beta, (int, float)) and 0.0 < beta < 4.0 - 2.0 * alpha):
        raise ValueError(f"beta must be in (0, 4 - 2 alpha) = (0, {4 - 2 * alpha:g}), not {beta!r}")
    if gamma is not None:
        g_hi = 4.0 * alpha * beta / (2.0 - alpha)
        if not (isinstance(gamma, (int, float)) and 0.0 < gamma < g_hi):
            raise ValueError(f"gamma must be in (0, 4 alpha beta / (2 - alpha)) = (0, {g_hi:g}), "
                             f"not {gamma!r}")


@dataclass(frozen=True)
class AlphaBetaFormats(FormatTable):
    """Fixed-point formats of the alpha-beta(-gamma) tracker (per-sample units)."""

    z: FixedFormat = fmt(32, 20)
    x: FixedFormat = fmt(40, 28)
    e: FixedFormat = fmt(32, 20)
    c: FixedFormat = fmt(24, 22)
    s: FixedFormat = fmt(40, 24)
    l: FixedFormat = fmt(28, 16)

    def __post_init__(self):
        self.validate()

    def floor_drop_bits(self) -> int:
        """Fraction bits of ``1 - alpha`` dropped in ``floor / (1 - alpha)`` (the floor
        moves up by the rest, staying within 62 bits)."""
        return max(0, self.c.frac - (62 - self.s.width))

    def check(self, window: int) -> None:
        r = self.fracs()
        w = {s: getattr(self, s).width for s in self.signals()}
        need_shift("z - xp", r["x"] - r["z"], "z")
        need_shift("z - xp", r["x"] - r["e"], "e")
        a = r["c"] + r["e"]
        need_bits("xp + c e", max(w["c"] + w["e"] - 1, w["x"] + need_shift("xp + c e", a - r["x"], "x")) + 1)
        need_bits("e^2", 2 * w["e"] - 1)
        need_shift("e^2", 2 * r["e"] - r["s"], "s")
        need_bits("sum of e^2", w["s"] + math.ceil(math.log2(window)))
        need_shift("sqrt(S - floor)", 2 * r["l"] - r["s"], "s")
        need_bits("sqrt(S - floor)", w["s"] + 2 * r["l"] - r["s"])
        need_bits("sqrt(S - floor) / (sigma_v / k)", w["l"] + r["l"])
        need_bits("lambda^2 + 8 lambda", max(2 * w["l"] - 1, w["l"] + 3 + r["l"]) + 1)
        need_bits("4 / (4 + lambda + sqrt)", r["l"] + 4 + r["c"])
        need_bits("1 - r^2", 2 * w["c"] + 1)
        need_bits("sqrt(1 - alpha)", w["c"] + r["c"])
        need_bits("2 (1 - r)^2", 2 * w["c"] + 1)
        need_bits("floor / (1 - alpha)", w["s"] + r["c"] - self.floor_drop_bits())
        need_bits("1 - (1 - alpha) relax", 2 * w["c"] + 1)


#: Noise floor of the adaptive mode: ``fixed`` ``tau sigma_v^2``; ``gain`` ``tau sigma_v^2 / (1 -
#: alpha)`` with the alpha in use (the innovation variance those gains give on noise alone).
FLOOR_SCALINGS = ("fixed", "gain")

SIGNALS = AlphaBetaFormats.signals()
EVENTS = EventRegistry(SIGNALS, ("implausible", "s_zero", "neg_sqrt", "upsets"))
_Z, _X, _E, _C, _S, _L = (SIGNALS.index(s) for s in ("z", "x", "e", "c", "s", "l"))
_EV_IMPL = EVENTS.index("implausible")
_EV_SZ = EVENTS.index("s_zero")
_EV_NSQ = EVENTS.index("neg_sqrt")
_EV_UPS = EVENTS.index("upsets")
_BASE = EVENTS.base


@njit_cached
def _ab_kernel(x, c, z, zok, adapt, ring, rpos, rcnt, consts, fr, lo, hi, hf, wd, k0, ups, ev, xs, cs):
    """consts = [noise floor tau sigma_v^2 (s), alpha_min (c), alpha_max (c), one (c), window (as a
    number), sigma_v / k (l), 4 (l), floor scaled by 1 / (1 - alpha) (0 or 1), alpha_relax (c)]."""
    nb, n = x.shape
    T = z.shape[1]
    N = ring.shape[1]
    z0 = x[0, 0] - x[0, 0]
    floor, amin, amax, one, nw, svl, four = consts[0], consts[1], consts[2], consts[3], consts[4], consts[5], consts[6]
    scale, grow = consts[7], consts[8]
    # floor / (1 - alpha): the numerator moves up at most to 62 bits, the denominator drops
    # the fraction bits that do not fit (floor_drop_bits)
    kd = max(0, fr[_C] - (62 - wd[_S]))
    xp = np.empty(n, x.dtype)
    for b in range(nb):
        eb = ev[b]
        for k in range(T):
            for r in range(ups.shape[0]):
                if ups[r, 0] == k0 + k and ups[r, 1] == b:
                    eb[_EV_UPS] += 1
                    x[b, ups[r, 2]] = flip(x[b, ups[r, 2]], ups[r, 3], wd[_X])
            if n == 3:
                xp[0] = store(x[b, 0] + x[b, 1] + x[b, 2], 0, 0, lo[_X], hi[_X], eb, _X, _BASE)
                xp[1] = store(x[b, 1] + x[b, 2] + x[b, 2], 0, 0, lo[_X], hi[_X], eb, _X, _BASE)
                xp[2] = x[b, 2]
            else:
                xp[0] = store(x[b, 0] + x[b, 1], 0, 0, lo[_X], hi[_X], eb, _X, _BASE)
                xp[1] = x[b, 1]
            if not zok[b, k]:
                eb[_EV_IMPL] += 1
                for i in range(n):
                    x[b, i] = xp[i]
            else:
                e = store(align(z[b, k], fr[_X] - fr[_Z]) - xp[0], fr[_X] - fr[_E], hf[_E],
                          lo[_E], hi[_E], eb, _E, _BASE)
                if adapt:
                    ring[b, rpos[b]] = store(e * e, 2 * fr[_E] - fr[_S], hf[_S], lo[_S], hi[_S], eb, _S, _BASE)
                    rpos[b] = (rpos[b] + 1) % N
                    rcnt[b] += 1
                    if rcnt[b] >= N:
                        acc = z0
                        for j in range(N):
                            acc += ring[b, j]
                        Sm = div_q(acc, nw, 0, hf[_S], lo[_S], hi[_S], eb, _S, _EV_SZ, _BASE)
                        fl = floor
                        if scale != z0:     # the floor of the gains in use: / (1 - alpha)
                            den = rs(one - c[b, 0], kd, False)
                            fl = div_q(floor, den, fr[_C] - kd, hf[_S], lo[_S], hi[_S], eb, _S, _EV_SZ, _BASE)
                        dm = Sm - fl        # innovation power beyond the noise floor
                        if dm > z0:
                            g = sqrt_q(dm, 2 * fr[_L] - fr[_S], hf[_L], hi[_L], eb, _L, _EV_NSQ, _BASE)
                            lam = div_q(g, svl, fr[_L], hf[_L], lo[_L], hi[_L], eb, _L, _EV_SZ, _BASE)
                            l8 = lam + lam
                            l8 = l8 + l8
                            l8 = l8 + l8
                            sq = sqrt_q(lam * lam + align(l8, fr[_L]), 0, hf[_L], hi[_L], eb, _L, _EV_NSQ, _BASE)
                            # Kalata r = (4 + l - sqrt(l^2 + 8 l)) / 4 = 4 / (4 + l + sqrt(l^2 + 8 l))
                            rk = div_q(four, four + lam + sq, fr[_C], hf[_C], lo[_C], hi[_C], eb, _C, _EV_SZ, _BASE)
                            al = store(align(one, fr[_C]) - rk * rk, fr[_C], hf[_C], lo[_C], hi[_C], eb, _C, _BASE)
                        else:  # no manoeuvre
                            al = amin
                        if grow != z0:      # (1 - alpha) grows at most by ``grow`` a step
                            lim = align(one, fr[_C]) - (one - c[b, 0]) * grow
                            lim = store(lim, fr[_C], hf[_C], lo[_C], hi[_C], eb, _C, _BASE)
                            if al < lim:
                                al = lim
                        if al < amin:
                            al = amin
                        if al > amax:
                            al = amax
                        rr = sqrt_q(one - al, fr[_C], hf[_C], hi[_C], eb, _C, _EV_NSQ, _BASE)
                        d = one - rr
                        c[b, 0] = al
                        c[b, 1] = store(d * d + d * d, fr[_C], hf[_C], lo[_C], hi[_C], eb, _C, _BASE)
                a = fr[_C] + fr[_E]
                for i in range(n):
                    x[b, i] = store(align(xp[i], a - fr[_X]) + c[b, i] * e, a - fr[_X], hf[_X],
                                    lo[_X], hi[_X], eb, _X, _BASE)
            for i in range(n):
                xs[b, k, i] = x[b, i]
            cs[b, k, 0] = c[b, 0]
            cs[b, k, 1] = c[b, 1]


@dataclass
class AlphaBetaRun:
    """States after each step in physical units ``(B, T, n)`` (position, velocity[,
    acceleration]), the alpha and beta in use after each step ``(B, T, 2)``, events."""

    x: np.ndarray
    coefficients: np.ndarray
    events: dict


class AlphaBetaFilter:
    """Alpha-beta (``gamma=None``) or alpha-beta-gamma tracker, batched over trials.

    Parameters
    ----------
    T_s : float
        Sample time (s).
    alpha, beta : float
        Coefficients (stability region checked; :func:`kalata` gives the Kalman pair).
    gamma : float, optional
        Third coefficient: an alpha-beta-gamma tracker (3 states).
    adaptive : bool
        Re-derive alpha and beta from the innovation level (alpha-beta only).
    sigma_v : float
        Measurement noise standard deviation (adaptive mode).
    window : int
        Innovations averaged by the adaptive mode (2..64; the monopulse paper's 3-5).
    noise_floor : float
        ``tau``: innovation power ``tau sigma_v^2`` taken as noise, not manoeuvre.
    manoeuvre_gain : float
        ``k`` of ``sigma_a T^2 = k sqrt(mean e^2 - tau sigma_v^2)``.
    floor_scaling : {"fixed", "gain"}
        The noise floor ``tau sigma_v^2`` as is, or divided by ``1 - alpha`` of the gains in
        use (the innovation variance a Kalata pair gives on measurement noise alone; see the
        module doc).
    alpha_relax : float
        0: alpha follows the estimate at once; in (1, 2): ``1 - alpha`` grows at most by this
        factor a step (alpha falls back gradually after a manoeuvre).
    alpha_min, alpha_max : float
        Limits of the adaptive alpha.
    arithmetic : {"float64", "float32"} or AlphaBetaFormats
    trials : int
    x0 : (n,) or (B, n) array, optional
        Initial state in physical units (default zeros).
    z_limit : float, optional
        Largest plausible ``|z|`` (NaN or beyond: predict only, counted ``implausible``).
    """

    def __init__(self, T_s: float, alpha: float, beta: float, gamma: float | None = None, *,
                 adaptive: bool = False, sigma_v: float | None = None, window: int = 4,
                 alpha_min: float = 0.05, alpha_max: float = 0.95, noise_floor: float = 4.0,
                 manoeuvre_gain: float = 2.0, floor_scaling: str = "fixed", alpha_relax: float = 0.0,
                 arithmetic="float64", trials: int = 1, x0=None, z_limit: float | None = None):
        if not (isinstance(T_s, (int, float)) and math.isfinite(T_s) and T_s > 0):
            raise ValueError(f"T_s must be a finite number > 0, not {T_s!r}")
        check_coefficients(alpha, beta, gamma)
        if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials < 1:
            raise ValueError(f"trials must be an integer >= 1, not {trials!r}")
        if adaptive:
            if gamma is not None:
                raise ValueError("the adaptive mode is for the alpha-beta tracker (gamma=None)")
            if not (isinstance(sigma_v, (int, float)) and math.isfinite(sigma_v) and sigma_v > 0):
                raise ValueError(f"sigma_v must be a finite number > 0 in adaptive mode, not {sigma_v!r}")
            if isinstance(window, bool) or not isinstance(window, int) or not 2 <= window <= 64:
                raise ValueError(f"window must be an integer in [2, 64], not {window!r}")
            if not (isinstance(noise_floor, (int, float)) and math.isfinite(noise_floor)
                    and noise_floor >= 0):
                raise ValueError(f"noise_floor must be a finite number >= 0, not {noise_floor!r}")
            if not (isinstance(manoeuvre_gain, (int, float)) and math.isfinite(manoeuvre_gain)
                    and manoeuvre_gain > 0):
                raise ValueError(f"manoeuvre_gain must be a finite number > 0, not {manoeuvre_gain!r}")
            if isinstance(alpha_relax, bool) or not isinstance(alpha_relax, (int, float)) or not (
                    alpha_relax == 0 or 1 < alpha_relax < 2):
                raise ValueError(f"alpha_relax must be 0 (no limit) or in (1, 2), not {alpha_relax!r}")
            if floor_scaling not in FLOOR_SCALINGS:
                raise ValueError(f"floor_scaling must be one of {', '.join(FLOOR_SCALINGS)}, not "
                                 f"{floor_scaling!r}")
            if not 0.0 < alpha_min < alpha_max < 1.0:
                raise ValueError(f"alpha limits must satisfy 0 < alpha_min < alpha_max < 1, not "
                                 f"{alpha_min!r}, {alpha_max!r}")
        if z_limit is not None and not (np.isfinite(z_limit) and z_limit > 0):
            raise ValueError(f"z_limit must be a finite number > 0 or None, not {z_limit!r}")
        self.T_s, self.trials, self.adaptive, self.z_limit = float(T_s), int(trials), bool(adaptive), z_limit
        self.n = 2 if gamma is None else 3
        self.ar = ar = Arithmetic.of(arithmetic, AlphaBetaFormats, "alpha-beta filter")
        self.kind, self.formats = ar.kind, ar.formats
        self.fr, self.lo, self.hi, self.hf, self.wd = ar.arrays
        n = self.n
        x0 = np.zeros(n) if x0 is None else np.asarray(x0, dtype=np.float64)
        if x0.shape not in ((n,), (self.trials, n)):
            raise ValueError(f"x0 must have shape ({n},) or ({self.trials}, {n}), not {x0.shape}")
        x0 = np.broadcast_to(x0, (self.trials, n)) * np.array([1.0, T_s, T_s * T_s / 2][:n])
        coef = np.array([alpha, beta, 0.0 if gamma is None else gamma / 4.0])
        sv = 1.0 if sigma_v is None else float(sigma_v)
        scale = 1.0 if adaptive and floor_scaling == "gain" else 0.0
        consts = np.array([noise_floor * sv ** 2, alpha_min, alpha_max, 1.0, window, sv / manoeuvre_gain, 4.0,
                           scale, alpha_relax])
        window = window if adaptive else 1
        self.events = EVENTS
        if ar.fixed:
            fm = ar.formats
            fm.check(window)
            fits("x0 (per-sample units)", x0, fm.x)
            fits("coefficients", coef, fm.c)
            fits("noise_floor sigma_v^2", consts[:1], fm.s)
            fits("sigma_v / manoeuvre_gain", consts[5:6], fm.l)
            fits("alpha_relax", consts[8:9], fm.c)
            if adaptive and to_fixed(consts[5], fm.l) < 1:
                raise ValueError(f"format too narrow for sigma_v / manoeuvre_gain = {consts[5]:g}: "
                                 f"below one LSB of {fm.l}")
            self.x = to_fixed(x0, fm.x)
            self.c = np.broadcast_to(to_fixed(coef, fm.c), (self.trials, 3)).copy()
            self.consts = np.array([to_fixed(consts[0], fm.s), to_fixed(alpha_min, fm.c),
                                    to_fixed(alpha_max, fm.c), 1 << fm.c.frac, window,
                                    to_fixed(consts[5], fm.l), 4 << fm.l.frac, int(scale),
                                    to_fixed(alpha_relax, fm.c)], np.int64)
        else:
            self.x = x0.astype(ar.dtype)
            self.c = np.array(np.broadcast_to(coef, (self.trials, 3)), dtype=ar.dtype, order="C")
            self.consts = consts.astype(ar.dtype)
        dt = ar.dtype
        self._x_scale = np.array([1.0, T_s, T_s * T_s / 2][:n])
        self._c0 = self.c.copy()
        self.ring = np.zeros((self.trials, window), dt)
        self.rpos = np.zeros(self.trials, np.int64)
        self.rcnt = np.zeros(self.trials, np.int64)
        self.ev = EVENTS.new((self.trials,))
        self.k = 0

    def reset(self, mask, x0) -> None:
        """Re-initialise the trials selected by ``mask`` ((B,) bool) at the physical state
        ``x0`` ((n,) or (count, n)): state, coefficients back to their initial values, the
        adaptive window emptied. Event counters and the step count are kept."""
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != (self.trials,):
            raise ValueError(f"mask must have shape ({self.trials},), not {mask.shape}")
        m = int(mask.sum())
        x0 = np.asarray(x0, dtype=np.float64)
        if x0.shape not in ((self.n,), (m, self.n)):
            raise ValueError(f"x0 must have shape ({self.n},) or ({m}, {self.n}), not {x0.shape}")
        if m == 0:
            return
        xs = np.broadcast_to(x0, (m, self.n)) * self._x_scale
        if self.kind == "fixed":
            fits("x0 (per-sample units)", xs, self.formats.x)
            self.x[mask] = to_fixed(xs, self.formats.x)
        else:
            self.x[mask] = xs.astype(self.x.dtype)
        self.c[mask] = self._c0[mask]
        self.ring[mask] = 0
        self.rpos[mask] = 0
        self.rcnt[mask] = 0

    def counts(self) -> dict:
        return EVENTS.counts(self.ev)

    def run(self, z, *, upsets=None) -> AlphaBetaRun:
        """Track ``T`` measurements ``z`` (``(T,)`` or ``(B, T)``).

        ``upsets`` (fixed point only): ``(U, 4)`` rows ``(step, trial, element, bit)``, a bit
        flip of the per-sample state word ``x[element]`` before step ``step`` (global count).
        """
        z = np.asarray(z, dtype=np.float64)
        shape = z.shape
        if z.ndim == 1:
            z = np.broadcast_to(z, (self.trials,) + z.shape)
        if z.ndim != 2 or z.shape[0] != self.trials:
            raise ValueError(f"z must have shape (T,) or ({self.trials}, T), not {shape}")
        ok = np.isfinite(z)
        lim = self.ar.limit(self.z_limit, "z")
        if lim is not None:
            ok &= np.abs(np.where(ok, z, 0.0)) <= lim
        zc = np.where(ok, z, 0.0)
        zc = self.ar.words(zc, "z")
        T = z.shape[1]
        if upsets is None:
            ups = np.zeros((0, 4), np.int64)
        else:
            if self.kind != "fixed":
                raise ValueError("upsets flip bits of fixed-point state words; use an AlphaBetaFormats arithmetic")
            ups = np.asarray(upsets, dtype=np.int64).reshape(-1, 4)
            for row in ups:
                if not (0 <= row[1] < self.trials and 0 <= row[2] < self.n and 0 <= row[3] < self.formats.x.width):
                    raise ValueError(f"upset (step, trial, element, bit) out of range: {row.tolist()}")
        xs = np.empty((self.trials, T, self.n), self.x.dtype)
        cs = np.empty((self.trials, T, 2), self.x.dtype)
        _ab_kernel(self.x, self.c, np.ascontiguousarray(zc), ok, self.adaptive, self.ring, self.rpos,
                   self.rcnt, self.consts, self.fr, self.lo, self.hi, self.hf, self.wd, self.k, ups,
                   self.ev, xs, cs)
        self.k += T
        unit = np.array([1.0, 1.0 / self.T_s, 2.0 / self.T_s ** 2][:self.n])
        if self.kind == "fixed":
            xs_f = xs * (2.0 ** -self.formats.x.frac) * unit
            cs_f = cs * 2.0 ** -self.formats.c.frac
        else:
            xs_f = xs.astype(np.float64) * unit
            cs_f = cs.astype(np.float64)
        return AlphaBetaRun(xs_f, cs_f, self.counts())


__all__ = ["AlphaBetaFilter", "AlphaBetaFormats", "AlphaBetaRun", "check_coefficients", "kalata",
           "steady_state_gains", "tracking_index", "FLOOR_SCALINGS"]
