"""End to end through the CLI contract: `python -m cosim tacan ... --json`."""
import json
import subprocess
import sys

import pytest

from cosim.backends.verilator_harness import verilator_available
from cosim.cli import main

KEYS = {"bearing_true_deg", "bearing_est_deg", "rmse_deg", "mean_error_deg", "crb_deg",
        "n_updates", "backend"}


def test_cli_json_contract(capsys):
    rc = main(["tacan", "--bearing-deg", "123", "--snr-db", "15", "--duration-s", "1.5",
               "--seed", "2", "--mode", "X", "--backend", "golden", "--json"])
    assert rc == 0
    r = json.loads(capsys.readouterr().out)
    assert KEYS <= set(r)
    assert r["backend"] == "golden" and r["bearing_true_deg"] == 123.0
    assert abs(r["bearing_est_deg"] - 123.0) < 0.5
    assert r["n_updates"] > 5000 and r["crb_deg"] > 0


def test_cli_readable_summary(capsys):
    assert main(["tacan", "--duration-s", "1.5", "--snr-db", "20", "--bearing-deg", "10"]) == 0
    out = capsys.readouterr().out
    assert "bearing: true 10.000 deg" in out and "RMSE" in out and "Cramer-Rao" in out
    assert "first valid bearing at 0.0" in out and "rotation rate 15.0000 Hz" in out


@pytest.mark.parametrize("args, message", [
    (["--fs-hz", "2e6"], "sample rate 2 MS/s is too low for the IF"),
    (["--adc-bits", "0"], "adc_bits must be an integer in [1, 24], not 0"),
    (["--mod-15", "1.5"], "modulation depths must satisfy"),
    (["--duration-s", "0"], "duration_s must be > 0, not 0.0"),
    (["--duration-s", "0.5"], "leaves no time after the filter settles"),
    (["--rotation-hz", "17"], "rotation_hz must be within 5 % of 15 Hz (14.25..15.75), not 17.0"),
])
def test_cli_errors_go_to_stderr_with_nonzero_exit(capsys, args, message):
    rc = main(["tacan", "--json"] + args)
    cap = capsys.readouterr()
    assert rc != 0
    assert message in cap.err
    assert cap.out == ""


def test_cli_nan_bearing_is_refused():
    p = subprocess.run([sys.executable, "-m", "cosim", "tacan", "--bearing-deg", "nan", "--json"],
                       capture_output=True, text=True)
    assert p.returncode != 0
    assert "must be a finite number, not nan" in p.stderr
    assert p.stdout == ""


def test_cli_hdl_model_fixed_dsp_compare_golden(capsys):
    """The `make run` command line: bit-exact front end, FIFO, fixed-point DSP, vs golden."""
    rc = main(["tacan", "--backend", "model", "--dsp", "fixed", "--compare", "golden",
               "--duration-s", "2", "--dsp-stall", "0.8:0.9", "--json"])
    assert rc == 0
    r = json.loads(capsys.readouterr().out)
    assert r["backend"] == "model" and r["dsp"] == "fixed"
    assert r["fifo_dropped"] > 0 and r["fifo_dropped"] == r["fifo_dropped_reported"]
    assert set(r["dsp_events"]) >= {"reinit", "gated", "sat_P", "p_neg", "invalid_bearings"}
    assert 0 <= r["vs_golden_rms_deg"] < 0.05 and r["vs_golden_n"] > 50
    assert r["rmse_deg"] < 0.3


@pytest.mark.parametrize("args, message", [
    (["--dsp-stall", "0.5"], "--dsp-stall takes START:STOP in seconds"),
    (["--dsp-stall", "0.5:0.2"], "--dsp-stall needs 0 <= START < STOP"),
    (["--dsp-batch-words", "0"], "batch_words must be an integer >= 1"),
    (["--dsp-period-cycles", "100"], "must end before the next timer tick"),
])
def test_cli_bad_dsp_service(capsys, args, message):
    rc = main(["tacan", "--backend", "model", "--json"] + args)
    cap = capsys.readouterr()
    assert rc != 0 and message in cap.err and cap.out == ""


@pytest.mark.skipif(not verilator_available(),
                    reason="Verilator not installed")
def test_cli_waveform_window_from_verilator(tmp_path, capsys):
    f = tmp_path / "front.vcd"
    rc = main(["tacan", "--backend", "verilator", "--duration-s", "0.2", "--memory-s", "0.02",
               "--settle-s", "0.05", "--trace", str(f), "--trace-window", "0.001:0.0012",
               "--json"])
    assert rc == 0 and json.loads(capsys.readouterr().out)["backend"] == "verilator"
    text = f.read_text()
    assert "$enddefinitions" in text and "o__valid" in text
    # only the window: 4000 cycles = 8000 half-cycle time steps
    times = [int(line[1:]) for line in text.splitlines() if line.startswith("#")]
    assert min(times) >= 2 * 20_000 and max(times) < 2 * 24_000


def test_cli_trace_needs_a_cycle_accurate_backend(capsys):
    assert main(["tacan", "--backend", "model", "--trace", "build/x.vcd"]) != 0
    assert "trace needs a cycle-accurate backend" in capsys.readouterr().err


