"""Satellite positions, velocities and clocks of the IS-GPS-200 user algorithm against
gnss-lib-py's independent implementation, on real IGS broadcast ephemerides; the RINEX
reader; the Sagnac rotation against pymap3d; the nominal constellation."""
from dataclasses import replace
from pathlib import Path

import gnss_lib_py.navdata.navdata as glp_navdata
import gnss_lib_py.utils.constants as glp_consts
import gnss_lib_py.utils.sv_models as glp_sv
import numpy as np
import pymap3d
import pytest

from cosim.gnss.rinex_nav import read_rinex_nav, ura_index
from dsp.gnss import ephemeris as E
from dsp.gnss.nominal_orbits import SLOT_NAMES, SLOTS, EPOCH_GHA_DEG, EPOCH_GPS_S, \
    nominal_constellation, nodal_rate
from dsp.gnss.lnav_fields import EPHEMERIS_FIELDS


DATA = Path(__file__).resolve().parents[2] / "data" / "gnss"
RINEX2 = DATA / "brdc2800.15n"
RINEX3 = DATA / "ZIM200CHE_R_20201390000_01D_GN.rnx"


@pytest.fixture(scope="module")
def nav2():
    return read_rinex_nav(RINEX2)


@pytest.fixture(scope="module")
def nav3():
    return read_rinex_nav(RINEX3)


def test_constants_are_those_of_is_gps_200_and_of_gnss_lib_py():
    assert (E.MU_GPS, E.OMEGA_E_DOT, E.PI_GPS) == (3.986005e14, 7.2921151467e-5, 3.1415926535898)
    assert E.F_REL == -4.442807633e-10 and E.C_LIGHT == 299792458.0
    # The comparison below is exact in its constants: gnss-lib-py uses the same values.
    assert (glp_consts.MU_EARTH, glp_consts.OMEGA_E_DOT, glp_consts.F, glp_consts.C) == \
        (E.MU_GPS, E.OMEGA_E_DOT, E.F_REL, E.C_LIGHT)
    # F = -2 sqrt(mu) / c^2 (20.3.3.3.3.1) to the 10 digits the standard prints.
    assert -2 * np.sqrt(E.MU_GPS) / E.C_LIGHT ** 2 == pytest.approx(E.F_REL, rel=1e-9)


def test_rinex2_file_content(nav2):
    assert nav2.version == 2.0 and len(nav2.ephemerides) == 420
    assert nav2.prns() == list(range(1, 33))
    e = [x for x in nav2.ephemerides if x.prn == 1][0]      # the first record of the file
    assert (e.week, e.toe, e.toc, e.IODE, e.IODC) == (1865, 259200.0, 259200.0, 70, 70)
    assert e.sqrtA == 0.515366233826e4 and e.M0 == -0.106626835218 and e.TGD == 0.512227416039e-8
    assert nav2.iono.alpha == (0.1490e-07, 0.7451e-08, -0.1192e-06, -0.5960e-07)
    assert nav2.iono.beta == (0.1065e+06, 0.3277e+05, -0.2621e+06, -0.6554e+05)
    assert sum(x.health != 0 for x in nav2.ephemerides) == 13     # all of them G10's, 63
    assert {(x.prn, x.health) for x in nav2.ephemerides if x.health} == {(10, 63)}


def test_rinex3_file_content(nav3):
    assert nav3.version == 3.02 and [x.prn for x in nav3.ephemerides] == [5, 6]
    e = nav3.ephemerides[0]
    assert (e.week, e.toe, e.toc, e.IODE) == (2106, 86400.0, 86400.0, 21)
    assert e.af0 == -0.128676183522e-04 and e.Crc == 0.288281250000e+03


