"""Symmetric FIR decimator: Amaranth simulation == bit-exact model, quantisation, corners, lint;
the exported Verilog (Verilator) == Amaranth simulation == model."""
from __future__ import annotations


import numpy as np
import pytest
from scipy import signal

from cosim.backends.pysim import pack_fields, run_stream, unpack_fields
from dsp.design import design_pulse_fir
from hdl.fir import Fir
from hdl.model.fir import (FirParams, default_fir_taps, fir_float_reference, fir_init_state,
                           fir_model)
from cosim.core.executables import find_executable

from _util import (WithClear, accepted_cycles, assert_same_stream, channel_layout, needs_verilator,
                   pack_channels, random_samples, unpack_channels, verilator_sim)

TACAN = FirParams()   # 33 taps, 18-bit coefficients, 24-bit complex in, D = 1
LOWPASS = tuple(signal.firwin(15, 0.3))             # has negative taps
HALFBAND = tuple(signal.firwin(11, 0.5))            # has exact zeros (every other tap)


# -- helpers --------------------------------------------------------------------------------
def _layout(width: int, channels: int):
    return channel_layout(width, channels)


def _pack(p: FirParams, x: np.ndarray) -> np.ndarray:
    return pack_channels(x, p.in_width, p.channels)


def _unpack(p: FirParams, words: np.ndarray) -> np.ndarray:
    return unpack_channels(words, p.out_width, p.channels)


def _random_input(rng, p: FirParams, n: int) -> np.ndarray:
    return random_samples(rng, p.in_width, n, p.sample_shape)


def _sim(p: FirParams, x: np.ndarray, in_valid=None, dut=None, **kw):
    dut = Fir(p) if dut is None else dut
    res = run_stream(dut, _pack(p, x), in_valid=in_valid, flush_cycles=p.latency + 4, **kw)
    return _unpack(p, res.words), res


