"""TACAN front-end top with both searches (single pulses and pulse pairs in one FIFO stream):
parameters and words, each search alone, merge collisions, chunking, sessions, Amaranth
simulation and Verilator == model, lint."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cosim.tacan.equivalence import check_equivalence, tacan_record
from cosim.tools.equivalence import stall_pattern
from cosim.backends.pysim import run_stream
from cosim.tacan.signal import TacanSignalConfig
from dsp.tacan.standard import SOURCE_PAIR, SOURCE_PULSE
from dsp.tacan.standard import pair_spacing_s
from hdl.tacan.model import FrontendPeaks, TacanFrontendModel
from hdl.tacan.params import TacanFrontendParams
from hdl.tacan.frontend import TacanFrontEnd

from _tacan_fe_util import BOTH, P, both_params, verilator  # on sys.path: conftest.py


# -- both searches: single pulses and pulse pairs in one FIFO stream ------------------------------
def _triples(shifts, seed: int = 0, start: int = 4096, every: int = 1600) -> np.ndarray:
    """A directed record for the merge: pulse triples A, B = A + 12 us, C = B + 12 us + shift
    (ADC samples), 0.4 FS at the IF, white noise of 30 codes rms. The pair search reports
    (A, B) 12 us after B closes, about when the pulse search closes C: the shifts move C
    across the pair's emitting envelope sample."""
    sig = TacanSignalConfig()
    fs = sig.fs_hz
    d, sigma = int(round(pair_spacing_s(sig.mode) * fs)), sig.pulse_sigma_s * fs
    n = start + every * len(shifts) + 1000
    t = np.arange(n)
    env = np.zeros(n)
    for k, sh in enumerate(shifts):
        for c in np.array([0, d, 2 * d + sh]) + start + k * every:
            env += np.exp(-0.5 * ((t - c) / sigma) ** 2)
    noise = np.random.default_rng(seed).normal(0, 30, n)
    x = 0.4 * 2047 * env * np.cos(2 * np.pi * sig.digital_if_hz / fs * t + 0.7) + noise
    return np.clip(np.round(x), -2048, 2047).astype(np.int64)


#: 16 triples (C at +9 .. +16 ADC samples, twice): at decimation 2, 2 collisions with the
#: pair checks on and valid on every cycle, 4 with the checks off and :data:`VALID_11101`
#: (:data:`COLLISIONS`; the tests assert them).
TRIPLES = _triples(list(range(9, 17)) * 2)


