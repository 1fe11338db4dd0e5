"""The FPGA -> DSP link model: DSP service patterns, stalls, drops, control path, timestamps."""
import numpy as np
import pytest

from cosim.core.link import DSP_PRESETS, DspServiceConfig, run_link
from cosim.core.control import ControlPath, Segment, unwrap_timestamps
from hdl.model.fifo import FifoParams, ReadySchedule, fifo_model
from hdl.model.fifo_reference import fifo_model_reference


# -- service configuration -------------------------------------------------------------------
@pytest.mark.parametrize("kw, msg", [
    (dict(period_cycles=0), "period_cycles must be an integer >= 1"),
    (dict(latency_cycles=-1), "latency_cycles must be an integer >= 0"),
    (dict(batch_words=0), "batch_words must be an integer >= 1"),
    (dict(cycles_per_word=1.5), "cycles_per_word must be an integer"),
    (dict(period_cycles=100, latency_cycles=50, batch_words=20, cycles_per_word=3),
     "must end before the next timer tick"),
    (dict(stalls=((10, 5),)), "stall stop must be an integer >= 11"),
    (dict(stalls=((100, 200), (150, 300))), "must be sorted and must not overlap"),
    (dict(stalls=(7,)), "stalls are \\(start, stop\\) cycle pairs"),
])
def test_service_config_rejects_bad_values(kw, msg):
    with pytest.raises(ValueError, match=msg):
        DspServiceConfig(**kw)


def test_ready_mask_is_the_documented_pattern():
    s = DspServiceConfig(period_cycles=100, latency_cycles=10, batch_words=3, cycles_per_word=2)
    m = s.ready_mask(250)
    assert list(np.flatnonzero(m)) == [10, 12, 14, 110, 112, 114, 210, 212, 214]
    assert s.sustainable_words_per_cycle == pytest.approx(0.03)
    assert list(s.service_starts(250)) == [10, 110, 210]
    st = s.with_stalls((105, 213))
    assert list(np.flatnonzero(st.ready_mask(250))) == [10, 12, 14, 214]
    # the segments reproduce the mask, a stall's schedule is never ready inside it
    seg = st.segments(250)
    assert [(a, b) for a, b, _ in seg] == [(0, 105), (105, 213), (213, 250)]
    rebuilt = np.concatenate([sch.mask(b - a, start=a) for a, b, sch in seg])
    np.testing.assert_array_equal(rebuilt, st.ready_mask(250))


def test_presets_are_valid_and_ordered():
    d, dma, slow = (DSP_PRESETS[k] for k in ("default", "dma", "undersized"))
    assert dma.sustainable_rate_hz() > d.sustainable_rate_hz() > 15_000 > slow.sustainable_rate_hz()


# -- run_link against the per-cycle FIFO reference -------------------------------------------
def _unreported(res, p):
    """Drops the DSP has not learnt about yet: pending in the FPGA, or in a queued marker."""
    st = res.state
    queued = list(st.queue) + ([st.out_reg] if st.out_full else [])
    return st.pending + sum(w & p.marker_max for w in queued if (w >> p.width) == 2)


def _writes(rng, n_cycles, rate, burst_p=0.0):
    wc = np.flatnonzero(rng.random(n_cycles) < rate)
    if burst_p:   # clumps of back-to-back writes
        starts = np.flatnonzero(rng.random(n_cycles) < burst_p)
        wc = np.unique(np.concatenate([wc] + [s + np.arange(12) for s in starts]))
        wc = wc[wc < n_cycles]
    return wc.astype(np.int64)


@pytest.mark.parametrize("depth, stalls", [(512, ()), (8, ()), (8, ((3_000, 9_000),)),
                                           (1, ((100, 400), (5_000, 5_001)))])
