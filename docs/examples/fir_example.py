"""A user's own block checked with cosim.testing: a small direct-form FIR against
scipy.signal.lfilter, on the Amaranth simulator and on Verilator, with back-pressure.

Run it as a test: ``python -m pytest docs/examples/fir_example.py`` (the project's suite runs
it too, from ``tests/cosim/test_testing.py``, so this example cannot rot).
"""
import numpy as np
from amaranth.hdl import Module, Signal, signed
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out
from scipy.signal import lfilter

from cosim.testing import check_stream


class Fir(wiring.Component):
    """y[n] = sum_k taps[k] x[n-k], full precision, one output per input.

    Ports: ``i`` in, ``signed(in_width)`` samples; ``o`` out, ``signed(out_width)``,
    registered (1 cycle after the input is taken), with back-pressure (``o.ready``).
    """

    def __init__(self, taps, in_width=12):
        self.taps = [int(t) for t in taps]
        self.in_width = in_width
        bound = sum(abs(t) for t in self.taps) << (in_width - 1)
        self.out_width = bound.bit_length() + 1
        super().__init__({"i": In(stream.Signature(signed(in_width))),
                          "o": Out(stream.Signature(signed(self.out_width)))})

    def elaborate(self, platform):
        m = Module()
        x = [self.i.payload] + [Signal(signed(self.in_width), name=f"x{k}")
                                for k in range(1, len(self.taps))]
        m.d.comb += self.i.ready.eq(~self.o.valid | self.o.ready)
        with m.If(self.i.valid & self.i.ready):
            m.d.sync += [x[k].eq(x[k - 1]) for k in range(1, len(x))]
            m.d.sync += [self.o.payload.eq(sum(t * v for t, v in zip(self.taps, x))),
                         self.o.valid.eq(1)]
        with m.Elif(self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        return m


def fir_model(taps, x):
    """The numpy model: exact in float64 while |y| < 2**53."""
    return np.round(lfilter(taps, [1.0], x)).astype(np.int64)


TAPS = [3, -10, 40, 100, 40, -10, 3]


def test_fir_against_lfilter():
    rng = np.random.default_rng(1)
    x = rng.integers(-2048, 2048, 1000)
    valid = rng.random(1500) < 0.8          # gaps in the input
    ready = rng.random(1500) < 0.6          # the consumer stalls
    check_stream(Fir(TAPS), lambda s: fir_model(TAPS, s), x, valid=valid, ready=ready)
