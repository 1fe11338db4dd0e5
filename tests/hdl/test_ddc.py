"""DDC (NCO + mixer): Amaranth simulation == bit-exact model, run-time tuning, gaps, reset,
full scale, baseband sanity, errors, lint; the exported Verilog (Verilator) == Amaranth
simulation == model."""
from __future__ import annotations

import numpy as np
import pytest

from amaranth.hdl import Module, signed
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from cosim.backends.pysim import run_stream, unpack_fields
from hdl.ddc import Ddc
from hdl.common import iq_layout
from hdl.model.ddc import DdcModel, DdcParams
from hdl.model.mixer import MixerParams
from hdl.model.nco import NcoModel, NcoParams, nco_freq_word
from hdl.nco import Nco

from _util import (WithClear, accepted_cycles, assert_lints_clean, assert_same_stream,
                   needs_verilator, verilator_sim)

F_CLK = 20e6


def _freq_at(cycles, writes, port) -> np.ndarray:
    out = np.zeros(len(cycles), dtype=np.int64)
    for c, pt, v in sorted(writes, key=lambda w: w[0]):
        if pt is port:
            out[cycles >= c] = v
    return out


def _sim(dut, p: DdcParams, x, writes, in_valid=None, run=None):
    """Run ``dut`` (with ``run_stream``, or ``run``: a Verilator simulator's ``run``)."""
    w = np.asarray(x, dtype=np.int64) & ((1 << p.adc_width) - 1)
    kw = dict(in_valid=in_valid, writes=writes, flush_cycles=p.latency + 4)
    res = run_stream(dut, w, **kw) if run is None else run(w, **kw)
    o = unpack_fields(res.words, [("i", p.out_width, True), ("q", p.out_width, True)])
    return o["i"], o["q"], res


