"""Monopulse front end: model == Amaranth simulation == Verilator, parameter errors, widths,
the noise-free angle against the float equations within the quantisation bound."""
import math
from dataclasses import replace

import numpy as np
import pytest

from _util import assert_lints_clean, needs_verilator, verilator_sim  # tests/hdl/conftest.py
from cosim.monopulse.signal import MonopulseSignalConfig, generate
from cosim.monopulse.trajectory import ConstantRate
from cosim.backends.pysim import run_stream
from dsp.monopulse.angles import direction_cosines
from dsp.monopulse.golden import golden_chain
from hdl.model.bus import bus_writes
from hdl.monopulse.frontend import MonopulseFrontEnd
from hdl.monopulse.model import MonopulseFrontendModel, angle_error_bound, hadamard_channels
from hdl.monopulse.params import (REG_COEF, REG_U0, REG_V0, MonopulseFrontendParams, coef_word,
                                  dc_word, pack_input)

#: Reduced sizes for the Amaranth simulation: 4 samples per snapshot, 12 snapshots a block.
SMALL = MonopulseFrontendParams(snapshots=12, cic_rate=4, snapshot_decimation=4,
                                cordic_iterations=12, angle_bits=16, fifo_depth=16)
#: CIC N=2, R=2 then a 5-tap FIR decimating by 2.
SMALL_FIR = replace(SMALL, cic_stages=2, cic_rate=2, fir_taps=(0.1, 0.3, 0.5, 0.3, 0.1),
                    fir_decim=2, fir_coef_bits=12, fir_out_bits=18)


def stimulus(p, n, seed, n_writes=4, ready_p=0.6):
    rng = np.random.default_rng(seed)
    lo = -(1 << (p.adc_bits - 1))
    x = rng.integers(lo, -lo, (n, 4))
    chips = rng.integers(0, 2, n)
    cyc = sorted(rng.choice(np.arange(2, n), n_writes, replace=False))
    writes = []
    for k, c in enumerate(cyc):
        reg = int(rng.integers(0, 6))
        if reg < 4:
            v = coef_word(complex(*rng.uniform(-1, 1, 2)), p)
        else:
            v = dc_word(float(rng.uniform(-0.9, 0.9)), p)
        writes.append((int(c), reg, v))
    ready = rng.random(n + 4000) < ready_p
    return x, chips, writes, ready


def model_run(p, x, chips, writes, ready, n_cycles, valid=None):
    cyc = None if valid is None else np.flatnonzero(valid)[:len(x)]
    return MonopulseFrontendModel(p).run(x, chips, writes, n_cycles=n_cycles, out_ready=ready,
                                         cycles=cyc)


def sim_run(dut_or_sim, p, x, chips, writes, ready, n_cycles, valid=None):
    kw = dict(in_valid=valid, out_ready=ready, n_cycles=n_cycles,
              writes=bus_writes(writes, data_width=p.reg_data_width))
    words = pack_input(x, chips, p)
    if hasattr(dut_or_sim, "run"):
        return dut_or_sim.run(words, **kw)
    return run_stream(dut_or_sim, words, **kw)


def assert_same(got, res):
    np.testing.assert_array_equal(np.asarray(got.words, np.int64), res.words)
    np.testing.assert_array_equal(got.cycles, res.cycles)


def test_pysim_matches_model_with_writes_and_backpressure():
    """Random ADC words and chips, register writes of every kind mid-run (one in a block
    boundary's neighbourhood is likely), a DSP that stalls: same FIFO words on the same
    cycles. The run is long enough for the 16-word FIFO to drop records (markers)."""
    p = SMALL
    n = 6 * 12 * 4 + 20
    x, chips, writes, ready = stimulus(p, n, seed=1, n_writes=8, ready_p=0.15)
    n_cycles = n + p.latency + 60
    r, res = model_run(p, x, chips, writes, ready, n_cycles)
    assert len(r.values) == 6
    assert res.dropped.any()          # back-pressure reached the drop policy
    got = sim_run(MonopulseFrontEnd(p), p, x, chips, writes, ready, n_cycles)
    assert_same(got, res)


