"""NMEA 0183 GGA and RMC sentences of a PVT solution (``dsp.gnss.pvt.PvtSolution``).

The sentences are built and checksummed by pynmea2; this module fills their fields:

* time: UTC, from the fix's GPS week / time of week minus ``leap_seconds`` (GPS - UTC, 18 s
  since 2017-01-01; the LNAV message carries it in subframe 4 page 18), ``hhmmss.ss``;
  RMC's date ``ddmmyy``;
* latitude ``ddmm.mmmmm`` and longitude ``dddmm.mmmmm`` (1e-5 arc minute: 1.9 cm), rounded
  once in integer units of that resolution, hemisphere letters;
* GGA: quality 1 (GPS SPS fix) for a valid solution (``PvtSolution.valid``), 0 otherwise
  with the position, HDOP and altitude fields **empty** (no position is made up); the
  number of satellites used; HDOP (2 decimals); altitude above mean sea level and the
  geoid separation (3 decimals, metres): ``altitude = h - N``, ``separation = N`` with
  ``N`` = ``geoid_separation_m`` (no geoid model is built in: the default 0 makes the
  altitude field the ellipsoidal height, and ``altitude + separation = h`` always holds);
* RMC: status ``A`` / ``V``, speed over ground (knots, 3 decimals) and true course
  (degrees from north, 2 decimals) from the east-north velocity (empty without a velocity
  or below 1 mm/s for the course), mode indicator ``A`` (autonomous) / ``N`` (not valid).

A sentence longer than NMEA's 82 characters raises.
"""
from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pynmea2

from dsp.gnss.observables import gps_datetime
from dsp.gnss.pvt import PvtSolution

#: Knots per m/s; the angular resolution of the position fields (arc minutes).
KNOTS_PER_MPS = 3600.0 / 1852.0
MINUTE_DECIMALS = 5
MAX_SENTENCE = 82


def _angle(value_deg: float, deg_digits: int, hemis: str) -> tuple[str, str]:
    scale = 10 ** MINUTE_DECIMALS
    units = round(abs(value_deg) * 60.0 * scale)            # 1e-5 arc minutes
    deg, rest = divmod(units, 60 * scale)
    minutes, frac = divmod(rest, scale)
    text = f"{deg:0{deg_digits}d}{minutes:02d}.{frac:0{MINUTE_DECIMALS}d}"
    return text, hemis[0] if value_deg >= 0 else hemis[1]


def _utc(sol: PvtSolution, leap_seconds: int) -> dt.datetime:
    if isinstance(leap_seconds, bool) or not isinstance(leap_seconds, (int, np.integer)) \
            or leap_seconds < 0:
        raise ValueError(f"leap_seconds (GPS - UTC) must be a non-negative integer, "
                         f"not {leap_seconds!r}")
    if sol.gps_week is None or sol.gps_tow_s is None:
        raise ValueError("an NMEA sentence needs the solution's GPS week and time of week")
    weeks, tow = divmod(float(sol.gps_tow_s), 604_800.0)  # the clock bias may cross a week
    t = gps_datetime(sol.gps_week + int(weeks), tow)
    t -= dt.timedelta(seconds=int(leap_seconds))
    cs = round(t.microsecond / 1e4)                        # to the hundredth of a second
    return t.replace(microsecond=0) + dt.timedelta(milliseconds=10 * cs)


def _hhmmss(t: dt.datetime) -> str:
    return f"{t:%H%M%S}.{t.microsecond // 10_000:02d}"


def _render(msg) -> str:
    s = msg.render(checksum=True, dollar=True, newline=False)
    if len(s) > MAX_SENTENCE:
        raise ValueError(f"NMEA sentence longer than {MAX_SENTENCE} characters: {s!r}")
    return s


def gga(sol: PvtSolution, *, leap_seconds: int, geoid_separation_m: float = 0.0,
        talker: str = "GP") -> str:
    """The GGA sentence of ``sol`` (module doc)."""
    t = _utc(sol, leap_seconds)
    if not np.isfinite(geoid_separation_m):
        raise ValueError(f"geoid_separation_m must be finite, not {geoid_separation_m!r}")
    if sol.valid:
        lat, ns = _angle(sol.lat_deg, 2, "NS")
        lon, ew = _angle(sol.lon_deg, 3, "EW")
        hdop = f"{sol.dop.hdop:.2f}" if np.isfinite(sol.dop.hdop) else ""
        fields = (_hhmmss(t), lat, ns, lon, ew, "1", f"{len(sol.used_prns):02d}", hdop,
                  f"{sol.height_m - geoid_separation_m:.3f}", "M",
                  f"{geoid_separation_m:.3f}", "M", "", "")
    else:
        fields = (_hhmmss(t), "", "", "", "", "0", f"{len(sol.used_prns):02d}", "", "", "",
                  "", "", "", "")
    return _render(pynmea2.GGA(talker, "GGA", fields))


def rmc(sol: PvtSolution, *, leap_seconds: int, talker: str = "GP") -> str:
    """The RMC sentence of ``sol`` (module doc)."""
    t = _utc(sol, leap_seconds)
    date = f"{t:%d%m%y}"
    if not sol.valid:
        fields = (_hhmmss(t), "V", "", "", "", "", "", "", date, "", "", "N")
        return _render(pynmea2.RMC(talker, "RMC", fields))
    lat, ns = _angle(sol.lat_deg, 2, "NS")
    lon, ew = _angle(sol.lon_deg, 3, "EW")
    east, north = float(sol.velocity_enu_mps[0]), float(sol.velocity_enu_mps[1])
    speed = course = ""
    if np.isfinite(east) and np.isfinite(north):
        ground = math.hypot(east, north)
        speed = f"{ground * KNOTS_PER_MPS:.3f}"
        if ground >= 1e-3:
            course = f"{math.degrees(math.atan2(east, north)) % 360.0:.2f}"
            course = "0.00" if course == "360.00" else course
    fields = (_hhmmss(t), "A", lat, ns, lon, ew, speed, course, date, "", "", "A")
    return _render(pynmea2.RMC(talker, "RMC", fields))


def sentences(sol: PvtSolution, *, leap_seconds: int, geoid_separation_m: float = 0.0,
              talker: str = "GP") -> list[str]:
    """GGA then RMC for one fix."""
    return [gga(sol, leap_seconds=leap_seconds, geoid_separation_m=geoid_separation_m,
                talker=talker), rmc(sol, leap_seconds=leap_seconds, talker=talker)]
