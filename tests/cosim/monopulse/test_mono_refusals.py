"""Issue 42, the monopulse side and the shared classes: every class of bad or unusual input is
refused before any work with one line naming the option (messages pinned), not run away,
ignored, answered with a meaningless figure or failed late. Only the configuration, the parser
and the up-front checks run here (fast); the one closed loop is marked slow."""
from __future__ import annotations

import os
import re

import pytest

from cosim.cli import main
from cosim.core.validate import check_budget, check_out_dir
from cosim.monopulse.run import MonopulseRunConfig


def refused(**kw):
    return pytest.raises(ValueError, match=re.escape(kw.pop("msg")))


def one_error_line(capsys, argv, msg, rc=2):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == rc
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(msg), err


def exits_2(capsys, argv, msg):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: " + msg), err


# -- 1. run away: memory and time estimated from the configuration, refused up front -------
@pytest.mark.parametrize("kw,msg", [
    (dict(du_dt=0.0, dv_dt=0.0, duration_s=1e6),
     "1,220,703,125 blocks x 1 trial on the fast backend (--duration-s 1e+06 in blocks of "
     "0.819 ms, --snapshots 8192) needs about 455 GiB"),
    (dict(snapshots=1, duration_s=0.3, snr_db=25.0),
     "3,000,000 blocks x 1 trial on the fast backend (--duration-s 0.3 in blocks of 0.0001 ms, "
     "--snapshots 1) would take about 3.5 h on this machine (limit 2 h): reduce --duration-s "
     "or --trials, or raise --snapshots (fewer, longer blocks)"),
    (dict(trials=1_000_000), "2,441 blocks x 1,000,000 trials on the fast backend"),
    (dict(backend="golden", duration_s=200.0, du_dt=0.0, dv_dt=0.0),
     "244,141 blocks x 1 trial on the golden backend"),
])
def test_a_run_too_big_is_refused_before_work(kw, msg):
    with refused(msg=msg):
        MonopulseRunConfig(**kw)


def test_check_budget_is_the_one_size_rule(capsys):
    with refused(msg="7 blocks would take about 2.78 h on this machine (limit 2 h): reduce "
                     "--duration-s"):
        check_budget("7 blocks", "--duration-s", seconds=1e4)
    with refused(msg="7 blocks has no finite run time: reduce --duration-s"):
        check_budget("7 blocks", "--duration-s", seconds=float("inf"))
    with refused(msg="7 blocks needs about"):
        check_budget("7 blocks", "--duration-s", memory_bytes=1e15)
    check_budget("7 blocks", "--duration-s", seconds=90.0, note=True)
    assert capsys.readouterr().err == "warning: 7 blocks: about 90 s estimated\n"
    check_budget("7 blocks", "--duration-s", seconds=90.0)
    assert capsys.readouterr().err == ""


# -- 2. options that change nothing in the run asked for: refused ---------------------------
@pytest.mark.parametrize("kw,msg", [
    (dict(skip_calibration=True, cal_snapshots=1000),
     "--cal-snapshots sets the calibration, but --skip-calibration skips it"),
    (dict(service_period_cycles=100), "--service-period-cycles sets how the DSP reads the "
     "FPGA FIFO, but --backend fast has no FIFO: use --backend model, pysim, verilator or "
     "icarus"),
    (dict(backend="golden", compute_cycles=500, control_latency_cycles=3),
     "--compute-cycles, --control-latency-cycles set how the DSP reads the FPGA FIFO, but "
     "--backend golden has no FIFO"),
    (dict(eq36="literal", tracker="fixed"), "--eq36 sets the adaptive tracking index, but "
     "--tracker fixed has fixed gains (--sigma-a)"),
    (dict(manoeuvre_start_s=1.0), "--manoeuvre-start-s sets the manoeuvre window, but there "
     "is no manoeuvre (--accel-u and --accel-v are 0)"),
    (dict(accel_u=1.0, manoeuvre_start_s=5.0, manoeuvre_end_s=6.0),
     "the manoeuvre starts at --manoeuvre-start-s 5, after the end of the run (--duration-s "
     "2): it would change nothing"),
    (dict(detect_db=-100.0), "--detect-db must be > 0 dB (the threshold over the sum beam's "
     "noise power; at 0 dB noise alone passes 37 % of the blocks, below it nearly all), not "
     "-100"),
])
def test_an_option_without_effect_is_refused(kw, msg):
    with refused(msg=msg):
        MonopulseRunConfig(**kw)


# -- 3. meaningless values ------------------------------------------------------------------
@pytest.mark.parametrize("kw,msg", [
    (dict(snr_db=-200.0), "--snr-db -200 gives the sum beam of a block -154.8 dB over its noise "
     "(4 channels x 8192 snapshots), below the 13 dB detection threshold: the target could "
     "never be detected; raise --snr-db"),
    (dict(snr_db=500.0), "--snr-db 500 is above what the 12-bit ADC resolves (61.2 dB: the "
     "noise must span at least one ADC step; above it the ADC sets the noise): lower --snr-db "
     "or raise --adc-bits"),
    (dict(latency_blocks=5000), "the record is too short to score anything: 2,441 blocks of "
     "0.819 ms (--duration-s 2), the first tracked block is 2 + --latency-blocks 5000 at the "
     "earliest and scoring starts at --settle-s 0.1 (block 5,002)"),
    (dict(settle_s=5.0), "--settle-s must be >= 0 and shorter than the record (--duration-s 2: "
     "nothing would be scored), not 5"),
    (dict(duration_s=0.002, settle_s=0.0), "the record is too short to score anything: 2 "
     "blocks of 0.819 ms"),
    (dict(gain_spread_db=-1.0), "--gain-spread-db must be >= 0 (channels 2-4 are drawn in +- "
     "it), not -1"),
])
def test_a_meaningless_value_is_refused(kw, msg):
    with refused(msg=msg):
        MonopulseRunConfig(**kw)