def test_pysim_fir_chain_with_adc_gaps_matches_model():
    p = SMALL_FIR
    n = 4 * 12 * 4 + 10
    x, chips, writes, ready = stimulus(p, n, seed=2, n_writes=5, ready_p=0.7)
    valid = np.random.default_rng(22).random(2 * n) < 0.8
    n_cycles = int(np.flatnonzero(valid)[n - 1]) + p.latency + 60
    r, res = model_run(p, x, chips, writes, ready, n_cycles, valid)
    assert len(r.values) >= 3
    got = sim_run(MonopulseFrontEnd(p), p, x, chips, writes, ready, n_cycles, valid)
    assert_same(got, res)


def test_model_chunks_give_the_same_records():
    p = SMALL_FIR
    n = 7 * 48 + 5
    x, chips, writes, _ = stimulus(p, n, seed=3, n_writes=6)
    whole = MonopulseFrontendModel(p).step(x, chips, writes, horizon=n + 100)
    m = MonopulseFrontendModel(p)
    cuts = [0, 1, 47, 48, 49, 130, 200, 333, n]
    cyc, vals = [], []
    for a, b in zip(cuts[:-1], cuts[1:]):
        r = m.step(x[a:b], chips[a:b], [w for w in writes if a <= w[0] < b])
        cyc.append(r.cycles)
        vals += r.values
    r = m.advance(n + 100)    # the last block's boundary lies after the last sample
    cyc.append(r.cycles)
    vals += r.values
    np.testing.assert_array_equal(np.concatenate(cyc), whole.cycles)
    assert vals == whole.values and len(vals) == 7


def test_register_latch_at_the_block_boundary():
    """A coefficient write takes effect from the next block on: the record of the block it
    is written in is unchanged, the next one differs; a write in the boundary cycle itself
    (the cycle the block's last snapshot enters the correction) waits one more block."""
    p = SMALL
    n = 4 * 48
    x, chips, _, _ = stimulus(p, n, seed=4, n_writes=1)
    w = coef_word(0.3 + 0.4j, p)

    def recs(writes):
        return MonopulseFrontendModel(p).step(x, chips, writes).values

    base = recs([])
    boundary = 47 + p.latency_pre          # block 0 ends with ADC sample 47
    assert recs([(10, REG_COEF + 2, w)])[0] == base[0]
    assert recs([(10, REG_COEF + 2, w)])[1] != base[1]
    late = recs([(boundary, REG_COEF + 2, w)])
    assert late[:2] == base[:2] and late[2] != base[2]
    early = recs([(boundary - 1, REG_COEF + 2, w)])
    assert early[1] != base[1]
    writes = [(boundary, REG_COEF + 2, w), (boundary - 1, REG_U0, dc_word(0.5, p))]
    _, res = model_run(p, x, chips, writes, None, n + p.latency + 40)
    got = sim_run(MonopulseFrontEnd(p), p, x, chips, writes, None, n + p.latency + 40)
    assert_same(got, res)


@pytest.mark.parametrize("kw, msg", [
    (dict(snapshots=0), r"monopulse snapshots must be an integer in \[1, 2\*\*24\], not 0"),
    (dict(adc_bits=1), r"monopulse adc_bits must be an integer in \[2, 16\], not 1"),
    (dict(cic_rate=5), r"cic_rate \* fir_decim must equal snapshot_decimation .*5 \* 1 != 10"),
    (dict(fir_decim=2, cic_rate=5), r"fir_decim must be 1 without a FIR .*not 2"),
    (dict(spacing_x_wl=0.0), r"spacing_x_wl must be > 0, not 0.0"),
    (dict(spacing_y_wl=0.3), r"spacing_y_wl must be >= 0.5 wavelengths, not 0.3"),
    (dict(if_hz=60e6), r"if_hz must lie in \(0, fs_hz/2 = 5e\+07\) Hz, not 60000000.0"),
    (dict(fs_hz=float("nan")), r"fs_hz must be a finite number, not nan"),
    (dict(corr_coef_bits=19), r"corr_coef_bits must be an integer in \[2, 18\], not 19"),
    (dict(cordic_iterations=2), r"cordic_iterations must be an integer in \[4, 32\], not 2"),
    (dict(snapshots=2),
     r"block too short: snapshots \* snapshot_decimation = 20 cycles must be >= 44"),
    (dict(cic_out_bits=None, mixer_out_bits=20, cic_stages=2, cic_rate=1024,
          snapshot_decimation=1024), r"snapshot width \(decimator output\) must be <= 30 "
                                     r"bits, not 40"),
])
def test_parameter_errors(kw, msg):
    with pytest.raises(ValueError, match=msg):
        MonopulseFrontendParams(**kw)


