"""Every GNSS backend streams the record: the golden chain and the bit-exact model hold one
block and the per-epoch outputs whatever the duration (tracemalloc over two durations), the
bits do not depend on the block size, and check_run_size counts epochs and blocks, not the
record's samples (it refuses only a duration whose records would not fit, naming
--duration-s)."""
from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from cosim.cli import main
from cosim.core import validate
from cosim.gnss.config import (BLOCK_BYTES_PER_SAMPLE, EPOCH_BYTES, DynamicsChoice,
                               GnssRunConfig, check_run_size, run_memory_bytes)
from cosim.gnss.run import run_gnss, track_record
from cosim.gnss.signal import GnssSignalConfig, GnssSignalGenerator, SampleStream
from cosim.gnss.tracking import golden_track


def _sig(duration_s, **kw):
    base = GnssSignalConfig(prn=5, cn0_dbhz=45.0, duration_s=duration_s,
                            code_phase_chips=200.5, oscillator="tcxo", seed=4, **kw)
    return DynamicsChoice("aukf-patent").apply(base)


def _hand(gen):
    """A hand-over 2 Hz and 0.1 chip off the truth (no acquisition: its snapshot is not the
    streaming under test)."""
    t = gen.truth_at([0.0])
    return {"doppler_hz": float(t["doppler_hz"][0]) + 2.0,
            "code_phase_chips": (float(t["code_phase_chips"][0]) + 0.1) % 1023}


def _traced_peak(fn):
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_sample_stream_serves_the_same_samples_whatever_the_block_and_the_reads():
    cfg = GnssSignalConfig(cn0_dbhz=38.0, duration_s=0.02, seed=7)
    g = GnssSignalGenerator(cfg)
    codes, clip = g.samples(0, cfg.n_samples)
    rng = np.random.default_rng(0)
    for block in (1, 1000, 1 << 16, 1 << 20):
        s = SampleStream(g, block_samples=block)
        n, parts = 0, []
        while n < cfg.n_samples:
            m = int(rng.integers(1, 40000))
            parts.append(s(n, m).copy())
            n += m
        np.testing.assert_array_equal(np.concatenate(parts), codes)
        assert s.n_clipped == clip
        # the window holds at most a block plus the read
        assert s.held_samples < block + 40000
        # a read backwards is served (generated afresh) and counts no clip twice
        np.testing.assert_array_equal(s(100, 5000), codes[100:5100])
        assert s.n_clipped == clip
    with pytest.raises(ValueError, match="block_samples"):
        SampleStream(g, block_samples=0)


def test_golden_chain_gives_the_same_bits_whatever_the_block():
    sig = _sig(0.25)
    ref = None
    for block in (1024, 50_000, 1 << 17, 1 << 23):      # the last one > the record
        gen = GnssSignalGenerator(sig)
        run = GnssRunConfig(backend="golden", block_samples=block)
        tr, n_b = golden_track(gen, run, _hand(gen), "fixed")
        got = (tr.digest(), n_b.tolist(), tr.obs, tr.words)
        if ref is None:
            ref = got
            assert len(n_b) >= 240
        else:
            assert got == ref, block


def test_model_backend_gives_the_same_bits_whatever_the_block():
    sig = _sig(0.25)
    out = [run_gnss(sig, GnssRunConfig(backend="model", block_samples=b, settle_s=0.1))
           for b in (5000, 1 << 17)]
    a, b = out
    assert a["digest"] == b["digest"]
    assert a["n_records"] == b["n_records"] >= 240
    np.testing.assert_array_equal(a["_series"][1], b["_series"][1])
    assert a["fifo_dropped"] == b["fifo_dropped"] == 0


def _growth(backend, block, short_s, long_s):
    """tracemalloc peaks of track_record (generation, channel, tracker, boundary replay)
    on a short and a long record, after a warm-up (compiled kernels, caches)."""
    run = GnssRunConfig(backend=backend, block_samples=block)

    def peak(d):
        gen = GnssSignalGenerator(_sig(d))
        hand = _hand(gen)
        return _traced_peak(lambda: track_record(gen, run, hand))

    peak(0.02)
    return peak(short_s), peak(long_s)


@pytest.mark.slow
def test_golden_track_memory_is_bounded_by_the_block_not_the_record():
    block = 1 << 16
    short, long = _growth("golden", block, 0.3, 1.5)
    extra_epochs = 1200
    # the 1.2 s more hold 19.6e6 more samples (39 MB as codes, 157 MB as float64); the run
    # grows by its per-epoch records only, within check_run_size's allowance
    assert long - short < EPOCH_BYTES["golden"] * extra_epochs, (short, long)
    assert long < BLOCK_BYTES_PER_SAMPLE * block + EPOCH_BYTES["golden"] * 1500 + (2 << 20)


@pytest.mark.slow
def test_model_backend_memory_is_bounded_by_the_block_not_the_record():
    block = 1 << 16
    short, long = _growth("model", block, 0.2, 0.8)
    assert long - short < EPOCH_BYTES["model"] * 600, (short, long)


def test_run_size_counts_epochs_and_blocks_not_samples(monkeypatch):
    run = GnssRunConfig(backend="golden")
    a = run_memory_bytes(_sig(150.0), run)
    # the same duration at twice the rate: the same estimate (the block is the same)
    assert run_memory_bytes(_sig(150.0, fs_hz=32.736e6, if_hz=8.184e6), run) == a
    assert run_memory_bytes(_sig(300.0), run) - a == pytest.approx(
        EPOCH_BYTES["golden"] * 150_000)
    m = run_memory_bytes(_sig(150.0), GnssRunConfig(backend="model"))
    assert run_memory_bytes(_sig(150.0), GnssRunConfig(backend="model", compare="golden")) \
        - m == pytest.approx(EPOCH_BYTES["golden"] * 150_002)
    # the INS paper's 150 s on a machine of 8 GiB (4 GiB for a run): accepted on every
    # streaming backend; a duration whose records would not fit is refused, naming the option
    monkeypatch.setattr(validate, "memory_bytes", lambda: 8 * 2 ** 30)
    for backend in ("golden", "model"):
        check_run_size(_sig(150.0), GnssRunConfig(backend=backend))
    with pytest.raises(ValueError, match="--duration-s"):
        check_run_size(_sig(1e6), run)


@pytest.mark.parametrize("receiver", ["gnss", "ins"])
def test_cli_refuses_a_duration_that_would_not_fit_before_work(receiver, capsys):
    rc = main([receiver, "--backend", "golden", "--duration-s", "1e7"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "--duration-s" in err and "epochs of records" in err