def test_the_limits_are_derived_not_guessed():
    # 60 dB resolves with 12 bits, not with 8; -30 dB still detects at 8192 snapshots
    MonopulseRunConfig(snr_db=60.0, duration_s=0.2)
    with refused(msg="--snr-db 60 is above what the 8-bit ADC resolves (37.1 dB"):
        MonopulseRunConfig(snr_db=60.0, adc_bits=8, duration_s=0.2)
    MonopulseRunConfig(snr_db=-30.0, duration_s=0.2)
    with refused(msg="--snr-db -30 gives the sum beam of a block 12.1 dB"):
        MonopulseRunConfig(snr_db=-30.0, snapshots=4096, duration_s=0.2)
    # a record for the bits only (the sweep's re-check) need not score
    MonopulseRunConfig(duration_s=0.002, settle_s=0.0, require_score=False)


# -- 4. generic: a value that runs nothing, a named backend that would be skipped, "" -------
def test_study_and_tool_options_that_would_do_nothing_exit_2(capsys, tmp_path):
    out = str(tmp_path / "o")
    exits_2(capsys, ["faults", "monopulse", "--ber", "0", "--out", out],
            "BER values must lie in (0, 1) (BER 0, the baseline, is always run), not '0'")
    exits_2(capsys, ["sweep", "monopulse", "--recheck", "5", "--out", out],
            "--recheck 5 is more than the 4 points it picks from")
    exits_2(capsys, ["check-equivalence", "--top", "monopulse", "--backends",
                     "model,pysim,verilator", "--samples", "100000"],
            "--backends names pysim, which cannot run this check: pysim runs only for samples "
            "<= 40000")
    exits_2(capsys, ["bench", "monopulse", "--quick", "--out", ""],
            "--out needs a directory name, not an empty string")
    assert not (tmp_path / "o").exists()


# -- 5. late errors: checked before the work --------------------------------------------------
@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc")
def test_an_unwritable_output_is_refused_up_front_also_as_root(capsys):
    with refused(msg="--out '/proc/x' is not writable (cannot create a file in '/proc'"):
        check_out_dir("/proc/x", "--out")
    exits_2(capsys, ["faults", "monopulse", "--out", "/proc/x"], "--out '/proc/x' is not "
            "writable")
    exits_2(capsys, ["synth", "--results", "/proc/x"], "--results '/proc/x' is not writable")


def test_a_sweep_snr_that_cannot_run_is_refused_before_the_points(capsys, tmp_path):
    exits_2(capsys, ["sweep", "monopulse", "--snr-db", "-200", "--out", str(tmp_path / "o")],
            "sweep point cordic_iterations=8: --snr-db -200 gives the sum beam of a block")


@pytest.mark.slow
def test_a_dsp_slower_than_a_service_period_still_gets_the_last_record():
    """--compute-cycles beyond the FIFO service period (inside the block's turnaround) was an
    internal RuntimeError ("front end gave 12 records for 12 blocks and the preamble"): the
    loop's end flush now waits for the DSP's last call."""
    from cosim.monopulse.run import run_monopulse
    r = run_monopulse(MonopulseRunConfig(
        backend="model", duration_s=12 * 6.4e-6, snapshots=64, snr_db=10.0, settle_s=0.0,
        service_period_cycles=40, service_latency_cycles=0, service_batch_words=8,
        compute_cycles=400, control_latency_cycles=10, seed=2))
    assert r["records"] == 13 and r["scored_blocks"] > 0


# -- 6. messages that blamed the wrong thing ------------------------------------------------
@pytest.mark.parametrize("kw,msg", [
    (dict(snapshots=10 ** 12), "--duration-s 2 is shorter than one measurement block "
     "(1,000,000,000,000 snapshots at 10 Msnapshot/s = 1e+05 s): lengthen --duration-s or "
     "reduce --snapshots"),
    (dict(duration_s=100.0), "the target leaves the visible region u^2 + v^2 < 1 at t = "
     "32.82 s (u = 0.9564, v = -0.2923): shorten --duration-s 100 to below that"),
    (dict(adc_bits=1), "adc_bits must be an integer in [2, 16], not 1"),
])
def test_messages_name_the_cause_in_option_terms(kw, msg):
    with refused(msg=msg):
        MonopulseRunConfig(**kw)


# -- 7. argparse's own errors: one line, every subcommand -----------------------------------
@pytest.mark.parametrize("argv,msg", [
    (["monopulse", "--snr-db", "x"], "error: argument --snr-db: not a number: 'x' (see "
     "python -m cosim monopulse --help)"),
    (["monopulse", "--backend", "foo"], "error: argument --backend: invalid choice: 'foo'"),
    (["sweep", "monopulse", "--trials", "1.5"], "error: argument --trials: must be a whole "
     "number, not 1.5 (see python -m cosim sweep monopulse --help)"),
    (["sweep"], "error: the following arguments are required: receiver"),
    (["bench", "nope"], "error: argument name: invalid choice: 'nope'"),
    (["check-equivalence", "--top", "x"], "error: argument --top: invalid choice: 'x'"),
    (["adc-loss", "--trials", "x"], "error: argument --trials: invalid int value: 'x' (see "
     "python -m cosim adc-loss --help)"),
])
def test_parser_errors_are_one_line(argv, msg, capsys):
    one_error_line(capsys, argv, msg)