def test_rinex_values_lie_on_the_lnav_grid(nav2, nav3):
    # The files carry the broadcast integers times the scale factors of Tables 20-I/20-III
    # (angles converted to radians), printed with 12 digits by converters of finite
    # precision (brdc2800's deltaN is off by up to 6e-4 count, relative 5e-8). Every value
    # lies within 0.01 count of its grid, where a wrong scale factor (a grid too coarse by 2)
    # or pi would put half the values half a count off; and the integers fit their bits
    # (quantised() would raise), which catches a grid too fine.
    for e in nav2.ephemerides + nav3.ephemerides:
        for name, f in EPHEMERIS_FIELDS.items():
            x = getattr(e, name) / f.lsb
            assert abs(x - round(x)) <= 0.01, (e.prn, name, x)
        e.quantised()
    top = max(abs(e.M0) for e in nav2.ephemerides) / EPHEMERIS_FIELDS["M0"].lsb
    assert 2 ** 30 < top < 2 ** 31          # M0 spans the 32-bit field: the grid is not too fine


def test_unreadable_file_is_named(tmp_path):
    bad = tmp_path / "junk.15n"
    bad.write_text("hello\nworld\n")
    with pytest.raises(ValueError, match=r"RINEX navigation file .*junk\.15n: georinex cannot "
                                         r"parse it as RINEX 2/3 GPS navigation data"):
        read_rinex_nav(bad)
    with pytest.raises(FileNotFoundError, match=r"RINEX navigation file .*nothere\.15n: no such"):
        read_rinex_nav(tmp_path / "nothere.15n")


def test_ura_index_from_nominal_value():
    assert [ura_index(v) for v in (2.0, 2.8, 4.0, 5.7, 8.0, 11.3, 16.0, 32.0, 6144.0)] == \
        [0, 1, 2, 3, 4, 5, 6, 7, 15]


def test_selection_picks_the_nearest_healthy_toe(nav2):
    sel = nav2.select(1865, 259200.0 + 3 * 3600 + 100)
    for prn, e in sel.items():
        assert e.health == 0 and e.valid_at(1865, 259200.0 + 3 * 3600 + 100)
        others = [x for x in nav2.ephemerides if x.prn == prn and x.health == 0
                  and x.valid_at(1865, 259200.0 + 3 * 3600 + 100)]
        assert all(abs(e.toe - 270100.0) <= abs(x.toe - 270100.0) for x in others)
    assert 20 <= len(sel) <= 32
    assert nav2.select(1865, 0.0) == {}          # a day earlier: nothing covers it


def _navdata(ephs):
    nd = glp_navdata.NavData()
    cols = {"gnss_id": np.array(["gps"] * len(ephs)), "sv_id": [e.prn for e in ephs],
            "gps_week": [e.week for e in ephs], "t_oe": [e.toe for e in ephs],
            "t_oc": [e.toc for e in ephs], "e": [e.e for e in ephs],
            "omega": [e.omega for e in ephs], "Omega_0": [e.Omega0 for e in ephs],
            "OmegaDot": [e.OmegaDot for e in ephs], "sqrtA": [e.sqrtA for e in ephs],
            "deltaN": [e.deltaN for e in ephs], "IDOT": [e.IDOT for e in ephs],
            "i_0": [e.i0 for e in ephs], "C_is": [e.Cis for e in ephs],
            "C_ic": [e.Cic for e in ephs], "C_rs": [e.Crs for e in ephs],
            "C_rc": [e.Crc for e in ephs], "C_uc": [e.Cuc for e in ephs],
            "C_us": [e.Cus for e in ephs], "M_0": [e.M0 for e in ephs],
            "SVclockBias": [e.af0 for e in ephs], "SVclockDrift": [e.af1 for e in ephs],
            "SVclockDriftRate": [e.af2 for e in ephs], "TGD": [e.TGD for e in ephs]}
    for k, v in cols.items():
        nd[k] = np.asarray(v)
    return nd


