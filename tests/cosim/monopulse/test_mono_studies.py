"""``sweep monopulse`` and ``faults monopulse`` on the generic study engines: the closed loop
on the bit-exact front end against the float golden, bit errors in the ADC samples and FIFO
words. Bad input is refused before any point runs (fast); the studies themselves run a short
record (~15 s of model per run: slow) and their verdicts can fail (a 4-iteration CORDIC is
rejected, a corrupted FIFO word is counted, not crashed on)."""
import csv
import json
import re

import pytest

from cosim.cli import main
from cosim.studies.faults import FaultConfig
from cosim.studies.spec import SweepConfig, parse_param
from cosim.studies.sweep import check_points

SHORT = ["--duration-s", "0.115", "--memory-s", "0.005", "--trials", "1"]


@pytest.mark.parametrize("argv,msg", [
    (["sweep", "monopulse", "--param", "fs_hz=1e6"], "error: unknown parameter 'fs_hz': use "
     "adc_bits, a MonopulseFrontendParams field"),
    (["sweep", "monopulse", "--param", "dsp.q=30"], "error: unknown parameter 'dsp.q'"),
    (["sweep", "monopulse", "--param", "cordic_iterations=2"] + SHORT,
     "error: sweep point cordic_iterations=2: monopulse cordic_iterations must be"),
    (["sweep", "monopulse", "--param", "dsp.x=70"] + SHORT,
     "error: sweep point dsp.x=70: dsp.x must be an integer in [2, 62], not 70"),
    (["sweep", "monopulse", "--duration-s", "0.1"],
     "error: --duration-s must exceed 0.2 s (scoring starts at twice the filter memory"),
    (["sweep", "monopulse", "--recheck-backend", "pysim"],
     "error: --recheck-backend sets the re-checks, but --recheck 0 runs none"),
    (["faults", "monopulse", "--bits", "12"] + SHORT,
     "error: bits must be positions 0..11 of the adc words (12 bits), not [12]"),
    (["faults", "monopulse", "--target", "fifo", "--bits", "50"] + SHORT,
     "error: bits must be positions 0..49 of the fifo words (50 bits), not [50]"),
    (["faults", "monopulse", "--ber", "2"], "error: BER values must lie in (0, 1)"),
    (["faults", "monopulse", "--trials", "100", "--duration-s", "20"],
     "error: 500 runs of 20 s would take about"),
])
def test_bad_study_input_exits_2_before_work(argv, msg, capsys, tmp_path):
    assert main(argv + ["--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(msg), err
    assert not (tmp_path / "o").exists()


def test_fault_config_refuses_what_the_monopulse_loop_does_not_have():
    with pytest.raises(ValueError, match=re.escape("the monopulse FIFO words carry no parity "
                                                   "bit")):
        FaultConfig(receiver="monopulse", target="fifo", fifo_parity=True, duration_s=0.2,
                    memory_s=0.02, trials=1)
    with pytest.raises(ValueError, match=re.escape("runs on the bit-exact model")):
        FaultConfig(receiver="monopulse", backend="verilator", duration_s=0.2, memory_s=0.02,
                    trials=1)


def test_sweep_points_are_validated_up_front():
    cfg = SweepConfig(receiver="monopulse", params=(parse_param("cordic_in_bits=3,12",
                                                                "monopulse"),),
                      snr_db=(-8.0,), duration_s=0.2, memory_s=0.02, trials=1)
    with pytest.raises(ValueError, match=re.escape("sweep point cordic_in_bits=3: monopulse "
                                                   "cordic_in_bits must be")):
        check_points(cfg)


@pytest.mark.slow
def test_sweep_rejects_a_short_cordic_and_proposes_enough_iterations(tmp_path, capsys):
    """CORDIC 4 iterations: the angle unit's error (~atan 2^-4) dominates the tracking RMS
    (measured 18x the golden's); 16: within 2 % (the front end's quantisation)."""
    out = tmp_path / "sw"
    assert main(["sweep", "monopulse", "--param", "cordic_iterations=4,16", "--no-confirm",
                 "--jobs", "1", "--json", "--out", str(out)] + SHORT) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["proposal"] == {"cordic_iterations": 16}
    with open(out / "summary.csv") as f:
        rows = {int(r["cordic_iterations"]): r for r in csv.DictReader(f)}
    assert float(rows[4]["ratio_to_golden"]) > 5
    assert float(rows[16]["ratio_to_golden"]) < 1.1
    assert rows[16]["locked"] == "1" and rows[16]["golden_locked"] == "1"
    assert (out / "report.md").read_text().startswith("# Monopulse word-length sweep")


@pytest.mark.slow
def test_faults_in_fifo_words_are_counted_not_crashed_on(tmp_path, capsys):
    out = tmp_path / "f"
    assert main(["faults", "monopulse", "--target", "fifo", "--ber", "1e-4,1e-2", "--json",
                 "--out", str(out)] + SHORT) == 0
    s = json.loads(capsys.readouterr().out)
    rows = {r["ber"]: r for r in s["rows"]}
    assert all(r["exceptions"] == 0 and r["nan_bearings"] == 0 for r in s["rows"])
    assert rows[0.0]["flips"] == 0 and rows[0.0]["gated"] == 0 and rows[0.0]["reinit"] == 0
    assert rows[1e-4]["flips"] > 0 and rows[1e-4]["gated"] > 0      # bad records caught
    assert rows[1e-4]["rmse_deg"] < 2 * rows[0.0]["rmse_deg"]         # and tracking goes on
    assert rows[1e-2]["flips"] > 100
    recs = json.loads((out / "faults_fifo.json").read_text())["records"]
    hard = next(r for r in recs if r["ber"] == 1e-2)
    assert hard["rx"]["broken_records"] > 0 and hard["events"]["gated"] > 0
    assert (out / "faults_fifo.md").exists()


@pytest.mark.slow
def test_faults_in_adc_codes_run_and_degrade_gracefully(tmp_path, capsys):
    out = tmp_path / "a"
    assert main(["faults", "monopulse", "--target", "adc", "--ber", "1e-3", "--json",
                 "--out", str(out)] + SHORT) == 0
    rows = {r["ber"]: r for r in json.loads(capsys.readouterr().out)["rows"]}
    assert all(r["exceptions"] == 0 and r["nan_bearings"] == 0 for r in rows.values())
    # 4 channels x 12 bits x ~11.8 M samples x 1e-3
    assert rows[1e-3]["flips"] > 1e5 and rows[1e-3]["rmse_deg"] is not None
