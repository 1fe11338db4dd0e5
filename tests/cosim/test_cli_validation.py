"""No silent wrong answers (issue 11): the command line refuses bad input before any work
starts, with one line on stderr and a non-zero exit, and a check that compares nothing fails.

One test per class of bad input, messages pinned; the wrong-answer classes first. The CLI
runs in-process (``cosim.cli.main``); refusals return before any signal is generated, so
these tests take milliseconds except the few that run a short scenario.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import build_parser, main
from cosim.core.validate import check_jobs, cores, dumps, json_safe

REPO = Path(__file__).resolve().parents[2]
SHORT = ["--duration-s", "1.0", "--memory-s", "0.2"]


def refused(capsys, argv, message, rc=2):
    """``argv`` exits ``rc`` with exactly one stderr line matching ``message``."""
    got = main(argv)
    out, err = capsys.readouterr()
    lines = [l for l in err.splitlines() if l.strip()]
    assert got == rc, (got, err)
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert message in lines[0], lines[0]
    return lines[0], out


# ---------------------------------------------------------------------------------------
# Wrong answers with exit 0 (fixed first)
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("fs_hz, backend", [
    (20e6, "golden"),      # 63 MHz in the 7th zone (spectrum not inverted)
    (24e6, "golden"),      # 6th zone, inverted
    (40e6, "model"),       # 4th zone, through the bit-exact model and the fixed DSP
    (28e6, "model"),       # 5th zone
])
def test_every_sample_rate_gives_the_true_bearing(capsys, fs_hz, backend):
    """The DSP counts ticks of the run's ADC clock (it assumed 20 MHz: 307/211 deg for 90)."""
    dsp = "fixed" if backend == "model" else "float"
    rc = main(["tacan", "--fs-hz", f"{fs_hz:g}", "--backend", backend, "--dsp", dsp,
               "--bearing-deg", "90", "--snr-db", "20", "--json"] + SHORT)
    r = json.loads(capsys.readouterr().out)
    assert rc == 0 and r["n_bearings"] > 0
    assert abs(r["mean_error_deg"]) < 0.5 and r["rmse_deg"] < 0.5, (fs_hz, r["rmse_deg"])


def test_the_timestamp_clock_is_checked():
    from dsp.tacan.kalman_config import KalmanConfig
    for bad in (float("nan"), 0.0, 1e5, True):
        with pytest.raises(ValueError, match=r"tick_hz must be a finite number >= 135000"):
            KalmanConfig(tick_hz=bad)


@pytest.mark.parametrize("dsp", ["float", "fixed"])
def test_the_dsp_runs_on_the_signal_clock(dsp):
    from cosim.tacan.config import TacanRunConfig
    from cosim.tacan.signal import TacanSignalConfig
    run = TacanRunConfig(signal=TacanSignalConfig(fs_hz=24e6), dsp=dsp)
    assert run.receiver.kalman.tick_hz == 24e6


def test_dsp_service_presets_keep_their_times_at_any_clock():
    """The presets are times in cycles of 20 MHz: the 1 ms timer stays 1 ms at 40 MS/s."""
    from cosim.tacan.receiver import tacan_run_config
    p = build_parser()
    at = lambda *x: tacan_run_config(p.parse_args(["tacan", "--backend", "model", *x])).service
    d20, d40 = at(), at("--fs-hz", "40e6")
    assert (d20.period_cycles, d20.latency_cycles) == (20_000, 200)
    assert (d40.period_cycles, d40.latency_cycles, d40.cycles_per_word) == (40_000, 400, 8)
    assert at("--fs-hz", "40e6", "--dsp-period-cycles", "30000").period_cycles == 30_000


def test_bearing_out_of_range_is_refused(capsys):
    refused(capsys, ["tacan", "--bearing-deg", "1e20"],
            "bearing_deg must be in [-360, 360] deg, not 1e+20")