def _glp_states(ephs, dt):
    """gnss-lib-py's states of each ephemeris at toe + dt. It takes one time for all the
    columns of a call: one call per (week, toe) group, in integer milliseconds so its time
    is exact."""
    nd = _navdata(ephs)
    pos, vel, clk = np.zeros((len(ephs), 3)), np.zeros((len(ephs), 3)), np.zeros(len(ephs))
    keys = np.array([e.week * E.WEEK_S + e.toe for e in ephs])
    for k in np.unique(keys):
        cols = np.flatnonzero(keys == k)
        r = glp_sv.find_sv_states(int(round((k + dt) * 1000)), nd.copy(cols=cols))
        pos[cols] = np.stack([np.ravel(r[c]) for c in ("x_sv_m", "y_sv_m", "z_sv_m")], axis=1)
        vel[cols] = np.stack([np.ravel(r[c]) for c in ("vx_sv_mps", "vy_sv_mps", "vz_sv_mps")],
                             axis=1)
        clk[cols] = np.ravel(r["b_sv_m"]) / E.C_LIGHT
    return pos, vel, clk


DTS = (0.0, 1234.0, -3600.0, 7199.0)


@pytest.mark.parametrize("dt", DTS)
def test_against_gnss_lib_py_exact_part(nav2, nav3, dt):
    # gnss-lib-py evaluates the second-harmonic corrections at an argument of latitude it
    # iterates (phi = phi0 + Cuc cos 2phi + Cus sin 2phi, five passes); IS-GPS-200 Table 20-IV
    # evaluates them at the uncorrected Phi_k. With Cuc = Cus = 0 both are the same equations:
    # every other term (Crs, Crc, Cis, Cic, IDOT, OmegaDot, deltaN, Kepler) is compared to 1 mm.
    ephs = [replace(e, Cuc=0.0, Cus=0.0) for e in nav2.ephemerides + nav3.ephemerides]
    p_ref, v_ref, _ = _glp_states(ephs, dt)
    tow = np.array([e.toe for e in ephs]) + dt
    st = E.satellite_states(ephs, tow)
    assert np.abs(st.position - p_ref).max() < 1e-3
    assert np.abs(st.velocity - v_ref).max() < 1e-6


@pytest.mark.parametrize("dt", DTS)
def test_against_gnss_lib_py_full(nav2, nav3, dt):
    ephs = list(nav2.ephemerides + nav3.ephemerides)
    p_ref, v_ref, c_ref = _glp_states(ephs, dt)
    tow = np.array([e.toe for e in ephs]) + dt
    st = E.satellite_states(ephs, tow)
    # Clock: polynomial, relativistic term and TGD, the same equations: 1e-12 s.
    assert np.abs(st.clock_bias - c_ref).max() < 1e-12
    # Position: the one difference is gnss-lib-py's iterated argument of latitude. To first
    # order its harmonic terms are taken at phi0 + du instead of phi0 (du = the u correction),
    # which moves the position by at most 2 |du| (r |C_u| + |C_r| + r |C_i|) with C_x the
    # larger of each sine/cosine pair: the residual must lie inside that bound.
    p = {k: np.array([getattr(e, k) for e in ephs]) for k in
         ("Cuc", "Cus", "Crc", "Crs", "Cic", "Cis", "sqrtA")}
    r = p["sqrtA"] ** 2
    du = np.hypot(p["Cuc"], p["Cus"])
    bound = 2 * du * (r * du + np.hypot(p["Crc"], p["Crs"]) + r * np.hypot(p["Cic"], p["Cis"]))
    res = np.linalg.norm(st.position - p_ref, axis=1)
    assert np.all(res <= 1.05 * bound + 1e-6), (res / bound).max()
    assert res.max() > 1e-3      # the iteration does show at the mm level on real orbits


def test_velocity_is_the_derivative_of_position(nav2):
    ephs = list(nav2.ephemerides[::7])
    t = np.array([e.toe for e in ephs]) + 1000.0
    h = 0.5
    pp, _ = E.satellite_position_velocity(ephs, t + h)
    pm, _ = E.satellite_position_velocity(ephs, t - h)
    _, v = E.satellite_position_velocity(ephs, t)
    # central difference: error h^2/6 |d3r/dt3| < 0.25/6 * 1e-3 m/s^3 (GPS orbits)
    assert np.abs((pp - pm) / (2 * h) - v).max() < 1e-4
    bp, _ = E.satellite_clock(ephs, t + h)
    bm, _ = E.satellite_clock(ephs, t - h)
    _, d = E.satellite_clock(ephs, t)
    assert np.abs((bp - bm) / (2 * h) - d).max() < 1e-17