# -- simulation == model --------------------------------------------------------------------
def _sim_vs_model_tacan(seed: int, n: int):
    rng = np.random.default_rng(seed)
    x = _random_input(rng, TACAN, n)
    in_valid = rng.random(n + n // 10) < 0.93
    got, _ = _sim(TACAN, x, in_valid)
    want, st = fir_model(TACAN, x)
    np.testing.assert_array_equal(got, want, err_msg=f"seed {seed}")
    assert st.overflows == 0


def test_sim_matches_model_tacan():
    """6000 random complex samples with gaps in valid: zero bit mismatches."""
    _sim_vs_model_tacan(20260201, 6000)


@pytest.mark.slow
def test_sim_matches_model_1e5_tacan():
    """10^5 random complex samples (pysim: ~80 s on an idle core, ~250 s on a loaded one)."""
    _sim_vs_model_tacan(20260202, 100_000)


CONFIGS = [
    FirParams(channels=1, decimation=3, in_width=14, out_width=16, rounding="half_even"),
    FirParams(taps=LOWPASS, coef_bits=12, decimation=2, in_width=12, out_width=10,
              overflow="wrap", rounding="zero"),
    FirParams(taps=HALFBAND, coef_bits=16, decimation=2, in_width=16, channels=1,
              rounding="floor"),
    FirParams(taps=(0.25, 0.5, 0.25), coef_bits=8, decimation=4, in_width=8, out_shift=0),
    FirParams(taps=LOWPASS, in_width=10, channels=1, out_width=8, overflow="saturate"),
]


@pytest.mark.parametrize("seed,p", list(enumerate(CONFIGS)))
def test_sim_matches_model_configs(seed, p):
    rng = np.random.default_rng(2000 + seed)
    x = _random_input(rng, p, 3000)
    in_valid = rng.random(4000) < 0.75
    got, _ = _sim(p, x, in_valid)
    want, _ = fir_model(p, x)
    np.testing.assert_array_equal(got, want, err_msg=f"seed {2000 + seed} {p}")


# -- time-shared multipliers (input_spacing >= 2) -------------------------------------------
def _spaced_valid(rng, n: int, spacing: int) -> np.ndarray:
    """Valid pattern with at least ``spacing`` cycles between inputs, sometimes more."""
    gaps = spacing + rng.integers(0, 4, size=n) * (rng.random(n) < 0.3)
    idx = np.cumsum(gaps)
    valid = np.zeros(idx[-1] + 1, bool)
    valid[idx] = True
    return valid


SHARED = [
    FirParams(input_spacing=4),                                          # TACAN after R=4
    FirParams(input_spacing=2, channels=1, decimation=3, in_width=12, rounding="floor"),
    FirParams(taps=HALFBAND, input_spacing=3, in_width=10, channels=1),  # zero taps skipped
    FirParams(taps=LOWPASS, input_spacing=20, in_width=10, out_width=8),  # one multiplier
]


@pytest.mark.parametrize("seed,p", list(enumerate(SHARED)))
def test_shared_sim_matches_model(seed, p):
    """Same values as the model (and the parallel design) at the guaranteed cadence; each
    output `latency` cycles after its input; no overrun."""
    rng = np.random.default_rng(3000 + seed)
    n = 1500 if p.input_spacing < 10 else 400
    x = _random_input(rng, p, n)
    valid = _spaced_valid(rng, n, p.input_spacing)
    dut = Fir(p)
    got, res = _sim(p, x, valid, dut=dut, probe={"overrun": dut.overrun})
    want, _ = fir_model(p, x)
    np.testing.assert_array_equal(got, want, err_msg=f"seed {3000 + seed} {p}")
    in_cycles = np.flatnonzero(valid)[:n]
    d = p.decimation
    np.testing.assert_array_equal(res.cycles, in_cycles[d - 1::d] + p.latency)
    assert res.probes["overrun"].max() == 0


def test_shared_overrun_is_flagged():
    """Inputs closer than input_spacing set the sticky overrun flag."""
    p = FirParams(input_spacing=4, in_width=12, channels=1)
    x = np.arange(40, dtype=np.int64)
    valid = np.r_[np.tile([1, 0, 0, 0], 5), [1, 0, 1], np.tile([1, 0, 0, 0], 5)].astype(bool)
    dut = Fir(p)
    _, res = _sim(p, x, valid, dut=dut, probe={"overrun": dut.overrun})
    ov = res.probes["overrun"]
    assert ov[:22].max() == 0 and ov[23:].min() == 1


def test_shared_multiplier_counts():
    assert [FirParams(input_spacing=s).multipliers for s in (1, 2, 4, 8, 17, 40)] == \
        [34, 18, 10, 6, 2, 2]
    p = FirParams(input_spacing=4)
    assert p.dsp_blocks == 20 and p.tree_levels == 4 and p.latency == 7 + 4 + 4
    q = FirParams(input_spacing=4, in_width=17)     # 18-bit pre-adder: one DSP each
    assert q.multipliers == q.dsp_blocks == 10


# -- directed corners ------------------------------------------------------------------------
@pytest.mark.parametrize("taps", [None, LOWPASS])
def test_worst_case_input_reaches_accumulator_bounds(taps):
    """Inputs at +-full scale with the taps' signs drive the accumulator to exactly its
    computed bounds (out_shift=0, full width): acc_width is tight and nothing wraps."""
    p = FirParams(taps=taps, in_width=12, channels=1, out_shift=0)
    assert p.out_width == p.acc_width
    lo, hi = -(1 << 11), (1 << 11) - 1
    s = np.sign(np.array(p.taps_int))[::-1]          # x[n-k] lines up with h[k]
    up = np.where(s > 0, hi, lo)
    down = np.where(s > 0, lo, hi)
    x = np.r_[up, np.zeros(5, np.int64), down]
    got, _ = _sim(p, x)
    want, _ = fir_model(p, x)
    np.testing.assert_array_equal(got, want)
    a_lo, a_hi = p.acc_bounds
    assert got[p.numtaps - 1] == a_hi and got[-1] == a_lo
    assert a_hi < 1 << (p.acc_width - 1) <= max(a_hi, -a_lo) * 2


def test_full_scale_dc_both_signs_and_alternating():
    p = TACAN
    lo, hi = -(1 << 23), (1 << 23) - 1
    col = np.r_[np.full(200, hi), np.full(200, lo), np.tile([hi, lo], 200)]
    x = np.stack([col, col[::-1]], axis=1)
    got, _ = _sim(p, x)
    want, _ = fir_model(p, x)
    np.testing.assert_array_equal(got, want)
    dc = sum(p.taps_int)
    assert np.all(got[40:200, 0] == (hi * dc + (1 << 19)) >> 20)     # half_up, no overflow
    assert np.all(got[240:400, 0] == (lo * dc + (1 << 19)) >> 20)
    h = np.array(p.taps_int, dtype=object)
    even, odd = int(h[0::2].sum()), int(h[1::2].sum())
    n = np.arange(440, 800)      # alternating from index 400 (even: hi)
    want_alt = np.where(n % 2 == 0, (hi * even + lo * odd + (1 << 19)) >> 20,
                        (lo * even + hi * odd + (1 << 19)) >> 20)
    np.testing.assert_array_equal(got[440:, 0], want_alt)


def test_overflow_saturate_and_wrap_counted():
    """A DC gain of 1.21 at full scale does not fit the input width: saturated or wrapped,
    and counted by the model."""
    base = dict(in_width=12, channels=1, out_width=12)
    x = np.r_[np.full(100, 2047), np.full(100, -2048)]
    ys, sts = fir_model(FirParams(**base, overflow="saturate"), x)
    yw, stw = fir_model(FirParams(**base, overflow="wrap"), x)
    assert sts.overflows == stw.overflows > 100
    assert ys[50] == 2047 and ys[150] == -2048
    assert yw[50] == round(2047 * TACAN.dc_gain) - 4096 and yw[150] > 0
    for ov, want in [("saturate", ys), ("wrap", yw)]:
        got, _ = _sim(FirParams(**base, overflow=ov), x)
        np.testing.assert_array_equal(got, want)


def test_gaps_in_valid_and_latency():
    """One input per cycle in bursts and sparse single inputs: values as the model, each
    output `latency` cycles after the input that produced it; decimation keeps the D-th,
    2D-th, ... input."""
    p = FirParams(taps=LOWPASS, decimation=3, in_width=12, channels=1)
    rng = np.random.default_rng(8)
    x = _random_input(rng, p, 1500)
    pattern = np.r_[np.ones(100, bool), np.zeros(13, bool), rng.random(8000) < 0.25]
    got, res = _sim(p, x, pattern)
    want, _ = fir_model(p, x)
    np.testing.assert_array_equal(got, want)
    in_cycles = np.flatnonzero(pattern)[:len(x)]
    assert len(in_cycles) == len(x)
    np.testing.assert_array_equal(res.cycles, in_cycles[2::3] + p.latency)
    assert p.latency == 7 + p.tree_levels


def test_reset_mid_run():
    """A synchronous reset clears the delay line, the decimation phase and the pipeline."""
    p = FirParams(taps=LOWPASS, decimation=2, in_width=12)
    rng = np.random.default_rng(12)
    n1, n2, gap = 501, 500, 20
    x = _random_input(rng, p, n1 + n2)
    dut = WithClear(Fir(p))
    in_valid = np.r_[np.ones(n1, bool), np.zeros(gap, bool)]
    clear_at = n1 + p.latency + 2
    got, _ = _sim(p, x, in_valid, dut=dut,
                  writes=[(clear_at, dut.clear, 1), (clear_at + 1, dut.clear, 0)])
    y1, _ = fir_model(p, x[:n1])
    y2, _ = fir_model(p, x[n1:])
    np.testing.assert_array_equal(got, np.concatenate([y1, y2]))


# -- model, coefficients ----------------------------------------------------------------------
@pytest.mark.parametrize("p", [TACAN, CONFIGS[0], CONFIGS[1], CONFIGS[3]])
def test_model_chunking(p):
    rng = np.random.default_rng(6)
    x = _random_input(rng, p, 10_007)
    whole, st_whole = fir_model(p, x)
    st, parts = None, []
    for a, b in [(0, 1), (1, 5), (5, 5), (5, 40), (40, 3001), (3001, 10_007)]:
        y, st = fir_model(p, x[a:b], st)
        parts.append(y)
    np.testing.assert_array_equal(np.concatenate(parts), whole)
    assert st.overflows == st_whole.overflows and st.n_in == len(x)


@pytest.mark.parametrize("p", [TACAN, CONFIGS[0], CONFIGS[2], CONFIGS[3]])
def test_model_against_float_reference(p):
    """Without overflow the model is the float filter (quantised taps) plus rounding only."""
    rng = np.random.default_rng(4)
    x = _random_input(rng, p, 20_000)
    y, st = fir_model(p, x)
    ref = fir_float_reference(p, x)
    assert st.overflows == 0 and y.shape == ref.shape
    err = y - ref
    bound = {"floor": (-1, 0), "half_up": (-0.5, 0.5), "half_even": (-0.5, 0.5),
             "zero": (-1, 1)}[p.rounding]
    assert err.min() >= bound[0] - 1e-9 and err.max() <= bound[1] + 1e-9


def test_default_coefficients():
    p = TACAN
    assert p.taps == default_fir_taps()
    np.testing.assert_allclose(p.taps, design_pulse_fir(fs_in_hz=20e6, cic_stages=3,
                                                        cic_rate=4, numtaps=33), rtol=0, atol=0)
    h = np.array(p.taps_int)
    assert p.numtaps == 33 and np.array_equal(h, h[::-1])
    assert p.coef_frac == 20 and h.max() == round(max(p.taps) * 2 ** 20)
    # Full range: one more fraction bit would overflow the 18-bit coefficient word.
    assert (1 << 16) <= np.abs(h).max() <= (1 << 17) - 1
    assert np.abs(p.taps_quantised - np.array(p.taps)).max() <= 2.0 ** -21
    assert p.dc_gain == pytest.approx(1.2124, abs=1e-3) and p.float_gain == 1.0
    assert p.acc_width == 45 and p.out_width == 25 and p.out_shift == 20
    assert p.multipliers == 34 and p.multipliers_per_channel == 17
    # 25-bit pre-adder x 18-bit tap = two 18x18 pieces (17-bit unsigned low limb).
    assert p.data_limbs == ((0, 17, False), (17, 8, True)) and p.dsp_blocks == 68
    assert p.tree_levels == 6 and p.latency == 13
    assert FirParams(in_width=17).dsp_blocks == 34
    q = FirParams(taps=HALFBAND, coef_bits=16)
    assert q.multipliers_per_channel == 4          # zeros cost no multiplier
    assert FirParams(out_shift=22).float_gain == 0.25


def test_float_reference_design_taps():
    """With the unquantised taps the reference differs from the quantised one by less than
    the coefficient quantisation allows."""
    rng = np.random.default_rng(10)
    x = _random_input(rng, TACAN, 2000)
    a = fir_float_reference(TACAN, x)
    b = fir_float_reference(TACAN, x, quantised_taps=False)
    bound = np.abs(TACAN.taps_quantised - np.array(TACAN.taps)).sum() * (1 << 23)
    assert np.abs(a - b).max() <= bound


# -- parameters ------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs,match", [
    (dict(taps=(0.1, 0.2, 0.3, 0.2)), r"FIR numtaps must be an odd integer >= 3 \(type I\), not 4"),
    (dict(taps=(1.0,)), r"FIR numtaps must be an odd integer >= 3 \(type I\), not 1"),
    (dict(taps=(0.1, 0.2, 0.3)), r"FIR taps must be symmetric \(h\[k\] == h\[L-1-k\], type I\)"),
    (dict(taps=(0.1, float("nan"), 0.1)), r"FIR taps must be finite"),
    (dict(taps=(0.0, 0.0, 0.0)), r"FIR taps must not be all zero"),
    (dict(taps=("a", "b", "c")), r"FIR taps must be a sequence of real numbers"),
    (dict(taps=(1e-9, 1.0, 1e-9), coef_bits=4, out_shift=0), None),   # small taps -> 0: fine
    (dict(coef_bits=1), r"FIR coef_bits must be an integer in \[2, 32\], not 1"),
    (dict(decimation=0), r"FIR decimation must be an integer >= 1, not 0"),
    (dict(decimation=1.5), r"FIR decimation must be an integer >= 1, not 1.5"),
    (dict(in_width=1), r"FIR in_width must be an integer in \[2, 62\], not 1"),
    (dict(channels=0), r"FIR channels must be 1 \(real\) or 2 \(complex\), not 0"),
    (dict(rounding="round"), r"FIR rounding must be one of .*, not 'round'"),
    (dict(overflow="clamp"), r"FIR overflow must be one of .*, not 'clamp'"),
    (dict(out_shift=-1), r"FIR out_shift must be an integer in \[0, 43\], not -1"),
    (dict(out_width=1), r"FIR out_width must be an integer in \[2, 62\], not 1"),
    (dict(in_width=50), r"FIR accumulator width must be <= 62 bits, not 71"),
])
def test_bad_params(kwargs, match):
    if match is None:
        FirParams(**kwargs)
        return
    with pytest.raises(ValueError, match=match):
        FirParams(**kwargs)


