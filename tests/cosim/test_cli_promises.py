"""Issue 42, second pass, the rules every command shares: one size rule
(:func:`cosim.core.validate.check_budget`) for the runs' and the studies' time limits,
``--recheck`` bounded by the sweep's points, argparse's unrecognised arguments pointing at the
subcommand's help, an option given at its default value where it changes nothing refused like
any other, and a refusal that does not pay for scipy. Only the parser and the up-front checks
run here (fast)."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

import cosim.core.validate as validate
from cosim.cli import build_parser, main
from cosim.core.provenance import REPO_ROOT
from cosim.core.receivers import given_options


def _err(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def _exits(capsys, argv, code=2) -> str:
    """The one error line of ``argv``, whether main returns the code or argparse exits."""
    try:
        rc = main(argv)
    except SystemExit as e:
        rc = e.code
    assert rc == code
    return _err(capsys)


# -- one size rule ---------------------------------------------------------------------------
@pytest.mark.parametrize("argv, limit_s, msg", [
    (["tacan", "--backend", "verilator", "--duration-s", "1.2"], 1.0,
     "error: 24,000,000 cycles on the verilator backend (about 5e+06 cycles/s) would take "
     "about 4.8 s on this machine (limit 1 s): reduce --duration-s"),
    (["tacan", "--backend", "model", "--recheck", "pysim", "--recheck-samples", "1e6"], 60.0,
     "error: 1,000,000 cycles on the pysim backend (about 3e+03 cycles/s) would take about "
     "5.56 min on this machine (limit 60 s): reduce --recheck-samples"),
    (["gnss", "--backend", "pysim", "--duration-s", "0.01"], 60.0,
     "error: 163,840 cycles on the pysim backend (about 2e+03 cycles/s; --duration-s 0.01) "
     "would take about 81.9 s on this machine (limit 60 s): reduce --duration-s"),
])
def test_the_runs_time_limit_is_check_budgets(argv, limit_s, msg, capsys, monkeypatch):
    """TACAN's and GNSS's cycle-accurate estimates go through check_budget: its limit
    (lowered here below these runs' estimates, which the default 2 h accepts) is the one
    they are held to, with its message."""
    monkeypatch.setattr(validate, "MAX_RUN_S", limit_s)
    assert _exits(capsys, argv) == msg


@pytest.mark.parametrize("argv, msg", [
    (["sweep", "tacan", "--param", "adc_bits=8", "--snr-db", "20", "--trials", "2"],
     "error: 2 points of 1 s would take about 1.5 s"),
    (["faults", "tacan", "--trials", "2"], "error: 10 runs of 2 s would take about"),
])
def test_the_studies_time_limit_is_check_budgets(argv, msg, capsys, monkeypatch, tmp_path):
    monkeypatch.setattr(validate, "MAX_STUDY_S", 1.0)
    line = _exits(capsys, argv + ["--out", str(tmp_path / "o")])
    assert line.startswith(msg) and "(limit 1 s): reduce" in line, line
    assert not (tmp_path / "o").exists()


# -- --recheck -------------------------------------------------------------------------------
@pytest.mark.parametrize("argv, msg", [
    (["sweep", "tacan", "--param", "adc_bits=8", "--recheck", "2"],
     "error: --recheck 2 is more than the 1 point it picks from (the combinations of the "
     "swept values)"),
    (["sweep", "tacan", "--param", "adc_bits=8,10", "--recheck", "3"],
     "error: --recheck 3 is more than the 2 points it picks from"),
    (["sweep", "monopulse", "--param", "adc_bits=8", "--recheck", "2"],
     "error: --recheck 2 is more than the 1 point it picks from"),
])
def test_a_recheck_beyond_the_points_is_refused_for_every_sweep(argv, msg, capsys, tmp_path):
    assert _exits(capsys, argv + ["--out", str(tmp_path / "o")]).startswith(msg)
    assert not (tmp_path / "o").exists()


def test_tacans_default_recheck_takes_all_of_a_smaller_sweep():
    from cosim.studies.spec import SweepConfig, check_recheck
    cfg = SweepConfig(params=(("adc_bits", (8,)),))
    assert cfg.recheck == 2 and len(cfg.combos) == 1
    check_recheck(cfg, given=False)             # the default: re-checks the one point
    with pytest.raises(ValueError, match=r"--recheck 2 is more than the 1 point "):
        check_recheck(cfg, given=True)          # the same value asked for


# -- argparse's own errors ---------------------------------------------------------------------
@pytest.mark.parametrize("argv, extra, prog", [
    (["gnss", "--bogus", "3"], "--bogus 3", "python -m cosim gnss"),
    (["ins", "--bogus"], "--bogus", "python -m cosim ins"),
    (["monopulse", "--bogus"], "--bogus", "python -m cosim monopulse"),
    (["sweep", "tacan", "--bogus"], "--bogus", "python -m cosim sweep tacan"),
    (["bench", "gnss-speed", "--bogus"], "--bogus", "python -m cosim bench"),
])
def test_unrecognised_arguments_point_at_the_subcommands_help(argv, extra, prog, capsys):
    assert _exits(capsys, argv) == f"error: unrecognized arguments: {extra} (see {prog} --help)"


# -- an option given at its default value ------------------------------------------------------
def test_the_parser_records_what_was_given_at_the_default_too():
    p = build_parser()
    a = p.parse_args(["monopulse", "--cal-snapshots", "1048576"])     # its default
    assert a.cal_snapshots == 1048576 and "cal_snapshots" in given_options(a)
    a = p.parse_args(["monopulse"])
    assert a.cal_snapshots == 1048576 and given_options(a) == frozenset()


@pytest.mark.parametrize("argv, msg", [
    (["monopulse", "--cal-snapshots", "1048576", "--skip-calibration"],
     "error: --cal-snapshots sets the calibration, but --skip-calibration skips it"),
    (["monopulse", "--service-period-cycles", "20000"],
     "error: --service-period-cycles sets how the DSP reads the FPGA FIFO, but --backend fast "
     "has no FIFO"),
    (["monopulse", "--tracker", "fixed", "--eq36", "repaired", "--alpha-relax", "1.1"],
     "error: --eq36, --alpha-relax set the adaptive tracking index, but --tracker fixed has "
     "fixed gains"),
    (["monopulse", "--manoeuvre-start-s", "0.8"],
     "error: --manoeuvre-start-s sets the manoeuvre window, but there is no manoeuvre"),
    (["gnss", "--tracker", "aukf", "--bn-hz", "15"],
     "error: --bn-hz applies to the trackers aided-pll, pll2, pll3; --tracker aukf has no such "
     "setting"),
    (["gnss", "--dynamics", "static", "--jerk-g-per-s", "5"],
     "error: --jerk-g-per-s sets the jerk segment of --dynamics aukf-patent-jerk"),
    (["ins", "--loop", "aided-kf", "--bn-hz", "15"], None),
])
def test_an_option_at_its_default_that_changes_nothing_is_refused(argv, msg, capsys):
    line = _exits(capsys, argv)
    if msg is None:         # ins has no --bn-hz at all: argparse's line, the command's help
        assert line == "error: unrecognized arguments: --bn-hz 15 (see python -m cosim ins " \
                       "--help)"
    else:
        assert line.startswith(msg), line


def test_ins_refuses_a_profile_option_at_its_default_with_a_csv(capsys, tmp_path):
    """--start-s 5 is the built-in profile's own start: with --trajectory-csv it is still an
    option that changes nothing."""
    import numpy as np
    from cosim.ins.trajectory import PaperTrajectory
    assert PaperTrajectory().start_s == 5.0
    t = np.arange(-0.1, 3.0, 0.01)
    np.savetxt(tmp_path / "t.csv", np.c_[t, 5.0 * np.clip(t, 0, None) ** 2], delimiter=",")
    line = _exits(capsys, ["ins", "--duration-s", "1", "--trajectory-csv",
                           str(tmp_path / "t.csv"), "--start-s", "5"])
    assert line == ("error: --start-s shapes the built-in profile; --trajectory-csv replaces "
                    "it (the option would change nothing)")


def test_the_same_options_left_out_run_the_defaults():
    """The refusals above are about the options given, not the configuration: without them
    the same configuration is accepted (built, not run)."""
    from cosim.core.receivers import config_kwargs, get
    from cosim.monopulse.checks import check_ignored
    from cosim.monopulse.run import MonopulseRunConfig
    p = build_parser()
    a = p.parse_args(["monopulse", "--skip-calibration"])
    opts = get("monopulse").options
    run = MonopulseRunConfig(**config_kwargs(a, opts, MonopulseRunConfig))
    check_ignored(run, frozenset({"skip_calibration"}))
    with pytest.raises(ValueError, match="--cal-snapshots sets the calibration"):
        check_ignored(run, frozenset({"skip_calibration", "cal_snapshots"}))


# -- a refusal does not pay for scipy ----------------------------------------------------------
def test_the_command_line_refuses_without_importing_scipy():
    """``import cosim.cli`` imports no scipy at all; a refusal (parser built, options checked)
    imports neither scipy.signal nor scipy.stats (numba, which the TACAN DSP's constants
    bring in, imports bare ``scipy`` to check its version)."""
    code = textwrap.dedent("""
        import sys
        import cosim.cli
        bare = sorted(m for m in sys.modules if m == "scipy" or m.startswith("scipy."))
        rc = cosim.cli.main(["gnss", "--cn0-dbhz", "200"])
        heavy = sorted(m for m in sys.modules if m.startswith(("scipy.signal", "scipy.stats",
                                                               "scipy.optimize")))
        print(rc, bare, heavy)
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=REPO_ROOT, env={"PYTHONPATH": str(REPO_ROOT), "PATH": "/usr/bin:/bin"},
                       timeout=120)
    assert r.stdout.strip() == "2 [] []", (r.stdout, r.stderr)
    assert r.stderr.strip() == ("error: --cn0-dbhz must be a finite number >= 10 dB-Hz and <= "
                                "70 dB-Hz, not 200.0")
