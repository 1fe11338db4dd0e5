"""Envelope (CORDIC vectoring magnitude): Amaranth sim == bit-exact model, accuracy, corners."""
from __future__ import annotations

import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from amaranth.back import verilog
from amaranth.hdl import Const, Module, ResetInserter, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In

from cosim.pysim import pack_fields, run_stream
from hdl.envelope import Envelope
from hdl.model.envelope import EnvelopeParams, envelope_model

BUILD = Path(__file__).resolve().parents[2] / "build" / "lint"


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


class _WithClear(wiring.Component):
    """The DUT with a synchronous ``clear`` input (reset in the middle of a run)."""

    def __init__(self, dut):
        self.dut = dut
        super().__init__({**dict(dut.signature.members), "clear": In(1)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = ResetInserter(self.clear)(self.dut)
        wiring.connect(m, wiring.flipped(self.i), self.dut.i)
        wiring.connect(m, self.dut.o, wiring.flipped(self.o))
        return m


def _lint(component, name):
    """Export to Verilog and lint with Verilator -Wall.

    Waived, because Amaranth's output always has them: UNUSEDSIGNAL (unused slices of
    internal nets), DECLFILENAME (module name vs file name), WIDTH (Amaranth compares and
    extends with unsized 1-bit constants such as ``$signed(1'h0)``).
    """
    if shutil.which("verilator") is None:
        pytest.skip("verilator not on PATH (install verilator >= 5)")
    # Amaranth 0.5 cannot take the constant ``ready`` of an always-ready stream as a port
    # (amaranth-lang/amaranth#1574), so list the ports without it.
    ports = [Value.cast(v) for _, _, v in component.signature.flatten(component)]
    ports = [v for v in ports if not isinstance(v, Const)]
    text = verilog.convert(component, name=name, ports=ports)
    BUILD.mkdir(parents=True, exist_ok=True)
    path = BUILD / f"{name}.v"
    path.write_text(text)
    r = subprocess.run(["verilator", "--lint-only", "-Wall", "-Wno-UNUSEDSIGNAL",
                        "-Wno-DECLFILENAME", "-Wno-WIDTH", str(path)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


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
    dut = _WithClear(Envelope(p))
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
    _lint(Envelope(EnvelopeParams(**kw)), "envelope" + ("_comp" if kw else ""))
