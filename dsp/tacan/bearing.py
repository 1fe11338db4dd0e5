"""Bearing from the envelope phases at the references, and the coarse/fine combination.

With the convention of :mod:`cosim.tacan.signal` (the 15 Hz component is
``A sin(2 pi 15 (t - t_M) - theta)``), the Kalman state at a pulse at ``t_k`` has 15 Hz
phase ``alpha_k = 2 pi 15 (t_k - t_M) - theta``, hence the TACAN paper's eq. 15
``theta = theta_a - theta_b`` with ``theta_a = 2 pi 15 (t_k - t_M)`` (phase of the pulse
after the reference) and ``theta_b = alpha_k = atan2(x1, x2)`` (eq. 16). The 135 Hz
component gives ``9 theta mod 2 pi`` the same way from the latest auxiliary (or main)
reference.

Coarse/fine combination: the paper's eq. 17, ``40 floor(theta_15 / 40) + theta_135 / 9``,
takes the 40-degree sector from the coarse bearing alone, so it slips a whole sector
whenever the true bearing is near a sector edge and the coarse error crosses it. Here the
fine bearing's nine candidates ``(phi + 360 i) / 9`` are compared with the coarse bearing and
the nearest (circular distance) is taken: correct whenever the coarse error is below 20
degrees, at every bearing. The resolved fine bearing and the coarse bearing are then
combined with weights ``m1^2 : 81 m2^2`` (their Fisher information).

Fixed point (what the DSP does with integers only): angles are *binary angles* of
:data:`ANGLE_BITS` = 32 bits per turn (LSB 8.4e-8 deg), reduced mod ``2**32`` so that
sums and differences wrap like a 32-bit register. :func:`combine_coarse_fine_fixed` is the
combination above with integer candidate choice, a restoring divider for the weight
fraction and one rounding (<= 0.62 LSB from the exact result); :func:`bearing_from_state`
goes from the integer Kalman state (:class:`dsp.tacan.kalman_config.KalmanFixedConfig`, s36.28)
and the 40-bit phase advances since the references (:func:`reference_advances`) to the
bearing with the vectoring CORDIC of :mod:`dsp.cordic` (<= 2.1 LSB from the float path on
the same state). :func:`deg_to_bangle`/:func:`bangle_to_deg` (and the radian forms) are the
float boundary.
"""
from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

from ..cordic import CordicConfig
from ..fixed import FixedFormat
from .standard import F15, F135

TWO_PI = 2 * np.pi


def wrap_pi(a):
    """Wrap angles (rad) to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % TWO_PI - np.pi


def wrap_deg(a):
    """Wrap angles (deg) to [-180, 180)."""
    return (np.asarray(a, dtype=np.float64) + 180.0) % 360.0 - 180.0


def combine_coarse_fine(coarse_rad, fine9_rad, w_coarse=None, w_fine=None):
    """Bearing (rad, [0, 2 pi)) from the coarse bearing and the fine phase ``9 theta``.

    Parameters
    ----------
    coarse_rad : array
        Coarse bearing from the 15 Hz component.
    fine9_rad : array
        ``9 * theta mod 2 pi`` from the 135 Hz component.
    w_coarse, w_fine : array, optional
        Information weights (``m1**2`` and ``81 m2**2``); default: fine only.
    """
    coarse = np.asarray(coarse_rad, dtype=np.float64) % TWO_PI
    base = (np.asarray(fine9_rad, dtype=np.float64) % TWO_PI) / 9.0
    # Candidate i = base + i * 40 deg; nearest to coarse, circularly.
    i = np.rint(wrap_pi(coarse - base) / (TWO_PI / 9.0))
    fine = base + i * (TWO_PI / 9.0)
    if w_coarse is None or w_fine is None:
        return fine % TWO_PI
    wc = np.asarray(w_coarse, dtype=np.float64)
    wf = np.asarray(w_fine, dtype=np.float64)
    tot = wc + wf
    frac = np.divide(wc, tot, out=np.zeros_like(tot), where=tot > 0)
    return (fine + frac * wrap_pi(coarse - fine)) % TWO_PI


def paper_eq17(coarse_deg, fine135_deg):
    """The TACAN paper's eq. 17 as printed (kept to show the sector slip it suffers)."""
    return 40.0 * np.floor(np.asarray(coarse_deg) / 40.0) + np.asarray(fine135_deg) / 9.0


