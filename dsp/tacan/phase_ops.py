"""Phase operators of the TACAN Kalman core (:mod:`dsp.tacan.kalman_kernel`), in the
one-source float/fixed form of :mod:`dsp.qops`: the sine and cosine of a phase advance from
a sine ROM with a Taylor correction (:func:`sincos_dt`) and the process noise of an
interval (:func:`rate_dt`). The phase accumulator is :data:`dsp.tacan.bearing.PHASE_BITS`
bits per turn."""
from __future__ import annotations

import math

import numpy as np
from numba.extending import overload

from ..qops import OVERLOAD_OPTS, is_float, is_int, jit_only
from .bearing import PHASE_BITS

#: Sine ROM size (log2 entries, full circle) and its fraction bits.
LUT_BITS = 10
TRIG_FRAC = 30
SIN_LUT = np.round(np.sin(2 * np.pi * np.arange(1 << LUT_BITS) / (1 << LUT_BITS))
                   * (1 << TRIG_FRAC)).astype(np.int64)
_TWO_PI_30 = int(round(2 * math.pi * (1 << 30)))


def sincos_dt(lut, dt, fw, cs_frac, half):
    """``(sin, cos)`` of the phase advance over ``dt``.

    Integers: ``dt`` in ticks, ``fw`` the ``PHASE_BITS`` frequency word; phase ``dt fw mod
    2**40`` from a ``2**LUT_BITS``-entry full-circle sine ROM (``TRIG_FRAC`` fraction
    bits) plus a 3rd-order Taylor correction of the residual angle (< 1e-12), rounded once
    to ``cs_frac`` fraction bits. Floats: ``dt`` in seconds, ``fw = 2 pi f``.
    """
    jit_only()


@overload(sincos_dt, jit_options=OVERLOAD_OPTS)
def _ol_sincos_dt(lut, dt, fw, cs_frac, half):
    if is_int(dt):
        def impl(lut, dt, fw, cs_frac, half):
            phase = (dt * fw) & ((np.int64(1) << PHASE_BITS) - 1)
            sh = PHASE_BITS - LUT_BITS
            idx = phase >> sh
            d = phase - (idx << sh)
            s0 = lut[idx]
            c0 = lut[(idx + (1 << (LUT_BITS - 2))) & ((1 << LUT_BITS) - 1)]
            # residual angle at 30 fraction bits (d >> 8 keeps the product in 63 bits)
            dl = ((d >> 8) * _TWO_PI_30 + (np.int64(1) << (PHASE_BITS - 9))) >> (PHASE_BITS - 8)
            d2 = (dl * dl + (np.int64(1) << (TRIG_FRAC - 1))) >> TRIG_FRAC
            d3 = (d2 * dl + (np.int64(1) << (TRIG_FRAC - 1))) >> TRIG_FRAC
            cd = (np.int64(1) << TRIG_FRAC) - (d2 >> 1)
            sd = dl - d3 // 6
            sh2 = 2 * TRIG_FRAC - cs_frac
            rnd = (np.int64(1) << (sh2 - 1)) if half else np.int64(0)
            sn = (s0 * cd + c0 * sd + rnd) >> sh2
            cn = (c0 * cd - s0 * sd + rnd) >> sh2
            return sn, cn
        return impl
    if is_float(dt):
        def impl(lut, dt, fw, cs_frac, half):
            a = fw * dt
            return math.sin(a), math.cos(a)
        return impl


def rate_dt(q, dt, extra, half):
    """Process noise ``q dt``: integers ``q`` per tick at ``extra`` more fraction bits
    (``q dt`` capped below 2**61 before the shift); floats ``q`` per second."""
    jit_only()


@overload(rate_dt, jit_options=OVERLOAD_OPTS)
def _ol_rate_dt(q, dt, extra, half):
    if is_int(dt):
        def impl(q, dt, extra, half):
            lim = (np.int64(1) << 61) // max(q, np.int64(1))
            dq = dt if dt <= lim else lim
            v = q * dq
            if half:
                v += np.int64(1) << (extra - 1)
            return v >> extra
        return impl
    if is_float(dt):
        return lambda q, dt, extra, half: q * dt
