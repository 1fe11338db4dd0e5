"""The AUKF patent's master-slave adaptive UKF carrier tracker (``"aukf"``) and its fixed-q UKF
baseline (``"ukf"``), float64 / float32 / fixed point from one source.

Master (docs/explanation/gnss_aukf.md): state ``x = [theta, w0, w1, w2]`` (rad, rad/s, rad/s^2,
rad/s^3) of the Singer jerk model (``cosim.gnss.dynamics.jerk_phi`` / ``jerk_q``), where
``theta`` is the carrier phase *minus the replica (NCO) phase* at the epoch's midpoint (the
residual the I/Q pair measures) and ``w0..w2`` are absolute. Prediction (linear, exact in
any UKF): ``x- = Phi x - [2 pi T (f_k + f_k+1) / 2, 0, 0, 0]`` (the NCO's advance between
the midpoints, ``f`` the replica Doppler in force, Hz), ``P- = Phi P Phi^T + q_hat Q_bar``.
Update: the patent's closed form (its eqs 7.1-7.11, as reconstructed for this project) of the
augmented UKF with ``n = 10`` (4 states, 4 process noise, 2 measurement noise), lower
Cholesky ``S`` of ``P-``: ``c = sqrt((n + lambda) P-_11)``, ``a = W1 + 18 W2 + 2 cos(c) W2``,
``y_hat = A a u``, ``Pyy = A^2 ((W4 - l) u u^T + m I) + R``, ``Pxy = 2 A W2 sin(c)
sqrt(n + lambda) S[:, 0] v^T`` (``u = [cos th, sin th]``, ``v = [-sin th, cos th]``). As
``Pxy`` has rank 1, ``P = P- - g^2 (v^T Pyy^-1 v) s0 s0^T`` (``s0 = sqrt(n+lambda) S[:,0]``,
``g = 2 A W2 sin c``). :func:`dsp.gnss.aukf_master.master_update` is this form (a numba kernel);
:func:`dsp.gnss.aukf_master.master_update_generic` runs the same update through the generic augmented UKF of
:mod:`dsp.estimation.ukf` (identity transition, zero process noise: its 21 sigma points are
then exactly the patent's); test A1 holds them to 1e-12.

Measurement: the prompt ``P = I + jQ`` divided by the amplitude ``A_c`` so that ``A = 1`` and
the noise variance is ``1 / (2 T C/N0)`` ("R from C/N0", default) or the patent's ``1e-9``
(``r_mode="seed"``); the navigation bit is removed by the sign of the prompt rotated by the
predicted residual (``data_wipe``). ``A_c`` is in the correlator's own units, which the
tracker is not told (the fast path's correlations have unit noise per component, the HDL
channel's are integer accumulators thousands of times larger), so by default
(``amplitude="auto"``) it is estimated from the prompt power with the nominal C/N0:
``E|P|^2 = A_c^2 + 2 sigma^2 = A_c^2 (1 + 1 / (T C/N0))``, the mean of ``|P|^2`` taken over
the epochs so far, then exponentially over ``amp_epochs`` epochs (the bit and the phase do
not enter it). A number fixes ``A_c``. ``P0`` defaults to the patent's ``1e-3 I`` (a start on the
truth), its ``w0`` entry widened to ``(2 pi sigma)^2`` when the context gives the hand-over's
``doppler0_sigma_hz``. The initial Doppler rate is the context's ``doppler_rate0_hz_s``
(the HDL run: ``GnssRunConfig.handover_doppler_rate_hz_s``, the patent's x0 rate under
``--scenario aukf-patent``; started on rate 0 with the patent's ``P0`` the patent's own 1 g drove
the 32 dB-Hz loop off lock, 175 slips, and widening ``P0[w1]`` to 100 (Hz/s)^2 did too).

Slave (scalar ``q``). Order per block (the patent's): slave predict -> master epochs with
``q_hat_k|k-1`` -> slave update. **Deviation from the patent** (``slave="block"``, default):
at 32 dB-Hz the q-dependent part of one epoch's innovation covariance is ~1 % of the thermal
noise (the steady-state ``P-_11 / R`` is 0.009 at q = 5), so the patent's per-epoch measurement
``z = diag(nu nu^T)`` hardly moves ``q_hat`` (a previous attempt failed A2/A4 that way). The
slave instead measures, once per block of ``M`` epochs, ``z = (w2_hat_end - s^M w2_hat_start)^2``
(``s = e^-alpha T``) -- the sum of the master's jerk corrections ``sum s^(M-k) K4 nu_k``
over the block, in which the process noise dominates the thermal noise once ``M T`` exceeds
the filter's time constant. Its expectation, for a master in steady state with the gain of
``q_hat``, is *linear* in the true ``q``: ``h(q) = a(q_hat) q + b(q_hat)``, from the
mismatched-filter Lyapunov equation of the linearised loop (:func:`dsp.gnss.aukf_slave.block_moments`,
tabulated on a log grid of ``q_hat``); ``Rq = 2 h(q_hat)^2`` (``z`` is a squared Gaussian).
The block slave's state is ``ln q`` (a scalar UKF in ``q`` let a quarter of the runs at
``q_true = 0.1 q0`` collapse onto the floor ``q >= 0``); its prior is derived: ``P_lnq0 = 1``
(a factor e at 1 sigma), ``Q_lnq = 0.01`` per block (the patent's ``Pq0 = 1e-8`` on ``q`` would
freeze ``q_hat`` at ``q0``). ``slave="seed"`` runs the patent's slave
literally: per epoch, ``z = diag(nu nu^T)``, ``h(q_j) = diag Pyy(q_j)``, ``q0 = 5``,
``Pq0 = 1e-8``, ``Qq = 1e-10``, ``Rq = diag(1e-8, 1e-8)``. ``eq414="literal"`` takes the
patent's eq. 4.14 as written (``P_k|k-1 = Qq``), default ``P_k|k-1 = P_k-1 + Qq``.

Loop: ``f_next = w0_pred / 2 pi + (C1 e + C2 sum e) / T`` with ``e = theta_hat / 2 pi``
(cycles; a 2nd-order filter, ``K0 Kd = 1``, ``wn`` from ``loop_bn_hz``) and
``w0_pred`` the master's ``w0`` predicted to the epoch the write takes effect in
(``latency_epochs``); carrier-aided 1st-order DLL as ``loops_fixed.ChannelCore``.

Divergence (``report()["diverged"]``, per trial), any of: (1) the narrow-band lock indicator
of the data-wiped prompt summed over blocks of 20 epochs, ``((sum I)^2 - (sum Q)^2) /
((sum I)^2 + (sum Q)^2)``, below 0 in 3 consecutive blocks after the first 100 epochs and
after a block above 0.5 (a phase loss; not the pull-in after a hand-over); (2) a frequency loss, which (1) misses: the per-epoch data wipe folds a
residual rotating at tens of Hz into the half plane of the prediction, so the wiped sums stay
"locked" (a 28 dB-Hz run drifted to 92 Hz unflagged). Over each second (``NBW_WINDOW``
epochs) the ratio of narrow-band power (``|sum P|^2`` of the *raw* prompt over
``NBW_EPOCHS = 10`` epochs) to wide-band power (``sum |P|^2``), both normalised, is compared
with its value in lock, ``(L^2 eta + L / (T C/N0)) / (L (1 + 1 / (T C/N0)))`` (``L = 10``,
``eta = 0.835`` the mean coherent loss of a 10-epoch sum from random 20-ms bit edges) and 1
for noise only: below the midpoint the trial has diverged (a residual of ~40 Hz and more;
measured at 28 dB-Hz: 4.41 mean, 3.87 lowest of 99 locked trials x 10 s vs expected 3.84,
limit 2.42; the lost trial fell to 2.1 when 60 Hz off). Needs the nominal C/N0 (else only (1)).
(3) A non-finite state.

Fixed point (:class:`dsp.gnss.aukf_master.AukfFormats`): every stored signal of the master (predicted state and
covariance, trig values, ``c``, ``Pyy``, its inverse, gain terms, state and covariance) is
rounded half-up to its format's fraction bits and saturated (counted) -- an emulation of
the DSP's word lengths evaluated in float64 (exact products of up to 53 bits), not an
integer bit-exact model. float32 rounds every stored signal to float32.
"""
from __future__ import annotations

