"""The INS paper's carrier tracking loops: the (INS-aided) 3rd-order Kalman loop and the
INS-aided 3rd-order PLL, registered as GNSS trackers ``aided-kf``, ``unaided-kf``,
``aided-pll``.

Kalman loop (docs/explanation/ins.md; O'Driscoll & Lachapelle 2011 for the form). State at the end
of interval ``k`` (NCO frequency ``f_k`` in force over it), units cycles, Hz, Hz/s::

    x = [theta - phi_nco,  f_D - f_k,  r_res]

``r_res`` is the part of the Doppler rate the loop estimates: the whole rate unaided, the
INS's error aided (rate = ``u + r_res``, ``u`` the INS Doppler rate). Transition and
control (``Delta f = f_{k+1} - f_k`` is the NCO's own step, a known input)::

    x' = A x + B [u, Delta f],   A = [[1, T, T^2/2], [0, 1, T], [0, 0, 1]],
    B = [[T^2/2, -T], [T, -1], [0, 0]]   (aided; the u column is 0 unaided)

Measurement: the Costas discriminator's phase over the interval, the state's phase
averaged over it: ``z = e - u T^2/6 = H x``, ``H = [1, -T/2, T^2/6]``;
``R = (1/(2 T C/N0)) (1 + 1/(2 T C/N0)) / (2 pi)^2`` cycles^2 (Kaplan & Hegarty, atan).
Process noise: the receiver clock (two-state model from h0, h-2 at L1: white phase
``q_phi = h0/2 L1^2`` cycles^2/s, frequency random walk ``q_f = 2 pi^2 h-2 L1^2``
Hz^2/s) plus a rate random walk ``q_r`` (Hz^2/s^3) for the line-of-sight dynamics
(unaided: the 5 g/s jerk over 1 s, ``(J / lambda)^2``; aided: the INS rate error's drift).
NCO: ``Delta f = x2 + T/2 (x3 + u_{k+1}) + x1/T``, which puts the predicted phase error
at the next interval's end to 0. With a loop latency of ``L`` epochs
(``TrackerContext.latency_epochs``: 1 on the HDL channel, whose writes take effect at the
next dump boundary) the step issued after epoch ``k`` is in force from interval
``k + 1 + L``: the state is first carried over the ``L`` intervals whose steps are already
issued (the same A, B), the control input of each prediction is the step in force then,
and the Doppler estimate refers to the frequency in force over the interval just dumped.
On a hand-over (``TrackerContext.doppler0_sigma_hz`` given) P0 takes the Costas phase as
uniform (1/48 cycles^2) and the Doppler variance from the hand-over error. The filter is :class:`dsp.estimation.kalman.KalmanFilter`
(float64 or fixed point by its :class:`KalmanFormats`); Delta f is computed from the
filter's (real-valued) state and rounded into the ``u`` format, so the NCO follows exactly
what the filter was told.

Aided PLL: ``dsp.gnss.loops_fixed.ChannelCore`` (Kaplan a3 1.1, b3 2.4, w0 = Bn/0.7845,
Bn 15 Hz) with the INS rate fed forward into its frequency integrator
(``v1 += T u`` each epoch, in the core's arithmetic), so its rate integrator holds only the
INS error. The hand-over gives a frequency but not the carrier phase: the first tracked
epoch aligns the phase (``ChannelCore.step(align=True)``: the NCO runs ``v1 + e0 / T`` for
one interval, the integrators untouched) and, until that interval has been seen, the
discriminator is read less the correction still to come (``e0`` over the ``latency``
epochs before it is in force, ``e0 / 2`` over the interval it is: the phase error's mean
there) -- without it a phase near a quarter cycle kicks the rate integrator (``K3 e`` per
epoch) and the loop needs over 100 ms to settle. Both loops close a carrier-aided 1st-order DLL (4 Bn_dll chips/s per chip).

PLI: ``(I^2 - Q^2) / (I^2 + Q^2)`` of the prompt summed over ``pli_epochs``.
"""
from __future__ import annotations

import math

import numpy as np

from dsp.gnss.oscillator import oscillator as _oscillator
from dsp.estimation.formats import fmt, to_fixed
from dsp.estimation.kalman import KalmanFilter, KalmanFormats
from dsp.estimation.models import LinearGaussianModel
from dsp.gnss.ca_code import CHIP_RATE_HZ, L1_HZ
from dsp.gnss.ephemeris import L1_WAVELENGTH_M
from dsp.gnss.discriminators import costas_atan, dll_nelp
from dsp.gnss.trackers import register_tracker

