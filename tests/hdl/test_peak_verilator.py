"""Pulse-peak search, exported Verilog: lints clean, and Verilator == Amaranth simulation ==
model (default, censored floor, partner readout, pair detection, pair checks, fractional
floor)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cosim.backends.pysim import run_stream, unpack_fields
from dsp.tacan.peak_params import PeakParams
from hdl.tacan.peak_model import peak_search
from hdl.tacan.peak import PeakSearch

from _util import (accepted_cycles, assert_lints_clean, assert_same_stream, needs_verilator,
                   verilator_sim)
from _peak_util import (TACAN_X_PAIR, assert_checks_bite, checked_envelope, pair_envelope,
                        pair_sum, realistic_envelope)


# -- exported Verilog: Verilator == Amaranth simulation == model ---------------------------
@pytest.mark.verilator
def test_verilog_lints_clean():
    """Waived: cosim.verilog.LINT_WAIVERS (UNUSEDSIGNAL, DECLFILENAME, WIDTH)."""
    assert_lints_clean(PeakSearch(PeakParams()), "peak_search")


#: Compiled with Verilator: the default (TACAN) configuration.
VL_PARAMS = PeakParams()


@pytest.fixture(scope="module")
def vl_peak():
    dut = PeakSearch(VL_PARAMS)
    return dut, verilator_sim(dut, "peak_search_vl")


def _vl_stimulus(rng, n, p_valid):
    """Realistic envelope with a continuous carrier (max_len cuts); random gaps in valid."""
    e = realistic_envelope(rng, n)
    e[n // 2:n // 2 + 700] = 2500
    return e, rng.random(int(n / p_valid) + 100) < p_valid


@needs_verilator
def test_verilator_matches_pysim(vl_peak):
    dut, sim = vl_peak
    p = VL_PARAMS
    e, valid = _vl_stimulus(np.random.default_rng(240), 5000, 0.6)
    kw = dict(in_valid=valid, flush_cycles=p.latency + 2)
    want = run_stream(dut, e, **kw)
    got = sim.run(e, **kw)
    assert_same_stream(got, want, "verilator vs pysim")
    assert len(got.words) > 20


@needs_verilator
def test_verilator_matches_model_long(vl_peak):
    _, sim = vl_peak
    p = VL_PARAMS
    e, valid = _vl_stimulus(np.random.default_rng(241), 1_000_000, 0.7)
    res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
    f = unpack_fields(res.words, p.out_layout)
    ref, _ = peak_search(e, p)
    assert ref.amplitude.size > 10_000
    np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
    np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
    np.testing.assert_array_equal(res.cycles,
                                  accepted_cycles(e.size, valid)[ref.end_index] + p.latency)


#: The censored noise floor (``clip_to_floor``) compiled with Verilator as well.
VL_CENSORED = PeakParams(clip_to_floor=True, thr_mult=52)


@needs_verilator
def test_verilator_matches_model_censored_floor():
    sim = verilator_sim(PeakSearch(VL_CENSORED), "peak_search_censored_vl")
    p = VL_CENSORED
    e, valid = _vl_stimulus(np.random.default_rng(242), 200_000, 0.7)
    res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
    f = unpack_fields(res.words, p.out_layout)
    ref, _ = peak_search(e, p)
    plain, _ = peak_search(e, PeakParams(thr_mult=52))
    assert ref.amplitude.size > 1000
    # the option changes the floor (else this test would not test it)
    assert not np.array_equal(ref.thresholds, plain.thresholds)
    np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
    np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
    np.testing.assert_array_equal(res.cycles,
                                  accepted_cycles(e.size, valid)[ref.end_index] + p.latency)


#: The pair-partner readout (TACAN X mode: 12 us of 5 MHz envelope samples) with Verilator.
VL_PARTNER = PeakParams(partner_offset=60)


@needs_verilator
def test_verilator_matches_model_partner_readout():
    sim = verilator_sim(PeakSearch(VL_PARTNER), "peak_search_partner_vl")
    p = VL_PARTNER
    e, valid = _vl_stimulus(np.random.default_rng(243), 200_000, 0.7)
    res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
    f = unpack_fields(res.words, p.out_layout)
    ref, _ = peak_search(e, p)
    assert ref.amplitude.size > 1000
    for k in ("amplitude", "timestamp", "partner", "partner_late"):
        np.testing.assert_array_equal(f[k], getattr(ref, k))
    np.testing.assert_array_equal(res.cycles, accepted_cycles(e.size, valid)[
        ref.end_index + p.partner_offset] + p.latency)


@pytest.mark.verilator
@pytest.mark.parametrize("D", [60, 1])
def test_verilog_lints_clean_pair_detection(D):
    """The pair detection (TACAN X mode; and D = 1, a one-word memory)."""
    p = TACAN_X_PAIR if D == 60 else PeakParams(pair_offset=1)
    assert_lints_clean(PeakSearch(p), f"peak_search_pair{D}")


#: The pulse-pair detection (TACAN X mode: 12 us of 5 MHz envelope samples, censored floor)
#: with Verilator.
VL_PAIR = TACAN_X_PAIR


@needs_verilator
def test_verilator_matches_model_pair_detection():
    sim = verilator_sim(PeakSearch(VL_PAIR), "peak_search_pair_vl")
    p = VL_PAIR
    rng = np.random.default_rng(320)
    n = 200_000
    e = pair_envelope(rng, n, p.pair_offset)
    valid = rng.random(int(n / 0.7) + 100) < 0.7
    res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
    f = unpack_fields(res.words, p.out_layout)
    ref, _ = peak_search(e, p)
    inner, _ = peak_search(pair_sum(e, p.pair_offset), p.search_params)
    # the side-lobe rule drops many of the search's pulses and keeps most pairs
    assert ref.amplitude.size > 1000 and inner.amplitude.size - ref.amplitude.size > 500
    np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
    np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
    np.testing.assert_array_equal(res.cycles, accepted_cycles(e.size, valid)[
        ref.end_index + p.emit_delay] + p.latency)


@pytest.mark.verilator
def test_verilog_lints_clean_pair_checks():
    """The pair checks (TACAN X mode, balance 4, spread 8; and D = 1, spread 1)."""
    assert_lints_clean(PeakSearch(replace(TACAN_X_PAIR, pair_balance=4, pair_spread=8)),
                       "peak_search_pair_checks")
    assert_lints_clean(PeakSearch(PeakParams(pair_offset=1, pair_balance=8, pair_spread=1)),
                       "peak_search_pair_checks1")


#: The pair checks (balance 4, spread 8) on the TACAN X-mode pair detection with Verilator.
VL_PAIR_CHECKED = PeakParams(pair_offset=60, clip_to_floor=True, smooth_log2=10, thr_mult=46,
                             pair_balance=4, pair_spread=8)


@needs_verilator
def test_verilator_matches_model_pair_checks():
    """2e5 samples: pairs 60 apart, single pulses and 15-us-like pairs 75 apart; gaps."""
    sim = verilator_sim(PeakSearch(VL_PAIR_CHECKED), "peak_search_pair_checks_vl")
    p = VL_PAIR_CHECKED
    rng = np.random.default_rng(350)
    n = 200_000
    e = checked_envelope(rng, n, p.pair_offset, other=75, width=19.0)
    valid = rng.random(int(n / 0.7) + 100) < 0.7
    res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
    f = unpack_fields(res.words, p.out_layout)
    ref = assert_checks_bite(p, e)
    assert ref.amplitude.size > 500
    np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
    np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
    np.testing.assert_array_equal(res.cycles, accepted_cycles(e.size, valid)[
        ref.end_index + p.emit_delay] + p.latency)


#: The floor with fraction bits (floor_frac) on the TACAN X-mode pair detection with its pair
#: checks (dsp.tacan.frontend.PAIR_DETECTOR) with Verilator.
VL_PAIR_FRAC = replace(VL_PAIR_CHECKED, floor_frac=True)


@pytest.mark.verilator
def test_verilog_lints_clean_floor_frac():
    assert_lints_clean(PeakSearch(VL_PAIR_FRAC), "peak_search_pair_frac")
    assert_lints_clean(PeakSearch(PeakParams(floor_frac=True)), "peak_search_frac")


@needs_verilator
def test_verilator_matches_model_floor_frac():
    """2e5 samples, gaps in valid: the pair detection with floor_frac, and the single-pulse
    search with floor_frac (smooth_log2 6: the fraction bits move the floor within the run)."""
    rng = np.random.default_rng(352)
    n = 200_000
    for name, p, e in (
            ("peak_search_pair_frac_vl", VL_PAIR_FRAC,
             checked_envelope(rng, n, VL_PAIR_FRAC.pair_offset, other=75, width=19.0)),
            ("peak_search_frac_vl", PeakParams(smooth_log2=6, floor_frac=True),
             _vl_stimulus(rng, n, 0.7)[0])):
        sim = verilator_sim(PeakSearch(p), name)
        valid = rng.random(int(n / 0.7) + 100) < 0.7
        res = sim.run(e, in_valid=valid, flush_cycles=p.latency + 2)
        f = unpack_fields(res.words, p.out_layout)
        ref, _ = peak_search(e, p)
        plain, _ = peak_search(e, replace(p, floor_frac=False))
        assert ref.amplitude.size > 500
        assert not np.array_equal(ref.thresholds, plain.thresholds)
        np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
        np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
        np.testing.assert_array_equal(res.cycles, accepted_cycles(e.size, valid)[
            ref.end_index + p.emit_delay] + p.latency)
