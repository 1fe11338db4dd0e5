"""The TACAN paper's 5-state Kalman filter for the envelope (its eqs. 6-14), one source for
float (golden) and fixed point.

State ``x = [m1 sin a, m1 cos a, m2 sin b, m2 cos b, u]`` (15 Hz and 135 Hz components and
the DC level), transition from the *non-uniform* time ``dt`` between pulse peaks (eq. 12)::

    A = blkdiag(R(2 pi 15 dt), R(2 pi 135 dt), 1),  R(d) = [[cos d, sin d], [-sin d, cos d]]

measurement ``y = x1 + x3 + x5 + v`` (eq. 14). Batched: trials sharing one pulse timeline
run in one call (``x`` is ``(B, 5)``, ``P`` ``(B, 5, 5)``).

One source, two arithmetics (data-type override)
-----------------------------------------------
The filter is written once (:func:`dsp.tacan.kalman_kernel._trial`) in terms of the
operators of :mod:`dsp.qops`. numba compiles it for ``float64`` state -- the golden filter:
every operator is the real operation -- and for ``int64`` state -- the fixed-point DSP
core: every operator quantises to the formats of :class:`KalmanFixedConfig`. :class:`EnvelopeKalman` picks the arithmetic
from its configuration: a :class:`KalmanConfig` runs in float, a :class:`KalmanFixedConfig`
(which contains the :class:`KalmanConfig`) in fixed point. The two therefore differ only
where quantisation happens.

Design choices (the paper leaves them open)
-------------------------------------------
* The filter works in units of the measurement noise variance (``R = 1``); ``P``
  and ``Q`` are scaled by ``r``, so the gains do not depend on the signal level and only
  the outlier gate needs ``r``, which is estimated from the innovations.
* ``Q`` is set by the filter's *memory* ``memory_s``: random-walk process noise on each
  state per second such that the steady-state gain equals that of an exponential window of
  ``N = rate * memory_s`` pulses (``K = 2 / (N + 1)``; scalar random walk
  ``q = K^2 r_eff / (1 - K)`` per pulse, with ``r_eff = 2 r`` for a rotating sin/cos pair,
  which only sees half of each measurement on average).
* Scalar update ``P <- Pp - K PH^T`` (for a scalar measurement the Joseph form reduces to
  ``Pp - S K K^T``, which this is); only the upper triangle is computed and mirrored, so
  ``P`` is symmetric by construction in both arithmetics.
* Innovation gate (``gate`` sigmas) after a warm-up; gated measurements are counted; a run
  of ``max_rejects`` consecutive gated measurements means divergence: the trial is
  re-initialised and the event counted. ``S <= 0`` or a negative diagonal of ``P`` (lost
  positive definiteness) also re-initialise (``p_neg``). Nothing here can produce a NaN from
  finite input; NaN input is refused.

Number formats (:class:`KalmanFixedConfig`, defaults)
-----------------------------------------------------
======  ==================  ===========================================================
signal  format              why
======  ==================  ===========================================================
y       s18.16  (+-2)       peak amplitudes 0.2-1.4 FS plus noise
x       s36.28  (+-128)     state; LSB 3.7e-9; early transients reach ~10
P       s46.30  (+-32768)   covariance in units of r, see below
K       s38.30  (+-128)     gain (early on |K_i| <= sqrt(P_ii / S) reaches ~100)
cs      s24.22  (+-2)       sin/cos of the transition (LSB 2.4e-7)
innov   s24.20  (+-8)       innovation
r       s40.30  (+-512)     innovation power e2 = innov^2/S and the r estimate (signal^2)
======  ==================  ===========================================================

Dynamic range of P (the design choice): P runs from ``p0 = 1e4`` (uninformative prior, in
units of r) down to ~5e-4 on the diagonal in steady state, and its per-pulse process noise
is ~6e-7: 3e10 : 1, i.e. 35 bits before any precision. A plain wide word is used rather
than a block-floating form: 46 bits with 30 fraction bits hold ``p0`` up to 16384 with a
steady-state diagonal of 5e5 LSB and a per-pulse ``Q`` of ~670 LSB (0.1 % quantisation;
``half_up`` rounding so that the recursion carries no per-step bias). The products of this
46-bit word with 24-bit sin/cos and 38-bit gains do not fit an int64 product, so they go
through an *exact split multiply* (:func:`_mac2`): the wide operand is split at ``k`` bits,
both partial products fit 63 bits, and the rounding of the full product is reassembled
exactly (``floor((hi*2^k + lo) / 2^s) = Q + floor((R*2^k + lo) / 2^s)``) -- in hardware,
one 27x18 DSP slice cascade. The result equals the exactly rounded product bit for bit
(the tests check it against Python's unbounded integers).

Fixed-point stability
---------------------
* ``P`` is symmetric by construction: only the upper triangle is computed and mirrored.
* ``P <- Pp - K PH^T`` (the scalar-update form of the float filter); a diagonal that comes
  out below 1 LSB is clamped to 1 LSB (``p_clamps``); a negative diagonal or ``S <= 0``
  (lost positive definiteness) re-initialises the trial (``p_neg`` and ``reinit``).
* The transition comes from the integer timestamp difference: phase = ``dt_ticks * fw mod
  2^40`` (``fw`` the 40-bit frequency word of 15/135 Hz: frequency error < 1e-5 Hz),
  sin/cos from a 1024-entry full-circle sine ROM (30 fraction bits) plus a 3rd-order
  Taylor correction of the residual angle (< 1e-12), then one rounding to ``cs``
  (<= 0.5 LSB = 1.2e-7).
* Every store saturates to its format and counts the event per signal (``sat_*``).
* Gated measurements are counted; ``max_rejects`` consecutive gated ones re-initialise the
  trial (``reinit``), as in the float filter. Integers cannot be NaN.
* An input the ``y`` format cannot hold (or beyond ``KalmanConfig.input_limit``) is not
  saturated into a measurement: the step only predicts (``implausible``; in float the same
  with ``input_limit``), so garbage never enters the state, not even right after a
  re-initialisation.

Timestamps: ``run`` takes ``dts`` as integer ticks (``KalmanConfig.tick_hz``, default 20 MHz, the ADC
clock) or float seconds. The fixed core converts seconds by rounding the *cumulative* time to
ticks (the residual carried between calls) so no rounding drift builds up; the float filter
converts ticks to seconds.
"""
from __future__ import annotations

