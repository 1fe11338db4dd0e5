"""Configuration of the TACAN envelope Kalman filter (:mod:`dsp.tacan.kalman`): the filter
(:class:`KalmanConfig`, memory, gate, noise rates; the golden float64 filter) and the
word lengths of its fixed-point core (:class:`KalmanFixedConfig`, which contains the
:class:`KalmanConfig`), with the constants each arithmetic's kernel receives."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..fixed import FixedFormat
from ..qops import S_BITS
from .bearing import PHASE_BITS
from .phase_ops import TRIG_FRAC
from .standard import F15, F135

#: Fraction bits of the gate^2 constant and extra fraction bits of the Q-per-tick rates.
GATE_FRAC = 8
Q_EXTRA = 16
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
    input_limit : float, optional
        Largest plausible ``|amplitude|`` (signal units). A value beyond it is not a
        measurement: the step only predicts, counted as ``implausible``, and neither the
        gate, the divergence count nor the ``r`` estimate sees it -- so garbage cannot be
        fitted, not even by a filter that has just re-initialised. ``None`` (default): the
        fixed core's input range, i.e. its ``y`` format (a value it cannot hold is
        implausible rather than saturated); no limit in float (the golden filter takes
        amplitudes on any scale).
    tick_hz : float
        The clock of integer timestamps (Hz, >= 135 kHz): the ADC sample rate the front end
        stamps its peaks with. The fixed-point core's frequency words and the float filter's
        tick-to-second conversion read it, and so does the receiver
        (:func:`dsp.tacan.receiver.process_peaks`): the one place the clock is given.
    """

    memory_s: float = 0.5
    pulse_rate_hz: float = 7200.0
    p0: float = 1.0e4
    gate: float = 5.0
    warmup: int = 400
    max_rejects: int = 64
    r_smooth: int = 512
    input_limit: float | None = None
    tick_hz: float = 20e6

    def __post_init__(self):
        t = self.tick_hz
        if isinstance(t, bool) or not (isinstance(t, (int, float)) and math.isfinite(t)
                                       and t >= 1000 * F135):
            raise ValueError(f"tick_hz must be a finite number >= {1000 * F135:g}, not {t!r}")
        if self.input_limit is not None and not (
                isinstance(self.input_limit, (int, float)) and math.isfinite(self.input_limit)
                and self.input_limit > 0):
            raise ValueError(f"input_limit must be a finite number > 0 or None, not "
                             f"{self.input_limit!r}")
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



def _default(width, frac):
    return FixedFormat(width, frac, True, "half_up", "saturate")


