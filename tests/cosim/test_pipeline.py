"""Persistent front-end sessions and the closed-loop pipeline (issue 12).

A toy DSP policy writes the NCO word as a function of the FIFO words it read; the loop runs
on the bit-exact model, on the Amaranth simulation and on Verilator, the record fed in 1, 7
and 50 blocks: the same words on the same cycles and the same writes everywhere. The writes
the loop made, replayed into a one-shot run of the old harness, give the same words again:
they reached the HDL at the modelled cycles.
"""
import numpy as np
import pytest

from cosim.core.link import DspServiceConfig, run_link
from cosim.core.pipeline import Pipeline
from cosim.backends.factory import open_frontend
from cosim.core.session import ready_window
from cosim.tacan.session import TacanModelSession
from cosim.tacan.config import TacanRunConfig
from cosim.tacan.signal import TacanSignalConfig, generate
from cosim.backends.verilator_harness import verilator_available
from dsp.tacan.kalman_config import KalmanConfig

needs_verilator = pytest.mark.skipif(not verilator_available(),
                                     reason="Verilator, make or a C++ compiler not on PATH")

#: A fast DSP loop for short records: a 25 us timer, 8 reads 2 cycles apart.
FAST_SVC = DspServiceConfig(period_cycles=500, latency_cycles=20, batch_words=8,
                            cycles_per_word=2)
N_SHORT = 6000      # cycles on the Amaranth simulation (~4 s): the first peaks come at ~4500


def _run_config(duration_s, first_main_ref_s, **kw):
    sig = TacanSignalConfig(duration_s=duration_s, snr_db=20.0, seed=3, bearing_deg=123.0,
                            first_main_ref_s=first_main_ref_s)
    return TacanRunConfig(signal=sig, backend="model", settle_s=0.0, require_bearing=False,
                          kalman=KalmanConfig(memory_s=0.01), **kw)


@pytest.fixture(scope="module")
def short():
    """2 ms with a main reference burst from 0.2 ms: ~7 FIFO words in the first 6000 cycles."""
    run = _run_config(0.002, 0.2e-3)
    return run.hdl_params, generate(run.signal).samples[:N_SHORT]


@pytest.fixture(scope="module")
def long_record():
    """9.5 ms, a 12-word FIFO and a DSP stall: drops, gap markers, ~100 words."""
    run = _run_config(0.0095, 1e-3, hdl_changes=(("fifo_depth", 12),))
    return run.hdl_params, generate(run.signal).samples


class ToyNcoPolicy:
    """Retune the NCO from what was read: base word + (sum of the words mod 31 - 15) *
    2**20 (+-70 kHz at 20 MHz), written whenever a service read something."""

    def __init__(self, base: int):
        self.base = base
        self.calls = 0

    def __call__(self, call):
        self.calls += 1
        if not call.words.size:
            return []
        return [("freq", self.base + (int(call.words.sum()) % 31 - 15) * (1 << 20))]


def _closed_loop(backend, params, samples, n_blocks, service=FAST_SVC, flush=300, *,
                 compute_cycles=30, latency_cycles=40):
    with open_frontend(backend, params) as fe:
        pipe = Pipeline(fe, service, ToyNcoPolicy(params.nco_freq_word),
                        compute_cycles=compute_cycles, control_latency_cycles=latency_cycles,
                        initial={"freq": params.nco_freq_word})
        for block in np.array_split(samples, n_blocks):
            pipe.feed(block)
        pipe.idle(flush)
        return pipe.result()


def _same(a, b):
    np.testing.assert_array_equal(a.words, b.words)
    np.testing.assert_array_equal(a.cycles, b.cycles)
    assert a.writes == b.writes
    assert a.overflow_count == b.overflow_count
    assert a.digest == b.digest


@pytest.fixture(scope="module")
def short_ref(short):
    params, x = short
    return _closed_loop("model", params, x, 1)


def test_toy_loop_writes_and_the_writes_change_the_words(short, short_ref):
    params, x = short
    r = short_ref
    assert r.n_words >= 5 and len(r.writes) >= 3
    # Effect cycle = end of the read window + compute time + control latency.
    for c, reg, v in r.writes:
        assert reg == "freq" and (c - 20 - FAST_SVC.window_cycles - 30 - 40) % 500 == 0
    with open_frontend("model", params) as fe:
        open_loop = Pipeline(fe, FAST_SVC)
        open_loop.feed(x)
        open_loop.idle(300)
        o = open_loop.result()
    assert o.writes == [] and not np.array_equal(o.words, r.words)


@pytest.mark.parametrize("backend", ["model", "pysim",
                                     pytest.param("verilator", marks=needs_verilator)])
