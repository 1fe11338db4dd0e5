"""NMEA GGA / RMC of PVT solutions (cosim.gnss.nmea), parsed back with pynmea2: the
position, time, speed and course to the sentences' resolution; no fix gives quality 0 and
empty position fields."""
from __future__ import annotations

import datetime as dt

import numpy as np
import pymap3d
import pynmea2
import pytest

from cosim.gnss import nmea
from dsp.gnss import observables as ob
from dsp.gnss import pvt

AZ = np.array([10.0, 55.0, 100.0, 150.0, 200.0, 250.0, 300.0, 340.0])
EL = np.array([75.0, 20.0, 45.0, 15.0, 60.0, 30.0, 25.0, 40.0])
PRN = np.arange(1, 9)
WEEK, TOW = 2400, 302_417.987654          # Wednesday 2026-01-07 12:00:17.99 GPS
LEAP = 18
RES_DEG = 1e-5 / 60.0                     # the position fields' resolution


def fix(lat, lon, h, v_enu=(12.0, -5.0, 0.2), n=8, b_m=3_000.0):
    pos, vel = ob.sky_geometry(lat, lon, h, AZ[:n], EL[:n])
    r = np.array(pymap3d.geodetic2ecef(lat, lon, h))
    v = np.array(pymap3d.enu2uvw(*v_enu, lat, lon))
    clk, drift = np.zeros(n), np.zeros(n)
    pr, tau = ob.predict_pseudoranges(r, b_m, pos, clk)
    rate = ob.predict_range_rates(r, v, 0.0, pos, vel, drift, tau)
    return pvt.solve(PRN[:n], pos, clk, pr, sat_vel_mps=vel, sat_clock_drift=drift,
                     pseudorange_rate_mps=rate, gps_week=WEEK,
                     gps_tow_s=TOW + b_m / pvt.C_LIGHT)


@pytest.mark.parametrize("lat, lon, h", [(48.15, 11.58, 520.0), (-33.8688, 151.2093, 58.0),
                                         (40.4168, -3.7038, 667.0),
                                         (-12.0464, -77.0428, 154.0)])
def test_gga_and_rmc_give_back_the_fix(lat, lon, h):
    sol = fix(lat, lon, h)
    assert sol.valid
    g_text, r_text = nmea.sentences(sol, leap_seconds=LEAP, geoid_separation_m=47.25)
    g = pynmea2.parse(g_text, check=True)
    assert g_text.startswith("$GPGGA,") and len(g_text) <= 82
    assert abs(g.latitude - sol.lat_deg) <= RES_DEG / 2 + 1e-12
    assert abs(g.longitude - sol.lon_deg) <= RES_DEG / 2 + 1e-12
    assert abs(g.latitude - lat) < RES_DEG and abs(g.longitude - lon) < RES_DEG
    assert g.gps_qual == 1 and int(g.num_sats) == 8
    assert float(g.horizontal_dil) == pytest.approx(sol.dop.hdop, abs=0.005)
    assert g.altitude + float(g.geo_sep) == pytest.approx(h, abs=1e-3)
    assert float(g.geo_sep) == 47.25 and g.altitude_units == "M"
    utc = dt.datetime(2026, 1, 7, 12, 0, 17, 987654) - dt.timedelta(seconds=LEAP)
    assert g.timestamp == dt.time(11, 59, 59, 990000, tzinfo=dt.timezone.utc)
    r = pynmea2.parse(r_text, check=True)
    assert r.status == "A" and r.mode_indicator == "A"
    assert r.datestamp == utc.date()
    assert r.timestamp == g.timestamp
    assert abs(r.latitude - g.latitude) < 1e-15 and abs(r.longitude - g.longitude) < 1e-15
    assert r.spd_over_grnd == pytest.approx(13.0 * 3600 / 1852, abs=0.0005)
    assert r.true_course == pytest.approx(np.degrees(np.arctan2(12.0, -5.0)) % 360, abs=0.005)


