"""Correlation efficiency of a memoryless quantiser (an ADC) for Gaussian noise: the
theory of the quantisation loss of a matched filter in the weak-signal limit.

The Monte Carlo that reproduces these figures is :mod:`cosim.studies.adc_loss`; the GNSS
fast path scales its correlator SNR by :func:`quantizer_efficiency`.

Theory
------
Let ``x = s + n`` with ``n ~ N(0, sigma^2)`` white and a signal ``|s| << sigma`` (per-sample
SNR far below 0 dB), digitised by a memoryless quantiser ``q = Q(x)``. For a weak signal the
quantiser is linear on average (Bussgang; Price's theorem):

    E[q | s] = g s + O(s^3),   g = E[n Q(n)] / sigma^2  (= E[Q'(n)] by Stein's lemma),

and the output fluctuation is that of ``Q(n)``: variance ``Var Q(n)``, white, since a
memoryless function of white Gaussian noise is white. A coherent matched filter (correlation
with the known tone over ``N`` samples) therefore sees its output SNR multiplied by the
*correlation efficiency*

    eta = E[n Q(n)]^2 / (E[n^2] Var Q(n)),

the squared correlation coefficient between quantiser input and output; the loss is
``-10 log10(eta)`` dB. The mean of ``Q(n)`` is removed (``Var`` rather than ``E[Q^2]``):
a DC offset (an asymmetric quantiser, e.g. the two's-complement mid-tread ADC) is rejected
by the tone correlator and is not noise.

For a quantiser with thresholds ``t_1 < ... < t_{L-1}`` and levels ``l_0 .. l_{L-1}`` the
Gaussian integrals are exact sums over the cells ``[t_i, t_{i+1})`` (``t_0 = -inf``,
``t_L = +inf``; ``phi``, ``Phi`` the standard normal density and distribution):

    E[n Q]   = sigma * sum_i l_i (phi(t_i / sigma) - phi(t_{i+1} / sigma)),
    E[Q^k]   = sum_i l_i^k (Phi(t_{i+1} / sigma) - Phi(t_i / sigma)),   k = 1, 2.

(:func:`efficiency` evaluates them with ``scipy.special.ndtr``; the test suite cross-checks
them against ``scipy.integrate.quad``.) For more than 2**16 levels the sum is replaced by its
high-resolution expansion (granular noise ``Delta^2 / 12`` corrected for the Gaussian
curvature, plus the exact clipping terms, error ``O(Delta^4)``): at the optimal step it
agrees with the exact sum to 4e-5 relative in ``1 - eta`` at 5 bits and 4e-10 at 10 bits,
beyond which the rounding of the exact sum (1e-16 on ``eta``) dominates.

Known values, all reproduced by :func:`quantizer_efficiency` / :func:`optimal_step`:

* 1 bit (sign, "hard limiter", Van Vleck): ``E[|n|] = sigma sqrt(2/pi)``, ``Var = 1``:
  ``eta = 2/pi = 0.6366``, loss ``10 log10(pi/2) = 1.961 dB``, for any step.
* 2 bits (four levels): Thompson, Moran & Swenson, *Interferometry and Synthesis in Radio
  Astronomy*, ch. 8: ``eta = 0.8825`` at the optimum (thresholds ``+-0.98 sigma``, outer/inner
  level ratio 3.34); with the uniform levels of a 2-bit ADC (ratio 3) the optimum threshold
  is ``0.996 sigma`` and ``eta = 0.8812`` (loss 0.549 dB).
* More bits: uniform quantiser, step chosen to maximise ``eta``. The optimum coincides with
  Max's (1960) minimum-MSE uniform step for a Gaussian input: 0.9957, 0.5860, 0.3352,
  0.1881, 0.1041 sigma for 2..6 bits; then ``1 - eta`` is about ``Delta^2 / 12`` plus the
  clipping power.


ADC model
---------
The word length ``b`` gives two's-complement codes ``c`` in ``[-2**(b-1), 2**(b-1) - 1]`` and
the step ``Delta = full_scale / 2**(b-1)``. Two conventions:

``"mid_rise"`` (default, the one the theory above is tabulated for)
    ``c = clip(floor(x / Delta))`` and the code means ``(c + 1/2) Delta``: levels
    ``+-(k + 1/2) Delta``, symmetric, thresholds at multiples of ``Delta``, clipping at
    ``+-(full_scale - Delta)``. With one bit this is the **sign only**: levels
    ``+-Delta/2``, threshold at 0, so the step (loading) does not matter.
``"mid_tread"``
    Exactly the ADC of the TACAN signal generator: ``c = clip(rint(x / Delta))``, meaning
    ``c Delta`` -- zero is a level, clipping is asymmetric (``-full_scale`` .. ``full_scale -
    Delta``). Note that with one bit this ADC is *not* a sign detector: its only threshold
    sits at ``-Delta/2`` (half of full scale).
"""
from __future__ import annotations