#: ADC valid 4 cycles in 5 for TRIPLES: envelope samples 3 and 2 cycles apart in turn, so
#: two of them can be 5 cycles apart, the latency difference with the pair checks off (at
#: decimation 2 on every cycle they are an even number of cycles apart).
VALID_11101 = np.resize(np.array([1, 1, 1, 0, 1], bool), TRIPLES.size * 5 // 4 + 2)


#: pair checks on -> (ADC valid, collisions of TRIPLES) at decimation 2
COLLISIONS = {True: (None, 2), False: (VALID_11101, 4)}


def _collisions(m: TacanFrontendModel, pk, in_valid=None) -> int:
    """Pair words that leave their search with a pulse word (the merge delays them)."""
    em = m.emit_cycles(pk, in_valid)
    pulse = em[pk.source == SOURCE_PULSE]
    hit = np.isin(em[pk.source == SOURCE_PAIR], pulse)
    assert np.count_nonzero(m.peak_cycles(pk, in_valid) != em) == hit.sum()
    return int(hit.sum())


def test_both_searches_params_and_words():
    """pair_peak is built as peak is (the chain's widths, step and threshold floor); the
    payload grows by the source bit at the top; latencies per search; without pair_peak
    nothing changes."""
    p = BOTH
    cfg = p.config
    assert p.pair_peak == replace(cfg.pair_peak, amp_width=p.envelope.out_width,
                                  ts_bits=p.ts_bits, ts_step=4, thr_min=p.peak.thr_min)
    assert p.pair_peak.pair_offset == 60 and p.pair_peak.pair_checks
    assert p.source_bits == 1 and P.source_bits == 0 and P.pair_peak is None
    assert p.fifo.width == p.peak.amp_width + p.peak.ts_bits + 1 == P.fifo.width + 1
    assert p.latency == P.latency and p.peak_latency == P.peak_latency
    assert p.pair_peak_latency == p.chain_latency + p.pair_peak.latency == p.peak_latency + 6
    assert P.pair_peak_latency is None
    m = TacanFrontendModel(p)
    pk, _ = m.run(tacan_record(40_000, seed=2))
    assert set(pk.source.tolist()) == {SOURCE_PULSE, SOURCE_PAIR}
    w = m.words(pk)
    aw, tb = p.peak.amp_width, p.peak.ts_bits
    np.testing.assert_array_equal(w >> (aw + tb), pk.source)
    f = m.unpack(w | (np.int64(2) << p.fifo.width))          # as markers: tag above source
    np.testing.assert_array_equal(f["source"], pk.source)
    np.testing.assert_array_equal(f["amplitude"], pk.amplitudes)
    np.testing.assert_array_equal(f["timestamp"], pk.timestamps & ((1 << tb) - 1))
    assert (f["tag"] == 2).all() and "source" not in TacanFrontendModel(P).unpack(w)
    with pytest.raises(ValueError, match="carry a source exactly when"):
        TacanFrontendModel(P).words(pk)
    with pytest.raises(ValueError, match="carry a source exactly when"):
        m.words(replace(pk, source=None))
    # the rule behind the one-word hold register (FrontendConfig checks cic_rate >= 2 too)
    bad = replace(cfg)
    object.__setattr__(bad, "cic_rate", 1)
    with pytest.raises(ValueError, match="with pair_peak the total decimation must be >= 2 "
                                         r"\(the merge .*\), not 1"):
        TacanFrontendParams(config=bad)


def test_both_searches_model_is_each_search_alone():
    """Per source, the merged stream is exactly what a front end with that search alone
    reports; fast == block chain; chunked runs == one run."""
    x = tacan_record(120_003, seed=4)
    cfg = BOTH.config
    alone = {SOURCE_PULSE: replace(cfg, pair_peak=None),
             SOURCE_PAIR: replace(cfg, peak=cfg.pair_peak, pair_peak=None)}
    fast, slow = TacanFrontendModel(BOTH), TacanFrontendModel(BOTH, fast=False)
    pk, _ = fast.run(x)
    for src, c in alone.items():
        one, _ = TacanFrontendModel(TacanFrontendParams(config=c, adc_bits=BOTH.adc_bits)).run(x)
        sel = pk.take(pk.source == src)
        for f in ("amplitudes", "timestamps", "index", "end_index"):
            np.testing.assert_array_equal(getattr(sel, f), getattr(one, f))
        assert len(one) > 10
    ref, _ = slow.run(x)
    np.testing.assert_array_equal(fast.words(ref), fast.words(pk))
    cyc = fast.peak_cycles(pk)
    assert np.all(np.diff(cyc) > 0)                      # run() gives the FIFO's order
    assert np.any(np.diff(pk.timestamps) < 0)            # ... which is not timestamp order
    st, parts = None, []
    for chunk in np.array_split(x, [1, 4097, 50_001, 50_002, 99_999]):
        q, st = fast.run(chunk, st)
        parts.append(q)
    np.testing.assert_array_equal(fast.words(FrontendPeaks.concat(parts)), fast.words(pk))


def test_collisions_follow_the_latency_difference():
    """The pair search emits 6 cycles (5 without the checks) later than the pulse search
    after the same envelope sample: a pulse word and a pair word meet when their envelope
    samples are that many cycles apart. At decimation 4 with a sample on every cycle they are
    a multiple of 4 apart and never meet; gaps in valid make it possible. At decimation 2
    :data:`COLLISIONS`, and each difference never meets the other pattern (6 is no sum of
    consecutive gaps 3, 2, 3, ...; 5 is odd)."""
    assert BOTH.pair_peak_latency - BOTH.peak_latency == 6
    m = TacanFrontendModel(BOTH)
    x = tacan_record(400_000, seed=3)
    pk, _ = m.run(x)
    gaps = np.random.default_rng(3).random(len(x) * 2) < 0.6
    assert _collisions(m, pk) == 0 and _collisions(m, pk, gaps) == 1
    assert len(pk) > 200
    assert both_params(cic_rate=2, checks=False).pair_peak_latency \
        - both_params(cic_rate=2, checks=False).peak_latency == 5
    for checks, (valid, n) in COLLISIONS.items():
        m = TacanFrontendModel(both_params(cic_rate=2, checks=checks))
        pk, _ = m.run(TRIPLES)
        assert _collisions(m, pk, valid) == n, checks
        other = None if valid is not None else VALID_11101
        assert _collisions(m, pk, other) == 0, checks


def test_pysim_equals_model_both_searches():
    """1 ms of SNR 10 dB TACAN IF through the front end with both searches: every FIFO word
    (with its source bit) and its cycle; a pair word leaves pair_peak_latency (+ FIFO)
    cycles after the ADC sample completing its emitting envelope sample."""
    p = BOTH
    x = tacan_record(20_000, seed=2)
    m = TacanFrontendModel(p)
    pk, _ = m.run(x)
    dut = TacanFrontEnd(p)
    res = run_stream(dut, x, n_cycles=len(x) + 600, inputs={"freq": p.nco_freq_word},
                     probe={"ovf": dut.overflow_count})
    ref = m.fifo_output(pk, res.n_cycles)
    assert np.bincount(pk.source).tolist() == [4, 2]
    np.testing.assert_array_equal(res.words, ref.words)
    np.testing.assert_array_equal(res.cycles, ref.cycles)
    assert not res.probes["ovf"].any()
    f = m.unpack(res.words)
    np.testing.assert_array_equal(f["source"], pk.source)
    np.testing.assert_array_equal(f["amplitude"], pk.amplitudes)
    k = np.flatnonzero(pk.source == SOURCE_PAIR)[0]
    adc = (pk.end_index[k] + 1) * p.decimation - 1
    assert res.cycles[k] == adc + p.pair_peak_latency + p.FIFO_LATENCY


@pytest.mark.slow   # 17 s; Verilator == model with stalls and both searches runs in make test
def test_pysim_both_searches_gaps_in_valid_and_dsp_stalls():
    """Both searches, ADC valid with gaps, a DSP that stalls on a 1-deep FIFO: drops,
    markers and the overflow counter, word for word."""
    p = both_params(fifo_depth=1)
    x = tacan_record(20_000, seed=2)
    rng = np.random.default_rng(12)
    in_valid = rng.random(24_000) < 0.85
    n_cycles = int(np.flatnonzero(in_valid)[len(x) - 1]) + 600
    ready = np.zeros(n_cycles, bool)
    ready[-300:] = True
    m = TacanFrontendModel(p)
    pk, _ = m.run(x)
    dut = TacanFrontEnd(p)
    res = run_stream(dut, x, in_valid=in_valid, out_ready=ready, n_cycles=n_cycles,
                     inputs={"freq": p.nco_freq_word}, probe={"ovf": dut.overflow_count})
    ref = m.fifo_output(pk, n_cycles, in_valid=in_valid, out_ready=ready)
    np.testing.assert_array_equal(res.words, ref.words)
    np.testing.assert_array_equal(res.cycles, ref.cycles)
    np.testing.assert_array_equal(res.probes["ovf"], ref.overflow_count)
    assert ref.dropped.sum() >= 2 and (m.unpack(ref.words)["tag"] == 2).sum() >= 1
    assert set(pk.source[ref.dropped].tolist()) == {SOURCE_PULSE, SOURCE_PAIR}


def test_pysim_merge_collision():
    """Decimation 2, pair checks on (the pair search 6 cycles behind): a pulse word and a
    pair word in the same cycle, the pair word written from the hold register the next
    cycle -- the first 8 triples of :data:`TRIPLES` (one collision), word for word."""
    p = both_params(cic_rate=2)
    x = TRIPLES[:4096 + 8 * 1600 + 1000]
    m = TacanFrontendModel(p)
    pk, _ = m.run(x)
    assert _collisions(m, pk) == 1
    dut = TacanFrontEnd(p)
    res = run_stream(dut, x, n_cycles=len(x) + 600, inputs={"freq": p.nco_freq_word})
    ref = m.fifo_output(pk, res.n_cycles)
    np.testing.assert_array_equal(res.words, ref.words)
    np.testing.assert_array_equal(res.cycles, ref.cycles)
    assert np.any(np.diff(res.cycles) == 1)             # the held word right behind


def _collision_cuts(m: TacanFrontendModel, pk) -> list[int]:
    """ADC sample indices just after the envelope sample emitting each colliding pair word
    (its pulse word comes from the next envelope sample)."""
    em = m.emit_cycles(pk)
    hit = np.flatnonzero((pk.source == SOURCE_PAIR) & np.isin(em, em[pk.source == SOURCE_PULSE]))
    d = m.params.decimation
    return sorted({int(c) for k in hit for c in (pk.end_index[k] + 1) * d + np.array([0, 1])})


def test_both_searches_chunking_across_a_collision():
    """Decimation 2: a call that ends just after the envelope sample that emits a pair word,
    whose pulse word of the same cycle comes from the next call's first sample. With
    ``final=False`` the pair word is held and the outputs put together equal one call's;
    with ``final=True`` it comes out before the pulse (the test can tell)."""
    m = TacanFrontendModel(both_params(cic_rate=2))
    pk, _ = m.run(TRIPLES)
    cuts = _collision_cuts(m, pk)
    assert len(cuts) == 4
    want = m.words(pk)
    for final, equal in ((False, True), (True, False)):
        st, parts = None, []
        for chunk in np.split(TRIPLES, sorted(cuts + [7, 12_345])):
            q, st = m.run(chunk, st, final=final)
            parts.append(q)
        q, st = m.run(TRIPLES[:0], st)                   # the end of the record
        parts.append(q)
        got = m.words(FrontendPeaks.concat(parts))
        assert np.array_equal(got, want) == equal and np.array_equal(np.sort(got), np.sort(want))
        assert st.held is None


def test_model_session_both_searches_in_steps():
    """The model session (streaming: emit cycles carried between steps) == the model on the
    whole record: steps cut at the collisions (checks on, a sample on every cycle), and steps
    of 4 samples with an idle cycle in them (checks off, :data:`VALID_11101`)."""
    from cosim.tacan.session import TacanModelSession
    n_flush = 800
    for checks in (False, True):
        p = both_params(cic_rate=2, checks=checks)
        m = TacanFrontendModel(p)
        pk, _ = m.run(TRIPLES)
        valid, n = COLLISIONS[checks]
        if valid is None:
            in_valid = np.ones(TRIPLES.size, bool)
            # after the emitting envelope sample; and a step ending with the collision's
            # cycle or the one before (one sample per cycle: the cycle is the sample index)
            em = m.emit_cycles(pk)
            cyc = m.peak_cycles(pk)
            late = cyc[cyc != em]
            cuts = _collision_cuts(m, pk) + [7, 12_345] + [int(c) for c in np.r_[late, late - 1]]
        else:
            in_valid = valid[:np.flatnonzero(valid)[TRIPLES.size - 1] + 1]
            cuts = []
        assert _collisions(m, pk, in_valid) == n
        # runs of in_valid, valid runs also cut at `cuts` (ADC sample indices)
        edges = np.flatnonzero(np.diff(in_valid.astype(np.int8))) + 1
        idx = np.cumsum(in_valid) - in_valid                 # ADC index at each cycle
        edges = np.union1d(edges, np.flatnonzero(in_valid & np.isin(idx, cuts)))
        bounds = np.r_[0, edges, in_valid.size]
        ref = m.fifo_output(pk, in_valid.size + n_flush, in_valid=in_valid)
        with TacanModelSession(p) as fe:
            got = []
            for a, b in zip(bounds[:-1], bounds[1:]):
                if in_valid[a]:
                    got.append(fe.step(TRIPLES[idx[a]:idx[a] + b - a]))
                else:
                    got.append(fe.step(None, n_cycles=int(b - a)))
            got.append(fe.step(None, n_cycles=n_flush))
        np.testing.assert_array_equal(np.concatenate([g.words for g in got]), ref.words)
        np.testing.assert_array_equal(np.concatenate([g.cycles for g in got]), ref.cycles)
        assert len(ref.words) == len(pk)


@pytest.mark.verilator
@verilator
@pytest.mark.parametrize("samples, stall", [(200_000, False), (400_000, True)])
def test_verilator_equals_model_both_searches(samples, stall):
    """Model == Verilator word for word (and cycle) with both searches."""
    p = both_params(fifo_depth=4) if stall else BOTH
    r = check_equivalence(samples=samples, backends=("model", "verilator"), seed=1,
                          stall=stall, params=p)
    assert r["backends"] == ["model", "verilator"]
    assert r["mismatches"] == 0, r
    assert r["peaks"] > 50
    if stall:
        assert r["dropped"] > 0 and r["markers"] > 0


def _verilator_words_with_stalls(p, m, pk, x, in_valid, n, name):
    """The Verilated top on ``x`` (valid ``in_valid``, DSP stalls) against the model's FIFO
    words for the peaks ``pk``: word for word and cycle; returns the model's words."""
    from cosim.backends.verilator import VerilatorStreamSim
    ready = stall_pattern(n, seed=5, burst=600)
    res = VerilatorStreamSim(TacanFrontEnd(p), name=name).run(
        x, in_valid=in_valid, out_ready=ready, n_cycles=n, inputs={"freq": p.nco_freq_word})
    ref = m.fifo_output(pk, n, in_valid=in_valid, out_ready=ready)
    np.testing.assert_array_equal(res.words, ref.words)
    np.testing.assert_array_equal(res.cycles, ref.cycles)
    return ref.words


@pytest.mark.verilator
@verilator
@pytest.mark.parametrize("checks", [True, False])
def test_verilator_merge_collisions(checks):
    """Decimation 2: the collisions of :data:`TRIPLES` (with the checks off they need the
    gaps in valid), with DSP stalls, on the Verilated top: word for word and cycle."""
    p = both_params(cic_rate=2, checks=checks, fifo_depth=8)
    m = TacanFrontendModel(p)
    pk, _ = m.run(TRIPLES)
    in_valid, hits = COLLISIONS[checks]
    assert _collisions(m, pk, in_valid) == hits
    words = _verilator_words_with_stalls(p, m, pk, TRIPLES, in_valid,
                                         TRIPLES.size * 3 // 2 + 2000, "tacan_frontend_both_d2")
    assert len(words) > 50


@pytest.mark.verilator
@verilator
def test_verilator_merge_collision_at_decimation_4():
    """Decimation 4, the default: a pulse word and a pair word meet only when valid has
    gaps (once in this 400k-sample record, :func:`test_collisions_follow_the_latency_difference`);
    the Verilated top, with DSP stalls, holds the pair word as the model does: word for word
    and cycle."""
    p = both_params(fifo_depth=8)
    m = TacanFrontendModel(p)
    x = tacan_record(400_000, seed=3)
    pk, _ = m.run(x)
    gaps = np.random.default_rng(3).random(len(x) * 2) < 0.6
    assert _collisions(m, pk, gaps) == 1
    n = int(np.flatnonzero(gaps)[len(x) - 1]) + 2000
    words = _verilator_words_with_stalls(p, m, pk, x, gaps[:n], n, "tacan_frontend_both_d4")
    assert len(words) > 200


@pytest.mark.verilator
@verilator
def test_exported_top_lints_clean_both_searches(tmp_path):
    from cosim.tools.verilog import export_verilog, lint
    for name, p in (("tacan_frontend_both", BOTH),
                    ("tacan_frontend_both_d2", both_params(cic_rate=2, checks=False))):
        assert lint(export_verilog(TacanFrontEnd(p), name=name, out_dir=tmp_path)) == [], name