def test_zero_modulation_is_refused(capsys):
    refused(capsys, ["tacan", "--mod-15", "0", "--mod-135", "0", "--json"],
            "both depths must be > 0, not mod_15=0, mod_135=0")
    refused(capsys, ["tacan", "--mod-15", "0"], "both depths must be > 0")


def test_json_is_always_valid():
    d = {"a": float("inf"), "b": [np.float64("nan"), 1.5], "c": np.int64(3), "d": np.bool_(1)}
    assert json_safe(d) == {"a": None, "b": [None, 1.5], "c": 3, "d": True}
    assert json.loads(dumps(d)) == {"a": None, "b": [None, 1.5], "c": 3, "d": True}


def test_no_noise_run_has_valid_json(capsys):
    """SNR 'none': CRB 0, RMSE/CRB undefined -> null, never Infinity."""
    rc = main(["tacan", "--snr-db", "none", "--json"] + SHORT)
    text = capsys.readouterr().out
    assert rc == 0 and "Infinity" not in text and "NaN" not in text
    r = json.loads(text)
    assert r["crb_deg"] == 0 and r["rmse_over_crb"] is None


@pytest.mark.parametrize("argv, message", [
    (["--backends", "model"], "--backends must name at least two backends to compare, "
                              "not 'model'"),
    (["--backends", ""], "--backends must name at least two backends"),
    (["--backends", "model,model"], "at least two backends"),
    (["--backends", "model,gpu"], "--backends takes a subset of "
                                  "model,pysim,verilator,icarus, not ['gpu']"),
])
def test_equivalence_needs_two_backends(capsys, argv, message):
    refused(capsys, ["check-equivalence"] + argv, message)


def test_equivalence_that_compares_nothing_fails(capsys):
    # pysim named but above its record limit: refused before work, not skipped
    refused(capsys, ["check-equivalence", "--backends", "model,pysim", "--samples", "50000",
                     "--json"],
            "--backends names pysim, which cannot run this check: pysim runs only for samples "
            "<= 40000 (~3e3 cycles/s) (--samples 50,000; lower --samples or leave pysim out)")
    # a record without a single FIFO word
    line, out = refused(capsys, ["check-equivalence", "--backends", "model,pysim",
                                 "--samples", "2000"],
                        "nothing was compared: the 2000 samples gave no FIFO word", rc=1)
    assert "compared pysim vs model: 0 vs 0 FIFO words" in out


@pytest.mark.parametrize("param, message", [
    ("adc_bits=4.5,6", "sweep point adc_bits=4.5: adc_bits must be an integer in [1, 24], "
                       "not 4.5"),
    ("dsp.K.rounding=sideways", "dsp.K.rounding must be one of floor, half_up, not 'sideways'"),
    ("nco_amp_bits=1", "sweep point nco_amp_bits=1: NCO amp_bits must be an integer in [2, 32]"),
    ("dsp.P=30.5", "dsp.P must be an integer in [2, 62], not 30.5"),
    ("adc_bits=0:1000000", "--param adc_bits '0:1000000' gives 1,000,001 values; at most 1000"),
    ("bogus=1", "unknown parameter 'bogus'"),
])
def test_sweep_parameters_checked_before_the_first_point(capsys, tmp_path, param, message):
    refused(capsys, ["sweep", "tacan", "--param", param, "--out", str(tmp_path / "s")], message)
    assert not (tmp_path / "s").exists()          # nothing started, nothing written


def test_faults_parameters_checked_before_the_first_point(capsys, tmp_path):
    out = str(tmp_path / "f")
    refused(capsys, ["faults", "tacan", "--bits", "99", "--out", out],
            "bits must be positions 0..11 of the adc words (12 bits), not [99]")
    refused(capsys, ["faults", "tacan", "--target", "dsp-state", "--bits", "60", "--out", out],
            "of the dsp-state words")
    refused(capsys, ["faults", "tacan", "--bits", "a,b", "--out", out],
            "--bits takes a comma list of bit positions, not 'a,b'")
    refused(capsys, ["faults", "tacan", "--ber", "2", "--out", out], "BER values must lie in (0, 1)")
    assert not Path(out).exists()


