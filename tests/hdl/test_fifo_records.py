"""FIFO records (``record_words > 1``): a record of n words with a start-of-record tag,
queued or dropped whole, markers counting records. Model == Amaranth simulation ==
Verilator (wide input ports: 3 x 24 = 72 and 6 x 24 = 144 bits), the drops counted on both
sides (the FPGA's ``overflow_count`` and the DSP receiver via the markers), directed
corners."""
from __future__ import annotations

import numpy as np
import pytest
from amaranth.hdl import Fragment

from cosim.core.link import DspServiceConfig, run_link
from cosim.testing import check_stream
from dsp.records import receive_records
from hdl.fifo import DspFifo
from hdl.model.fifo import (TAG_DATA, TAG_MARKER, TAG_START, FifoParams, ReadySchedule,
                            fifo_model, fifo_model_events, pack_records, pack_word,
                            unpack_records, unpack_word)

from _util import assert_lints_clean, needs_verilator

#: The issue's 3-word record format: three 24-bit words (e.g. I, Q and a tag/time word).
P3 = FifoParams(width=24, depth=16, record_words=3)


def _records(rng, p, n):
    return rng.integers(0, 1 << p.width, (n, p.record_words))


def _bursts(rng, n, burst, p_on, p_fine):
    on = np.repeat(rng.random(n // burst + 1) < p_on, burst)[:n]
    return on & (rng.random(n) < p_fine)


def _stall_stimulus(p, rng, n_cycles, *, period=40, count=12, stall=(0.3, 0.6),
                    p_rec=0.08):
    """Records at random cycles for 90 % of the run (not always ``record_words`` apart, so
    some arrive while the hold register is busy), read by a DSP serving the FIFO from a
    timer interrupt (:class:`cosim.core.link.DspServiceConfig`: ``count`` words every ``period``
    cycles) that stalls (``ready`` low) for the fraction ``stall`` of the run."""
    in_valid = rng.random(n_cycles) < p_rec
    in_valid[int(0.9 * n_cycles):] = False      # the DSP catches up: queue drained at the end
    service = DspServiceConfig(period_cycles=period, latency_cycles=5, batch_words=count,
                               cycles_per_word=1,
                               stalls=((int(stall[0] * n_cycles), int(stall[1] * n_cycles)),))
    ready = service.ready_mask(n_cycles)
    assert not ready[int(stall[0] * n_cycles):int(stall[1] * n_cycles)].any()
    return _records(rng, p, int(in_valid.sum())), in_valid, ready


def _check_accounting(recs, ref, p):
    """Walk the output: a start word begins the next record not dropped, followed by its
    other words; a marker stands for exactly its count of dropped records."""
    payload, tag = unpack_word(ref.words, p)
    k = 0
    i = 0
    n = p.record_words
    while i < payload.size:
        if tag[i] == TAG_MARKER:
            assert payload[i] > 0 and ref.dropped[k:k + payload[i]].all()
            k += int(payload[i])
            i += 1
            continue
        assert tag[i] == TAG_START and not ref.dropped[k], (i, k)
        # (the run may end with the DSP half-way through the last record)
        np.testing.assert_array_equal(payload[i:i + n], recs[k][:payload.size - i])
        assert (tag[i + 1:i + n] == TAG_DATA).all()
        k += 1
        i += n
    return k


def _check(p, recs, in_valid, ready, *, backends=("pysim",), name=None):
    """The model's words, cycles and per-cycle ``overflow_count`` on ``backends`` (records
    packed into the wide input port)."""
    ref = fifo_model(recs, in_valid, ready, p)
    check_stream(DspFifo(p), dict(words=ref.words, cycles=ref.cycles,
                                  probes={"ovf": ref.overflow_count}),
                 pack_records(recs, p), valid=in_valid, ready=ready, n_cycles=in_valid.size,
                 probe={"ovf": "overflow_count"}, backends=backends, name=name)
    return ref


def test_pack_records_roundtrip():
    p = FifoParams(width=24, depth=8, record_words=6)
    recs = _records(np.random.default_rng(1), p, 50)
    packed = pack_records(recs, p)
    assert packed.dtype == object and max(int(v) for v in packed) < 1 << 144
    np.testing.assert_array_equal(unpack_records(packed, p), recs)
    q = FifoParams(width=20, depth=8, record_words=3)
    assert pack_records(recs[:, :3] & 0xFFFFF, q).dtype == np.int64


@pytest.mark.parametrize("p, seed", [
    (FifoParams(width=24, depth=8, record_words=3), 401),
    (FifoParams(width=24, depth=5, record_words=3, parity=True), 402),
    (FifoParams(width=10, depth=16, record_words=6), 403),
    (FifoParams(width=5, depth=4, record_words=2, count_width=3), 404),
])
def test_sim_matches_model_random(p, seed):
    """Bursty records and bursty reads; every record either whole in the output or dropped."""
    rng = np.random.default_rng(seed)
    n = 5000
    in_valid = rng.random(n) < 0.3
    ready = _bursts(rng, n, 20, 0.5, 0.8)
    recs = _records(rng, p, int(in_valid.sum()))
    ref = _check(p, recs, in_valid, ready)
    assert ref.dropped.sum() > 100 and (~ref.dropped).sum() > 100
    _check_accounting(recs, ref, p)


def _stall_run_checks(p, recs, in_valid, ready, ref, final_ovf):
    """Dropped whole and counted on both sides."""
    assert ref.state.pending == 0 and ref.state.level == 0     # drained, last marker out
    rx = receive_records(ref.words, width=p.width, record_words=p.record_words,
                         parity=p.parity)
    st = rx.state.stats
    np.testing.assert_array_equal(rx.records, recs[~ref.dropped])
    assert final_ovf == ref.state.overflow == int(ref.dropped.sum()) == st["dropped_reported"]
    assert st["broken_records"] == st["orphan_words"] == st["parity_errors"] == 0
    # each record knows how many were dropped just before it
    kept = np.flatnonzero(~ref.dropped)
    np.testing.assert_array_equal(rx.gap_before, np.diff(np.r_[-1, kept]) - 1)
    return st


def test_three_word_records_dsp_stall_pysim():
    """The issue's check on the Amaranth simulator: 3-word records, a DSP that stalls."""
    p = P3
    recs, in_valid, ready = _stall_stimulus(p, np.random.default_rng(405), 8000)
    ref = _check(p, recs, in_valid, ready)
    st = _stall_run_checks(p, recs, in_valid, ready, ref, int(ref.overflow_count[-1]))
    assert st["dropped_reported"] > 50 and st["records"] > 300


@needs_verilator
def test_three_word_records_dsp_stall_verilator():
    """Same stimulus: model == pysim == Verilator, words and cycles, the counter too."""
    p = P3
    recs, in_valid, ready = _stall_stimulus(p, np.random.default_rng(405), 8000)
    ref = _check(p, recs, in_valid, ready, backends=("pysim", "verilator"),
                 name="dsp_fifo_rec3")
    _stall_run_checks(p, recs, in_valid, ready, ref, int(ref.overflow_count[-1]))


def _correlator_run(n_cycles, seed):
    """6 x 24-bit records (I/Q x early/prompt/late: a 144-bit port), one per ~50 cycles, the
    DSP reading 8 words every 64 cycles and stalling a third of the run."""
    p = FifoParams(width=24, depth=32, record_words=6, parity=True)
    rng = np.random.default_rng(seed)
    recs, in_valid, ready = _stall_stimulus(p, rng, n_cycles, period=64, count=8,
                                            stall=(0.4, 0.7), p_rec=0.02)
    return p, recs, in_valid, ready


@needs_verilator
def test_correlator_records_verilator_matches_model():
    p, recs, in_valid, ready = _correlator_run(200_000, 406)
    ref = _check(p, recs, in_valid, ready, backends=("verilator",), name="dsp_fifo_rec6")
    st = _stall_run_checks(p, recs, in_valid, ready, ref, int(ref.overflow_count[-1]))
    assert st["dropped_reported"] > 500


@pytest.mark.slow
@needs_verilator
def test_correlator_records_verilator_matches_model_1e6():
    p, recs, in_valid, ready = _correlator_run(1_000_000, 407)
    ref = _check(p, recs, in_valid, ready, backends=("verilator",), name="dsp_fifo_rec6")
    _stall_run_checks(p, recs, in_valid, ready, ref, int(ref.overflow_count[-1]))


# -- directed corners ------------------------------------------------------------------------
def _directed(p, record_cycles, ready, n_cycles):
    """Records (payloads 100*k + j) at ``record_cycles``; model and pysim, compared."""
    in_valid = np.zeros(n_cycles, bool)
    in_valid[record_cycles] = True
    recs = np.array([[100 * k + j for j in range(p.record_words)]
                     for k in range(len(record_cycles))], dtype=np.int64)
    return _check(p, recs, in_valid, ready)


def _w(p, payload, tag):
    return int(pack_word(payload, tag, p))


@pytest.mark.parametrize("depth, fits", [(6, True), (5, False)])
def test_record_exactly_fitting_or_full_by_one_word(depth, fits):
    """``ready`` low: record A fills the output register and 2 memory words. With depth 6
    (5 memory words) record B fits exactly (3 free); with depth 5 the FIFO is one word short
    and B is dropped whole -- none of its words is queued -- and reported once ``ready``
    rises."""
    p = FifoParams(width=24, depth=depth, record_words=3)
    n = 120
    ready = np.zeros(n, bool)
    ready[60:] = True
    ref = _directed(p, [0, 10, 70], ready, n)
    A = [_w(p, 0, TAG_START), _w(p, 1, TAG_DATA), _w(p, 2, TAG_DATA)]
    B = [_w(p, 100, TAG_START), _w(p, 101, TAG_DATA), _w(p, 102, TAG_DATA)]
    C = [_w(p, 200, TAG_START), _w(p, 201, TAG_DATA), _w(p, 202, TAG_DATA)]
    if fits:
        assert ref.words.tolist() == A + B + C and not ref.dropped.any()
    else:
        assert ref.words.tolist() == A + [_w(p, 1, TAG_MARKER)] + C
        assert ref.dropped.tolist() == [False, True, False]
        assert ref.overflow_count[11] == 1 and ref.overflow_count[10] == 0


def test_back_to_back_records():
    """One record every ``record_words`` cycles streams through with no drop (1 word per
    cycle); one every cycle keeps every record the hold register can take, and counts and
    reports the others (A, marker 2, D, marker 3, H, ...)."""
    p = FifoParams(width=24, depth=8, record_words=3)
    n = 200
    ready = np.ones(n, bool)
    ref = _directed(p, list(range(0, 90, 3)), ready, n)
    assert not ref.dropped.any() and ref.words.size == 90
    assert np.all(np.diff(ref.cycles) == 1)
    ref = _directed(p, list(range(0, 40)), ready, n)
    payload, tag = unpack_word(ref.words, p)
    assert tag[:8].tolist() == [TAG_START, TAG_DATA, TAG_DATA, TAG_MARKER] * 2
    assert payload[:8].tolist() == [0, 1, 2, 2, 300, 301, 302, 3]
    assert ref.dropped[:8].tolist() == [False, True, True, False, True, True, True, False]
    _check_accounting(np.array([[100 * k + j for j in range(3)] for k in range(40)]), ref, p)


def test_marker_when_the_fifo_frees():
    """``ready`` low: A fills the output register and 2 of the 4 memory words; B and C are
    dropped and their markers fill the memory; D is dropped with the memory full, so its
    marker waits. One read (cycle 50) frees a word and D's marker goes in on the next cycle;
    E, arriving on that very cycle, does not fit: it is dropped and becomes a new gap of 1
    (not added to D's), reported when the DSP reads again; then F."""
    p = FifoParams(width=24, depth=5, record_words=3)   # 4 memory words + output register
    n = 200
    ready = np.zeros(n, bool)
    ready[50] = True
    ready[120:] = True
    ref = _directed(p, [0, 10, 20, 30, 51, 130], ready, n)
    payload, tag = unpack_word(ref.words, p)
    assert ref.dropped.tolist() == [False, True, True, True, True, False]
    assert tag.tolist() == [TAG_START, TAG_DATA, TAG_DATA] + [TAG_MARKER] * 4 + \
        [TAG_START, TAG_DATA, TAG_DATA]
    assert payload.tolist() == [0, 1, 2, 1, 1, 1, 1, 500, 501, 502]
    assert ref.overflow_count[-1] == 4


def test_chunks_equal_one_run_records():
    """The model's state carries a half-written record across chunks."""
    p = P3
    recs, in_valid, ready = _stall_stimulus(p, np.random.default_rng(408), 20_000)
    whole = fifo_model(recs, in_valid, ready, p)
    wc = np.flatnonzero(in_valid)
    st, words, cycles = None, [], []
    for a, b in [(0, 4999), (4999, 5001), (5001, 13_333), (13_333, 20_000)]:
        sel = (wc >= a) & (wc < b)
        r = fifo_model_events(wc[sel], recs[sel], b - a, ready[a:b], p, state=st)
        st = r.state
        words.append(r.words)
        cycles.append(r.cycles)
    np.testing.assert_array_equal(np.concatenate(words), whole.words)
    np.testing.assert_array_equal(np.concatenate(cycles), whole.cycles)
    assert st.overflow == whole.state.overflow


def test_schedule_equals_mask():
    p = P3
    rng = np.random.default_rng(409)
    n = 30_000
    in_valid = rng.random(n) < 0.05
    recs = _records(rng, p, int(in_valid.sum()))
    sch = ReadySchedule(period=50, offset=3, count=4, stride=2)
    a = fifo_model(recs, in_valid, sch, p)
    b = fifo_model(recs, in_valid, sch.mask(n), p)
    np.testing.assert_array_equal(a.words, b.words)
    np.testing.assert_array_equal(a.cycles, b.cycles)
    assert a.dropped.sum() > 10


@pytest.mark.parametrize("kw, msg", [
    (dict(record_words=0), r"FIFO record_words must be an integer in \[1, 64\], not 0"),
    (dict(record_words=3, depth=4), r"FIFO depth must be at least record_words \+ 2 "
                                    r"\(5: a record and a gap marker\), not 4"),
    (dict(record_words=2, asynchronous=True),
     r"FIFO records \(record_words > 1\) need the synchronous FIFO"),
])
def test_bad_params(kw, msg):
    with pytest.raises(ValueError, match=msg):
        FifoParams(**kw)


def test_bad_record_shape():
    with pytest.raises(ValueError, match=r"records must have shape \(n_records, 3\)"):
        fifo_model(np.zeros((4, 2), np.int64), np.ones(10, bool), np.ones(10, bool), P3)


def test_single_word_ports_unchanged():
    """record_words=1 (TACAN) keeps its port widths and word format."""
    p = FifoParams()
    dut = DspFifo(p)
    assert len(dut.i.payload) == 51 and len(dut.o.payload.as_value()) == 53
    Fragment.get(dut, None)     # elaborated, so no UnusedElaboratable warning
    assert pack_records(np.arange(5), p).tolist() == list(range(5))


@pytest.mark.verilator
def test_verilog_lints_clean_records():
    assert_lints_clean(DspFifo(FifoParams(width=24, depth=16, record_words=3, parity=True)),
                       "dsp_fifo_rec3")


def test_run_link_refuses_records():
    with pytest.raises(ValueError, match=r"run_link carries single words \(record_words=1\), "
                                         r"not record_words=3"):
        run_link([0], [1], 10, P3, DspServiceConfig())


def test_used_register_tracks_the_queue_memory_every_cycle():
    """The record FIFO's fit test counts the queue memory's words in a register of its own
    and keeps its flags registered (timing); the count must equal SyncFIFOBuffered's
    ``level - r_rdy``, ``w_ok`` its ``w_rdy``, and the fit flags ``count <= depth - 1 - n``
    and ``<= depth - 2 - n`` at every cycle, and no taken record ever waits for room, through
    back-to-back records, drops, markers and a stalling reader."""
    from amaranth.sim import Simulator
    p = FifoParams(width=12, depth=9, record_words=3)
    rng = np.random.default_rng(7)
    n = 3000
    iv = rng.random(n) < 0.35
    ready = rng.random(n) < 0.45
    dut = DspFifo(p)
    bad = []

    async def bench(ctx):
        for c in range(n):
            ctx.set(dut.i.valid, int(iv[c]))
            ctx.set(dut.i.payload, int(rng.integers(1 << p.in_width)))
            ctx.set(dut.o.ready, int(ready[c]))
            await ctx.tick()
            q = dut._queue
            used, level, r_rdy = ctx.get(dut._used), ctx.get(q.level), ctx.get(q.r_rdy)
            flags = (ctx.get(dut._w_ok), ctx.get(dut._fits), ctx.get(dut._fits1))
            want = (ctx.get(q.w_rdy), used <= p.depth - 1 - p.record_words,
                    used <= p.depth - 2 - p.record_words)
            if used != level - r_rdy or flags != want:
                bad.append((c, used, level, r_rdy, flags, want))
            # a taken record is written a word per cycle: never a word waiting for room
            if ctx.get(dut._hold_left) != 0 and not ctx.get(q.w_rdy):
                stalled.append(c)
            seen[0] = max(seen[0], used)

    seen, stalled = [0], []
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    assert not bad, bad[:5]
    assert not stalled, stalled[:5]
    assert seen[0] >= p.depth - 1 - p.record_words      # the queue did fill up to the fit limit