import math

import numpy as np

from ..qops import RANGE_BASE, new_event_array
from .bearing import PHASE_BITS
from .phase_ops import SIN_LUT
from .kalman_kernel import EVENT_INDEX, run_parallel, run_serial, step_consts
from .kalman_monitor import StateMonitor
from .kalman_config import KalmanConfig, KalmanFixedConfig, float_consts
from .standard import F15

#: Largest dt in ticks (2^38 ticks: 3.8 h at 20 MHz).
MAX_TICKS = 1 << 38

#: Signals whose range the fixed-point core logs (event index -> format name): every store
#: of that format goes through a saturating operator with that index (r also holds e2).
RANGE_SIGNALS = {0: "y", 1: "x", 2: "P", 3: "K", 4: "innov", 5: "r", 6: "rmult"}


#: The slope table's smoothing (entries either side) and its floor.
SLOPE_HALF_WIDTH = 3
SLOPE_MIN = 0.25


def bias_slopes(bias, step_log2: int) -> np.ndarray:
    """``g[i] = 1 + d bias / ds`` at the entries of a peak-bias table of step
    ``2**-step_log2`` (central differences over :data:`SLOPE_HALF_WIDTH` entries either
    side, one-sided at the ends), within [:data:`SLOPE_MIN`, 1]: the expected report
    rises with the amplitude (the bias falls), at least a quarter as fast as it (a floor
    that bounds the filter's step on a report near the threshold to 4x the plain one)."""
    b = np.asarray(bias, dtype=np.float64).ravel()
    if b.size < 2:
        return np.ones(b.size)
    i = np.arange(b.size)
    lo = np.maximum(i - SLOPE_HALF_WIDTH, 0)
    hi = np.minimum(i + SLOPE_HALF_WIDTH, b.size - 1)
    d = (b[hi] - b[lo]) / ((hi - lo) * 2.0 ** -int(step_log2))
    return np.clip(1.0 + d, SLOPE_MIN, 1.0)


