"""The Verilator backend gives the same bits and cycles as cosim.backends.pysim.run_stream.

The demo components here are small on purpose: they exercise the runner (valid gaps,
back-pressure, control ports, register writes, signed and 64-bit payloads), not any block.
"""
import os
import shutil

import numpy as np
import pytest
from amaranth.hdl import Cat, Module, Signal, signed, unsigned
from amaranth.lib import data, fifo, stream, wiring
from amaranth.lib.wiring import In, Out

import cosim.backends.verilator as vl
from cosim.backends.pysim import run_stream
from cosim.backends.verilator import VerilatorStreamSim
from cosim.backends.verilator_harness import verilator_available

needs_verilator = pytest.mark.skipif(not verilator_available(),
                                     reason="Verilator (and make, g++) not found on PATH")
pytestmark = pytest.mark.verilator  # needs_verilator on each test but the missing-tool one


def iq(width):
    return data.StructLayout({"i": signed(width), "q": signed(width)})


class AccDemo(wiring.Component):
    """Valid-only I/Q accumulator; ``shift`` and ``clear`` are control (register) inputs.

    ``o`` carries the running sums one cycle after each input (latency 1); ``clear`` zeroes
    the sums while high.
    """

    def __init__(self, width=8, acc_width=14):
        self._acc_width = acc_width
        super().__init__({
            "i": In(stream.Signature(iq(width), always_ready=True)),
            "o": Out(stream.Signature(iq(acc_width), always_ready=True)),
            "shift": In(unsigned(3)),
            "clear": In(1),
        })

    def elaborate(self, platform):
        m = Module()
        acc_i = Signal(signed(self._acc_width))
        acc_q = Signal(signed(self._acc_width))
        with m.If(self.clear):
            m.d.sync += [acc_i.eq(0), acc_q.eq(0)]
        with m.Elif(self.i.valid):
            m.d.sync += [acc_i.eq(acc_i + (self.i.payload.i << self.shift)),
                         acc_q.eq(acc_q - self.i.payload.q)]
        m.d.comb += [self.o.payload.i.eq(acc_i), self.o.payload.q.eq(acc_q)]
        m.d.sync += self.o.valid.eq(self.i.valid & ~self.clear)
        return m