def test_adc_loss_fail_verdict_exits_nonzero(capsys, tmp_path):
    """A measurement that misses the 0.1 dB reference (too few samples to resolve it) is
    a FAIL: exit 1 with the reason on stderr."""
    rc = main(["adc-loss", "--bits", "1", "--trials", "100", "--n-samples", "4",
               "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 1 and "error: reference points FAIL" in err and "1 bit" in err


def test_adc_loss_bad_input(capsys, tmp_path):
    refused(capsys, ["adc-loss", "--bits", "1.5", "--out", str(tmp_path)],
            "--bits takes integers a:b or a comma list, not '1.5'")
    refused(capsys, ["adc-loss", "--loading", "max", "--out", str(tmp_path)],
            "--loading must be optimal, agc or a number")
    refused(capsys, ["adc-loss", "--out", ""], "--out needs a directory name")


# ---------------------------------------------------------------------------------------
# Work that should never start
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv, message", [
    (["tacan", "--duration-s", "1e4"], "reduce --duration-s or --fs-hz"),
    (["tacan", "--fs-hz", "1e12"], "3e+12 ADC samples (--duration-s 3 x --fs-hz 1e+12) needs "
                                   "about"),
    (["check-equivalence", "--samples", "1e11"], "--samples 100,000,000,000 needs about"),
    (["sweep", "tacan", "--snr-db", "0:1000000:0.001"],
     "--snr-db '0:1000000:0.001' gives 1,000,000,001 values; at most 1000"),
    (["tacan", "--backend", "pysim", "--duration-s", "1.2"],
     "24,000,000 cycles on the pysim backend (about 3e+03 cycles/s) would take about 2.22 h "
     "on this machine (limit 2 h): reduce --duration-s; long records run on --backend model"),
    (["tacan", "--backend", "model", "--recheck", "pysim", "--recheck-samples", "1e8"],
     "reduce --recheck-samples"),
    (["sweep", "tacan", "--snr-db", "0:100", "--trials", "100", "--duration-s", "10"],
     "111,100 points of 10 s would take about"),
    (["faults", "tacan", "--trials", "100000"], "500,000 runs of 2 s would take about"),
    (["faults", "tacan", "--duration-s", "1e4"], "reduce --duration-s or --fs-hz"),
])
def test_runs_too_big_are_refused_up_front(capsys, argv, message):
    line, _ = refused(capsys, argv, message)


@pytest.mark.parametrize("jobs", ["100000", "0", "-1"])
def test_jobs_bounded_by_the_cores(capsys, tmp_path, jobs):
    refused(capsys, ["sweep", "tacan", "--jobs", jobs, "--out", str(tmp_path)],
            f"--jobs must be an integer in [1, {cores()}] (the cores of this machine")


def test_check_jobs():
    assert check_jobs(None) == cores() and check_jobs(1) == 1
    with pytest.raises(ValueError, match="must be an integer in"):
        check_jobs(True)