def test_run_link_matches_the_cycle_reference(depth, stalls):
    rng = np.random.default_rng(depth + len(stalls))
    p = FifoParams(width=20, depth=depth, count_width=6)
    svc = DspServiceConfig(period_cycles=500, latency_cycles=37, batch_words=5,
                           cycles_per_word=3, stalls=stalls)
    n = 12_000
    wc = _writes(rng, n, 0.008, burst_p=0.0005)
    pl = rng.integers(0, 1 << 20, wc.size)
    res = run_link(wc, pl, n, p, svc)
    valid = np.zeros(n, bool)
    valid[wc] = True
    ref = fifo_model_reference(pl, valid, svc.ready_mask(n), p)
    np.testing.assert_array_equal(res.words, ref.words)
    np.testing.assert_array_equal(res.read_cycles, ref.cycles)
    np.testing.assert_array_equal(res.dropped_mask, ref.dropped)
    assert res.dropped == min(int(ref.dropped.sum()), p.count_max) == ref.overflow_count[-1]
    # every word is accounted for: read, dropped (counted) or still in the FPGA
    assert res.n_written == len(res.data) + res.n_dropped + res.undelivered
    st = res.state
    queued = list(st.queue) + ([st.out_reg] if st.out_full else [])
    in_fpga = sum(1 for w in queued if (w >> p.width) == 0) + int(st.hold_valid)
    assert res.undelivered == in_fpga
    # the data the DSP gets are the words not dropped, in order
    np.testing.assert_array_equal(res.data, pl[~res.dropped_mask][:len(res.data)])
    assert np.all(res.wait_cycles >= 2)
    if stalls and depth <= 8:
        assert res.n_dropped > 0
    if res.n_dropped <= p.marker_max:
        assert res.dropped_reported + _unreported(res, p) == res.n_dropped


def test_overload_drops_and_no_drops_below_the_sustainable_rate():
    p = FifoParams(width=20, depth=64)
    svc = DspServiceConfig(period_cycles=1000, latency_cycles=10, batch_words=10,
                           cycles_per_word=2)       # sustains 0.01 words/cycle
    n = 400_000
    for rate, expect_drops in ((0.006, False), (0.02, True)):
        wc = np.arange(0, n - 200, int(round(1 / rate)), dtype=np.int64)
        res = run_link(wc, np.zeros(wc.size, np.int64), n, p, svc)
        assert (res.dropped > 0) == expect_drops
        if expect_drops:
            # the DSP takes its full batch every service and gets told about every drop
            assert res.dropped_reported + _unreported(res, p) == res.dropped
            # it reads its whole budget (10 words per service, markers included) ...
            assert np.all(res.reads_per_service[1:] == 10)
            # ... and everything else is dropped (counted) or still queued
            assert res.dropped == wc.size - len(res.data) - res.undelivered
        else:
            assert res.max_level <= 10


def test_run_link_rejects_bad_input():
    p = FifoParams(width=8, depth=4)
    svc = DspServiceConfig(period_cycles=10, latency_cycles=0, batch_words=2, cycles_per_word=1)
    with pytest.raises(ValueError, match="fit in the FIFO width"):
        run_link([1, 2], [3, 1 << 9], 100, p, svc)
    with pytest.raises(ValueError, match="strictly increasing"):
        run_link([5, 5], [1, 2], 100, p, svc)
    with pytest.raises(ValueError, match=r"lie in \[0, 100\)"):
        run_link([5, 100], [1, 2], 100, p, svc)
    with pytest.raises(ValueError, match="integers"):
        run_link([1, 2], [1.5, 2.0], 100, p, svc)
    with pytest.raises(ValueError, match="one payload per write cycle"):
        run_link([1, 2, 3], [1, 2], 100, p, svc)
    with pytest.raises(ValueError, match="DspServiceConfig"):
        run_link([1], [1], 100, p, ReadySchedule(period=1))


