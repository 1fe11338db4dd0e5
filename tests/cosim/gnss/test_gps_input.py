"""``python -m cosim gps``'s generated scenario refuses bad input before any sample is
written (exit 2, one line naming the option): no satellite above ``--elevation-mask-deg``,
fewer than four (of ``--prns``) above it, a ``--trajectory`` that leaves the Earth's
neighbourhood or the troposphere model's heights, moves faster than the escape speed,
accelerates beyond 100 g (a position step that does not fit its velocities), does not
cover the record or does not parse, bad
``--bit-error-rate`` / ``--jump-bound-m``, scenario options with ``--file``. A trajectory
CSV is the motion it lists; ``--trajectory ins`` is the INS paper's profile; a moving
receiver's fixes are compared with the truth at their own epochs, and (slow) a receiver on
the INS trajectory is fixed within metres of it at every epoch. (An unparsable RINEX
for ``--nav`` and ``--ephemeris``, and fewer than four tracked satellites giving the
solver's no-fix status without a position, are pinned in ``test_gps.py``.)"""
import json
from types import SimpleNamespace

import numpy as np
import pymap3d
import pytest

from cosim.cli import main
from cosim.gnss.constellation import ConstellationSignal
from cosim.gnss.constellation_geometry import MAX_ACCEL_MPS2, StaticReceiver, check_motion, \
    csv_receiver
from cosim.gnss.gps_outputs import fix_rows
from cosim.gnss.gps_scenario import ScenarioSpec, scenario_config, scenario_signal
from cosim.ins.trajectory import PaperTrajectory

HOME = StaticReceiver.geodetic(52.0, 4.4, 30.0).position_m
UP = HOME / np.linalg.norm(HOME)
EAST = np.array(pymap3d.enu2uvw(1.0, 0.0, 0.0, 52.0, 4.4))


