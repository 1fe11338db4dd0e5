"""Export Amaranth components to Verilog files and lint them with Verilator
(``python -m cosim verilog``); the text is :func:`cosim.backends.verilog.verilog_text`, the
same the Verilator backend simulates and synthesis reads."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

from amaranth.lib import wiring

from ..backends.verilog import verilator_missing_message, verilog_text
from ..core.executables import find_executable, tool_env
from ..core.provenance import REPO_ROOT

__all__ = ["export_verilog", "lint", "LINT_WAIVERS"]

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
    exe = find_executable("verilator")
    if exe is None:
        raise RuntimeError(verilator_missing_message())
    top = top or paths[0].stem
    cmd = [exe, "--lint-only", "-Wall", *LINT_WAIVERS, "--top-module", top, *extra_args,
           *map(str, paths)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=tool_env())
    findings = [line for line in (proc.stdout + proc.stderr).splitlines()
                if _WARNING_RE.match(line) and not line.startswith("%Error: Exiting due to")]
    if proc.returncode != 0 and not findings:
        raise RuntimeError(f"verilator --lint-only failed ({proc.returncode}):\n"
                           f"{proc.stdout}{proc.stderr}")
    return findings
