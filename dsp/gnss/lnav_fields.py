"""The LNAV parameter fields of IS-GPS-200 (section 20.3.3): bit widths, scale factors, signs.

Every broadcast parameter is an integer of ``bits`` bits times ``2**exponent`` (times ``PI_GPS``
for the angles, which LNAV carries in semicircles and :class:`dsp.gnss.ephemeris.Ephemeris`
holds in radians), two's complement when ``signed``:

* subframe 1, Table 20-I: TGD, toc, af2, af1, af0 (and the integers WN, URA index, health,
  IODC, codes on L2, L2 P data flag);
* subframes 2 and 3, Table 20-III: Crs, deltaN, M0, Cuc, e, Cus, sqrtA, toe, Cic, Omega0, Cis,
  i0, Crc, omega, OmegaDot, IDOT (and IODE, the fit interval flag, AODO);
* subframe 4 page 18, Tables 20-X (ionosphere, Klobuchar alpha_n / beta_n) and 20-IX (UTC).

``quantise_value`` rounds a value to its field's grid and ``field_integer`` /
``integer_value`` convert between a value and the field's integer; the encoder, the decoder and
``Ephemeris.quantised`` all go through these, so a decoded value equals the quantised one bit
for bit. This module knows nothing of the ``Ephemeris`` class (it works on plain values).
"""
from __future__ import annotations

from dataclasses import dataclass

#: pi as IS-GPS-200 defines it for the user algorithm and the semicircle conversions
#: (section 20.3.3.4.3, Table 20-IV: "pi = 3.1415926535898").
PI_GPS = 3.1415926535898


@dataclass(frozen=True)
class Field:
    """One LNAV field: ``bits`` wide, LSB ``2**exponent`` (semicircles for ``semicircles``
    fields, whose value is held in radians), two's complement when ``signed``."""

    name: str
    bits: int
    exponent: int
    signed: bool
    semicircles: bool = False

    @property
    def lsb(self) -> float:
        """The value of one count in the held unit (radians for angles)."""
        return 2.0 ** self.exponent * (PI_GPS if self.semicircles else 1.0)

    @property
    def range(self) -> tuple[int, int]:
        """The integers the field can carry."""
        if self.signed:
            return -(1 << (self.bits - 1)), (1 << (self.bits - 1)) - 1
        return 0, (1 << self.bits) - 1


def _f(name, bits, exponent, signed, semicircles=False):
    return Field(name, bits, exponent, signed, semicircles)


#: Table 20-I (subframe 1) clock fields and Table 20-III (subframes 2, 3) ephemeris fields.
EPHEMERIS_FIELDS = {f.name: f for f in (
    _f("TGD", 8, -31, True),
    _f("toc", 16, 4, False),
    _f("af2", 8, -55, True),
    _f("af1", 16, -43, True),
    _f("af0", 22, -31, True),
    _f("Crs", 16, -5, True),
    _f("deltaN", 16, -43, True, True),
    _f("M0", 32, -31, True, True),
    _f("Cuc", 16, -29, True),
    _f("e", 32, -33, False),
    _f("Cus", 16, -29, True),
    _f("sqrtA", 32, -19, False),
    _f("toe", 16, 4, False),
    _f("Cic", 16, -29, True),
    _f("Omega0", 32, -31, True, True),
    _f("Cis", 16, -29, True),
    _f("i0", 32, -31, True, True),
    _f("Crc", 16, -5, True),
    _f("omega", 32, -31, True, True),
    _f("OmegaDot", 24, -43, True, True),
    _f("IDOT", 14, -43, True, True),
)}

#: Integer fields of subframes 1-3 (Tables 20-I, 20-III): name -> bits.
EPHEMERIS_INTEGERS = {"week": 10, "l2_codes": 2, "ura_index": 4, "health": 6, "IODC": 10,
                      "l2p_flag": 1, "IODE": 8, "fit_interval_flag": 1, "aodo": 5}

#: Table 20-X: the Klobuchar coefficients alpha_0..3 (s, s/semicircle^n) and beta_0..3 (s,
#: s/semicircle^n), 8 bits each, two's complement.
IONO_FIELDS = tuple(_f(f"alpha{i}", 8, e, True) for i, e in enumerate((-30, -27, -24, -24))) \
    + tuple(_f(f"beta{i}", 8, e, True) for i, e in enumerate((11, 14, 16, 16)))

#: Table 20-IX: the UTC parameters of subframe 4 page 18.
UTC_FIELDS = {f.name: f for f in (
    _f("A0", 32, -30, True),
    _f("A1", 24, -50, True),
    _f("tot", 8, 12, False),
    _f("WNt", 8, 0, False),
    _f("dtLS", 8, 0, True),
    _f("WNLSF", 8, 0, False),
    _f("DN", 8, 0, False),
    _f("dtLSF", 8, 0, True),
)}


def field_integer(field: Field, value: float, *, what: str = "") -> int:
    """The integer ``field`` carries for ``value`` (rounded to the nearest count); a
    ``ValueError`` naming the field when it does not fit."""
    x = float(value)
    if x != x or x in (float("inf"), float("-inf")):
        raise ValueError(f"{what}{field.name} = {value!r} is not a finite number")
    n = round(x / field.lsb)
    lo, hi = field.range
    if not lo <= n <= hi:
        raise ValueError(f"{what}{field.name} = {value!r} is outside the {field.bits}-bit "
                         f"LNAV field ({lo * field.lsb:.6g} .. {hi * field.lsb:.6g})")
    return n


def integer_value(field: Field, n: int) -> float:
    """The value of integer ``n`` of ``field`` (the inverse of ``field_integer`` on the grid)."""
    return float(n) * field.lsb


def quantise_value(field: Field, value: float, *, what: str = "") -> float:
    """``value`` rounded to the grid of ``field`` (what a decoder reads back)."""
    return integer_value(field, field_integer(field, value, what=what))


def check_integer(name: str, bits: int, value, *, what: str = "") -> int:
    """``value`` as an unsigned integer of ``bits`` bits; a ``ValueError`` naming the field when
    it is not one."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value < (1 << bits):
        raise ValueError(f"{what}{name} = {value!r} is not an unsigned {bits}-bit integer")
    return value


def to_unsigned(n: int, bits: int) -> int:
    """Two's complement bit pattern of ``n`` in ``bits`` bits."""
    return n & ((1 << bits) - 1)


def from_unsigned(u: int, bits: int, signed: bool) -> int:
    """The integer a ``bits``-bit pattern ``u`` carries (two's complement when ``signed``)."""
    if signed and u >> (bits - 1):
        return u - (1 << bits)
    return u
