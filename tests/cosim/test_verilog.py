"""Verilog export and Verilator lint (cosim.tools.verilog)."""
import re

import pytest
from amaranth.hdl import Fragment, Module, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from cosim.tools.verilog import LINT_WAIVERS, export_verilog, lint
from cosim.backends.verilog import component_ports, verilog_text
from cosim.core.executables import find_executable
from test_verilator import AccDemo, DropFifoDemo, FifoDemo, Wide64Demo

needs_verilator = pytest.mark.skipif(find_executable("verilator") is None,
                                     reason="Verilator not found on PATH")


class Passthrough(wiring.Component):
    i: In(stream.Signature(unsigned(8), always_ready=True))
    o: Out(stream.Signature(unsigned(8), always_ready=True))

    def elaborate(self, platform):
        m = Module()
        m.d.sync += [self.o.payload.eq(self.i.payload), self.o.valid.eq(self.i.valid)]
        return m


def used(component):
    """Elaborate ``component`` so Amaranth does not warn that it was never used."""
    Fragment.get(component, None)
    return component


def test_ports_follow_the_signature():
    ports = {p.name: p for p in component_ports(used(FifoDemo()))}
    assert set(ports) == {"i__payload", "i__valid", "i__ready", "o__payload", "o__valid",
                          "o__ready", "level"}
    assert ports["i__ready"].direction == "out" and ports["o__ready"].direction == "in"
    # always-ready streams have no ready port (Const(1) is not a port)
    assert "i__ready" not in {p.name for p in component_ports(used(AccDemo()))}
    acc = {p.name: p for p in component_ports(used(AccDemo(width=8, acc_width=14)))}
    assert acc["i__payload"].width == 16 and acc["o__payload"].width == 28
    assert acc["shift"].width == 3 and acc["clear"].direction == "in"


def test_export_writes_the_module(tmp_path):
    path = export_verilog(AccDemo(), name="acc_export", out_dir=tmp_path)
    assert path == tmp_path / "acc_export.v"
    text = path.read_text()
    header = re.search(r"module acc_export\((.*?)\);", text).group(1)
    assert set(header.replace(" ", "").split(",")) == {
        "clk", "rst", "i__payload", "i__valid", "o__payload", "o__valid", "shift", "clear"}


def test_bad_module_name():
    dut = Passthrough()
    with pytest.raises(ValueError, match="simple identifier, not 'a-b'"):
        verilog_text(dut, name="a-b")
    used(dut)


@needs_verilator
@pytest.mark.verilator
@pytest.mark.parametrize("demo", [AccDemo, FifoDemo, DropFifoDemo, Wide64Demo, Passthrough])
def test_demos_lint_clean(tmp_path, demo):
    name = demo.__name__.lower()
    assert lint(export_verilog(demo(), name=name, out_dir=tmp_path)) == []


@needs_verilator
@pytest.mark.verilator
def test_lint_reports_real_problems(tmp_path):
    bad = tmp_path / "bad.v"
    bad.write_text("module bad(input wire a, output wire y, output wire z);\n"
                   "  assign y = a;\nendmodule\n")
    findings = lint(bad)
    assert len(findings) == 1 and "UNDRIVEN" in findings[0] and "'z'" in findings[0]
    assert "-Wno-UNDRIVEN" not in LINT_WAIVERS


@needs_verilator
@pytest.mark.verilator
def test_lint_without_waivers_would_complain(tmp_path):
    """The waivers are needed: plain -Wall flags Amaranth's output of a correct design."""
    path = export_verilog(FifoDemo(), name="fifo_nowaive", out_dir=tmp_path)
    findings = lint(path, extra_args=("-Wwarn-DECLFILENAME", "-Wwarn-UNUSEDSIGNAL", "-Wwarn-WIDTH"))
    kinds = {re.match(r"%Warning-(\w+)", f).group(1) for f in findings}
    assert kinds == {"DECLFILENAME", "UNUSEDSIGNAL", "WIDTH"}


def test_lint_missing_verilator(monkeypatch, tmp_path):
    path = tmp_path / "x.v"
    path.write_text("module x(); endmodule\n")
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(RuntimeError, match="Verilator not found on PATH"):
        lint(path)
