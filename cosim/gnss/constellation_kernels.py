"""The constellation generator's compiled kernels: the geometry's interpolation
(:func:`hermite`, :func:`linear`), one satellite's code and phase ranges at a receiver time
(:func:`ranges_at`), and the sample kernel that adds a satellite's code, data and carrier to
a block (:func:`constellation_kernel`; the signal model is :mod:`cosim.gnss.constellation`'s
module notes). The fast path (:mod:`cosim.gnss.gps_fast`) evaluates the same
:func:`ranges_at`, so both paths share one truth."""
from __future__ import annotations

import numpy as np

from dsp.gnss.ephemeris import CHIP_M, L1_WAVELENGTH_M
from dsp.jit import njit_cached

__all__ = ["hermite", "linear", "ranges_at", "interpolate_ranges",
           "constellation_kernel"]



@njit_cached(nogil=True)
def hermite(s, s0, h, val, der):
    """Cubic Hermite interpolation at ``s`` of grid values ``val`` and rates ``der`` on the
    grid ``s0 + k h``."""
    u = (s - s0) / h
    k = min(max(np.int64(np.floor(u)), 0), val.shape[0] - 2)
    x = u - k
    x2 = x * x
    x3 = x2 * x
    return ((2.0 * x3 - 3.0 * x2 + 1.0) * val[k] + (x3 - 2.0 * x2 + x) * h * der[k]
            + (3.0 * x2 - 2.0 * x3) * val[k + 1] + (x3 - x2) * h * der[k + 1])


@njit_cached(nogil=True)
def linear(s, s0, h, val):
    """Linear interpolation at ``s`` of ``val`` on the grid ``s0 + k h``."""
    u = (s - s0) / h
    k = min(max(np.int64(np.floor(u)), 0), val.shape[0] - 2)
    return val[k] + (u - k) * (val[k + 1] - val[k])


@njit_cached(nogil=True)
def ranges_at(s, s0, h, gcode, dgcode, gphase, dgphase, c_step, cdt):
    """``(P, Phi)``: one satellite's code and phase ranges (m) at receiver time ``s``, the
    geometry's Hermite interpolation plus the receiver clock's ``c dt`` (linear on its
    grid of step ``c_step``) -- the one formula of the sample kernel and of the truth."""
    clk = linear(s, 0.0, c_step, cdt)
    return (hermite(s, s0, h, gcode, dgcode) + clk, hermite(s, s0, h, gphase, dgphase) + clk)


@njit_cached(nogil=True)
def interpolate_ranges(s, s0, h, gcode, dgcode, gphase, dgphase, c_step, cdt, out):
    """``out[i] = (P, Phi)`` at receiver times ``s[i]`` as the kernel computes them."""
    for i in range(s.shape[0]):
        out[i, 0], out[i, 1] = ranges_at(s[i], s0, h, gcode, dgcode, gphase, dgphase, c_step,
                                         cdt)


@njit_cached(nogil=True)
def constellation_kernel(n0, fs, f_ratio, sign, s0, h, gcode, dgcode, gphase, dgphase, amp,
                         c_step, cdt, chi0, code, bits, out_re, out_im):
    """Add one satellite (module notes) to samples ``n0 ..`` of ``out_re`` (and ``out_im``
    when it is not empty: complex output)."""
    cplx = out_im.shape[0] > 0
    for i in range(out_re.shape[0]):
        n = n0 + i
        s = n / fs
        a = linear(s, s0, h, amp)
        if a == 0.0:
            continue
        p, ph = ranges_at(s, s0, h, gcode, dgcode, gphase, dgphase, c_step, cdt)
        chi = chi0 + s * 1.023e6 - p / CHIP_M
        ci = np.int64(np.floor(chi))
        bi = np.int64(np.floor(chi / 20460.0))
        if bi < 0 or bi >= bits.shape[0]:
            raise ValueError("constellation_kernel: code phase outside the encoded LNAV bits")
        v = a * code[ci % 1023] * bits[bi]
        cyc = -ph / L1_WAVELENGTH_M
        cyc -= np.floor(cyc)
        f = n * f_ratio
        arg = 2.0 * np.pi * ((f - np.floor(f)) + sign * cyc)
        out_re[i] += v * np.cos(arg)
        if cplx:
            out_im[i] += v * np.sin(arg)