# -- control path ------------------------------------------------------------------------------
def test_control_path_segments_and_errors():
    ctl = ControlPath(latency_cycles=10, initial={"freq": 100})
    assert ctl.write(500, "freq", 120) == 510
    assert ctl.write(500, "gain", 3) == 510
    assert ctl.write(700, "freq", 90, read_cycle=650) == 710
    assert ctl.writes() == [(510, "freq", 120), (510, "gain", 3), (710, "freq", 90)]
    assert ctl.segments(1000) == [Segment(0, 510, {"freq": 100, "gain": None}),
                                  Segment(510, 710, {"freq": 120, "gain": 3}),
                                  Segment(710, 1000, {"freq": 90, "gain": 3})]
    assert ctl.segments(600)[-1] == Segment(510, 600, {"freq": 120, "gain": 3})
    assert ctl.values_at(709) == {"freq": 120, "gain": 3}
    with pytest.raises(ValueError, match="causality"):
        ctl.write(800, "freq", 1, read_cycle=801)
    with pytest.raises(ValueError, match="time order"):
        ctl.write(600, "freq", 1)
    with pytest.raises(ValueError, match="must be an integer"):
        ctl.write(900, "freq", 1.5)
    with pytest.raises(ValueError, match="latency_cycles must be an integer >= 0"):
        ControlPath(-1)
    # latency 0: an upset of the register itself takes effect in its own cycle
    up = ControlPath(0, initial={"freq": 7})
    assert up.write(5, "freq", 8) == 5
    assert up.segments(10) == [Segment(0, 5, {"freq": 7}), Segment(5, 10, {"freq": 8})]


# -- timestamps -----------------------------------------------------------------------------------
def test_unwrap_timestamps_across_batches():
    rng = np.random.default_rng(3)
    bits = 12
    ticks = np.cumsum(rng.integers(1, 1 << (bits - 1), 5000)) + 77
    wrapped = ticks % (1 << bits)
    out, last = [], None
    for part in np.array_split(wrapped, 7):
        u, last = unwrap_timestamps(part, bits, last)
        out.append(u)
    u = np.concatenate(out)
    np.testing.assert_array_equal(u - u[0], ticks - ticks[0])
    assert last == int(u[-1])
    with pytest.raises(ValueError, match=r"lie in \[0, 2\*\*12\)"):
        unwrap_timestamps([1 << 12], bits)
    with pytest.raises(ValueError, match="ts_bits"):
        unwrap_timestamps([1], 63)


def test_run_link_in_blocks_equals_one_call():
    """A long run in blocks (carrying the FIFO state) gives the same bits, with stalls and
    service windows straddling the block edges and words queued across them."""
    rng = np.random.default_rng(9)
    p = FifoParams(width=20, depth=6, count_width=8)
    svc = DspServiceConfig(period_cycles=700, latency_cycles=50, batch_words=4,
                           cycles_per_word=5, stalls=((2_000, 4_100), (9_990, 10_500)))
    n = 20_000
    wc = _writes(rng, n, 0.007, burst_p=0.0004)
    pl = rng.integers(0, 1 << 20, wc.size)
    one = run_link(wc, pl, n, p, svc)
    st, words, cycles, idx, data = None, [], [], [], []
    edges = [0, 1_999, 2_000, 4_100, 7_777, 10_000, 10_001, n]
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (wc >= a) & (wc < b)
        r = run_link(wc[sel], pl[sel], b - a, p, svc, state=st)
        st = r.state
        words.append(r.words)
        cycles.append(r.read_cycles)
        data.append(r.data)
        assert r.undelivered == _queued(r.state, p)
        ok = r.data_index >= 0
        np.testing.assert_array_equal(pl[sel][r.data_index[ok]], r.data[ok])
    np.testing.assert_array_equal(np.concatenate(words), one.words)
    np.testing.assert_array_equal(np.concatenate(cycles), one.read_cycles)
    np.testing.assert_array_equal(np.concatenate(data), one.data)
    assert st.overflow == one.dropped > 0


def _queued(st, p):
    queued = list(st.queue) + ([st.out_reg] if st.out_full else [])
    return sum(1 for w in queued if (w >> p.width) == 0) + int(st.hold_valid)