def test_no_fix_gives_quality_zero_and_no_position():
    sol = fix(48.15, 11.58, 520.0, n=3)
    assert sol.status is pvt.PvtStatus.NO_FIX_TOO_FEW
    g = pynmea2.parse(nmea.gga(sol, leap_seconds=LEAP), check=True)
    assert g.gps_qual == 0 and g.lat == "" and g.lon == "" and g.altitude is None
    assert g.horizontal_dil == ""
    r = pynmea2.parse(nmea.rmc(sol, leap_seconds=LEAP), check=True)
    assert r.status == "V" and r.lat == "" and r.mode_indicator == "N"


def test_a_detected_fault_is_not_a_fix():
    pos, _ = ob.sky_geometry(48.15, 11.58, 520.0, AZ[:5], EL[:5])
    r = np.array(pymap3d.geodetic2ecef(48.15, 11.58, 520.0))
    pr, _ = ob.predict_pseudoranges(r, 0.0, pos, np.zeros(5))
    pr[2] += 300.0
    sol = pvt.solve(PRN[:5], pos, np.zeros(5), pr, gps_week=WEEK, gps_tow_s=TOW)
    assert sol.status is pvt.PvtStatus.FAULT_DETECTED
    assert pynmea2.parse(nmea.gga(sol, leap_seconds=LEAP)).gps_qual == 0


def test_rounding_carries_into_degrees_and_the_hemispheres():
    lat = 10.0 - 1e-9                     # 9 deg 59.99999994' rounds to 10 deg 00.00000'
    sol = fix(lat, -0.5, 10.0)
    g = pynmea2.parse(nmea.gga(sol, leap_seconds=LEAP), check=True)
    assert g.lat == "1000.00000" and g.lat_dir == "N"
    assert g.lon_dir == "W" and g.longitude == pytest.approx(-0.5, abs=RES_DEG)


def test_without_velocity_speed_and_course_are_empty():
    pos, _ = ob.sky_geometry(48.15, 11.58, 520.0, AZ, EL)
    r = np.array(pymap3d.geodetic2ecef(48.15, 11.58, 520.0))
    pr, _ = ob.predict_pseudoranges(r, 0.0, pos, np.zeros(8))
    sol = pvt.solve(PRN, pos, np.zeros(8), pr, gps_week=WEEK, gps_tow_s=TOW)
    r = pynmea2.parse(nmea.rmc(sol, leap_seconds=LEAP), check=True)
    assert r.status == "A" and r.spd_over_grnd is None and r.true_course is None


def test_bad_input_raises():
    sol = fix(48.15, 11.58, 520.0)
    with pytest.raises(ValueError, match="leap_seconds"):
        nmea.gga(sol, leap_seconds=-1)
    pos, _ = ob.sky_geometry(48.15, 11.58, 520.0, AZ, EL)
    r = np.array(pymap3d.geodetic2ecef(48.15, 11.58, 520.0))
    pr, _ = ob.predict_pseudoranges(r, 0.0, pos, np.zeros(8))
    untimed = pvt.solve(PRN, pos, np.zeros(8), pr)           # no gps_week / gps_tow_s
    with pytest.raises(ValueError, match="week"):
        nmea.gga(untimed, leap_seconds=LEAP)


def test_a_fix_time_before_the_week_start_is_in_the_previous_week():
    """Receiver time 1 ms into the week with a 2 ms clock bias: the fix is 1 ms before the
    week's start, Saturday 23:59:59.999 GPS (rounded to .00 of the next second, 18 s
    earlier in UTC)."""
    b = 2e-3 * pvt.C_LIGHT
    pos, _ = ob.sky_geometry(48.15, 11.58, 520.0, AZ, EL)
    r = np.array(pymap3d.geodetic2ecef(48.15, 11.58, 520.0))
    pr, _ = ob.predict_pseudoranges(r, b, pos, np.zeros(8))
    sol = pvt.solve(PRN, pos, np.zeros(8), pr, gps_week=WEEK, gps_tow_s=1e-3)
    assert sol.gps_tow_s == pytest.approx(-1e-3, abs=1e-9)
    r_msg = pynmea2.parse(nmea.rmc(sol, leap_seconds=LEAP), check=True)
    assert r_msg.datestamp == dt.date(2026, 1, 3)
    assert r_msg.timestamp == dt.time(23, 59, 42, 0, tzinfo=dt.timezone.utc)
