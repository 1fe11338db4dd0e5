"""RINEX 3.04 observation files of the GPS L1 C/A observables (``dsp.gnss.observables``).

One satellite system (``G``), four observation types ``C1C L1C D1C S1C`` (pseudorange m,
carrier phase cycles, Doppler Hz, C/N0 dB-Hz). The layout follows the RINEX 3.04
specification (IGS / RTCM-SC104, 2018), tables A1-A3: header records of 60 columns of data
and their label in columns 61-80; epoch records
``> yyyy mm dd hh mm ss.sssssss  f nnn      clock-offset`` (``A1,1X,I4,4(1X,I2.2),F11.7,
2X,I1,I3,6X,F15.12``); one line per satellite ``Gnn`` (``A1,I2.2``) followed per type by
the value ``F14.3``, the loss-of-lock indicator ``I1`` and the signal-strength indicator
``I1``. Written:

* LLI on the phase only, blank when 0; the signal-strength indicator (RINEX 3.04 table 12,
  ``min(max(floor(C/N0 / 6), 1), 9)``: 1 below 12 dB-Hz, 5 for 30-35, 9 from 54) on every
  value but S1C itself; a missing value (NaN) and its indicators blank;
* every observation line padded to its full width (trailing blanks are allowed);
* ``SIGNAL STRENGTH UNIT`` ``DBHZ``; ``TIME OF FIRST OBS`` in GPS time; ``RCV CLOCK OFFS
  APPL`` 0 (the receiver clock offset is not applied to the observables; it is written in
  the epoch record when known); ``SYS / PHASE SHIFT`` ``G L1C`` with no correction.

A value that does not fit ``F14.3`` (magnitude >= 1e10) raises instead of writing a
corrupt record.
"""
from __future__ import annotations

import datetime as dt
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dsp.gnss.observables import ObservationEpoch

#: The observation types written, in order.
OBS_TYPES = ("C1C", "L1C", "D1C", "S1C")
RINEX_VERSION = 3.04
_MAX_F14_3 = 1e10 - 0.0005


@dataclass(frozen=True)
class RinexObsHeader:
    """The header's descriptive records. ``created``: the file's creation time (UTC) for
    ``PGM / RUN BY / DATE`` (default: now); ``interval_s``: the nominal epoch interval."""

    marker_name: str = "KFNAV"
    marker_type: str = "NON_GEODETIC"
    observer: str = ""
    agency: str = ""
    receiver_number: str = ""
    receiver_type: str = "KFNAV GPS L1 C/A"
    receiver_version: str = ""
    antenna_number: str = ""
    antenna_type: str = ""
    approx_position_m: tuple = (0.0, 0.0, 0.0)
    antenna_delta_hen_m: tuple = (0.0, 0.0, 0.0)
    interval_s: float | None = None
    program: str = "kfnav"
    run_by: str = ""
    created: dt.datetime | None = None


def signal_strength_indicator(cn0_dbhz: float) -> int:
    """RINEX 3.04 table 12: 1 (< 12 dB-Hz) .. 9 (>= 54 dB-Hz), 6 dB steps."""
    return int(min(max(math.floor(cn0_dbhz / 6.0), 1), 9))


def _line(data: str, label: str) -> str:
    if len(data) > 60:
        raise ValueError(f"header record {label!r} does not fit in 60 columns: {data!r}")
    return f"{data:<60}{label:<20}".rstrip() + "\n"


def _text(value: str, width: int, what: str) -> str:
    if len(value) > width or any(not (32 <= ord(c) < 127) for c in value):
        raise ValueError(f"{what} must be at most {width} printable ASCII characters: {value!r}")
    return f"{value:<{width}}"


def _f14_3(v: float) -> str:
    if not abs(v) <= _MAX_F14_3:
        raise ValueError(f"{v!r} does not fit the RINEX F14.3 field")
    return f"{v:14.3f}"