@pytest.mark.parametrize("n_blocks", [1, 7, 50])
def test_closed_loop_same_bits_on_every_backend_and_blocking(short, short_ref, backend,
                                                             n_blocks):
    params, x = short
    _same(_closed_loop(backend, params, x, n_blocks), short_ref)


@pytest.mark.parametrize("backend,n_blocks", [
    ("model", 50), ("pysim", 7), pytest.param("verilator", 50, marks=needs_verilator)])
def test_zero_latency_write_lands_on_the_issue_cycle(short, backend, n_blocks):
    """Writes issued the very cycle the words were read and applied at once (latency 0): the
    write falls on a step boundary of the session, identically on every backend."""
    params, x = short
    ref = _closed_loop("model", params, x, 1, compute_cycles=0, latency_cycles=0)
    assert ref.writes and all((c - 20 - FAST_SVC.window_cycles) % 500 == 0
                              for c, _, _ in ref.writes)
    _same(_closed_loop(backend, params, x, n_blocks, compute_cycles=0, latency_cycles=0), ref)


@needs_verilator
@pytest.mark.parametrize("n_blocks", [7, 50])
def test_closed_loop_with_drops_model_and_verilator(long_record, n_blocks):
    """190k cycles with FIFO overflows in a DSP stall, the default 1 ms service: model in one
    block == model and Verilator in 7 and 50 blocks."""
    params, x = long_record
    svc = DspServiceConfig().with_stalls((60_000, 100_000))
    ref = _closed_loop("model", params, x, 1, service=svc, flush=20_000)
    assert ref.overflow_count > 0 and len(ref.writes) > 0
    _same(_closed_loop("model", params, x, n_blocks, service=svc, flush=20_000), ref)
    _same(_closed_loop("verilator", params, x, n_blocks, service=svc, flush=20_000), ref)


@needs_verilator
def test_loop_writes_replayed_in_a_one_shot_run_give_the_same_words(long_record):
    """The writes the loop decided at run time, given up front to the old one-shot harness
    (``VerilatorStreamSim.run(writes=...)``): the same words on the same cycles."""
    from cosim.backends.verilator import VerilatorStreamSim
    from hdl.tacan.frontend import TacanFrontEnd
    params, x = long_record
    svc = DspServiceConfig().with_stalls((60_000, 100_000))
    r = _closed_loop("verilator", params, x, 7, service=svc, flush=20_000)
    n = x.size + 20_000
    sim = VerilatorStreamSim(TacanFrontEnd(params), name="tacan_frontend")
    one = sim.run(x, out_ready=svc.ready_mask(n), n_cycles=n,
                  inputs={"freq": params.nco_freq_word}, writes=r.writes,
                  final={"ovf": "overflow_count"})
    np.testing.assert_array_equal(one.words, r.words)
    np.testing.assert_array_equal(one.cycles, r.cycles)
    assert one.final["ovf"] == r.overflow_count


def test_model_session_in_blocks_equals_model_and_link_in_one_call(long_record):
    """Open loop: the model session stepped in uneven blocks == the front-end model plus
    :func:`run_link` on the whole record."""
    from hdl.tacan.model import TacanFrontendModel
    params, x = long_record
    svc = DspServiceConfig().with_stalls((60_000, 100_000))
    n = x.size + 1000
    m = TacanFrontendModel(params)
    pk, _ = m.run(x)
    ref = run_link(m.peak_cycles(pk), m.words(pk), n, params.fifo, svc)
    cuts = [0, 1, 3, 4000, 4001, 77_777, 150_000, x.size]
    with TacanModelSession(params) as fe:
        got = [fe.step(x[a:b], svc) for a, b in zip(cuts[:-1], cuts[1:])]
        got.append(fe.step(None, svc, n_cycles=1000))
        assert fe.read("overflow_count") == ref.dropped > 0
    np.testing.assert_array_equal(np.concatenate([g.words for g in got]), ref.words)
    np.testing.assert_array_equal(np.concatenate([g.cycles for g in got]), ref.read_cycles)


def test_ready_window_matches_the_service_mask():
    svc = DspServiceConfig().with_stalls((30_000, 45_000))
    full = svc.ready_mask(100_000)
    for a, n in [(0, 100_000), (12_345, 40_000), (44_999, 2)]:
        np.testing.assert_array_equal(ready_window(svc, a, n), full[a:a + n])
    np.testing.assert_array_equal(ready_window([True, False], 5, 4), [True, False, True, True])
    assert ready_window(None, 0, 3) is None


