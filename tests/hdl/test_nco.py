"""NCO: Amaranth simulation == bit-exact model, table symmetry, frequency words, SFDR, lint;
the exported Verilog (Verilator) == Amaranth simulation == model."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.backends.pysim import run_stream, unpack_fields
from hdl.model.nco import (LFSR_BITS, NcoModel, NcoParams, NcoState, lfsr_bits,
                           nco_freq_word, nco_full_tables, nco_quarter_table)
from hdl.nco import Nco

from _util import (WithClear, accepted_cycles, assert_lints_clean, assert_same_stream,
                   needs_verilator, verilator_sim)


def _layout(p: NcoParams):
    return [("cos", p.amp_bits, True), ("sin", p.amp_bits, True)]


def _port_at(cycles, writes, port, default=0) -> np.ndarray:
    """Value of ``port`` at each cycle, given run_stream ``writes``."""
    ws = sorted((c, v) for c, pt, v in writes if pt is port)
    out = np.full(len(cycles), default, dtype=np.int64)
    for c, v in ws:
        out[cycles >= c] = v
    return out


def _run_nco(p: NcoParams, n: int, writes, in_valid=None, dut=None):
    dut = Nco(p) if dut is None else dut
    res = run_stream(dut, np.zeros(n, dtype=np.int64), in_valid=in_valid, writes=writes,
                     flush_cycles=p.latency + 4)
    f = unpack_fields(res.words, _layout(p))
    return f["cos"], f["sin"], res


def _model_for(p: NcoParams, n: int, writes, in_valid, dut):
    cyc = accepted_cycles(n, in_valid)
    fw = _port_at(cyc, writes, dut.freq)
    po = _port_at(cyc, writes, dut.phase) if p.phase_port else 0
    return NcoModel(p).run(n, fw, phase_offset=po)


def _random_stimulus(p: NcoParams, dut, rng, n: int, n_writes: int = 12):
    """Run-time frequency (and phase) writes at random cycles, random gaps in valid."""
    writes = [(0, dut.freq, int(rng.integers(0, 1 << p.phase_bits)))]
    for c in np.sort(rng.choice(n, n_writes, replace=False)):
        writes.append((int(c), dut.freq, int(rng.integers(0, 1 << p.phase_bits))))
        if p.phase_port:
            writes.append((int(c) + 3, dut.phase, int(rng.integers(0, 1 << p.phase_bits))))
    in_valid = rng.random(n + n // 3) < 0.75
    return writes, in_valid


@pytest.mark.parametrize("seed,p", [
    (1, NcoParams()),
    (2, NcoParams(dither_bits=7)),
    (3, NcoParams(phase_bits=12, table_bits=8, amp_bits=9, dither_bits=4, phase_port=True)),
    (4, NcoParams(phase_bits=20, table_bits=3, amp_bits=2)),
    (5, NcoParams(phase_bits=10, table_bits=10, amp_bits=12, phase_port=True)),
])
def test_sim_matches_model_random(seed, p):
    """Random run-time frequency/phase writes and random gaps in valid."""
    rng = np.random.default_rng(seed)
    n = 6000
    dut = Nco(p)
    writes, in_valid = _random_stimulus(p, dut, rng, n)
    cos, sin, res = _run_nco(p, n, writes, in_valid, dut)
    mc, ms, _ = _model_for(p, n, writes, in_valid, dut)
    assert len(cos) == n, f"seed {seed}"
    np.testing.assert_array_equal(cos, mc, err_msg=f"seed {seed}")
    np.testing.assert_array_equal(sin, ms, err_msg=f"seed {seed}")
    # Fixed latency, whatever the gaps.
    np.testing.assert_array_equal(res.cycles, accepted_cycles(n, in_valid) + p.latency)


def test_frequency_change_mid_run_negative_and_wrap():
    """Positive then negative (two's complement) frequency, written while running; the
    32-bit accumulator wraps many times with a near-Nyquist word."""
    p = NcoParams()
    dut = Nco(p)
    f_pos = nco_freq_word(9.9e6, f_clk_hz=20e6, phase_bits=32).word   # wraps every ~2 steps
    f_neg = nco_freq_word(-1.25e6, f_clk_hz=20e6, phase_bits=32).word
    assert f_neg > 1 << 31
    n = 3000
    writes = [(0, dut.freq, f_pos), (1234, dut.freq, f_neg), (2222, dut.freq, 0)]
    cos, sin, _ = _run_nco(p, n, writes, None, dut)
    fw = _port_at(np.arange(n), writes, dut.freq)
    mc, ms, st = NcoModel(p).run(n, fw)
    np.testing.assert_array_equal(cos, mc)
    np.testing.assert_array_equal(sin, ms)
    # The negative-frequency segment turns clockwise: sin leads cos by -90 deg, i.e. the
    # phase of cos + j*sin decreases by 2*pi*1.25/20 per step.
    seg = slice(1240, 2200)
    z = cos[seg] + 1j * sin[seg]
    dphi = np.angle(z[1:] * np.conj(z[:-1]))
    np.testing.assert_allclose(dphi, -2 * np.pi * 1.25 / 20, atol=2 * np.pi / 1024)
    # After freq=0 the phase is frozen.
    assert np.all(cos[2230:] == cos[2230]) and np.all(sin[2230:] == sin[2230])
    expected_acc = (1234 * f_pos + (2222 - 1234) * f_neg) % (1 << 32)
    assert st == NcoState(acc=expected_acc, lfsr=p.dither_seed)


def test_accumulator_wraparound_small():
    """An 8-bit accumulator with freq 0x70 wraps every 2-3 steps; the phase is exact mod 256."""
    p = NcoParams(phase_bits=8, table_bits=8, amp_bits=10)
    dut = Nco(p)
    n = 600
    cos, sin, _ = _run_nco(p, n, [(0, dut.freq, 0x70)], None, dut)
    ct, st_ = nco_full_tables(p)
    addr = (np.arange(n) * 0x70) % 256
    np.testing.assert_array_equal(cos, ct[addr])
    np.testing.assert_array_equal(sin, st_[addr])


def test_dither_on_off():
    """Dither changes the output bits but not the frequency; with dither off the output is
    periodic with the frequency word's period, with dither on it is not."""
    f = 0x0123_4567
    base = NcoParams(phase_bits=32, table_bits=10, amp_bits=16)
    dith = NcoParams(phase_bits=32, table_bits=10, amp_bits=16, dither_bits=12)
    n = 2000
    out = {}
    for name, p in (("off", base), ("on", dith)):
        dut = Nco(p)
        c, s, _ = _run_nco(p, n, [(0, dut.freq, f)], None, dut)
        mc, ms, _ = NcoModel(p).run(n, f)
        np.testing.assert_array_equal(c, mc)
        np.testing.assert_array_equal(s, ms)
        out[name] = (c, s)
    assert np.count_nonzero(out["on"][0] != out["off"][0]) > n // 20
    # Same carrier: mean phase difference ~0 (dither is signed, nearly zero-mean).
    z_off = out["off"][0] + 1j * out["off"][1]
    z_on = out["on"][0] + 1j * out["on"][1]
    assert abs(np.angle(np.mean(z_on * np.conj(z_off)))) < 2 * np.pi / 1024 / 4
    # Dither words are spread over their full signed range and are nearly zero-mean.
    d, _ = NcoModel(dith).dither(100_000)
    assert d.min() == -2048 and d.max() == 2047 and abs(d.mean()) < 10


def test_reset_restarts_phase_and_dither():
    """A synchronous reset mid-run restarts accumulator, LFSR and pipeline."""
    p = NcoParams(dither_bits=6)
    dut = WithClear(Nco(p))
    n1, n2, gap, clear_at = 500, 500, 12, 505
    in_valid = np.r_[np.ones(n1, bool), np.zeros(gap, bool), np.ones(n2, bool)]
    f = 0x1357_9BDF
    res = run_stream(dut, np.zeros(n1 + n2, dtype=np.int64), in_valid=in_valid,
                     writes=[(0, dut.freq, f), (clear_at, dut.clear, 1), (clear_at + 1, dut.clear, 0)])
    got = unpack_fields(res.words, _layout(p))
    mc, ms, _ = NcoModel(p).run(n1, f)
    np.testing.assert_array_equal(got["cos"], np.r_[mc, mc])
    np.testing.assert_array_equal(got["sin"], np.r_[ms, ms])


# -- model-only ----------------------------------------------------------------------------

def test_quarter_table_symmetry_and_accuracy():
    p = NcoParams(table_bits=10, amp_bits=16)
    q = nco_quarter_table(p)
    assert len(q) == 256 and q.min() >= 0 and q.max() <= p.peak
    assert len(np.unique(q)) == len(q)  # half-LSB offset: no duplicated entry
    c, s = nco_full_tables(p)
    N = 1 << p.table_bits
    a = np.arange(N)
    theta = 2 * np.pi * (a + 0.5) / N
    assert np.max(np.abs(s - p.peak * np.sin(theta))) <= 0.5
    assert np.max(np.abs(c - p.peak * np.cos(theta))) <= 0.5
    # Exact symmetries of the bin-centred table.
    np.testing.assert_array_equal(s[(a + N // 2) % N], -s)
    np.testing.assert_array_equal(s[N - 1 - a], -s)
    np.testing.assert_array_equal(c[(a + N // 4) % N], -s)
    np.testing.assert_array_equal(c[N - 1 - a], c)


def test_lfsr_matches_recurrence():
    seed = 0x1234_5678_9ABC_DEF
    bits = lfsr_bits(seed, 4000)
    ref = [(seed >> j) & 1 for j in range(LFSR_BITS)]
    for m in range(LFSR_BITS, 4000):
        ref.append(ref[m - 63] ^ ref[m - 62])
    np.testing.assert_array_equal(bits, ref)


@pytest.mark.parametrize("p", [NcoParams(), NcoParams(dither_bits=9), NcoParams(phase_bits=13, table_bits=9)])
def test_model_chunking(p):
    rng = np.random.default_rng(11)
    n = 50_000
    fw = rng.integers(0, 1 << p.phase_bits, n)
    m = NcoModel(p)
    c, s, st = m.run(n, fw)
    cuts = [0, 1, 777, 20_000, 20_001, n]
    state = None
    parts = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        pc, ps, state = m.run(b - a, fw[a:b], state)
        parts.append((pc, ps))
    np.testing.assert_array_equal(np.concatenate([x[0] for x in parts]), c)
    np.testing.assert_array_equal(np.concatenate([x[1] for x in parts]), s)
    assert state == st
    # A constant word equals the same word as an array; negative words are two's complement.
    c1, s1, st1 = m.run(1000, -12345)
    c2, s2, st2 = m.run(1000, np.full(1000, (1 << p.phase_bits) - 12345))
    np.testing.assert_array_equal(c1, c2)
    np.testing.assert_array_equal(s1, s2)
    assert st1 == st2


def _sfdr_db(x: np.ndarray) -> float:
    spec = np.abs(np.fft.fft(x)) ** 2
    k = int(np.argmax(spec))
    carrier = spec[k]
    spec = spec.copy()
    spec[k] = 0
    return 10 * np.log10(carrier / spec.max())


def test_sfdr_table_bits_10():
    """Spurious-free dynamic range of the complex NCO output, table_bits=10, amp_bits=16.

    Phase truncation to T bits bounds the worst spur at -6.02*T + 3.92 dBc (Nicholas &
    Samueli 1987), i.e. SFDR >= 56.3 dB for T = 10; the half-LSB table offset only adds a
    constant phase. 16-bit amplitude rounding is far lower (~ -100 dBc). Measured with
    coherent FFTs (no window) of 2**16 samples: 60.2 dB for words on FFT bins (dropped bits
    a multiple of 2**16), 56.3 dB -- the theory exactly -- when the dropped 22 bits are
    half a table LSB (the worst case), and 89-90 dB with 12 bits of dither. Asserted: the
    theory with 0.3 dB of slack, and dither at least 25 dB better.
    """
    p = NcoParams(table_bits=10, amp_bits=16)
    pd = NcoParams(table_bits=10, amp_bits=16, dither_bits=12)
    n = 1 << 16
    rng = np.random.default_rng(5)
    bins = [1, 3, 7, 129, 1001, 4097, 12345] + list(rng.integers(1, n // 2, 6) | 1)
    words = [int(b) * ((1 << 32) // n) for b in bins]
    # Half a table LSB in the dropped bits: period 2048 steps, still coherent in n.
    words += [k * (1 << 22) + (1 << 21) for k in (37, 101, 255)]
    worst, worst_d = np.inf, np.inf
    for word in words:
        c, s, _ = NcoModel(p).run(n, word)
        worst = min(worst, _sfdr_db(c + 1j * s))
        cd, sd, _ = NcoModel(pd).run(n, word)
        worst_d = min(worst_d, _sfdr_db(cd + 1j * sd))
    bound = 6.02 * p.table_bits - 3.92 - 0.3
    assert worst >= bound, f"SFDR {worst:.1f} dB < {bound:.1f} dB"
    assert worst < bound + 1.5  # the worst-case words really reach the bound
    assert worst_d >= worst + 25, f"dithered SFDR {worst_d:.1f} dB vs {worst:.1f} dB"


# -- frequency words -----------------------------------------------------------------------

def test_freq_word_values():
    fw = nco_freq_word(3e6, f_clk_hz=20e6, phase_bits=32)
    assert fw.word == round(3e6 / 20e6 * 2**32) == 644245094
    assert abs(fw.actual_hz - 644245094 * 20e6 / 2**32) < 1e-9
    assert abs(fw.error_hz) <= 20e6 / 2**33
    assert math.isclose(fw.error_ppm, fw.error_hz / 3e6 * 1e6)
    neg = nco_freq_word(-3e6, f_clk_hz=20e6, phase_bits=32)
    assert neg.word == 2**32 - 644245094 and neg.actual_hz == -fw.actual_hz
    assert nco_freq_word(0.0, f_clk_hz=20e6, phase_bits=32) == (0, 0.0, 0.0, 0.0)
    # Exact at 62 bits (float64 alone would lose the low bits).
    w62 = nco_freq_word(1.0, f_clk_hz=3.0, phase_bits=62)
    assert w62.word == ((1 << 62) + 1) // 3  # round(2**62 / 3) in integers


@pytest.mark.parametrize("kwargs,match", [
    (dict(f_hz=10e6, f_clk_hz=20e6, phase_bits=32), r"frequency word out of range.*10000000"),
    (dict(f_hz=-10e6, f_clk_hz=20e6, phase_bits=32), r"frequency word out of range"),
    (dict(f_hz=9.999999e6, f_clk_hz=20e6, phase_bits=8), r"frequency word out of range.*rounds to the Nyquist"),
    (dict(f_hz=float("nan"), f_clk_hz=20e6, phase_bits=32), r"f_hz must be a finite number, not nan"),
    (dict(f_hz=1e6, f_clk_hz=float("inf"), phase_bits=32), r"f_clk_hz must be a finite number"),
    (dict(f_hz=1e6, f_clk_hz=0.0, phase_bits=32), r"f_clk_hz must be > 0, not 0.0"),
    (dict(f_hz=1e6, f_clk_hz=-20e6, phase_bits=32), r"f_clk_hz must be > 0"),
    (dict(f_hz=1e6, f_clk_hz=20e6, phase_bits=2), r"phase_bits must be an integer in \[3, 62\], not 2"),
])
def test_freq_word_errors(kwargs, match):
    f = kwargs.pop("f_hz")
    with pytest.raises(ValueError, match=match):
        nco_freq_word(f, **kwargs)


# -- parameters ----------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs,match", [
    (dict(phase_bits=2), r"NCO phase_bits must be an integer in \[3, 62\], not 2"),
    (dict(phase_bits=63), r"NCO phase_bits must be an integer in \[3, 62\], not 63"),
    (dict(table_bits=2), r"NCO table_bits must be an integer in \[3, 20\], not 2"),
    (dict(amp_bits=1), r"NCO amp_bits must be an integer in \[2, 32\], not 1"),
    (dict(amp_bits=16.0), r"NCO amp_bits must be an integer, not 16.0"),
    (dict(phase_bits=10, table_bits=12), r"NCO LUT larger than the phase width.*table_bits=12 > phase_bits=10"),
    (dict(phase_bits=12, table_bits=10, dither_bits=3), r"dither_bits must be an integer in .* = \[0, 2\], not 3"),
    (dict(dither_bits=-1), r"dither_bits must be an integer in .*, not -1"),
    (dict(dither_seed=0), r"dither_seed must be a nonzero 63-bit integer, not 0"),
    (dict(dither_seed=1 << 63), r"dither_seed must be a nonzero 63-bit integer"),
    (dict(phase_port=1), r"phase_port must be a bool, not 1"),
])
def test_bad_params(kwargs, match):
    with pytest.raises(ValueError, match=match):
        NcoParams(**kwargs)


def test_bad_model_inputs():
    m = NcoModel(NcoParams())
    with pytest.raises(ValueError, match=r"freq_word must be a scalar or have shape \(10,\), not \(9,\)"):
        m.run(10, np.zeros(9, dtype=np.int64))
    with pytest.raises(ValueError, match=r"phase_offset needs NcoParams\(phase_port=True\)"):
        m.run(10, 1, phase_offset=5)
    with pytest.raises(ValueError, match=r"Nco needs an NcoParams"):
        Nco(16)


# -- Verilog -------------------------------------------------------------------------------

@pytest.mark.verilator
@pytest.mark.parametrize("name,p", [("nco", NcoParams()),
                                    ("nco_dither_phase", NcoParams(dither_bits=8, phase_port=True))])
def test_verilog_lint(name, p):
    # Waived: only cosim.tools.verilog.LINT_WAIVERS less WIDTH (the NCO is clean of it).
    assert_lints_clean(Nco(p), name, check_width=True)


#: The configuration compiled with Verilator: dither and the phase port exercise every path.
VL_PARAMS = NcoParams(dither_bits=8, phase_port=True)


@pytest.fixture(scope="module")
def vl_nco():
    dut = Nco(VL_PARAMS)
    return dut, verilator_sim(dut, "nco_vl")


@needs_verilator
def test_verilator_matches_pysim(vl_nco):
    """Same stimulus as the random sim test: frequency/phase writes, gaps in valid."""
    dut, sim = vl_nco
    p = VL_PARAMS
    rng = np.random.default_rng(21)
    n = 3000
    writes, in_valid = _random_stimulus(p, dut, rng, n)
    kw = dict(in_valid=in_valid, writes=writes, flush_cycles=p.latency + 4)
    want = run_stream(dut, np.zeros(n, dtype=np.int64), **kw)
    got = sim.run(np.zeros(n, dtype=np.int64), **kw)
    assert_same_stream(got, want, "verilator vs pysim")
    assert len(got.words) == n


@needs_verilator
def test_verilator_matches_model_long(vl_nco):
    """1e6 steps with 40 run-time frequency and phase writes and random gaps."""
    dut, sim = vl_nco
    p = VL_PARAMS
    rng = np.random.default_rng(22)
    n = 1_000_000
    writes, in_valid = _random_stimulus(p, dut, rng, n, n_writes=40)
    res = sim.run(np.zeros(n, dtype=np.int64), in_valid=in_valid, writes=writes,
                  flush_cycles=p.latency + 4)
    f = unpack_fields(res.words, _layout(p))
    mc, ms, _ = _model_for(p, n, writes, in_valid, dut)
    np.testing.assert_array_equal(f["cos"], mc)
    np.testing.assert_array_equal(f["sin"], ms)
    np.testing.assert_array_equal(res.cycles, accepted_cycles(n, in_valid) + p.latency)