class FifoDemo(wiring.Component):
    """Ready/valid on both sides with a small FIFO inside (back-pressure reaches ``i.ready``);
    ``level`` is an output port (for probes)."""

    def __init__(self, depth=4, xor=0x5A5A):
        self._depth, self._xor = depth, xor
        super().__init__({
            "i": In(stream.Signature(unsigned(16))),
            "o": Out(stream.Signature(unsigned(16))),
            "level": Out(range(depth + 1)),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.fifo = f = fifo.SyncFIFOBuffered(width=16, depth=self._depth)
        m.d.comb += [
            f.w_data.eq((self.i.payload ^ self._xor) + 1),
            f.w_en.eq(self.i.valid),
            self.i.ready.eq(f.w_rdy),
            self.o.payload.eq(f.r_data),
            self.o.valid.eq(f.r_rdy),
            f.r_en.eq(self.o.ready),
            self.level.eq(f.level),
        ]
        return m


class DropFifoDemo(wiring.Component):
    """Always-ready signed input into a FIFO with a real-ready output; words that find the
    FIFO full are dropped and counted in ``dropped``."""

    def __init__(self, depth=8):
        self._depth = depth
        super().__init__({
            "i": In(stream.Signature(signed(12), always_ready=True)),
            "o": Out(stream.Signature(signed(12))),
            "dropped": Out(unsigned(16)),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.fifo = f = fifo.SyncFIFO(width=12, depth=self._depth)
        m.d.comb += [f.w_data.eq(self.i.payload), f.w_en.eq(self.i.valid),
                     self.o.payload.eq(f.r_data), self.o.valid.eq(f.r_rdy),
                     f.r_en.eq(self.o.ready)]
        with m.If(self.i.valid & ~f.w_rdy):
            m.d.sync += self.dropped.eq(self.dropped + 1)
        return m


class Wide64Demo(wiring.Component):
    """Signed 64-bit output payload: {input word, count of inputs} (exercises the object-dtype
    path of 64-bit words and sign extension at bit 63)."""

    i: In(stream.Signature(unsigned(32), always_ready=True))
    o: Out(stream.Signature(signed(64), always_ready=True))

    def elaborate(self, platform):
        m = Module()
        count = Signal(32)
        with m.If(self.i.valid):
            m.d.sync += [count.eq(count + 1), self.o.payload.eq(Cat(count, self.i.payload))]
        m.d.sync += self.o.valid.eq(self.i.valid)
        return m


class StrobeDemo(wiring.Component):
    """Zero-width input payload (a bare strobe stream, as the NCO's): each strobe emits the
    strobe count plus ``offset``; the payload is not a Verilog port at all."""

    i: In(stream.Signature(unsigned(0), always_ready=True))
    o: Out(stream.Signature(unsigned(16), always_ready=True))
    offset: In(unsigned(8))

    def elaborate(self, platform):
        m = Module()
        count = Signal(16)
        with m.If(self.i.valid):
            m.d.sync += [count.eq(count + 1), self.o.payload.eq(count + self.offset)]
        m.d.sync += self.o.valid.eq(self.i.valid)
        return m


def assert_same(got, want):
    assert got.n_cycles == want.n_cycles
    assert got.in_accepted == want.in_accepted
    np.testing.assert_array_equal(got.cycles, want.cycles)
    assert got.words.dtype == want.words.dtype
    np.testing.assert_array_equal(got.words, want.words)
    assert set(got.probes) == set(want.probes)
    for k in want.probes:
        np.testing.assert_array_equal(got.probes[k], want.probes[k])


def random_pattern(rng, n, p):
    return rng.random(n) < p


@pytest.fixture(scope="module")
def acc():
    dut = AccDemo()
    return dut, VerilatorStreamSim(dut, "acc_demo")


@pytest.fixture(scope="module")
def fifo_demo():
    dut = FifoDemo()
    return dut, VerilatorStreamSim(dut, "fifo_demo")


@pytest.fixture(scope="module")
def drop_fifo():
    dut = DropFifoDemo()
    return dut, VerilatorStreamSim(dut, "drop_fifo_demo")


@pytest.mark.parametrize("seed", [1, 2])
@needs_verilator
def test_acc_matches_pysim_with_gaps_inputs_and_writes(acc, seed):
    dut, sim = acc
    rng = np.random.default_rng(seed)
    n = 3000
    words = rng.integers(-(1 << 20), 1 << 20, n)  # wider than 16 bits: both backends mask
    in_valid = random_pattern(rng, 4000, 0.6)     # shorter than the run: then every cycle
    writes = [(int(c), port, int(v)) for c, port, v in [
        (rng.integers(0, 500), dut.shift, rng.integers(0, 8)),
        (1200, "clear", 1), (1203, dut.clear, 0),
        (rng.integers(1500, 4000), "shift", rng.integers(0, 8)),
        (5000, "shift", 7),  # after the end: never applied
    ]]
    kw = dict(in_valid=in_valid, inputs=[(dut.shift, 2)], writes=writes)
    want = run_stream(dut, words, **kw)
    got = sim.run(words, **kw)
    assert_same(got, want)
    assert got.in_accepted == n and len(got.words) > n // 2


@needs_verilator
def test_acc_inputs_by_name_and_n_cycles(acc):
    dut, sim = acc
    rng = np.random.default_rng(3)
    words = rng.integers(0, 1 << 16, 2000)
    kw = dict(in_valid=random_pattern(rng, 2000, 0.3), n_cycles=1500, inputs={"shift": 3})
    want = run_stream(dut, words, **kw)
    got = sim.run(words, **kw)
    assert_same(got, want)
    assert got.n_cycles == 1500 and got.in_accepted < 2000


@needs_verilator
def test_no_input_runs_flush_cycles(acc):
    dut, sim = acc
    got = sim.run(flush_cycles=10)
    want = run_stream(dut, flush_cycles=10)
    assert_same(got, want)
    assert got.n_cycles == 10 and len(got.words) == 0


@pytest.mark.parametrize("seed", [4, 5])
@needs_verilator
def test_fifo_backpressure_matches_pysim(fifo_demo, seed):
    dut, sim = fifo_demo
    rng = np.random.default_rng(seed)
    words = rng.integers(0, 1 << 16, 2000)
    kw = dict(in_valid=random_pattern(rng, 5000, 0.7), out_ready=random_pattern(rng, 3000, 0.4),
              probe={"level": dut.level})
    want = run_stream(dut, words, **kw)
    got = sim.run(words, **kw)
    assert_same(got, want)
    # The FIFO did fill up: input was refused on some cycles.
    assert got.n_cycles > 2000 + 64 and want.probes["level"].max() == 4
    assert np.array_equal(got.words, (words ^ 0x5A5A) + 1 & 0xFFFF)


@needs_verilator
def test_drop_fifo_signed_payload_and_probe_by_name(drop_fifo):
    dut, sim = drop_fifo
    rng = np.random.default_rng(6)
    words = rng.integers(-2048, 2048, 3000)
    kw = dict(in_valid=random_pattern(rng, 3000, 0.5), out_ready=random_pattern(rng, 3000, 0.45))
    want = run_stream(dut, words, probe={"dropped": dut.dropped}, **kw)
    got = sim.run(words, probe={"dropped": "dropped"}, **kw)
    assert_same(got, want)
    assert got.words.min() < 0
    dropped = int(got.probes["dropped"][-1])
    assert dropped > 0 and len(got.words) + dropped == 3000


@needs_verilator
def test_wide_64bit_signed_payload():
    dut = Wide64Demo()
    sim = VerilatorStreamSim(dut, "wide64_demo")
    rng = np.random.default_rng(7)
    words = rng.integers(0, 1 << 32, 500, dtype=np.uint64)
    kw = dict(in_valid=random_pattern(rng, 800, 0.5))
    want = run_stream(dut, words, **kw)
    got = sim.run(words, **kw)
    assert_same(got, want)
    assert got.words.dtype == object and min(got.words) < 0


@needs_verilator
def test_zero_width_input_payload():
    dut = StrobeDemo()
    sim = VerilatorStreamSim(dut, "strobe_demo")
    assert "i__payload" not in [p.name for p in sim.ports]
    rng = np.random.default_rng(8)
    kw = dict(in_valid=random_pattern(rng, 900, 0.4), writes=[(300, "offset", 77)])
    want = run_stream(dut, np.zeros(500, dtype=np.int64), **kw)
    got = sim.run(np.zeros(500, dtype=np.int64), **kw)
    assert_same(got, want)
    assert got.in_accepted == 500 and len(got.words) == 500


@needs_verilator
def test_chunked_runs_give_the_same_result(acc, drop_fifo, monkeypatch):
    """Tiny output buffers and chunks force every pause/resume path of the C loop."""
    dut, sim = drop_fifo
    rng = np.random.default_rng(8)
    words = rng.integers(-2048, 2048, 4000)
    kw = dict(in_valid=random_pattern(rng, 6000, 0.5), out_ready=random_pattern(rng, 6000, 0.6),
              probe={"dropped": "dropped"})
    whole = sim.run(words, **kw)
    monkeypatch.setattr(vl, "_OUT_CHUNK", 7)
    monkeypatch.setattr(vl, "_CHUNK_CYCLES", 333)
    monkeypatch.setattr(vl, "_PROBE_CHUNK", 101)
    assert_same(sim.run(words, **kw), whole)
    adut, asim = acc
    awords = rng.integers(0, 1 << 16, 3000)
    writes = [(int(c), "shift", int(s)) for c, s in zip(rng.integers(0, 3000, 40), rng.integers(0, 8, 40))]
    akw = dict(in_valid=random_pattern(rng, 5000, 0.5), writes=writes)
    assert_same(asim.run(awords, **akw), run_stream(adut, awords, **akw))


@needs_verilator
def test_long_run_against_itself(acc):
    """1e6 cycles with gaps: fast enough to be a unit test, and rerunning gives the same bits
    (each run starts from reset)."""
    dut, sim = acc
    rng = np.random.default_rng(9)
    words = rng.integers(0, 1 << 16, 1_000_000)
    valid = random_pattern(rng, 1_500_000, 0.7)
    a = sim.run(words, in_valid=valid)
    b = sim.run(words, in_valid=valid)
    assert_same(a, b)
    assert a.in_accepted == 1_000_000


@needs_verilator
def test_port_errors(acc):
    dut, sim = acc
    with pytest.raises(KeyError, match="no port named 'nope'"):
        sim.run(np.zeros(3, np.int64), inputs={"nope": 1})
    with pytest.raises(KeyError, match="is not a port of the component"):
        sim.run(np.zeros(3, np.int64), inputs=[(Signal(3), 1)])
    with pytest.raises(ValueError, match="driven by the stream runner"):
        sim.run(np.zeros(3, np.int64), writes=[(3, "i__valid", 1)])


def _seed_runtime(build_dir):
    # Reuse the Verilator runtime objects of the default cache so that this test builds
    # only the design (a few seconds) rather than the runtime too.
    default_runtime = vl.REPO_ROOT / "build" / "verilator" / "_runtime"
    if default_runtime.is_dir():
        shutil.copytree(default_runtime, build_dir / "_runtime")


@needs_verilator
def test_build_is_cached_and_rebuilt_on_change(tmp_path):
    _seed_runtime(tmp_path)
    first = VerilatorStreamSim(FifoDemo(depth=4, xor=0x1234), "cache_demo", build_dir=tmp_path)
    assert first.built
    again = VerilatorStreamSim(FifoDemo(depth=4, xor=0x1234), "cache_demo", build_dir=tmp_path)
    assert not again.built and again.lib_path == first.lib_path
    other = VerilatorStreamSim(FifoDemo(depth=4, xor=0x4321), "cache_demo", build_dir=tmp_path)
    assert other.built and other.lib_path != first.lib_path
    words = np.arange(100)
    np.testing.assert_array_equal(other.run(words).words, (words ^ 0x4321) + 1)


@needs_verilator
def test_concurrent_builds_of_one_design_compile_once(tmp_path):
    """Two builders of the same design into one cache (pytest-xdist workers do this): the
    build lock lets one compile and the other load its library."""
    from concurrent.futures import ThreadPoolExecutor
    _seed_runtime(tmp_path)
    with ThreadPoolExecutor(2) as ex:
        sims = list(ex.map(lambda _: VerilatorStreamSim(FifoDemo(depth=4, xor=0x5a5a), "lock_demo",
                                                        build_dir=tmp_path), range(2)))
    assert sorted(s.built for s in sims) == [False, True]
    assert sims[0].lib_path == sims[1].lib_path
    words = np.arange(50)
    for s in sims:
        np.testing.assert_array_equal(s.run(words).words, (words ^ 0x5a5a) + 1)


def test_missing_verilator_message(monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(RuntimeError, match=r"Verilator not found on PATH: install it with "
                                           r"`make setup` \(apt-get install verilator\) or use "
                                           r"the pysim/model backends"):
        VerilatorStreamSim(AccDemo(), "missing_demo")


@pytest.mark.parametrize("suffix", [".vcd", pytest.param(".fst", marks=pytest.mark.slow)])
@needs_verilator
def test_trace_window(acc, tmp_path, suffix):
    dut, sim = acc
    path = tmp_path / f"acc{suffix}"
    words = np.arange(200)
    traced = sim.run(words, trace=path, trace_window=(50, 60))
    assert_same(traced, sim.run(words))
    assert path.stat().st_size > 0
    if suffix == ".vcd":
        times = [int(line[1:]) for line in path.read_text().splitlines() if line.startswith("#")]
        assert times[0] == 100 and times[-1] == 119 and len(times) == 20


@needs_verilator
def test_long_run(acc):
    """A 2M-cycle run (many C++ batches) completes with every cycle accounted for; the
    speed figures are in ``cosim bench sim-speed``, not asserted here."""
    dut, sim = acc
    n = 2_000_000
    res = sim.run(n_cycles=n, inputs={"shift": 1})
    assert res.n_cycles == n
