"""The TACAN sensitivity trade table (cosim.tools.tacan_trade) from synthetic results."""
import json

from cosim.tools.tacan_trade import main, trade_table


def _summary(path, rmse, avail, mis):
    path.mkdir(parents=True)
    head = "adc_bits,snr_db,trials,rmse_deg,crb_deg,availability,misleading\n"
    path.joinpath("summary.csv").write_text(head + "".join(
        f"{b},{s:.1f},20,{rmse},0.1,{avail},{mis}\n" for b in (8, 12) for s in (0, 5, 10, 15, 20)))


def _proposal(path, confirmed, params):
    path.mkdir(parents=True, exist_ok=True)
    path.joinpath("proposal.json").write_text(json.dumps(
        {"confirmation": {"confirmed": confirmed, "params": params}}))


def test_the_trade_table_sets_both_receivers_and_their_word_lengths_side_by_side(tmp_path):
    _summary(tmp_path / "study_default", 0.12, 1.0, 0)
    _summary(tmp_path / "study_default_pulse", 0.15, 0.9, 2)
    _proposal(tmp_path / "study_default", True, {"adc_bits": 7})
    _proposal(tmp_path / "study_default_pulse", True, {"adc_bits": 6, "detector": "pulse"})
    _proposal(tmp_path / "study_wordlength", True, {"adc_bits": 5, "dsp.y": 10, "dsp.P": 38})
    _proposal(tmp_path / "study_wordlength_pulse", True,
              {"adc_bits": 5, "dsp.y": 8, "dsp.P": 34, "detector": "pulse"})
    lines, missing = trade_table(tmp_path)
    assert missing == ["tacan_sensitivity.json"]
    row = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:5]] for ln in lines[2:]}
    key = ("0 dB, ADC 12 bits, fixed point (20 records): RMSE / CRB of the valid bearings, "
           "availability, misleading")
    assert row[key] == ["1.20x, 1.000, 0", "1.50x, 0.900, 2", ""]
    assert row["ADC bits confirmed (0-20 dB, 20 records)"] == ["7", "6", "+1"]
    assert row["`dsp.y` confirmed (5/10/20 dB, 10 records)"] == ["10", "8", "+2"]
    assert row["sum of the confirmed widths"] == ["53", "47", "+6"]
    # a study that did not confirm gives no widths
    _proposal(tmp_path / "study_wordlength", False, {"adc_bits": 5, "dsp.y": 10, "dsp.P": 38})
    lines, _ = trade_table(tmp_path)
    row = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:5]] for ln in lines[2:]}
    assert row["`dsp.y` confirmed (5/10/20 dB, 10 records)"] == ["-", "8", ""]
    assert main(["--results", str(tmp_path)]) == 0
    assert "tacan_sensitivity.json" in (tmp_path / "tacan_trade.md").read_text()


def test_a_study_without_proposal_json_gives_the_widths_its_report_states(tmp_path):
    d = tmp_path / "study_wordlength_pulse"
    d.mkdir()
    d.joinpath("report.md").write_text(
        "# TACAN quantisation sweep\n\n`python -m cosim sweep tacan` on X (2 cores), "
        "2026-12-05T04:00:00+00:00, commit abc1234: 9 points in 1 s.\n\nConfirmation re-run "
        "(...): **confirmed**: `adc_bits`=5, `dsp.y`=8, `detector`=pulse\n")
    _proposal(tmp_path / "study_wordlength", True, {"adc_bits": 5, "dsp.y": 10})
    lines, notes = trade_table(tmp_path)
    row = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:5]] for ln in lines[2:]}
    assert row["`dsp.y` confirmed (5/10/20 dB, 10 records)"] == ["10", "8", "+2"]
    assert any("study_wordlength_pulse" in n and "commit abc1234" in n for n in notes)
