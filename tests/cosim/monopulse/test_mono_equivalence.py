"""check-equivalence --top monopulse: model == pysim == Verilator on a record with register
writes (and drops under --stall); an empty record is not called equivalent."""

import pytest

from cosim.cli import build_parser
from cosim.monopulse.equivalence import check_monopulse_equivalence
from cosim.core.executables import find_executable


def test_cli_lists_monopulse():
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices
    top = next(a for a in sub["check-equivalence"]._actions if a.dest == "top")
    assert "monopulse" in top.choices


def test_model_equals_pysim_with_writes():
    r = check_monopulse_equivalence(1500, backends=("model", "pysim"), seed=3)
    assert r["equivalent"] and r["mismatches"] == 0, r["verdict"]
    assert r["backends"] == ["model", "pysim"] and r["peaks"] >= 30


@pytest.mark.skipif(find_executable("verilator") is None, reason="verilator not installed")
def test_model_equals_verilator_under_stall_with_drops():
    r = check_monopulse_equivalence(20_000, backends=("model", "verilator"), seed=1, stall=True)
    assert r["equivalent"] and r["mismatches"] == 0, r["verdict"]
    assert r["dropped"] > 0 and r["peaks"] > 100


def test_empty_record_is_not_equivalent_and_bad_input():
    r = check_monopulse_equivalence(40, backends=("model", "pysim"))
    assert not r["equivalent"] and r["verdict"].startswith("nothing was compared")
    with pytest.raises(ValueError, match="samples must be"):
        check_monopulse_equivalence(0)
    with pytest.raises(ValueError, match="backends must be"):
        check_monopulse_equivalence(100, backends=("model", "fpga"))
