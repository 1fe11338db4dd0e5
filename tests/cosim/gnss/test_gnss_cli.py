"""python -m cosim gnss: the issue's command line, its JSON, and bad input pinned."""
import json

import pytest

from cosim.cli import main

BASE = ["gnss", "--prn", "7", "--cn0-dbhz", "40", "--dynamics", "aukf-patent", "--tracker",
        "pll3", "--bn-hz", "15", "--backend", "model", "--dsp", "fixed"]


def test_gnss_json_has_the_issue_keys(capsys):
    assert main(BASE + ["--duration-s", "0.8", "--code-phase-chips", "511.5",
                        "--settle-s", "0.4", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    for k in ("doppler_rmse_hz", "phase_rmse_deg", "code_rmse_chips", "lock_fraction",
              "cycle_slips", "cn0_est_dbhz", "acquired", "fifo_dropped", "digest"):
        assert k in r, k
    a = r["acquired"]
    assert abs(a["code_phase_found_chips"] - 511.5) <= 0.5
    assert abs(a["doppler_found_hz"] - a["doppler_dwell_true_hz"]) <= a["bin_width_hz"]
    assert r["cycle_slips"] == 0 and r["fifo_dropped"] == 0
    assert abs(r["cn0_est_dbhz"] - 40.0) < 2.0
    assert set(r["digest"]) == {"words", "cycles", "writes", "dsp", "all"}


@pytest.mark.parametrize("args, msg", [
    (["--prn", "33"], "error: PRN must be an integer in [1, 32], not 33"),
    (["--prn", "0"], "error: PRN must be an integer in [1, 32], not 0"),
    (["--adc-bits", "0"], "error: adc_bits must be an integer in [1, 16], not 0"),
    (["--fs-hz", "2e6"], "error: sample rate must be >= the C/A main-lobe bandwidth 2.046 MHz"),
    (["--if-hz", "9e6"], "error: IF must keep the C/A main lobe (IF +- 1.023 MHz) inside the "
                         "first Nyquist zone"),
    (["--bn-hz", "0"], "error: --bn-hz must be a finite number > 0 Hz"),
    (["--coherent-ms", "21", "--noncoherent", "2"],
     "error: --coherent-ms must be a whole number in 1..20, not 21"),
    (["--duration-s", "0.3"], "error: duration_s 0.3 s leaves nothing after settle_s 0.5 s"),
    (["--dynamics", "aukf-patent-jerk", "--jerk-duration-s", "0"],
     "error: --jerk-duration-s must be a finite number > 0 s"),
    (["--tracker", "aided-kf"], "error: tracker aided-kf needs an INS aiding source: run it "
                                "with `python -m cosim ins --loop aided-kf`"),
    (["--tracker", "aided-pll"], "error: tracker aided-pll needs an INS aiding source"),
])
def test_bad_input_is_one_error_line_exit_2(args, msg, capsys):
    assert main(["gnss"] + args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(msg), err


@pytest.mark.parametrize("args, msg", [
    (["--cn0-dbhz", "nan"], "argument --cn0-dbhz: must be a finite number, not nan"),
    (["--tracker", "pll9"], "argument --tracker: invalid choice: 'pll9'"),
    (["--backend", "fpga"], "argument --backend: invalid choice: 'fpga'"),
    (["--prn", "7.5"], "argument --prn: must be a whole number, not 7.5"),
])
def test_bad_option_values_rejected_by_the_parser(args, msg, capsys):
    with pytest.raises(SystemExit) as e:
        main(["gnss"] + args)
    assert e.value.code == 2
    assert msg in capsys.readouterr().err