# ---------------------------------------------------------------------------------------
# Fixed point: binary angles, integers only
# ---------------------------------------------------------------------------------------
# A *binary angle* of ``b`` bits is an integer where ``2**b`` is one full turn; angles are
# held in int64 reduced mod ``2**b`` (``[0, 2**b)``), so additions and subtractions wrap
# naturally, as a ``b``-bit register does.

#: Bits per turn of the bearing-side binary angles: LSB = 360 / 2**32 = 8.4e-8 deg, far
#: below the filter's noise (~1e-3 deg), and two angles times a 30-bit fraction still fit
#: the int64 intermediates of :func:`combine_coarse_fine_fixed`.
ANGLE_BITS = 32
#: Bits per turn of the Kalman core's phase accumulator (:mod:`dsp.tacan.phase_ops` and the
#: Kalman kernel read it here).
PHASE_BITS = 40
#: TACAN modulation frequencies (Hz) of the coarse and fine components (dsp.tacan.standard).
F15_HZ, F135_HZ = F15, F135
#: Magnitudes are normalised (common right shift) so that ``max(m1, 9 m2) < 2**MAG_BITS``
#: before squaring: the weights then fit 61 bits.
MAG_BITS = 30
#: Largest information weight :func:`combine_coarse_fine_fixed` accepts (exclusive).
MAX_WEIGHT = 1 << 62


def _angle_bits(angle_bits, lo: int = 1, hi: int = 62) -> int:
    if isinstance(angle_bits, bool) or not isinstance(angle_bits, (int, np.integer)):
        raise ValueError(f"angle_bits must be an integer, not {angle_bits!r}")
    if not lo <= int(angle_bits) <= hi:
        raise ValueError(f"angle_bits must be an integer in [{lo}, {hi}], not {angle_bits}")
    return int(angle_bits)


def _int_array(v, name: str) -> np.ndarray:
    v = np.asarray(v)
    if v.dtype.kind not in "iu":
        raise ValueError(f"{name} must be integers (binary angles / integer weights), "
                         f"not dtype {v.dtype}")
    if v.dtype == np.uint64 and v.size and int(v.max()) >= 1 << 63:
        raise ValueError(f"{name} does not fit int64")
    return v.astype(np.int64)


def deg_to_bangle(deg, angle_bits: int = ANGLE_BITS) -> np.ndarray:
    """Degrees to a binary angle in ``[0, 2**angle_bits)`` (rounded to nearest, ties even).

    The float boundary of the fixed-point path (tests, constants); NaN/inf refused.
    """
    b = _angle_bits(angle_bits)
    d = np.asarray(deg, dtype=np.float64)
    if not np.all(np.isfinite(d)):
        raise ValueError("angles must be finite to convert to binary angles")
    turns = np.rint(np.ldexp(d % 360.0 / 360.0, b))
    return turns.astype(np.int64) & ((np.int64(1) << np.int64(b)) - 1)


def bangle_to_deg(a, angle_bits: int = ANGLE_BITS) -> np.ndarray:
    """Binary angle (any integer, taken mod ``2**angle_bits``) to degrees in ``[0, 360)``."""
    b = _angle_bits(angle_bits)
    a = _int_array(a, "a") & ((np.int64(1) << np.int64(b)) - 1)
    return np.ldexp(a.astype(np.float64), -b) * 360.0


