"""TACAN front-end top: params, model (fast == block chain, chunking), Amaranth sim ==
model, Verilator == model (incl. DSP stalls), lint, quantisation bound vs the golden chain;
the same with the pair detection, and with both searches (pulses and pairs merged into one
FIFO stream, including the cycle where both emit)."""
from __future__ import annotations

import math
import shutil
from dataclasses import replace

import numpy as np
import pytest

from cosim.equivalence import check_equivalence, stall_pattern, tacan_record
from cosim.pysim import run_stream
from cosim.tacan.signal import TacanSignalConfig, generate
from dsp.fixed import shift_right
from dsp.tacan.frontend import PAIR_DETECTOR, FrontendConfig, pair_detector, run_golden_frontend
from dsp.tacan.standard import SOURCE_PAIR, SOURCE_PULSE, pair_spacing_s
from dsp.tacan.peak_params import PeakParams
from hdl.tacan.peak_model import peak_search
from hdl.model.fir import fir_kernel as _fir_kernel
from hdl.model.rounding import round_consts as _round_consts
from hdl.tacan.model import FrontendPeaks, TacanFrontendModel
from hdl.tacan.params import TacanFrontendParams, amp_error_terms
from hdl.tacan.frontend import TacanFrontEnd

P = TacanFrontendParams()
HAVE_VERILATOR = shutil.which("verilator") is not None


# -- parameters ------------------------------------------------------------------------------
def test_widths_chain_and_derived_values():
    p = P
    assert p.ddc.adc_width == 12
    assert p.cic.in_width == p.ddc.out_width
    assert p.fir.in_width == p.cic.out_width
    assert p.envelope.in_width == p.fir.out_width
    assert p.peak.amp_width == p.envelope.out_width
    assert p.fifo.width == p.peak.amp_width + p.peak.ts_bits
    assert p.peak.ts_step == p.config.decimation == 4
    assert p.fir.numtaps == 33 and np.allclose(p.fir.taps, p.config.fir_taps)
    assert p.fir.data_limbs == ((0, 18, True),) and p.fir.coef_limbs == ((0, 18, True),)
    assert p.nco_freq_word == round(3e6 / 20e6 * 2 ** 32)
    assert p.latency == p.peak_latency + 2
    assert p.group_delay_samples == p.config.group_delay_samples - 3
    # thr_min is the golden's thr_min_fs in envelope LSBs.
    assert abs(p.peak.thr_min * p.scale_to_fs - p.config.thr_min_fs) < p.scale_to_fs


def test_scale_to_fs_from_a_carrier():
    """A constant carrier of amplitude A FS at the IF comes out as the golden's level: A
    times the FIR's DC gain (1.21; the golden keeps it too)."""
    a = 0.5
    n = np.arange(40_000)
    x = np.round(a * 2047 * np.cos(2 * np.pi * 0.15 * n + 0.3)).astype(np.int64)
    e, _ = TacanFrontendModel(P).envelope(x)
    level = np.median(e[2000:]) * P.scale_to_fs
    assert abs(level - a * 2047 / 2048 * sum(P.config.fir_taps)) < 2e-4


@pytest.mark.parametrize("kw, msg", [
    (dict(adc_bits=0), r"ADC adc_bits must be an integer in \[2, 18\], not 0"),
    (dict(nco_table_bits=12, nco_phase_bits=10), "NCO LUT larger than the phase width"),
    (dict(mixer_out_bits=0), r"mixer out_width must be an integer in \[2, 48\], not 0"),
    (dict(cic_out_bits=30), r"CIC out_width must be an integer in \[2, 22\]"),
    (dict(mixer_rounding="up"), "mixer_rounding must be one of"),
    (dict(fifo_depth=0), "FIFO depth must be >= 1, not 0"),
    (dict(fir_input_spacing=5), r"fir_input_spacing must be an integer in \[1, cic_rate = 4\]"),
    (dict(fir_out_bits=17), "fir output can overflow: a full-scale ADC input reaches 79452 LSB "
                            "but fir words hold 65535"),
    (dict(config=None), "config must be a FrontendConfig, not None"),
])
def test_bad_parameters(kw, msg):
    with pytest.raises(ValueError, match=msg):
        TacanFrontendParams(**kw)


