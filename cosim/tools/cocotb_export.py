"""A self-contained cocotb testbench of an exported design (``python -m cosim verilog
--cocotb DIR``), to run in a flow of one's own with nothing of this toolkit installed.

:func:`export_cocotb` writes, into ``DIR/<name>/``:

- ``<name>.v``: the Verilog (:func:`cosim.backends.verilog.verilog_text`, the text the
  toolkit's own Icarus and Verilator runs simulate);
- ``case.json``: a :class:`cosim.tools.stream_cases.StreamCase` -- the input words, ``valid``
  and ``ready`` per cycle, the constant inputs and register writes, and the output words and
  their cycles the bit-exact model predicts (unsigned, masked to the port widths);
- ``kfnav_stream_driver.py``: the per-cycle stream driver the toolkit's Icarus backend uses
  (:mod:`cosim.backends.icarus_tb`, copied as is: it imports only cocotb);
- ``test_<name>.py``: the cocotb test -- it sets the inputs, starts a 2 ns clock, drives the
  case through the driver and asserts every output word and its cycle, and that no output is
  X or Z;
- ``run.py``: builds the Verilog with Icarus Verilog and runs the test through cocotb's
  runner (``python run.py``: exit status 0 when it passes; or ``pytest run.py``).

Requirements to run it: Python 3.9+, cocotb 2.x, Icarus Verilog (``iverilog``, ``vvp``).
The how-to: ``docs/howto/cocotb_testbench.md``.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from ..backends.icarus import TB_PATH
from ..backends.verilog import component_ports, verilog_text
from .stream_cases import StreamCase

__all__ = ["export_cocotb", "DRIVER_MODULE"]

#: The driver's module name in an exported testbench.
DRIVER_MODULE = "kfnav_stream_driver"

_TEST = '''"""cocotb test of {name}: the stimulus of case.json driven into {name}.v, every output
word and its cycle compared with the bit-exact model's (written by `python -m cosim verilog
--cocotb`); an output X or Z fails. Run it with `python run.py` (or `pytest run.py`)."""
import json
from pathlib import Path

import cocotb
from cocotb.clock import Clock

from {driver} import StreamDriver

CASE = Path(__file__).with_name("case.json")


@cocotb.test()
async def test_{name}(dut):
    case = json.loads(CASE.read_text())
    for port, value in case["inputs"].items():
        getattr(dut, port).value = value
    drv = StreamDriver(dut, case["outputs"])
    Clock(dut.clk, 2, unit="ns").start(start_high=False)
    valid = [c == "1" for c in case["in_valid"]]
    ready = [c == "1" for c in case["out_ready"]]
    writes = [tuple(w) for w in case["writes"]]
    words, cycles, _, unknown, _ = await drv.step(
        ("step", case["in_words"], valid, ready, case["n_cycles"], writes, []))
    if unknown is not None:
        cycle, port, bits = unknown
        raise AssertionError(f"output {{port}} is {{bits}} (X or Z bits) at the edge of cycle "
                             f"{{cycle}}, after {{len(words)}} output words")
    want_w, want_c = case["words"], case["cycles"]
    for k, (w, c, ww, wc) in enumerate(zip(words, cycles, want_w, want_c)):
        assert (w, c) == (ww, wc), (f"output word {{k}}: {{w:#x}} on cycle {{c}}, the model "
                                    f"gives {{ww:#x}} on cycle {{wc}}")
    assert len(words) == len(want_w), (f"{{len(words)}} output words in {{case['n_cycles']}} "
                                       f"cycles, the model gives {{len(want_w)}}")
    dut._log.info("%d output words equal the model's, words and cycles", len(words))
'''

_RUN = '''"""Build {name}.v with Icarus Verilog and run its cocotb test with cocotb's runner.

    python run.py          # exit status 0 when the test passes
    pytest run.py          # the same as a pytest test
"""
import os
import sys
from pathlib import Path

from cocotb_tools.runner import get_results, get_runner

HERE = Path(__file__).resolve().parent
TOP = "{name}"


def run() -> int:
    runner = get_runner("icarus")
    build = HERE / "sim_build"
    runner.build(sources=[HERE / f"{{TOP}}.v"], hdl_toplevel=TOP, build_dir=build,
                 timescale=("1ns", "1ps"), always=True)
    path = os.pathsep.join(p for p in (str(HERE), os.environ.get("PYTHONPATH")) if p)
    xml = runner.test(test_module=f"test_{{TOP}}", hdl_toplevel=TOP, build_dir=build,
                      test_dir=HERE, extra_env={{"PYTHONPATH": path}})
    tests, failed = get_results(xml)
    return 0 if tests > 0 and failed == 0 else 1


def test_{name}():
    assert run() == 0


if __name__ == "__main__":
    sys.exit(run())
'''


def _unsigned(values, width: int) -> list[int]:
    mask = (1 << width) - 1
    return [int(v) & mask for v in np.asarray(values).ravel()]


def _bits(mask, n: int) -> str:
    """A per-cycle bool array as a string of 0/1 (empty: all 1, as the driver reads it)."""
    return "" if mask is None else "".join("1" if b else "0" for b in np.asarray(mask, bool)[:n])


def export_cocotb(case: StreamCase, out_dir: str | Path) -> Path:
    """Write the standalone cocotb testbench of ``case`` into ``<out_dir>/<case.name>/``
    (module doc) and return that directory."""
    d = Path(out_dir) / case.name
    d.mkdir(parents=True, exist_ok=True)
    comp = case.make()
    ports = {p.name: p for p in component_ports(comp)}
    (d / f"{case.name}.v").write_text(verilog_text(comp, name=case.name, emit_src=False))
    inputs = {"rst": 0, **{n: 0 for n, p in ports.items() if p.direction == "in"}}
    inputs.update({k: int(v) & ((1 << ports[k].width) - 1) for k, v in case.inputs.items()})
    n = case.n_cycles
    pin, pout = ports.get("i__payload"), ports["o__payload"]
    data = {
        "top": case.name, "n_cycles": n, "inputs": inputs,
        "writes": [[int(c), p, int(v) & ((1 << ports[p].width) - 1)] for c, p, v in case.writes],
        "in_words": [] if case.in_words is None else
        (_unsigned(case.in_words, pin.width) if pin is not None else [0] * len(case.in_words)),
        "in_valid": _bits(case.in_valid, n), "out_ready": _bits(case.out_ready, n),
        "words": _unsigned(case.words, pout.width), "cycles": [int(c) for c in case.cycles],
        "outputs": [p for p, info in ports.items() if info.direction == "out"],
    }
    (d / "case.json").write_text(json.dumps(data))
    shutil.copyfile(TB_PATH, d / f"{DRIVER_MODULE}.py")
    (d / f"test_{case.name}.py").write_text(_TEST.format(name=case.name, driver=DRIVER_MODULE))
    (d / "run.py").write_text(_RUN.format(name=case.name))
    return d
