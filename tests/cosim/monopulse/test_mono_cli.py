"""``python -m cosim monopulse``: the registry entry, the JSON report, bad input -> exit 2."""
from __future__ import annotations

import json

import pytest

from cosim.core import receivers
from cosim.cli import main
from cosim.monopulse.run import MonopulseRunConfig


def test_registered_with_options_from_the_config(capsys):
    r = receivers.get("monopulse")
    assert r.config is MonopulseRunConfig
    with pytest.raises(SystemExit):
        main(["monopulse", "--help"])
    out = capsys.readouterr().out
    for flag in ("--snr-db", "--snapshots", "--duration-s", "--tracker", "--backend", "--dsp",
                 "--spacing-wl", "--phase-bits", "--json"):
        assert flag in out


def test_json_report(capsys):
    rc = main(["monopulse", "--snr-db", "-8", "--snapshots", "8192", "--duration-s", "0.2",
               "--tracker", "fixed", "--backend", "fast", "--dsp", "fixed", "--json"])
    assert rc == 0
    r = json.loads(capsys.readouterr().out)
    for k in ("az_meas_rms_deg", "az_track_rms_deg", "el_meas_mean_deg", "az_crb_deg",
              "az_meas_over_crb", "pointing_error_max_fraction", "lost_track_events",
              "fifo_dropped", "digest", "calibration"):
        assert k in r
    assert r["dsp"] == "fixed" and r["tracker"] == "fixed" and r["blocks"] == 244


@pytest.mark.parametrize("argv,msg", [
    (["--spacing-wl", "0"], "error: spacing_wl must be a finite number > 0, not 0.0"),
    (["--spacing-wl", "-1"], "error: spacing_wl must be a finite number > 0, not -1.0"),
    (["--snapshots", "0"], "error: snapshots must be an integer >= 1, not 0"),
    (["--u0", "0.8", "--v0", "0.7"], "error: initial target direction must lie in the visible "
                                      "region u^2 + v^2 < 1, not u = 0.8, v = 0.7"),
    (["--phase-bits", "0"], "error: phase_bits must be an integer in [1, 24], not 0"),
    (["--backend", "verilator", "--trials", "2"],
     "error: the verilator backend runs one trial, not trials = 2"),
    (["--backend", "pysim", "--duration-s", "2"], "error: 200,048,640 cycles on the pysim backend (about 2e+03 cycles/s"),
])
def test_bad_input_exits_2_with_an_error_line(argv, msg, capsys):
    assert main(["monopulse", "--duration-s", "0.01"] + argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(msg), err


def test_registry_declares_the_front_end_its_top_and_the_bench():
    from cosim.tools.bench import benchmarks
    from cosim.cli import build_parser, hdl_blocks
    from cosim.monopulse.session import MonopulseModelSession
    from cosim.core.receivers import get
    from cosim.backends.factory import open_frontend
    from hdl.monopulse.frontend import MonopulseFrontEnd
    from hdl.monopulse.params import MonopulseFrontendParams
    p = MonopulseFrontendParams(snapshots=12, cic_rate=4, snapshot_decimation=4,
                                cordic_iterations=12, angle_bits=16, fifo_depth=16)
    r = get("monopulse")
    assert r.frontend.verilog_name == "monopulse_frontend"
    made = [r.frontend.component(p), hdl_blocks()["monopulse_frontend"]()]
    for c in made:      # built, not elaborated: no 'created but never used' at collection
        c._MustUse__silence = c._fifo._MustUse__silence = True
    assert all(isinstance(c, MonopulseFrontEnd) for c in made)
    assert isinstance(open_frontend("model", p), MonopulseModelSession)
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices
    top = next(a for a in sub["synth"]._actions if a.dest == "top")
    assert "monopulse" in top.choices
    assert "monopulse" in benchmarks()


def test_synth_timeout_is_validated_before_work(capsys, tmp_path):
    """``synth --timeout-min`` (the limit of each tool run; the monopulse front end needs more
    than the default 30 min of nextpnr on a loaded machine) is checked before yosys runs."""
    assert main(["synth", "--top", "monopulse", "--timeout-min", "0", "--out",
                 str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: --timeout-min must be in (0, 1440] minutes, not 0"]
    assert not (tmp_path / "s" / "monopulse_frontend").exists()
