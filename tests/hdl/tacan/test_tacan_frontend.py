"""TACAN front-end top: its parameters (word lengths, derived values, checks, headroom) and its
bit-exact model (fast path == block chain, chunking, frequency changes, variants, the FIR
kernel)."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.tacan.equivalence import tacan_record
from dsp.fixed import shift_right
from dsp.tacan.frontend import FrontendConfig
from dsp.tacan.peak_params import PeakParams
from hdl.model.fir import fir_kernel
from hdl.model.rounding import round_consts
from hdl.tacan.model import TacanFrontendModel
from hdl.tacan.params import TacanFrontendParams

from _tacan_fe_util import P  # on sys.path: conftest.py


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
            fir_kernel(z, hh, h.astype(np.float64), bool(np.array_equal(h, h[::-1])), down,
                        round_consts(7, rounding), out)
            np.testing.assert_array_equal(out, shift_right(full, 7, rounding))
            np.testing.assert_array_equal(hh, buf[len(buf) - (L - 1):])