def test_headroom_check_can_be_waived_for_studies():
    p = TacanFrontendParams(fir_out_bits=17, check_headroom=False)
    assert p.headroom()["fir"][0] > p.headroom()["fir"][1]
    assert not TacanFrontendModel(p).fast


def test_full_scale_pulse_does_not_overflow():
    """A full-scale (clipping) pulse burst: no stage saturates in the block models."""
    n = np.arange(60_000)
    env = np.exp(-0.5 * ((n % 6000 - 3000) / 30.0) ** 2)
    x = np.clip(np.round(2100 * env * np.cos(2 * np.pi * 0.15 * n)), -2048, 2047).astype(np.int64)
    x[::7] = np.where(x[::7] > 0, 2047, -2048)   # the rails, both signs
    m = TacanFrontendModel(P, fast=False)
    e, st = m.envelope(x)
    assert st.cic.overflows == 0 and st.fir.overflows == 0
    assert e.max() < (1 << P.envelope.out_width) - 1   # envelope never saturates
    assert e.max() <= P.headroom()["envelope"][0]
    # the mixer's worst case is exactly in range (checked by headroom()): |x*lo| >> 11
    assert P.headroom()["mixer"] == (32767, 32767)


# -- model -----------------------------------------------------------------------------------
def test_fast_path_equals_block_chain_and_chunking():
    rng = np.random.default_rng(11)
    x = tacan_record(120_003, seed=4)
    x[1000:1200] = rng.integers(-2048, 2048, 200)      # rails and wideband junk
    fast, slow = TacanFrontendModel(P), TacanFrontendModel(P, fast=False)
    assert fast.fast and not slow.fast
    e1, _ = fast.envelope(x)
    e2, _ = slow.envelope(x)
    np.testing.assert_array_equal(e1, e2)
    whole, _ = fast.run(x)
    for m in (fast, slow):
        st, parts = None, []
        for chunk in np.array_split(x, [1, 4097, 50_001, 50_002, 99_999]):
            pk, st = m.run(chunk, st)
            parts.append(pk)
        for f in ("amplitudes", "timestamps", "index", "end_index"):
            np.testing.assert_array_equal(np.concatenate([getattr(q, f) for q in parts]),
                                          getattr(whole, f))
    assert len(whole) > 20


def test_freq_changes_fast_equals_block_chain_and_chunking():
    """NCO word writes (DSP -> FPGA) at arbitrary samples, also inside a decimation group and
    across chunk boundaries: the compiled path, the block chain and chunked runs agree, and
    the writes do change the output."""
    x = tacan_record(120_003, seed=6)
    f0 = P.nco_freq_word
    changes = [(5, f0 + 12345), (4_037, f0 - 99_999), (50_001, f0), (50_002, f0 + 7),
               (99_998, (1 << P.nco_phase_bits) - 3)]
    fast, slow = TacanFrontendModel(P), TacanFrontendModel(P, fast=False)
    whole, _ = fast.run(x, freq_changes=changes)
    ref, _ = slow.run(x, freq_changes=changes)
    plain, _ = fast.run(x)
    for f in ("amplitudes", "timestamps"):
        np.testing.assert_array_equal(getattr(whole, f), getattr(ref, f))
    assert not np.array_equal(whole.amplitudes, plain.amplitudes)
    for m in (fast, slow):
        st, parts = None, []
        for chunk in np.array_split(x, [3, 4097, 50_001, 99_999]):
            pk, st = m.run(chunk, st, freq_changes=changes)
            parts.append(pk)
        np.testing.assert_array_equal(np.concatenate([q.amplitudes for q in parts]),
                                      whole.amplitudes)
        assert st.freq == changes[-1][1]
    with pytest.raises(ValueError, match="strictly increasing"):
        fast.run(x, freq_changes=[(10, f0), (10, f0)])
    with pytest.raises(ValueError, match="freq words must lie in"):
        fast.run(x, freq_changes=[(10, -1)])


def _variant(cfg_kw, **kw):
    dec = cfg_kw.get("cic_rate", 4) * cfg_kw.get("fir_decim", 1)
    return TacanFrontendParams(config=FrontendConfig(**cfg_kw, peak=PeakParams(ts_step=dec)), **kw)