def header_lines(h: RinexObsHeader, first: dt.datetime) -> list[str]:
    """The header records for a file whose first epoch is ``first`` (GPS time)."""
    created = h.created or dt.datetime.now(dt.timezone.utc).replace(tzinfo=None)
    out = [
        _line(f"{RINEX_VERSION:9.2f}{'':11}{'OBSERVATION DATA':<20}{'G: GPS':<20}",
              "RINEX VERSION / TYPE"),
        _line(_text(h.program, 20, "program") + _text(h.run_by, 20, "run_by")
              + f"{created:%Y%m%d %H%M%S} UTC ", "PGM / RUN BY / DATE"),
        _line(_text(h.marker_name, 60, "marker_name"), "MARKER NAME"),
        _line(_text(h.marker_type, 20, "marker_type"), "MARKER TYPE"),
        _line(_text(h.observer, 20, "observer") + _text(h.agency, 40, "agency"),
              "OBSERVER / AGENCY"),
        _line(_text(h.receiver_number, 20, "receiver_number")
              + _text(h.receiver_type, 20, "receiver_type")
              + _text(h.receiver_version, 20, "receiver_version"), "REC # / TYPE / VERS"),
        _line(_text(h.antenna_number, 20, "antenna_number")
              + _text(h.antenna_type, 20, "antenna_type"), "ANT # / TYPE"),
        _line("".join(f"{v:14.4f}" for v in _triple(h.approx_position_m, "approx_position_m")),
              "APPROX POSITION XYZ"),
        _line("".join(f"{v:14.4f}" for v in _triple(h.antenna_delta_hen_m,
                                                      "antenna_delta_hen_m")),
              "ANTENNA: DELTA H/E/N"),
        _line(f"G  {len(OBS_TYPES):3d}" + "".join(f" {t}" for t in OBS_TYPES),
              "SYS / # / OBS TYPES"),
        _line(f"{'DBHZ':<20}", "SIGNAL STRENGTH UNIT"),
    ]
    if h.interval_s is not None:
        if not (np.isfinite(h.interval_s) and h.interval_s > 0):
            raise ValueError(f"interval_s must be > 0, not {h.interval_s!r}")
        out.append(_line(f"{h.interval_s:10.3f}", "INTERVAL"))
    sec = first.second + first.microsecond / 1e6
    out += [
        _line(f"{first.year:6d}{first.month:6d}{first.day:6d}{first.hour:6d}"
              f"{first.minute:6d}{sec:13.7f}{'':5}GPS", "TIME OF FIRST OBS"),
        _line(f"{0:6d}", "RCV CLOCK OFFS APPL"),
        _line("G L1C  0.00000", "SYS / PHASE SHIFT"),
        _line("", "END OF HEADER"),
    ]
    return out


def _triple(v, name):
    a = np.asarray(v, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(np.abs(a) >= 1e8):
        raise ValueError(f"{name} must be 3 finite values (m) fitting F14.4, not {v!r}")
    return a


def epoch_lines(ep: ObservationEpoch) -> list[str]:
    """The epoch record and one observation record per satellite (module doc)."""
    t = ep.time
    sec = t.second + t.microsecond / 1e6
    clock = ""
    if ep.clock_offset_s is not None:
        if not abs(ep.clock_offset_s) < 1e3:
            raise ValueError(f"clock_offset_s {ep.clock_offset_s!r} does not fit F15.12")
        clock = f"{'':6}{ep.clock_offset_s:15.12f}"
    order = np.argsort(ep.prns, kind="stable")
    out = [f"> {t.year:4d} {t.month:02d} {t.day:02d} {t.hour:02d} {t.minute:02d}"
           f"{sec:11.7f}  {ep.flag:1d}{len(order):3d}{clock}\n"]
    for i in order:
        cn0 = ep.cn0_dbhz[i]
        ssi = " " if np.isnan(cn0) else str(signal_strength_indicator(cn0))
        fields = []
        for name, value in zip(OBS_TYPES, (ep.pseudorange_m[i], ep.carrier_cycles[i],
                                           ep.doppler_hz[i], cn0)):
            if np.isnan(value):
                fields.append(" " * 16)
                continue
            lli = str(ep.lli[i]) if name == "L1C" and ep.lli[i] else " "
            fields.append(_f14_3(value) + lli + (" " if name == "S1C" else ssi))
        out.append(f"G{int(ep.prns[i]):02d}" + "".join(fields) + "\n")
    return out


def write_rinex_obs(target, epochs, header: RinexObsHeader = RinexObsHeader()) -> None:
    """Write ``epochs`` (``ObservationEpoch``, in time order) as a RINEX 3.04 observation
    file to ``target`` (a path or a text stream)."""
    epochs = list(epochs)
    if not epochs:
        raise ValueError("a RINEX observation file needs at least one epoch")
    times = [e.time for e in epochs]
    if any(b <= a for a, b in zip(times, times[1:])):
        raise ValueError("epochs must be in strictly increasing time order")
    text = "".join(header_lines(header, times[0]) +
                   [ln for e in epochs for ln in epoch_lines(e)])
    if isinstance(target, (str, Path)):
        Path(target).write_text(text, encoding="ascii")
    elif isinstance(target, io.TextIOBase) or hasattr(target, "write"):
        target.write(text)
    else:
        raise TypeError(f"target must be a path or a text stream, not {type(target)!r}")