def test_week_crossover():
    e0 = read_rinex_nav(RINEX3).ephemerides[0]
    e = replace(e0, toe=597600.0, toc=597600.0)       # toe 2 h before the week's end
    # 1 h after the week turns: tow 3600 of the next week is tk = +10800 s, not -594000 s.
    a = E.satellite_states(e, 3600.0)
    b = E.satellite_states(e, 597600.0 + 10800.0)
    np.testing.assert_array_equal(a.position, b.position)
    assert a.clock_bias == b.clock_bias
    np.testing.assert_allclose(E.fold_time([302399.0, 302400.0, -302400.0, -302401.0, 604800.0]),
                               [302399.0, -302400.0, -302400.0, 302399.0, 0.0])


def test_vectorised_shapes_and_consistency(nav2):
    ephs = list(nav2.ephemerides[:5])
    t = ephs[0].toe + np.array([0.0, 60.0, 120.0])
    pos, vel = E.satellite_position_velocity(ephs, t[:, None])
    assert pos.shape == vel.shape == (3, 5, 3)
    for j, e in enumerate(ephs):
        for i, ti in enumerate(t):
            p1, _ = E.satellite_position_velocity(e, ti)
            np.testing.assert_array_equal(p1, pos[i, j])


def test_clock_terms_and_system_time(nav2):
    e = nav2.ephemerides[3]
    t = e.toc + 500.0
    st = E.satellite_states(e, t)
    poly = e.af0 + e.af1 * 500.0 + e.af2 * 500.0 ** 2
    assert st.clock_bias == pytest.approx(poly + st.relativistic - e.TGD, abs=1e-20)
    assert 0 < abs(st.relativistic) < 2.3e-8 * e.e / 0.01 + 1e-12   # |F e sqrtA| bound
    b_dual, _ = E.satellite_clock(e, t, l1_ca=False)
    assert b_dual - st.clock_bias == pytest.approx(e.TGD, abs=1e-20)
    # t_sv = t + dtsv(t) inverts to t.
    t_sv = t + E.satellite_clock(e, t)[0]
    assert abs(E.system_time(e, t_sv) - t) < 1e-12


def test_sagnac_rotation_against_pymap3d(nav2):
    ephs = list(nav2.ephemerides[:32])
    pos, vel = E.satellite_position_velocity(ephs, np.array([e.toe for e in ephs]))
    tau = 0.070
    rot, vrot = E.sagnac_rotate(pos, tau, vel)
    d = np.linalg.norm(rot - pos, axis=1)
    rho = np.hypot(pos[:, 0], pos[:, 1])
    np.testing.assert_allclose(d, 2 * rho * np.sin(E.OMEGA_E_DOT * tau / 2), atol=1e-7)
    assert 5.0 < d.min() and d.max() < 140.0            # tens of metres at 70 ms
    # In the reception-time frame the satellite's longitude is OmegaE tau smaller, its
    # latitude and height unchanged (pymap3d's geodetic conversion).
    lat0, lon0, h0 = pymap3d.ecef2geodetic(pos[:, 0], pos[:, 1], pos[:, 2])
    lat1, lon1, h1 = pymap3d.ecef2geodetic(rot[:, 0], rot[:, 1], rot[:, 2])
    dlon = (np.asarray(lon1) - np.asarray(lon0) + 180) % 360 - 180
    np.testing.assert_allclose(dlon, -np.degrees(E.OMEGA_E_DOT * tau), atol=1e-9)
    np.testing.assert_allclose(lat1, lat0, atol=1e-9)
    np.testing.assert_allclose(h1, h0, atol=1e-4)
    np.testing.assert_allclose(np.linalg.norm(vrot, axis=1), np.linalg.norm(vel, axis=1),
                               rtol=1e-14)
    with pytest.raises(ValueError, match=r"sagnac_rotate: position of shape \(4,\)"):
        E.sagnac_rotate(np.zeros(4), tau)


