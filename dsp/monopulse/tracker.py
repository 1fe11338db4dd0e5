"""Monopulse DSP after the angle measurement: per-axis alpha-beta trackers on the direction
cosines, the predicted direction as the next beam-steering command, channel calibration and
the search / capture sequence (docs/explanation/monopulse_tracker.md).

Tracker (the monopulse paper's eqs. 27-37 as reconstructed). One alpha-beta filter per axis of the direction
cosines, state ``[u, du/dt]``, ``F = [[1, T], [0, 1]]``, ``Gamma = [T^2/2, T]``, ``z = u +
noise``; gains ``K = [alpha, beta / T]`` from Kalata's tracking index ``lambda = sigma_a T^2 /
sigma_v``. Decision: the u and v axes are tracked; the third cosine ``w = sqrt(1 - u^2 - v^2)``
is not an independent measurement of this array (it is a function of u, v), so a third
filter would only re-filter the same data.

* ``mode="fixed"``: alpha, beta = Kalata of ``sigma_a`` (the fixed-gain baseline; a low
  ``sigma_a`` is the smooth, lagging filter, a high one the agile, noisy one).
* ``mode="adaptive"``: the manoeuvre level is re-estimated every step from the last
  ``window`` (3-5) innovations and alpha, beta recomputed from it
  (:class:`dsp.estimation.AlphaBetaFilter` with ``adaptive=True``). ``eq36="repaired"``
  (the project's decision): ``sigma_a T^2 = k sqrt(max(mean e^2 - tau sigma_v^2 / (1 -
  alpha), 0))`` (``k = manoeuvre_gain`` 2, ``tau = noise_floor`` 6), alpha relaxing back by
  at most ``alpha_relax`` 1.1 in ``1 - alpha`` a step (``dsp/estimation/alphabeta``'s
  ``floor_scaling="gain"``, ``alpha_relax``). Why: with the fixed floor ``4 sigma_v^2`` (the
  previous default, ``floor_scaling="fixed"``, ``noise_floor=4``, ``alpha_relax=0``) a high
  alpha inflates its own innovation (``sigma_v^2 / (1 - alpha)``) above the floor and stays
  high after a manoeuvre or a noise outlier: in the C4 scenario (seed 41) the quiet-window
  RMS was 5.8e-4 against 1.6e-4 for the fixed low-index filter; now 1.5e-4, and 1.9e-4 after
  the manoeuvre (low-index 3.1e-4), with the manoeuvre lag 6.3e-4 (low-index 82e-4);
  tau 6: the mean of 4 squared innovations passes 6 times its variance with probability
  8e-5 (chi-square, 4 dof), 4 times with 3e-3 (a false manoeuvre every ~170 blocks a axis);
  ``eq36="literal"``: the paper's eq. 36 as printed, ``sigma_w = sqrt(mean e^2)`` taken as the
  acceleration standard deviation although it is in direction-cosine units (``k = T^2``,
  ``tau = 0``): the index then is ``T^2`` times too small and the filter never leaves
  ``alpha_min`` (kept to show it).

Steering (closed loop): after the update on the measurement of block k the tracker predicts
the direction of block ``k + 1 + latency_blocks`` (the command written over the control path
takes ``latency_blocks`` whole blocks before the beam moves) and that prediction is the beam
command. In fixed point the prediction is formed in the state's own format
(``x0 + m x1``, saturating), so float and fixed differ only by quantisation.

One source float/fixed: ``arithmetic`` is ``"float64"``, ``"float32"`` or an
:class:`~dsp.estimation.AlphaBetaFormats` (:data:`MONOPULSE_FORMATS`: direction cosines need
fractions far below the library's defaults: an innovation of ``sigma_v ~ 8e-4`` squared is
``6e-7``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..estimation.alphabeta import (FLOOR_SCALINGS, AlphaBetaFilter, AlphaBetaFormats, kalata,
                                   tracking_index)
from ..estimation.formats import fmt
from .angles import direction_cosines

#: Tracker formats for direction cosines (|u| < 1): z, e 2^-22 (sigma_v / 3000), state 2^-36,
#: squared innovations 2^-44, tracking index 2^-22 (range +-128).
MONOPULSE_FORMATS = AlphaBetaFormats(z=fmt(24, 22), x=fmt(40, 36), e=fmt(24, 22), c=fmt(24, 22),
                                     s=fmt(48, 44), l=fmt(30, 22))

MODES = ("adaptive", "fixed")
EQ36 = ("repaired", "literal")


def _num(name, v, lo=None, hi=None, lo_open=True):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v) or (lo is not None and (v <= lo if lo_open else v < lo)) \
            or (hi is not None and v >= hi):
        rule = "" if lo is None else f" {'>' if lo_open else '>='} {lo:g}"
        rule += "" if hi is None else f" and < {hi:g}"
        raise ValueError(f"{name} must be a finite number{rule}, not {v!r}")
    return float(v)


def _int(name, v, lo, hi=None):
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo \
            or (hi is not None and v > hi):
        rng = f"in [{lo}, {hi}]" if hi is not None else f">= {lo}"
        raise ValueError(f"{name} must be an integer {rng}, not {v!r}")
    return int(v)


@dataclass(frozen=True)
class TrackerConfig:
    """Angle tracker settings (defaults: the monopulse paper's adaptive filter, repaired eq. 36)."""

    mode: str = field(default="adaptive", metadata={
        "help": "adaptive (Kalata index from the last innovations) or fixed gains",
        "choices": MODES, "case": "lower"})
    eq36: str = field(default="repaired", metadata={
        "help": "adaptive index: repaired or literal (the monopulse paper's eq. 36 as printed)",
        "choices": EQ36, "case": "lower"})
    sigma_a: float = field(default=2.0, metadata={
        "help": "acceleration std of the direction cosines giving the fixed tracking index "
                "(1/s^2; also the adaptive filter's start)"})
    window: int = field(default=4, metadata={"help": "innovations averaged by the adaptive "
                                                     "filter (3-5 in the monopulse paper; 2..64)"})
    noise_floor: float = field(default=6.0, metadata={
        "help": "innovation power (x sigma_v^2, x 1 / (1 - alpha) with floor_scaling gain) "
                "taken as noise by the adaptive filter"})
    manoeuvre_gain: float = field(default=2.0, metadata={
        "help": "k of sigma_a T^2 = k sqrt(mean e^2 - tau sigma_v^2) (adaptive, repaired)"})
    floor_scaling: str = field(default="gain", metadata={
        "help": "adaptive noise floor: gain (tau sigma_v^2 / (1 - alpha), the innovation "
                "variance of the gains in use) or fixed (tau sigma_v^2)",
        "choices": FLOOR_SCALINGS, "case": "lower"})
    alpha_relax: float = field(default=1.1, metadata={
        "help": "adaptive: 1 - alpha grows at most by this factor a step (0: no limit)"})
    alpha_min: float = field(default=0.05, metadata={"help": "smallest adaptive alpha"})
    alpha_max: float = field(default=0.95, metadata={"help": "largest adaptive alpha"})
    latency_blocks: int = field(default=1, metadata={
        "help": "whole measurement blocks between a steering command and the beam moving"})

    def __post_init__(self):
        if self.mode not in MODES:
            raise ValueError(f"tracker mode must be one of {', '.join(MODES)}, not {self.mode!r}")
        if self.eq36 not in EQ36:
            raise ValueError(f"eq36 must be one of {', '.join(EQ36)}, not {self.eq36!r}")
        _num("sigma_a", self.sigma_a, 0)
        _int("window", self.window, 2, 64)
        _num("noise_floor", self.noise_floor, 0, lo_open=False)
        _num("manoeuvre_gain", self.manoeuvre_gain, 0)
        if isinstance(self.alpha_relax, bool) or not isinstance(self.alpha_relax, (int, float)) \
                or not (self.alpha_relax == 0 or 1 < self.alpha_relax < 2):
            raise ValueError(f"alpha_relax must be 0 (no limit) or in (1, 2), not "
                             f"{self.alpha_relax!r}")
        if self.floor_scaling not in FLOOR_SCALINGS:
            raise ValueError(f"floor_scaling must be one of {', '.join(FLOOR_SCALINGS)}, not "
                             f"{self.floor_scaling!r}")
        if not (isinstance(self.alpha_min, (int, float)) and isinstance(self.alpha_max, (int, float))
                and 0.0 < self.alpha_min < self.alpha_max < 1.0):
            raise ValueError(f"alpha limits must satisfy 0 < alpha_min < alpha_max < 1, not "
                             f"{self.alpha_min!r}, {self.alpha_max!r}")
        _int("latency_blocks", self.latency_blocks, 0)


class AngleTracker:
    """Two alpha-beta filters (u, v) per trial, batched over ``trials``.

    Parameters
    ----------
    config : TrackerConfig
    T_s : float
        Measurement interval (s): one matched-filter block.
    sigma_v : float
        Measurement noise standard deviation of a direction cosine (the adaptive filter's
        noise reference; :func:`dsp.monopulse.angles.crb_uv` at the design SNR).
    arithmetic : "float64", "float32" or AlphaBetaFormats
    trials : int
    u0, v0 : float or (trials,) arrays
        Initial direction (rate 0).
    """

    def __init__(self, config: TrackerConfig, T_s: float, sigma_v: float, *,
                 arithmetic="float64", trials: int = 1, u0=0.0, v0=0.0):
        if not isinstance(config, TrackerConfig):
            raise ValueError(f"config must be a TrackerConfig, not {config!r}")
        _num("T_s", T_s, 0)
        _num("sigma_v", sigma_v, 0)
        trials = _int("trials", trials, 1)
        self.config, self.T_s, self.sigma_v, self.trials = config, float(T_s), float(sigma_v), trials
        self.alpha, self.beta = kalata(tracking_index(T_s, config.sigma_a, sigma_v))
        adaptive = config.mode == "adaptive"
        if config.eq36 == "literal":
            tau, k = 0.0, T_s * T_s
        else:
            tau, k = config.noise_floor, config.manoeuvre_gain
        x0 = np.zeros((2 * trials, 2))
        x0[:trials, 0] = np.broadcast_to(np.asarray(u0, float), (trials,))
        x0[trials:, 0] = np.broadcast_to(np.asarray(v0, float), (trials,))
        self.filter = AlphaBetaFilter(
            T_s, self.alpha, self.beta, adaptive=adaptive, sigma_v=sigma_v, window=config.window,
            alpha_min=config.alpha_min, alpha_max=config.alpha_max, noise_floor=tau,
            manoeuvre_gain=k, floor_scaling=config.floor_scaling, alpha_relax=config.alpha_relax,
            arithmetic=arithmetic,
            trials=2 * trials, x0=x0, z_limit=1.0)
        self.kind = self.filter.kind
        self.lead = 1 + config.latency_blocks
        self.coefficients = np.broadcast_to(np.array([self.alpha, self.beta]), (2 * trials, 2)).copy()

    def update(self, u, v, valid=None):
        """One measurement per trial ``u``, ``v`` ((trials,)); ``valid`` False (or a NaN
        measurement): predict only. Returns the filtered ``(u, v)`` ((trials,) each)."""
        z = np.concatenate([np.broadcast_to(np.asarray(u, float), (self.trials,)),
                            np.broadcast_to(np.asarray(v, float), (self.trials,))])
        if valid is not None:
            ok = np.broadcast_to(np.asarray(valid, bool), (self.trials,))
            z = np.where(np.concatenate([ok, ok]), z, np.nan)
        r = self.filter.run(z[:, None])
        self.coefficients = r.coefficients[:, -1]
        x = r.x[:, -1, 0]
        return x[:self.trials], x[self.trials:]

    def state(self):
        """Physical ``(u, v, du_dt, dv_dt)`` of each trial."""
        f = self.filter
        x = f.x.astype(np.float64)
        if self.kind == "fixed":
            x = x * 2.0 ** -f.formats.x.frac
        pos, vel = x[:, 0], x[:, 1] / self.T_s
        n = self.trials
        return pos[:n], pos[n:], vel[:n], vel[n:]

    def predict(self, steps: int | None = None):
        """Direction ``steps`` measurement intervals after the last update (default: the
        steering lead ``1 + latency_blocks``), in the filter's arithmetic."""
        m = self.lead if steps is None else _int("steps", steps, 0)
        f = self.filter
        if self.kind == "fixed":
            fx = f.formats.x
            p = np.clip(f.x[:, 0] + m * f.x[:, 1], fx.min_int, fx.max_int) * 2.0 ** -fx.frac
        else:
            p = (f.x[:, 0] + f.x.dtype.type(m) * f.x[:, 1]).astype(np.float64)
        return p[:self.trials], p[self.trials:]

    def command(self, margin: float = 1e-6):
        """The beam-steering command: :meth:`predict` pulled inside the visible region."""
        u, v = self.predict()
        rho = np.hypot(u, v)
        s = np.where(rho >= 1.0 - margin, (1.0 - margin) / np.maximum(rho, 1e-300), 1.0)
        return u * s, v * s

    def reset(self, mask, u, v) -> None:
        """Re-initialise the trials in ``mask`` at direction ``(u, v)`` (rate 0)."""
        mask = np.asarray(mask, bool)
        if mask.shape != (self.trials,):
            raise ValueError(f"mask must have shape ({self.trials},), not {mask.shape}")
        m = int(mask.sum())
        u = np.broadcast_to(np.asarray(u, float), (self.trials,))[mask]
        v = np.broadcast_to(np.asarray(v, float), (self.trials,))[mask]
        x0 = np.zeros((2 * m, 2))
        x0[:m, 0], x0[m:, 0] = u, v
        self.filter.reset(np.concatenate([mask, mask]), x0)

    def counts(self) -> dict:
        return self.filter.counts()


def calibration_from_measurement(s_cal, reference: int = 0) -> np.ndarray:
    """Channel correction from a calibration measurement.

    ``s_cal`` (..., 4): matched-filter outputs of a calibration source at the steering
    direction (every channel then carries the same signal but for its gain/phase ``g_i``);
    leading axes are averaged. Returns ``c`` (4,) complex, ``c_i = S_ref / S_i``: multiplying
    channel ``i``'s correction by ``c_i`` equalises the channels to the reference.
    """
    s = np.asarray(s_cal)
    if s.ndim < 1 or s.shape[-1] != 4:
        raise ValueError(f"s_cal must have shape (..., 4), not {s.shape}")
    _int("reference", reference, 0, 3)
    m = s.reshape(-1, 4).mean(axis=0)
    if not np.all(np.isfinite(m)) or np.any(m == 0):
        raise ValueError(f"s_cal must be finite and non-zero in every channel, not {m!r}")
    return m[reference] / m


def search_pattern(step_u: float, step_v: float) -> np.ndarray:
    """The 5 beam positions around a centre: centre, +u, +v, -u, -v (offsets (5, 2))."""
    return np.array([[0, 0], [1, 0], [0, 1], [-1, 0], [0, -1]], float) * [step_u, step_v]


def search_centres(spacing_u: float, spacing_v: float) -> np.ndarray:
    """The 9 centres: the guided pointing, then the 8 around it (offsets (9, 2))."""
    ring = [[0, 0], [1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1]]
    return np.array(ring, float) * [spacing_u, spacing_v]


class SearchCapture:
    """Search / capture sequence of one trial (seed): 5 beam positions around the guided
    pointing, then each of 9 centres searched with the same 5-position pattern, then
    re-initialise (start again from the guided pointing); 50 dwells per cycle.

    A dwell whose sum beam exceeds the detection threshold starts a *capture*: the beam is
    steered at the monopulse measurement of that dwell; the capture is confirmed if the next
    measurement there is detected and within ``confirm_fraction`` of the unambiguous offset
    of its steering (a detection beyond the unambiguous region of the dwell reads a wrong,
    wrapped direction; steered there, the target falls near a null of the subarray pattern and
    the capture fails), else the search resumes where it was.

    Parameters
    ----------
    guided : (u, v)
        The guided (designated) pointing.
    step : (du, dv)
        Offset of the pattern's outer positions (default: the unambiguous offset).
    spacing : (du, dv)
        Spacing of the 9 centres (default: 2 steps).
    """

    PATTERN = 5
    CENTRES = 9

    def __init__(self, guided, step, spacing=None, confirm_fraction: float = 0.5,
                 unambiguous=None):
        gu, gv = (_num("guided pointing", float(x)) for x in guided)
        su, sv = (_num("search step", float(x), 0) for x in step)
        cu, cv = (2 * su, 2 * sv) if spacing is None else \
            (_num("search spacing", float(x), 0) for x in spacing)
        self.unambiguous = np.array((su, sv) if unambiguous is None else unambiguous, float)
        self.confirm_fraction = _num("confirm_fraction", confirm_fraction, 0, 1.0 + 1e-12)
        pat = search_pattern(su, sv)
        cen = search_centres(cu, cv)
        self.offsets = np.concatenate([pat] + [c + pat for c in cen])  # (50, 2)
        self.cycles = 0          # completed re-initialisations
        self.index = 0
        self.guide(gu, gv)

    def guide(self, u, v):
        """New guided pointing; restarts the sequence."""
        self.guided = np.array([u, v], float)
        self.index = 0

    @property
    def phase(self) -> str:
        """``"guided"`` (the first 5 dwells) or ``"centres"`` (the 9 x 5)."""
        return "guided" if self.index < self.PATTERN else "centres"

    def next_position(self, margin: float = 1e-6):
        """The next dwell's steering ``(u, v)`` (pulled inside the visible region); advances,
        and re-initialises after the 50th dwell."""
        p = self.guided + self.offsets[self.index]
        self.index += 1
        if self.index == len(self.offsets):
            self.index = 0
            self.cycles += 1
        rho = math.hypot(p[0], p[1])
        if rho >= 1.0 - margin:
            p = p * (1.0 - margin) / rho
        return float(p[0]), float(p[1])

    def confirmed(self, steering, measured, detected: bool) -> bool:
        """Whether a capture measurement at ``steering`` confirms the target."""
        d = np.abs(np.asarray(measured, float) - np.asarray(steering, float))
        return bool(detected) and bool(np.all(d < self.confirm_fraction * self.unambiguous))


def measure_uv(s, steering, dx_wl, dy_wl):
    """Monopulse ``(u, v)`` of outputs S (B, 4) at per-trial steering (B, 2)."""
    steering = np.asarray(steering, float)
    return direction_cosines(s, steering[:, 0], steering[:, 1], dx_wl, dy_wl)


__all__ = ["AngleTracker", "MONOPULSE_FORMATS", "SearchCapture", "TrackerConfig",
           "calibration_from_measurement", "measure_uv", "search_centres", "search_pattern"]