def test_write_and_input_errors():
    p = SMALL
    m = MonopulseFrontendModel(p)
    z = np.zeros((8, 4), np.int64)
    b = p.corr_coef_bits
    with pytest.raises(ValueError, match=r"monopulse register coef1 \(address 0\) takes 36-bit "
                                         r"words of 2 two's complement 18-bit parts \(LSB "
                                         r"first\), each in \[-131071, 131071\], not 131072"):
        m.step(z, np.zeros(8, int), [(1, REG_COEF, 1 << (b - 1))])
    with pytest.raises(ValueError, match=r"monopulse register coef2 \(address 1\) takes .*, "
                                         r"not 34359738368"):   # im part -131072
        m.step(z, np.zeros(8, int), [(1, REG_COEF + 1, 1 << (2 * b - 1))])
    with pytest.raises(ValueError, match=r"monopulse register v0 \(address 5\) takes 25-bit "
                                         r"two's complement words in \[-4194304, 4194304\], "
                                         r"not 6291456"):
        m.step(z, np.zeros(8, int), [(1, REG_V0, dc_word(0.75, p) * 2)])
    with pytest.raises(ValueError, match=r"monopulse register u0 \(address 4\) takes .*, "
                                         r"not -1"):   # a word is the register's bits
        m.step(z, np.zeros(8, int), [(1, REG_U0, -1)])
    with pytest.raises(ValueError, match=r"monopulse register address must be one of 0, 1, 2, "
                                         r"3, 4, 5, not 6"):
        m.step(z, np.zeros(8, int), [(1, 6, 0)])
    with pytest.raises(ValueError, match=r"replica bits must be 0 \(\+1\) or 1 \(-1\)"):
        m.step(z, np.full(8, 2))
    with pytest.raises(ValueError, match=r"ADC samples must have shape \(n, 4\), not \(8, 3\)"):
        m.step(np.zeros((8, 3), np.int64), np.zeros(8, int))
    with pytest.raises(ValueError, match=r"DDC input x must be signed 12-bit integers"):
        MonopulseFrontendModel(p).step(np.full((8, 4), 4096), np.zeros(8, int))
    with pytest.raises(ValueError, match=r"MonopulseFrontEnd needs a MonopulseFrontendParams, "
                                         r"not 3"):
        MonopulseFrontEnd(3)


