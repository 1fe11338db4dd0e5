"""The HDL C/A generator's registers against the IS-GPS-200 tables, all 32 PRNs."""
import numpy as np
from amaranth.hdl import Module, Mux, Signal, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from cosim.testing import check_stream
from dsp.gnss.ca_code import CODE_LENGTH, FIRST_10_CHIPS_OCTAL, ca_code, ca_code_table
from hdl.gnss.channel import CaCodeGenerator
from _util import needs_verilator, verilator_sim  # on sys.path: tests/hdl/conftest.py


class _Bench(wiring.Component):
    """One output per input strobe: the current chip, then a step (restart every 1023)."""

    i: In(stream.Signature(unsigned(1), always_ready=True))
    prn: In(unsigned(6))
    o: Out(stream.Signature(unsigned(1), always_ready=True))

    def __init__(self, restart: bool = True):
        self.with_restart = restart
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        m.submodules.gen = gen = CaCodeGenerator(restart=self.with_restart)
        k = Signal(range(CODE_LENGTH))
        last = k == CODE_LENGTH - 1
        m.d.comb += [gen.prn.eq(self.prn), gen.step.eq(self.i.valid)]
        if self.with_restart:
            m.d.comb += gen.restart.eq(self.i.valid & last)
        with m.If(self.i.valid):
            m.d.sync += k.eq(Mux(last, 0, k + 1))
        m.d.sync += [self.o.valid.eq(self.i.valid), self.o.payload.eq(gen.chip)]
        return m



def _expected(prn, n):
    code = ca_code_table()[prn if 1 <= prn <= 32 else 0]
    return code[np.arange(n) % CODE_LENGTH].astype(np.int64)


def test_generator_pysim_prn_7_two_periods_and_first_chips():
    n = 2 * CODE_LENGTH + 5
    r = check_stream(_Bench(), _expected(7, n), np.zeros(n, np.int64), inputs={"prn": 7},
                     backends=("pysim",))
    first = int("".join(str(int(b)) for b in r.words[:10]), 2)
    assert first == FIRST_10_CHIPS_OCTAL[7]


def test_without_restart_the_registers_repeat_the_code():
    """G1 and G2 have period 1023: stepped on without the restart (as the correlator does,
    hdl.gnss.channel) the generator gives the same chips, period after period."""
    n = 2 * CODE_LENGTH + 5
    check_stream(_Bench(restart=False), _expected(19, n), np.zeros(n, np.int64),
                 inputs={"prn": 19}, backends=("pysim",))


@needs_verilator
def test_generator_verilator_all_prns():
    """One Verilator build, every PRN register value 1-32 plus two invalid ones (G1 only)."""
    sim = verilator_sim(_Bench(), "ca_code_bench")
    n = CODE_LENGTH + 11
    for prn in list(range(1, 33)) + [0, 40]:
        r = sim.run(np.zeros(n, np.int64), inputs={"prn": prn}, n_cycles=n + 2)
        np.testing.assert_array_equal(r.words, _expected(prn, n), err_msg=f"PRN {prn}")
        np.testing.assert_array_equal(r.cycles, np.arange(1, n + 1))
        if 1 <= prn <= 32:
            np.testing.assert_array_equal(r.words[:CODE_LENGTH], ca_code(prn))