def test_bad_model_inputs():
    with pytest.raises(ValueError, match=r"FIR input must fit in 24 signed bits"):
        fir_model(TACAN, np.full((4, 2), 1 << 23))
    with pytest.raises(ValueError, match=r"FIR input must have shape"):
        fir_model(TACAN, np.zeros(4, dtype=np.int64))
    with pytest.raises(ValueError, match=r"FIR input must be integers"):
        fir_model(TACAN, np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"Fir needs a FirParams, not "):
        Fir(dict(decimation=2))
    assert fir_init_state(TACAN).hist.shape == (32, 2)


# -- Verilog ---------------------------------------------------------------------------------
@pytest.mark.verilator
@pytest.mark.skipif(find_executable("verilator") is None, reason="verilator not on PATH")
@pytest.mark.parametrize("name,p", [("fir_tacan", TACAN), ("fir_d3", CONFIGS[0]),
                                    ("fir_lowpass_wrap", CONFIGS[1]), ("fir_3tap", CONFIGS[3]),
                                    ("fir_shared4", SHARED[0]), ("fir_shared_one", SHARED[3])])
def test_verilog_lint(name, p):
    from cosim.core.provenance import REPO_ROOT
    from cosim.tools.verilog import export_verilog, lint
    path = export_verilog(Fir(p), name=name, out_dir=REPO_ROOT / "build" / "verilog" / "test")
    assert lint(path) == []


