"""``python -m cosim gps`` and its back end: bad input refused before work with one line,
fewer than four satellites give the solver's no-fix status (said so, no position), the
receiver time set and steered, and (slow) a generated static scenario of >= 8 satellites at
45 dB-Hz tracked on the bit-exact array, hot-started, fixed within a few metres of the
truth, with every output written."""
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from cosim.cli import main
from cosim.gnss.gps_outputs import summarise, table, write_outputs
from cosim.gnss.gps_receiver import GpsConfig, navigate
from dsp.gnss.nominal_orbits import nominal_constellation
from dsp.gnss.pvt import PvtStatus

from test_navigation import F, FS, IF, P, WEEK, TOE, records


def _err(capsys, *argv):
    rc = main(["gps", *map(str, argv)])
    err = capsys.readouterr().err
    return rc, err


@pytest.mark.parametrize("argv,match", [
    (["--file", "x.int8", "--fs-hz", "5e6"], "--file needs --format"),
    (["--format", "int8"], "--format needs --file"),
    (["--hot-start", "--file", "x.int8", "--format", "int8", "--fs-hz", "5e6"],
     "--hot-start is for a generated scenario"),
    (["--duration-s", "0"], "--duration-s"),
    (["--cn0-dbhz", "5"], "--cn0-dbhz"),
    (["--prns", "40"], "PRN"),
])
def test_bad_options_are_refused_before_work(capsys, tmp_path, argv, match):
    rc, err = _err(capsys, *argv, "--out", tmp_path / "o")
    assert rc == 2 and match in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()


def test_a_cold_start_on_a_file_needs_the_week_and_the_file_must_exist(capsys, tmp_path):
    f = tmp_path / "r.int8"
    f.write_bytes(bytes(100_000))
    rc, err = _err(capsys, "--file", f, "--format", "int8", "--fs-hz", "5e6", "--if-hz",
                   "1.25e6", "--out", tmp_path / "o")
    assert rc == 2 and "--week" in err
    rc, err = _err(capsys, "--file", tmp_path / "none.int8", "--format", "int8", "--fs-hz",
                   "5e6", "--week", "2300", "--out", tmp_path / "o")
    assert rc == 2 and "none.int8" in err


def test_an_unparsable_rinex_is_a_clear_error(capsys, tmp_path):
    bad = tmp_path / "bad.rnx"
    bad.write_text("this is not a RINEX navigation file\n")
    for opt in ("--ephemeris", "--nav"):
        rc, err = _err(capsys, opt, bad, "--out", tmp_path / "o")
        assert rc == 2 and "bad.rnx" in err and err.startswith("error:"), err
        assert not (tmp_path / "o" / "scenario.int8").exists()


def _fake_track(n_sats: int):
    """``n_sats`` synthetic channels (distinct PRNs, same satellite time: a geometry that
    does not matter for the count of satellites) of 14 s."""
    asg, writes = [], []
    for k in range(n_sats):
        a, tr, _ = records(500.0 * k, F + 5.7, 14.0, seed=k, ch=k)
        a.prn, a.candidate.prn = k + 1, k + 1
        asg.append(a)
        writes += tr.bus_writes
    return SimpleNamespace(fs_hz=FS, n_samples=int(14.0 * FS), channels=12,
                           bus_writes=writes, assignments=asg)


def test_fewer_than_four_satellites_give_no_fix_and_say_so(tmp_path):
    ephs = nominal_constellation(WEEK, TOE)
    g = navigate(_fake_track(3), P, reference_week=WEEK, inverted=False, if_hz=IF,
                 ephemerides=ephs, config=GpsConfig(rate_hz=1.0))
    sols = [e.solution for e in g.epochs if e.solution is not None]
    assert sols and all(s.status == PvtStatus.NO_FIX_TOO_FEW for s in sols)
    assert all(np.all(np.isnan(s.position_ecef_m)) for s in sols)
    assert g.ttff_s is None and not g.fixes
    # the receiver time was set at the first epoch with a TOW: 70 ms after the transmission
    e0 = next(e for e in g.epochs if e.obs is not None)
    assert g.time_set_s == pytest.approx(e0.sample / FS)
    t_sv = F + 5.7 + e0.sample / FS                   # Doppler 0 on the first channel
    assert e0.tow_s - t_sv == pytest.approx(0.070, abs=1e-3)
    s = write_outputs(g, tmp_path, plots=False)
    assert s["fixes"] == 0 and "no valid solution" in s["no_fix"]
    assert "no fix" in table(s)
    assert (tmp_path / "fixes.nmea").read_text() == ""
    assert json.loads((tmp_path / "gps.json").read_text())["statuses"] == \
        {"no_fix_too_few_satellites": len(sols)}


def test_a_run_without_any_usable_channel_reports_it():
    tr = _fake_track(2)
    for a in tr.assignments:
        a.lock_sample = None
    g = navigate(tr, P, reference_week=WEEK, inverted=False, if_hz=IF, ephemerides=(),
                 config=GpsConfig())
    s = summarise(g)
    assert s["fixes"] == 0 and s["solutions"] == 0 and "no channel" in s["no_fix"]
    assert [c["status"] for c in s["channels"]] == ["not-locked"] * 2


def test_bad_config_is_refused():
    with pytest.raises(ValueError, match="--rate"):
        GpsConfig(rate_hz=5.0)
    with pytest.raises(ValueError, match="initial_travel_s"):
        GpsConfig(initial_travel_s=0.2)