import math

import numpy as np

from ..estimation.ukf_formats import sigma_weights
from ..estimation.models import check_psd
from .ca_code import CHIP_RATE_HZ
from .discriminators import dll_nelp
from .loops_fixed import DISC_CODE, WORD_BITS
from .aukf_master import (N_AUG, TWO_PI, AukfFormats, master_kernel, master_update_generic,
                          pyy_diag_kernel, ut_weights)
from .aukf_slave import Q_TABLE, block_table, wipe_gain
from .trackers import register_tracker

PATENT_X0 = (0.0, 32995.519, 323.356, 0.0)
PATENT_P0 = 1e-3
PATENT_R = 1e-9
EVENTS = ("chol_fail", "s_not_pd", "saturations")
#: P0[theta] after a hand-over: the carrier phase is unknown, uniform over the Costas
#: half-cycle: (pi / 2)^2 / 3 rad^2.
HANDOVER_P_THETA = (np.pi / 2) ** 2 / 3
#: Divergence, frequency test (module docstring): narrow-band (NBW_EPOCHS-epoch coherent
#: sums of the raw prompt) over wide-band power, over NBW_WINDOW epochs.
NBW_EPOCHS = 10
NBW_WINDOW = 1000


# ------------------------------------------------------------------------------------------
# the tracker
# ------------------------------------------------------------------------------------------
def _check_pos(name, v):
    if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a finite number > 0, not {v!r}")
    return float(v)


