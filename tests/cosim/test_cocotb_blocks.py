"""Every exported design under cocotb on Icarus Verilog against its bit-exact model, and a
four-state defect that only Icarus sees.

- Each HDL block (:data:`cosim.tools.stream_cases.BLOCK_CASES`) runs its seeded case
  (random words with full-scale values, gaps in ``valid``, run-time writes, a stall that
  overflows the FIFO) through :func:`cosim.testing.check_stream` on the ``icarus`` backend:
  every output word and its cycle equal the model's (0 mismatches), no output X or Z.
- Every receiver top runs its short case (:mod:`cosim.tools.top_cases`: the top's HDL at
  reduced parameters, register writes mid-run, seeded stalls into a FIFO of one record) in
  the fast suite, but the 12-channel I/Q array (its real-input twin runs) and the monopulse
  front end (its Icarus session with writes and drops runs in test_icarus.py), slow:
  :data:`SLOW_SHORT_TOPS`. Icarus runs whole tops at ~0.2-1.5e3 cycles/s. The registered
  tops with their own parameters (the cases ``python -m cosim verilog --cocotb`` exports)
  are slow.
- A new exported design without a case fails :func:`test_every_exported_design_has_a_case`.
- The four-state defect: a lookup table of 10 entries read by a 4-bit counter that is never
  wrapped at 9. The Amaranth simulator and Verilator (two-state) read 0 past the end and
  agree with a model that assumes so; Icarus reads X there and the check fails naming the
  port, its bits and the cycle.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import memory, stream, wiring
from amaranth.lib.wiring import In, Out

from cosim.backends.icarus import icarus_available, icarus_missing_message
from cosim.backends.verilator_harness import verilator_available
from cosim.testing import StreamMismatch, check_stream
from cosim.tools.stream_cases import BLOCK_CASES, exported_designs, stream_case, top_case_names

pytestmark = [pytest.mark.icarus,
              pytest.mark.skipif(not icarus_available(), reason=icarus_missing_message())]

#: The tops whose short case is slow, and the fast Icarus check of the same HDL: the real-input
#: array's case; the monopulse front end's session on Icarus (register writes mid-run, stalls
#: that drop records, every word and cycle against the model) in test_icarus.py.
SLOW_SHORT_TOPS = {"gnss_channel_array12_iq": "test_top_on_icarus_equals_model",
                   "monopulse_frontend": "test_session_in_blocks_equals_one_step_and_reads_ports"}


def _check(case):
    return check_stream(case.make(), (case.words, case.cycles), case.in_words,
                        valid=case.in_valid, ready=case.out_ready, n_cycles=case.n_cycles,
                        inputs=case.inputs, writes=case.writes, backends=("icarus",),
                        name=case.name, vcd="never")


def test_every_exported_design_has_a_case():
    """Every design ``python -m cosim verilog`` exports has a cocotb case."""
    designs = set(exported_designs())
    cased = set(BLOCK_CASES) | set(top_case_names())
    assert designs - cased == set(), f"exported without a cocotb case: {designs - cased}"
    assert cased - designs == set(), f"cases of designs not exported: {cased - designs}"
    assert set(SLOW_SHORT_TOPS) < set(top_case_names())
    src = Path(__file__).read_text() + Path(__file__).with_name("test_icarus.py").read_text()
    for name, test in SLOW_SHORT_TOPS.items():
        assert re.search(rf"^def {test}\(", src, re.M), f"{name}: no fast check {test}"


@pytest.mark.parametrize("name", list(BLOCK_CASES))
def test_block_on_icarus_equals_model(name):
    case = stream_case(name)
    assert len(case.words) >= 10, "the case must produce output words"
    res = _check(case).results["icarus"]
    assert len(res.words) == len(case.words)


def _top_checked(name, short):
    """Top ``name``'s case on Icarus: its words and cycles, and register writes on the bus
    (or the NCO word) that fall between output words (``short``; else before the last one),
    so the words after them carry their effect."""
    case = stream_case(name, short=short)
    assert len(case.words) >= 3, "the case must produce output words"
    w = [c for c, port, v in case.writes if port in ("reg_we", "freq") and v and c > 0]
    assert len(w) >= 3, "register writes"
    # between output words; the registered monopulse top gives one record (84,372 cycles)
    first = case.cycles[0] if short else 0
    assert any(first < c < case.cycles[-1] for c in w), "writes between output words"
    res = _check(case).results["icarus"]
    assert len(res.words) == len(case.words)


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow)
                                  if n in SLOW_SHORT_TOPS else n for n in top_case_names()])
def test_top_on_icarus_equals_model(name):
    """A registered top's HDL on its short case (reduced parameters, register writes
    mid-run, stalls that drop records): TACAN 3,400 cycles (17 s on Icarus), the GNSS
    channels 8,884 (four code periods; 9-21 s), the 12-channel arrays 6,838 (three; 38 s),
    monopulse 1,944 (14 s)."""
    _top_checked(name, short=True)


@pytest.mark.slow
@pytest.mark.parametrize("name", top_case_names())
def test_registered_top_on_icarus_equals_model(name):
    """The registered top with its own parameters on the case ``verilog --cocotb`` exports:
    TACAN 10,400 cycles, the GNSS tops three code periods (49,804 cycles), monopulse one
    record (84,372 cycles)."""
    _top_checked(name, short=False)


# -- the four-state defect ------------------------------------------------------------------------
TABLE = (3, 1, 4, 1, 5, 9, 2, 6, 5, 3)


class _Lut(wiring.Component):
    """Adds ``TABLE[k]`` to the k-th input word. The defect (``wrap=False``): the 4-bit index
    ``k`` is not wrapped at ``len(TABLE) - 1``, so words 10..15 of every 16 read past the
    table's end."""

    def __init__(self, wrap: bool = False):
        self.wrap = wrap
        super().__init__({"i": In(stream.Signature(8)), "o": Out(stream.Signature(8))})

    def elaborate(self, platform):
        m = Module()
        m.submodules.mem = mem = memory.Memory(shape=8, depth=len(TABLE), init=TABLE)
        rd = mem.read_port(domain="comb")
        k = Signal(4)
        nxt = Mux(k == len(TABLE) - 1, 0, k + 1) if self.wrap else k + 1
        m.d.comb += [rd.addr.eq(k), self.i.ready.eq(~self.o.valid | self.o.ready)]
        with m.If(self.i.valid & self.i.ready):
            m.d.sync += [k.eq(nxt), self.o.valid.eq(1),
                         self.o.payload.eq(rd.data + self.i.payload)]
        with m.Elif(self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        return m


def _two_state_model(x):
    """What a two-state simulator makes of the defect: 0 past the table's end."""
    t = np.r_[TABLE, np.zeros(16 - len(TABLE), np.int64)]
    return (np.asarray(x) + t[np.arange(len(x)) % 16]) & 0xFF


def test_four_state_defect_only_icarus_sees():
    """Amaranth's simulator and Verilator pass the defective LUT against the two-state
    model; Icarus fails it: the 11th word (index 10) reads X at the table's end."""
    rng = np.random.default_rng(45)
    x = rng.integers(0, 256, 40)
    ready = rng.random(80) < 0.7
    two_state = ("pysim", "verilator") if verilator_available() else ("pysim",)
    ok = check_stream(_Lut(), _two_state_model, x, ready=ready, backends=two_state,
                      name="lut_defect", vcd="never")
    assert len(ok.words) == 40
    with pytest.raises(StreamMismatch) as e:
        check_stream(_Lut(), _two_state_model, x, ready=ready, backends=("icarus",),
                     name="lut_defect", vcd="never")
    msg = str(e.value)
    assert re.search(r"icarus: Icarus: output o__payload of lut_defect is [01xX]*[xX][01xX]* "
                     r"\(X or Z bits\) at the edge of cycle \d+, after 10 output words", msg), msg
    # Wrapped at the table's end, the same LUT passes on Icarus too.
    fixed = (np.asarray(x) + np.asarray(TABLE)[np.arange(len(x)) % len(TABLE)]) & 0xFF
    check_stream(_Lut(wrap=True), fixed, x, ready=ready, backends=("icarus",),
                 name="lut_fixed", vcd="never")
    fixed[7] ^= 1 << 3      # and the Icarus check fails on a wrong expected word
    with pytest.raises(StreamMismatch, match=r"icarus vs model: words differ at index 7 "):
        check_stream(_Lut(wrap=True), fixed, x, ready=ready, backends=("icarus",),
                     name="lut_fixed", vcd="never")
