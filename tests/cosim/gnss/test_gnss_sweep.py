"""``python -m cosim sweep gnss``: the AUKF core's word lengths through the generic sweep
engine (paired float64 golden, proposal, confirmation), and bad parameters refused before
any point runs."""
import json

import pytest

from cosim.cli import main


def test_sweep_gnss_proposes_and_confirms(tmp_path, capsys):
    out = tmp_path / "sw"
    assert main(["sweep", "gnss", "--param", "dsp.trig=4,12", "--trials", "2", "--duration-s", "1.0",
                 "--jobs", "1", "--out", str(out), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["n_points"] == 4 and set(r["proposal"]) == {"dsp.trig"}
    assert r["confirmed"] in (True, False) and r["confirmed_params"] is not None
    s = json.loads((out / "summary.json").read_text())
    rows = {row["dsp.trig"]: row for row in s["rows"]}
    assert set(rows) == {4, 12}
    for row in rows.values():
        assert row["golden_phase_rmse_deg"] > 0 and row["ratio_to_golden"] > 0
        assert row["locked"] == row["golden_locked"] == 2
    # 4-bit sin/cos (2 fraction bits) is coarser than 12-bit: farther from the golden run
    assert abs(rows[4]["ratio_to_golden"] - 1) > abs(rows[12]["ratio_to_golden"] - 1)
    assert (out / "report.md").read_text().startswith("# GNSS AUKF core word-length sweep")


@pytest.mark.parametrize("args, msg", [
    (["--param", "dsp.Q=8"], "error: unknown parameter 'dsp.Q': use dsp.<fmt> with fmt in theta"),
    (["--param", "adc_bits=2:4"], "error: unknown parameter 'adc_bits'"),
    (["--param", "dsp.gain=8"], "error: sweep point dsp.gain=8: dsp.gain = 8 bits leaves no "
                                "fraction bits (the format keeps 10 integer bits)"),
    (["--param", "dsp.P=24"], "error: sweep point dsp.P=24: formats too narrow: AukfFormats.P "
                              "QFormat(bits=24, frac=12) resolves 0.000244141, not 1 % of min diag "
                              "P0; the smallest dsp.P that passes is 29"),
    (["--param", "dsp.w0=17"], "error: sweep point dsp.w0=17: dsp.w0 = 17 bits leaves no fraction bits"),
])
def test_sweep_gnss_bad_params(args, msg, capsys, tmp_path):
    assert main(["sweep", "gnss", "--out", str(tmp_path / "x")] + args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(msg), err
