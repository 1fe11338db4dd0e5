"""TACAN front-end top: Amaranth simulation == model (gaps in valid, DSP stalls) and the
exported Verilog (Verilator == model, lint)."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.tacan.equivalence import check_equivalence, tacan_record
from cosim.backends.pysim import run_stream
from hdl.tacan.model import TacanFrontendModel
from hdl.tacan.params import TacanFrontendParams
from hdl.tacan.frontend import TacanFrontEnd

from _tacan_fe_util import P, verilator  # on sys.path: conftest.py


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
    from cosim.tools.verilog import export_verilog, lint
    path = export_verilog(TacanFrontEnd(P), name="tacan_frontend", out_dir=tmp_path)
    assert lint(path) == []
