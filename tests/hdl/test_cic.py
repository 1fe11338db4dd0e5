"""CIC decimator: Amaranth simulation == bit-exact model, Hogenauer widths and pruning, lint;
the exported Verilog (Verilator) == Amaranth simulation == model."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.backends.pysim import pack_fields, run_stream, unpack_fields
from dsp.design import cic_taps
from hdl.cic import Cic
from hdl.model.cic import CicParams, cic_init_state, cic_model, hogenauer_f2
from cosim.core.executables import find_executable

from _util import (WithClear, accepted_cycles, assert_same_stream, channel_layout, needs_verilator,
                   pack_channels, random_samples, unpack_channels, verilator_sim)

TACAN = CicParams()  # N=3, R=4, M=1, 18-bit complex in, 24-bit out


# -- helpers --------------------------------------------------------------------------------
def _layout(width: int, channels: int):
    return channel_layout(width, channels)


def _pack(p: CicParams, x: np.ndarray) -> np.ndarray:
    return pack_channels(x, p.in_width, p.channels)


def _unpack(p: CicParams, words: np.ndarray) -> np.ndarray:
    return unpack_channels(words, p.out_width, p.channels)


def _random_input(rng, p: CicParams, n: int) -> np.ndarray:
    return random_samples(rng, p.in_width, n, p.sample_shape)


def _sim(p: CicParams, x: np.ndarray, in_valid=None, dut=None, **kw):
    dut = Cic(p) if dut is None else dut
    res = run_stream(dut, _pack(p, x), in_valid=in_valid, flush_cycles=p.latency + 4, **kw)
    return _unpack(p, res.words), res


# -- simulation == model --------------------------------------------------------------------
def _sim_vs_model_tacan(seed: int, n: int):
    rng = np.random.default_rng(seed)
    x = _random_input(rng, TACAN, n)
    in_valid = rng.random(n + n // 10) < 0.93
    got, _ = _sim(TACAN, x, in_valid)
    want, st = cic_model(TACAN, x)
    assert len(want) == n // 4, seed
    np.testing.assert_array_equal(got, want, err_msg=f"seed {seed}")
    assert st.overflows == 0


def test_sim_matches_model_tacan():
    """2*10^4 random complex samples, random gaps in valid: zero bit mismatches."""
    _sim_vs_model_tacan(20260102, 20_000)


@pytest.mark.slow
def test_sim_matches_model_1e5_tacan():
    """10^5 random complex samples (pysim: ~15 s on an idle core, ~110 s on a loaded one)."""
    _sim_vs_model_tacan(20260101, 100_000)


CONFIGS = [
    CicParams(channels=1, in_width=12),
    CicParams(stages=1, rate=2, in_width=8, channels=1),
    CicParams(stages=4, rate=5, diff_delay=2, in_width=12, out_width=16, rounding="half_up"),
    CicParams(stages=3, rate=4, out_width=14, rounding="half_up", prune=True, channels=1),
    CicParams(stages=5, rate=7, diff_delay=2, in_width=10, out_width=12, rounding="half_even",
              prune=True),
    CicParams(stages=2, rate=3, in_width=10, out_width=9, rounding="zero", overflow="wrap",
              channels=1),
    CicParams(stages=8, rate=3, in_width=6, channels=1, out_width=8, prune=True,
              rounding="half_up"),
]


@pytest.mark.parametrize("seed,p", list(enumerate(CONFIGS)))
def test_sim_matches_model_configs(seed, p):
    rng = np.random.default_rng(1000 + seed)
    x = _random_input(rng, p, 6000)
    in_valid = rng.random(8000) < 0.75
    got, _ = _sim(p, x, in_valid)
    want, _ = cic_model(p, x)
    np.testing.assert_array_equal(got, want, err_msg=f"seed {1000 + seed} {p}")


# -- directed corners ------------------------------------------------------------------------
@pytest.mark.parametrize("p", [TACAN, CicParams(channels=1, out_width=14, rounding="half_up",
                                                prune=True),
                               CicParams(stages=5, rate=7, diff_delay=2, in_width=10,
                                         channels=1)])
def test_full_scale_dc_both_signs_sim(p):
    """Full-scale DC: integrators wrap many times; the output is gain * x exactly."""
    lo, hi = -(1 << (p.in_width - 1)), (1 << (p.in_width - 1)) - 1
    n = 3000
    x = np.r_[np.full(n, hi), np.full(n, lo)]
    if p.channels == 2:
        x = np.stack([x, x[::-1]], axis=1)   # i and q at opposite signs
    got, _ = _sim(p, x)
    want, _ = cic_model(p, x)
    np.testing.assert_array_equal(got, want)
    settle = p.stages * p.diff_delay + 2
    pos, neg = got[settle:n // p.rate - 1], got[n // p.rate + settle:]
    if p.channels == 2:
        pos, neg = pos[:, 0], neg[:, 0]
    if not p.prune:   # full width: exact
        assert np.all(pos == hi * p.gain) and np.all(neg == lo * p.gain)
    else:             # pruning noise: within 2 output LSBs, never wrapped to the other sign
        assert np.all(np.abs(pos - hi * p.float_gain) <= 2) and np.all(pos > 0)
        assert np.all(np.abs(neg - lo * p.float_gain) <= 2) and np.all(neg < 0)


def test_full_scale_dc_long_run_model_exact():
    """Model over 4e6 samples in chunks at +-full scale: integrators wrap ~2^16 times and
    every output is exact (gain 64, so -2^17 -> -2^23 = most negative 24-bit word)."""
    p = TACAN
    lo, hi = -(1 << 17), (1 << 17) - 1
    for v in (lo, hi):
        st = None
        chunk = np.full((1 << 18, 2), v, dtype=np.int64)
        for k in range(16):
            y, st = cic_model(p, chunk, st)
            tail = y if k else y[2:]
            assert np.all(tail == v * 64), (v, k)
        # The stage method wraps its integrators many times and agrees.
        ys, sts = cic_model(p, np.full((1 << 20, 2), v), method="stages")
        assert np.all(ys[2:] == v * 64)
        assert np.abs(sts.integ).max() < 1 << 23


def test_integrator_wraparound_in_sim():
    """Small widths so the sim's integrators wrap within a few hundred samples: exact."""
    p = CicParams(stages=3, rate=4, in_width=4, channels=1)  # 10-bit registers
    x = np.r_[np.full(600, 7), np.full(600, -8), np.tile([7, -8], 300)]
    got, _ = _sim(p, x)
    want, _ = cic_model(p, x)
    np.testing.assert_array_equal(got, want)
    assert np.all(got[5:149] == 7 * 64) and np.all(got[155:299] == -8 * 64)


