"""What every HDL block shares: sample layouts, rounding and saturation, constructor checks.

One place for each, so the blocks (and the next receivers' blocks) build the same thing
the same way:

* **Layouts** -- :func:`iq_layout` (complex sample), :func:`lo_layout` (LO ``cos``/``sin``),
  :func:`sample_shape` / :func:`channel_values` (real or complex streams).
* **Rounding** -- :func:`round_shift`, the HDL form of :func:`dsp.fixed.shift_right` (the
  numpy models use that, the numba kernels :mod:`hdl.model.rounding`); **saturation /
  wraparound** -- :func:`fit_width` (the ``overflow`` modes of :mod:`dsp.fixed`).
* **Constant and narrow products** -- :func:`const_mul` and :func:`narrow_mul`, shifts and
  adds instead of a multiplier.
* **Fan-out copies** -- :func:`fanout_copies`, a registered value copied per slice of the
  bits it drives, each copy kept apart from yosys's merging.
* **Constructor errors** -- a block validates its arguments in ``__init__`` and raises
  ``ValueError`` stating the rule and repeating the bad value (never ``assert``: it vanishes
  under ``python -O``): :func:`check_params` for the parameter object, the parameter
  dataclasses use :func:`dsp.fixed.check_width` / :func:`dsp.fixed.check_int` for numbers.
"""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Mux, Signal, signed
from amaranth.lib import data

from dsp.fixed import OVERFLOWS, ROUNDINGS

__all__ = ["iq_layout", "lo_layout", "sample_shape", "channel_values", "round_shift",
           "fit_width", "const_mul", "narrow_mul", "fanout_copies", "check_params",
           "check_bool"]

#: Bits one copy of a :func:`fanout_copies` register drives.
FANOUT_SLICE = 32


# -- layouts ----------------------------------------------------------------------------------

def iq_layout(width: int) -> data.StructLayout:
    """Complex sample ``{"i", "q"}``, signed ``width`` each, ``i`` at the LSB."""
    return data.StructLayout({"i": signed(width), "q": signed(width)})


def lo_layout(width: int) -> data.StructLayout:
    """LO sample ``exp(j*phi)`` as ``{"cos", "sin"}``, signed ``width`` each, cos at the LSB."""
    return data.StructLayout({"cos": signed(width), "sin": signed(width)})


def sample_shape(width: int, channels: int):
    """``signed(width)`` for real samples, :func:`iq_layout` for complex ones."""
    if channels == 1:
        return signed(width)
    return iq_layout(width)


def channel_values(payload, channels: int) -> list:
    """The per-channel signed values of a stream payload (real: [x]; complex: [i, q])."""
    if channels == 1:
        return [payload]
    return [payload.i, payload.q]


# -- rounding and overflow ----------------------------------------------------------------------

def round_shift(v, drop: int, rounding: str):
    """``v >> drop`` with the rounding of :func:`dsp.fixed.shift_right`; ``drop <= 0`` is a
    left shift. The result is one bit wider than ``v >> drop``, so a rounding carry is never
    lost (:func:`fit_width` then applies the overflow mode).

    Every mode is ``floor(v / 2**drop) + up`` with a one-bit ``up`` taken from the dropped
    bits, i.e. one adder. It is written ``q - (up ? -1 : 0)`` with ``-1`` as ``up`` replicated
    to ``q``'s width, so the exported Verilog has no operand width mismatch (``q + up`` is
    emitted as a 29-bit plus a 2-bit ``{1'h0, up}`` operand, which Verilator flags; a bare
    bit slice would likewise be emitted as a 1-bit ``$signed(v[k])``).
    """
    if drop <= 0:
        return v << -drop
    q = v >> drop
    if rounding == "floor":
        return q
    if rounding == "half_up":
        up = v[drop - 1:drop].any()  # a reduction, not a bare slice (docstring)
    elif rounding == "half_even":
        # Above half, or exactly half with an odd kept LSB.
        up = v[drop - 1] & (v[:drop - 1].any() | v[drop])
    elif rounding == "zero":
        # Negative and inexact: floor went one too far down.
        up = v[-1] & v[:drop].any()
    else:
        raise ValueError(f"rounding must be one of {ROUNDINGS}, not {rounding!r}")
    return q - up.replicate(len(q)).as_signed()


def fit_width(v, width: int, overflow: str):
    """``v`` (signed) brought into ``width`` signed bits by saturation or wraparound (the
    ``overflow`` modes of :mod:`dsp.fixed`); unchanged if it already fits."""
    if overflow not in OVERFLOWS:
        raise ValueError(f"overflow must be one of {OVERFLOWS}, not {overflow!r}")
    if len(v) <= width:
        return v
    if overflow == "wrap":
        return v[:width].as_signed()
    # In range iff the bits from the output sign up are all equal (no comparators).
    top = v[width - 1:]
    sign = v[-1]
    return Mux(top.all() | ~top.any(), v[:width], Cat((~sign).replicate(width - 1), sign)
               ).as_signed()