import functools
import math

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import ndtr

__all__ = ["MAX_BITS", "QUANTIZERS", "REFERENCE_LOSS_DB", "efficiency", "quantizer_cells",
           "quantizer_moments", "quantizer_efficiency", "theoretical_loss_db", "optimal_step",
           "clip_fraction"]

#: Largest ADC word length accepted (as the TACAN signal generator's ``adc_bits``).
MAX_BITS = 24
#: Quantiser conventions (see the module docstring).
QUANTIZERS: tuple[str, ...] = ("mid_rise", "mid_tread")
#: Published matched-filter losses (dB) of the sign-only 1-bit ADC (exactly
#: ``10 log10(pi/2)``, Van Vleck) and of the 2-bit ADC at its optimal step (0.55 dB,
#: Thompson, Moran & Swenson ch. 8).
REFERENCE_LOSS_DB = {1: 10.0 * math.log10(math.pi / 2.0), 2: 0.55}

# Above this many levels the efficiency uses the high-resolution expansion.
_EXACT_MAX_LEVELS = 1 << 16
# optimal_step searches on the expansion from this word length on.
_OPT_HR_MIN_BITS = 10
_SQRT_2PI = math.sqrt(2.0 * math.pi)


# -- argument checks (the rules and messages of cosim.validate; dsp stands alone) ---------
def _check_bits(bits) -> int:
    if not isinstance(bits, bool) and isinstance(bits, (int, np.integer)) \
            and 1 <= bits <= MAX_BITS:
        return int(bits)
    raise ValueError(f"bits must be an integer in [1, {MAX_BITS}], not {bits!r}")


def _check_quantizer(quantizer) -> str:
    if quantizer not in QUANTIZERS:
        raise ValueError(f"quantizer must be one of {', '.join(QUANTIZERS)}, "
                         f"not {quantizer!r}")
    return quantizer


def _check_positive(name: str, value) -> float:
    if (not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
            and math.isfinite(value) and float(value) > 0):
        return float(value)
    raise ValueError(f"{name} must be a finite number > 0, not {value!r}")


# -- theory ------------------------------------------------------------------------------
def _phi(x: np.ndarray) -> np.ndarray:
    """Standard normal density, 0 at +-inf."""
    x = np.asarray(x, dtype=float)
    out = np.zeros_like(x)
    ok = np.isfinite(x)
    out[ok] = np.exp(-0.5 * x[ok] * x[ok]) / _SQRT_2PI
    return out


def _cell_probabilities(edges: np.ndarray) -> np.ndarray:
    """P(edges[i] <= n < edges[i+1]) for n ~ N(0, 1), accurate in both tails."""
    lo, hi = edges[:-1], edges[1:]
    upper = lo > 0  # right tail: difference of upper-tail probabilities (no cancellation)
    return np.where(upper, ndtr(-lo) - ndtr(-hi), ndtr(hi) - ndtr(lo))


def _moments_cells(thresholds, levels) -> tuple[float, float, float]:
    """E[Q], E[n Q], E[Q^2] for n ~ N(0, 1), exact (sums over the cells)."""
    t = np.asarray(thresholds, dtype=float)
    lv = np.asarray(levels, dtype=float)
    edges = np.concatenate(([-np.inf], t, [np.inf]))
    p = _cell_probabilities(edges)
    ph = _phi(edges)
    return float(np.dot(lv, p)), float(np.dot(lv, ph[:-1] - ph[1:])), float(np.dot(lv * lv, p))


