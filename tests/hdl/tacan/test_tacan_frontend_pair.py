"""TACAN front-end top with the pulse-pair detection in its peak search: parameters and words,
Amaranth simulation == model, Verilator == model, lint."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cosim.tacan.equivalence import check_equivalence, tacan_record
from cosim.backends.pysim import run_stream
from cosim.tacan.signal import TacanSignalConfig
from dsp.tacan.frontend import FrontendConfig
from dsp.tacan.standard import pair_spacing_s
from hdl.tacan.peak_model import peak_search
from hdl.tacan.model import TacanFrontendModel
from hdl.tacan.params import TacanFrontendParams
from hdl.tacan.frontend import TacanFrontEnd

from _tacan_fe_util import P, verilator  # on sys.path: conftest.py


# -- pulse-pair detection in the front end ------------------------------------------------------
def _pair_params(**kw) -> TacanFrontendParams:
    """The front end with the peak search's pulse-pair detection at the X-mode pair spacing
    in envelope samples (12 us at 5 MHz = 60), as ``cosim.tacan.config`` builds its partner
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
    from cosim.tools.verilog import export_verilog, lint
    path = export_verilog(TacanFrontEnd(PAIR), name="tacan_frontend_pair", out_dir=tmp_path)
    assert lint(path) == []
    path = export_verilog(TacanFrontEnd(PAIR_CHECKED), name="tacan_frontend_pair_checked",
                          out_dir=tmp_path)
    assert lint(path) == []