def _refused(capsys, tmp_path, *argv):
    rc = main(["gps", *map(str, argv), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("error:") and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()           # refused before any work
    return err


def _csv(tmp_path, rows, header="t,x,y,z,vx,vy,vz", name="traj.csv"):
    p = tmp_path / name
    p.write_text((header + "\n" if header else "") +
                 "\n".join(",".join(f"{v:.6f}" for v in r) for r in rows) + "\n")
    return p


def _line(t, v_east=0.0, dh=0.0):
    """Rows at times ``t``: moving east at ``v_east`` from HOME raised by ``dh``."""
    return [[s, *(HOME + dh * UP + v_east * s * EAST), *(v_east * EAST)] for s in t]


def _max_elevations(**kw):
    sig = ConstellationSignal(scenario_config(ScenarioSpec(mask_deg=3.0, **kw))[0])
    el = sig.truth_at(np.array([0.0, 8.0])).elevation_deg.max(axis=0)
    return dict(zip(sig.prns, el))


def test_no_satellite_above_the_mask_is_refused(capsys, tmp_path):
    top = max(_max_elevations().values())
    err = _refused(capsys, tmp_path, "--elevation-mask-deg", f"{top + 1:.1f}")
    assert "--elevation-mask-deg" in err and "no satellite above" in err
    for bad in ("90", "2.9", "nan"):
        assert "--elevation-mask-deg" in _refused(capsys, tmp_path, "--elevation-mask-deg", bad)


def test_fewer_than_four_satellites_above_the_mask_are_refused(capsys, tmp_path):
    el = sorted(_max_elevations().items(), key=lambda kv: -kv[1])
    mask = 0.5 * (el[2][1] + el[3][1])                  # leaves the three highest
    err = _refused(capsys, tmp_path, "--elevation-mask-deg", f"{mask:.3f}")
    assert "only 3 satellite(s) above" in err and "needs 4" in err
    assert all(f"G{p:02d}" in err for p, _ in el[:3])
    # four visible but only three of them searched
    prns = ",".join(str(p) for p, e in el[:3] if e >= 10.0) + ",32"
    err = _refused(capsys, tmp_path, "--prns", prns)
    assert "among --prns" in err and "only 3" in err


@pytest.mark.parametrize("what,rows,match", [
    ("escape speed", lambda t: _line(t, v_east=12e3), "exceeds 11200 m/s"),
    ("into space", lambda t: _line(t, dh=2e5), "leaves the band"),
    ("underground", lambda t: _line(t, dh=-5e3), "leaves the band"),
    ("stratosphere", lambda t: _line(t, dh=5e4), "outside the troposphere model's range"),
    # the position jumps 50 m between rows 0.1 s apart while the velocities say rest
    ("teleport", lambda t: [r if r[0] < 4.0 else [r[0], *(np.array(r[1:4]) + 50 * EAST),
                                                  0, 0, 0] for r in _line(t)],
     "exceeds 980.665 m/s^2"),
    ("too short", lambda t: _line(t[t < 5.0]), "must cover the record"),
    ("late start", lambda t: _line(t[t > 1.0]), "must cover the record"),
])
def test_an_impossible_trajectory_is_refused(capsys, tmp_path, what, rows, match):
    p = _csv(tmp_path, rows(np.arange(0.0, 8.01, 0.1)))
    err = _refused(capsys, tmp_path, "--trajectory", p)
    assert "--trajectory" in err and match in err, (what, err)


def test_a_trajectory_that_does_not_parse_is_refused(capsys, tmp_path):
    t = np.arange(0.0, 8.01, 1.0)
    cases = [
        (_csv(tmp_path, [r[:5] for r in _line(t)], name="five.csv"), "4 (t, x, y, z) or 7"),
        (_csv(tmp_path, _line(t[::-1]), name="back.csv"),
         "line 3, column 1: time must increase strictly; 7 s does not follow 8 s (line 2)"),
        (tmp_path / "none.csv", "is not a file"),
        (_csv(tmp_path, [[0.0, 1.0, 2.0, 3.0]], header="t,x,y,z\nx,y", name="two.csv"),
         "line 2: 2 columns; a row is 4 (t, x, y, z) or 7"),
        (_csv(tmp_path, _line(t)[:1], name="one.csv"), "the interpolation needs at least 2"),
    ]
    for p, match in cases:
        err = _refused(capsys, tmp_path, "--trajectory", p)
        assert "--trajectory" in err and match in err, err
    err = _refused(capsys, tmp_path, "--trajectory", "inss")
    assert "--trajectory 'inss' is not a file" in err


@pytest.mark.parametrize("argv,match", [
    (["--bit-error-rate", "0.6"], "--bit-error-rate"),
    (["--bit-error-rate=-1e-3"], "--bit-error-rate"),
    (["--jump-bound-m", "0"], "--jump-bound-m"),
    (["--file", "x.int8", "--format", "int8", "--fs-hz", "5e6", "--week", "2300",
      "--bit-error-rate", "1e-3"], "--bit-error-rate is for a generated scenario"),
    (["--file", "x.int8", "--format", "int8", "--fs-hz", "5e6", "--week", "2300",
      "--trajectory", "ins"], "--trajectory is for a generated scenario"),
    (["--file", "x.int8", "--format", "int8", "--fs-hz", "5e6", "--week", "2300",
      "--elevation-mask-deg", "5"], "--elevation-mask-deg is for a generated scenario"),
    (["--file", "x.int8", "--format", "int8", "--fs-hz", "5e6", "--week", "2300",
      "--tracker", "aided-kf"], "--tracker aided-kf needs an INS aiding source; a recording"),
    (["--tracker", "aided-pll"], "--tracker aided-pll needs an INS aiding source: a generated "
                                 "scenario has one with --trajectory ins"),
])
def test_bad_scenario_options_are_refused(capsys, tmp_path, argv, match):
    assert match in _refused(capsys, tmp_path, *argv)


def test_a_csv_trajectory_is_the_motion_it_lists(tmp_path):
    # a 1 g circle-free manoeuvre: x(t) = HOME + 0.5 a t^2 east, rows every 0.5 s
    a = 9.80665
    t = np.arange(-0.5, 9.01, 0.5)
    rows = [[s, *(HOME + 0.5 * a * s * s * EAST), *(a * s * EAST)] for s in t]
    rx = csv_receiver(_csv(tmp_path, rows), "--trajectory")
    u = np.array([0.123, 3.3, 7.77])
    p, v = rx.state(u)
    assert np.allclose(p, HOME + 0.5 * a * u[:, None] ** 2 * EAST, atol=1e-6)
    assert np.allclose(v, a * u[:, None] * EAST, atol=1e-4)     # rows written to 1e-6
    check_motion(rx, -0.2, 8.2)
    # without velocities: the cubic spline through the positions, velocity its derivative
    rx4 = csv_receiver(_csv(tmp_path, [r[:4] for r in rows], header="", name="p.csv"))
    p4, v4 = rx4.state(u)
    assert np.allclose(p4, p, atol=1e-4) and np.allclose(v4, v, atol=1e-4)
    assert rx.span_s == (-0.5, 9.0) and MAX_ACCEL_MPS2 == pytest.approx(100 * a)
    # the scenario's receiver: the truth at receiver time s is the row motion at GPS time
    # u = s - dt_r(s)
    sig, _ = scenario_signal(ScenarioSpec(trajectory=str(tmp_path / "traj.csv")))
    tr = sig.truth_at(np.array([0.0, 4.0, 8.0]))
    u = tr.t_gps - sig.cfg.tow_s
    assert np.allclose(tr.rx_position_m, HOME + 0.5 * a * u[:, None] ** 2 * EAST, atol=1e-4)


def test_the_ins_trajectory_moves_the_scenario_receiver():
    spec = ScenarioSpec(trajectory="ins", duration_s=9.0)
    sig = ConstellationSignal(scenario_config(spec)[0])
    tr = sig.truth_at(np.array([0.0, 4.0, 9.0]))
    k = PaperTrajectory().kinematics(tr.t_gps - sig.cfg.tow_s)
    speed = np.linalg.norm(tr.rx_velocity_mps, axis=1)
    assert np.allclose(speed, k[1], rtol=1e-9, atol=1e-9) and speed[1] == 0 and speed[2] > 300
    moved = np.linalg.norm(tr.rx_position_m - HOME, axis=1)
    assert moved[0] < 1e-6 and moved[2] == pytest.approx(k[0][2], rel=1e-6)
    east = (tr.rx_position_m[2] - HOME) @ EAST / moved[2]
    assert east > 0.999999                       # flown east from --lat/--lon/--height


def test_a_moving_receivers_fix_is_compared_with_the_truth_at_its_epoch():
    from dsp.gnss.pvt import PvtStatus
    sol = lambda pos: SimpleNamespace(                                         # noqa: E731
        status=PvtStatus.FIX, valid=True, used_prns=(1, 2, 3, 4), lat_deg=52.0, lon_deg=4.4,
        height_m=30.0,
        position_ecef_m=np.asarray(pos), clock_bias_m=0.0, clock_drift_mps=0.0,
        velocity_enu_mps=np.zeros(3), dop=SimpleNamespace(pdop=1.0, hdop=1.0, vdop=1.0))
    p1 = HOME + 100.0 * EAST
    run = SimpleNamespace(fs_hz=1000.0, epochs=[
        SimpleNamespace(sample=1000, week=2300, tow_s=1.0, solution=sol(HOME + [0, 0, 2.0])),
        SimpleNamespace(sample=2000, week=2300, tow_s=2.0, solution=sol(p1 + [0, 0, 3.0]))])
    truth = {"receiver_ecef_m": list(HOME), "ecef_at_sample": {2000: list(p1)}}
    rows = fix_rows(run, truth)
    assert [round(r["err_3d_m"], 9) for r in rows] == [2.0, 3.0]
    assert rows[1]["truth_x_m"] == pytest.approx(p1[0])


@pytest.mark.slow
@pytest.mark.parametrize("tracker", ["pll3", "aided-kf"])
def test_a_receiver_on_the_ins_trajectory_is_fixed_at_every_epoch(capsys, tmp_path, tracker):
    """9 s of the INS paper's profile (at rest, from 5 s 5 g/s: 20 g and 370 m/s at the end)
    under 8 satellites at 45 dB-Hz, hot start, 10 Hz, on the bit-exact array, the 3rd-order
    PLL or the aided Kalman loop (each channel aided by the scenario's INS): every fix
    within 5 m of the trajectory at its own epoch (hundreds of metres from the start point),
    the Doppler velocity within 0.2 m/s of the truth, no fix jump. ~80 s of CPU each (2-10
    minutes on the shared cores)."""
    import csv
    out = tmp_path / "gps"
    rc = main(["gps", "--duration-s", "9", "--hot-start", "--rate", "10", "--trajectory", "ins",
               "--tracker", tracker, "--out", str(out), "--no-plots", "--json"])
    s = json.loads(capsys.readouterr().out)
    assert rc == 0 and s["truth"]["trajectory"] == "ins"
    assert all(c["status"] == "ok" for c in s["channels"]) and len(s["channels"]) >= 8
    with open(out / "fixes.csv") as fh:
        rows = [r for r in csv.DictReader(fh) if r["status"].startswith("fix")]
    assert len(rows) >= 10 and s["fixes"] == len(rows)
    spec = ScenarioSpec(duration_s=9.0, trajectory="ins")
    sig = ConstellationSignal(scenario_config(spec)[0])
    t = np.array([float(r["t_s"]) for r in rows])
    tr = sig.truth_at(t)
    got = np.array([[float(r[k]) for k in ("x_m", "y_m", "z_m")] for r in rows])
    err = np.linalg.norm(got - tr.rx_position_m, axis=1)
    assert np.allclose([float(r["err_3d_m"]) for r in rows], err, atol=1e-6)
    assert err.max() < 5.0 and np.linalg.norm(tr.rx_position_m[-1] - HOME) > 300.0
    assert s["error"]["3d_m"]["max"] == pytest.approx(err.max(), abs=1e-6)
    for r, v, p in zip(rows, tr.rx_velocity_mps, tr.rx_position_m):
        lat, lon, _ = pymap3d.ecef2geodetic(*p)
        want = np.array(pymap3d.uvw2enu(*v, lat, lon))
        dv = [float(r[k]) for k in ("vel_e_mps", "vel_n_mps", "vel_u_mps")] - want
        assert np.linalg.norm(dv) < 0.2, (r["t_s"], dv)
    assert s["fix_jumps"]["count"] == 0 and s["fix_jumps"]["off_truth"] == 0
