"""Receiver oscillator phase noise from the power-law h-parameters.

The fractional-frequency noise ``y(t)`` has the one-sided power spectral density
``S_y(f) = h0 + h_1 / f + h_2 / f^2`` (1/Hz): white FM, flicker FM and random-walk FM
(IEEE Std 1139; ``h_1`` is written h-1 in the literature, ``h_2`` is h-2). The clock's time
error is ``x(t) = int y dt`` (s); at L1 it is a carrier phase of ``L1 x(t)`` cycles.
The generator draws ``x`` on a uniform grid of ``step_s``:

* white FM: ``x`` is a random walk, increment variance ``(h0 / 2) step``;
* random-walk FM: ``y`` is a random walk with intensity ``2 pi^2 h_2`` (the two-state clock
  model, RECEIVERS.md 2: q_phi = h0 / 2, q_omega = 2 pi^2 h-2), drawn with its exact
  discrete covariance ``2 pi^2 h_2 [[T^3/3, T^2/2], [T^2/2, T]]``;
* flicker FM: ``y`` shaped in the frequency domain (``|H(f)|^2 = S_y(f) fs / 2`` applied to
  unit white noise over twice the record, the first half kept), integrated to ``x``.

Between grid points the phase is interpolated linearly. The Allan variances these give,
``sigma_y^2(tau) = h0 / (2 tau) + 2 ln 2 h_1 + (2 pi^2 / 3) h_2 tau`` (for ``tau`` well
above the grid step for flicker FM), are what the tests check.

Tables (h0, h-1, h-2): the "typical" crystal-oscillator values of Brown & Hwang,
*Introduction to Random Signals and Applied Kalman Filtering* (Wiley; the clock-model
table of the GPS chapter, Table 9.2 in the 4th ed., 2012), as widely reproduced in GNSS
receiver literature. (Seed 003 cites O'Driscoll & Lachapelle 2011 for its oscillator
table, which is empty in the seed's text; we have not checked that paper's values.)

=========  ========  ========  ========
class      h0        h-1       h-2
=========  ========  ========  ========
TCXO       2e-19     7e-21     2e-20
OCXO       2e-25     7e-25     6e-25
=========  ========  ========  ========

(Entered from that table as it is commonly quoted, not re-read from the book in this
work: check against the book before quoting them in a publication.)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dsp.gnss.ca_code import L1_HZ


@dataclass(frozen=True)
class Oscillator:
    """Power-law coefficients of ``S_y(f)`` (1/Hz), all >= 0."""

    h0: float
    h_1: float
    h_2: float
    name: str = "custom"

    def __post_init__(self):
        for k in ("h0", "h_1", "h_2"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v) or v < 0:
                raise ValueError(f"oscillator {k} must be a finite number >= 0, not {v!r}")

    def allan_variance(self, tau_s):
        """``sigma_y^2(tau)`` of the three power laws (the continuous-time values)."""
        tau = np.asarray(tau_s, dtype=np.float64)
        return self.h0 / (2 * tau) + 2 * math.log(2) * self.h_1 + 2 * math.pi ** 2 / 3 * self.h_2 * tau


#: Brown & Hwang (4th ed.) Table 9.2 "typical" values (module docstring).
OSCILLATORS = {
    "tcxo": Oscillator(2e-19, 7e-21, 2e-20, "tcxo"),
    "ocxo": Oscillator(2e-25, 7e-25, 6e-25, "ocxo"),
}


def oscillator(spec) -> Oscillator | None:
    """``None``, an :class:`Oscillator`, or a table name (``"tcxo"``, ``"ocxo"``)."""
    if spec is None or isinstance(spec, Oscillator):
        return spec
    if isinstance(spec, str) and spec.lower() in OSCILLATORS:
        return OSCILLATORS[spec.lower()]
    raise ValueError(f"oscillator must be None, an Oscillator or one of "
                     f"{sorted(OSCILLATORS)}, not {spec!r}")


def clock_error_s(osc: Oscillator, n_steps: int, step_s: float,
                  rng: np.random.Generator) -> np.ndarray:
    """The clock time error ``x`` (s) on the grid ``k step_s``, ``k = 0..n_steps``, x[0] = 0.

    Each component draws from its own child of ``rng`` in a fixed order, so turning one
    coefficient to 0 does not change the others' draws.
    """
    T = float(step_s)
    n = int(n_steps)
    r_white, r_rw, r_flk = rng.spawn(3)
    x = np.zeros(n + 1)
    if osc.h0 > 0:
        x[1:] += np.cumsum(r_white.standard_normal(n)) * math.sqrt(osc.h0 / 2 * T)
    if osc.h_2 > 0:
        q = 2 * math.pi ** 2 * osc.h_2
        L = np.linalg.cholesky(q * np.array([[T ** 3 / 3, T ** 2 / 2], [T ** 2 / 2, T]]))
        w = r_rw.standard_normal((n, 2)) @ L.T      # (dx, dy) increments
        y = np.concatenate(([0.0], np.cumsum(w[:, 1])))
        # x_{k+1} = x_k + T y_k + w_x
        x[1:] += np.cumsum(T * y[:-1] + w[:, 0])
    if osc.h_1 > 0:
        m = 2 * max(n, 1)
        f = np.fft.rfftfreq(m, d=T)
        H = np.zeros_like(f)
        H[1:] = np.sqrt(osc.h_1 / f[1:] / (2 * T))   # S_y(f) fs / 2 with unit white noise
        y = np.fft.irfft(np.fft.rfft(r_flk.standard_normal(m)) * H, n=m)[:n]
        x[1:] += np.cumsum(y) * T
    return x


def allan_variance_from_phase(x: np.ndarray, step_s: float, m: int) -> float:
    """Overlapping Allan variance at ``tau = m step_s`` from phase (time-error) samples."""
    d = x[2 * m:] - 2 * x[m:-m] + x[:-2 * m]
    tau = m * step_s
    return float(np.mean(d * d) / (2 * tau * tau))


class OscillatorPhase:
    """The oscillator's carrier phase (L1 cycles) at any time of a realised record."""

    def __init__(self, osc: Oscillator | None, duration_s: float, step_s: float,
                 rng: np.random.Generator):
        self.step_s = float(step_s)
        n = int(math.ceil(duration_s / self.step_s)) + 1
        self.x = np.zeros(n + 1) if osc is None else clock_error_s(osc, n, self.step_s, rng)
        self.active = osc is not None

    def phase_cycles(self, t_s) -> np.ndarray:
        """``-L1 x(t)`` (cycles): a fast receiver clock makes the downconverted phase lag."""
        t = np.asarray(t_s, dtype=np.float64)
        if not self.active:
            return np.zeros(t.shape)
        u = t / self.step_s
        k = np.clip(np.floor(u).astype(np.int64), 0, self.x.size - 2)
        f = u - k
        return -L1_HZ * (self.x[k] + f * (self.x[k + 1] - self.x[k]))