def rad_to_bangle(rad, angle_bits: int = ANGLE_BITS) -> np.ndarray:
    """Radians to a binary angle in ``[0, 2**angle_bits)`` (rounded to nearest)."""
    b = _angle_bits(angle_bits)
    r = np.asarray(rad, dtype=np.float64)
    if not np.all(np.isfinite(r)):
        raise ValueError("angles must be finite to convert to binary angles")
    turns = np.rint(np.ldexp(r % TWO_PI / TWO_PI, b))
    return turns.astype(np.int64) & ((np.int64(1) << np.int64(b)) - 1)


def bangle_to_rad(a, angle_bits: int = ANGLE_BITS) -> np.ndarray:
    """Binary angle (taken mod ``2**angle_bits``) to radians in ``[0, 2 pi)``."""
    return np.radians(bangle_to_deg(a, angle_bits))


def reduce_bangle(a, from_bits: int, to_bits: int = ANGLE_BITS) -> np.ndarray:
    """A binary angle of ``from_bits`` bits as one of ``to_bits`` bits.

    Dropped LSBs are rounded half up (error <= 1/2 LSB of ``to_bits``); more bits are
    appended as zeros. The result is in ``[0, 2**to_bits)``.
    """
    fb = _angle_bits(from_bits)
    tb = _angle_bits(to_bits)
    a = _int_array(a, "a") & ((np.int64(1) << np.int64(fb)) - 1)
    s = fb - tb
    if s > 0:
        a = (a + (np.int64(1) << np.int64(s - 1))) >> np.int64(s)
    elif s < 0:
        a = a << np.int64(-s)
    return a & ((np.int64(1) << np.int64(tb)) - 1)