G_MPS2 = 9.80665

#: Fixed-point table of the Kalman loop on the scaled state (below): rate up to +-7800 Hz/s,
#: covariance resolution 2^-34; ``check(3, 1, 2)`` passes (every product fits int64).
KF_FORMATS = KalmanFormats(z=fmt(24, 22), u=fmt(32, 26), x=fmt(32, 26), P=fmt(36, 34),
                           F=fmt(24, 20), B=fmt(24, 20), H=fmt(24, 22), Q=fmt(36, 38),
                           R=fmt(24, 22), e=fmt(24, 22), S=fmt(32, 30), L=fmt(30, 28),
                           W=fmt(32, 30), K=fmt(24, 22), A=fmt(24, 22), M=fmt(36, 34),
                           PH=fmt(36, 34), G=fmt(36, 34))
#: The filter runs on the scaled state ``x_s = [x1, x2 T 2^a, x3 T^2 2^b]`` (cycles,
#: cycles/epoch, cycles/epoch^2, times powers of two) so that its elements and variances
#: have like magnitudes; A, B, H stay exact in fixed point (powers of two but 1/6).
SCALE_BITS = (5, 12)


def _finite(name, v, lo=None, strict=False):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v) or (lo is not None and (v <= lo if strict else v < lo)):
        rule = "" if lo is None else (f" > {lo}" if strict else f" >= {lo}")
        raise ValueError(f"{name} must be a finite number{rule}, not {v!r}")
    return float(v)


def r_from_cn0(cn0_dbhz: float, T_s: float) -> float:
    """Arctan discriminator variance (cycles^2) at ``cn0_dbhz``."""
    c = 10.0 ** (_finite("cn0_dbhz", cn0_dbhz) / 10.0)
    x = 1.0 / (2.0 * T_s * c)
    return x * (1.0 + x) / (2.0 * math.pi) ** 2


def kf_model_matrices(T_s: float, h0: float, h_2: float, q_rate: float, r: float, aided: bool):
    """``A, B, H, Q, R`` of the Kalman loop (see the module docstring)."""
    T = _finite("T_s", T_s, 0.0, strict=True)
    _finite("h0", h0, 0.0)
    _finite("h_2", h_2, 0.0)
    _finite("q_rate", q_rate, 0.0)
    _finite("R", r, 0.0, strict=True)
    A = np.array([[1.0, T, T * T / 2], [0.0, 1.0, T], [0.0, 0.0, 1.0]])
    B = np.array([[T * T / 2 if aided else 0.0, -T], [T if aided else 0.0, -1.0], [0.0, 0.0]])
    H = np.array([[1.0, -T / 2, T * T / 6]])
    qp, qf = h0 / 2 * L1_HZ ** 2, 2 * math.pi ** 2 * h_2 * L1_HZ ** 2
    Q = q_rate * np.array([[T ** 5 / 20, T ** 4 / 8, T ** 3 / 6],
                           [T ** 4 / 8, T ** 3 / 3, T ** 2 / 2],
                           [T ** 3 / 6, T ** 2 / 2, T]])
    Q[:2, :2] += qf * np.array([[T ** 3 / 3, T ** 2 / 2], [T ** 2 / 2, T]])
    Q[0, 0] += qp * T
    return A, B, H, Q, np.array([[r]])


def default_q_rate(aided: bool, jerk_g_s: float = 5.0, ins_rate_drift_hz_s2: float = 1.0) -> float:
    """Rate random-walk intensity (Hz^2/s^3): unaided ``(J/lambda)^2`` per second for the
    line-of-sight jerk; aided ``ins_rate_drift^2`` (the INS rate error's rate of change:
    gyro drift times 50 g is ~0.13 Hz/s^2, sensor noise and the tilt's growth add to it;
    1 Hz/s^2 default)."""
    if aided:
        return _finite("ins_rate_drift_hz_s2", ins_rate_drift_hz_s2, 0.0) ** 2
    return (_finite("jerk_g_s", jerk_g_s, 0.0) * G_MPS2 / L1_WAVELENGTH_M) ** 2


