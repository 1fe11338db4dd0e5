import numpy as np, time
from cosim.pysim import run_stream
from cosim.verilator import VerilatorStreamSim
from hdl.fifo import DspFifo
from hdl.model.fifo import FifoParams, fifo_model, pack_records
from amaranth.hdl import Module, unsigned
from amaranth.lib import wiring, stream
from amaranth.lib.wiring import In, Out
rng = np.random.default_rng(1)
p = FifoParams(width=24, depth=8, record_words=6)
n=6000
iv = rng.random(n) < 0.2
rdy = np.repeat(rng.random(n//20+1) < 0.5, 20)[:n] & (rng.random(n) < 0.8)
recs = rng.integers(0, 1<<p.width, (int(iv.sum()), p.record_words))
t=time.time()
sim = VerilatorStreamSim(DspFifo(p), "fifo_rec6")
print("build", time.time()-t)
res = sim.run(pack_records(recs, p), in_valid=iv, out_ready=rdy, n_cycles=n, final={"ovf": "overflow_count"})
ref = fifo_model(recs, iv, rdy, p)
np.testing.assert_array_equal(res.words, ref.words); np.testing.assert_array_equal(res.cycles, ref.cycles)
print(res.final, ref.state.overflow)
# wide out: a passthrough register of 150 bits, signed
class Wide(wiring.Component):
    def __init__(self, w):
        super().__init__({"i": In(stream.Signature(unsigned(w))), "o": Out(stream.Signature(unsigned(w)))})
    def elaborate(self, platform):
        m = Module()
        with m.If(self.o.ready | ~self.o.valid):
            m.d.sync += [self.o.valid.eq(self.i.valid), self.o.payload.eq(self.i.payload + 1)]
        m.d.comb += self.i.ready.eq(self.o.ready | ~self.o.valid)
        return m
for w in (65, 96, 150):
    x = np.array([int(v) for v in rng.integers(0, 1<<62, 300)], dtype=object) * (1 << (w-62)) + 12345
    x = np.array([int(v) % (1<<w) for v in x], dtype=object)
    rd = rng.random(400) < 0.7
    a = run_stream(Wide(w), x, out_ready=rd)
    b = VerilatorStreamSim(Wide(w), f"wide{w}").run(x, out_ready=rd)
    assert list(a.words) == list(b.words) == [(int(v)+1) % (1<<w) for v in x], w
    np.testing.assert_array_equal(a.cycles, b.cycles)
print("ok")