def freq_word(f_hz: float, tick_hz: float, phase_bits: int = PHASE_BITS) -> int:
    """Frequency word of a phase accumulator: ``round(f * 2**phase_bits / tick_hz)``.

    The phase advance over ``dt`` ticks is ``dt * word mod 2**phase_bits`` (see
    :func:`phase_advance`); the frequency error is below ``tick_hz / 2**(phase_bits+1)``
    (1e-5 Hz at 20 MHz and 40 bits). Identical to the Kalman core's words
    (:meth:`dsp.tacan.kalman_config.KalmanFixedConfig.value_consts`).
    """
    b = _angle_bits(phase_bits)
    for name, v in (("f_hz", f_hz), ("tick_hz", tick_hz)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or not math.isfinite(v):
            raise ValueError(f"{name} must be a finite number, not {v!r}")
    if tick_hz <= 0 or f_hz < 0 or f_hz >= tick_hz:
        raise ValueError(f"need 0 <= f_hz < tick_hz, not f_hz={f_hz}, tick_hz={tick_hz}")
    return int(round(f_hz * 2.0 ** b / tick_hz))


def phase_advance(dt_ticks, word: int, phase_bits: int = PHASE_BITS) -> np.ndarray:
    """Phase advance ``dt_ticks * word mod 2**phase_bits`` (exact for any int64 ``dt``).

    The product is formed modulo ``2**64`` (unsigned wraparound: the low bits of a
    multiplier), of which the low ``phase_bits`` are the advance; negative ``dt`` works.

    Parameters
    ----------
    dt_ticks : array_like of int
        Tick differences (e.g. ``t_last - t_main``).
    word : int
        Frequency word, ``0 <= word < 2**phase_bits`` (:func:`freq_word`).
    """
    b = _angle_bits(phase_bits)
    if isinstance(word, bool) or not isinstance(word, (int, np.integer)) \
            or not 0 <= int(word) < (1 << b):
        raise ValueError(f"word must be an integer in [0, 2**{b}), not {word!r}")
    d = _int_array(dt_ticks, "dt_ticks")
    with np.errstate(over="ignore"):
        p = d.astype(np.uint64) * np.uint64(word)
    return np.asarray(p & np.uint64((1 << b) - 1)).astype(np.int64)


def reference_advances(dt_main_ticks, dt_ref_ticks, tick_hz: float, *,
                       angle_bits: int = ANGLE_BITS, phase_bits: int = PHASE_BITS,
                       rotation_hz: float = F15_HZ):
    """The 15 Hz advance since the main reference and the 135 Hz advance since the latest
    reference, as binary angles of ``angle_bits``.

    Each is formed in the ``phase_bits`` accumulator (``dt * freq_word mod 2**phase_bits``,
    as the Kalman core does) and rounded to ``angle_bits`` (<= 1/2 LSB).

    Parameters
    ----------
    dt_main_ticks, dt_ref_ticks : array_like of int
        ``t_last - t_main`` and ``t_last - t_ref`` in ticks of ``tick_hz``.
    rotation_hz : float
        The beacon's rotation rate (the 15 Hz component; the fine one at nine times it),
        as the Kalman core turns at (:meth:`dsp.tacan.kalman.EnvelopeKalman.set_rotation`).

    Returns
    -------
    (adv15, adv135) : int64 arrays
    """
    f = float(rotation_hz)
    a15 = phase_advance(dt_main_ticks, freq_word(f, tick_hz, phase_bits), phase_bits)
    a135 = phase_advance(dt_ref_ticks, freq_word(9 * f, tick_hz, phase_bits), phase_bits)
    return reduce_bangle(a15, phase_bits, angle_bits), reduce_bangle(a135, phase_bits, angle_bits)


def _bit_length(v: np.ndarray) -> np.ndarray:
    """Bit length of non-negative int64 values (a leading-zero counter), vectorised."""
    t = np.asarray(v, dtype=np.int64).copy()
    n = np.zeros(t.shape, dtype=np.int64)
    for s in (32, 16, 8, 4, 2, 1):
        big = t >= (np.int64(1) << np.int64(s))
        n += np.where(big, s, 0)
        t = np.where(big, t >> np.int64(s), t)
    return n + (t > 0)


def _frac_bits(angle_bits: int) -> int:
    """Fraction bits of the combination weight ``wc / (wc + wf)``."""
    return min(40, 62 - angle_bits)


def combine_coarse_fine_fixed(coarse, fine9, w_coarse=None, w_fine=None, *,
                              angle_bits: int = ANGLE_BITS) -> np.ndarray:
    """Integer version of :func:`combine_coarse_fine` on binary angles.

    Parameters
    ----------
    coarse : array_like of int
        Coarse bearing (binary angle, taken mod ``2**angle_bits``).
    fine9 : array_like of int
        ``9 theta`` from the 135 Hz component (binary angle).
    w_coarse, w_fine : array_like of int, optional
        Non-negative integer information weights (``m1**2`` and ``81 m2**2`` at any common
        scale, each ``< 2**62``; see :func:`information_weights`). Default: fine only.
    angle_bits : int
        Bits per turn, 8..40 (default :data:`ANGLE_BITS`).

    Returns
    -------
    numpy.ndarray of int64
        Bearing binary angle in ``[0, 2**angle_bits)`` (broadcast shape).

    Notes
    -----
    Same algorithm as the float version, in integers (``B = 2**angle_bits``, angles as
    integers mod ``B``):

    1. Candidate choice at nine times the scale (exact): ``D = (9 coarse - fine9) mod 9B``,
       ``i = floor((D + B/2) / B)`` (0..9; ties -- coarse exactly midway between two
       candidates -- go to the higher ``i``), residual ``r9 = D - i B`` in ``[-B/2, B/2)``,
       which is ``9 * wrap(coarse - fine)``, and resolved ``F9 = fine9 + (i mod 9) B``,
       i.e. ``fine = F9 / 9`` exactly.
    2. Weight fraction ``f = round(wc 2**F / (wc + wf))`` (half up), ``F = min(40, 62 -
       angle_bits)`` fraction bits, by a restoring (radix-2, bit-serial) divider after a
       common right shift that leaves both weights below ``2**60`` (only when a weight is
       larger). ``wc + wf = 0`` gives ``f = 0`` (fine only), as the float version.
    3. ``bearing = round((F9 + f r9 / 2**F) / 9)`` -- one rounding, half up, with
       ``F9 = 9 q + rem`` split so that every intermediate fits int64 --, mod ``B``.

    Error against the exact (rational) result for these integer inputs: <= 1/2 LSB (step 3)
    plus ``2**-(F+1) * |r9| / 9 <= 2**(angle_bits - F - 1) / 18`` LSB from rounding ``f``
    (1/9 LSB at 32 bits): below 0.62 LSB (5.2e-8 deg at 32 bits), and the same against
    :func:`combine_coarse_fine` on the same angles in radians (float64 adds ~1e-6 LSB).
    """
    b = _angle_bits(angle_bits, 8, 40)
    B = np.int64(1) << np.int64(b)
    mask = B - 1
    c = _int_array(coarse, "coarse") & mask
    f9 = _int_array(fine9, "fine9") & mask
    c, f9 = np.broadcast_arrays(c, f9)
    # 1. nearest candidate, at nine times the scale
    D = 9 * c - f9
    D = np.where(D < 0, D + 9 * B, D)
    i = (D + (B >> np.int64(1))) >> np.int64(b)
    r9 = D - (i << np.int64(b))
    F9 = f9 + np.where(i == 9, 0, i) * B
    q = F9 // 9
    rem = F9 - 9 * q
    if w_coarse is None or w_fine is None:
        return (q + (rem >= 5)) & mask           # round(F9 / 9); no ties (9 is odd)
    F = _frac_bits(b)
    frac = weight_fraction(w_coarse, w_fine, F)
    # 3. bearing = round((F9 + frac r9 / 2**F) / 9) = q + round((rem 2**F + frac r9) / (9 2**F))
    one = np.int64(1) << np.int64(F)
    num = rem * one + frac * r9 + 9 * (one >> np.int64(1))
    return (q + num // (9 * one)) & mask


def weight_fraction(w_coarse, w_fine, frac_bits: int) -> np.ndarray:
    """``round(wc * 2**frac_bits / (wc + wf))`` (half up) for non-negative integer weights.

    Weights must be integers in ``[0, 2**62)``. If either is ``>= 2**60`` both are shifted
    right by a common amount (floor) to bring them below ``2**60``; the quotient is then
    formed exactly by a restoring divider (one integer bit, ``frac_bits + 1`` fraction
    bits, then rounding). ``wc + wf = 0`` gives 0.
    """
    F = _angle_bits(frac_bits, 1, 60)
    wc = _int_array(w_coarse, "w_coarse")
    wf = _int_array(w_fine, "w_fine")
    for name, w in (("w_coarse", wc), ("w_fine", wf)):
        if w.size and (w.min() < 0 or w.max() >= MAX_WEIGHT):
            raise ValueError(f"{name} must be integers in [0, 2**62) (information weights)")
    wc, wf = np.broadcast_arrays(wc, wf)
    s = np.maximum(_bit_length(np.maximum(wc, wf)) - 60, 0)
    wc, wf = wc >> s, wf >> s
    tot = wc + wf                                # < 2**61
    zero = tot == 0
    tot = np.where(zero, 1, tot)
    qi = (wc >= tot).astype(np.int64)            # wc <= tot: integer bit
    r = wc - qi * tot
    q = qi
    for _ in range(F + 1):                       # 2 r < 2 tot < 2**62
        r = r << np.int64(1)
        ge = r >= tot
        r = np.where(ge, r - tot, r)
        q = (q << np.int64(1)) | ge
    return np.where(zero, 0, (q + 1) >> np.int64(1))


def information_weights(m1, m2, mag_bits: int = MAG_BITS):
    """Integer information weights ``(m1**2, 81 m2**2)`` from integer magnitudes.

    Both magnitudes (non-negative integers at one common scale, e.g. CORDIC magnitudes of
    the state) are first shifted right by a common ``s`` (rounded half up; ``s`` from a
    leading-zero count, per element) so that ``max(m1, 9 m2) < 2**mag_bits``; only their
    ratio matters to the combination, which this keeps to ``~2**-mag_bits`` relative.
    With the default 30 bits the weights are below ``2**61``.

    Returns
    -------
    (w_coarse, w_fine) : int64 arrays
    """
    mb = _angle_bits(mag_bits, 1, 30)
    m1 = _int_array(m1, "m1")
    m2 = _int_array(m2, "m2")
    if (m1.size and m1.min() < 0) or (m2.size and m2.min() < 0):
        raise ValueError("magnitudes must be non-negative")
    if (m1.size and m1.max() >= 1 << 58) or (m2.size and m2.max() >= 1 << 58):
        raise ValueError("magnitudes must be below 2**58")
    m1, m2 = np.broadcast_arrays(m1, m2)
    s = np.maximum(_bit_length(np.maximum(m1, 9 * m2)) - mb, 0)
    half = np.where(s > 0, np.int64(1) << np.maximum(s - 1, 0), 0)
    a = (m1 + half) >> s
    b = (9 * m2 + half) >> s          # 9 m2 rounded once (not 9 x a rounded m2)
    return a * a, b * b


class StateBearing(NamedTuple):
    """Output of :func:`bearing_from_state` (binary angles of ``angle_bits``)."""

    bearing: np.ndarray   #: combined bearing, int64 in [0, 2**angle_bits)
    coarse: np.ndarray    #: coarse bearing (15 Hz only), int64 in [0, 2**angle_bits)
    valid: np.ndarray     #: bool: both magnitudes >= min_magnitude
    m1: np.ndarray        #: |(x0, x1)|, int64 at the state's scale (CORDIC, gain compensated)
    m2: np.ndarray        #: |(x2, x3)|, int64 at the state's scale


def state_cordic(width: int, angle_bits: int = ANGLE_BITS,
                 iterations: int | None = None) -> CordicConfig:
    """The CORDIC :func:`bearing_from_state` uses for a state of ``width`` bits.

    ``iterations = angle_bits + 2`` (residual rotation < 1/4 LSB), ``guard_bits =
    min(20, 60 - width)`` (datapath error negligible down to magnitudes of a few LSB),
    ``lut_bits = angle_bits + ceil(log2 iterations) + 1``, magnitudes with ``guard_bits``
    fraction bits below the state's LSB (``magnitude_frac``: the weights of small
    magnitudes keep their precision); for the default s36.28 state and 32-bit angles: a
    58-bit datapath, 34 iterations, 39-bit LUT, angle error (:meth:`CordicConfig.
    angle_error_bound`) <= 0.71 LSB + 96 / (r 2**20) rad for a magnitude of ``r`` state
    LSBs, i.e. <= 0.78 LSB from ``r >= 2**20`` (0.004 in s36.28) and 1.7 LSB from
    ``r >= 2**16``; magnitude relative error <= 2**-21 K_n = 8e-7 (the 20-bit gain
    constant; common to ``m1`` and ``m2``, so it cancels in the weights' ratio).
    """
    n = angle_bits + 2 if iterations is None else iterations
    return _state_cordic(int(width), int(angle_bits), int(n))


@functools.lru_cache(maxsize=32)
def _state_cordic(width: int, angle_bits: int, iterations: int) -> CordicConfig:
    g = max(0, min(20, 60 - width))
    return CordicConfig(width=width, iterations=iterations, angle_bits=angle_bits,
                        guard_bits=g, magnitude_frac=g)


def bearing_from_state(x, x_fmt: FixedFormat, adv15, adv135, *, adv_bits: int = PHASE_BITS,
                       angle_bits: int = ANGLE_BITS, iterations: int | None = None,
                       min_magnitude: int = 1) -> StateBearing:
    """Bearing from the integer Kalman state, with integers only (the fixed-point mirror of
    what :func:`dsp.tacan.receiver.process_peaks` does in float).

    ``alpha = atan2(x0, x1)``, ``beta = atan2(x2, x3)``, ``m1 = |(x0, x1)|``,
    ``m2 = |(x2, x3)|`` by the vectoring CORDIC (:func:`state_cordic`);
    ``coarse = adv15 - alpha``, ``fine9 = adv135 - beta`` (mod one turn);
    ``bearing = combine_coarse_fine_fixed(coarse, fine9, m1**2, 81 m2**2)`` with the
    weights from :func:`information_weights`.

    Parameters
    ----------
    x : array_like of int, (..., 5)
        State ``[m1 sin a, m1 cos a, m2 sin b, m2 cos b, u]`` as integers of ``x_fmt``.
    x_fmt : FixedFormat
        Its format (signed; e.g. the core's s36.28). Only the width matters here.
    adv15, adv135 : array_like of int
        Phase advances since the main reference (15 Hz) and since the latest reference
        (135 Hz) as binary angles of ``adv_bits`` (the core's 40-bit accumulator:
        ``dt_ticks * freq_word mod 2**40``, see :func:`phase_advance`); broadcast against
        ``x[..., 0]``. They are rounded to ``angle_bits`` (<= 1/2 LSB).
    adv_bits : int
        Bits per turn of the advances (default :data:`PHASE_BITS` = 40).
    angle_bits : int
        Bits per turn of the outputs, 8..40 (default :data:`ANGLE_BITS` = 32).
    iterations : int, optional
        CORDIC iterations (default ``angle_bits + 2``).
    min_magnitude : int
        ``valid`` needs ``m1 >= min_magnitude`` and ``m2 >= min_magnitude`` (state LSBs).

    Returns
    -------
    StateBearing
        ``bearing``, ``coarse`` (binary angles), ``valid``, ``m1``, ``m2``.

    Notes
    -----
    Zero state (``x[..., :4] == 0``, e.g. right after a reset): the CORDIC gives angle 0
    and magnitude 0, hence both weights 0 and the combination falls back to the fine
    bearing (as the float version with zero total weight): ``bearing`` is the candidate of
    ``adv135 / 9`` nearest to ``coarse = adv15`` -- timing only, no signal -- and ``valid``
    is False. The same happens (``valid`` False) whenever either component is below
    ``min_magnitude``; with ``m2 = 0 < m1`` the bearing is the coarse one.

    Error against the float path on the same integer state and advances (float64
    ``arctan2``/``hypot``, :func:`combine_coarse_fine`), at 32 bits and magnitudes
    ``>= 2**20`` state LSB: coarse and fine9 each <= 0.78 (CORDIC) + 0.5 (advance
    rounding) LSB, entering the bearing as ``(1 - f) e_fine9 / 9 + f e_coarse`` (<= 1.28
    LSB); the combination's own rounding <= 0.62 LSB; the weights' 30-bit normalisation
    moves ``f`` by <= ~3e-10, times ``|coarse - fine| <= 20 deg`` <= 0.07 LSB. In all
    <= 2.1 LSB = 1.8e-7 deg (measured: 1.5 LSB over 1e5 random states, see the tests).
    """
    if not isinstance(x_fmt, FixedFormat) or not x_fmt.signed:
        raise ValueError(f"x_fmt must be a signed FixedFormat, not {x_fmt!r}")
    b = _angle_bits(angle_bits, 8, 40)
    ab = _angle_bits(adv_bits)
    if isinstance(min_magnitude, bool) or not isinstance(min_magnitude, (int, np.integer)) \
            or min_magnitude < 1:
        raise ValueError(f"min_magnitude must be an integer >= 1, not {min_magnitude!r}")
    x = _int_array(x, "x")
    if x.ndim == 0 or x.shape[-1] != 5:
        raise ValueError(f"x must have shape (..., 5), not {x.shape}")
    if x.size and (x.min() < x_fmt.min_int or x.max() > x_fmt.max_int):
        raise ValueError(f"x does not fit its format {x_fmt}")
    cordic = state_cordic(x_fmt.width, b, iterations)
    alpha, m1f = cordic(x[..., 0], x[..., 1])     # magnitudes with magnitude_frac more bits
    beta, m2f = cordic(x[..., 2], x[..., 3])
    mask = (np.int64(1) << np.int64(b)) - 1
    a15 = reduce_bangle(adv15, ab, b)
    a135 = reduce_bangle(adv135, ab, b)
    coarse = (a15 - alpha) & mask
    fine9 = (a135 - beta) & mask
    wc, wf = information_weights(m1f, m2f)
    bearing = combine_coarse_fine_fixed(coarse, fine9, wc, wf, angle_bits=b)
    mf = cordic.magnitude_frac
    m1 = (m1f + (np.int64(1) << np.int64(mf - 1))) >> np.int64(mf) if mf else m1f
    m2 = (m2f + (np.int64(1) << np.int64(mf - 1))) >> np.int64(mf) if mf else m2f
    valid = (m1 >= min_magnitude) & (m2 >= min_magnitude)
    coarse, valid, m1, m2 = np.broadcast_arrays(coarse, valid, m1, m2)
    bearing = np.broadcast_to(bearing, coarse.shape)
    return StateBearing(bearing, coarse, valid, m1, m2)


def track_sector(bearing, coarse, state=None, *, ready=None, angle_bits: int = ANGLE_BITS,
                 shift: int = 6):
    """Sector tracking near the noise floor (issue 18), in integers (binary angles).

    The combination takes the 40 deg sector of the fine bearing from the coarse bearing
    alone, output by output; near the noise floor the coarse bearing wanders by up to ~20
    deg over the filter's memory and the sector slips by 40 deg. Here the sector is kept
    from one output to the next (the candidate nearest the previous tracked bearing: the
    fine bearing moves continuously) and changed only when the coarse bearing disagrees
    with the tracked one by more than half a sector *on average*: the disagreement
    ``d = wrap(coarse - tracked)`` is smoothed as ``e += (d - e) >> shift`` (64 outputs, ~0.5
    s at 135 outputs/s), and when ``|e| > 20 deg`` the tracked bearing moves by the nearest
    whole number of sectors towards the coarse one (``e`` with it).

    Parameters
    ----------
    bearing, coarse : int arrays (B, M)
        Combined and coarse bearings as binary angles (outputs in time order).
    state : (tracked, e, started) arrays (B,), optional
        Carried from an earlier block.
    ready : bool array (B, M), optional
        Where False (the filter warming up or re-initialised: its coarse bearing can be
        anything), the output keeps its own sector and the tracker restarts at the next
        ready output. Default: all ready.

    Returns
    -------
    (tracked, state) : int64 array (B, M) and the new state. A sector is
    ``round(k 2**angle_bits / 9)`` (not a whole number of LSBs: <= 1/2 LSB of rounding).
    """
    b = _angle_bits(angle_bits, 8, 40)
    B = np.int64(1) << np.int64(b)
    half = B >> np.int64(1)
    bb = _int_array(bearing, "bearing") & (B - 1)
    cc = _int_array(coarse, "coarse") & (B - 1)
    nb, M = bb.shape
    out = np.empty_like(bb)
    if state is None:
        tr, e, st = np.zeros(nb, np.int64), np.zeros(nb, np.int64), np.zeros(nb, bool)
    else:
        tr, e, st = (np.array(v) for v in state)

    def wrap(x):
        return ((x + half) & (B - 1)) - half

    def sectors(k):                                   # round(k B / 9), any sign
        num = k * B
        return np.where(num >= 0, (num + 4) // 9, -((-num + 4) // 9))

    rd = np.ones((nb, M), bool) if ready is None else np.asarray(ready, bool)
    for i in range(M):
        st = st & rd[:, i]
        w = wrap(tr - bb[:, i])
        m = (9 * w + half) >> np.int64(b)             # nearest sector to the previous one
        t = np.where(st, (bb[:, i] + sectors(m)) & (B - 1), bb[:, i])
        d = wrap(cc[:, i] - t)
        e = np.where(st, e + ((d - e) >> np.int64(shift)), d)
        k = (9 * e + half) >> np.int64(b)
        t = np.where(k != 0, (t + sectors(k)) & (B - 1), t)
        e = e - sectors(k)
        st = rd[:, i].copy()
        tr = t
        out[:, i] = t
    return out, (tr, e, st)