class _History:
    """Per-epoch records kept by the trackers for the study (lists of batch arrays)."""

    def __init__(self, pli_epochs: int):
        self.pli_epochs = int(pli_epochs)
        self.disc, self.dopp, self.code_hz = [], [], []
        self._si = self._sq = None
        self._n = 0
        self.pli = []

    def add(self, e, ip, qp, dopp):
        self.disc.append(np.asarray(e, float))
        self.dopp.append(np.asarray(dopp, float))
        self._si = ip if self._si is None else self._si + ip
        self._sq = qp if self._sq is None else self._sq + qp
        self._n += 1
        if self._n == self.pli_epochs:
            i2, q2 = self._si ** 2, self._sq ** 2
            self.pli.append((i2 - q2) / np.where(i2 + q2 > 0, i2 + q2, 1.0))
            self._si = self._sq = None
            self._n = 0

    def arrays(self):
        return {"disc_cycles": np.array(self.disc), "doppler_hz": np.array(self.dopp),
                "pli": np.array(self.pli)}


def _check_aiding_value(u, k):
    u = np.asarray(u, float)
    if not np.all(np.isfinite(u)):
        raise ValueError(f"aiding must give a finite Doppler rate (Hz/s); epoch {k} gave {u!r}")
    return u


class KalmanCarrierLoop:
    """3rd-order Kalman carrier loop (aided or unaided) + carrier-aided DLL; a tracker
    of :mod:`dsp.gnss.trackers` (``step``, ``frequencies_hz``, ``doppler_hz``,
    ``report``). ``history`` holds the discriminator, Doppler estimate and PLI series.
    The Doppler estimate after epoch ``k`` is the state's, at the end of interval ``k``."""

    doppler_offset_epochs = 0.0

    def __init__(self, ctx, arith, aided: bool, cn0_dbhz: float | None = None,
                 oscillator="tcxo", q_rate: float | None = None, dll_bn_hz: float = 1.0,
                 formats: KalmanFormats | None = None, pli_epochs: int = 10,
                 p0_diag=(1e-3, 1.0, 1.0)):
        T = _finite("T_s", ctx.T_s, 0.0, strict=True)
        self.T, self.aided, self.fs = T, bool(aided), float(ctx.fs_hz)
        if self.aided and ctx.aiding is None:
            raise ValueError("aided Kalman loop needs ctx.aiding (the INS Doppler rate per epoch)")
        self.aiding = ctx.aiding if self.aided else None
        cn0 = cn0_dbhz if cn0_dbhz is not None else (ctx.cn0_dbhz if ctx.cn0_dbhz is not None else 40.0)
        osc = _oscillator(oscillator)
        h0, h2 = (0.0, 0.0) if osc is None else (osc.h0, osc.h_2)
        q = default_q_rate(self.aided) if q_rate is None else q_rate
        self.A, self.B, self.H, self.Q, self.R = kf_model_matrices(T, h0, h2, q, r_from_cn0(cn0, T), self.aided)
        a, b = SCALE_BITS
        self.D = np.diag([1.0, 2.0 ** -a / T, 2.0 ** -b / T ** 2])      # x = D x_s
        self.Du = np.array([T * T * 2.0 ** b, T * 2.0 ** a])             # u_s = Du u
        Di = np.linalg.inv(self.D)
        self.model = LinearGaussianModel(Di @ self.A @ self.D, self.H @ self.D, Di @ self.Q @ Di,
                                         self.R, Di @ self.B @ np.diag(1.0 / self.Du))
        self.f = np.asarray(ctx.doppler0_hz, float).copy()
        shape = self.f.shape
        trials = int(np.prod(shape)) if shape else 1
        self.shape, self.trials = shape, trials
        r0 = 0.0 if self.aided else np.broadcast_to(np.asarray(ctx.doppler_rate0_hz_s, float), shape).reshape(trials)
        x0 = np.zeros((trials, 3))
        x0[:, 2] = r0 / self.D[2, 2]
        p0_diag = tuple(p0_diag)
        if ctx.doppler0_sigma_hz is not None:
            # a hand-over from acquisition: the carrier phase is unknown (uniform over the
            # Costas half cycle) and the Doppler is off by the hand-over error
            p0_diag = (max(p0_diag[0], 1.0 / 48.0), max(p0_diag[1], float(ctx.doppler0_sigma_hz) ** 2),
                       p0_diag[2])
        p0 = np.diag(p0_diag) / np.outer(np.diag(self.D), np.diag(self.D))
        self.fixed = bool(getattr(arith, "fixed", False))
        self.formats = (formats or KF_FORMATS) if self.fixed else None
        self.kf = KalmanFilter(self.model, x0, p0, self.formats if self.fixed else "float64",
                               trials=trials, z_limit=0.5)
        self.k = 0
        self.u = self._u(0)
        self.df = np.zeros(trials)
        # loop latency: a step's NCO setting takes effect ``latency`` epochs later; the
        # steps already issued but not yet in force (oldest first)
        self.latency = int(ctx.latency_epochs)
        if self.latency < 0:
            raise ValueError(f"latency_epochs must be >= 0, not {ctx.latency_epochs!r}")
        self.pending = [np.zeros(trials) for _ in range(self.latency)]
        self.f_cmd = self.f.copy()
        self.d = float(ctx.spacing_chips)
        self.kd = 4.0 * _finite("dll_bn_hz", dll_bn_hz, 0.0)
        self.if_hz, self.s = float(ctx.if_hz), (-1 if ctx.inverted else 1)
        self.history = _History(pli_epochs)
        self._dopp = self.f.copy()

    def _u(self, k):
        if not self.aided:
            return np.zeros(self.trials)
        return np.broadcast_to(_check_aiding_value(self.aiding(k), k), self.shape).reshape(self.trials)

    def _q(self, v):
        """Delta f (Hz) as the filter's u format holds it."""
        if not self.fixed:
            return v
        f = self.formats.u
        return to_fixed(v * self.Du[1], f) * 2.0 ** -f.frac / self.Du[1]

    def doppler_hz(self):
        return self._dopp

    def step(self, ie, qe, ip, qp, il, ql):
        ip, qp = np.asarray(ip, float), self.s * np.asarray(qp, float)
        e = costas_atan(ip, qp)
        T = self.T
        z = (e.reshape(self.trials) - self.u * T * T / 6)[:, None, None]
        uu = (np.stack([self.u, self.df], axis=-1) * self.Du)[:, None, :]
        x = self.kf.run(z, uu).x[:, 0, :] @ self.D
        self._dopp = (self.f.reshape(self.trials) + x[:, 1]).reshape(self.shape)
        u_next = self._u(self.k + 1)
        # carry the state over the intervals whose NCO steps are issued but not in force
        # (latency), then set the next free step so the predicted phase error at the end
        # of its interval is 0
        x1, x2, x3 = x[:, 0], x[:, 1], x[:, 2]
        for j, d in enumerate(self.pending):
            uj = u_next if j == 0 else self._u(self.k + 1 + j)
            x1, x2 = x1 + T * x2 + T * T / 2 * (x3 + uj) - T * d, x2 + T * (x3 + uj) - d
        u_free = u_next if not self.pending else self._u(self.k + 1 + self.latency)
        df = self._q(x2 + T / 2 * (x3 + u_free) + x1 / T)
        self.f_cmd = self.f_cmd + df.reshape(self.shape)
        self.pending.append(df)
        df = self.pending.pop(0)              # the step in force from the next epoch on
        self.f = self.f + df.reshape(self.shape)
        self.u, self.df = u_next, df
        self.k += 1
        tau = dll_nelp(ie, qe, il, ql, self.d)
        self.history.add(e, ip, qp, self._dopp)
        fc = self.if_hz + self.s * self.f_cmd
        kc = CHIP_RATE_HZ + self.f_cmd / 1540.0 + self.kd * tau
        if not self.fixed:
            return fc, kc
        return np.rint(fc * 2.0 ** 32 / self.fs).astype(np.int64), np.rint(kc * 2.0 ** 32 / self.fs).astype(np.int64)

    def frequencies_hz(self, out):
        if not self.fixed:
            return out
        cw, kw = out
        return cw * self.fs / 2.0 ** 32, kw * self.fs / 2.0 ** 32

    def steady_gain(self):
        """The steady-state Kalman gain (3,) of this model (discrete Riccati equation)."""
        return steady_state_gain(self.A, self.H, self.Q, self.R)

    def report(self):
        return {"events": {k: int(np.sum(v)) for k, v in self.kf.counts().items()}}


