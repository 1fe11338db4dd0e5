"""Issue 42, second pass, the GNSS and INS commands: every class of input that ran to exit 0
having been ignored or meaningless, or failed late or inside the work, is refused before
any work with one line naming the option (exit 2); a failed acquisition is a result (exit 1
and a status), not bad input. The refusals are reached before a record is generated: these
tests run the parsers and the validation only."""
import json
from types import SimpleNamespace

import numpy as np
import pytest

from cosim.cli import main


def _err(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


# -- a default the validation refused ---------------------------------------------------------
# (check_point reads the C/N0 of the configuration only: no SweepConfig, whose receiver
# registry would load every receiver)
SWEEP_CFG = SimpleNamespace(snr_db=(32.0,))


def test_the_default_sweep_points_all_pass_the_cores_checks():
    from cosim.gnss.study import SWEEP_MODEL, check_point
    [(name, values)] = SWEEP_MODEL.default_params
    for v in values:
        check_point(SWEEP_CFG, ((name, v),))


def test_a_refused_width_names_the_smallest_that_passes():
    from cosim.gnss.study import check_point
    cfg = SWEEP_CFG
    with pytest.raises(ValueError, match=r"AukfFormats.P QFormat\(bits=28, frac=16\) resolves "
                                         r".*; the smallest dsp.P that passes is 29$"):
        check_point(cfg, (("dsp.P", 28),))
    check_point(cfg, (("dsp.P", 29),))


# -- inputs that changed nothing ------------------------------------------------------------
@pytest.mark.parametrize("args, msg", [
    (["--jerk-g-per-s", "9"], "error: --jerk-g-per-s sets the jerk segment of --dynamics "
                              "aukf-patent-jerk; --dynamics static has none"),
    (["--dynamics", "aukf-patent", "--jerk-start-s", "1", "--jerk-duration-s", "1"],
     "error: --jerk-start-s, --jerk-duration-s set the jerk segment of --dynamics "
     "aukf-patent-jerk; --dynamics aukf-patent has none"),
    (["--dynamics", "aukf-patent-jerk", "--duration-s", "1", "--jerk-start-s", "50"],
     "error: --jerk-start-s 50 s starts after the record ends (1.7 s: --duration-s and the "
     "acquisition)"),
    (["--dynamics", "aukf-patent-jerk", "--duration-s", "1"],
     "error: --jerk-start-s 2 s (its default) starts after the record ends"),
    (["--tracker", "aukf", "--bn-hz", "40"], "error: --bn-hz applies to the trackers aided-pll, "
                                             "pll2, pll3; --tracker aukf has no such setting"),
    (["--tracker", "pll3", "--r-mode", "cn0"], "error: --r-mode applies to the trackers aukf, "
                                               "ukf; --tracker pll3 has no such setting"),
    (["--backend", "golden", "--latency", "100"],
     "error: --latency is the HDL channel's register-write latency; --backend golden has no "
     "register bus"),
    (["--backend", "golden", "--compare", "golden"],
     "error: --compare golden compares the channel with the golden chain; --backend golden is "
     "that chain"),
])
def test_gnss_refuses_an_option_that_would_change_nothing(args, msg, capsys):
    assert main(["gnss"] + args) == 2
    assert _err(capsys).startswith(msg)


def test_the_tracker_options_are_the_trackers_own():
    from cosim.gnss.config import GnssRunConfig
    from dsp.gnss.trackers import tracker_options
    assert {k for k in tracker_options("aided-kf")} == {"dll_bn_hz"}
    run = GnssRunConfig(tracker="aukf")
    assert run.tracker_setting("bn_hz") is None and run.tracker_setting("r_mode") == "cn0"
    assert GnssRunConfig(tracker="pll3").tracker_setting("bn_hz") == 15.0
    assert GnssRunConfig(tracker="pll2", bn_hz=20.0).tracker_kwargs() == {"bn_hz": 20.0}


def _csv(path, t, s):
    np.savetxt(path, np.c_[t, s], delimiter=",")
    return str(path)


@pytest.mark.parametrize("opt, msg", [
    (["--accel-g", "30"], "--accel-g shapes"),
    (["--jerk-g-s", "2", "--start-s", "1", "--v-max-mps", "100"],
     "--start-s, --jerk-g-s, --v-max-mps shape"),
])
def test_ins_refuses_profile_options_with_a_csv(opt, msg, capsys, tmp_path):
    t = np.arange(-0.1, 3.0, 0.01)
    good = _csv(tmp_path / "t.csv", t, 5.0 * np.clip(t, 0, None) ** 2)
    assert main(["ins", "--duration-s", "1", "--trajectory-csv", good] + opt) == 2
    assert _err(capsys) == (f"error: {msg} the built-in profile; --trajectory-csv replaces it "
                            f"(the option would change nothing)")


# -- meaningless values ---------------------------------------------------------------------
@pytest.mark.parametrize("cmd", [["gnss"], ["ins"]])
def test_one_cn0_range_for_gnss_and_ins(cmd, capsys):
    assert main(cmd + ["--cn0-dbhz", "200"]) == 2
    assert _err(capsys) == ("error: --cn0-dbhz must be a finite number >= 10 dB-Hz and <= 70 "
                            "dB-Hz, not 200.0")


def test_a_latency_past_the_next_dump_is_refused_with_the_limit(capsys):
    assert main(["gnss", "--latency", "1000000000"]) == 2
    assert _err(capsys).startswith(
        "error: --latency 1000000000 cycles: the DSP's writes would reach the channel up to "
        "1,000,008,506 cycles after a record's dump, later than the next dump (16,384 cycles")
    assert main(["ins", "--latency", "9000"]) == 2
    assert _err(capsys).startswith("error: --latency 9000 cycles: the DSP's writes would reach")
    from cosim.gnss.config import GnssRunConfig
    GnssRunConfig(control_latency_cycles=7869).check_loop_timing(16.368e6)
    with pytest.raises(ValueError, match="at most 7869 cycles here"):
        GnssRunConfig(control_latency_cycles=7870).check_loop_timing(16.368e6)


# -- late or internal errors ----------------------------------------------------------------
def test_sweep_gnss_refuses_a_cn0_out_of_range_before_work(capsys, tmp_path):
    assert main(["sweep", "gnss", "--cn0-dbhz", "-50", "--out", str(tmp_path / "x")]) == 2
    assert _err(capsys) == ("error: --cn0-dbhz must be a finite number >= 10 dB-Hz and <= 70 "
                            "dB-Hz, not -50")


@pytest.mark.parametrize("what, msg", [
    ("step", "line 61, column 2: 1001.25 m after 1.2005 m 0.01 s earlier (line 60) is 1e+05 "
             "m/s, faster than 11200 m/s: a position step?"),
    ("kink", "line 60, column 2: the speed changes from 10 to 110 m/s around 0.49 s, 1.02e+03 "
             "g, more than 100 g: a position step?"),
    ("cols", "line 1: 3 columns; a row is time_s, distance_m (2 columns)"),
    ("text", "line 3, column 2: 'abc' is not a finite number"),
    ("short", "has 3 rows of (time_s, distance_m); the spline needs at least 4"),
])
def test_a_trajectory_csv_is_checked_on_load_naming_line_and_column(what, msg, tmp_path):
    from cosim.ins.trajectory import PaperTrajectory
    t = np.round(np.arange(-0.1, 3.0, 0.01), 10)
    s = 5.0 * np.clip(t, 0, None) ** 2
    p = tmp_path / f"{what}.csv"
    if what == "step":
        _csv(p, t, s + 1000.0 * (t >= 0.5))
    elif what == "kink":
        _csv(p, t, 10.0 * t + 1.0 * (t >= 0.5))
    elif what == "cols":
        np.savetxt(p, np.c_[t, s, s], delimiter=",")
    elif what == "text":
        p.write_text("0,0\n1,1\n2,abc\n3,3\n")
    else:
        p.write_text("# t, s\n0,0\n1,1\n2,2\n")
    with pytest.raises(ValueError) as e:
        PaperTrajectory(duration_s=1.0, csv_path=str(p))
    assert str(e.value) == f"--trajectory-csv {str(p)!r} {msg}"


def test_ins_refuses_a_run_too_big_before_building_the_scenario(capsys, monkeypatch):
    import cosim.ins.run as ins_run

    def no_work(*a, **k):
        raise AssertionError("the scenario was built before the size check")
    monkeypatch.setattr(ins_run, "Scenario", no_work)
    monkeypatch.setattr("cosim.core.validate.memory_bytes", lambda: 8 << 30)
    assert main(["ins", "--duration-s", "20000", "--backend", "golden"]) == 2
    assert _err(capsys).startswith("error: 20000.7 s of tracking (20,000,700 epochs of records) "
                                   "needs about 38.6 GiB, more than the 4 GiB a run may use")


# -- a weak signal is a result ----------------------------------------------------------------
def test_gnss_acquire_finding_nothing_is_a_result_exit_1(capsys, tmp_path):
    rng = np.random.default_rng(3)
    f = tmp_path / "noise.bin"
    (2 * rng.integers(-2, 2, size=int(2.046e6 * 0.021)) + 1).astype(np.int8).tofile(f)
    assert main(["gnss-acquire", "--file", str(f), "--format", "int8", "--fs-hz", "2.046e6",
                 "--prns", "1", "--json"]) == 1
    r = json.loads(capsys.readouterr().out)
    assert r["status"] == "no satellite found" and r["detections"] == []


@pytest.mark.parametrize("cmd", ["gnss", "ins"])
def test_a_failed_acquisition_is_status_not_acquired_exit_1(cmd, capsys, monkeypatch):
    from cosim.gnss.handover import AcquisitionFailed

    def fails(*a, **k):
        raise AcquisitionFailed("acquisition did not find PRN 1 within 54 ms of signal",
                                {"detected": False, "metric": 0.74})
    if cmd == "gnss":
        monkeypatch.setattr("cosim.gnss.receiver.run_gnss", fails)
    else:
        monkeypatch.setattr("cosim.ins.receiver.run_ins", fails)
    dur = {"gnss": "1", "ins": "40"}[cmd]       # ins: the profile's manoeuvre fits
    assert main([cmd, "--duration-s", dur, "--backend", "golden", "--json"]) == 1
    out = capsys.readouterr()
    r = json.loads(out.out)
    assert out.err == "" and r["status"] == "not acquired"
    assert r["acquired"] == {"detected": False, "metric": 0.74}
    assert r["message"].startswith("acquisition did not find PRN 1")


@pytest.mark.parametrize("tracker", ["unaided-kf", "aukf"])
def test_the_code_loop_bandwidth_reaches_the_kalman_trackers(tracker):
    # --dll-bn-hz of ins (and of gnss with an AUKF) was dropped on the way to the tracker
    from cosim.gnss.config import GnssRunConfig
    from cosim.gnss.tracking import make_tracker_for
    kd = [make_tracker_for(GnssRunConfig(tracker=tracker, dll_bn_hz=d), 16.368e6, 4.092e6,
                           False, 40.0, 100.0, 0.5, "float")[0].kd for d in (None, 2.0)]
    assert kd == [4.0, 8.0]
