"""The ports a stream simulator runs (:func:`cosim.backends.verilog.stream_ports`, shared by
the Verilator and Icarus backends): an output stream ``o`` is required and no port may take
the sync domain's ``clk``/``rst`` names."""
from __future__ import annotations

import pytest
from amaranth.hdl import Module
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from cosim.backends.verilog import stream_ports


class _Dut(wiring.Component):
    def __init__(self, members):
        super().__init__(members)
        self._MustUse__silence = True   # never elaborated: no 'created but never used'

    def elaborate(self, platform):
        m = Module()
        for name in self.signature.members:
            port = getattr(self, name)
            if name == "o":
                m.d.comb += port.valid.eq(1)
        return m


def test_a_stream_component_gives_its_ports():
    dut = _Dut({"i": In(stream.Signature(8)), "o": Out(stream.Signature(8))})
    names = [p.name for p in stream_ports(dut)]
    assert "o__valid" in names and "o__payload" in names and "i__payload" in names


@pytest.mark.parametrize("members,msg", [
    ({"x": In(8), "y": Out(8)}, r"must have an output stream `o` \(no o__valid port\)"),
    ({"clk": In(1), "o": Out(stream.Signature(8))},
     r"port name 'clk' clashes with the sync domain's clock/reset"),
])
def test_refused(members, msg):
    with pytest.raises(ValueError, match=msg):
        stream_ports(_Dut(members))