def test_cic_fir_chain_pulse_level():
    """TACAN chain levels: a Gaussian pulse of amplitude A through the CIC (gain 64) and the
    default FIR comes out with peak A * 64 * 1 (design_pulse_fir's normalisation)."""
    from hdl.model.cic import CicParams, cic_model
    cic = CicParams()
    fs, sigma = 20e6, 3.5e-6 / (2 * np.sqrt(2 * np.log(2)))
    t = (np.arange(4000) - 2000.3) / fs
    amp = 100_000
    pulse = np.round(amp * np.exp(-t ** 2 / (2 * sigma ** 2))).astype(np.int64)
    x = np.stack([pulse, -pulse], axis=1)
    y_cic, _ = cic_model(cic, x)
    y, st = fir_model(TACAN, y_cic)
    want = amp * cic.float_gain * TACAN.float_gain
    assert st.overflows == 0
    assert y[:, 0].max() == pytest.approx(want, rel=0.01)
    assert y[:, 1].min() == pytest.approx(-want, rel=0.01)


#: Compiled with Verilator: the TACAN FIR (parallel) and its time-shared variant.
VL_PARAMS = {"parallel": TACAN, "shared4": SHARED[0]}


@pytest.fixture(scope="module", params=sorted(VL_PARAMS))
def vl_fir(request):
    p = VL_PARAMS[request.param]
    dut = Fir(p)
    return p, dut, verilator_sim(dut, f"fir_{request.param}_vl")