class EnvelopeKalman(StateMonitor):
    """Batched envelope Kalman filter, float (golden) or fixed point by configuration.

    Parameters
    ----------
    cfg : KalmanConfig or KalmanFixedConfig
        A :class:`KalmanConfig` runs the filter in float64; a :class:`KalmanFixedConfig`
        (the same :class:`KalmanConfig` plus word lengths) runs the same source in fixed
        point.
    batch : int
        Independent trials sharing one pulse timeline.
    parallel : bool, optional
        Spread the trials over the cores (numba threads). Default: when ``batch >= 16``.

    Attributes
    ----------
    x, P : arrays (B, 5), (B, 5, 5)
        Raw state (float64, or int64 codes in the formats of ``cfg``).
    arithmetic : str
        ``"float"`` or ``"fixed"``.

    The state monitor (checkpoints, continuity checks, recovery) and the upset injection
    of the bit-error studies come from :class:`dsp.tacan.kalman_monitor.StateMonitor`.
    """

    def __init__(self, cfg: KalmanConfig | KalmanFixedConfig | None = None, batch: int = 1, *,
                 parallel: bool | None = None):
        cfg = KalmanConfig() if cfg is None else cfg
        if isinstance(cfg, KalmanFixedConfig):
            self.fixed: KalmanFixedConfig | None = cfg
            self.kalman = cfg.kalman
            self._ci = cfg.int_consts()
            self._cv = cfg.value_consts()
            dtype = np.int64
        elif isinstance(cfg, KalmanConfig):
            self.fixed = None
            self.kalman = cfg
            self._ci = KalmanFixedConfig(kalman=cfg).int_consts()   # unused by float ops
            self._cv = float_consts(cfg)
            dtype = np.float64
        else:
            raise ValueError(f"cfg must be a KalmanConfig or KalmanFixedConfig, not {cfg!r}")
        self.cfg = cfg
        #: The clock of integer ``dts`` (:attr:`KalmanConfig.tick_hz`).
        self.tick_hz = float(self.kalman.tick_hz)
        self._rotation_hz = F15
        if isinstance(batch, bool) or not isinstance(batch, (int, np.integer)) or batch < 1:
            raise ValueError(f"batch must be an integer >= 1, not {batch!r}")
        self.batch = int(batch)
        self.parallel = self.batch >= 16 if parallel is None else bool(parallel)
        self.x = np.zeros((self.batch, 5), dtype)
        self.P = np.zeros((self.batch, 5, 5), dtype)
        self._r = np.full(self.batch, self._cv[6], dtype)
        self._cnt = np.zeros((self.batch, 3), np.int64)   # n, gated / implausible in a row
        self._ev = new_event_array((self.batch,))    # counts, then the range log
        self._t_resid = 0.0
        self.n_updates = 0
        self._upsets = None
        self.upsets_applied = 0
        self._bt = np.zeros(0, dtype)      # the peak-bias table (set_peak_bias), step 2**_bs
        self._gt = np.zeros(0, dtype)      # its slope table (1 + d bias / ds, cs format)
        self._bs = 0
        self._nq = np.zeros(2, dtype)      # its noise-report rule (0: off)
        self._ck = None                    # the state-continuity checkpoint (checkpoint())
        self._adv = [0, 0] if dtype == np.int64 else [0.0, 0.0]   # model phase advance since
        self._elapsed_s = 0.0
        self._elapsed_ticks = 0
        self._failed = np.zeros(self.batch, bool)   # the last check failed (recover())
        self.reset()

    @property
    def arithmetic(self) -> str:
        return "float" if self.fixed is None else "fixed"

    @property
    def rotation_hz(self) -> float:
        """The rotation rate the transition model turns at (``F15`` unless set)."""
        return self._rotation_hz

    def set_rotation(self, f_hz: float) -> None:
        """Turn the transition model at the beacon's rotation rate ``f_hz`` (its 15 Hz
        component) and ``9 f_hz`` (135 Hz) from the next step on: the fixed core's two
        40-bit frequency words (``round(f 2**40 / tick_hz)``, as for 15 Hz) or the float
        angular rates. ``F15`` gives exactly the nominal constants."""
        f = float(f_hz)
        if not (math.isfinite(f) and 0.9 * F15 <= f <= 1.1 * F15):
            raise ValueError(f"rotation rate must be within 10 % of {F15:g} Hz, not {f_hz!r}")
        if self.fixed is None:
            self._cv[0], self._cv[1] = 2 * math.pi * f, 2 * math.pi * (9 * f)
        else:
            scale = 2.0 ** PHASE_BITS / self.tick_hz
            self._cv[0], self._cv[1] = int(round(f * scale)), int(round(9 * f * scale))
        self._rotation_hz = f

    def set_peak_bias(self, bias, step_log2: int, noise: tuple | None = None) -> None:
        """Expect measurements biased by ``bias[i]`` at the amplitude ``i * 2**-step_log2``
        (signal units; the last entry beyond the table, the first below zero) from the next
        step on: the innovation is taken against the predicted amplitude plus that bias (the
        conditional mean of a peak the front end reports near its threshold,
        :class:`dsp.tacan.peakbias.PeakBias`). The fixed core holds the table in the ``x``
        format. An empty ``bias``: none (the default).

        The measurement row is the expected report's slope at the predicted amplitude times
        ``H`` (``g = 1 + d bias / ds``, :func:`bias_slopes`, in the ``cs`` format): an
        extended Kalman filter. Near the threshold a report moves ~0.2-0.6x as much as the
        amplitude; with the row ``H`` alone each such report counts as a full measurement,
        the covariance (and the coarse bearing's sigma) claims 2-5x too little, and from
        the uninformative start the filter can settle on a biased state (measured with
        ``H``: 0 dB, X, 250 deg, seed 201, both searches: the 15 Hz phase 31 deg off at
        0.34 s with a sigma of 2.7 deg, a 40 deg sector held until 1.1 s; with ``g H``
        +6 deg, sigma 5.4 deg).

        ``noise = (report, predicted)`` (signal units): a report below ``report`` while the
        predicted amplitude is ``predicted`` or more is taken as a noise report, not a
        measurement (predict only; counted as ``noise_reports``), once the filter has warmed
        up (``KalmanConfig.warmup`` updates: before, the prediction is no yardstick -- the
        first extended updates near the threshold step up to 4x as far as plain ones)."""
        b = np.asarray(bias, dtype=np.float64).ravel()
        k = int(step_log2)
        nq = (0.0, 0.0) if noise is None else tuple(float(v) for v in noise)
        if len(nq) != 2 or not all(math.isfinite(v) and v >= 0 for v in nq):
            raise ValueError(f"noise rule must be (report, predicted) >= 0, not {noise!r}")
        if not np.isfinite(b).all():
            raise ValueError("peak-bias table must be finite")
        if b.size > 1 << 16:
            raise ValueError(f"peak-bias table of {b.size} entries: at most 65536")
        g = bias_slopes(b, k)
        if self.fixed is None:
            self._bt, self._gt, self._bs, self._nq = b.copy(), g, -k, np.array(nq)
            return
        fx = self.fixed.x
        if not -62 < fx.frac - k < 62:
            raise ValueError(f"peak-bias table step 2**-{k} does not suit the x format {fx}")
        self._bt = np.clip(np.round(np.ldexp(b, fx.frac)), fx.min_int, fx.max_int).astype(np.int64)
        self._gt = np.round(np.ldexp(g, self.fixed.cs.frac)).astype(np.int64)
        self._bs = fx.frac - k
        self._nq = np.clip(np.round(np.ldexp(np.array(nq), fx.frac)), 0, fx.max_int
                           ).astype(np.int64)

    def reset(self, mask=None) -> None:
        """Back to the prior (keeps r, events and the time residual): every trial, or those
        of the boolean ``mask``."""
        m = slice(None) if mask is None else np.asarray(mask, bool)
        self.x[m] = 0
        self.P[m] = 0
        for i in range(5):
            self.P[m, i, i] = self._cv[4]
        self._cnt[m] = 0

    # -- state continuity (integrity monitor) -------------------------------------------------
    def _advance(self, t) -> None:
        """Add the steps ``t`` (ticks in fixed point, seconds in float) to the time and the
        transition model's phase advance since the checkpoint: the fixed core's phase is
        ``dt * fw mod 2**40`` per step, so the sum is exact in integers."""
        if self.fixed is None:
            tot = float(np.sum(t))
            self._adv = [self._adv[i] + float(self._cv[i]) * tot for i in range(2)]
            self._elapsed_s += tot
        else:
            tot, m = int(np.sum(t)), (1 << PHASE_BITS) - 1
            self._adv = [(self._adv[i] + tot * int(self._cv[i])) & m for i in range(2)]
            self._elapsed_ticks += tot
            self._elapsed_s = self._elapsed_ticks / self.tick_hz

    # -- boundary conversions ----------------------------------------------------------------
    def _ticks(self, dts) -> np.ndarray:
        d = np.asarray(dts)
        if d.dtype.kind in "iu":
            t = d.astype(np.int64).ravel()
        else:
            d = d.astype(np.float64).ravel()
            if not np.isfinite(d).all() or (d < 0).any():
                raise ValueError("dts must be finite and >= 0")
            cum = np.cumsum(d) + self._t_resid
            tk = np.round(cum * self.tick_hz)
            if tk.size and tk[-1] >= 2.0 ** 62:
                raise ValueError("dts too long for the tick counter")
            tk = tk.astype(np.int64)
            t = np.diff(tk, prepend=np.int64(0))
            if tk.size:
                self._t_resid = float(cum[-1] - tk[-1] / self.tick_hz)
        if (t < 0).any() or (t >= MAX_TICKS).any():
            raise ValueError(f"dt ticks must lie in [0, 2^38), got {t.min()}..{t.max()}")
        return t

    def _seconds(self, dts) -> np.ndarray:
        d = np.asarray(dts)
        if d.dtype.kind in "iu":
            t = d.astype(np.float64).ravel() / self.tick_hz
        else:
            t = d.astype(np.float64).ravel()
        if not np.isfinite(t).all() or (t < 0).any():
            raise ValueError("dts must be finite and >= 0")
        return t

    def _measurements(self, ys):
        """Validated measurements for the kernel: float, or integer ``y`` codes (saturated
        to the format, counted as ``sat_y``, when ``input_limit`` lies beyond it); inputs
        beyond ``input_limit`` (fixed default: the ``y`` range) become the kernel's "no
        measurement" value (NaN / the int64 minimum)."""
        ys_a = np.asarray(ys)
        f = self.fixed
        lim = self.kalman.input_limit
        if f is None:
            yf = ys_a.astype(np.float64).reshape(self.batch, -1)
            if not np.isfinite(yf).all():
                raise ValueError("measurement is NaN or infinite: the front end must not send it")
            if lim is None:
                return yf, None
            bad = np.abs(yf) > lim
            return (np.where(bad, np.nan, yf) if bad.any() else yf), None
        fy = f.y
        if ys_a.dtype.kind in "iu":
            raw = ys_a.astype(np.int64).reshape(self.batch, -1)
        else:
            yf = ys_a.astype(np.float64).reshape(self.batch, -1)
            if not np.isfinite(yf).all():
                raise ValueError("measurement is NaN or infinite: the front end must not send it")
            raw = np.floor(np.clip(np.ldexp(yf, fy.frac), -2.0 ** 62, 2.0 ** 62)
                           + (0.5 if fy.rounding == "half_up" else 0.0)).astype(np.int64)
        outside = (raw < fy.min_int) | (raw > fy.max_int)
        bad = outside if lim is None else np.abs(raw.astype(np.float64)) > math.ldexp(lim, fy.frac)
        nsat = outside & ~bad
        self._y_raw = raw
        out = np.clip(raw, fy.min_int, fy.max_int)
        out[bad] = np.iinfo(np.int64).min
        return out, nsat

    def run(self, dts, ys, r_mult=None) -> None:
        """Run steps on a shared timeline.

        Parameters
        ----------
        dts : array (N,)
            Time since the previous pulse: integer ticks or float seconds.
        ys : array (B, N)
            Amplitudes (floats; the fixed core quantises them to ``cfg.y``; integer arrays
            are taken as raw ``y`` codes). Values beyond ``input_limit`` (fixed default:
            the ``y`` range) are no measurement (``implausible``).
        r_mult : array (N,), optional
            Measurement-noise multipliers (> 0); the fixed core holds them in the ``P``
            format, clipped to ``[2**-12, 2**12]`` (counted as ``sat_rmult``).
        """
        y, nsat = self._measurements(ys)
        t = self._ticks(dts) if self.fixed is not None else self._seconds(dts)
        if t.size != y.shape[1]:
            raise ValueError(f"{y.shape[1]} measurements for {t.size} time steps")
        if t.size == 0:
            return
        if nsat is not None:
            self._ev[:, EVENT_INDEX["sat_y"]] += nsat.sum(axis=1)
            # range log of the values taken as measurements (not the implausible ones)
            self._note_python(0, self._y_raw, used=y != np.iinfo(np.int64).min)
        if r_mult is None:
            rmf = np.ones(t.size)
        else:
            rmf = np.asarray(r_mult, dtype=np.float64)
            if rmf.shape != t.shape or not (np.isfinite(rmf).all() and (rmf > 0).all()):
                raise ValueError("r_mult must hold one finite value > 0 per step")
        if self.fixed is not None:
            lo, hi = 2.0 ** -12, 2.0 ** 12
            self._ev[:, EVENT_INDEX["sat_rmult"]] += int(np.count_nonzero((rmf < lo) | (rmf > hi)))
            rm = np.round(np.ldexp(np.clip(rmf, lo, hi), self.fixed.P.frac)).astype(np.int64)
            self._note_python(6, np.round(np.ldexp(rmf, self.fixed.P.frac))[None, :])
        else:
            rm = rmf
        self._advance(t)
        sc = np.empty((t.size, 7), self.x.dtype)
        step_consts(SIN_LUT, t, rm, self._ci, self._cv, sc)
        kern = run_parallel if self.parallel else run_serial
        y = np.ascontiguousarray(y)
        if self._upsets is None:
            kern(self.x, self.P, self._r, self._cnt, self._ev, sc, y, self._ci, self._cv,
                 self._bt, self._gt, self._bs, self._nq)
            self.n_updates += t.size
            return
        st, wd, bt, k = self._upsets
        a, n0 = 0, self.n_updates
        while a < t.size:
            # run up to the next upset inside this call, flip, go on
            b = t.size if k >= st.size or st[k] - n0 >= t.size else int(st[k] - n0)
            if b > a:
                kern(self.x, self.P, self._r, self._cnt, self._ev, sc[a:b],
                     np.ascontiguousarray(y[:, a:b]), self._ci, self._cv, self._bt, self._gt,
                     self._bs, self._nq)
                a = b
            while k < st.size and st[k] - n0 == a and a < t.size:
                self._flip(int(wd[k]), int(bt[k]))
                k += 1
            if b == t.size:
                break
        self._upsets = (st, wd, bt, k)
        self.n_updates += t.size

    def _note_python(self, i: int, raw, used=None) -> None:
        """Range log of a value stored outside the compiled core (per trial rows; only the
        entries where ``used`` is set)."""
        raw = np.asarray(raw, dtype=np.float64)
        if raw.size == 0:
            return
        j = RANGE_BASE + 2 * i
        used = np.ones(raw.shape, bool) if used is None else used
        shape = (self.batch,)       # one row of raw may stand for every trial
        rows = np.broadcast_to(used.any(axis=-1), shape)   # nothing used: slots unchanged
        lo = np.broadcast_to(np.where(used, raw, np.inf).min(axis=-1), shape)[rows]
        hi = np.broadcast_to(np.where(used, raw, -np.inf).max(axis=-1), shape)[rows]
        self._ev[rows, j] = np.minimum(self._ev[rows, j],
                                       np.clip(lo, -2.0 ** 62, 2.0 ** 62).astype(np.int64))
        self._ev[rows, j + 1] = np.maximum(self._ev[rows, j + 1],
                                           np.clip(hi, -2.0 ** 62, 2.0 ** 62).astype(np.int64))

    # -- outputs -----------------------------------------------------------------------------
    def ranges(self) -> dict:
        """Range log of the fixed-point core since construction, per format: ``{name:
        {"min", "max", "lo", "hi", "saturations"}}`` -- the smallest and largest value each
        store was asked to hold before saturation (real units; over all trials), the
        format's representable range and its saturation count. Empty in float mode (the
        float operators do not quantise, so there is nothing to log)."""
        if self.fixed is None:
            return {}
        out = {}
        big = np.iinfo(np.int64).max
        for i, name in RANGE_SIGNALS.items():
            j = RANGE_BASE + 2 * i
            mn, mx = int(self._ev[:, j].min()), int(self._ev[:, j + 1].max())
            fmt = self.fixed.P if name == "rmult" else getattr(self.fixed, name)
            sat_name = "sat_rmult" if name == "rmult" else f"sat_{name}"
            lo, hi = (2.0 ** -12, 2.0 ** 12) if name == "rmult" else (fmt.min_value,
                                                                        fmt.max_value)
            out[name] = {"min": None if mn == big else math.ldexp(mn, -fmt.frac),
                         "max": None if mx == -big - 1 else math.ldexp(mx, -fmt.frac),
                         "lo": lo, "hi": hi,
                         "saturations": int(self._ev[:, EVENT_INDEX[sat_name]].sum())}
        return out

    @property
    def events(self) -> dict:
        """Per-trial event counters (name -> (B,) int64); float mode counts only ``gated``,
        ``reinit`` and ``p_neg``."""
        return {n: self._ev[:, i].copy() for n, i in EVENT_INDEX.items()}

    def _to_float(self, v, fmt_name):
        if self.fixed is None:
            return np.array(v, dtype=np.float64)
        return getattr(self.fixed, fmt_name).to_float(v)

    @property
    def r(self) -> np.ndarray:
        """Estimated measurement noise variance (signal units), per trial."""
        return self._to_float(self._r, "r")

    def health(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per trial: updates since the last (re)initialisation, how many of the latest
        inputs in a row were not used (gated, or implausible), and the estimated amplitude
        noise relative to the pulse level, ``sqrt(r) / |dc|`` (``inf`` for ``dc = 0``; a
        float readout, for monitoring only)."""
        dc = np.abs(self._to_float(self.x[:, 4], "x"))
        ratio = np.full(self.batch, np.inf)
        np.divide(np.sqrt(np.maximum(self.r, 0.0)), dc, out=ratio, where=dc > 0)
        return self._cnt[:, 0].copy(), self._cnt[:, 1:].max(axis=1), ratio

    def coarse_sigma_deg(self) -> np.ndarray:
        """Per trial: the standard deviation of the 15 Hz phase (deg) the filter's own
        covariance gives, ``sqrt(r (P00 + P11) / 2) / m1`` (a float readout, for monitoring
        only; ``inf`` for ``m1 = 0``)."""
        x = self.x_float()
        P = self.P_float()
        m1 = np.hypot(x[:, 0], x[:, 1])
        v = np.maximum(self.r, 0.0) * np.maximum(P[:, 0, 0] + P[:, 1, 1], 0.0) / 2.0
        out = np.full(self.batch, np.inf)
        np.divide(np.degrees(np.sqrt(v)), m1, out=out, where=m1 > 0)
        return out

    def x_float(self) -> np.ndarray:
        return self._to_float(self.x, "x")

    def P_float(self) -> np.ndarray:
        return self._to_float(self.P, "P")

    def phases(self):
        """(alpha, beta, m1, m2, dc): envelope phases (rad) at the last update and amplitudes
        (float readout of the state)."""
        x = self.x_float()
        return (np.arctan2(x[:, 0], x[:, 1]), np.arctan2(x[:, 2], x[:, 3]),
                np.hypot(x[:, 0], x[:, 1]), np.hypot(x[:, 2], x[:, 3]), x[:, 4])
