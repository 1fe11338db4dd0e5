"""The public block-test API (cosim.testing.check_stream): the docs example runs, and a
wrong model or wrong timing fails with a report that names the index, cycle, values and
waveform."""
from __future__ import annotations

import importlib.util
import re

import numpy as np
import pytest

from cosim.testing import StreamMismatch, check_stream
from cosim.backends.verilator_harness import verilator_available
from hdl.model.fifo import ReadySchedule

from cosim.core.provenance import REPO_ROOT


def _example():
    path = REPO_ROOT / "docs" / "examples" / "fir_example.py"
    spec = importlib.util.spec_from_file_location("fir_example", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


EX = _example()


@pytest.mark.verilator
def test_docs_example_runs():
    """docs/howto/own_block.md's example, as its user would run it."""
    EX.test_fir_against_lfilter()


def _stim(seed=2, n=300):
    rng = np.random.default_rng(seed)
    return rng.integers(-2048, 2048, n), rng.random(n + 200) < 0.6


def test_wrong_word_reports_index_cycle_values_and_vcd(tmp_path):
    x, ready = _stim()
    want = EX.fir_model(EX.TAPS, x)
    bad = want.copy()
    bad[57] += 1
    with pytest.raises(StreamMismatch) as e:
        check_stream(EX.Fir(EX.TAPS), bad, x, ready=ready, backends=("pysim",),
                     build_dir=tmp_path)
    msg = str(e.value)
    assert "pysim vs model: words differ at index 57 of 300 expected (300 produced)" in msg
    assert f"expected: {bad[57]}" in msg and f"actual  : {want[57]}" in msg
    cycle = int(re.search(r"cycle  : (\d+)", msg).group(1))
    assert cycle > 57
    vcd = tmp_path / "fir.pysim.vcd"
    assert f"waveforms: {vcd}" in msg and vcd.stat().st_size > 1000


def test_missing_words_and_wrong_cycles(tmp_path):
    x, ready = _stim(3, 100)
    want = EX.fir_model(EX.TAPS, x)
    with pytest.raises(StreamMismatch, match=r"words differ at index 100 of 101 expected "
                                             r"\(100 produced\)[\s\S]*actual  : \(no more words\)"):
        check_stream(EX.Fir(EX.TAPS), np.r_[want, 0, 0][:101], x, ready=ready,
                     backends=("pysim",), vcd="never")
    res = check_stream(EX.Fir(EX.TAPS), want, x, ready=ready, backends=("pysim",))
    cycles = res.cycles.copy()
    cycles[10] += 1
    with pytest.raises(StreamMismatch, match=r"output cycles differ at index 10[\s\S]*"
                                             rf"expected cycle: {cycles[10]}"):
        check_stream(EX.Fir(EX.TAPS), (want, cycles), x, ready=ready, backends=("pysim",),
                     vcd="never")


@pytest.mark.verilator
@pytest.mark.skipif(not verilator_available(), reason="Verilator not found on PATH")
def test_verilator_mismatch_writes_its_vcd(tmp_path):
    x, ready = _stim(4, 200)
    bad = EX.fir_model(EX.TAPS, x)
    bad[3] = 0
    with pytest.raises(StreamMismatch, match="verilator vs model: words differ at index 3"):
        check_stream(EX.Fir(EX.TAPS), bad, x, ready=ready, backends=("verilator",),
                     build_dir=tmp_path)
    assert (tmp_path / "fir.verilator.vcd").stat().st_size > 1000


def test_schedule_and_probe_and_bad_arguments():
    x, _ = _stim(5, 200)
    want = EX.fir_model(EX.TAPS, x)
    res = check_stream(EX.Fir(EX.TAPS), want, x, ready=ReadySchedule(period=3, count=2),
                       n_cycles=400, backends=("pysim",), probe={"rdy": "i__ready"})
    assert res.results["pysim"].probes["rdy"].mean() < 0.9
    with pytest.raises(ValueError, match="backend must be one of"):
        check_stream(EX.Fir(EX.TAPS), want, x, backends=("iverilog",))
    with pytest.raises(ValueError, match="a ReadySchedule needs n_cycles"):
        check_stream(EX.Fir(EX.TAPS), want, x, ready=ReadySchedule(period=3))


def test_without_verilator_pysim_is_checked_then_skipped(monkeypatch):
    import cosim.backends.verilator_harness
    monkeypatch.setattr(cosim.backends.verilator_harness, "verilator_available", lambda: False)
    x, ready = _stim(6, 100)
    want = EX.fir_model(EX.TAPS, x)
    with pytest.raises(pytest.skip.Exception, match=r"verilator not run: Verilator, make or a "
                                                    r"C\+\+ compiler not found on PATH "
                                                    r"\(checked on pysim\)"):
        check_stream(EX.Fir(EX.TAPS), want, x, ready=ready, backends=("pysim", "verilator"))
    bad = want.copy()
    bad[0] += 1
    with pytest.raises(StreamMismatch, match="pysim vs model"):   # a failure is not skipped
        check_stream(EX.Fir(EX.TAPS), bad, x, ready=ready, vcd="never")
