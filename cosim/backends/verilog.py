"""Amaranth components as Verilog text, and their ports as the Verilog names them.

Every simulation backend and the synthesis flow take the Verilog from here, so that what is
linted (:mod:`cosim.tools.verilog`), what is simulated with Verilator and what is
synthesised are the same text.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from amaranth.back import verilog as _amaranth_verilog
from amaranth.hdl import Const, Value, ValueCastable
from amaranth.hdl import _ir
from amaranth.lib import wiring

__all__ = ["PortInfo", "component_ports", "stream_ports", "verilog_text",
           "verilator_missing_message"]

def verilator_missing_message() -> str:
    return ("Verilator not found on PATH: install it with `make setup` (apt-get install "
            "verilator) or use the pysim/model backends")


@dataclass(frozen=True)
class PortInfo:
    """One top-level port of an exported component.

    Attributes
    ----------
    name : str
        Verilog port name (signature path joined with ``__``, e.g. ``i__payload``).
    value : Value
        The component's Amaranth value for this port.
    direction : str
        ``"in"`` or ``"out"`` (as seen from the component).
    width : int
        Port width in bits.
    signed : bool
        Whether the Amaranth value is signed (affects only how read-back values are shown).
    """

    name: str
    value: Value
    direction: str
    width: int
    signed: bool


def component_ports(component: wiring.Component) -> list[PortInfo]:
    """List the Verilog ports of ``component``: its signature members, less constants.

    Amaranth 0.5.10's own ``convert(component)`` fails on components with always-ready
    streams (their ``ready`` member is ``Const(1)``, not a signal); constant members are
    simply not ports here.
    """
    if not isinstance(getattr(component, "signature", None), wiring.Signature):
        raise TypeError(f"expected a wiring.Component with a signature, not {component!r}")
    ports = []
    for path, member, value in component.signature.flatten(component):
        if isinstance(value, ValueCastable):
            value = value.as_value()
        if not isinstance(value, Value) or isinstance(value, Const) or len(value) == 0:
            continue  # constants and zero-width members (e.g. a bare strobe stream) are not ports
        shape = value.shape()
        ports.append(PortInfo(name="__".join(map(str, path)), value=value,
                              direction="in" if member.flow == wiring.In else "out",
                              width=len(value), signed=shape.signed))
    return ports


def stream_ports(component: wiring.Component) -> list[PortInfo]:
    """The ports of a component a stream simulator runs (:func:`component_ports`): it must
    have an output stream ``o``, and no port may be named ``clk`` or ``rst`` (the sync
    domain's)."""
    ports = component_ports(component)
    names = {p.name for p in ports}
    for required in ("o__valid", "o__payload"):
        if required not in names:
            raise ValueError(f"component must have an output stream `o` (no {required} port)")
    for p in ports:
        if p.name in ("clk", "rst"):
            raise ValueError(f"port name {p.name!r} clashes with the sync domain's clock/reset")
    return ports


def verilog_text(component: wiring.Component, *, name: str, emit_src: bool = True) -> str:
    """Convert ``component`` to Verilog text with module name ``name``.

    ``emit_src=False`` leaves out the source-location attributes, so the text (and any
    cache keyed on it) depends on the design only, not on line numbers of the Python source.
    """
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise ValueError(f"Verilog module name must be a simple identifier, not {name!r}")
    ports = {p.name: (p.value, _ir.PortDirection.Input if p.direction == "in"
                      else _ir.PortDirection.Output)
             for p in component_ports(component)}
    return _amaranth_verilog.convert(component, name=name, ports=ports, emit_src=emit_src)