def test_alternating_full_scale():
    """+FS/-FS alternating: the CIC nulls fs/2 (R even), so only the -0.5 mean is left."""
    p = TACAN
    lo, hi = -(1 << 17), (1 << 17) - 1
    col = np.tile([hi, lo], 2000)
    x = np.stack([col, -1 - col], axis=1)
    got, _ = _sim(p, x)
    want, _ = cic_model(p, x)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(got[3:, 0], -32)   # (hi + lo)/2 * 64
    np.testing.assert_array_equal(got[3:, 1], -32)


def test_gaps_in_valid_and_latency():
    """Sparse, bursty valid: same values as the model; output `latency` cycles after the
    input that completes each decimation group."""
    p = TACAN
    rng = np.random.default_rng(7)
    x = _random_input(rng, p, 2000)
    pattern = np.r_[np.ones(37, bool), np.zeros(11, bool), rng.random(12000) < 0.2]
    got, res = _sim(p, x, pattern)
    want, _ = cic_model(p, x)
    np.testing.assert_array_equal(got, want)
    in_cycles = np.flatnonzero(pattern)[:len(x)]
    assert len(in_cycles) == len(x)
    np.testing.assert_array_equal(res.cycles, in_cycles[p.rate - 1::p.rate] + p.latency)


def test_reset_mid_run():
    """A synchronous reset clears integrators, combs, decimation phase and the pipeline."""
    p = TACAN
    rng = np.random.default_rng(11)
    n1, n2, gap = 1002, 1000, 20      # n1 not a multiple of R: the phase must reset too
    x = _random_input(rng, p, n1 + n2)
    dut = WithClear(Cic(p))
    in_valid = np.r_[np.ones(n1, bool), np.zeros(gap, bool)]
    clear_at = n1 + 15                  # after the last group of part 1 has come out
    got, _ = _sim(p, x, in_valid, dut=dut,
                  writes=[(clear_at, dut.clear, 1), (clear_at + 1, dut.clear, 0)])
    y1, _ = cic_model(p, x[:n1])
    y2, _ = cic_model(p, x[n1:])
    np.testing.assert_array_equal(got, np.concatenate([y1, y2]))


