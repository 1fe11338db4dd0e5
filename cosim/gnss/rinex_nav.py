"""GPS broadcast ephemerides from a RINEX navigation file (RINEX 2 and 3), read with georinex.

The file is parsed by georinex (``georinex.load``); this module turns its GPS records into
:class:`dsp.gnss.ephemeris.Ephemeris` objects and the header's GPS ionosphere coefficients
(RINEX 2 ``ION ALPHA`` / ``ION BETA``, RINEX 3 ``IONOSPHERIC CORR GPSA`` / ``GPSB``) into
:class:`dsp.gnss.ephemeris.KlobucharParameters`. It lives in ``cosim`` beside the other file
formats (sample files, RINEX observations, NMEA): file I/O and georinex's xarray/pandas stack stay
out of ``dsp``, whose models take the parsed ``Ephemeris`` objects.

Mapping (RINEX 2.11 / 3.0x GPS navigation message record -> IS-GPS-200 parameter)
--------------------------------------------------------------------------------
* the record's epoch (GPS time) is toc, as seconds of its GPS week;
* ``GPS Week`` (continuous, not modulo 1024) is the week of toe;
* ``SV accuracy`` (metres) -> URA index N: the smallest N whose nominal URA (IS-GPS-200
  20.3.3.3.1.3: 2, 2.8, 4, 5.7, 8, 11.3, 16, 32, ..., 4096 m; 6144 m for N = 15) is at least
  the value, which gives back the index from the nominal value a RINEX writer stores;
* ``Fit interval`` (hours; 0 when not known, absent in some RINEX 3 files) -> the fit interval
  flag: 0 for 0..4 h, 1 above;
* angles are radians in both RINEX and :class:`Ephemeris`; ``health``, ``IODE``, ``IODC``,
  ``codes on L2``, ``L2 P data flag`` are the broadcast integers.

A file that georinex cannot parse, that is not a navigation file, or that holds no GPS record
raises a ``ValueError`` naming the file, before any ephemeris is built.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dsp.gnss.ephemeris import WEEK_S, Ephemeris, KlobucharParameters, select_ephemeris

#: Nominal URA (m) of each index N, IS-GPS-200 20.3.3.3.1.3.
URA_NOMINAL_M = (2.0, 2.8, 4.0, 5.7, 8.0, 11.3, 16.0, 32.0, 64.0, 128.0, 256.0, 512.0,
                 1024.0, 2048.0, 4096.0, 6144.0)

_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")

#: RINEX (georinex variable) -> Ephemeris field, for the float parameters.
_FLOAT_MAP = {"SVclockBias": "af0", "SVclockDrift": "af1", "SVclockDriftRate": "af2",
              "Crs": "Crs", "DeltaN": "deltaN", "M0": "M0", "Cuc": "Cuc", "Eccentricity": "e",
              "Cus": "Cus", "sqrtA": "sqrtA", "Toe": "toe", "Cic": "Cic", "Omega0": "Omega0",
              "Cis": "Cis", "Io": "i0", "Crc": "Crc", "omega": "omega", "OmegaDot": "OmegaDot",
              "IDOT": "IDOT", "TGD": "TGD"}
_INT_MAP = {"IODE": "IODE", "IODC": "IODC", "health": "health", "CodesL2": "l2_codes",
            "L2Pflag": "l2p_flag"}


@dataclass(frozen=True)
class RinexNav:
    """The GPS content of one RINEX navigation file: its ephemerides (file order: by epoch,
    then PRN), the GPS Klobuchar coefficients of the header (``None`` if absent) and the
    RINEX version."""

    path: Path
    version: float
    ephemerides: tuple
    iono: KlobucharParameters | None

    def prns(self) -> list[int]:
        """The PRNs with at least one ephemeris."""
        return sorted({e.prn for e in self.ephemerides})

    def select(self, week: int, tow: float, *, healthy_only: bool = True) -> dict:
        """PRN -> the ephemeris to use at GPS time (``week``, ``tow``)
        (:func:`dsp.gnss.ephemeris.select_ephemeris`); PRNs without a valid one are left out."""
        out = {}
        for prn in self.prns():
            e = select_ephemeris(self.ephemerides, prn, week, tow, healthy_only=healthy_only)
            if e is not None:
                out[prn] = e
        return out


def ura_index(accuracy_m: float) -> int:
    """URA index N of an SV accuracy in metres (the smallest N whose nominal value covers it)."""
    for n, v in enumerate(URA_NOMINAL_M):
        if accuracy_m <= v * (1 + 1e-9):
            return n
    return 15


def gps_week_tow(t: np.datetime64) -> tuple[int, float]:
    """GPS week and seconds of week of a GPS-time ``datetime64``."""
    ns = int((np.datetime64(t, "ns") - _GPS_EPOCH) / np.timedelta64(1, "ns"))
    week, rem = divmod(ns, int(WEEK_S) * 1_000_000_000)
    return int(week), rem / 1e9


def read_rinex_nav(path) -> RinexNav:
    """The GPS ephemerides and ionosphere coefficients of the RINEX 2 or 3 navigation file
    ``path`` (see the module notes for the mapping)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"RINEX navigation file {path}: no such file")
    import georinex  # imported here: the xarray/pandas stack loads only when a file is read
    try:
        nav = georinex.load(path, use="G")
    except Exception as exc:  # georinex raises many types for a malformed file
        raise ValueError(f"RINEX navigation file {path}: georinex cannot parse it as RINEX 2/3 "
                         f"GPS navigation data ({type(exc).__name__}: {exc})") from exc
    if nav is None or nav.attrs.get("rinextype") != "nav":
        raise ValueError(f"RINEX navigation file {path}: not a navigation file "
                         f"(RINEX type {getattr(nav, 'attrs', {}).get('rinextype')!r})")
    svs = [str(s) for s in nav.sv.values if str(s).startswith("G")]
    if not svs:
        raise ValueError(f"RINEX navigation file {path}: no GPS ephemeris record")
    ephs = []
    for t in nav.time.values:
        week_c, toc = gps_week_tow(t)
        for sv in svs:
            rec = nav.sel(time=t, sv=sv)
            if math.isnan(float(rec["sqrtA"])):
                continue  # no record of this satellite at this epoch
            ephs.append(_ephemeris(rec, int(sv[1:3]), toc, path))
    iono = None
    coeffs = nav.attrs.get("ionospheric_corr_GPS")
    if coeffs is not None and len(coeffs) == 8:
        iono = KlobucharParameters(tuple(coeffs[:4]), tuple(coeffs[4:]))
    return RinexNav(path, float(nav.attrs.get("version", math.nan)), tuple(ephs), iono)


def _ephemeris(rec, prn: int, toc: float, path: Path) -> Ephemeris:
    kw = {dst: float(rec[src]) for src, dst in _FLOAT_MAP.items()}
    for src, dst in _INT_MAP.items():
        v = float(rec[src]) if src in rec else 0.0
        kw[dst] = int(v) if math.isfinite(v) else 0
    fit = float(rec["FitIntvl"]) if "FitIntvl" in rec else 0.0
    kw["fit_interval_flag"] = 1 if math.isfinite(fit) and fit > 4.0 else 0
    kw["ura_index"] = ura_index(float(rec["SVacc"]))
    try:
        return Ephemeris(prn=prn, week=int(float(rec["GPSWeek"])), toc=toc, **kw)
    except ValueError as exc:
        raise ValueError(f"RINEX navigation file {path}: G{prn:02d} record at toc {toc:.0f} s: "
                         f"{exc}") from exc
