"""Register maps: a front end's control registers, their bus addresses and word widths, and
the one check of a register write.

One :class:`RegisterMap` describes a front end's registers for every side that reads or
writes them: the HDL top decodes each :attr:`Register.address` and takes
:attr:`Register.width` bits of the bus data, the bit-exact model and the register sessions
check each write with :meth:`RegisterMap.check_write`, and the DSP names registers through
:attr:`RegisterMap.names`. A bus word is the register's raw bits (``0 <= word <
2**width``); a signed register holds its value(s) in two's complement.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple


class Register(NamedTuple):
    """One register.

    ``name`` and bus ``address``; ``width`` bits of bus data. The word holds ``parts`` equal
    values of ``width // parts`` bits, LSB first (e.g. ``re | im << b``), each two's
    complement if ``signed``; each must lie in ``[minimum, maximum]`` (default: every value
    its bits hold).
    """

    name: str
    address: int
    width: int
    signed: bool = False
    minimum: int | None = None
    maximum: int | None = None
    parts: int = 1

    @property
    def part_width(self) -> int:
        return self.width // self.parts

    @property
    def bounds(self) -> tuple[int, int]:
        """``(lo, hi)``: the range every part must lie in."""
        b = self.part_width
        lo, hi = (-(1 << (b - 1)), (1 << (b - 1)) - 1) if self.signed else (0, (1 << b) - 1)
        return (lo if self.minimum is None else self.minimum,
                hi if self.maximum is None else self.maximum)

    def rule(self) -> str:
        """The rule a write must follow, for messages."""
        kind = "two's complement" if self.signed else "unsigned"
        lo, hi = self.bounds
        if self.parts == 1:
            return (f"{self.width}-bit {kind} words in [{lo}, {hi}]" if self.signed else
                    f"{kind} {self.width}-bit words in [{lo}, {hi}]")
        return (f"{self.width}-bit words of {self.parts} {kind} {self.part_width}-bit parts "
                f"(LSB first), each in [{lo}, {hi}]")


@dataclass(frozen=True)
class RegisterMap:
    """A front end's registers.

    Parameters
    ----------
    what : str
        The front end's name in error messages.
    registers : sequence of Register or tuples
        Names and addresses unique; widths >= 1 and divisible by ``parts``.
    """

    what: str
    registers: tuple[Register, ...]

    def __post_init__(self):
        try:
            rs = tuple(Register(*r) for r in self.registers)
        except TypeError as e:
            raise ValueError(f"{self.what} registers must be Register tuples: {e}") from None
        for r in rs:
            if not isinstance(r.name, str) or not r.name:
                raise ValueError(f"{self.what} register name must be a non-empty string, "
                                 f"not {r.name!r}")
            for k in ("address", "width", "parts"):
                v = getattr(r, k)
                if isinstance(v, bool) or not isinstance(v, int) or v < (k != "address"):
                    raise ValueError(f"{self.what} register {r.name} {k} must be an int >= "
                                     f"{int(k != 'address')}, not {v!r}")
            if r.width % r.parts:
                raise ValueError(f"{self.what} register {r.name} width {r.width} must be a "
                                 f"multiple of its {r.parts} parts")
            lo, hi = r.bounds
            full = Register(*r[:4], parts=r.parts).bounds
            if not full[0] <= lo <= hi <= full[1]:
                raise ValueError(f"{self.what} register {r.name} range [{lo}, {hi}] must be "
                                 f"non-empty and within its bits' [{full[0]}, {full[1]}]")
        for k, what in (("name", "names"), ("address", "addresses")):
            vs = [getattr(r, k) for r in rs]
            if len(set(vs)) != len(vs):
                raise ValueError(f"{self.what} register {what} must be unique, not {vs}")
        object.__setattr__(self, "registers", rs)
        # lookups by name and by address (every write goes through them)
        object.__setattr__(self, "_by_name", {r.name: r for r in rs})
        object.__setattr__(self, "_by_addr", {r.address: (r, r.part_width, *r.bounds)
                                              for r in rs})

    @property
    def names(self) -> dict[str, int]:
        """Register name -> bus address."""
        return {r.name: r.address for r in self.registers}

    @property
    def addresses(self) -> tuple[int, ...]:
        return tuple(r.address for r in self.registers)

    def __getitem__(self, name: str) -> Register:
        try:
            r = self._by_name.get(name)
        except TypeError:       # unhashable
            r = None
        if r is not None:
            return r
        raise KeyError(f"{self.what} registers are {', '.join(self.names)}, not {name!r}")

    def address(self, name: str) -> int:
        """The bus address of register ``name`` (``KeyError`` listing the names)."""
        return self[name].address

    def at(self, address: int) -> Register:
        """The register at bus ``address`` (``ValueError`` listing the addresses)."""
        try:
            e = self._by_addr.get(address)
        except TypeError:       # unhashable
            e = None
        if e is not None:
            return e[0]
        raise ValueError(f"{self.what} register address must be one of "
                         f"{', '.join(map(str, self.addresses))}, not {address!r}")

    def width(self, address: int) -> int:
        """Bus data bits of the register at ``address``."""
        return self.at(address).width

    def check_write(self, address: int, value) -> int:
        """The bus word of a write of ``value`` to ``address`` (an int), or ``ValueError``
        naming the register and its rule (:meth:`Register.rule`)."""
        r = self.at(address)
        _, b, lo, hi = self._by_addr[r.address]
        try:
            v = int(value)
            ok = v == value and not isinstance(value, bool)
        except (TypeError, ValueError, OverflowError):
            ok = False
        if ok and 0 <= v < 1 << r.width:
            for i in range(r.parts):
                x = (v >> (i * b)) & ((1 << b) - 1)
                if r.signed and x >> (b - 1):
                    x -= 1 << b
                ok = ok and lo <= x <= hi
            if ok:
                return v
        raise ValueError(f"{self.what} register {r.name} (address {r.address}) takes "
                         f"{r.rule()}, not {value!r}")