def test_output_paths_checked_before_the_run(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    refused(capsys, ["verilog", "--out", ""], "--out needs a directory name, not an empty string")
    assert list(tmp_path.iterdir()) == []         # nothing written into the cwd
    f = tmp_path / "file"
    f.write_text("x")
    refused(capsys, ["sweep", "tacan", "--out", str(f)], "is an existing file, not a directory")
    refused(capsys, ["synth", "--out", str(f / "sub")], "cannot be created")
    refused(capsys, ["synth", "--results", str(f)], "--results")
    refused(capsys, ["tacan", "--backend", "pysim", "--trace", "wave.txt"],
            "--trace takes the format from the file suffix (.vcd or .fst), not 'wave.txt'")
    refused(capsys, ["tacan", "--backend", "pysim", "--trace", "wave.fst"],
            "FST is written by --backend verilator only")
    refused(capsys, ["tacan", "--backend", "verilator", "--trace", str(tmp_path)],
            "--trace takes the format from the file suffix")


def test_bench_quick_never_overwrites_results(capsys):
    refused(capsys, ["bench", "tacan-accuracy", "--quick", "--out", str(REPO / "results")],
            "must not overwrite the published results/")
    refused(capsys, ["bench", "dsp-speed", "--jobs", "1"], "--jobs has no effect on bench "
                                                           "dsp-speed")


def test_expected_errors_are_one_line_without_traceback(capsys, monkeypatch):
    import cosim.cli as cli

    def boom(a):
        raise OSError(28, "No space left on device", "build/x")
    parser = cli.build_parser
    monkeypatch.setattr(cli, "build_parser", lambda: _with_func(parser(), boom))
    refused(capsys, ["verilog"], "No space left on device: build/x")

    def oom(a):
        raise MemoryError()
    monkeypatch.setattr(cli, "build_parser", lambda: _with_func(parser(), oom))
    refused(capsys, ["verilog"], "out of memory")
    with pytest.raises(MemoryError):            # --debug: the traceback
        main(["verilog", "--debug"])


def _with_func(p, fn):
    sub = next(a for a in p._actions if a.dest == "command")
    sub.choices["verilog"].set_defaults(func=fn)
    return p


def test_expected_error_exit_path_in_a_process():
    """The real exit path: one stderr line, exit 2, no traceback."""
    r = subprocess.run([sys.executable, "-m", "cosim", "tacan", "--bearing-deg", "1e20"],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().splitlines() == [
        "error: bearing_deg must be in [-360, 360] deg, not 1e+20"]


# ---------------------------------------------------------------------------------------
# Options that are silently ignored
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv, message", [
    (["--dsp-service", "dma"], "--dsp-service set how the DSP reads the FPGA FIFO, but "
                               "--backend golden has no FIFO"),
    (["--dsp-stall", "0.5:0.6"], "--dsp-stall set how the DSP reads"),
    (["--dsp-period-cycles", "1000", "--dsp-batch-words", "8"],
     "--dsp-period-cycles, --dsp-batch-words set how the DSP reads"),
    (["--trace-window", "0:1"], "--trace-window selects what --trace dumps: give --trace"),
    (["--backend", "pysim", "--trace", "build/x.vcd", "--trace-window", "0:0.001"],
     "--trace-window works with --backend verilator; pysim dumps the whole run"),
    (["--backend", "model", "--recheck-samples", "1000"],
     "--recheck-samples sets how much --recheck re-runs: give --recheck too"),
    (["--backend", "model", "--dsp-stall", "5:6"],
     "--dsp-stall 5:6 starts after the end of the run (--duration-s 3)"),
    (["--backend", "model", "--dsp-stall", "1"], "--dsp-stall takes START:STOP in seconds"),
])
def test_tacan_options_without_effect_are_refused(capsys, argv, message):
    refused(capsys, ["tacan"] + argv, message)


def test_study_options_without_effect_are_refused(capsys, tmp_path):
    out = str(tmp_path / "x")
    refused(capsys, ["faults", "tacan", "--fifo-parity", "--out", out],
            "fifo_parity protects the FIFO words: it changes nothing for target 'adc'")
    refused(capsys, ["faults", "tacan", "--target", "fifo", "--scrub-period-s", "0.1",
                     "--out", out], "--scrub-period-s only affect(s) --target register")
    refused(capsys, ["sweep", "tacan", "--recheck", "0", "--recheck-samples", "5000",
                     "--out", out], "--recheck 0 runs none")
    refused(capsys, ["sweep", "tacan", "--scheduler", "sideways", "--out", out],
            "--scheduler must be local, dask or a Dask scheduler address")
    refused(capsys, ["sweep", "tacan", "--scheduler", "tcp://10.0.0.1:8786", "--jobs", "1",
                     "--out", out], "a remote Dask scheduler (--scheduler ADDRESS) has its own")