def steady_state_gain(A, H, Q, R):
    """Steady-state gain of the predict-then-update filter (``scipy`` DARE)."""
    from scipy.linalg import solve_discrete_are
    Pp = solve_discrete_are(A.T, H.T, Q, R)
    S = H @ Pp @ H.T + R
    return (Pp @ H.T / S).ravel()


class AidedPll:
    """Kaplan 3rd-order Costas PLL (``ChannelCore``) with the INS Doppler rate fed
    forward into its frequency integrator. Its Doppler estimate after epoch ``k`` is the
    frequency of the interval it is in force, ``k + 1 + latency`` (``ctx.latency_epochs``):
    ``doppler_offset_epochs`` = 0.5 + latency (it stands for that interval's midpoint)."""

    def __init__(self, ctx, arith, bn_hz: float = 15.0, dll_bn_hz: float = 1.0, pli_epochs: int = 10):
        from dsp.gnss.loops_fixed import T_FRAC, V1, V2, ChannelCore
        if ctx.aiding is None:
            raise ValueError("aided PLL needs ctx.aiding (the INS Doppler rate per epoch)")
        _finite("T_s", ctx.T_s, 0.0, strict=True)
        _finite("bn_hz", bn_hz, 0.0, strict=True)
        self.aiding = ctx.aiding
        self.latency = int(ctx.latency_epochs)
        self.doppler_offset_epochs = 0.5 + self.latency
        self.core = ChannelCore(arith, ctx.fs_hz, ctx.T_s, 3, bn_hz, dll_bn_hz, ctx.spacing_chips,
                                ctx.if_hz, ctx.inverted, np.asarray(ctx.doppler0_hz, float),
                                0.0 * np.asarray(ctx.doppler_rate0_hz_s, float), True)
        self._fmt = (V1, V2, T_FRAC)
        self.shape = np.shape(self.core.v1)
        self.k = 0
        self.history = _History(pli_epochs)

    def doppler_hz(self):
        return self.core.doppler_hz()

    def step(self, ie, qe, ip, qp, il, ql):
        o, (V1, V2, T_FRAC) = self.core.o, self._fmt
        # v1 after this step is the frequency of interval k+1: it moves by the rate at the
        # boundary, the mean of the two epochs' midpoint rates
        if self.k == 0:
            self._u = _check_aiding_value(self.aiding(0), 0)
        u1 = _check_aiding_value(self.aiding(self.k + 1), self.k + 1)
        u = np.broadcast_to((self._u + u1) / 2, self.shape)
        self._u = u1
        self.core.v1 = o.add(self.core.v1, o.mul(o.q(u, V2), self.core.KT, V2.frac + T_FRAC - V1.frac), V1)
        L = self.latency
        if self.k == 0:                 # the hand-over's phase alignment (module doc)
            out = self.core.step(ie, qe, ip, qp, il, ql, align=True)
            self._e0 = self.core.e
        elif self.k <= L + 1:           # the alignment not yet (fully) in the interval seen
            off = self._e0 if self.k <= L else (o.mul(self._e0, 1, 1) if o.fixed
                                                 else self._e0 / 2)
            out = self.core.step(ie, qe, ip, qp, il, ql, phase_offset=off)
        else:
            out = self.core.step(ie, qe, ip, qp, il, ql)
        e = self.core.e * 2.0 ** -15 if o.fixed else self.core.e
        self.history.add(e, np.asarray(ip, float), self.core.s * np.asarray(qp, float), self.core.doppler_hz())
        self.k += 1
        return out

    def frequencies_hz(self, out):
        return self.core.frequencies_hz(out)

    def report(self):
        return {"saturations": {f"{k.bits}.{k.frac}": v for k, v in getattr(self.core.o, "sat", {}).items()}}


def _kf(aided):
    def make(ctx, arith, **opts):
        return KalmanCarrierLoop(ctx, arith, aided, **opts)
    return make


register_tracker("aided-kf", _kf(True), "the INS paper's INS-aided 3rd-order Kalman carrier loop + DLL",
                 needs_aiding=True, options={"dll_bn_hz": 1.0})
register_tracker("unaided-kf", _kf(False), "the INS paper's unaided 3rd-order Kalman carrier loop + DLL",
                 options={"dll_bn_hz": 1.0})
register_tracker("aided-pll", lambda ctx, arith, **o: AidedPll(ctx, arith, **o),
                 "the INS paper's INS-aided 3rd-order PLL (Kaplan, Bn 15 Hz, rate feed-forward) + DLL",
                 needs_aiding=True, options={"bn_hz": 15.0, "dll_bn_hz": 1.0})