class AukfTracker:
    """The AUKF patent's carrier tracker (``adaptive=False``: the fixed-q UKF baseline); see the
    module docstring. Tracker interface of :mod:`dsp.gnss.trackers`."""

    def __init__(self, ctx, arith="float64", *, adaptive: bool = True, epsilon: float = 1.027,
                 beta: float = 2.0, kappa: float = 0.0, alpha_per_s: float = 0.1, q0: float = 5.0,
                 P0=None, r_mode: str = "cn0", slave: str = "block", eq414: str = "plausible",
                 block_epochs: int = 500, Pq0: float | None = None, Qq: float | None = None,
                 loop_bn_hz: float = 10.0, loop_xi: float = 0.707, dll_bn_hz: float = 1.0,
                 amplitude: float | str = "auto", amp_epochs: int = 100, data_wipe: bool = True, form: str = "closed",
                 p_floor: float = 1e-12):
        from .jerk import jerk_phi, jerk_q
        if not (isinstance(epsilon, (int, float)) and epsilon > 0):
            raise ValueError(f"epsilon (UT scaling) must be > 0, not {epsilon!r}")
        if not (isinstance(beta, (int, float)) and beta >= 0):
            raise ValueError(f"beta must be >= 0, not {beta!r}")
        if not (isinstance(kappa, (int, float)) and N_AUG + kappa > 0):
            raise ValueError(f"kappa must make n + kappa > 0 (n = {N_AUG}), not {kappa!r}")
        if not (isinstance(q0, (int, float)) and math.isfinite(q0) and q0 >= 0):
            raise ValueError(f"q0 (initial process-noise intensity) must be >= 0, not {q0!r}")
        if not (isinstance(alpha_per_s, (int, float)) and alpha_per_s >= 0):
            raise ValueError(f"alpha_per_s must be >= 0, not {alpha_per_s!r}")
        if r_mode not in ("cn0", "seed"):
            raise ValueError(f"r_mode must be 'cn0' or 'seed', not {r_mode!r}")
        if slave not in ("block", "seed"):
            raise ValueError(f"slave must be 'block' or 'seed', not {slave!r}")
        if eq414 not in ("plausible", "literal"):
            raise ValueError(f"eq414 must be 'plausible' or 'literal', not {eq414!r}")
        if form not in ("closed", "generic"):
            raise ValueError(f"form must be 'closed' or 'generic', not {form!r}")
        if isinstance(block_epochs, bool) or not isinstance(block_epochs, int) or block_epochs < 2:
            raise ValueError(f"block_epochs must be an integer >= 2, not {block_epochs!r}")
        loop_bn_hz, loop_xi = _check_pos("loop_bn_hz", loop_bn_hz), _check_pos("loop_xi", loop_xi)
        if isinstance(arith, str):
            if arith not in ("float64", "float32"):
                raise ValueError(f"arith must be 'float64', 'float32' or an AukfFormats, not {arith!r}")
            self.mode, self.formats = (0 if arith == "float64" else 1), None
        elif isinstance(arith, AukfFormats):
            self.mode, self.formats = 2, arith
        elif getattr(arith, "fixed", None) is False:          # loops_fixed.FLOAT
            self.mode, self.formats = 0, None
        elif getattr(arith, "fixed", None) is True:           # loops_fixed.FixedArith
            self.mode, self.formats = 2, AukfFormats()
        else:
            raise ValueError(f"arith must be 'float64', 'float32' or an AukfFormats, not {arith!r}")
        if form == "generic" and self.mode != 0:
            raise ValueError("form='generic' (the generic augmented UKF) runs in float64 only")
        self.form = form
        T = self.T = float(ctx.T_s)
        self.fs, self.if_hz, self.s = float(ctx.fs_hz), float(ctx.if_hz), (-1 if ctx.inverted else 1)
        self.lat = int(ctx.latency_epochs)
        self.d = float(ctx.spacing_chips)
        f0 = np.atleast_1d(np.asarray(ctx.doppler0_hz, float))
        self.shape = np.shape(ctx.doppler0_hz)
        Bn = f0.size
        fd0 = np.broadcast_to(np.asarray(ctx.doppler_rate0_hz_s, float), np.shape(ctx.doppler0_hz)).ravel()
        if P0 is None:     # the patent's, widened on w0 to the hand-over Doppler's error if told
            P0 = np.diag([PATENT_P0] * 4)
            sd = ctx.doppler0_sigma_hz
            if sd is not None:
                sd = _check_pos("doppler0_sigma_hz (tracker context)", sd)
                P0[1, 1] = max(PATENT_P0, (TWO_PI * sd) ** 2)
                P0[0, 0] = HANDOVER_P_THETA
        P0 = np.asarray(P0, float)
        if P0.shape != (4, 4):
            raise ValueError(f"P0 must be 4 x 4, not {P0.shape}")
        check_psd("P0", P0[None])
        cn0 = ctx.cn0_dbhz
        auto = isinstance(amplitude, str)
        if auto and amplitude != "auto":
            raise ValueError(f"amplitude must be 'auto' or a number > 0, not {amplitude!r}")
        if not auto:
            amplitude = _check_pos("amplitude", amplitude)
        if isinstance(amp_epochs, bool) or not isinstance(amp_epochs, int) or amp_epochs < 1:
            raise ValueError(f"amp_epochs must be an integer >= 1, not {amp_epochs!r}")
        if r_mode == "cn0" or auto:
            if cn0 is None:
                raise ValueError("cn0_dbhz must be given in the tracker context (R and the "
                                 "amplitude are derived from it)")
        c = 10.0 ** (float(cn0) / 10) if cn0 is not None else None
        self.amp_auto, self.amp_epochs = auto, int(amp_epochs)
        self.amp_gain = 1.0 / (1.0 + 1.0 / (T * c)) if auto else 1.0   # A_c^2 / E|P|^2
        self.amp = np.full(Bn, np.nan if auto else float(amplitude))
        self.p2 = np.zeros(Bn)                   # running mean of |P|^2 (amplitude="auto")
        self.r = 1.0 / (2 * T * c) if r_mode == "cn0" else PATENT_R
        self.R = np.diag([self.r, self.r])
        # the block slave's model: the data wipe's mean discriminator gain at the nominal C/N0
        self.wipe_kd = wipe_gain(1.0 / (2 * T * c)) if (data_wipe and c is not None) else 1.0
        self.W = ut_weights(float(epsilon), float(beta), float(kappa))
        self.ut = (float(epsilon), float(beta), float(kappa))
        self.Phi = jerk_phi(alpha_per_s, T)
        self.Qbar = jerk_q(alpha_per_s, 1.0, T)
        self.x = np.zeros((Bn, 4))
        self.x[:, 1] = TWO_PI * f0
        self.x[:, 2] = TWO_PI * fd0
        self.P0 = P0.copy()
        self.P = np.broadcast_to(P0, (Bn, 4, 4)).copy()
        self.pfloor = float(p_floor)
        if self.mode == 2:
            fm = self.formats
            for name, v in (("theta", 0.0), ("w0", self.x[:, 1]), ("w1", self.x[:, 2]),
                            ("P", P0), ("y", 4.0), ("q", q0)):
                big = float(np.max(np.abs(v)))
                f = getattr(fm, name)
                if big > f.max_value:
                    raise ValueError(f"formats too narrow: AukfFormats.{name} {f} holds "
                                     f"+-{f.max_value:g}, not {big:g}")
            if 2.0 ** -fm.P.frac > 0.01 * float(np.min(np.diag(P0))):
                raise ValueError(f"formats too narrow: AukfFormats.P {fm.P} resolves "
                                 f"{2.0 ** -fm.P.frac:g}, not 1 % of min diag P0")
            self._fm = fm.table()
        else:
            self._fm = np.zeros((9, 2))
        self.ev = np.zeros((Bn, 3), np.int64)
        self.adaptive, self.slave, self.eq414 = bool(adaptive), slave, eq414
        self.M = int(block_epochs)
        if slave == "seed":
            self.Pq0 = 1e-8 if Pq0 is None else float(Pq0)
            self.Qq = 1e-10 if Qq is None else float(Qq)
            self.Rq = 1e-8
        else:   # the block slave estimates ln q (it cannot collapse to q <= 0)
            if q0 <= 0:
                raise ValueError(f"q0 must be > 0 for the block slave (it estimates ln q), not {q0!r}")
            self.Pq0 = 1.0 if Pq0 is None else float(Pq0)
            self.Qq = 0.01 if Qq is None else float(Qq)
        self.q0 = float(q0)
        self.qhat = np.full(Bn, float(q0))
        self.Pq = np.full(Bn, self.Pq0)
        self.log = slave == "block"
        self.lq = np.full(Bn, math.log(q0) if q0 > 0 else 0.0)
        self.q_traj = [self.qhat.copy()]
        self.k = 0
        self.w2_start = self.x[:, 3].copy()
        self.qmin = 1e-4 * max(q0, 1e-3)
        # loop filter: bilinear 2nd order, K0 Kd = 1
        wn = 2.0 * loop_bn_hz / (loop_xi + 1.0 / (4 * loop_xi))
        wt = wn * T
        den = 4 + 4 * loop_xi * wt + wt * wt
        self.C1, self.C2 = 8 * loop_xi * wt / den, 4 * wt * wt / den
        self.acc = np.zeros(Bn)
        self.kd = 4.0 * dll_bn_hz
        self.data_wipe = bool(data_wipe)
        self.queue = [f0.copy() for _ in range(self.lat + 1)]   # [in force now, next, ...]
        self.nb_i = np.zeros(Bn)
        self.nb_q = np.zeros(Bn)
        self.bad_blocks = np.zeros(Bn, np.int64)
        # frequency-lock test (module docstring): raw prompt sums over NBW_EPOCHS, their
        # power (narrow band) and the epochs' power (wide band), accumulated over NBW_WINDOW
        self.nbw_s = np.zeros((Bn, 2))
        self.nbw_w = np.zeros(Bn)
        self.nbw_nb = np.zeros(Bn)
        self.nbw_wb = np.zeros(Bn)
        self.nbw_ratio = np.full(Bn, np.nan)
        self.nbw_hist = []                       # lowest ratio over the trials, per window
        self.div_freq = np.zeros(Bn, bool)
        self.div_phase = np.zeros(Bn, bool)
        self.was_locked = np.zeros(Bn, bool)
        if c is not None:
            L, snr = NBW_EPOCHS, T * c               # normalised: A = 1, 2 sigma^2 = 1/(T C/N0)
            eta = 1.0 - ((L - 1) / 20) * 0.5 * (1.0 - np.mean((L - 2.0 * np.arange(1, L)) ** 2) / L ** 2)
            self.nbw_lock = (L * L * eta + L / snr) / (L * (1.0 + 1.0 / snr))
            self.nbw_limit = 1.0 + 0.5 * (self.nbw_lock - 1.0)
        else:
            self.nbw_lock = self.nbw_limit = None
        self.diverged = np.zeros(Bn, bool)
        self._started = False

    # -- helpers -----------------------------------------------------------------------
    def _fixed_word(self, f_hz):
        return np.rint(f_hz * 2.0 ** WORD_BITS / self.fs).astype(np.int64)

    def doppler_hz(self):
        return (self.x[:, 1] / TWO_PI).reshape(self.shape)

    def _slave_predict(self):
        if self.eq414 == "literal":
            self.Pq = np.full_like(self.Pq, self.Qq)
        else:
            self.Pq = self.Pq + self.Qq

    def _slave_update(self, z, h_of_q, Rq):
        """Scalar UKF on q (3 sigma points, the master's UT parameters with L = 1)."""
        eps, beta, kappa = self.ut
        wm, wc, cL = sigma_weights(1, eps, beta, kappa)
        sq = np.sqrt(cL * np.maximum(self.Pq, 0.0))
        c0 = self.lq if self.log else self.qhat
        X = np.stack([c0, c0 + sq, c0 - sq], axis=1)
        Q = np.exp(X) if self.log else np.maximum(X, self.qmin)
        Z = h_of_q(Q)                                           # (B, 3, m)
        zp = np.einsum("j,bjm->bm", wm, Z)
        dz = Z - zp[:, None, :]
        dq = X - c0[:, None]
        S = np.einsum("j,bjm,bjn->bmn", wc, dz, dz) + Rq
        Pqz = np.einsum("j,bj,bjm->bm", wc, dq, dz)
        K = np.linalg.solve(S, Pqz[..., None])[..., 0]
        new = c0 + np.einsum("bm,bm->b", K, z - zp)
        if self.log:
            # inside the range block_table covers: beyond it h(q) would be extrapolated
            # flat and q_hat could run away (seen at 10 q0 with a wide prior)
            self.lq = np.clip(new, math.log(max(self.qmin, Q_TABLE[0])), math.log(Q_TABLE[1]))
            self.qhat = np.exp(self.lq)
        else:
            self.qhat = np.maximum(new, self.qmin)
        self.Pq = np.maximum(self.Pq - np.einsum("bm,bmn,bn->b", K, S, K), 0.0)
        if self.mode == 2:
            f = self.formats.q
            self.qhat = np.clip(np.floor(self.qhat * 2.0 ** f.frac + 0.5) * 2.0 ** -f.frac, 0, f.max_value)

    # -- one dump ------------------------------------------------------------------------
    def step(self, ie, qe, ip, qp, il, ql):
        T = self.T
        f_now = self.queue[0]
        ipr = np.asarray(ip, float).ravel()
        qpr = np.asarray(qp, float).ravel()
        if self.amp_auto:      # A_c from the prompt power, in the correlator's units
            p2 = ipr * ipr + qpr * qpr
            p2 = np.where(np.isfinite(p2), p2, self.p2)
            self.p2 = self.p2 + (p2 - self.p2) / min(self.k + 1, self.amp_epochs)
            self.amp = np.sqrt(self.amp_gain * self.p2)
        amp = np.where(self.amp > 0, self.amp, 1.0)
        ipf = ipr / amp
        qpf = self.s * qpr / amp
        B = ipf.size
        if self.adaptive and (self.slave == "seed" or self.k % self.M == 0):
            self._slave_predict()
        # NCO advance from the previous midpoint to this one: f of the last epoch and this
        dphi = np.zeros(B) if not self._started else TWO_PI * T * (self._f_prev + f_now) / 2
        # predicted residual (for the data wipe)
        th_pred = self.Phi[0] @ self.x.T - dphi if self._started else self.x[:, 0]
        if self.data_wipe:
            sgn = np.where(ipf * np.cos(th_pred) + qpf * np.sin(th_pred) < 0, -1.0, 1.0)
        else:
            sgn = np.ones(B)
        y = np.stack([sgn * ipf, sgn * qpf], axis=1)
        ok = np.isfinite(y).all(axis=1)
        y = np.where(ok[:, None], y, 0.0)
        if self.adaptive and self.slave == "seed":
            p11_base = (self.Phi @ self.P @ self.Phi.T)[:, 0, 0] if self._started else self.P[:, 0, 0]
        nu = np.zeros((B, 2))
        if self.form == "generic":
            if self._started:
                xp = self.x @ self.Phi.T
                xp[:, 0] -= dphi
                Pp = self.Phi @ self.P @ self.Phi.T + self.qhat[:, None, None] * self.Qbar
            else:
                xp, Pp = self.x, self.P
            self.x, self.P, _ = master_update_generic(xp, Pp, y, self.R, 1.0, *self.ut)
        else:
            master_kernel(self.x, self.P, np.ascontiguousarray(y), ok, dphi, self.qhat, self.Phi,
                           self.Qbar, self.R, 1.0, self.W, self.pfloor, self.mode, self._fm, self.ev, nu,
                           self._started)
        self._started = True
        self.k += 1
        if self.adaptive:
            if self.slave == "seed":
                def h(Qs):
                    p11 = p11_base[:, None] + Qs * self.Qbar[0, 0]
                    out = np.empty(Qs.shape + (2,))
                    pyy_diag_kernel(np.ascontiguousarray(p11), np.ascontiguousarray(th_pred), 1.0,
                                     self.W, self.R, out)
                    return out
                self._slave_update(nu * nu, h, np.eye(2) * self.Rq)
            elif self.k % self.M == 0:
                s = self.Phi[3, 3] ** self.M
                z = (self.x[:, 3] - s * self.w2_start) ** 2
                lg, ta, tb = block_table(self.Phi, self.Qbar, self.r, self.M, kd=self.wipe_kd)
                lq = np.clip(np.log(self.qhat), lg[0], lg[-1])
                a, b = np.interp(lq, lg, ta), np.interp(lq, lg, tb)
                hq = a * self.qhat + b
                self._slave_update(z[:, None], lambda Qs: (a[:, None] * Qs + b[:, None])[..., None],
                                   (2 * hq * hq)[:, None, None])
                self.w2_start = self.x[:, 3].copy()
                self.q_traj.append(self.qhat.copy())
        # lock indicator / divergence
        self.nb_i += y[:, 0]
        self.nb_q += y[:, 1]
        if self.nbw_limit is not None:
            pr = np.where(ok[:, None], np.stack([ipf, qpf], axis=1), 0.0)
            self.nbw_s += pr
            self.nbw_w += np.sum(pr * pr, axis=1)
            if self.k % NBW_EPOCHS == 0:
                self.nbw_nb += np.sum(self.nbw_s * self.nbw_s, axis=1)
                self.nbw_wb += self.nbw_w
                self.nbw_s[:] = 0
                self.nbw_w[:] = 0
            if self.k % NBW_WINDOW == 0:
                self.nbw_ratio = self.nbw_nb / np.maximum(self.nbw_wb, 1e-300)
                self.nbw_hist.append(float(np.min(self.nbw_ratio)))
                self.div_freq |= self.nbw_ratio < self.nbw_limit
                self.diverged |= self.div_freq
                self.nbw_nb[:] = 0
                self.nbw_wb[:] = 0
        if self.k % 20 == 0:
            pli = (self.nb_i ** 2 - self.nb_q ** 2) / np.maximum(self.nb_i ** 2 + self.nb_q ** 2, 1e-300)
            self.was_locked |= pli > 0.5
            if self.k > 100:     # a loss needs a lock first (not the pull-in after a hand-over)
                self.bad_blocks = np.where((pli < 0) & self.was_locked, self.bad_blocks + 1, 0)
                self.div_phase |= self.bad_blocks >= 3
                self.diverged |= self.div_phase
            self.nb_i[:] = 0
            self.nb_q[:] = 0
        self.diverged |= ~np.isfinite(self.x).all(axis=1)
        # loop filter -> NCO for epoch k + 1 + latency
        e = self.x[:, 0] / TWO_PI
        self.acc = self.acc + e
        tau_ahead = (0.5 + self.lat + 0.5) * T       # from this midpoint to the target's
        w0p = self.x[:, 1] + tau_ahead * self.x[:, 2] + tau_ahead ** 2 / 2 * self.x[:, 3]
        f = w0p / TWO_PI + (self.C1 * e + self.C2 * self.acc) / T
        f = np.where(np.isfinite(f), f, f_now)
        tau = dll_nelp(np.asarray(ie, float).ravel(), np.asarray(qe, float).ravel(),
                       np.asarray(il, float).ravel(), np.asarray(ql, float).ravel(), self.d)
        if self.mode == 2:
            tq = np.floor(tau * 2.0 ** DISC_CODE.frac + 0.5) * 2.0 ** -DISC_CODE.frac
            cw = self._fixed_word(self.if_hz + self.s * f)
            kw = self._fixed_word(CHIP_RATE_HZ + f / 1540.0 + self.kd * tq)
            f = (cw * self.fs / 2.0 ** WORD_BITS - self.if_hz) * self.s     # Doppler in force
            out = (cw.reshape(self.shape), kw.reshape(self.shape))
        else:
            out = ((self.if_hz + self.s * f).reshape(self.shape),
                   (CHIP_RATE_HZ + f / 1540.0 + self.kd * tau).reshape(self.shape))
        self._f_prev = f_now
        self.queue.pop(0)
        self.queue.append(f)
        return out

    def frequencies_hz(self, out):
        if self.mode != 2:
            return out
        cw, kw = out
        return cw * self.fs / 2.0 ** WORD_BITS, kw * self.fs / 2.0 ** WORD_BITS

    def counts(self) -> dict:
        return {n: int(self.ev[:, i].sum()) for i, n in enumerate(EVENTS)}

    def report(self) -> dict:
        tr = np.array(self.q_traj)                    # (blocks + 1, B)
        return {"q_hat": {"final": self.qhat.reshape(self.shape).tolist(),
                          "median_final": float(np.median(self.qhat)),
                          "trajectory_median": np.median(tr, axis=1).tolist(),
                          "trajectory_p10": np.percentile(tr, 10, axis=1).tolist(),
                          "trajectory_p90": np.percentile(tr, 90, axis=1).tolist()},
                "diverged": self.diverged.reshape(self.shape).tolist(),
                "diverged_count": int(self.diverged.sum()),
                "events": self.counts(),
                "lock_tests": {"phase_loss_count": int(self.div_phase.sum()),
                               "frequency_loss_count": int(self.div_freq.sum()),
                               "nbw_ratio_min_per_s": self.nbw_hist,
                               "nbw_ratio_in_lock": self.nbw_lock, "nbw_limit": self.nbw_limit},
                "params": {"adaptive": self.adaptive, "epsilon": self.ut[0], "beta": self.ut[1],
                           "kappa": self.ut[2], "q0": self.q0, "R": self.r,
                           "P0_diag": np.diag(self.P0).tolist(), "T_s": self.T,
                           "slave": self.slave, "block_s": self.M * self.T,
                           "arith": ["float64", "float32", "fixed"][self.mode]}}


def _make_aukf(ctx, arith, *, r_mode: str = "cn0", **opts):
    return AukfTracker(ctx, arith, adaptive=True, r_mode=r_mode, **opts)


def _make_ukf(ctx, arith, *, r_mode: str = "cn0", **opts):
    return AukfTracker(ctx, arith, adaptive=False, r_mode=r_mode, **opts)


register_tracker("aukf", _make_aukf, "the AUKF patent's master-slave adaptive UKF (jerk model, I/Q)",
                 options={"r_mode": "cn0", "dll_bn_hz": 1.0})
register_tracker("ukf", _make_ukf, "the AUKF patent's master UKF with fixed q (baseline)",
                 options={"r_mode": "cn0", "dll_bn_hz": 1.0})
