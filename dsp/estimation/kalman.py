"""Linear Kalman filter, one source for float64 (golden), float32 and fixed point.

:class:`KalmanFilter` combines a :class:`~dsp.estimation.models.LinearGaussianModel`
(constant or time-varying F, B, H, Q, R; ``n <= 8`` states, ``m <= n`` measurements, optional
control input ``B u``) in the arithmetic of its configuration: ``"float64"``, ``"float32"``
or a :class:`KalmanFormats` table (fixed point). The kernel :func:`_kf_kernel` is written
once with the operators of :mod:`dsp.qops`; numba compiles it per state dtype.
It runs Monte Carlo trials batched (``x`` is ``(B, n)``, ``P`` ``(B, n, n)``).

Steps of one update, each one rounding in fixed point (signal names of the table)::

    xp = F x + B u                  -> x   (both sums exact, aligned, one store)
    M  = F P                        -> M
    Pp = M F^T + Q                  -> P   (upper triangle, mirrored)
    e  = z - H xp                   -> e
    PH = Pp H^T                     -> PH
    S  = H PH + R                   -> S   (upper triangle, mirrored)
    L  = chol(S)                    -> L   (sqrt and one division per element)
    W  = L^-1 PH^T                  -> W   (forward substitution, one division per element)
    K  = (L^-T W)^T                 -> K   (back substitution)
    x  = xp + K e                   -> x
    A  = I - K H                    -> A
    M  = A Pp                       -> M
    G  = K R                        -> G
    P  = M A^T + G K^T              -> P   (Joseph form, upper triangle, mirrored)

Why the Joseph form keeps P positive semi-definite in fixed point
-----------------------------------------------------------------
The short form ``P = Pp - K H Pp`` subtracts two nearly equal words: when the update is
informative the difference is a few LSBs and its rounding errors (of ``K`` and of the
product) can make it indefinite, and no later step repairs that. The Joseph form
``A Pp A^T + K R K^T`` is a congruence of ``Pp`` plus a PSD term *for any K*, so the
quantisation of ``K`` (the largest error) cannot remove definiteness; what is left is the
rounding of the products themselves, O(1 LSB) per element, against a steady-state P whose
smallest eigenvalue the formats are chosen to hold in many LSBs. The square-root form would
halve the word length P needs but costs a QR (or Cholesky update) per step; for n <= 8 with
the 32-bit covariance words used here the Joseph form already keeps P PSD (tested over
1e5 steps: smallest eigenvalue > 0, symmetric by construction). A diagonal that would still
come out negative is set to 0 and counted (``p_neg``).

Events (:class:`~dsp.estimation.events.EventRegistry`): ``sat_<signal>`` per format,
``implausible`` (a measurement that is NaN, infinite or outside ``z_limit`` / the ``z``
format: the step only predicts), ``bad_u`` (NaN control input: taken as 0), ``s_not_pd``
(the Cholesky of S met a non-positive pivot: the step only predicts), ``p_neg`` and
``upsets`` (state-word bit flips injected).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fixed import FixedFormat
from ..jit import njit_cached
from .events import EventRegistry
from .formats import Arithmetic, FormatTable, fits, fmt, need_bits, need_shift, sum_bits
from .models import LinearGaussianModel, check_psd
from .linalg import chol_q, matmul_q, solve_lower_q, solve_upper_t_q
from ..qops import align, flip, store


@dataclass(frozen=True)
class KalmanFormats(FormatTable):
    """Fixed-point formats of the linear Kalman filter, one per signal.

    The defaults suit states and covariances of order 1-100 (``x`` +-128, ``P`` +-32);
    scale the model (units) or change the table for other ranges.

    ======  ===================================================
    signal  what
    ======  ===================================================
    z       measurement
    u       control input
    x       state (also the predicted state)
    P       covariance (also the predicted covariance)
    F       transition matrix
    B       control matrix
    H       measurement matrix
    Q       process noise covariance
    R       measurement noise covariance
    e       innovation ``z - H xp``
    S       innovation covariance
    L       Cholesky factor of S
    W       forward-substitution result ``L^-1 H Pp``
    K       gain
    A       ``I - K H``
    M       the products ``F P`` and ``A Pp``
    PH      ``Pp H^T``
    G       ``K R``
    ======  ===================================================
    """

    z: FixedFormat = fmt(32, 24)
    u: FixedFormat = fmt(24, 16)
    x: FixedFormat = fmt(32, 24)
    P: FixedFormat = fmt(32, 26)
    F: FixedFormat = fmt(24, 20)
    B: FixedFormat = fmt(24, 20)
    H: FixedFormat = fmt(24, 20)
    Q: FixedFormat = fmt(32, 30)
    R: FixedFormat = fmt(32, 26)
    e: FixedFormat = fmt(32, 24)
    S: FixedFormat = fmt(32, 26)
    L: FixedFormat = fmt(30, 24)
    W: FixedFormat = fmt(30, 24)
    K: FixedFormat = fmt(24, 20)
    A: FixedFormat = fmt(24, 20)
    M: FixedFormat = fmt(32, 26)
    PH: FixedFormat = fmt(32, 26)
    G: FixedFormat = fmt(32, 28)

    def __post_init__(self):
        self.validate()

    def check(self, n: int, m: int, p: int) -> None:
        """Every exact intermediate fits int64 and every alignment is a left shift."""
        f = {s: getattr(self, s) for s in self.signals()}
        w = {s: v.width for s, v in f.items()}
        r = {s: v.frac for s, v in f.items()}
        # predict x
        c = max(r["F"] + r["x"], r["B"] + r["u"])
        need_bits("F x + B u", max(sum_bits(w["F"], w["x"], n) + c - r["F"] - r["x"],
                                   sum_bits(w["B"], w["u"], p) + c - r["B"] - r["u"]) + 1)
        need_shift("F x + B u", c - r["x"], "x")
        need_bits("F P", sum_bits(w["F"], w["P"], n))
        need_shift("F P", r["F"] + r["P"] - r["M"], "M")
        a = r["M"] + r["F"]
        need_bits("M F^T + Q", max(sum_bits(w["M"], w["F"], n), w["Q"] + need_shift("M F^T + Q", a - r["Q"], "Q")) + 1)
        need_shift("M F^T + Q", a - r["P"], "P")
        a = r["H"] + r["x"]
        need_bits("z - H xp", max(sum_bits(w["H"], w["x"], n), w["z"] + need_shift("z - H xp", a - r["z"], "z")) + 1)
        need_shift("z - H xp", a - r["e"], "e")
        need_bits("Pp H^T", sum_bits(w["P"], w["H"], n))
        need_shift("Pp H^T", r["P"] + r["H"] - r["PH"], "PH")
        a = r["H"] + r["PH"]
        need_bits("H PH + R", max(sum_bits(w["H"], w["PH"], n), w["R"] + need_shift("H PH + R", a - r["R"], "R")) + 1)
        need_shift("H PH + R", a - r["S"], "S")
        a = 2 * r["L"]
        need_bits("Cholesky of S", max(sum_bits(w["L"], w["L"], m), w["S"] + need_shift("Cholesky of S", a - r["S"], "S")) + 1)
        if w["L"] > 53:
            raise ValueError(f"formats too wide: L must have at most 53 bits (the divisor of an "
                             f"exact float-assisted division), not {w['L']}")
        a = r["L"] + r["W"]
        need_bits("L^-1 PH^T", max(sum_bits(w["L"], w["W"], m), w["PH"] + need_shift("L^-1 PH^T", a - r["PH"], "PH")) + 1)
        a = r["L"] + r["K"]
        need_bits("L^-T W", max(sum_bits(w["L"], w["K"], m), w["W"] + need_shift("L^-T W", a - r["W"], "W")) + 1)
        a = r["K"] + r["e"]
        need_bits("xp + K e", max(sum_bits(w["K"], w["e"], m), w["x"] + need_shift("xp + K e", a - r["x"], "x")) + 1)
        a = r["K"] + r["H"]
        need_bits("I - K H", sum_bits(w["K"], w["H"], m) + 1)
        need_shift("I - K H", a - r["A"], "A")
        if a > 61:
            raise ValueError(f"formats too wide: K and H fraction bits sum to {a} (> 61)")
        need_bits("A Pp", sum_bits(w["A"], w["P"], n))
        need_shift("A Pp", r["A"] + r["P"] - r["M"], "M")
        need_bits("K R", sum_bits(w["K"], w["R"], m))
        need_shift("K R", r["K"] + r["R"] - r["G"], "G")
        c = max(r["M"] + r["A"], r["G"] + r["K"])
        need_bits("M A^T + G K^T", max(sum_bits(w["M"], w["A"], n) + c - r["M"] - r["A"],
                                       sum_bits(w["G"], w["K"], m) + c - r["G"] - r["K"]) + 1)
        need_shift("M A^T + G K^T", c - r["P"], "P")


SIGNALS = KalmanFormats.signals()
EVENTS = EventRegistry(SIGNALS, ("implausible", "bad_u", "s_not_pd", "p_neg", "upsets"))
# Kernel indices, by name from the one table (numba folds module-level ints to constants).
_Z, _U, _X, _P, _F, _B, _H, _Q, _R, _E, _S, _L, _W, _K, _A, _M, _PH, _G = (
    SIGNALS.index(s) for s in ("z", "u", "x", "P", "F", "B", "H", "Q", "R", "e", "S", "L",
                               "W", "K", "A", "M", "PH", "G"))
_EV_IMPL = EVENTS.index("implausible")
_EV_BADU = EVENTS.index("bad_u")
_EV_SNPD = EVENTS.index("s_not_pd")
_EV_PNEG = EVENTS.index("p_neg")
_EV_UPS = EVENTS.index("upsets")
_BASE = EVENTS.base
#: Upset targets (column 2 of an upset row).
UPSET_TARGETS = ("x", "P")


@njit_cached
def _kf_kernel(x, P, z, zok, u, uok, F, B, H, Q, R, k0, fr, lo, hi, hf, wd, one, ev, ups,
               xs, Ps, keep_P):
    nb, n = x.shape
    T, m = z.shape[1], z.shape[2]
    p = u.shape[2]
    z0 = x[0, 0] - x[0, 0]
    xp = np.empty(n, x.dtype)
    Pp = np.empty((n, n), x.dtype)
    Mt = np.empty((n, n), x.dtype)
    A = np.empty((n, n), x.dtype)
    e = np.empty(m, x.dtype)
    PH = np.empty((n, m), x.dtype)
    S = np.empty((m, m), x.dtype)
    L = np.zeros((m, m), x.dtype)
    W = np.empty((m, n), x.dtype)
    K = np.empty((n, m), x.dtype)
    G = np.empty((n, m), x.dtype)
    for b in range(nb):
        eb = ev[b]
        for k in range(T):
            kg = k0 + k
            kF = kg if F.shape[0] > 1 else 0
            kB = kg if B.shape[0] > 1 else 0
            kH = kg if H.shape[0] > 1 else 0
            kQ = kg if Q.shape[0] > 1 else 0
            kR = kg if R.shape[0] > 1 else 0
            for r in range(ups.shape[0]):
                if ups[r, 0] == kg and ups[r, 1] == b:
                    eb[_EV_UPS] += 1
                    el = ups[r, 3]
                    if ups[r, 2] == 0:
                        x[b, el] = flip(x[b, el], ups[r, 4], wd[_X])
                    else:
                        i, j = el // n, el % n
                        P[b, i, j] = flip(P[b, i, j], ups[r, 4], wd[_P])
                        P[b, j, i] = P[b, i, j]
            # -- predict
            c = max(fr[_F] + fr[_X], fr[_B] + fr[_U])
            ubad = not uok[b, k]
            if ubad and p > 0:
                eb[_EV_BADU] += 1
            for i in range(n):
                acc = z0
                for j in range(n):
                    acc += F[kF, i, j] * x[b, j]
                acc2 = z0
                if not ubad:
                    for l in range(p):
                        acc2 += B[kB, i, l] * u[b, k, l]
                acc = align(acc, c - fr[_F] - fr[_X]) + align(acc2, c - fr[_B] - fr[_U])
                xp[i] = store(acc, c - fr[_X], hf[_X], lo[_X], hi[_X], eb, _X, _BASE)
            matmul_q(F[kF], P[b], Mt, False, fr[_F] + fr[_P] - fr[_M], hf[_M], lo[_M], hi[_M], eb, _M, _BASE)
            a = fr[_M] + fr[_F]
            for i in range(n):
                for j in range(i, n):
                    acc = z0
                    for l in range(n):
                        acc += Mt[i, l] * F[kF, j, l]
                    acc += align(Q[kQ, i, j], a - fr[_Q])
                    v = store(acc, a - fr[_P], hf[_P], lo[_P], hi[_P], eb, _P, _BASE)
                    Pp[i, j] = v
                    Pp[j, i] = v
            if not zok[b, k]:
                eb[_EV_IMPL] += 1
                for i in range(n):
                    x[b, i] = xp[i]
                    for j in range(n):
                        P[b, i, j] = Pp[i, j]
            else:
                # -- innovation and its covariance
                a = fr[_H] + fr[_X]
                for r in range(m):
                    acc = align(z[b, k, r], a - fr[_Z])
                    for j in range(n):
                        acc -= H[kH, r, j] * xp[j]
                    e[r] = store(acc, a - fr[_E], hf[_E], lo[_E], hi[_E], eb, _E, _BASE)
                matmul_q(Pp, H[kH], PH, True, fr[_P] + fr[_H] - fr[_PH], hf[_PH], lo[_PH], hi[_PH], eb, _PH, _BASE)
                a = fr[_H] + fr[_PH]
                for r in range(m):
                    for c2 in range(r, m):
                        acc = z0
                        for j in range(n):
                            acc += H[kH, r, j] * PH[j, c2]
                        acc += align(R[kR, r, c2], a - fr[_R])
                        v = store(acc, a - fr[_S], hf[_S], lo[_S], hi[_S], eb, _S, _BASE)
                        S[r, c2] = v
                        S[c2, r] = v
                ok = chol_q(S, L, 2 * fr[_L] - fr[_S], hf[_L], lo[_L], hi[_L], eb, _L, _EV_SNPD, _BASE)
                if not ok:
                    eb[_EV_SNPD] += 1
                    for i in range(n):
                        x[b, i] = xp[i]
                        for j in range(n):
                            P[b, i, j] = Pp[i, j]
                else:
                    # -- gain: W = L^-1 PH^T, K^T = L^-T W
                    solve_lower_q(L, PH, W, fr[_L] + fr[_W] - fr[_PH], hf[_W], lo[_W], hi[_W], eb, _W,
                                  _EV_SNPD, _BASE)
                    solve_upper_t_q(L, W, K, fr[_L] + fr[_K] - fr[_W], hf[_K], lo[_K], hi[_K], eb, _K,
                                    _EV_SNPD, _BASE)
                    # -- state
                    a = fr[_K] + fr[_E]
                    for i in range(n):
                        acc = align(xp[i], a - fr[_X])
                        for r in range(m):
                            acc += K[i, r] * e[r]
                        x[b, i] = store(acc, a - fr[_X], hf[_X], lo[_X], hi[_X], eb, _X, _BASE)
                    # -- Joseph-form covariance
                    a = fr[_K] + fr[_H]
                    for i in range(n):
                        for j in range(n):
                            acc = one[0] if i == j else z0
                            for r in range(m):
                                acc -= K[i, r] * H[kH, r, j]
                            A[i, j] = store(acc, a - fr[_A], hf[_A], lo[_A], hi[_A], eb, _A, _BASE)
                    matmul_q(A, Pp, Mt, False, fr[_A] + fr[_P] - fr[_M], hf[_M], lo[_M], hi[_M], eb, _M, _BASE)
                    matmul_q(K, R[kR], G, False, fr[_K] + fr[_R] - fr[_G], hf[_G], lo[_G], hi[_G], eb, _G, _BASE)
                    c = max(fr[_M] + fr[_A], fr[_G] + fr[_K])
                    for i in range(n):
                        for j in range(i, n):
                            acc = z0
                            for l in range(n):
                                acc += Mt[i, l] * A[j, l]
                            acc2 = z0
                            for r in range(m):
                                acc2 += G[i, r] * K[j, r]
                            acc = align(acc, c - fr[_M] - fr[_A]) + align(acc2, c - fr[_G] - fr[_K])
                            v = store(acc, c - fr[_P], hf[_P], lo[_P], hi[_P], eb, _P, _BASE)
                            if i == j and v < z0:
                                eb[_EV_PNEG] += 1
                                v = z0
                            P[b, i, j] = v
                            P[b, j, i] = v
            for i in range(n):
                xs[b, k, i] = x[b, i]
            if keep_P:
                for i in range(n):
                    for j in range(n):
                        Ps[b, k, i, j] = P[b, i, j]


def _as_trials(name: str, a, trials: int, tail: tuple) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.shape == tail:
        return np.broadcast_to(a, (trials,) + tail).copy()
    if a.shape == (trials,) + tail:
        return a.copy()
    raise ValueError(f"{name} must have shape {tail} or {(trials,) + tail}, not {a.shape}")


@dataclass
class KalmanRun:
    """What :meth:`KalmanFilter.run` returns: states after each step (real values,
    ``(B, T, n)``), covariances if kept (``(B, T, n, n)``) and the events of the run."""

    x: np.ndarray
    P: np.ndarray | None
    events: dict


class KalmanFilter:
    """Linear Kalman filter (Joseph-form update), batched over trials.

    Parameters
    ----------
    model : LinearGaussianModel
        F, B, H, Q, R (constant or time-varying).
    x0 : (n,) or (B, n) array
        Initial state.
    P0 : (n, n) or (B, n, n) array
        Initial covariance, symmetric positive semi-definite.
    arithmetic : {"float64", "float32"} or KalmanFormats
        The arithmetic the one kernel runs in.
    trials : int
        Monte Carlo trials run side by side (``B``).
    z_limit : float, optional
        Largest plausible ``|z|``; beyond it (or NaN) the step only predicts (counted
        ``implausible``). Fixed point: also the ``z`` format's range.
    """

    def __init__(self, model: LinearGaussianModel, x0, P0, arithmetic="float64", trials: int = 1,
                 z_limit: float | None = None):
        if not isinstance(model, LinearGaussianModel):
            raise ValueError(f"model must be a LinearGaussianModel, not {model!r}")
        if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials < 1:
            raise ValueError(f"trials must be an integer >= 1, not {trials!r}")
        if z_limit is not None and not (np.isfinite(z_limit) and z_limit > 0):
            raise ValueError(f"z_limit must be a finite number > 0 or None, not {z_limit!r}")
        self.model, self.trials, self.z_limit = model, int(trials), z_limit
        self.ar = ar = Arithmetic.of(arithmetic, KalmanFormats, "Kalman filter")
        self.kind, self.formats = ar.kind, ar.formats
        self.fr, self.lo, self.hi, self.hf, self.wd = ar.arrays
        n, m, p = model.n, model.m, model.p
        x0 = _as_trials("x0", x0, self.trials, (n,))
        P0 = _as_trials("P0", P0, self.trials, (n, n))
        if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(P0))):
            raise ValueError("x0 and P0 must be finite")
        check_psd("P0", P0)
        self.events = EVENTS
        self.k = 0
        if ar.fixed:
            ar.formats.check(n, m, p)
        self.x = ar.words(x0, "x", "x0")
        self.P = ar.words(P0, "P", "P0")
        mats = {"F": model.F, "B": model.B, "H": model.H, "Q": model.Q, "R": model.R}
        if ar.fixed:
            for name in ("F", "H", "Q", "R", "B"):
                fits(name, mats[name], getattr(ar.formats, name))
        self._mats = tuple(ar.words(a, name) for name, a in mats.items())
        if ar.fixed:
            self.P = np.triu(self.P) + np.triu(self.P, 1).transpose(0, 2, 1)
            self._one = np.array([1 << (ar.formats.K.frac + ar.formats.H.frac)], np.int64)
        else:
            self._one = np.ones(1, ar.dtype)
        self.ev = EVENTS.new((self.trials,))

    # -- state in real units
    def x_float(self) -> np.ndarray:
        return self.ar.physical(self.x, "x")

    def P_float(self) -> np.ndarray:
        return self.ar.physical(self.P, "P")

    def counts(self) -> dict:
        return EVENTS.counts(self.ev)

    def _inputs(self, z, u):
        p = self.model.p
        zc, ok, T = self.ar.measurements(z, self.model.m, self.trials, self.z_limit)
        if u is None:
            if p:
                raise ValueError(f"the model has a control input (p = {p}): give u")
            uc = np.zeros((self.trials, T, 0))
            uok = np.ones((self.trials, T), bool)
        else:
            uc = np.asarray(u, dtype=np.float64)
            if uc.ndim == 1 and p == 1:
                uc = uc[:, None]
            if uc.ndim == 2:
                uc = np.broadcast_to(uc, (self.trials,) + uc.shape)
            if uc.shape != (self.trials, T, p):
                raise ValueError(f"u must have shape ({T}, {p}) or ({self.trials}, {T}, {p}), not {np.shape(u)}")
            uok = np.all(np.isfinite(uc), axis=2)
            uc = np.where(uok[..., None], uc, 0.0)
            if self.kind == "fixed":
                fu = self.formats.u
                big = np.any((uc > fu.max_value) | (uc < fu.min_value), axis=2)
                uok &= ~big
                uc = np.where(uok[..., None], uc, 0.0)
        return self.ar.words(zc, "z"), ok, self.ar.words(uc, "u"), uok, T

    def run(self, z, u=None, *, upsets=None, keep_P: bool = False) -> KalmanRun:
        """Filter ``T`` steps (predict then update with ``z[k]``).

        Parameters
        ----------
        z : (T, m) or (B, T, m) array (or (T,) for m = 1)
            Measurements; NaN or implausible values are counted and skipped.
        u : (T, p) or (B, T, p) array, optional
            Control inputs (required when the model has ``B``).
        upsets : (U, 5) int array, optional
            Fixed point only: state-word bit flips ``(step, trial, target, element, bit)``
            applied before step ``step`` (global step count), ``target`` an index of
            :data:`UPSET_TARGETS`, ``element`` the flat index in ``x`` or ``P`` (a flip in
            ``P[i, j]`` is mirrored: the core stores one triangle).
        keep_P : bool
            Also return the covariance after every step.
        """
        zc, zok, uc, uok, T = self._inputs(z, u)
        steps = self.model.steps
        if steps is not None and self.k + T > steps:
            raise ValueError(f"the time-varying model covers {steps} steps, not {self.k + T}")
        n = self.model.n
        if upsets is None:
            ups = np.zeros((0, 5), np.int64)
        else:
            if self.kind != "fixed":
                raise ValueError("upsets flip bits of fixed-point state words; use a KalmanFormats arithmetic")
            ups = np.asarray(upsets, dtype=np.int64).reshape(-1, 5)
            w = {0: self.formats.x.width, 1: self.formats.P.width}
            for row in ups:
                if row[2] not in (0, 1) or not 0 <= row[3] < (n if row[2] == 0 else n * n) \
                        or not 0 <= row[4] < w[int(row[2])] or not 0 <= row[1] < self.trials:
                    raise ValueError(f"upset (step, trial, target, element, bit) out of range: {row.tolist()}")
        xs = np.empty((self.trials, T, n), self.x.dtype)
        Ps = np.empty((self.trials, T if keep_P else 0, n, n), self.x.dtype)
        F, B, H, Q, R = self._mats
        _kf_kernel(self.x, self.P, zc, zok, uc, uok, F, B, H, Q, R, self.k, self.fr, self.lo,
                   self.hi, self.hf, self.wd, self._one, self.ev, ups, xs, Ps, keep_P)
        self.k += T
        return KalmanRun(self.ar.physical(xs, "x"),
                         self.ar.physical(Ps, "P") if keep_P else None, self.counts())