def _random_stimulus(p: DdcParams, dut, rng, n: int, n_writes: int = 10):
    """Random ADC words (10 % at full scale), random gaps, frequency rewritten ``n_writes``
    times."""
    a = p.adc_width
    x = rng.integers(-(1 << (a - 1)), 1 << (a - 1), n)
    fs = rng.random(n) < 0.1
    x[fs] = rng.choice([-(1 << (a - 1)), (1 << (a - 1)) - 1], np.count_nonzero(fs))
    writes = [(0, dut.freq, nco_freq_word(3e6, f_clk_hz=F_CLK, phase_bits=p.freq_width).word)]
    for c in np.sort(rng.choice(n, n_writes, replace=False)):
        writes.append((int(c), dut.freq, int(rng.integers(0, 1 << p.freq_width))))
    in_valid = rng.random(n + n // 4) < 0.8
    return x, writes, in_valid


def _check_random(p: DdcParams, n: int, seed: int):
    """Random ADC words (10 % at full scale), random gaps, frequency rewritten 10 times."""
    rng = np.random.default_rng(seed)
    dut = Ddc(p)
    x, writes, in_valid = _random_stimulus(p, dut, rng, n)
    i, q, res = _sim(dut, p, x, writes, in_valid)
    cyc = accepted_cycles(n, in_valid)
    mi, mq, _ = DdcModel(p).run(x, _freq_at(cyc, writes, dut.freq))
    assert len(i) == n, f"seed {seed}"
    np.testing.assert_array_equal(i, mi, err_msg=f"seed {seed}")
    np.testing.assert_array_equal(q, mq, err_msg=f"seed {seed}")
    np.testing.assert_array_equal(res.cycles, cyc + p.latency, err_msg=f"seed {seed}")


@pytest.mark.parametrize("seed,p", [
    (1, DdcParams()),
    (2, DdcParams(nco=NcoParams(dither_bits=10), mixer=MixerParams(rounding="half_even"))),
    (3, DdcParams(nco=NcoParams(phase_bits=24, table_bits=12, amp_bits=14),
                  mixer=MixerParams(in_width=14, lo_width=14, out_width=16, rounding="floor",
                                    overflow="wrap"))),
])
def test_random_vs_model(seed, p):
    _check_random(p, 6000, seed)


@pytest.mark.slow
def test_random_vs_model_1e5():
    """1e5 samples through the Amaranth simulation (about a minute)."""
    _check_random(DdcParams(nco=NcoParams(dither_bits=8)), 100_000, seed=10)


def test_full_scale_and_latency():
    """Full-scale ADC words of both signs, with the phase stepping through all quadrants."""
    p = DdcParams()
    dut = Ddc(p)
    n = 2048
    x = np.where(np.arange(n) % 3 == 0, -2048, 2047)
    word = (1 << 32) // 7 + 12345
    i, q, res = _sim(dut, p, x, [(0, dut.freq, word)])
    mi, mq, _ = DdcModel(p).run(x, word)
    np.testing.assert_array_equal(i, mi)
    np.testing.assert_array_equal(q, mq)
    assert res.cycles[0] == p.latency == dut.latency == 9
    # Unity gain in full-scale units and the symmetric LO: never saturates.
    peak = (1 << 17) - 1
    assert np.abs(i).max() <= peak and np.abs(q).max() <= peak and np.abs(i).max() > peak - 64


def test_reset_mid_run():
    p = DdcParams(nco=NcoParams(dither_bits=4))
    dut = WithClear(Ddc(p))
    rng = np.random.default_rng(3)
    n1, n2, gap = 400, 400, 14
    x = rng.integers(-2048, 2048, n1 + n2)
    in_valid = np.r_[np.ones(n1, bool), np.zeros(gap, bool), np.ones(n2, bool)]
    word = 0x2345_6789
    i, q, _ = _sim(dut, p, x, [(0, dut.freq, word), (n1 + 11, dut.clear, 1),
                               (n1 + 12, dut.clear, 0)], in_valid)
    m = DdcModel(p)
    i1, q1, _ = m.run(x[:n1], word)
    i2, q2, _ = m.run(x[n1:], word)
    np.testing.assert_array_equal(i, np.r_[i1, i2])
    np.testing.assert_array_equal(q, np.r_[q1, q2])


def test_model_chunks_and_baseband():
    """Chunked model == one run; a 3.001 MHz tone mixed with a 3 MHz LO lands at +1 kHz."""
    p = DdcParams()
    m = DdcModel(p)
    n = 200_000
    t = np.arange(n) / F_CLK
    x = np.round(1500 * np.cos(2 * np.pi * 3.001e6 * t + 0.3)).astype(np.int64)
    fw = nco_freq_word(3e6, f_clk_hz=F_CLK, phase_bits=32)
    i, q, st = m.run(x, fw.word)
    state = None
    parts = []
    for a, b in ((0, 1), (1, 65_537), (65_537, n)):
        pi, pq, state = m.run(x[a:b], fw.word, state)
        parts.append((pi, pq))
    np.testing.assert_array_equal(np.concatenate([u for u, _ in parts]), i)
    np.testing.assert_array_equal(np.concatenate([v for _, v in parts]), q)
    assert state == st
    # Down-converted: z = i + jq ~ (A/2) exp(j(2 pi 1 kHz t + 0.3)) plus a 6 MHz image.
    z = (i + 1j * q).astype(np.complex128)
    ref = np.exp(1j * (2 * np.pi * (3.001e6 - fw.actual_hz) * t + 0.3))
    amp = np.mean(z * np.conj(ref)) / 2 ** 17 * 2 ** 11 * 2  # in ADC units, x2 for the mixer's 1/2
    assert abs(abs(amp) - 1500) < 1.5 and abs(np.angle(amp)) < 1e-3


@pytest.mark.parametrize("kwargs,match", [
    (dict(mixer=MixerParams(complex_input=True)), r"DDC mixer must take the real ADC stream"),
    (dict(mixer=MixerParams(lo_width=14)), r"DDC mixer lo_width must equal the NCO amp_bits, not lo_width=14 with amp_bits=16"),
    (dict(nco=NcoParams(phase_port=True)), r"DDC has no phase offset port"),
    (dict(nco=dict(phase_bits=32)), r"DDC nco must be an NcoParams, not \{'phase_bits': 32\}"),
    (dict(mixer=None), r"DDC mixer must be a MixerParams, not None"),
])
def test_bad_params(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DdcParams(**kwargs)


def test_model_refuses_bad_samples():
    m = DdcModel(DdcParams())
    with pytest.raises(ValueError, match=r"DDC input x must be signed 12-bit integers in \[-2048, 2047\], found 2048"):
        m.run(np.array([0, 2048]), 1)
    with pytest.raises(ValueError, match=r"DDC input x must be an integer array, not dtype float64"):
        m.run(np.array([0.0, np.nan]), 1)


def test_bad_component_argument():
    with pytest.raises(ValueError, match=r"Ddc needs a DdcParams, not NcoParams"):
        Ddc(NcoParams())


@pytest.mark.verilator
def test_verilog_lint():
    # Waived: only cosim.tools.verilog.LINT_WAIVERS less WIDTH (the DDC is clean of it).
    assert_lints_clean(Ddc(DdcParams(nco=NcoParams(dither_bits=8))), "ddc", check_width=True)


#: Compiled with Verilator: the TACAN DDC with NCO dither (as the slow 1e5 sim test).
VL_PARAMS = DdcParams(nco=NcoParams(dither_bits=8))


@pytest.fixture(scope="module")
def vl_ddc():
    dut = Ddc(VL_PARAMS)
    return dut, verilator_sim(dut, "ddc_vl")


@needs_verilator
def test_verilator_matches_pysim(vl_ddc):
    """Same stimulus as the random sim tests: full-scale words, gaps, frequency writes."""
    dut, sim = vl_ddc
    p = VL_PARAMS
    rng = np.random.default_rng(31)
    n = 3000
    x, writes, in_valid = _random_stimulus(p, dut, rng, n)
    w = np.asarray(x, dtype=np.int64) & ((1 << p.adc_width) - 1)
    kw = dict(in_valid=in_valid, writes=writes, flush_cycles=p.latency + 4)
    want = run_stream(dut, w, **kw)
    got = sim.run(w, **kw)
    assert_same_stream(got, want, "verilator vs pysim")
    assert len(got.words) == n


@needs_verilator
def test_verilator_matches_model_long(vl_ddc):
    """1e6 ADC samples with 40 run-time frequency writes and random gaps."""
    dut, sim = vl_ddc
    p = VL_PARAMS
    rng = np.random.default_rng(32)
    n = 1_000_000
    x, writes, in_valid = _random_stimulus(p, dut, rng, n, n_writes=40)
    i, q, res = _sim(dut, p, x, writes, in_valid, run=sim.run)
    cyc = accepted_cycles(n, in_valid)
    mi, mq, _ = DdcModel(p).run(x, _freq_at(cyc, writes, dut.freq))
    np.testing.assert_array_equal(i, mi)
    np.testing.assert_array_equal(q, mq)
    np.testing.assert_array_equal(res.cycles, cyc + p.latency)


# -- external LO: one NCO shared by several channels ---------------------------------------

class SharedLoDdc(wiring.Component):
    """Two DDC channels sampled together on one NCO (a monopulse front end's layout):
    ``i`` carries both ADC words, ``o`` both channels' I/Q."""

    def __init__(self, params: DdcParams, n_channels: int = 2):
        self.params, self.n = params, n_channels
        a, w = params.adc_width, params.out_width
        super().__init__({
            "i": In(stream.Signature(data.StructLayout(
                {f"x{k}": signed(a) for k in range(n_channels)}), always_ready=True)),
            "freq": In(params.freq_width),
            "o": Out(stream.Signature(data.StructLayout(
                {f"c{k}": iq_layout(w) for k in range(n_channels)}), always_ready=True)),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.nco = nco = Nco(self.params.nco)
        m.d.comb += [nco.i.valid.eq(self.i.valid), nco.freq.eq(self.freq)]
        ddcs = []
        for k in range(self.n):
            m.submodules[f"ddc{k}"] = d = Ddc(self.params, external_lo=True)
            m.d.comb += [d.i.valid.eq(self.i.valid), d.i.payload.eq(self.i.payload[f"x{k}"]),
                         d.lo.valid.eq(nco.o.valid), d.lo.payload.eq(nco.o.payload),
                         self.o.payload[f"c{k}"].eq(d.o.payload)]
            ddcs.append(d)
        m.d.comb += self.o.valid.eq(ddcs[0].o.valid)
        return m


def _shared_lo_stimulus(p: DdcParams, dut, seed: int, n: int):
    rng = np.random.default_rng(seed)
    a = p.adc_width
    xs = rng.integers(-(1 << (a - 1)), 1 << (a - 1), (2, n))
    xs[:, :8] = [[-(1 << (a - 1))] * 4 + [(1 << (a - 1)) - 1] * 4,
                 [(1 << (a - 1)) - 1] * 4 + [-(1 << (a - 1))] * 4]   # full scale, both signs
    words = (xs[0] & ((1 << a) - 1)) | ((xs[1] & ((1 << a) - 1)) << a)
    writes = [(0, dut.freq, nco_freq_word(3e6, f_clk_hz=F_CLK, phase_bits=p.freq_width).word)]
    for c in np.sort(rng.choice(n, 5, replace=False)):
        writes.append((int(c), dut.freq, int(rng.integers(0, 1 << p.freq_width))))
    in_valid = rng.random(n + n // 4) < 0.8
    return xs, words, writes, in_valid


def _shared_lo_fields(p: DdcParams, words):
    w = p.out_width
    return unpack_fields(words, [(f, w, True) for f in ("i0", "q0", "i1", "q1")])


#: Dithered NCO: the LO depends on the step sequence, so a misaligned LO would show.
#: 16-bit outputs: two channels' I/Q in one 64-bit word for the Verilator backend.
SHARED_P = DdcParams(nco=NcoParams(dither_bits=8), mixer=MixerParams(out_width=16))


def test_shared_lo_two_channels_vs_model():
    """Two ``Ddc(external_lo=True)`` on one ``Nco``, with gaps and frequency writes: each
    channel == ``DdcModel.mix`` on the shared ``NcoModel`` LO == the internal-NCO model."""
    p = SHARED_P
    dut = SharedLoDdc(p)
    n = 3000
    xs, words, writes, in_valid = _shared_lo_stimulus(p, dut, 41, n)
    res = run_stream(dut, words, in_valid=in_valid, writes=writes, flush_cycles=p.latency + 4)
    o = _shared_lo_fields(p, res.words)
    cyc = accepted_cycles(n, in_valid)
    np.testing.assert_array_equal(res.cycles, cyc + p.latency)
    fw = _freq_at(cyc, writes, dut.freq)
    cos, sin, _ = NcoModel(p.nco).run(n, fw)
    m = DdcModel(p)
    for k in range(2):
        mi, mq = m.mix(xs[k], cos, sin)
        np.testing.assert_array_equal(o[f"i{k}"], mi, err_msg=f"channel {k}")
        np.testing.assert_array_equal(o[f"q{k}"], mq, err_msg=f"channel {k}")
        ri, rq, _ = m.run(xs[k], fw)
        np.testing.assert_array_equal(mi, ri)
        np.testing.assert_array_equal(mq, rq)


def test_external_lo_ports_and_errors():
    ext, own = Ddc(SHARED_P, external_lo=True), Ddc(SHARED_P)
    for d in (ext, own):
        d._MustUse__silence = True  # never elaborated: no 'created but never used'
    assert hasattr(ext, "lo") and not hasattr(ext, "freq") and ext.latency == own.latency
    assert hasattr(own, "freq") and not hasattr(own, "lo")
    with pytest.raises(ValueError, match=r"Ddc external_lo must be True or False, not 1"):
        Ddc(SHARED_P, external_lo=1)
    m = DdcModel(SHARED_P)
    with pytest.raises(ValueError, match=r"DDC LO cos/sin must have the shape of x \(3,\), not \(2,\)/\(2,\)"):
        m.mix(np.zeros(3, np.int64), np.zeros(2, np.int64), np.zeros(2, np.int64))
    with pytest.raises(ValueError, match=r"DDC LO sin must be signed 16-bit integers"):
        m.mix(np.zeros(1, np.int64), np.zeros(1, np.int64), np.array([1 << 15]))


@needs_verilator
def test_shared_lo_verilator_matches_pysim():
    p = SHARED_P
    dut = SharedLoDdc(p)
    n = 3000
    _, words, writes, in_valid = _shared_lo_stimulus(p, dut, 42, n)
    kw = dict(in_valid=in_valid, writes=writes, flush_cycles=p.latency + 4)
    want = run_stream(dut, words, **kw)
    got = verilator_sim(dut, "ddc_shared_lo").run(words, **kw)
    assert_same_stream(got, want, "verilator vs pysim")
    assert len(got.words) == n


# -- compiled DDC -> CIC fast path (the TACAN front end's) ---------------------------------

def test_ddc_cic_kernel_equals_models():
    """DdcCicKernel == DdcModel then cic_model, with frequency writes and two chunks."""
    from hdl.model.cic import CicParams, cic_model
    from hdl.model.ddc import DdcCicKernel
    p = DdcParams()
    cp = CicParams(stages=3, rate=4, diff_delay=1, in_width=p.out_width, channels=2,
                   out_width=17, rounding="half_even", overflow="saturate")
    assert DdcCicKernel.exact(p, cp)
    rng = np.random.default_rng(51)
    n = 4000
    x = rng.integers(-2048, 2048, n)
    idx = np.array([0, 5, 1001, 2002, 3999], np.int64)
    val = rng.integers(0, 1 << 32, idx.size).astype(np.int64)
    fw = np.zeros(n, np.int64)
    for k, v in zip(idx, val):
        fw[k:] = v
    i, q, _ = DdcModel(p).run(x, fw)
    want, _ = cic_model(cp, np.stack([i, q], axis=-1))
    k = DdcCicKernel(p, cp)
    integ, combs = np.zeros((2, 3), np.int64), np.zeros((2, 3, 1), np.int64)
    big = np.iinfo(np.int64).max
    mrng = np.array([big, -big, big, -big], np.int64)
    ph, fw0, got = 0, 0, []
    for a, b in ((0, 2000), (2000, n)):
        sel = (idx >= a) & (idx < b)
        ci, cq, ph = k.run(x[a:b].astype(np.int64), ph, fw0, integ, combs, idx[sel] - a,
                           val[sel], mrng)
        fw0 = int(fw[b - 1])
        got.append(np.stack([ci, cq], axis=-1))
    np.testing.assert_array_equal(np.concatenate(got), want)
    assert list(mrng) == [i.min(), i.max(), q.min(), q.max()]
    with pytest.raises(ValueError, match=r"ADC codes must be signed 12-bit integers"):
        k.run(np.array([0, 0, 0, 2048]), 0, 0, integ, combs, idx[:0], val[:0], mrng)
