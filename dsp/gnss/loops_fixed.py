"""The tracking channel's loop arithmetic written once, run in float64 or in fixed point.

One source: :func:`channel_step` is written in terms of the operators of an arithmetic
object (``FLOAT`` or a :class:`FixedArith`): ``q(x, fmt)`` puts a real value into a format
(float: identity; fixed: round-half-up to ``fmt.frac`` fraction bits, saturated to
``fmt.bits``, saturations counted), ``mul(a, k, shift)`` multiplies by a coefficient and
re-scales (float: ``a k``; fixed: the exact integer product shifted right ``shift`` bits,
round half up), ``add``. The float run is the golden (``dsp.gnss.loops.TrackingChannel``
without FLL, same equations to float64 rounding); the fixed run differs from it only where
the formats quantise. Vectorised over any batch shape (numpy ``int64``; every product is
kept below ``2^62``: :func:`check_products` bounds each one from its operand's format and
its coefficient at construction and raises where one cannot hold, and the test re-does
every step with Python integers).

Named formats (``Format(bits, frac)``, signed, value = integer * 2^-frac):

=============  =====================  ================================================
DISC_PHASE     Q(16, 15) cycles       Costas/atan2 output (|e| <= 1/2)
DISC_CODE      Q(16, 14) chips        normalised E-L envelope (|tau| <= 1)
COEF           24 fraction bits       loop gains T w0^3, T a3 w0^2, b3 w0, (4 Bn_dll)
V2             Q(40, 20) Hz/s         3rd-order rate integrator
T_Q            30 fraction bits       the epoch T (1 ms is not binary: 1.7e-7 relative)
V1, FREQ       Q(48, 31) Hz           frequency integrator and the Doppler output (+-65 kHz)
F16            Q(32, 15) Hz           Doppler fed to the word multipliers (|f16| <= 2^31)
WORD_COEF      Q(32, c), K < 2^31     2^32 / fs (carrier), 2^32 / (1540 fs) (code),
                                      2^32 4 Bn_dll / fs (DLL); ``c`` per coefficient
                                      from fs (:func:`word_coef_frac`)
NCO word       32-bit two's complement  round(f 2^32 / fs), carrier and code
=============  =====================  ================================================

The word coefficients: each takes the largest fraction ``c`` that leaves it below ``2^31``,
so its product with an operand of at most ``2^31`` (F16, DISC_CODE) stays below ``2^62``
at any sample rate (at 5 MS/s the carrier's ``c`` is 21, at 16.368 MS/s 22). The carrier
word is within ``1/2 + 2^16 / fs + 2^(15 - c)`` LSB of ``f 2^32 / fs`` (``f`` the V1
Doppler, any value V1 holds: final rounding, F16's rounding, the coefficient's rounding;
0.529 LSB at 5 MS/s), so it differs from the float path's word ``round(f 2^32 / fs)`` by at
most 1. The code word sums three terms rounded each on its own (the chip rate, ``f / 1540``
and the DLL term ``4 Bn_dll tau``): within 3/2 LSB plus the coefficients' and F16's rounding
(each at most 1/16 LSB) of the exact sum. :func:`word_coef_frac` raises where the coefficient's or
F16's rounding would pass 1/16 LSB over V1's range (fs below 2^20 Hz for the carrier).

The discriminators themselves (atan, envelope division) are evaluated in float64 and
quantised at their output to DISC_PHASE / DISC_CODE: in the FPGA+DSP split they run on the
DSP core, whose CORDIC is outside this model.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .ca_code import CHIP_RATE_HZ
from .discriminators import costas_atan, dll_nelp, pll_atan2
from .loops import A2, A3, B3, pll_w0


@dataclass(frozen=True)
class Format:
    bits: int
    frac: int


DISC_PHASE = Format(16, 15)
DISC_CODE = Format(16, 14)
V2 = Format(40, 20)
V1 = Format(48, 31)
COEF_FRAC = 24
T_FRAC = 30
F16 = Format(32, 15)
F16_FRAC = F16.frac
WORD_COEF_BITS = 32
WORD_BITS = 32
#: Most a word coefficient's or F16's rounding may add to a word over its operand's range (LSB).
WORD_ROUNDING_LSB = 1.0 / 16
PRODUCT_LIMIT = 1 << 62


def word_coef_frac(scale: float, operand_max: float, name: str) -> int:
    """The fraction ``c`` of the word coefficient ``round(scale 2^c)``: the largest that
    keeps it below ``2^(WORD_COEF_BITS - 1)``. ``operand_max``: the largest magnitude (real
    units) the coefficient multiplies; raises ``ValueError`` where the coefficient's rounding
    (``operand_max 2^-(c+1)`` LSB) would pass ``WORD_ROUNDING_LSB``."""
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"{name}: word scale must be a finite number > 0, not {scale!r}")
    top = 1 << (WORD_COEF_BITS - 1)
    c = math.floor(math.log2(top / scale)) + 1
    while c > -64 and round(scale * 2.0 ** c) >= top:
        c -= 1
    err = operand_max * 2.0 ** -(c + 1)
    if err > WORD_ROUNDING_LSB:
        raise ValueError(f"{name}: coefficient {scale:.6g} word LSB per unit fits {WORD_COEF_BITS} "
                         f"bits only with {c} fraction bits, whose rounding adds up to {err:.3g} "
                         f"LSB over +-{operand_max:g} (more than {WORD_ROUNDING_LSB:g}): sample "
                         f"rate too low for the {WORD_BITS}-bit NCO word formats")
    return c


def check_products(products) -> None:
    """Raise ``ValueError`` unless every ``(name, operand Format, integer coefficient)``
    product stays below ``2^62`` (the operand at its format's full range)."""
    for name, fmt, k in products:
        if (1 << (fmt.bits - 1)) * abs(int(k)) >= PRODUCT_LIMIT:
            raise ValueError(f"{name}: Q({fmt.bits}, {fmt.frac}) operand times coefficient {k} "
                             f"can reach 2^{math.log2(abs(k)) + fmt.bits - 1:.2f}, past the int64 "
                             f"products' 2^62 (the formats do not hold this rate / loop setting)")


class FloatArith:
    fixed = False

    def q(self, x, fmt):
        return np.asarray(x, dtype=np.float64)

    def coef(self, c, frac):
        return float(c)

    def mul(self, a, k, shift):
        return a * k

    def add(self, a, b, fmt=None):
        return a + b

    def word(self, f_hz, scale):
        return f_hz


class FixedArith:
    """Fixed point on numpy int64; ``sat`` counts saturations per format name.

    A scalar operand held as a Python ``int`` (what :meth:`q` returns for a scalar) stays a
    Python ``int`` through :meth:`rs`, :meth:`mul` and :meth:`add`, wrapped to 64-bit two's
    complement where numpy's int64 would wrap: the same bits as the numpy path at a
    fraction of its cost per call (one tracker per channel steps once a millisecond)."""

    fixed = True

    def __init__(self):
        self.sat = {}

    @staticmethod
    def rs(v, s):
        if type(v) is int:
            if s <= 0:
                v <<= -s
                return v if -_I63 <= v < _I63 else _wrap64(v)
            v += 1 << (s - 1)
            return (v if -_I63 <= v < _I63 else _wrap64(v)) >> s
        v = np.asarray(v, dtype=np.int64)
        if s <= 0:
            return v << -s
        return (v + (1 << (s - 1))) >> s

    def _sat(self, v, fmt):
        hi, lo = (1 << (fmt.bits - 1)) - 1, -(1 << (fmt.bits - 1))
        if type(v) is int:
            if lo <= v <= hi:
                return v
            self.sat[fmt] = self.sat.get(fmt, 0) + 1
            return hi if v > hi else lo
        n = int(np.count_nonzero((v > hi) | (v < lo)))
        if n:
            self.sat[fmt] = self.sat.get(fmt, 0) + n
        return np.clip(v, lo, hi)

    def q(self, x, fmt):
        if np.ndim(x) == 0:
            y = math.floor(float(x) * 2.0 ** fmt.frac + 0.5) if math.isfinite(x) else None
            if y is not None and -_I63 <= y < _I63:
                return self._sat(y, fmt)
            # (outside int64: the numpy conversion's result, whatever the platform makes it)
            return int(self._sat(np.floor(np.asarray(x, float) * 2.0 ** fmt.frac + 0.5)
                                 .astype(np.int64), fmt))
        return self._sat(np.floor(np.asarray(x, float) * 2.0 ** fmt.frac + 0.5).astype(np.int64), fmt)

    def coef(self, c, frac):
        return int(round(c * 2 ** frac))

    def mul(self, a, k, shift):
        if type(a) is int and type(k) is int:
            v = a * k
            return self.rs(v if -_I63 <= v < _I63 else _wrap64(v), shift)
        return self.rs(np.asarray(a, np.int64) * k, shift)

    def add(self, a, b, fmt=None):
        if type(a) is int and type(b) is int:
            s = a + b
            if not -_I63 <= s < _I63:
                s = _wrap64(s)
        else:
            s = np.asarray(a, np.int64) + b
        return s if fmt is None else self._sat(s, fmt)


_I63 = 1 << 63


def _wrap64(v: int) -> int:
    """``v`` wrapped to 64-bit two's complement (numpy int64's overflow)."""
    if -_I63 <= v < _I63:
        return v
    return ((v + _I63) & ((1 << 64) - 1)) - _I63


FLOAT = FloatArith()


class ChannelCore:
    """PLL (2nd/3rd order) + carrier-aided 1st-order DLL, one source for both arithmetics.

    ``step(ie, qe, ip, qp, il, ql) -> (carrier_word, code_word)`` (fixed: int64 NCO words;
    float: the frequencies in Hz, whose words are ``loops.hz_to_word``). ``doppler_hz()``
    gives the Doppler state as a real value in both forms."""

    def __init__(self, arith, fs_hz: float, T_s: float = 1e-3, order: int = 3,
                 bn_hz: float = 15.0, dll_bn_hz: float = 1.0, spacing_chips: float = 0.5,
                 if_hz: float = 0.0, inverted: bool = False, doppler0_hz=0.0,
                 doppler_rate0_hz_s=0.0, costas: bool = True):
        o = self.o = arith
        self.order, self.d, self.costas = int(order), float(spacing_chips), bool(costas)
        self.s = -1 if inverted else 1
        w = pll_w0(self.order, bn_hz)
        T = float(T_s)
        if self.order == 3:
            k3, k2, k1 = T * w ** 3, T * A3 * w ** 2, B3 * w
        else:
            k3, k2, k1 = 0.0, T * w ** 2, A2 * w
        self.K3, self.K2, self.K1 = (o.coef(k, COEF_FRAC) for k in (k3, k2, k1))
        self.KT = o.coef(T, T_FRAC)
        self.KA = o.coef(1.0 / T, COEF_FRAC)          # Hz per cycle: the phase alignment
        self.KD = o.coef(4.0 * dll_bn_hz, COEF_FRAC)   # chips/s per chip of code error
        self.fs = float(fs_hz)
        self.if_hz = float(if_hz)
        # word scales (fixed) -- in float the frequencies are carried in Hz
        sc = 2.0 ** WORD_BITS / self.fs
        if o.fixed:
            if 2.0 ** (WORD_BITS - F16_FRAC - 1) / self.fs > WORD_ROUNDING_LSB:
                raise ValueError(f"fs {self.fs:g} Hz: F16's rounding (2^-{F16_FRAC + 1} Hz) "
                                 f"passes {WORD_ROUNDING_LSB:g} LSB of the {WORD_BITS}-bit word")
            f_max = 2.0 ** (V1.bits - 1 - V1.frac)
            self.CWC = word_coef_frac(sc, f_max, "carrier word")
            self.CWK = word_coef_frac(sc / 1540.0, f_max, "code word")
            tau_max = 2.0 ** (DISC_CODE.bits - 1 - DISC_CODE.frac)
            self.CWD = word_coef_frac(sc * 4.0 * dll_bn_hz, tau_max, "DLL word")
        else:
            self.CWC = self.CWK = self.CWD = 0
        self.KWC = o.coef(sc, self.CWC)
        self.KWK = o.coef(sc / 1540.0, self.CWK)
        self.KWD = o.coef(sc * 4.0 * dll_bn_hz, self.CWD)
        if o.fixed:
            check_products([("carrier word", F16, self.KWC), ("code word", F16, self.KWK),
                            ("DLL word", DISC_CODE, self.KWD), ("K3", DISC_PHASE, self.K3),
                            ("K2", DISC_PHASE, self.K2), ("K1", DISC_PHASE, self.K1),
                            ("KA", DISC_PHASE, self.KA), ("KT", V2, self.KT)])
        self.W_IF = int(round(if_hz * 2 ** WORD_BITS / fs_hz))
        self.W_CHIP = int(round(CHIP_RATE_HZ * 2 ** WORD_BITS / fs_hz))
        self.v1 = o.q(doppler0_hz, V1)
        self.v2 = o.q(np.broadcast_to(doppler_rate0_hz_s, np.shape(self.v1)), V2)
        self.e = self.tau = None

    def doppler_hz(self):
        return self.v1 * 2.0 ** -V1.frac if self.o.fixed else self.v1

    def _wrap(self, e):
        """A DISC_PHASE difference back into the discriminator's range (Costas: +-1/4
        cycle, else +-1/2)."""
        o, half = self.o, (0.25 if self.costas else 0.5)
        if not o.fixed:
            return (e + half) % (2 * half) - half
        h = int(round(half * 2 ** DISC_PHASE.frac))
        return (e + h) % (2 * h) - h

    def step(self, ie, qe, ip, qp, il, ql, phase_offset=None, align: bool = False):
        """One epoch. ``phase_offset`` (DISC_PHASE, the core's arithmetic): a phase
        correction already commanded but not yet seen, taken off the discriminator.
        ``align``: the hand-over's phase alignment -- the integrators keep their state and
        the carrier NCO runs ``v1 + e / T`` for the interval, which removes the phase error
        ``e`` measured now (the PLL's counterpart of a Kalman loop's uniform initial
        phase)."""
        o = self.o
        qs = self.s * (float(qp) if type(qp) is int else np.asarray(qp, float))
        e = o.q(costas_atan(ip, qs) if self.costas else pll_atan2(ip, qs), DISC_PHASE)
        if phase_offset is not None:
            e = self._wrap(o.add(e, -phase_offset))
        tau = o.q(dll_nelp(ie, qe, il, ql, self.d), DISC_CODE)
        ef = DISC_PHASE.frac + COEF_FRAC
        if align:
            f = o.add(self.v1, o.mul(e, self.KA, ef - V1.frac), V1)
            self.e, self.tau = e, tau
            return self._words(f, tau)
        if self.order == 3:
            self.v2 = o.add(self.v2, o.mul(e, self.K3, ef - V2.frac), V2)
            self.v1 = o.add(o.add(self.v1, o.mul(e, self.K2, ef - V1.frac)),
                            o.mul(self.v2, self.KT, V2.frac + T_FRAC - V1.frac), V1)
        else:
            self.v1 = o.add(self.v1, o.mul(e, self.K2, ef - V1.frac), V1)
        f = o.add(self.v1, o.mul(e, self.K1, ef - V1.frac), V1)    # Doppler, V1 format
        self.e, self.tau = e, tau
        return self._words(f, tau)

    def _words(self, f, tau):
        """The NCO words (fixed) or frequencies (float) of carrier Doppler ``f`` (V1) and
        code discriminator ``tau``."""
        o = self.o
        if not o.fixed:
            return self.if_hz + self.s * f, CHIP_RATE_HZ + f / 1540.0 + self.KD * tau
        f16 = o.mul(f, 1, V1.frac - F16_FRAC)
        cw = self.W_IF + self.s * o.mul(f16, self.KWC, F16_FRAC + self.CWC)
        kw = self.W_CHIP + o.mul(f16, self.KWK, F16_FRAC + self.CWK) \
            + o.mul(tau, self.KWD, DISC_CODE.frac + self.CWD)
        return cw, kw

    def frequencies_hz(self, words):
        """Fixed: the frequencies the NCO words stand for (Hz); float: as given."""
        if not self.o.fixed:
            return words
        cw, kw = words
        return cw * self.fs / 2.0 ** WORD_BITS, kw * self.fs / 2.0 ** WORD_BITS