def test_widths_are_derived():
    p = MonopulseFrontendParams()
    assert p.nco_freq_word == round(0.2 * 2 ** 32)          # 20 MHz at 100 MS/s
    assert p.cic.full_width == 16 + 4 and p.snap_width == 18
    assert p.beam_width == 18 + 2
    assert p.acc_width == 20 + 13                  # N = 8192: 13 bits of growth
    assert p.cordic.width == 33 and p.shift_bits == 5
    assert p.dc_bits == 25
    assert p.record_bits == 16 + 2 * 25 + 2 * 24 + 5 + 8 * 33
    assert p.record_words == -(-p.record_bits // 48) == p.fifo.record_words
    assert p.corr.latency == 5 + 1                # complex mixer, 2 input stages
    assert p.latency == p.ddc.latency + p.cic.latency + 6 + 2 + 10 + 20
    assert MonopulseFrontendParams(snapshots=8193).acc_width == 20 + 14
    k, s = p.dc_coefs[0]
    assert abs(k / 2 ** (s + p.dc_frac_bits - p.angle_bits) - 0.5) < 1e-12   # 2 / Dx, Dx = 4


@pytest.mark.parametrize("small", [True, False])
def test_verilog_lint_clean(small):
    if small:
        assert_lints_clean(MonopulseFrontEnd(SMALL), "monopulse_frontend_small")
    else:
        assert_lints_clean(MonopulseFrontEnd(MonopulseFrontendParams()), "monopulse_frontend")


@needs_verilator
@pytest.mark.parametrize("fir", [False, True])
def test_verilator_small_matches_model(fir):
    p, name, seed = ((SMALL_FIR, "monopulse_frontend_small_fir", 6) if fir else
                     (SMALL, "monopulse_frontend_small", 5))
    n = 20 * 48
    x, chips, writes, ready = stimulus(p, n, seed=seed, n_writes=12, ready_p=0.3)
    valid = np.random.default_rng(seed).random(2 * n) < 0.9
    n_cycles = int(np.flatnonzero(valid)[n - 1]) + p.latency + 60
    r, res = model_run(p, x, chips, writes, ready, n_cycles, valid)
    assert len(r.values) >= 19
    got = sim_run(verilator_sim(MonopulseFrontEnd(p), name), p, x, chips, writes, ready,
                  n_cycles, valid)
    assert_same(got, res)


@needs_verilator
def test_verilator_default_front_end_matches_model():
    """Default parameters (N = 8192, 10 samples a snapshot): 2 blocks of a noisy monopulse
    signal, steering and coefficient writes in both, a slow DSP."""
    p = MonopulseFrontendParams()
    x, chips, k, _ = monopulse_signal(p, snr_db=-8.0, n_blocks=2, du=0.03, dv=-0.02)
    rng = np.random.default_rng(7)
    writes = [(1000 + i, REG_COEF + i, coef_word(k[i], p)) for i in range(4)]
    writes += [(90000, REG_U0, dc_word(0.21, p)), (150000, REG_COEF + 3, coef_word(0.5j, p))]
    ready = rng.random(len(x) + 2000) < 0.05
    n_cycles = len(x) + p.latency + 400
    r, res = model_run(p, x, chips, writes, ready, n_cycles)
    assert len(r.values) == 2
    got = sim_run(verilator_sim(MonopulseFrontEnd(p), "monopulse_frontend"), p, x, chips,
                  writes, ready, n_cycles)
    assert_same(got, res)


# -- the angle against the float equations ---------------------------------------------------

STEER = (0.25, 0.15)


def monopulse_signal(p, *, snr_db, n_blocks, du, dv, phase=0.7, seed=1):
    """ADC codes (n, 4), replica bits, steering coefficients and the signal record."""
    cfg = MonopulseSignalConfig(snapshots=p.snapshots, snr_db=snr_db, carrier_phase_rad=phase,
                                trajectory=ConstantRate(u0=STEER[0] + du, v0=STEER[1] + dv),
                                seed=seed)
    rec = generate(cfg, STEER, 0, n_blocks)
    chips = np.repeat((rec.replica < 0).astype(np.int64).ravel(), cfg.decimation)
    k = cfg.array.steering_correction(*STEER)
    return rec.samples.T.astype(np.int64), chips, k, (cfg, rec)


def lo_image_error(p, first_sample, n):
    """``|E2|``: the relative image the quantised LO leaves in every channel over samples
    ``[first_sample, first_sample + n)`` (the ideal LO's image sums to zero over each
    integrate-and-dump window), computed exactly from the NCO model's table: with
    ``LO = e^(-j theta)(1 + eps)``, a real input ``Re(h e^(j theta))`` gives ``h (1 + E1) +
    conj(h) E2``, ``E1 = mean eps`` (common to the channels: cancels in the ratios),
    ``E2 = mean e^(-2 j theta) (1 + eps)``. Also ``max |eps|``."""
    from hdl.model.nco import NcoModel
    cos, sin, _ = NcoModel(p.nco).run(first_sample + n, p.nco_freq_word)
    m = np.arange(first_sample, first_sample + n)
    theta = 2 * np.pi * np.mod(m * (p.if_hz / p.fs_hz), 1.0)
    lo = (cos[first_sample:] - 1j * sin[first_sample:]) / p.nco.peak
    eps = lo * np.exp(1j * theta) - 1
    return abs(np.mean(np.exp(-2j * theta) * (1 + eps))), float(np.max(np.abs(eps)))


def quantisation_bound(p, rec_fields, j, adc_amp_lsb):
    """Bound on |u_hw - u_float| (and v) for record ``j`` of a noise-free run, the float
    computed by :mod:`dsp.monopulse.angles` from the golden chain on the same ADC codes.

    Terms (worst cases except the LO image, computed exactly): (1) the LO image
    (:func:`lo_image_error`, times 1.1 for the common ``1 + E1`` normalisation) and the LO
    error times the ADC codes' own rounding (<= 1/2 LSB against the signal's ADC amplitude);
    (2) rounding: mixer, CIC and correction each round by <= 1/2 LSB, referred to the
    corrected snapshot through the gains (each coefficient part <= 1, so |k| <= sqrt 2),
    summed over N snapshots and 4 channels; (3) the normalisation's floor (<= 1 LSB per part
    after the shift). The beam errors then bound the ratio's error ``|d r| <= (|dD| + |r|
    |dS|) / (|S| - |dS|)``, ``u = u0 + atan(Im r) / (pi D)``; (4) the angle unit
    (:func:`hdl.monopulse.model.angle_error_bound`)."""
    f = {k: int(v[j]) for k, v in rec_fields.items()}
    amp = float(np.max(np.abs(hadamard_channels(f))))
    n = p.snapshots * p.snapshot_decimation
    e2, eps_max = lo_image_error(p, j * n, n)
    rel = 1.1 * e2 + eps_max * 0.5 / adc_amp_lsb
    g_cic = p.cic.gain / 2 ** p.cic.out_shift
    g_c = math.sqrt(2) * 2 ** (p.corr_coef_bits - 1) / 2 ** p.corr.drop_bits
    e_snap = math.sqrt(2) * (0.5 + g_c * (0.5 + 0.5 * g_cic))
    d_beam = 4 * (rel * amp + p.snapshots * e_snap) + math.sqrt(2) * 2 ** f["shift"]
    s = abs(f["s_re"] + 1j * f["s_im"])
    out = []
    for name, d in (("da", p.spacing_x_wl), ("de", p.spacing_y_wl)):
        r = abs(f[f"{name}_re"] + 1j * f[f"{name}_im"]) / s
        dr = (d_beam + r * d_beam) / (s - d_beam)
        out.append(dr / (math.pi * d))
    xr = (s / 2 ** f["shift"]) ** 2
    ua, va = angle_error_bound(p, xr)
    return out[0] + ua, out[1] + va


@pytest.mark.parametrize("du, dv", [(0.1, 0.1), (-0.1, 0.07), (0.05, -0.1), (-0.08, -0.06),
                                    (0.0, 0.0), (0.1, -0.004)])
def test_noise_free_angle_matches_the_float_equations(du, dv):
    """No noise, N = 256 (so the test is fast; the bound scales with N): block 1 (the one
    after the steering/coefficient writes took effect) gives (u, v) within the quantisation
    bound of the float angle equations on the same ADC codes; the bound is below 5 % of
    the unambiguous half-width so the check means something (the error itself is ~1e-5-1e-4:
    the 10-bit LO table's image dominates)."""
    p = replace(MonopulseFrontendParams(), snapshots=256)
    x, chips, k, (cfg, rec) = monopulse_signal(p, snr_db=None, n_blocks=2, du=du, dv=dv)
    writes = [(10 + i, REG_COEF + i, coef_word(k[i], p)) for i in range(4)]
    writes += [(20, REG_U0, dc_word(STEER[0], p)), (21, REG_V0, dc_word(STEER[1], p))]
    r = MonopulseFrontendModel(p).step(x, chips, writes, horizon=len(x) + p.latency)
    s = golden_chain(rec.samples, rec.scale, rec.replica, k, cfg.if_hz, cfg.fs_hz,
                     cfg.decimation)
    u_f, v_f = direction_cosines(s, STEER[0], STEER[1], p.spacing_x_wl, p.spacing_y_wl)
    u_hw = r.fields["u"][1] / 2 ** p.dc_frac_bits
    v_hw = r.fields["v"][1] / 2 ** p.dc_frac_bits
    bu, bv = quantisation_bound(p, r.fields, 1, 1.0 / rec.scale)
    assert bu < 6.25e-3 and bv < 6.25e-3, (bu, bv)       # 5 % of 1 / (2 D)
    assert abs(u_hw - u_f[1]) <= bu, (u_hw - u_f[1], bu)
    assert abs(v_hw - v_f[1]) <= bv, (v_hw - v_f[1], bv)
    f = p.record.unpack(r.values[1])
    assert (f["u"], f["v"]) == (r.fields["u"][1], r.fields["v"][1])


@pytest.mark.synth
@pytest.mark.slow
def test_synth_meets_100mhz():
    from cosim.tools.synth import synth, yowasp_available
    if not yowasp_available():
        pytest.skip("YoWASP yosys/nextpnr not installed")
    from hdl.monopulse.frontend import monopulse_top
    r = synth(monopulse_top(), name="monopulse_frontend", target_mhz=100)
    assert r["timing_met"] and r["fmax_mhz"] >= 100, r["fmax_mhz"]