@dataclass(frozen=True)
class KalmanFixedConfig:
    """The float :class:`KalmanConfig` plus the fixed-point word lengths (see module doc).

    Every format must be signed, round ``"half_up"`` or ``"floor"`` and ``"saturate"``; the
    combinations are checked so that no int64 intermediate can overflow.
    """

    kalman: KalmanConfig = field(default_factory=KalmanConfig)
    y: FixedFormat = field(default_factory=lambda: _default(18, 16))
    x: FixedFormat = field(default_factory=lambda: _default(36, 28))
    P: FixedFormat = field(default_factory=lambda: _default(46, 30))
    K: FixedFormat = field(default_factory=lambda: _default(38, 30))
    cs: FixedFormat = field(default_factory=lambda: _default(24, 22))
    innov: FixedFormat = field(default_factory=lambda: _default(24, 20))
    r: FixedFormat = field(default_factory=lambda: _default(40, 30))

    def __post_init__(self):
        if not isinstance(self.kalman, KalmanConfig):
            raise ValueError(f"kalman must be a KalmanConfig, not {self.kalman!r}")
        for name in ("y", "x", "P", "K", "cs", "innov", "r"):
            f = getattr(self, name)
            if not isinstance(f, FixedFormat):
                raise ValueError(f"{name} must be a FixedFormat, not {f!r}")
            if not f.signed:
                raise ValueError(f"{name} format must be signed, not {f}")
            if f.rounding not in ("half_up", "floor"):
                raise ValueError(f"{name} rounding must be 'half_up' or 'floor', "
                                 f"not {f.rounding!r}")
            if f.overflow != "saturate":
                raise ValueError(f"{name} overflow must be 'saturate', not {f.overflow!r}")
            if f.frac < 0:
                raise ValueError(f"{name} frac must be >= 0, not {f.frac}")
        y, x, P, K, cs, iv, r = self.y, self.x, self.P, self.K, self.cs, self.innov, self.r
        if not (cs.int_bits >= 1 and cs.frac <= TRIG_FRAC):
            raise ValueError(f"cs must hold +-1 with at most {TRIG_FRAC} fraction bits, not {cs}")
        if not (x.frac >= y.frac and x.frac >= iv.frac):
            raise ValueError(f"x needs at least as many fraction bits as y and innov "
                             f"(x {x}, y {y}, innov {iv})")
        if x.width + cs.width > 61 or K.width + iv.width > 62:
            raise ValueError(f"x*cs and K*innov products must fit 62 bits "
                             f"(x {x}, cs {cs}, K {K}, innov {iv})")
        if K.frac + iv.frac < x.frac:
            raise ValueError(f"K.frac + innov.frac must be >= x.frac (K {K}, innov {iv}, x {x})")
        if P.width - cs.frac + cs.width + 1 > 62 or cs.frac + cs.width + 1 > 62:
            raise ValueError(f"the split P*cs product does not fit int64 (P {P}, cs {cs})")
        if P.width + 2 + 2 * K.width > 124 or K.frac < 1 or K.frac > 40:
            raise ValueError(f"the split P*K product does not fit int64 (P {P}, K {K})")
        if P.frac < 12:
            raise ValueError(f"P needs at least 12 fraction bits, not {P}")
        if 2 * iv.width > 48:
            raise ValueError(f"innov must be at most 24 bits wide (its square feeds e2), not {iv}")
        if not (0 <= r.frac - 2 * iv.frac + P.frac + (S_BITS - P.frac + 12) <= 33) or r.width > 48:
            raise ValueError(f"r format {r} does not fit e2 = innov^2/S with innov {iv}, P {P}")
        if 2 * self.kalman.p0 > P.max_value:
            raise ValueError(f"p0={self.kalman.p0:g} does not fit the P format {P} "
                             f"(needs p0 <= {P.max_value / 2:g})")
        if r.max_value < 1.0:
            raise ValueError(f"r format {r} must hold the initial r = 1")

    @property
    def tick_hz(self) -> float:
        """The clock of the timestamps the core counts (:attr:`KalmanConfig.tick_hz`)."""
        return self.kalman.tick_hz

    def int_consts(self) -> np.ndarray:
        """Integer parameters of the kernel: counters and, per format, frac/min/max/half-up."""
        k = self.kalman
        c = [k.warmup, k.max_rejects, k.r_smooth, GATE_FRAC, Q_EXTRA]
        for f in (self.y, self.x, self.P, self.K, self.cs, self.innov, self.r):   # 5..32
            c += [f.frac, f.min_int, f.max_int, 1 if f.rounding == "half_up" else 0]
        return np.array(c, dtype=np.int64)

    def value_consts(self) -> np.ndarray:
        """The quantised constants (built once from floats: the boundary)."""
        k = self.kalman
        q_rot, q_dc = k.q_rates()
        qf = self.P.frac + Q_EXTRA
        scale = 2.0 ** PHASE_BITS / self.tick_hz
        return np.array([
            int(round(F15 * scale)), int(round(F135 * scale)),       # frequency words
            int(round(q_rot / self.tick_hz * 2.0 ** qf)),            # q_rot per tick
            int(round(q_dc / self.tick_hz * 2.0 ** qf)),             # q_dc per tick
            int(round(k.p0 * 2.0 ** self.P.frac)),                   # p0
            min(int(round(k.gate ** 2 * (1 << GATE_FRAC))), 1 << 40),  # gate^2
            1 << self.r.frac,                                        # r init = 1
            np.iinfo(np.int64).min,                                  # "no measurement"
        ], dtype=np.int64)


def float_consts(k: KalmanConfig) -> np.ndarray:
    q_rot, q_dc = k.q_rates()
    return np.array([2 * math.pi * F15, 2 * math.pi * F135, q_rot, q_dc, k.p0, k.gate ** 2, 1.0,
                     math.nan])                                      # "no measurement"