def test_session_errors(short):
    params, _ = short
    with open_frontend("model", params) as fe:
        fe.step(np.zeros(10, np.int64))
        with pytest.raises(ValueError, match="in the past"):
            fe.write("freq", 1, cycle=5)
        with pytest.raises(KeyError, match="freq"):
            fe.write("gain", 1)
        with pytest.raises(ValueError, match="integer"):
            fe.write("freq", 1.5)
    with pytest.raises(RuntimeError, match="closed"):
        fe.step(np.zeros(1, np.int64))
    with pytest.raises(ValueError, match="backend"):
        open_frontend("golden", params)
    with pytest.raises(TypeError, match="no front end registered"):
        open_frontend("model", object())


# -- dsp-hour on the pipeline -----------------------------------------------------------------
def _old_chain(simulated_s, block_s, batch_s):
    """The chain ``dsp-hour`` ran before the pipeline (bench_dsp at a2c3ba2), blocks and
    batch length as parameters: front-end model, run_link and the FIFO receiver per block,
    all with carried state, the DSP per batch."""
    from cosim.tacan.bench_dsp import _if_block
    from dsp.tacan.bearing import wrap_deg
    from dsp.tacan.fifo_rx import receive_words
    from dsp.tacan.frontend import FrontendConfig
    from dsp.tacan.kalman_config import KalmanFixedConfig
    from dsp.tacan.receiver import ReceiverConfig, amplitude_codes, process_peaks
    from hdl.tacan.model import TacanFrontendModel
    from hdl.tacan.params import TacanFrontendParams
    n_blocks = int(round(simulated_s / block_s))
    bearing, snr = 90.0, 10.0
    sig0 = TacanSignalConfig(duration_s=block_s, snr_db=snr, bearing_deg=bearing)
    params = TacanFrontendParams(config=FrontendConfig.for_signal(sig0), adc_bits=sig0.adc_bits)
    fe = TacanFrontendModel(params)
    svc = DspServiceConfig()
    rc = ReceiverConfig(kalman=KalmanFixedConfig(kalman=KalmanConfig(tick_hz=20e6)))
    fs, n_blk = sig0.fs_hz, sig0.n_samples
    settle = 2 * rc.kalman.kalman.memory_s
    fe_state = link_state = rx_state = dsp_state = None
    carry_wc, carry_w = np.zeros(0, np.int64), np.zeros(0, np.int64)
    acc_t, acc_a, rows, peaks, n_words = [], [], [], 0, 0
    for k in range(n_blocks):
        x = _if_block(k, block_s, bearing, snr)
        pk, fe_state = fe.run(x, fe_state)
        wc = np.r_[carry_wc, fe.peak_cycles(pk)]
        w = np.r_[carry_w, fe.words(pk)]
        c0, c1 = k * n_blk, (k + 1) * n_blk
        now = wc < c1
        carry_wc, carry_w = wc[~now], w[~now]
        res = run_link(wc[now], w[now], c1 - c0, params.fifo, svc, state=link_state)
        link_state = res.state
        ts, amp, rx_state = receive_words(res.words, width=params.fifo.width,
                                          amp_width=params.peak.amp_width,
                                          ts_bits=params.peak.ts_bits, state=rx_state,
                                          parity=params.fifo.parity)
        acc_t.append(ts + np.int64(params.decimation - 1))
        acc_a.append(amp)
        peaks += pk.amplitudes.size
        n_words += res.words.size
        if round((k + 1) * block_s / batch_s, 9) % 1 == 0:
            ticks = np.concatenate(acc_t)
            y = amplitude_codes(np.concatenate(acc_a), params.scale_to_fs, rc.kalman.y)
            acc_t, acc_a = [], []
            tr = process_peaks(ticks / fs, y, rc, ticks=ticks, state=dsp_state)
            dsp_state = tr.state
            err = wrap_deg(tr.bearing_deg[0, tr.times_s >= settle] - bearing)
            rows.append({"bearings": int(err.size),
                         "rmse_deg": float(np.sqrt(np.mean(err ** 2))) if err.size else None,
                         "P_min_eig": float(np.linalg.eigvalsh(dsp_state.kf.P_float()[0]).min()),
                         "events": {k2: int(v[0]) for k2, v in tr.events.items()}})
    return {"rows": rows, "peaks": peaks, "fifo_words": n_words,
            "updates": int(dsp_state.kf.n_updates), "rx": dict(rx_state.stats),
            "fifo_dropped": int(link_state.overflow)}