def test_short_cycle_accurate_record_is_allowed(capsys):
    """pysim is for short records: no bearing (warned on stderr, null in the JSON), the
    digests of the bits."""
    rc = main(["tacan", "--backend", "pysim", "--duration-s", "0.0005", "--json"])
    cap = capsys.readouterr()
    r = json.loads(cap.out)
    assert rc == 0 and r["n_bearings"] == 0 and r["rmse_deg"] is None
    assert "no bearing is scored" in cap.err and r["digest"]["fifo"]


# ---------------------------------------------------------------------------------------
# --help and choices
# ---------------------------------------------------------------------------------------
def test_help_shows_every_default():
    p = build_parser()
    sub = next(a for a in p._actions if a.dest == "command")
    for name, sp in sub.choices.items():
        if name == "adc-loss":
            continue
        text = sp.format_help()
        for act in sp._actions:
            if act.option_strings and act.default not in (None, False, [], "==SUPPRESS=="):
                assert act.help, (name, act.option_strings)
        assert "default" in text, name
    text = sub.choices["tacan"].format_help()
    assert "ADC sample rate = FPGA clock (Hz)" in text and "(default: 20000000.0)" in text


def test_choices_are_case_insensitive_or_refused(capsys):
    a = build_parser().parse_args(["tacan", "--mode", "y", "--backend", "MODEL", "--dsp", "Fixed"])
    assert (a.mode, a.backend, a.dsp) == ("Y", "model", "fixed")
    with pytest.raises(SystemExit) as e:
        main(["tacan", "--backend", "gpu"])
    assert e.value.code == 2 and "invalid choice: 'gpu'" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------
# Reports
# ---------------------------------------------------------------------------------------
def _tables(text: str):
    lines = text.splitlines()
    for i, l in enumerate(lines[1:], 1):
        if l.startswith("|---") or l.startswith("|:--") or l.startswith("|--"):
            yield lines[i - 1].count("|"), l.count("|"), i


def test_sweep_report_tables_render():
    from cosim.studies.spec import SweepConfig
    from cosim.studies.report import report_md
    cfg = SweepConfig(params=(("adc_bits", (4, 6)), ("nco_amp_bits", (8, 12))))
    s = {"machine": {"command": "x", "cpu": "c", "cores": 2, "date": "d", "commit": "h"},
         "n_points": 0, "elapsed_s": 0.0, "rows": [], "ranges": {}, "proposal": {},
         "rechecks": []}
    tables = list(_tables(report_md(cfg, s, [])))
    assert tables and all(h == sep for h, sep, _ in tables), tables


@pytest.mark.parametrize("path", sorted((REPO / "results").glob("**/*.md")),
                         ids=lambda p: str(p.relative_to(REPO)))
def test_committed_report_tables_render(path):
    bad = [(i, h, s) for h, s, i in _tables(path.read_text()) if h != s]
    assert not bad, bad


def test_bench_scheduler_refusals(capsys, tmp_path):
    # before any work: a benchmark without tasks, a malformed or unreachable address,
    # --jobs with an address
    out = str(tmp_path / "x")
    refused(capsys, ["bench", "estimation", "--scheduler", "dask", "--out", out],
            "--scheduler has no effect on bench estimation (only on ins-table2)")
    refused(capsys, ["bench", "ins-table2", "--scheduler", "sideways", "--out", out],
            "--scheduler must be local, dask or a Dask scheduler address")
    refused(capsys, ["bench", "ins-table2", "--scheduler", "tcp://127.0.0.1:1", "--jobs", "2",
                     "--out", out], "a remote Dask scheduler (--scheduler ADDRESS) has its own")
    refused(capsys, ["bench", "ins-table2", "--scheduler", "tcp://127.0.0.1:1", "--out", out],
            "--scheduler tcp://127.0.0.1:1: cannot connect")
    assert not (tmp_path / "x").exists()