# -- model ---------------------------------------------------------------------------------
@pytest.mark.parametrize("p", [TACAN, CONFIGS[2], CONFIGS[4]])
def test_model_chunking(p):
    rng = np.random.default_rng(5)
    x = _random_input(rng, p, 20_011)
    whole, st_whole = cic_model(p, x)
    st, parts = None, []
    for a, b in [(0, 1), (1, 4), (4, 4), (4, 999), (999, 5003), (5003, 20_011)]:
        y, st = cic_model(p, x[a:b], st)
        parts.append(y)
    np.testing.assert_array_equal(np.concatenate(parts), whole)
    assert st.overflows == st_whole.overflows and st.n_in == len(x)


@pytest.mark.parametrize("p", [TACAN, CONFIGS[0], CONFIGS[1], CONFIGS[2], CONFIGS[5]])
def test_model_direct_equals_stages(p):
    """Two independent formulations (equivalent FIR vs integrators/combs) agree."""
    rng = np.random.default_rng(9)
    x = _random_input(rng, p, 30_000)
    a, _ = cic_model(p, x, method="direct")
    b, _ = cic_model(p, x, method="stages")
    np.testing.assert_array_equal(a, b)


def test_model_against_float_convolution():
    """Unpruned, full width: output = exact convolution with the CIC taps, decimated."""
    p = CicParams(stages=4, rate=5, diff_delay=2, in_width=12, channels=1)
    rng = np.random.default_rng(3)
    x = _random_input(rng, p, 5000)
    y, _ = cic_model(p, x)
    ref = np.convolve(x.astype(float), cic_taps(4, 5, 2) * p.gain)[:len(x)][p.rate - 1::p.rate]
    np.testing.assert_array_equal(y, ref.astype(np.int64))


def test_widths_hogenauer():
    assert TACAN.full_width == 24 and TACAN.gain == 64 and TACAN.out_width == 24
    assert CicParams(stages=4, rate=25, in_width=16).full_width == 16 + 19   # ceil(4 log2 25)
    assert CicParams(stages=3, rate=5, diff_delay=2, in_width=10).full_width == 20
    for n, r, m in [(1, 2, 1), (3, 4, 1), (5, 7, 2), (8, 3, 2)]:
        p = CicParams(stages=n, rate=r, diff_delay=m, in_width=8)
        assert p.full_width == 8 + math.ceil(n * math.log2(r * m) - 1e-12)
    assert TACAN.stage_widths == (24,) * 6 and TACAN.hogenauer_discard == (0,) * 6


