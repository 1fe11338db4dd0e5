"""Export Amaranth components to Verilog and lint the result with Verilator.

Every simulation backend and the synthesis flow take the Verilog from here, so that what is
linted, what is simulated with Verilator and what is synthesised are the same text.
"""
from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

from amaranth.back import verilog as _amaranth_verilog
from amaranth.hdl import Const, Value, ValueCastable
from amaranth.hdl import _ir
from amaranth.lib import wiring

__all__ = ["PortInfo", "component_ports", "verilog_text", "export_verilog", "lint",
           "LINT_WAIVERS", "verilator_missing_message"]

#: Root of the repository; generated files default to ``<repo>/build/...``.
REPO_ROOT = Path(__file__).resolve().parents[1]

#: Warnings that Amaranth 0.5's Verilog output (yosys ``write_verilog``) always produces, so
#: they say nothing about the design; everything else that ``-Wall`` reports is returned.
#:
#: - ``DECLFILENAME``: submodules are written as escaped identifiers (``\\top.sub``) into the
#:   one file named after the top module, so their names never match the file name.
#: - ``UNUSEDSIGNAL``: Amaranth keeps every named signal (struct field views such as
#:   ``\\i__payload.q``, unused bits of ports, the ``$auto$verilog_backend`` trigger reg)
#:   for debugging, and ``rst`` is an input even when no register uses it.
#: - ``WIDTH``: ``write_verilog`` writes sign extension as ``$signed(a) + $signed(b)`` with
#:   operands of their own width and lets Verilog's context-determined width extend them;
#:   that is correct Verilog and Amaranth's arithmetic, but Verilator flags every such
#:   expression. (Width bugs in the *Amaranth* source cannot exist at this level: Amaranth
#:   fixes every width before emitting.)
LINT_WAIVERS: tuple[str, ...] = ("-Wno-DECLFILENAME", "-Wno-UNUSEDSIGNAL", "-Wno-WIDTH")


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


def export_verilog(component: wiring.Component, *, name: str,
                   out_dir: str | Path = REPO_ROOT / "build" / "verilog",
                   emit_src: bool = True) -> Path:
    """Write ``component`` as Verilog to ``<out_dir>/<name>.v`` and return the path.

    Parameters
    ----------
    component : wiring.Component
        The design; its signature members (less constants such as the ``ready`` of an
        always-ready stream) become the ports, named by path with ``__``
        (``i__payload``, ``i__valid``, ``o__ready``, ...), plus ``clk`` and ``rst`` of the
        ``sync`` domain.
    name : str
        Top module name (also the file name).
    out_dir : path
        Output directory, created if needed; relative paths are relative to the current
        directory.
    emit_src : bool
        Keep Amaranth's ``src`` attributes (Python file and line of each signal).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{name}.v"
    path.write_text(verilog_text(component, name=name, emit_src=emit_src))
    return path


_WARNING_RE = re.compile(r"^%(Warning|Error)(-[A-Z0-9_]+)?:")


def lint(path_or_paths, *, top: str | None = None, extra_args: tuple[str, ...] = ()) -> list[str]:
    """Run ``verilator --lint-only -Wall`` with :data:`LINT_WAIVERS` and return the findings.

    Parameters
    ----------
    path_or_paths : path or list of paths
        Verilog file(s).
    top : str, optional
        Top module name (default: the stem of the first file, as :func:`export_verilog`
        names files).
    extra_args : tuple of str
        More Verilator options (e.g. further waivers for one design).

    Returns
    -------
    list of str
        One entry per ``%Warning``/``%Error`` message (first line of each); empty when the
        design lints clean.

    Raises
    ------
    RuntimeError
        If ``verilator`` is not on PATH, or it fails without reporting a warning or error.
    """
    paths = [Path(path_or_paths)] if isinstance(path_or_paths, (str, Path)) \
        else [Path(p) for p in path_or_paths]
    if not paths:
        raise ValueError("lint needs at least one Verilog file")
    exe = shutil.which("verilator")
    if exe is None:
        raise RuntimeError(verilator_missing_message())
    top = top or paths[0].stem
    cmd = [exe, "--lint-only", "-Wall", *LINT_WAIVERS, "--top-module", top, *extra_args,
           *map(str, paths)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    findings = [line for line in (proc.stdout + proc.stderr).splitlines()
                if _WARNING_RE.match(line) and not line.startswith("%Error: Exiting due to")]
    if proc.returncode != 0 and not findings:
        raise RuntimeError(f"verilator --lint-only failed ({proc.returncode}):\n"
                           f"{proc.stdout}{proc.stderr}")
    return findings
