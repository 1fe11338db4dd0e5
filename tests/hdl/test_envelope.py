"""Envelope (CORDIC vectoring magnitude): Amaranth sim == bit-exact model, accuracy, corners;
the exported Verilog (Verilator) == Amaranth simulation == model."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.backends.pysim import pack_fields, run_stream
from hdl.envelope import Envelope
from hdl.model.envelope import EnvelopeParams, envelope_model, envelope_model_numpy

from _util import (WithClear, accepted_cycles, assert_lints_clean, assert_same_stream,
                   needs_verilator, verilator_sim)


def _layout(p):
    return [("i", p.in_width, True), ("q", p.in_width, True)]


def _random_iq(rng, p, n):
    lo, hi = -(1 << (p.in_width - 1)), 1 << (p.in_width - 1)
    return rng.integers(lo, hi, n), rng.integers(lo, hi, n)


def _full_scale_iq(p):
    fs = 1 << (p.in_width - 1)
    vals = np.array([-fs, -fs + 1, -1, 0, 1, fs - 1])
    i, q = np.meshgrid(vals, vals)
    return i.ravel(), q.ravel()


def _check_sim(p, i, q, in_valid=None):
    words = pack_fields({"i": i, "q": q}, _layout(p))
    res = run_stream(Envelope(p), words, in_valid=in_valid, flush_cycles=p.latency + 2)
    np.testing.assert_array_equal(res.words, envelope_model(i, q, p))
    return res


# -- simulation == model -------------------------------------------------------------------
def test_sim_matches_model_quick():
    p = EnvelopeParams()
    rng = np.random.default_rng(101)
    i, q = _random_iq(rng, p, 10_000)
    _check_sim(p, i, q)


@pytest.mark.slow
def test_sim_matches_model_1e5():
    p = EnvelopeParams()
    rng = np.random.default_rng(102)
    i, q = _random_iq(rng, p, 100_000)
    _check_sim(p, i, q)


@pytest.mark.parametrize("kw", [
    dict(compensate=True, rounding="half_up"),
    dict(in_width=8, iterations=6, out_width=5),          # saturating output, shift > 0
    dict(in_width=12, iterations=10, guard_bits=0),
    dict(in_width=10, out_width=14, rounding="half_up"),  # extra fraction bits, shift < 0
    dict(in_width=16, iterations=20, compensate=True, comp_bits=12, out_width=12),
])
def test_sim_matches_model_variants(kw):
    p = EnvelopeParams(**kw)
    rng = np.random.default_rng(103)
    i, q = _random_iq(rng, p, 3000)
    fi, fq = _full_scale_iq(p)
    _check_sim(p, np.concatenate((fi, i)), np.concatenate((fq, q)))


def test_full_scale_both_signs():
    for p in (EnvelopeParams(), EnvelopeParams(compensate=True)):
        i, q = _full_scale_iq(p)
        _check_sim(p, i, q)
        mag = envelope_model(i, q, p)
        assert mag.max() <= p.max_out
        # |z| max = sqrt(2)*2**17 must not saturate at the default width.
        exact = p.eff_gain * np.abs(i + 1j * q) / 2.0 ** p.shift
        assert np.all(np.abs(mag - exact) <= p.error_bound_lsb)


def test_gaps_in_valid_keep_latency():
    p = EnvelopeParams()
    rng = np.random.default_rng(104)
    i, q = _random_iq(rng, p, 2000)
    valid = rng.random(6000) < 0.4
    res = _check_sim(p, i, q, in_valid=valid)
    in_cycles = np.flatnonzero(valid)[:i.size]
    np.testing.assert_array_equal(res.cycles, in_cycles + p.latency)


def test_reset_drops_samples_in_flight():
    p = EnvelopeParams()
    rng = np.random.default_rng(105)
    n, c = 400, 200
    i, q = _random_iq(rng, p, n)
    dut = WithClear(Envelope(p))
    words = pack_fields({"i": i, "q": q}, _layout(p))
    res = run_stream(dut, words, writes=[(c, dut.clear, 1), (c + 1, dut.clear, 0)],
                     flush_cycles=p.latency + 2)
    # Samples taken at cycles c-latency+1 .. c are still in the pipeline when it clears.
    keep = np.ones(n, dtype=bool)
    keep[c - p.latency + 1:c + 1] = False
    np.testing.assert_array_equal(res.words, envelope_model(i[keep], q[keep], p))


# -- model accuracy ------------------------------------------------------------------------
@pytest.mark.parametrize("kw", [dict(), dict(compensate=True), dict(rounding="half_up"),
                                dict(in_width=12, iterations=8), dict(in_width=8,
                                                                      iterations=6,
                                                                      guard_bits=0)])
def test_model_accuracy_against_abs(kw):
    """``|mag - eff_gain*|z|/2**shift| <= error_bound_lsb`` (bound derived in its docstring)."""
    p = EnvelopeParams(**kw)
    rng = np.random.default_rng(106)
    i, q = _random_iq(rng, p, 1_000_000)
    fi, fq = _full_scale_iq(p)
    i, q = np.concatenate((fi, i)), np.concatenate((fq, q))
    mag = envelope_model(i, q, p)
    err = mag - p.eff_gain * np.abs(i + 1j * q) / 2.0 ** p.shift
    assert np.abs(err).max() <= p.error_bound_lsb
    # Default case: the bound is not loose by more than ~3x (it should stay meaningful).
    if not kw:
        assert p.error_bound_lsb < 2.5
        assert np.abs(err).max() > 0.9  # floor rounding alone costs up to 1 LSB


def test_gain_is_exact_product():
    assert EnvelopeParams(iterations=1).gain == pytest.approx(math.sqrt(2), abs=1e-15)
    g = math.prod(math.sqrt(1 + 2.0 ** (-2 * k)) for k in range(16))
    assert EnvelopeParams().gain == pytest.approx(g, rel=1e-15)
    assert EnvelopeParams(iterations=32).gain == pytest.approx(1.6467602581210654, rel=1e-12)
    p = EnvelopeParams(compensate=True)
    assert p.eff_gain == pytest.approx(1.0, abs=2.0 ** -p.comp_bits)
    assert EnvelopeParams().shift == 0 and EnvelopeParams().out_width == 19


@pytest.mark.parametrize("kw", [
    dict(), dict(in_width=18, iterations=12, rounding="half_up"),
    dict(compensate=True, rounding="half_up"), dict(in_width=8, iterations=6, out_width=5),
    dict(in_width=12, iterations=10, guard_bits=0), dict(in_width=10, out_width=14,
                                                         rounding="half_up"),
    dict(in_width=16, iterations=20, compensate=True, comp_bits=12, out_width=12),
    dict(in_width=30, iterations=32, guard_bits=16),        # int64 working width
])
def test_compiled_model_equals_numpy_reference(kw):
    """The compiled CORDIC == the numpy reference (int32/int64 block loops), on random
    and full-scale inputs, any shape and a length that is not a block multiple."""
    p = EnvelopeParams(**kw)
    rng = np.random.default_rng(107)
    i, q = _random_iq(rng, p, 100_003)
    fi, fq = _full_scale_iq(p)
    i, q = np.concatenate((fi, i)), np.concatenate((fq, q))
    np.testing.assert_array_equal(envelope_model(i, q, p), envelope_model_numpy(i, q, p))
    i2, q2 = i[:60_000].reshape(300, 200), q[:60_000].reshape(300, 200)
    np.testing.assert_array_equal(envelope_model(i2, q2, p), envelope_model_numpy(i2, q2, p))
    np.testing.assert_array_equal(envelope_model(i2.astype(np.int32), q2, p),
                                  envelope_model_numpy(i2, q2, p))
    assert envelope_model(i[:0], q[:0], p).shape == (0,)


def test_model_rejects_out_of_range_input():
    with pytest.raises(ValueError, match="envelope input must fit signed 18 bits"):
        envelope_model([1 << 17], [0], EnvelopeParams())


# -- parameters ----------------------------------------------------------------------------
@pytest.mark.parametrize("kw, msg", [
    (dict(in_width=1), r"envelope in_width must be an integer in \[2, 30\], not 1"),
    (dict(iterations=0), r"CORDIC iterations must be an integer in \[1, 32\], not 0"),
    (dict(guard_bits=-1), r"CORDIC guard_bits must be an integer in \[0, 16\], not -1"),
    (dict(rounding="half_even"), r"envelope rounding must be one of .*, not 'half_even'"),
    (dict(out_width=0), r"envelope out_width must be an integer in \[1, 40\], not 0"),
    (dict(in_width=8, guard_bits=2, out_width=12),
     r"envelope out_width must be <= natural width \+ guard_bits = 11, not 12"),
    (dict(compensate=1), r"compensate must be a bool, not 1"),
])
def test_bad_params(kw, msg):
    with pytest.raises(ValueError, match=msg):
        EnvelopeParams(**kw)


@pytest.mark.verilator
@pytest.mark.parametrize("kw", [dict(), dict(compensate=True, rounding="half_up")])
def test_verilog_lints_clean(kw):
    """Waived: cosim.tools.verilog.LINT_WAIVERS (UNUSEDSIGNAL, DECLFILENAME, WIDTH: Amaranth
    compares and extends with unsized 1-bit constants such as ``$signed(1'h0)``)."""
    assert_lints_clean(Envelope(EnvelopeParams(**kw)), "envelope" + ("_comp" if kw else ""))


#: Compiled with Verilator: the default envelope and the gain-compensated one.
VL_PARAMS = {"plain": EnvelopeParams(), "comp": EnvelopeParams(compensate=True, rounding="half_up")}


@pytest.fixture(scope="module", params=sorted(VL_PARAMS))
def vl_envelope(request):
    p = VL_PARAMS[request.param]
    dut = Envelope(p)
    return p, dut, verilator_sim(dut, f"envelope_{request.param}_vl")


def _vl_stimulus(p, rng, n, p_valid):
    """Full-scale corners, then random I/Q; random gaps in valid."""
    fi, fq = _full_scale_iq(p)
    i, q = _random_iq(rng, p, n - fi.size)
    i, q = np.concatenate((fi, i)), np.concatenate((fq, q))
    return i, q, rng.random(int(n / p_valid) + 100) < p_valid


@needs_verilator
def test_verilator_matches_pysim(vl_envelope):
    """Like the gaps test: sparse valid (40 %), plus full-scale corners."""
    p, dut, sim = vl_envelope
    i, q, valid = _vl_stimulus(p, np.random.default_rng(110), 2000, 0.4)
    words = pack_fields({"i": i, "q": q}, _layout(p))
    kw = dict(in_valid=valid, flush_cycles=p.latency + 2)
    want = run_stream(dut, words, **kw)
    got = sim.run(words, **kw)
    assert_same_stream(got, want, "verilator vs pysim")
    assert len(got.words) == i.size


@needs_verilator
def test_verilator_matches_model_long(vl_envelope):
    p, _, sim = vl_envelope
    i, q, valid = _vl_stimulus(p, np.random.default_rng(111), 1_000_000, 0.7)
    res = sim.run(pack_fields({"i": i, "q": q}, _layout(p)), in_valid=valid,
                  flush_cycles=p.latency + 2)
    np.testing.assert_array_equal(res.words, envelope_model(i, q, p))
    np.testing.assert_array_equal(res.cycles, accepted_cycles(i.size, valid) + p.latency)