def efficiency(thresholds, levels) -> float:
    """Correlation efficiency of an arbitrary quantiser for a zero-mean unit Gaussian input.

    Parameters
    ----------
    thresholds : array_like, shape (L - 1,)
        Strictly increasing decision thresholds, in noise sigmas.
    levels : array_like, shape (L,)
        Output level of each cell ``[t_{i}, t_{i+1})`` (``t_0 = -inf``, ``t_L = +inf``).

    Returns
    -------
    float
        ``eta = E[n Q(n)]^2 / (E[n^2] Var Q(n))`` in [0, 1]; the matched-filter SNR loss is
        ``-10 log10(eta)``. E.g. ``efficiency([0], [-1, 1]) == 2/pi`` and the optimum
        four-level quantiser of Thompson, Moran & Swenson (ch. 8),
        ``efficiency([-0.98, 0, 0.98], [-3.34, -1, 1, 3.34])``, is 0.8825.

    Raises
    ------
    ValueError
        If the sizes do not match, values are not finite, thresholds do not increase, or
        the output is constant.
    """
    t = np.asarray(thresholds, dtype=float).ravel()
    lv = np.asarray(levels, dtype=float).ravel()
    if lv.size != t.size + 1:
        raise ValueError(f"need len(levels) == len(thresholds) + 1, got {lv.size} levels "
                         f"and {t.size} thresholds")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(lv))):
        raise ValueError("thresholds and levels must be finite")
    if t.size and not np.all(np.diff(t) > 0):
        raise ValueError("thresholds must be strictly increasing")
    e1, exq, e2 = _moments_cells(t, lv)
    var = e2 - e1 * e1
    if not var > 0:
        raise ValueError("the quantiser output is constant (zero variance)")
    return exq * exq / var