def _vl_valid(rng, p: FirParams, n: int) -> np.ndarray:
    """Gaps in valid; at least ``input_spacing`` cycles apart for the time-shared design."""
    if p.input_spacing > 1:
        return _spaced_valid(rng, n, p.input_spacing)
    return rng.random(n + n // 10) < 0.93


@needs_verilator
def test_verilator_matches_pysim(vl_fir):
    """Random complex samples with gaps (at the guaranteed cadence), overrun probed."""
    p, dut, sim = vl_fir
    rng = np.random.default_rng(20260203)
    n = 2000 if p.input_spacing == 1 else 600   # pysim steps every cycle of the spacing
    words = _pack(p, _random_input(rng, p, n))
    kw = dict(in_valid=_vl_valid(rng, p, n), flush_cycles=p.latency + 4)
    want = run_stream(dut, words, probe={"overrun": dut.overrun}, **kw)
    got = sim.run(words, probe={"overrun": "overrun"}, **kw)
    assert_same_stream(got, want, "verilator vs pysim")
    assert len(got.words) == n // p.decimation and got.probes["overrun"].max() == 0


@needs_verilator
def test_verilator_matches_model_long(vl_fir):
    p, _, sim = vl_fir
    rng = np.random.default_rng(20260204)
    n = 1_000_000
    x = _random_input(rng, p, n)
    in_valid = _vl_valid(rng, p, n)
    res = sim.run(_pack(p, x), in_valid=in_valid, flush_cycles=p.latency + 4,
                  probe={"overrun": "overrun"})
    want, st = fir_model(p, x)
    np.testing.assert_array_equal(_unpack(p, res.words), want)
    d = p.decimation
    np.testing.assert_array_equal(res.cycles, accepted_cycles(n, in_valid)[d - 1::d] + p.latency)
    assert res.probes["overrun"].max() == 0 and st.overflows == 0


def test_fir_kernel_class_equals_model():
    """FirKernel (compiled, float64 accumulation) == fir_model on one channel, in chunks."""
    from hdl.model.fir import FirKernel
    p = FirParams(taps=default_fir_taps(), coef_bits=18, decimation=2, in_width=17,
                  channels=1, out_width=20, rounding="half_up", overflow="saturate")
    assert FirKernel.exact(p)
    rng = np.random.default_rng(61)
    x = rng.integers(-(1 << 16), 1 << 16, 3000)
    want, _ = fir_model(p, x)
    k = FirKernel(p)
    hist = np.zeros(len(p.taps_int) - 1, np.int64)
    got = np.concatenate([k.run(x[a:b].astype(np.int64), hist) for a, b in ((0, 1000), (1000, 3000))])
    np.testing.assert_array_equal(got, want)