def test_dsp_hour_short_form_on_the_pipeline_matches_the_old_chain(tmp_path):
    """``dsp-hour`` for 2 simulated seconds (1 s blocks, 1 s DSP batches): the same peaks,
    FIFO words, receiver statistics, Kalman updates and per-batch bearing figures as the
    block-by-block chain it replaced; results files written."""
    from cosim.tacan.bench_dsp import dsp_hour
    s = dsp_hour(tmp_path, simulated_s=2.0, block_s=1.0, batch_s=1.0)
    ref = _old_chain(2.0, 1.0, 1.0)
    assert (tmp_path / "dsp_hour.json").exists() and (tmp_path / "dsp_hour.md").exists()
    assert s["totals"]["peaks"] == ref["peaks"] > 10_000
    assert s["totals"]["fifo_words"] == ref["fifo_words"]
    assert s["totals"]["rx"] == ref["rx"]
    assert s["totals"]["fifo_dropped"] == ref["fifo_dropped"] == 0
    assert s["updates"] == ref["updates"]
    assert len(s["minutes"]) == len(ref["rows"]) == 2
    cum = {}
    for new, old in zip(s["minutes"], ref["rows"]):
        assert new["bearings"] == old["bearings"]
        assert new["rmse_deg"] == old["rmse_deg"]
        assert new["P_min_eig"] == old["P_min_eig"] > 0
        for k, v in new["events"].items():
            cum[k] = cum.get(k, 0) + v
        assert {k: v for k, v in old["events"].items() if v} == {k: v for k, v in cum.items() if v}
    assert s["bearings"] > 100 and s["rmse_deg"] < 0.3 and not s["diverged"]


# -- generic stream components ----------------------------------------------------------------
class _Scaler:
    """A stream block with back-pressure on both sides and a writable register: takes an
    input word every other cycle, outputs ``payload * gain`` (a one-word buffer)."""

    @staticmethod
    def build():
        from amaranth.hdl import Module, Signal, unsigned
        from amaranth.lib import stream, wiring
        from amaranth.lib.wiring import In, Out

        class Scaler(wiring.Component):
            i: In(stream.Signature(unsigned(8)))
            o: Out(stream.Signature(unsigned(16)))
            gain: In(unsigned(8), init=1)

            def elaborate(self, platform):
                m = Module()
                phase = Signal()
                full = Signal()
                m.d.sync += phase.eq(~phase)
                m.d.comb += [self.i.ready.eq(phase & (~full | self.o.ready)),
                             self.o.valid.eq(full)]
                with m.If(self.o.valid & self.o.ready):
                    m.d.sync += full.eq(0)
                with m.If(self.i.valid & self.i.ready):
                    m.d.sync += [full.eq(1), self.o.payload.eq(self.i.payload * self.gain)]
                return m
        return Scaler()


@pytest.mark.parametrize("backend", ["pysim", pytest.param("verilator", marks=needs_verilator)])
def test_stream_session_in_blocks_equals_one_run_stream(backend):
    """Any stream component: a session stepped in uneven blocks, with back-pressure on both
    sides (words not accepted carry over to the next step) and register writes between and
    inside steps, gives :func:`cosim.backends.pysim.run_stream`'s words and cycles (seed 5)."""
    from cosim.backends.pysim import run_stream
    from cosim.backends.factory import open_stream_session
    rng = np.random.default_rng(5)
    words = rng.integers(0, 256, 500)
    n = 900
    ready = rng.random(n) < 0.6
    writes = [(0, "gain", 3), (101, "gain", 5), (102, "gain", 7), (450, "gain", 2)]
    ref = run_stream(_Scaler.build(), words, out_ready=ready, n_cycles=n, writes=writes,
                     inputs={"gain": 1})
    cuts = [0, 1, 60, 101, 102, 333, 700, n]
    # Words arrive faster than accepted (as in run_stream, where all are there from reset).
    feed = [words[:150], words[150:]] + [None] * (len(cuts) - 3)
    out_w, out_c, acc = [], [], 0
    with open_stream_session(backend, _Scaler.build(), name="scaler",
                             inputs={"gain": 1}) as s:
        for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
            for c, reg, v in writes:
                if a <= c < b:
                    s.write(reg, v, cycle=c)
            r = s.step(feed[k], ready[a:b], n_cycles=b - a)
            out_w.append(r.words)
            out_c.append(r.cycles)
            acc += r.in_accepted
        assert s.read("gain") == 2 and s.cycle == n
    np.testing.assert_array_equal(np.concatenate(out_w), ref.words)
    np.testing.assert_array_equal(np.concatenate(out_c), ref.cycles)
    assert acc == ref.in_accepted < words.size


def test_pysim_session_waveform_covers_every_step(short, tmp_path):
    """One waveform for the whole session (the simulator is the same across steps)."""
    params, x = short
    f = tmp_path / "session.vcd"
    with open_frontend("pysim", params, vcd=f) as fe:
        fe.step(x[:100], FAST_SVC)
        fe.step(x[100:200], FAST_SVC)
    text = f.read_text()
    times = [int(line[1:]) for line in text.splitlines() if line.startswith("#")]
    assert "$enddefinitions" in text and "o__valid" in text
    assert max(times) >= 199 * 50_000_000     # into the last cycle of the second step (fs)