def quantizer_cells(bits: int, step: float, quantizer: str = "mid_rise"
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Thresholds and levels of the b-bit ADC model (in the units of ``step``).

    Parameters
    ----------
    bits : int
        Word length, 1..24 (two's-complement codes ``-2**(b-1) .. 2**(b-1) - 1``).
    step : float
        Quantisation step (one LSB), > 0.
    quantizer : {"mid_rise", "mid_tread"}
        Level convention (see the module docstring).

    Returns
    -------
    thresholds, levels : ndarray
        ``2**b - 1`` thresholds and ``2**b`` levels, increasing.
    """
    b = _check_bits(bits)
    d = _check_positive("step", step)
    _check_quantizer(quantizer)
    k = 1 << (b - 1)
    codes = np.arange(-k, k, dtype=float)
    if quantizer == "mid_rise":
        return codes[1:] * d, (codes + 0.5) * d
    return (codes[:-1] + 0.5) * d, codes * d


def _edges(bits: int, step: float, quantizer: str) -> tuple[float, float, float, float]:
    """Lowest/highest threshold and the outer levels (lo, hi, l_lo, l_hi)."""
    k = 1 << (bits - 1)
    if quantizer == "mid_rise":
        return -(k - 1) * step, (k - 1) * step, -(k - 0.5) * step, (k - 0.5) * step
    return -(k - 0.5) * step, (k - 1.5) * step, -k * step, (k - 1) * step


def _moments_high_resolution(bits: int, step: float, quantizer: str
                             ) -> tuple[float, float, float]:
    """E[Q], E[n Q], E[Q^2] for many levels: interior cells expanded to O(step^2)."""
    a, c, l_lo, l_hi = _edges(bits, step, quantizer)
    pa, pc = _phi(np.array([a, c]))
    j0 = ndtr(c) - ndtr(a)
    j1 = pa - pc
    j2 = j0 + a * pa - c * pc
    g = step * step / 12.0
    p_lo, p_hi = ndtr(a), ndtr(-c)
    e1 = j1 * (1.0 + g) + l_lo * p_lo + l_hi * p_hi
    exq = j2 - g * (j0 - j2) - l_lo * pa + l_hi * pc
    e2 = j2 + g * (2.0 * j2 - j0) + l_lo * l_lo * p_lo + l_hi * l_hi * p_hi
    return float(e1), float(exq), float(e2)


def quantizer_moments(bits: int, step: float, quantizer: str = "mid_rise",
                      *, method: str = "auto") -> tuple[float, float, float]:
    """``(E[Q], E[n Q], E[Q^2])`` of the ADC model for ``n ~ N(0, 1)``.

    ``method="exact"`` sums over the cells, ``"high_resolution"`` uses the expansion for
    many levels, ``"auto"`` the exact sum up to 2**16 levels.
    """
    b = _check_bits(bits)
    d = _check_positive("step", step)
    _check_quantizer(quantizer)
    if method not in ("auto", "exact", "high_resolution"):
        raise ValueError(f"method must be 'auto', 'exact' or 'high_resolution', not {method!r}")
    if method == "exact" or (method == "auto" and (1 << b) <= _EXACT_MAX_LEVELS):
        return _moments_cells(*quantizer_cells(b, d, quantizer))
    return _moments_high_resolution(b, d, quantizer)


def quantizer_efficiency(bits: int, step: float, *, quantizer: str = "mid_rise",
                         method: str = "auto") -> float:
    """Correlation efficiency ``eta`` of the b-bit ADC model for Gaussian noise.

    Parameters
    ----------
    bits : int
        Word length, 1..24.
    step : float
        Quantisation step (LSB) in noise sigmas, > 0; full scale is ``step * 2**(bits-1)``.
    quantizer : {"mid_rise", "mid_tread"}
        Level convention (see the module docstring).
    method : {"auto", "exact", "high_resolution"}
        Exact cell sums, or the O(step^2) expansion for many levels (default above 2**16).

    Returns
    -------
    float
        ``eta = E[n Q(n)]^2 / Var Q(n)`` (unit-variance input); loss ``-10 log10(eta)`` dB.
        ``quantizer_efficiency(1, s) == 2/pi`` for any ``s`` (mid-rise 1 bit is the sign).
    """
    e1, exq, e2 = quantizer_moments(bits, step, quantizer, method=method)
    var = e2 - e1 * e1
    if not var > 0:
        return 0.0
    return exq * exq / var


def theoretical_loss_db(bits: int, step: float, *, quantizer: str = "mid_rise") -> float:
    """``-10 log10(eta)``: matched-filter SNR loss (dB) of the ADC model, weak-signal limit."""
    eta = quantizer_efficiency(bits, step, quantizer=quantizer)
    return math.inf if eta <= 0 else -10.0 * math.log10(eta)


@functools.lru_cache(maxsize=None)
def _optimal_step(bits: int, quantizer: str) -> float:
    k = 1 << (bits - 1)
    if quantizer == "mid_rise" and bits == 1:
        # Sign: any step. Return Max's 1-bit quantiser, levels +-E|n| = +-sqrt(2/pi).
        return 2.0 * math.sqrt(2.0 / math.pi)
    if quantizer == "mid_tread" and bits == 1:
        raise ValueError("a 1-bit mid-tread ADC has no optimal step: its only threshold is at "
                         "-step/2 and eta increases towards 2/pi (the sign) as step -> 0; "
                         "use quantizer='mid_rise' for a 1-bit sign ADC")

    # From 10 bits on, search on the high-resolution expansion: it equals the exact sum to
    # < 1e-9 relative in 1 - eta there, is O(1) instead of O(2**b), and is free of the
    # rounding noise of the exact sum (which makes a 16-bit optimum search jittery).
    method = "high_resolution" if bits >= _OPT_HR_MIN_BITS else "exact"

    def neg_eta(log_fs: float) -> float:
        return -quantizer_efficiency(bits, math.exp(log_fs) / k, quantizer=quantizer,
                                     method=method)

    # Coarse grid over the full scale (0.3 .. 12 sigma covers 2..24 bits), then Brent.
    grid = np.linspace(math.log(0.3), math.log(12.0), 49)
    vals = np.array([neg_eta(g) for g in grid])
    i = int(np.argmin(vals))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    res = minimize_scalar(neg_eta, bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-10, "maxiter": 500})
    best = res.x if res.fun <= vals[i] else grid[i]
    return math.exp(best) / k


def optimal_step(bits: int, *, quantizer: str = "mid_rise") -> float:
    """The step (in noise sigmas) maximising the correlation efficiency of a b-bit ADC.

    Found numerically (grid over the full scale, then bounded Brent) on
    :func:`quantizer_efficiency` (exact cell sums below 10 bits, the high-resolution
    expansion from 10 bits on); cached.

    Parameters
    ----------
    bits : int
        Word length, 1..24.
    quantizer : {"mid_rise", "mid_tread"}

    Returns
    -------
    float
        Mid-rise: 0.9957 (2 bits), 0.5860 (3), 0.3352 (4), 0.1881 (5), ... -- Max's uniform
        optimum. For 1 bit mid-rise (sign) every step is optimal; ``2 sqrt(2/pi)`` (levels
        ``+-E|n|``) is returned.

    Raises
    ------
    ValueError
        Bad ``bits``/``quantizer``, or 1-bit mid-tread (no optimum, see the message).
    """
    return _optimal_step(_check_bits(bits), _check_quantizer(quantizer))


def clip_fraction(bits: int, step: float, quantizer: str = "mid_rise") -> float:
    """Probability that unit Gaussian noise falls in one of the two outer (clipping) cells
    of the b-bit ADC model with ``step`` in noise sigmas."""
    a, c, _, _ = _edges(_check_bits(bits), _check_positive("step", step),
                        _check_quantizer(quantizer))
    return float(ndtr(a) + ndtr(-c))
