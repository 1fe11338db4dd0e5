"""FIFO towards the DSP: sync sim == cycle model; async conservation at two clock rates;
the exported Verilog of the sync FIFO (Verilator) == Amaranth simulation == cycle model;
the compiled cycle model == the pure-Python reference loop (random scenarios, chunks,
periodic ready schedules)."""
from __future__ import annotations

import numpy as np
import pytest
from amaranth.hdl import ClockDomain, Elaboratable, Module, Value
from amaranth.sim import Simulator

from cosim.testing import check_stream
from hdl.fifo import DspFifo
from hdl.model.fifo import (TAG_DATA, TAG_MARKER, FifoParams, FifoState, ReadySchedule,
                            decode_stream, fifo_model,
                            fifo_model_events, pack_word, unpack_word)
from hdl.model.fifo_reference import fifo_model_reference

from _util import assert_lints_clean, needs_verilator


def _bursts(rng, n, burst, p_on, p_fine):
    """Per-cycle pattern: bursts of ``burst`` cycles on with probability ``p_on``, thinned."""
    on = np.repeat(rng.random(n // burst + 1) < p_on, burst)[:n]
    return on & (rng.random(n) < p_fine)


def _stimulus(p, rng, n_cycles, w=(20, 0.5, 0.8), r=(15, 0.6, 0.8)):
    """Bursty writes and bursty reads (back-pressure), random words."""
    in_valid = _bursts(rng, n_cycles, *w)
    out_ready = _bursts(rng, n_cycles, *r)
    words = rng.integers(0, 1 << p.width, int(in_valid.sum()))
    return words, in_valid, out_ready


def _check(p, words, in_valid, out_ready, *, backends=("pysim",), name=None):
    """The model's words, cycles and per-cycle ``overflow_count`` on ``backends``."""
    ref = fifo_model(words, in_valid, out_ready, p)
    check_stream(DspFifo(p), dict(words=ref.words, cycles=ref.cycles,
                                  probes={"ovf": ref.overflow_count}),
                 words, valid=in_valid, ready=out_ready, n_cycles=in_valid.size,
                 probe={"ovf": "overflow_count"}, backends=backends, name=name)
    return ref


def _check_sim(p, rng, n_cycles, *, w=(20, 0.5, 0.8), r=(15, 0.6, 0.8)):
    words, in_valid, out_ready = _stimulus(p, rng, n_cycles, w, r)
    return words, _check(p, words, in_valid, out_ready)


def _check_accounting(words, ref, p):
    """Data words come out in order; markers count exactly the words skipped before them."""
    payload, tag = unpack_word(ref.words, p)
    assert set(np.unique(tag)) <= {TAG_DATA, TAG_MARKER}
    kept = words[~ref.dropped]
    data, _ = decode_stream(ref.words, p)
    np.testing.assert_array_equal(data, kept[:data.size])
    # Walk the output: a marker stands for exactly its count of dropped inputs (a long gap
    # may be reported by several markers); a data word is the next input not dropped.
    k = 0
    for pl, tg in zip(payload.tolist(), tag.tolist()):
        if tg == TAG_MARKER:
            assert pl > 0 and ref.dropped[k:k + pl].all() and k + pl <= words.size
            k += pl
        else:
            assert not ref.dropped[k] and words[k] == pl
            k += 1


# -- synchronous: simulation == model ------------------------------------------------------
def test_sim_matches_model_quick():
    p = FifoParams(width=12, depth=8)
    rng = np.random.default_rng(301)
    words, ref = _check_sim(p, rng, 20_000)
    assert ref.dropped.sum() > 100 and ref.words.size > 1000
    _check_accounting(words, ref, p)


@pytest.mark.slow
def test_sim_matches_model_1e5():
    p = FifoParams(width=51, depth=16)
    rng = np.random.default_rng(302)
    words, ref = _check_sim(p, rng, 100_000)
    assert ref.dropped.sum() > 1000
    _check_accounting(words, ref, p)


@pytest.mark.parametrize("depth", [1, 2, 3])
def test_small_depths(depth):
    p = FifoParams(width=8, depth=depth)
    rng = np.random.default_rng(303 + depth)
    words, ref = _check_sim(p, rng, 6000, w=(10, 0.5, 0.6), r=(7, 0.7, 0.7))
    assert ref.dropped.sum() > 50
    _check_accounting(words, ref, p)


def test_back_to_back_writes_and_no_overflow():
    """Continuous input, always-ready reader: nothing dropped, 2-cycle latency, no markers."""
    p = FifoParams(width=10, depth=4)
    rng = np.random.default_rng(306)
    n = 2000
    words = rng.integers(0, 1 << p.width, n)
    in_valid = np.ones(n + 10, bool)
    ready = np.ones(n + 10, bool)
    ref = _check(p, words, in_valid, ready)
    np.testing.assert_array_equal(ref.words, words)
    np.testing.assert_array_equal(ref.cycles, np.arange(n) + 2)


def test_marker_words_directed():
    p = FifoParams(width=8, depth=4)
    n = 60
    in_valid = np.zeros(n, bool)
    in_valid[0:10] = True      # 4 fit (3 in the memory + the output register), 6 dropped
    in_valid[30:33] = True     # after the reader drained: marker first, then these
    ready = np.zeros(n, bool)
    ready[20:] = True
    words = np.arange(100, 113)
    expected = pack_word([100, 101, 102, 103, 6, 110, 111, 112],
                         [0, 0, 0, 0, TAG_MARKER, 0, 0, 0], p)
    ref = _check(p, words, in_valid, ready)
    np.testing.assert_array_equal(ref.words, expected)
    assert ref.overflow_count[-1] == 6
    # The marker cycle had an input word too: it went through the hold register.
    assert ref.dropped.tolist() == [False] * 4 + [True] * 6 + [False] * 3


def test_counter_and_marker_saturate():
    p = FifoParams(width=2, depth=2, count_width=3)
    rng = np.random.default_rng(307)
    words, ref = _check_sim(p, rng, 5000, w=(50, 0.7, 0.9), r=(50, 0.3, 0.3))
    assert ref.overflow_count.max() == p.count_max == 7
    payload, tag = unpack_word(ref.words, p)
    assert (payload[tag == TAG_MARKER] == p.marker_max).any()


def test_model_validates_inputs():
    p = FifoParams(width=8, depth=4)
    with pytest.raises(ValueError, match=r"out_ready must have one entry per cycle \(5\)"):
        fifo_model([1], np.ones(5, bool), np.ones(4, bool), p)
    with pytest.raises(ValueError, match="synchronous FIFO only"):
        fifo_model([1], [1], [1], FifoParams(depth=4, asynchronous=True))


# -- compiled model == pure-Python reference ----------------------------------------------
def _assert_same(got, want, msg=""):
    for name in ("words", "cycles", "dropped"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name),
                                      err_msg=f"{name} {msg}")
    if want.overflow_count is not None and got.overflow_count is not None:
        np.testing.assert_array_equal(got.overflow_count, want.overflow_count,
                                      err_msg=f"overflow_count {msg}")


def _random_pattern(rng, n):
    """One of: uniform random, bursty, periodic, all/none, with random densities."""
    kind = rng.integers(5)
    if kind == 0:
        return rng.random(n) < rng.random()
    if kind == 1:
        return _bursts(rng, n, int(rng.integers(1, 80)), rng.random(), rng.random())
    if kind == 2:
        sch = ReadySchedule(period=int(rng.integers(1, 200)), offset=int(rng.integers(0, 300)))
        return sch.mask(n)
    if kind == 3:
        return np.ones(n, bool)
    return np.zeros(n, bool) if rng.random() < 0.5 else rng.random(n) < 0.02


def _random_scenario(rng):
    depth = int(rng.choice([1, 2, 3, 4, 5, 6, 7, 8, 9, 16, 33, 512]))
    p = FifoParams(width=int(rng.integers(1, 13)), depth=depth,
                   count_width=int(rng.integers(1, 7)))
    n = int(rng.integers(1, 4000))
    in_valid = _random_pattern(rng, n)
    # Words wider than the payload (masked), and sometimes fewer/more words than valid cycles.
    words = rng.integers(0, 1 << 14, max(0, int(in_valid.sum()) + int(rng.integers(-3, 4))))
    return p, words, in_valid, _random_pattern(rng, n)


def test_fast_model_matches_reference_random():
    """Many random scenarios (depth, widths, densities, bursts, saturation) and seeds."""
    n_drop = n_sat = 0
    for seed in range(400):
        rng = np.random.default_rng(10_000 + seed)
        p, words, in_valid, out_ready = _random_scenario(rng)
        want = fifo_model_reference(words, in_valid, out_ready, p)
        got = fifo_model(words, in_valid, out_ready, p)
        _assert_same(got, want, f"(seed {10_000 + seed}, {p})")
        n_drop += bool(want.dropped.any())
        n_sat += bool(want.overflow_count.size and want.overflow_count[-1] == p.count_max)
    # The scenarios reach the interesting corners.
    assert n_drop > 100 and n_sat > 30


@pytest.mark.parametrize("depth", [1, 2, 4, 64])
def test_fast_model_matches_reference_schedule(depth):
    """A periodic ReadySchedule gives the same bits as its per-cycle mask."""
    p = FifoParams(width=6, depth=depth, count_width=4)
    for seed in range(40):
        rng = np.random.default_rng(20_000 + 100 * depth + seed)
        n = int(rng.integers(1000, 6000))
        count = int(rng.integers(1, 20))
        stride = int(rng.integers(1, 6))
        period = int(rng.integers((count - 1) * stride + 1, 600))
        sch = ReadySchedule(period=period, offset=int(rng.integers(0, 700)), count=count,
                            stride=stride)
        in_valid = _random_pattern(rng, n)
        words = rng.integers(0, 1 << p.width, int(in_valid.sum()))
        want = fifo_model_reference(words, in_valid, sch.mask(n), p)
        _assert_same(fifo_model(words, in_valid, sch, p), want, f"(seed {seed}, {sch})")
        ev = fifo_model_events(np.flatnonzero(in_valid), words, n, sch, p, trace=True)
        _assert_same(ev, want, f"events (seed {seed}, {sch})")


def test_chunks_equal_one_run():
    """Splitting a run at random cycles (state carried) gives the same bits."""
    for seed in range(60):
        rng = np.random.default_rng(30_000 + seed)
        p, words, in_valid, out_ready = _random_scenario(rng)
        words = words[:int(in_valid.sum())]
        want = fifo_model(words, in_valid, out_ready, p)
        n = in_valid.size
        cuts = np.unique(np.concatenate([[0, n], rng.integers(0, n, int(rng.integers(1, 6)))]))
        st, k = None, 0
        parts = []
        for a, b in zip(cuts[:-1], cuts[1:]):
            nw = int(in_valid[a:b].sum())
            r = fifo_model(words[k:k + nw], in_valid[a:b], out_ready[a:b], p, state=st)
            k += nw
            st = r.state
            parts.append(r)
        for name in ("words", "cycles", "overflow_count", "dropped"):
            np.testing.assert_array_equal(np.concatenate([getattr(r, name) for r in parts]),
                                          getattr(want, name), err_msg=f"{name} seed {seed}")
        assert st.cycle == n and st.max_level == want.max_level
        assert st.overflow == want.state.overflow and st.pending == want.state.pending


def test_state_and_level():
    """Directed: no reads, depth 4: 4 words queued (3 in memory + output register)."""
    p = FifoParams(width=8, depth=4)
    n = 12
    res = fifo_model(np.arange(10), np.r_[np.ones(10, bool), np.zeros(2, bool)],
                     np.zeros(n, bool), p)
    st = res.state
    assert st.cycle == n and st.out_full and st.out_reg == 0 and st.level == 4
    np.testing.assert_array_equal(st.queue, [1, 2, 3])
    assert st.pending == 6 and st.overflow == 6 and not st.hold_valid
    assert res.max_level == 4 and res.words.size == 0
    # Next chunk: read everything; the marker comes after the 4 queued words.
    res2 = fifo_model([], np.zeros(10, bool), np.ones(10, bool), p, state=st)
    np.testing.assert_array_equal(res2.words, pack_word([0, 1, 2, 3, 6], [0, 0, 0, 0, 2], p))
    assert res2.cycles[0] == n and res2.state.level == 0


def test_ready_schedule():
    sch = ReadySchedule(period=100, offset=10, count=3, stride=2)
    np.testing.assert_array_equal(np.flatnonzero(sch.mask(250)),
                                  [10, 12, 14, 110, 112, 114, 210, 212, 214])
    np.testing.assert_array_equal(np.flatnonzero(sch.mask(50, start=105)) + 105,
                                  [110, 112, 114])
    np.testing.assert_array_equal(sch.ready_cycles(11, 213), [12, 14, 110, 112, 114, 210, 212])
    assert ReadySchedule(period=1).mask(5).all() and sch.span == 5 and sch.duty == 0.03
    with pytest.raises(ValueError, match=r"ReadySchedule window \(\(count - 1\) \* stride "
                                         r"\+ 1 = 7 cycles\) must fit in the period \(6\)"):
        ReadySchedule(period=6, count=4, stride=2)
    with pytest.raises(ValueError, match=r"ReadySchedule period must be an integer >= 1, not 0"):
        ReadySchedule(period=0)
    with pytest.raises(ValueError, match=r"ReadySchedule offset must be an integer >= 0, not -1"):
        ReadySchedule(period=5, offset=-1)


def test_events_validate_inputs():
    p = FifoParams(width=8, depth=4)
    sch = ReadySchedule(period=1)
    with pytest.raises(ValueError, match="strictly increasing"):
        fifo_model_events([3, 3], [1, 2], 10, sch, p)
    with pytest.raises(ValueError, match=r"write_cycles must lie in \[0, 10\), not \[3, 10\]"):
        fifo_model_events([3, 10], [1, 2], 10, sch, p)
    with pytest.raises(ValueError, match=r"in_words must have one entry per write cycle \(2\)"):
        fifo_model_events([3, 4], [1], 10, sch, p)
    with pytest.raises(ValueError, match="write_cycles must be integers"):
        fifo_model_events([3.0], [1], 10, sch, p)
    with pytest.raises(ValueError, match=r"out_ready must have one entry per cycle \(10\)"):
        fifo_model_events([3], [1], 10, np.ones(9, bool), p)
    with pytest.raises(ValueError, match="state queue holds 4 words; depth 4 holds at most 3"):
        fifo_model([], [0], [1], p, state=FifoState(queue=np.arange(4)))


@pytest.mark.slow
def test_fast_model_long_tacan_like():
    """20M cycles (1 s at 20 MHz), ~15k peak words, DSP reading 256 words every 1 ms:
    compiled model == reference on the first 2M cycles (speed: ``cosim bench sim-speed``)."""
    rng = np.random.default_rng(311)
    n = 20_000_000
    first = np.sort(rng.choice(n - 300, 7500, replace=False))
    wc = np.unique(np.concatenate([first, first + 240]))
    words = rng.integers(0, 1 << 51, wc.size)
    p = FifoParams()
    sch = ReadySchedule(period=20_000, offset=200, count=256, stride=4)
    res = fifo_model_events(wc, words, n, sch, p)
    assert not res.dropped.any() and res.words.size > 14_000
    m = 2_000_000
    k = int(np.searchsorted(wc, m))
    iv = np.zeros(m, bool)
    iv[wc[:k]] = True
    want = fifo_model_reference(words[:k], iv, sch.mask(m), p)
    got = fifo_model_events(wc[:k], words[:k], m, sch, p, trace=True)
    _assert_same(got, want)
    np.testing.assert_array_equal(res.words[:want.words.size], want.words)


# -- asynchronous: two clocks --------------------------------------------------------------
class _TwoClocks(Elaboratable):
    def __init__(self, dut):
        self.dut = dut

    def elaborate(self, platform):
        m = Module()
        m.domains.dsp = ClockDomain("dsp")
        m.submodules.dut = self.dut
        return m


def _run_async(p, words, in_valid, out_ready, w_hz, r_hz, r_cycles):
    """Two-clock testbench (``cosim.backends.pysim.run_stream`` drives one clock only)."""
    dut = DspFifo(p)
    out, ovf_trace = [], []
    sim = Simulator(_TwoClocks(dut))
    sim.add_clock(1 / w_hz, domain="sync")
    sim.add_clock(1 / r_hz, domain="dsp")

    async def writer(ctx):
        k = 0
        for v in in_valid:
            offer = bool(v) and k < len(words)
            ctx.set(dut.i.valid, offer)
            if offer:
                ctx.set(dut.i.payload, int(words[k]))
                k += 1
            await ctx.tick("sync")
        ctx.set(dut.i.valid, 0)

    async def reader(ctx):
        for c in range(r_cycles):
            rdy = True if c >= len(out_ready) else bool(out_ready[c])
            ctx.set(dut.o.ready, rdy)
            _, _, valid, payload, cnt = await ctx.tick("dsp").sample(
                dut.o.valid, Value.cast(dut.o.payload), dut.overflow_count)
            if valid and rdy:
                out.append(int(payload))
            ovf_trace.append(int(cnt))

    sim.add_testbench(writer)
    sim.add_testbench(reader)
    sim.run()
    return np.array(out, dtype=np.int64), np.array(ovf_trace, dtype=np.int64)


@pytest.mark.parametrize("w_hz, r_hz", [(100e6, 37e6), (20e6, 73e6)])
def test_async_two_clock_rates(w_hz, r_hz):
    p = FifoParams(width=20, depth=5, asynchronous=True)
    assert p.actual_depth == 5
    rng = np.random.default_rng(308)
    n_w = 4000
    in_valid = _bursts(rng, n_w, 30, 0.5, 0.7)
    words = np.arange(int(in_valid.sum()))
    r_cycles = int(n_w * r_hz / w_hz) + 200  # the reader drains everything at the end
    out_ready = _bursts(rng, r_cycles - 150, 20, 0.5, 0.6)
    out, ovf = _run_async(p, words, in_valid, out_ready, w_hz, r_hz, r_cycles)
    payload, tag = unpack_word(out, p)
    data = payload[tag == TAG_DATA]
    lost = payload[tag == TAG_MARKER]
    assert lost.size > 0 and data.size > 100
    # In order, nothing lost silently: every gap in the data is announced by markers.
    assert np.all(np.diff(data) > 0)
    expect_prev = 0
    k = 0
    for pl, tg in zip(payload.tolist(), tag.tolist()):
        if tg == TAG_MARKER:
            k += pl
        else:
            assert pl == expect_prev + k, "gap not announced by a marker"
            expect_prev, k = pl + 1, 0
    assert data.size + lost.sum() == words.size
    # The count crosses into the read domain monotonically and ends at the total.
    assert np.all(np.diff(ovf) >= 0)
    assert ovf[-1] == lost.sum()


def test_parity_sim_matches_model():
    """With ``parity`` the HDL stores an even-parity bit above the tag: same words as the
    model, every output word has even parity, and the rest of the word is unchanged."""
    p = FifoParams(width=12, depth=8, parity=True)
    rng = np.random.default_rng(301)
    words, ref = _check_sim(p, rng, 20_000)
    assert ref.dropped.sum() > 100 and ref.words.size > 1000
    _check_accounting(words, ref, p)
    pop = np.array([bin(int(w)).count("1") for w in ref.words])
    assert (pop % 2 == 0).all() and (ref.words >> 14).max() == 1 and p.word_width == 15
    plain = fifo_model(*_stimulus(FifoParams(width=12, depth=8), np.random.default_rng(301),
                                  20_000), FifoParams(width=12, depth=8))
    np.testing.assert_array_equal(ref.words & ((1 << 14) - 1), plain.words)
    np.testing.assert_array_equal(ref.cycles, plain.cycles)
    ref2 = fifo_model_reference(*_stimulus(p, np.random.default_rng(301), 20_000), p)
    np.testing.assert_array_equal(ref2.words, ref.words)
    np.testing.assert_array_equal(pack_word(ref.words & 0xFFF, (ref.words >> 12) & 3, p),
                                  ref.words)


# -- parameters and Verilog ----------------------------------------------------------------
@pytest.mark.parametrize("kw, msg", [
    (dict(depth=0), r"FIFO depth must be >= 1, not 0"),
    (dict(depth=2, asynchronous=True), r"asynchronous FIFO depth must be >= 3, not 2"),
    (dict(width=0), r"FIFO width must be an integer in \[1, 61\], not 0"),
    (dict(count_width=0), r"FIFO count_width must be an integer in \[1, 32\], not 0"),
    (dict(asynchronous=True, r_domain="sync"),
     r"asynchronous FIFO needs two different domains, not 'sync' twice"),
    (dict(parity=1), r"FIFO parity must be a bool, not 1"),
    (dict(width=61, parity=True), r"FIFO width must be an integer in \[1, 60\], not 61"),
])
def test_bad_params(kw, msg):
    with pytest.raises(ValueError, match=msg):
        FifoParams(**kw)


def test_actual_depth():
    assert FifoParams(depth=7).actual_depth == 7
    assert FifoParams(depth=3, asynchronous=True).actual_depth == 3
    assert FifoParams(depth=6, asynchronous=True).actual_depth == 9
    assert FifoParams(depth=512, asynchronous=True).actual_depth == 513


@pytest.mark.verilator
@pytest.mark.parametrize("asynchronous, parity", [(False, False), (True, False), (False, True)])
def test_verilog_lints_clean(asynchronous, parity):
    """Waived: cosim.tools.verilog.LINT_WAIVERS (UNUSEDSIGNAL, DECLFILENAME, WIDTH)."""
    p = FifoParams(depth=16, asynchronous=asynchronous, parity=parity)
    name = ("dsp_fifo_async" if asynchronous else "dsp_fifo") + ("_parity" if parity else "")
    # Exported on its own, the asynchronous FIFO gets its read domain as ports (dsp_clk,
    # dsp_rst); inside _TwoClocks that clock would be an undriven constant.
    assert_lints_clean(DspFifo(p), name)


#: Compiled with Verilator: the sync FIFO of the quick sim test.
VL_PARAMS = FifoParams(width=12, depth=8)


@needs_verilator
def test_verilator_matches_pysim():
    """The quick sim test's stimulus (bursty writes, back-pressure), overflow count probed:
    model == pysim == Verilator."""
    words, in_valid, out_ready = _stimulus(VL_PARAMS, np.random.default_rng(309), 6000)
    ref = _check(VL_PARAMS, words, in_valid, out_ready, backends=("pysim", "verilator"),
                 name="dsp_fifo_vl")
    assert ref.overflow_count[-1] > 20 and len(ref.words) > 500


@needs_verilator
def test_verilator_matches_model_long():
    p = VL_PARAMS
    words, in_valid, out_ready = _stimulus(p, np.random.default_rng(310), 1_000_000)
    ref = _check(p, words, in_valid, out_ready, backends=("verilator",), name="dsp_fifo_vl")
    assert ref.dropped.sum() > 10_000
    _check_accounting(words, ref, p)


@needs_verilator
def test_verilator_with_parity_matches_model():
    p = FifoParams(width=12, depth=8, parity=True)
    words, in_valid, out_ready = _stimulus(p, np.random.default_rng(311), 200_000)
    ref = _check(p, words, in_valid, out_ready, backends=("verilator",),
                 name="dsp_fifo_parity_vl")
    assert ref.dropped.sum() > 1000