#: Structures and roundings for the compiled fast path's general branches (any N, R, M,
#: FIR decimation, every rounding mode, a left-shifting mixer).
FAST_VARIANTS = [
    ({}, {}),
    ({"cic_stages": 4, "cic_rate": 5, "cic_delay": 2, "fir_numtaps": 21, "fir_decim": 2}, {}),
    ({"cic_stages": 2, "cic_rate": 2, "fir_numtaps": 15, "fir_decim": 2}, {}),
    ({}, dict(mixer_rounding="zero", cic_rounding="floor", fir_rounding="half_even",
              env_rounding="floor")),
    ({}, dict(mixer_rounding="half_up", cic_rounding="zero", fir_rounding="zero",
              fir_out_shift_rel=1, fir_out_bits=19, env_out_bits=22)),
    ({}, dict(mixer_headroom_bits=1, mixer_rounding="floor", mixer_out_bits=18,
              cic_out_bits=18, fir_out_bits=19)),
    ({}, dict(adc_bits=8, nco_amp_bits=8)),          # mixer drop_bits < 0: a left shift
]


def _hard_record(p, n, seed):
    """TACAN IF with wideband junk, both rails and long full-scale runs."""
    rng = np.random.default_rng(seed)
    lo = 1 << (p.adc_bits - 1)
    x = tacan_record(n, seed=seed) >> (12 - p.adc_bits)
    x[1000:1600] = rng.integers(-lo, lo, 600)
    x[5000:5400] = lo - 1
    x[5400:5800] = -lo
    x[20_000:20_300] = np.where(rng.random(300) < 0.5, lo - 1, -lo)
    return x


@pytest.mark.parametrize("k", range(len(FAST_VARIANTS)))
def test_fast_path_equals_block_chain_variants(k):
    """The compiled fast path == the chained block models, whole and in odd chunks (down
    to fewer samples than a decimation group, so ``pending`` carries them)."""
    p = _variant(FAST_VARIANTS[k][0], **FAST_VARIANTS[k][1])
    fast, slow = TacanFrontendModel(p), TacanFrontendModel(p, fast=False)
    assert fast.fast and not slow.fast
    x = _hard_record(p, 60_001, seed=20 + k)
    e_fast, st_fast = fast.envelope(x)
    e_slow, st_slow = slow.envelope(x)
    np.testing.assert_array_equal(e_fast, e_slow)
    assert st_fast.nco == st_slow.nco and st_fast.n_adc == st_slow.n_adc
    np.testing.assert_array_equal(st_fast.pending, st_slow.pending)
    st, parts = None, []
    for chunk in np.array_split(x, [3, 5, 4001, 4002, 33_333, 59_990]):
        e, st = fast.envelope(chunk, st)
        parts.append(e)
    np.testing.assert_array_equal(np.concatenate(parts), e_fast)
    whole, _ = fast.run(x)
    ref, _ = slow.run(x)
    for f in ("amplitudes", "timestamps", "index", "end_index"):
        np.testing.assert_array_equal(getattr(whole, f), getattr(ref, f))