def test_bad_ephemeris_is_named(nav3):
    e = nav3.ephemerides[0]
    with pytest.raises(ValueError, match=r"Ephemeris\(prn=5\): e = 1.5 is not an eccentricity"):
        replace(e, e=1.5)
    with pytest.raises(ValueError, match=r"Ephemeris\(prn=5\): IODE = 256 is not an unsigned "
                                         r"8-bit integer"):
        replace(e, IODE=256)
    with pytest.raises(ValueError, match=r"Ephemeris: prn = 33 is not a GPS PRN"):
        replace(e, prn=33)
    with pytest.raises(ValueError, match=r"Ephemeris\(prn=5\): M0 = nan is not a finite"):
        replace(e, M0=float("nan"))


def test_nominal_constellation_matches_its_slots():
    week, toe = divmod(EPOCH_GPS_S, E.WEEK_S)
    # The node's regression (OmegaDot) tilts the osculating plane by OmegaDot / n ~ 3e-3
    # degree; without it the orbit elements read back exactly.
    consts = [replace(c, OmegaDot=0.0) for c in nominal_constellation(int(week), toe)]
    assert [c.prn for c in consts] == list(range(1, 25))
    pos, vel = E.satellite_position_velocity(consts, toe)
    np.testing.assert_allclose(np.linalg.norm(pos, axis=1), 26_559_700.0, rtol=1e-13)
    # Back to the inertial frame of the epoch: turn by the Greenwich hour angle, add w x r.
    g = np.radians(EPOCH_GHA_DEG)
    R = np.array([[np.cos(g), -np.sin(g), 0], [np.sin(g), np.cos(g), 0], [0, 0, 1]])
    r_i = pos @ R.T
    v_i = (vel + np.cross([0, 0, E.OMEGA_E_DOT], pos)) @ R.T
    h = np.cross(r_i, v_i)
    incl = np.degrees(np.arccos(h[:, 2] / np.linalg.norm(h, axis=1)))
    raan = np.degrees(np.arctan2(h[:, 0], -h[:, 1])) % 360
    node = np.stack([np.cos(np.radians(raan)), np.sin(np.radians(raan)), 0 * raan], axis=1)
    u = np.degrees(np.arctan2(np.einsum("ij,ij->i", np.cross(node, r_i), h)
                              / np.linalg.norm(h, axis=1), np.einsum("ij,ij->i", node, r_i)))
    want = np.array([SLOTS[n] for n in SLOT_NAMES])
    np.testing.assert_allclose(incl, 55.0, atol=1e-9)
    np.testing.assert_allclose((raan - want[:, 0] + 180) % 360 - 180, 0, atol=1e-9)
    np.testing.assert_allclose((u - want[:, 1] + 180) % 360 - 180, 0, atol=1e-9)
    assert nodal_rate() == pytest.approx(np.radians(-4.4874e-7), rel=1e-3)   # SPS PS A-2-1


def test_nominal_constellation_covers_the_earth():
    # At least 4 satellites above 5 degrees everywhere (the 24-slot design), at a few times.
    rng = np.random.default_rng(7)
    consts = [c.quantised() for c in nominal_constellation(2300, 345600.0)]
    for t in 345600.0 + np.array([0.0, 3000.0, 20000.0]):
        pos, _ = E.satellite_position_velocity(consts, t)
        for lat, lon in zip(rng.uniform(-90, 90, 40), rng.uniform(-180, 180, 40)):
            _, el, _ = pymap3d.ecef2aer(pos[:, 0], pos[:, 1], pos[:, 2], lat, lon, 0.0)
            assert np.sum(np.asarray(el) > 5.0) >= 4
    with pytest.raises(ValueError, match=r"toe = 345601.0 is not a multiple of 16 s"):
        nominal_constellation(2300, 345601.0)