@pytest.mark.slow
def test_generated_scenario_hot_start_fixes_within_metres(capsys, tmp_path):
    """9 s of 8 satellites at 45 dB-Hz (nominal constellation, Saastamoinen troposphere,
    receiver clock 0.3 ms + 5e-8), acquired and tracked on the bit-exact array (fixed pll3),
    hot-started from the generator's ephemerides, 10 Hz: the first fix once the TOW is
    decoded (7.7 s in), every fix with all 8 satellites within 5 m of the truth, the receiver
    time steered to GPS time; the observables against the generator's truth. 2-6 minutes on
    the shared cores."""
    out = tmp_path / "gps"
    rc = main(["gps", "--duration-s", "9", "--hot-start", "--rate", "10", "--out", str(out),
               "--json"])
    s = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert len(s["truth"]["prns"]) >= 8 and sorted(s["acquired"]) == s["truth"]["prns"]
    assert all(c["status"] == "ok" and c["parity_failures"] == 0 for c in s["channels"])
    assert 7.6 <= s["ttff_s"] <= 7.9
    rows = [r for r in csv_rows(out / "fixes.csv") if r["status"].startswith("fix")]
    full = [r for r in rows if int(r["n_used"]) == len(s["truth"]["prns"])]
    assert len(full) >= 10
    assert max(float(r["err_3d_m"]) for r in full) < 5.0
    # a static receiver: the Doppler velocity within 0.1 m/s of zero
    assert max(math.hypot(float(r["vel_e_mps"]), float(r["vel_n_mps"]), float(r["vel_u_mps"]))
               for r in full) < 0.1
    # steered: from the third fix on, the bias left is the drift over one epoch (0.1 s)
    drift = 5e-8 * 299792458.0
    assert all(abs(float(r["clock_drift_mps"]) - drift) < 0.2 for r in full)
    assert all(abs(float(r["clock_bias_m"]) - 0.1 * drift) < 2.5 for r in rows[2:])
    for name in ("obs.rnx", "fixes.nmea", "fixes.csv", "gps.json", "position_error.png",
                 "skyplot.png", "cn0.png", "scenario.int8", "truth.json"):
        assert (out / name).is_file(), name
    nmea = (out / "fixes.nmea").read_text().splitlines()
    assert len(nmea) == 2 * len(rows) and nmea[0].startswith("$GPGGA")
    _observables_against_the_truth(out, rows)


def _observables_against_the_truth(out, rows):
    """The RINEX observations against the generator's truth at the epochs' samples:
    between-satellite pseudorange differences (the receiver clock cancels) within 2 m RMS, the
    carrier phase's change between epochs within 0.05 cycle, Doppler within 2 Hz."""
    georinex = pytest.importorskip("georinex")
    from cosim.gnss.constellation import ConstellationSignal
    from cosim.gnss.gps_scenario import ScenarioSpec, scenario_config
    from dsp.gnss.ephemeris import C_LIGHT
    data = georinex.load(out / "obs.rnx")
    sig = ConstellationSignal(scenario_config(ScenarioSpec(duration_s=9.0))[0])
    t = np.array([float(r["t_s"]) for r in rows])
    tr = sig.truth_at(t)
    svs = [f"G{p:02d}" for p in sig.prns]
    assert data.time.size == t.size
    get = lambda obs: np.array([[float(data[obs].sel(time=data.time[k], sv=sv))
                                 for sv in svs] for k in range(t.size)])
    c1c, l1c, d1c = get("C1C"), get("L1C"), get("D1C")
    full = np.all(np.isfinite(c1c), axis=1)
    assert full.sum() >= 10
    want = -C_LIGHT * (tr.t_sv - tr.t_sv[:, :1])             # P_i - P_0 = c (t_sv0 - t_svi)
    got = c1c - c1c[:, :1]
    d = (got - want)[full][:, 1:]
    # DLL noise (Bn 1 Hz, half-chip spacing, ~43 dB-Hz after the 2-bit ADC): ~1 m per
    # satellite, ~1.5 m per difference
    assert np.sqrt(np.mean(d ** 2)) < 2.0 and np.max(np.abs(d)) < 5.0, d
    dl = np.diff(l1c[full], axis=0) + np.diff(tr.carrier_phase_cycles[full], axis=0)
    assert np.max(np.abs(dl)) < 0.05                          # RINEX L = -(signal phase)
    assert np.max(np.abs(d1c - tr.doppler_hz)[full]) < 2.0


def csv_rows(path):
    import csv
    with open(path) as fh:
        return list(csv.DictReader(fh))


def test_the_real_70ms_window_is_tracked_but_gives_no_fix_and_says_why(capsys, tmp_path):
    """70 ms of a real recording: three satellites acquired and tracked, far too short for
    bit synchronisation or a TOW: no solution, no position, exit 1 with the reason."""
    from pathlib import Path
    real = Path(__file__).resolve().parents[2] / "data" / "gnss" / \
        "L1_20211125_004000_12MHz_I_70ms.bin"
    rc = main(["gps", "--file", str(real), "--format", "int8", "--fs-hz", "12e6", "--if-hz",
               "3e6", "--week", "2185", "--prns", "13,15,24", "--rate", "10", "--out",
               str(tmp_path), "--no-plots", "--json"])
    s = json.loads(capsys.readouterr().out)
    assert rc == 1 and sorted(s["acquired"]) == [13, 15, 24]
    assert s["fixes"] == 0 and s["solutions"] == 0 and s["ttff_s"] is None
    assert "no channel had a TOW" in s["no_fix"]
    assert {c["status"] for c in s["channels"]} <= {"no-bit-sync", "not-locked"}
    assert (tmp_path / "fixes.csv").read_text() == ""
    assert not (tmp_path / "obs.rnx").exists()
