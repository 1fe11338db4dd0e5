"""Receiver oscillator phase noise from the power-law h-parameters.

The fractional-frequency noise ``y(t)`` has the one-sided power spectral density
``S_y(f) = h0 + h_1 / f + h_2 / f^2`` (1/Hz): white FM, flicker FM and random-walk FM
(IEEE Std 1139; ``h_1`` is written h-1 in the literature, ``h_2`` is h-2). The clock's time
error is ``x(t) = int y dt`` (s); at L1 it is a carrier phase of ``L1 x(t)`` cycles.
The generator draws ``x`` on a uniform grid of ``step_s``:

* white FM: ``x`` is a random walk, increment variance ``(h0 / 2) step``;
* random-walk FM: ``y`` is a random walk with intensity ``2 pi^2 h_2`` (the two-state clock
  model: q_phi = h0 / 2, q_omega = 2 pi^2 h-2), drawn with its exact
  discrete covariance ``2 pi^2 h_2 [[T^3/3, T^2/2], [T^2/2, T]]``;
* flicker FM: ``y`` shaped in the frequency domain (``|H(f)|^2 = S_y(f) fs / 2`` applied to
  unit white noise over twice the record, the first half kept), integrated to ``x``.

Between grid points the phase is interpolated linearly. The Allan variances these give,
``sigma_y^2(tau) = h0 / (2 tau) + 2 ln 2 h_1 + (2 pi^2 / 3) h_2 tau`` (for ``tau`` well
above the grid step for flicker FM), are what the tests check.

Tables (h0, h-1, h-2) and the :class:`Oscillator` model: :mod:`dsp.gnss.oscillator` (the DSP's
loops take their process noise from them too).
"""
from __future__ import annotations

import math

import numpy as np

from dsp.gnss.ca_code import L1_HZ
from dsp.gnss.oscillator import OSCILLATORS, Oscillator, oscillator  # noqa: F401


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