def test_cli_model_run_rechecked_cycle_accurately(capsys):
    rc = main(["tacan", "--backend", "model", "--dsp", "fixed", "--duration-s", "0.7",
               "--memory-s", "0.15", "--recheck", "auto", "--recheck-samples", "60000", "--json"])
    assert rc == 0
    c = json.loads(capsys.readouterr().out)["recheck"]
    assert c["same_bits"] is True and c["samples"] == 60000 and c["words"] > 0
    assert main(["tacan", "--backend", "golden", "--recheck", "auto"]) != 0
    assert "use it with backend='model'" in capsys.readouterr().err


def test_cli_censored_noise_floor_reaches_the_hardware_and_stays_bit_exact(capsys):
    """``--noise-floor censored`` changes the FPGA's pulse detector (other peaks than the
    default's), and the model still matches the cycle-accurate RTL word for word."""
    args = ["tacan", "--backend", "model", "--dsp", "fixed", "--duration-s", "0.5",
            "--memory-s", "0.15", "--snr-db", "3", "--json"]
    assert main(args) == 0
    plain = json.loads(capsys.readouterr().out)
    assert main(args + ["--noise-floor", "censored", "--recheck", "auto",
                        "--recheck-samples", "300000"]) == 0
    cens = json.loads(capsys.readouterr().out)
    assert cens["recheck"]["same_bits"] is True and cens["recheck"]["words"] > 50
    assert cens["n_peaks"] != plain["n_peaks"]


def test_cli_partner_amplitude_reaches_the_hardware_and_stays_bit_exact(capsys):
    """``--amplitude partner`` (an option of the single-pulse search alone, ``--detector
    pulse``): the FPGA reports the pair partner's envelope (other words than the peak's, the
    same pulses), and the model matches the RTL word for word -- Verilator over 0.05 s and
    the Amaranth simulation over the first 40,000 samples."""
    args = ["tacan", "--backend", "model", "--dsp", "fixed", "--duration-s", "0.5",
            "--memory-s", "0.15", "--snr-db", "3", "--json", "--detector", "pulse"]
    assert main(args) == 0
    plain = json.loads(capsys.readouterr().out)
    assert main(args + ["--amplitude", "partner", "--recheck", "auto"]) == 0
    part = json.loads(capsys.readouterr().out)
    assert part["recheck"]["same_bits"] is True and part["recheck"]["words"] > 100
    assert part["n_peaks"] == plain["n_peaks"]
    assert part["digest"]["fifo"] != plain["digest"]["fifo"]
    assert main(args + ["--amplitude", "partner", "--recheck", "pysim",
                        "--recheck-samples", "40000"]) == 0
    assert json.loads(capsys.readouterr().out)["recheck"]["same_bits"] is True


def test_cli_pair_detector_reaches_the_hardware_and_stays_bit_exact(capsys):
    """``--detector pair``: the FPGA detects pulse pairs (other words than the default's,
    about half as many: one per pair), the model matches the RTL word for word (Verilator
    when installed) and the DSP still finds the references."""
    args = ["tacan", "--backend", "model", "--dsp", "fixed", "--duration-s", "0.5",
            "--memory-s", "0.15", "--snr-db", "10", "--json"]
    assert main(args) == 0
    plain = json.loads(capsys.readouterr().out)
    assert main(args + ["--detector", "pair", "--recheck", "auto",
                        "--recheck-samples", "300000"]) == 0
    out = capsys.readouterr()
    pair = json.loads(out.out)
    assert "warning: --detector pair is experimental" in out.err
    assert pair["recheck"]["same_bits"] is True and pair["recheck"]["words"] > 50
    assert pair["n_main_refs"] == plain["n_main_refs"]
    assert pair["digest"]["fifo"] != plain["digest"]["fifo"]


@pytest.mark.parametrize("extra", [["--noise-floor", "censored"], ["--amplitude", "partner"]])
def test_cli_pair_detector_refuses_the_pulse_detector_options(capsys, extra):
    assert main(["tacan", "--detector", "pair", "--duration-s", "1"] + extra) == 2
    assert "the pair detector has its own noise floor" in capsys.readouterr().err


def test_sweep_availability_margin_reaches_the_proposal(monkeypatch, capsys, tmp_path):
    """``sweep tacan --availability-margin`` sets the proposal's availability margin (the
    study receives it; the proposal judges with it); out of [0, 1) it is refused in one
    line before the study starts."""
    import cosim.studies.sweep as sweep
    from cosim.studies.proposal import passes
    got = []

    def study(cfg, out, **kw):
        got.append(cfg)
        return {"n_points": 0, "elapsed_s": 0.0, "proposal": {}, "rechecks": []}
    monkeypatch.setattr(sweep, "study", study)
    base = ["sweep", "tacan", "--param", "adc_bits=8,12", "--out", str(tmp_path / "s")]
    assert main(base + ["--availability-margin", "0.1"]) == 0
    assert got[-1].availability_margin == 0.1
    assert main(base) == 0 and got[-1].availability_margin == 0.02
    # a point 5 epochs in 100 below the golden chain: refused at 0.02, passed at 0.1
    row = {"invalid": False, "excess_misleading": 0, "golden_locked": 10, "trials": 10,
           "availability_diff": -0.05, "ratio_to_golden": 1.0, "ratio_ci95": [0.99, 1.01]}
    assert passes(row, 0.05, 0.1) and not passes(row, 0.05, 0.02)
    capsys.readouterr()
    assert main(base + ["--availability-margin", "1.5"]) == 2
    err = [l for l in capsys.readouterr().err.splitlines() if l.strip()]
    assert len(err) == 1 and "availability_margin must be in [0, 1)" in err[0]
    assert len(got) == 2