def test_fast_path_across_internal_chunks_and_input_dtypes():
    """Longer than :attr:`TacanFrontendModel.CHUNK` (the CIC/FIR registers carried between
    internal chunks), random full-range codes included; int16 input gives the same bits;
    a state passed in is not modified."""
    x = _hard_record(P, 3 * TacanFrontendModel.CHUNK // 2 + 7, seed=31)
    rng = np.random.default_rng(31)
    x[200_000:260_000] = rng.integers(-2048, 2048, 60_000)
    fast, slow = TacanFrontendModel(P), TacanFrontendModel(P, fast=False)
    pk_fast, st_fast = fast.run(x)
    pk_slow, st_slow = slow.run(x)
    for f in ("amplitudes", "timestamps", "index", "end_index"):
        np.testing.assert_array_equal(getattr(pk_fast, f), getattr(pk_slow, f))
    assert st_fast.peak == st_slow.peak and st_fast.nco == st_slow.nco
    pk16, _ = fast.run(x.astype(np.int16))
    np.testing.assert_array_equal(pk16.amplitudes, pk_fast.amplitudes)
    # the same state twice gives the same continuation
    _, st = fast.envelope(x[:10_000])
    e1, _ = fast.envelope(x[10_000:30_000], st)
    e2, _ = fast.envelope(x[10_000:30_000], st)
    np.testing.assert_array_equal(e1, e2)


def test_fast_path_rejects_out_of_range_codes():
    m = TacanFrontendModel(P)
    x = np.zeros(4000, np.int64)
    x[1234] = 2048
    with pytest.raises(ValueError, match="ADC codes must be signed 12-bit integers"):
        m.envelope(x)
    x[1234] = -2049
    with pytest.raises(ValueError, match="ADC codes must be signed 12-bit integers"):
        m.run(x)


@pytest.mark.parametrize("L", [1, 2, 3, 4, 7, 32, 33])
@pytest.mark.parametrize("down", [1, 3])
def test_fir_kernel_equals_direct_sum(L, down):
    """The compiled FIR (folded when symmetric, several taps per pass) == the exact integer
    sum, for odd/even, symmetric and not, with history and every rounding."""
    rng = np.random.default_rng(L * 10 + down)
    for sym in (False, True):
        h = rng.integers(-2 ** 17, 2 ** 17, L)
        if sym:
            h = (h + h[::-1]) // 2
        z = rng.integers(-2 ** 16, 2 ** 16, 3001)
        hist = rng.integers(-2 ** 16, 2 ** 16, L - 1)
        buf = np.concatenate([hist, z])
        full = np.array([int(np.dot(h[::-1], buf[k:k + L])) for k in range(len(z))])
        full = full[down - 1::down]
        for rounding in ("floor", "half_up", "half_even", "zero"):
            hh = hist.copy()
            out = np.empty(len(z) // down, np.int64)
            _fir_kernel(z, hh, h.astype(np.float64), bool(np.array_equal(h, h[::-1])), down,
                        _round_consts(7, rounding), out)
            np.testing.assert_array_equal(out, shift_right(full, 7, rounding))
            np.testing.assert_array_equal(hh, buf[len(buf) - (L - 1):])


# -- Amaranth simulation == model ------------------------------------------------------------
def test_pysim_equals_model():
    """~1 ms of SNR 10 dB TACAN IF (about 20 s of pysim): every FIFO word and its cycle."""
    x = tacan_record(20_000, seed=2)
    m = TacanFrontendModel(P)
    pk, _ = m.run(x)
    dut = TacanFrontEnd(P)
    res = run_stream(dut, x, n_cycles=len(x) + 300, inputs={"freq": P.nco_freq_word},
                     probe={"ovf": dut.overflow_count})
    ref = m.fifo_output(pk, res.n_cycles)
    assert len(pk) >= 3
    np.testing.assert_array_equal(res.words, ref.words)
    np.testing.assert_array_equal(res.cycles, ref.cycles)
    assert not res.probes["ovf"].any()
    # latency: the first word leaves params.latency cycles after its closing ADC sample
    adc = (pk.end_index[0] + 1) * P.decimation - 1
    assert res.cycles[0] == adc + P.latency


def test_pysim_gaps_in_valid_and_dsp_stalls():
    """ADC valid with gaps and a DSP that stalls on a 1-deep FIFO: drops and markers."""
    p = TacanFrontendParams(fifo_depth=1)
    x = tacan_record(14_000, seed=11)     # 7 peaks in 0.7 ms
    rng = np.random.default_rng(11)
    in_valid = rng.random(17_000) < 0.85
    n_cycles = int(np.flatnonzero(in_valid)[len(x) - 1]) + 300
    ready = np.zeros(n_cycles, bool)
    ready[-150:] = True                                   # DSP wakes up at the end
    m = TacanFrontendModel(p)
    pk, _ = m.run(x)
    dut = TacanFrontEnd(p)
    res = run_stream(dut, x, in_valid=in_valid, out_ready=ready, n_cycles=n_cycles,
                     inputs={"freq": p.nco_freq_word}, probe={"ovf": dut.overflow_count})
    ref = m.fifo_output(pk, n_cycles, in_valid=in_valid, out_ready=ready)
    np.testing.assert_array_equal(res.words, ref.words)
    np.testing.assert_array_equal(res.cycles, ref.cycles)
    np.testing.assert_array_equal(res.probes["ovf"], ref.overflow_count)
    assert ref.dropped.sum() >= 1 and (m.unpack(ref.words)["tag"] == 2).sum() >= 1


@pytest.mark.slow
def test_pysim_equals_model_long():
    r = check_equivalence(samples=100_000, backends=("model", "pysim"), seed=3,
                          pysim_max_samples=100_000)
    assert r["mismatches"] == 0 and "pysim" in r["backends"]


# -- Verilator -------------------------------------------------------------------------------
verilator = pytest.mark.skipif(not HAVE_VERILATOR, reason="verilator not on PATH")


@pytest.mark.verilator
@verilator
@pytest.mark.parametrize("samples, stall", [(20_000, False), (200_000, False), (400_000, True)])
def test_verilator_equals_model(samples, stall):
    r = check_equivalence(samples=samples, backends=("model", "verilator"), seed=1,
                          stall=stall)
    assert r["backends"] == ["model", "verilator"]
    assert r["mismatches"] == 0, r
    assert r["peaks"] > 0
    if stall:
        assert r["dropped"] > 0 and r["markers"] > 0


@pytest.mark.verilator
@verilator
def test_exported_top_lints_clean(tmp_path):
    from cosim.verilog import export_verilog, lint
    path = export_verilog(TacanFrontEnd(P), name="tacan_frontend", out_dir=tmp_path)
    assert lint(path) == []


# -- quantisation vs the golden chain ---------------------------------------------------------
def _match(h_ts, g_ts, tol):
    j = np.clip(np.searchsorted(g_ts, h_ts), 1, max(len(g_ts) - 1, 1))
    jj = np.where(np.abs(g_ts[j - 1] - h_ts) <= np.abs(g_ts[j] - h_ts), j - 1, j)
    ok = np.abs(h_ts - g_ts[jj]) <= tol
    return jj, ok


def _sampling_phase_bound(p: TacanFrontendParams) -> float:
    """Relative amplitude loss bound when the envelope peak is sampled up to D/2 ticks off
    its top: the pulse after the matched chain is ~Gaussian with variance sigma_p**2 plus the
    filter's, so the loss is <= (D/2)**2 / (2 sigma_e**2)."""
    cfg = p.config
    h = np.convolve(np.repeat(np.asarray(p.fir.taps), cfg.cic_rate)[:: 1],
                    np.asarray(p.cic.impulse_response, float))
    t = np.arange(len(h))
    var_h = np.sum(h * (t - np.sum(h * t) / h.sum()) ** 2) / h.sum()
    sigma_e2 = (cfg.pulse_sigma_s * cfg.fs_hz) ** 2 + var_h
    return (p.decimation / 2) ** 2 / (2 * sigma_e2)


@pytest.mark.parametrize("snr_db", [None, 10.0])
def test_quantisation_bound_vs_golden(snr_db):
    """30 ms of TACAN IF. (1) Golden fed the record from ADC tick D-1 (the hardware's
    envelope sampling phase): same pulses, same timestamps (one pulse in a hundred may move
    by one envelope sample where two samples of a pulse top tie within the bound),
    amplitudes within ``amp_bound_fs``. (2) The same record: timestamps within one envelope
    sample; noiseless, amplitudes within the bound plus the sampling-phase loss (with noise
    the two sampling grids see different noise at the top, so only (1) bounds amplitudes).
    Pulses that only one side finds must be near the threshold."""
    p = P
    m = TacanFrontendModel(p)
    x = generate(TacanSignalConfig(duration_s=0.03, snr_db=snr_db, seed=5)).samples
    hw = m.peaks_to_fs(m.run(x)[0])
    bound = p.amp_bound_fs
    assert bound < 2e-4
    d = p.decimation
    # (1) phase-aligned
    g = run_golden_frontend(x[d - 1:], p.config, p.adc_bits)
    g_ts = g.timestamps + (d - 1)
    jj, ok = _match(hw.timestamps, g_ts, d)
    da = np.abs(hw.amplitudes - g.amplitudes[jj])
    dt = hw.timestamps - g_ts[jj]
    assert len(hw.timestamps) == len(g_ts) and ok.all()
    assert np.count_nonzero(dt) <= max(1, len(dt) // 100)
    assert np.all(np.abs(dt) <= d)
    assert da.max() <= bound, (da.max(), amp_error_terms(p))
    # (2) same record, golden's own sampling phase
    g = run_golden_frontend(x, p.config, p.adc_bits)
    jj, ok = _match(hw.timestamps, g.timestamps, d)
    thr_zone = 1.25 * max(p.config.thr_min_fs, 0)        # near-threshold pulses may differ
    assert np.all(hw.amplitudes[~ok] < 3 * thr_zone)
    assert abs(len(hw.timestamps) - len(g.timestamps)) <= np.count_nonzero(~ok) + 0
    dt = hw.timestamps[ok] - g.timestamps[jj[ok]]
    assert np.all(np.abs(dt) <= d)
    amp = g.amplitudes[jj[ok]]
    da = np.abs(hw.amplitudes[ok] - amp)
    if snr_db is None:
        assert np.all(da <= bound + amp * _sampling_phase_bound(p)), \
            (da.max(), bound, _sampling_phase_bound(p))


def test_range_log_is_the_same_on_both_paths_and_fits_the_words():
    x = tacan_record(80_000, seed=9)
    fast = TacanFrontendModel(P, log_ranges=True)
    slow = TacanFrontendModel(P, fast=False, log_ranges=True)
    st_f = st_s = None
    for chunk in np.array_split(x, [30_001]):
        _, st_f = fast.run(chunk, st_f)
        _, st_s = slow.run(chunk, st_s)
    assert fast.range_log == slow.range_log
    r = fast.ranges()
    assert set(r) == {"adc", "mixer", "cic", "fir", "envelope"}
    for name, v in r.items():
        assert v["lo"] <= v["min"] <= v["max"] <= v["hi"], name
        assert v["headroom_bits"] >= 0
    assert r["adc"]["min"] == int(x.min()) and r["adc"]["max"] == int(x.max())
    assert TacanFrontendModel(P).run(x)[0].amplitudes.size > 0
    assert TacanFrontendModel(P).range_log == {}          # opt-in


# -- pulse-pair detection in the front end ------------------------------------------------------
def _pair_params(**kw) -> TacanFrontendParams:
    """The front end with the peak search's pulse-pair detection at the X-mode pair spacing
    in envelope samples (12 us at 5 MHz = 60), as ``cosim.tacan.run`` builds its partner
    mode, on the censored floor (smooth_log2 10, threshold 46/16 of the pair sum's floor)."""
    sig = TacanSignalConfig()
    cfg = FrontendConfig.for_signal(sig)
    d = int(round(pair_spacing_s(sig.mode) * cfg.env_rate_hz))
    peak = replace(cfg.peak, pair_offset=d, clip_to_floor=True, smooth_log2=10, thr_mult=46)
    return TacanFrontendParams(config=replace(cfg, peak=peak), **kw)


PAIR = _pair_params()


def _checked_params(**kw) -> TacanFrontendParams:
    """:func:`_pair_params` with the pair checks (balance 4, spread 8): one cycle more."""
    p = _pair_params(**kw)
    return replace(p, config=replace(p.config, peak=replace(p.peak, pair_balance=4,
                                                            pair_spread=8)))


PAIR_CHECKED = _checked_params()


def _pair_sum_peaks(p: TacanFrontendParams, x):
    """The front end's envelope, and the pulses of the pair-sum search before the side-lobe
    filter (the inner search of the pair detection)."""
    e, _ = TacanFrontendModel(p).envelope(x)
    D = p.peak.pair_offset
    s = e + np.concatenate((np.zeros(D, e.dtype), e))[:e.size]
    inner, _ = peak_search(s, p.peak.search_params)
    return e, inner


def test_pair_detection_params_and_words():
    """Pair detection at 60 envelope samples: the FIFO word is unchanged (amplitude, here
    the pair's mean, | timestamp), 5 cycles more latency; on a TACAN record the filter keeps
    one pulse per pair (the s peak at the second pulse) and drops the side lobes."""
    p = PAIR
    assert p.peak.pair_offset == 60 and p.peak.partner_offset == 0
    assert p.peak.out_layout == [("amplitude", p.peak.amp_width, False),
                                 ("timestamp", p.peak.ts_bits, False)]
    assert p.fifo.width == p.peak.amp_width + p.peak.ts_bits == P.fifo.width
    assert p.latency == P.latency + 5
    x = tacan_record(400_000, seed=7)
    pk, _ = TacanFrontendModel(p).run(x)
    _, inner = _pair_sum_peaks(p, x)
    assert len(pk.amplitudes) > 50
    assert inner.amplitude.size - pk.amplitudes.size > len(pk.amplitudes)   # ~2 per pair


def test_pysim_equals_model_pair_detection():
    """~1.2 ms of SNR 10 dB TACAN IF (about 15 s of pysim) through the front end with pair
    detection: every FIFO word and its cycle (the amplitude field carries the pair's mean,
    s >> 1)."""
    p = PAIR
    x = tacan_record(24_000, seed=2)
    m = TacanFrontendModel(p)
    pk, _ = m.run(x)
    dut = TacanFrontEnd(p)
    res = run_stream(dut, x, n_cycles=len(x) + 600, inputs={"freq": p.nco_freq_word},
                     probe={"ovf": dut.overflow_count})
    ref = m.fifo_output(pk, res.n_cycles)
    # the record's two pulse pairs: one word each, their side lobes dropped
    _, inner = _pair_sum_peaks(p, x)
    assert len(pk.amplitudes) >= 2 and inner.amplitude.size >= 3 * len(pk.amplitudes)
    np.testing.assert_array_equal(res.words, ref.words)
    np.testing.assert_array_equal(res.cycles, ref.cycles)
    assert not res.probes["ovf"].any()
    # the first word leaves params.latency cycles after the ADC sample completing the
    # envelope sample pair_offset after its pulse's closing one
    adc = (pk.end_index[0] + 1) * p.decimation - 1
    assert res.cycles[0] == adc + p.latency
    np.testing.assert_array_equal(m.unpack(res.words)["amplitude"], pk.amplitudes)


@pytest.mark.verilator
@verilator
@pytest.mark.parametrize("samples, stall, checks", [(200_000, False, False),
                                                    (400_000, True, False),
                                                    (200_000, False, True),
                                                    (400_000, True, True)])
def test_verilator_equals_model_pair_detection(samples, stall, checks):
    """Model == Verilator word for word (and cycle), the pair checks off and on."""
    make = _checked_params if checks else _pair_params
    p = make(fifo_depth=4) if stall else make()
    if checks:
        assert p.peak.pair_balance == 4 and p.peak.pair_spread == 8
        assert p.latency == PAIR.latency + 1
    r = check_equivalence(samples=samples, backends=("model", "verilator"), seed=1,
                          stall=stall, params=p)
    assert r["backends"] == ["model", "verilator"]
    assert r["mismatches"] == 0, r
    assert r["peaks"] > 30
    if stall:
        assert r["dropped"] > 0 and r["markers"] > 0
    else:   # the side-lobe filter dropped pulses of the pair-sum search on this record
        x = tacan_record(samples, 1)
        _, inner = _pair_sum_peaks(p, x)
        assert inner.amplitude.size > 2 * r["peaks"]
        if checks:   # and the checks some of the pairs it keeps (3 of 44)
            assert 0 < len(TacanFrontendModel(PAIR).run(x)[0].amplitudes) - r["peaks"] < 10


@pytest.mark.verilator
@verilator
def test_exported_top_lints_clean_pair_detection(tmp_path):
    from cosim.verilog import export_verilog, lint
    path = export_verilog(TacanFrontEnd(PAIR), name="tacan_frontend_pair", out_dir=tmp_path)
    assert lint(path) == []
    path = export_verilog(TacanFrontEnd(PAIR_CHECKED), name="tacan_frontend_pair_checked",
                          out_dir=tmp_path)
    assert lint(path) == []



# -- both searches: single pulses and pulse pairs in one FIFO stream ------------------------------
def _both_params(cic_rate: int = 4, checks: bool = True, **kw) -> TacanFrontendParams:
    """The front end with both searches (``config.pair_peak``, as ``--detector both``): the
    single-pulse search and the pair detector (:data:`PAIR_DETECTOR`, its pair checks on
    unless ``checks=False``) at the X-mode spacing. With ``cic_rate=2`` (decimation 2) a pulse
    word and a pair word meet in one cycle with a sample on every cycle (checks on) or with
    gaps; at decimation 4 only with gaps (see
    :func:`test_collisions_follow_the_latency_difference`)."""
    sig = TacanSignalConfig()
    cfg = FrontendConfig.for_signal(sig, cic_rate=cic_rate, peak=PeakParams(ts_step=cic_rate))
    base = replace(PAIR_DETECTOR, ts_step=cfg.peak.ts_step)
    if not checks:
        base = replace(base, pair_balance=0, pair_spread=0)
    cfg = replace(cfg, pair_peak=pair_detector(sig.mode, cfg.env_rate_hz, base))
    return TacanFrontendParams(config=cfg, adc_bits=sig.adc_bits, **kw)


BOTH = _both_params()


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
    assert _both_params(cic_rate=2, checks=False).pair_peak_latency \
        - _both_params(cic_rate=2, checks=False).peak_latency == 5
    for checks, (valid, n) in COLLISIONS.items():
        m = TacanFrontendModel(_both_params(cic_rate=2, checks=checks))
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
    p = _both_params(fifo_depth=1)
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
    p = _both_params(cic_rate=2)
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
    m = TacanFrontendModel(_both_params(cic_rate=2))
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
        p = _both_params(cic_rate=2, checks=checks)
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
    p = _both_params(fifo_depth=4) if stall else BOTH
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
    from cosim.verilator import VerilatorStreamSim
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
    p = _both_params(cic_rate=2, checks=checks, fifo_depth=8)
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
    p = _both_params(fifo_depth=8)
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
    from cosim.verilog import export_verilog, lint
    for name, p in (("tacan_frontend_both", BOTH),
                    ("tacan_frontend_both_d2", _both_params(cic_rate=2, checks=False))):
        assert lint(export_verilog(TacanFrontEnd(p), name=name, out_dir=tmp_path)) == [], name


@pytest.mark.parametrize("snr_db", [None, 10.0])
def test_both_searches_vs_golden(snr_db):
    """30 ms of TACAN IF, golden fed from ADC tick D-1 (the hardware's sampling phase): per
    source the same peaks as the golden's (its Peaks.source), the same timestamps (one in a
    hundred may move by an envelope sample, ties within the bound), amplitudes within
    ``amp_bound_fs`` -- for a pair, the mean of two envelope values, plus half an LSB for the
    hardware's ``s >> 1``."""
    p = BOTH
    m = TacanFrontendModel(p)
    x = generate(TacanSignalConfig(duration_s=0.03, snr_db=snr_db, seed=5)).samples
    hw = m.peaks_to_fs(m.run(x)[0])
    d = p.decimation
    g = run_golden_frontend(x[d - 1:], p.config, p.adc_bits)
    for src, bound in ((SOURCE_PULSE, p.amp_bound_fs),
                       (SOURCE_PAIR, p.amp_bound_fs + 0.5 * p.scale_to_fs)):
        h_ts, h_a = hw.timestamps[hw.source == src], hw.amplitudes[hw.source == src]
        g_ts, g_a = g.timestamps[g.source == src] + (d - 1), g.amplitudes[g.source == src]
        assert len(h_ts) == len(g_ts) > 50, src
        dt = h_ts - g_ts
        assert np.count_nonzero(dt) <= max(1, len(dt) // 100) and np.all(np.abs(dt) <= d)
        da = np.abs(h_a - g_a)
        assert da.max() <= bound, (src, da.max(), bound)


def test_pair_detector_floor_vs_golden():
    """1.5 s of TACAN at 10 dB through the pair detector (:data:`PAIR_DETECTOR`, its floor
    smoothed over 2**10 blocks, ~0.2 s): the HDL model's threshold is the float golden's.
    The integer floor without fraction bits (``floor_frac``) settled ~2**10 LSB below the
    golden's: 6528 reports against 6368, threshold estimate 0.129 against 0.150 FS; with
    them the report counts agree within 1 % and the thresholds within 2 %."""
    from cosim.tacan.run import FRONTENDS, TacanRunConfig
    assert PAIR_DETECTOR.floor_frac
    sig = TacanSignalConfig(duration_s=1.5, seed=1)
    assert sig.snr_db == 10.0
    x = generate(sig).samples
    got = {}
    for be in ("golden", "model"):
        run = TacanRunConfig(signal=sig, backend=be, detector="pair", require_bearing=False)
        fo = FRONTENDS[be](x, run)
        got[be] = (len(fo.ticks), run.receiver.peak_bias.threshold(fo.amplitude_fs))
    (n_g, t_g), (n_m, t_m) = got["golden"], got["model"]
    assert n_g > 5000
    assert abs(n_m - n_g) <= 0.01 * n_g, got
    assert abs(t_m / t_g - 1) <= 0.02, got