def _hogenauer_h(n, r, m, j):
    """Hogenauer's closed form (his eq. 9b/c, as transcribed) of the stage-j impulse response."""
    rm = r * m
    if j <= n:
        out = []
        for k in range((rm - 1) * n + j):
            out.append(sum((-1) ** l * math.comb(n, l) * math.comb(n - j + k - rm * l, k - rm * l)
                           for l in range(k // rm + 1)))
        return out
    return [(-1) ** k * math.comb(2 * n + 1 - j, k) for k in range(2 * n + 2 - j)]


@pytest.mark.parametrize("n,r,m", [(3, 4, 1), (4, 25, 1), (5, 7, 2), (2, 3, 1)])
def test_hogenauer_variance_gains_closed_form(n, r, m):
    want = tuple(sum(c * c for c in _hogenauer_h(n, r, m, j)) for j in range(1, 2 * n + 1))
    assert hogenauer_f2(n, r, m) == want


def test_hogenauer_worked_example():
    """N=4, R=25, M=1, 16 bits in and out (Hogenauer 1981's example): B_max = 35,
    B_j = 1, 6, 9, 13, 14, 15, 16, 17 and 19 at the output."""
    p = CicParams(stages=4, rate=25, in_width=16, out_width=16, channels=1, prune=True)
    assert p.full_width == 35 and p.out_shift == 19
    assert p.hogenauer_bits == (1, 6, 9, 13, 14, 15, 16, 17)
    assert p.hogenauer_discard == (0, 6, 9, 13, 14, 15, 16, 17)
    assert p.stage_widths == (36, 30, 27, 23, 22, 21, 20, 19)   # one guard bit


@pytest.mark.parametrize("p", [CicParams(out_width=16, prune=True, channels=1),
                               CicParams(stages=4, rate=25, in_width=16, out_width=16,
                                         prune=True, channels=1),
                               CicParams(stages=5, rate=7, diff_delay=2, in_width=10,
                                         out_width=12, prune=True, channels=1),
                               CicParams(stages=8, rate=3, in_width=10, out_width=12,
                                         prune=True, channels=1)])
def test_pruning_error_bound(p):
    """Pruning noise (var, predicted and measured) is no larger than the output rounding
    noise, and it is zero-mean (stage 1 is not pruned)."""
    lsb = p.stage_lsbs
    f2 = hogenauer_f2(p.stages, p.rate, p.diff_delay)
    prev, predicted = 0, 0.0
    for j, b in enumerate(lsb):
        if b > prev:    # a stage that truncates adds at most 2**(2b)/12 of variance
            predicted += f2[j] * 4.0 ** b / 12
        prev = b
    rounding_var = 4.0 ** p.out_shift / 12
    assert predicted <= rounding_var

    rng = np.random.default_rng(17)
    x = _random_input(rng, p, 400_000)
    exact, _ = cic_model(CicParams(stages=p.stages, rate=p.rate, diff_delay=p.diff_delay,
                                   in_width=p.in_width, channels=1), x)
    exact = exact / 2.0 ** p.out_shift
    unpruned = CicParams(stages=p.stages, rate=p.rate, diff_delay=p.diff_delay,
                         in_width=p.in_width, channels=1, out_width=p.out_width)
    e_round = cic_model(unpruned, x)[0] - exact
    e_pruned = cic_model(p, x)[0] - exact
    extra_var = np.var(e_pruned) - np.var(e_round)
    assert np.var(e_round) == pytest.approx(1 / 12, rel=0.05)
    assert extra_var <= 1 / 12 * 1.05
    assert extra_var <= predicted / 4.0 ** p.out_shift * 1.1
    # Zero-mean pruning noise: the only bias is floor's on the coarser grid of the last
    # stage, -(1 - 2**(lsb_last - out_shift)) / 2 output LSBs.
    bias = -(1 - 2.0 ** (lsb[-1] - p.out_shift)) / 2
    assert np.mean(e_pruned) == pytest.approx(bias, abs=0.01)


def test_rounding_modes_and_saturation():
    """Half-up rounding at positive full scale carries out of range: saturated (counted)
    or wrapped, as asked."""
    base = dict(stages=1, rate=2, in_width=8, channels=1, out_width=3, rounding="half_up")
    x = np.full(40, 127)           # 254 / 2**6 = 3.97 -> rounds to 4, max is 3
    ys, sts = cic_model(CicParams(**base, overflow="saturate"), x)
    yw, stw = cic_model(CicParams(**base, overflow="wrap"), x)
    assert np.all(ys == 3) and np.all(yw == -4) and sts.overflows == stw.overflows == 20
    got, _ = _sim(CicParams(**base, overflow="saturate"), x)
    np.testing.assert_array_equal(got, ys)
    got, _ = _sim(CicParams(**base, overflow="wrap"), x)
    np.testing.assert_array_equal(got, yw)
    for rnd, want in [("floor", -2), ("half_up", -1), ("half_even", -2), ("zero", -1)]:
        p = CicParams(stages=1, rate=2, in_width=8, channels=1, out_width=3, rounding=rnd)
        y, _ = cic_model(p, np.full(8, -48))    # -96 / 64 = -1.5
        assert np.all(y[1:] == want), rnd


# -- parameters ------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs,match", [
    (dict(rate=1), r"CIC decimation must be an integer >= 2, not 1"),
    (dict(rate=2.0), r"CIC decimation must be an integer >= 2, not 2.0"),
    (dict(stages=0), r"CIC stages must be an integer in \[1, 8\], not 0"),
    (dict(stages=9), r"CIC stages must be an integer in \[1, 8\], not 9"),
    (dict(diff_delay=3), r"CIC differential delay must be 1 or 2, not 3"),
    (dict(in_width=1), r"CIC in_width must be an integer in \[2, 62\], not 1"),
    (dict(channels=3), r"CIC channels must be 1 \(real\) or 2 \(complex\), not 3"),
    (dict(out_width=25), r"CIC out_width must be an integer in \[2, 24\] \(the full width\), not 25"),
    (dict(out_width=1), r"CIC out_width must be an integer in \[2, 24\]"),
    (dict(rounding="nearest"), r"CIC rounding must be one of .*, not 'nearest'"),
    (dict(overflow="clip"), r"CIC overflow must be one of .*, not 'clip'"),
    (dict(prune=1), r"CIC prune must be a bool, not 1"),
    (dict(in_width=40, stages=8, rate=16), r"CIC full register width .* must be <= 62, not 72"),
])
def test_bad_params(kwargs, match):
    with pytest.raises(ValueError, match=match):
        CicParams(**kwargs)


def test_bad_model_inputs():
    with pytest.raises(ValueError, match=r"CIC input must fit in 18 signed bits"):
        cic_model(TACAN, np.full((4, 2), 1 << 17))
    with pytest.raises(ValueError, match=r"CIC input must have shape \(n, \*\(2,\)\)"):
        cic_model(TACAN, np.zeros(4, dtype=np.int64))
    with pytest.raises(ValueError, match=r"CIC input must be integers"):
        cic_model(TACAN, np.zeros((4, 2)))
    pruned = CicParams(out_width=16, prune=True)
    with pytest.raises(ValueError, match=r"'direct' is exact only without pruning"):
        cic_model(pruned, np.zeros((4, 2), dtype=np.int64), method="direct")
    _, st = cic_model(TACAN, np.zeros((4, 2), dtype=np.int64), method="direct")
    with pytest.raises(ValueError, match=r"state comes from method 'direct'"):
        cic_model(TACAN, np.zeros((4, 2), dtype=np.int64), st, method="stages")
    with pytest.raises(ValueError, match=r"Cic needs a CicParams, not "):
        Cic(dict(rate=4))
    assert cic_init_state(TACAN).integ.shape == (3, 2)


# -- Verilog ---------------------------------------------------------------------------------
@pytest.mark.verilator
@pytest.mark.skipif(find_executable("verilator") is None, reason="verilator not on PATH")
@pytest.mark.parametrize("name,p", [("cic_tacan", TACAN),
                                    ("cic_pruned", CicParams(out_width=16, prune=True,
                                                             rounding="half_even", channels=1,
                                                             diff_delay=2)),
                                    ("cic_wrap", CONFIGS[5])])
def test_verilog_lint(name, p):
    from cosim.core.provenance import REPO_ROOT
    from cosim.tools.verilog import export_verilog, lint
    path = export_verilog(Cic(p), name=name, out_dir=REPO_ROOT / "build" / "verilog" / "test")
    assert lint(path) == []


@pytest.fixture(scope="module")
def vl_cic():
    dut = Cic(TACAN)
    return dut, verilator_sim(dut, "cic_tacan_vl")


@needs_verilator
def test_verilator_matches_pysim(vl_cic):
    """The TACAN sim test's stimulus (random complex samples, gaps in valid), shorter."""
    dut, sim = vl_cic
    rng = np.random.default_rng(20260103)
    n = 4000
    words = _pack(TACAN, _random_input(rng, TACAN, n))
    kw = dict(in_valid=rng.random(n + n // 10) < 0.93, flush_cycles=TACAN.latency + 4)
    want = run_stream(dut, words, **kw)
    got = sim.run(words, **kw)
    assert_same_stream(got, want, "verilator vs pysim")
    assert len(got.words) == n // TACAN.rate


@needs_verilator
def test_verilator_matches_model_long(vl_cic):
    """10^6 random complex samples with gaps; each output `latency` cycles after the input
    that completes its decimation group."""
    p = TACAN
    _, sim = vl_cic
    rng = np.random.default_rng(20260104)
    n = 1_000_000
    x = _random_input(rng, p, n)
    in_valid = rng.random(n + n // 10) < 0.8
    res = sim.run(_pack(p, x), in_valid=in_valid, flush_cycles=p.latency + 4)
    want, st = cic_model(p, x)
    np.testing.assert_array_equal(_unpack(p, res.words), want)
    np.testing.assert_array_equal(res.cycles,
                                  accepted_cycles(n, in_valid)[p.rate - 1::p.rate] + p.latency)
    assert st.overflows == 0