# -- constructor checks -----------------------------------------------------------------------

def const_mul(x, c: int):
    """``x * c`` for a constant ``c >= 0`` as a sum of shifted copies of ``x`` (canonical signed
    digits: 7 is ``(x << 3) - x``; every ``c <= 10`` takes at most one adder), not a
    multiplier. An ECP5 DSP block without its registers, fed and read by fabric logic in one
    cycle, was the slowest path of the TACAN front end; the result is a signed expression
    when a digit is negative (its value is ``x * c >= 0``), assign it to an unsigned signal
    of the product's width."""
    if int(c) != c or c < 0:
        raise ValueError(f"const_mul needs an integer constant >= 0, not {c!r}")
    c = int(c)
    pos, neg, i = [], [], 0
    while c:
        if c & 1:
            d = 2 - (c & 3)           # 1, or -1 when the next bit is set too (... 0 1 1 -> 1 0 -1)
            (pos if d > 0 else neg).append(x << i)
            c -= d
        c >>= 1
        i += 1
    if not pos:
        return Const(0, 1)
    out = pos[0]
    for t in pos[1:]:
        out = out + t
    for t in neg:
        out = out - t
    return out


#: Widest operand :func:`narrow_mul` takes apart (the GNSS mixers' 2-3 bit samples).
NARROW_MUL_BITS = 4


def narrow_mul(a, b):
    """``a * b`` of two signed values. When one has at most :data:`NARROW_MUL_BITS` bits, the
    product is the other's shifted copies selected by its bits, the top bit's copy
    subtracted (two's complement: ``b = -b[n-1] 2**(n-1) + sum b[k] 2**k``), which maps onto
    LUTs; otherwise ``a * b``, an ECP5 DSP block. The value is the same either way (the
    signed product, to the width it is assigned to). A DSP block between two fabric
    registers is a fixed 4.5 ns of logic plus the routing to and from the DSP column: with 48
    of them in the 12-channel I/Q array that path was 12.3 ns, for products of 3 x 4 bits."""
    if len(a) < len(b):
        a, b = b, a
    n = len(b)
    if n > NARROW_MUL_BITS:
        return a * b
    out = Const(0, 1) - Mux(b[n - 1], a << (n - 1), 0)
    for k in range(n - 1):
        out = out + Mux(b[k], a << k, 0)
    return out


def fanout_copies(m, value, bits: int, name: str, width: int = 1):
    """Yield ``(bit slice, register)``: one ``width``-bit register loaded with ``value``
    every cycle in ``m``'s sync domain per :data:`FANOUT_SLICE` of the ``bits`` it drives,
    named ``<name><k>`` and marked ``keep`` so yosys does not merge the copies back into one
    (:mod:`cosim.tools.synth`): no copy drives more than ``FANOUT_SLICE`` enables or gates,
    and each can be placed beside its slice. Each register is made as its slice is asked
    for, so the caller's statements for a slice follow that register's."""
    for k in range(-(-bits // FANOUT_SLICE)):
        r = Signal(width, name=f"{name}{k}", attrs={"keep": 1})
        m.d.sync += r.eq(value)
        yield slice(k * FANOUT_SLICE, (k + 1) * FANOUT_SLICE), r


def check_params(component, params, cls: type, *, article: str | None = None):
    """``params`` if it is a ``cls``, else ``ValueError("<Block> needs a <cls>, not <params>")``.

    Call it first in a component's ``__init__``: a component that raises is never
    elaborated, so it is marked used (no ``UnusedElaboratable`` warning at collection).
    ``article``: "a" or "an" when the class name's first letter does not tell (``NcoParams``
    is read N-C-O: "an").
    """
    if not isinstance(params, cls):
        component._MustUse__silence = True
        if article is None:
            article = "an" if cls.__name__[:1] in "AEIOU" else "a"
        raise ValueError(f"{type(component).__name__} needs {article} {cls.__name__}, "
                         f"not {params!r}")
    return params


def check_bool(component, name: str, value) -> bool:
    """``value`` if it is a bool, else ``ValueError("<Block> <name> must be True or False,
    not <value>")`` (1 and 0 are refused: an option is not a count)."""
    if not isinstance(value, bool):
        component._MustUse__silence = True
        raise ValueError(f"{type(component).__name__} {name} must be True or False, "
                         f"not {value!r}")
    return value
