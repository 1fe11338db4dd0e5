"""What a GPS receiver run (:func:`cosim.gnss.gps_receiver.navigate`) gives the user.

* :func:`fix_rows`: one row per measurement epoch (recording time, receiver time, status,
  satellites used, latitude, longitude, height, ECEF, clock bias and drift, east/north/up
  velocity, DOPs, and with a
  truth the east/north/up and 3-D errors and the truth's ECEF position);
* :func:`summarise`: the JSON summary (start mode, time to first fix, channels with their
  bit sync / frame sync / decoding, fix counts, error statistics against the truth, the
  fix jumps and navigation counts of :mod:`cosim.gnss.fix_integrity`);
* :func:`table`: the terminal lines;
* :func:`write_outputs`: ``obs.rnx`` (RINEX 3 observations, :func:`cosim.gnss.rinex_obs.
  write_rinex_obs`), ``fixes.nmea`` (GGA + RMC per fix, :func:`cosim.gnss.nmea.sentences`),
  ``fixes.csv``, ``gps.json`` and the plots ``position_error.png`` (with a truth),
  ``skyplot.png``, ``cn0.png``.

The truth is a dict with ``receiver_ecef_m`` (as :func:`cosim.gnss.gps_scenario.
write_scenario` writes it) and, for a moving receiver, ``ecef_at_sample``: the receiver's
ECEF position at each epoch's sample (``{sample: [x, y, z]}``), against which that epoch's
fix is compared (it is left out of the JSON).
"""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from .fix_integrity import JUMP_BOUND_M, fix_jumps, navigation_counts

__all__ = ["fix_rows", "summarise", "table", "write_outputs", "DEFAULT_LEAP_SECONDS"]

#: GPS - UTC (s) when no page 18 was decoded (the value since 2017).
DEFAULT_LEAP_SECONDS = 18


def _enu(sol, ref_ecef):
    import pymap3d
    lat, lon, h = pymap3d.ecef2geodetic(*ref_ecef)
    d = np.asarray(sol.position_ecef_m) - np.asarray(ref_ecef)
    return np.array(pymap3d.ecef2enuv(d[0], d[1], d[2], lat, lon))


def fix_rows(run, truth: dict | None = None) -> list[dict]:
    """One row per epoch with an attempted solution (module doc)."""
    rows = []
    at = {} if truth is None else truth.get("ecef_at_sample") or {}
    for e in run.epochs:
        s = e.solution
        if s is None:
            continue
        ref = None if truth is None else at.get(e.sample, truth["receiver_ecef_m"])
        r = {"t_s": e.sample / run.fs_hz, "week": e.week, "tow_rx_s": e.tow_s,
             "status": s.status.value, "n_used": len(s.used_prns),
             "used_prns": " ".join(str(p) for p in s.used_prns),
             "lat_deg": s.lat_deg, "lon_deg": s.lon_deg, "height_m": s.height_m,
             "x_m": float(s.position_ecef_m[0]), "y_m": float(s.position_ecef_m[1]),
             "z_m": float(s.position_ecef_m[2]), "clock_bias_m": s.clock_bias_m,
             "clock_drift_mps": s.clock_drift_mps,
             "vel_e_mps": float(s.velocity_enu_mps[0]), "vel_n_mps": float(s.velocity_enu_mps[1]),
             "vel_u_mps": float(s.velocity_enu_mps[2]), "pdop": s.dop.pdop, "hdop": s.dop.hdop,
             "vdop": s.dop.vdop}
        if ref is not None:
            enu = _enu(s, ref) if s.valid else np.full(3, np.nan)
            r.update(err_e_m=float(enu[0]), err_n_m=float(enu[1]), err_u_m=float(enu[2]),
                     err_3d_m=float(np.linalg.norm(enu)),
                     truth_x_m=float(ref[0]), truth_y_m=float(ref[1]),
                     truth_z_m=float(ref[2]))
        rows.append(r)
    return rows


def _stats(x) -> dict:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if not x.size:
        return {"n": 0}
    return {"n": int(x.size), "rms": float(np.sqrt(np.mean(x ** 2))),
            "max": float(np.max(np.abs(x))), "last": float(x[-1])}


def summarise(run, truth: dict | None = None, jump_bound_m: float = JUMP_BOUND_M) -> dict:
    """The run as one JSON-ready dict (module doc); ``jump_bound_m`` the fix-jump bound."""
    rows = fix_rows(run, truth)
    valid = [r for r in rows if r["status"].startswith("fix")]
    chans = [c.as_dict() for c in run.channels]
    statuses: dict = {}
    for r in rows:
        statuses[r["status"]] = statuses.get(r["status"], 0) + 1
    out = {"start": run.start, "ttff_s": run.ttff_s, "time_set_s": run.time_set_s,
           "epochs": len(run.epochs), "solutions": len(rows), "fixes": len(valid),
           "statuses": statuses, "channels": chans,
           "last_fix": valid[-1] if valid else None,
           "fix_jumps": fix_jumps(rows, jump_bound_m),
           "navigation": navigation_counts(chans)}
    if not valid:
        why = "no channel had a TOW and an ephemeris" if not rows else \
            f"no valid solution (statuses: {statuses})"
        out["no_fix"] = why
    if truth is not None:
        out["truth"] = {k: v for k, v in truth.items() if k != "ecef_at_sample"}
        h = [np.hypot(r["err_e_m"], r["err_n_m"]) for r in valid]
        out["error"] = {"horizontal_m": _stats(h),
                        "vertical_m": _stats([r["err_u_m"] for r in valid]),
                        "3d_m": _stats([r["err_3d_m"] for r in valid])}
    return out


def table(s: dict) -> str:
    """The summary as terminal lines."""
    lines = [f"{'PRN':>4} {'ch':>3} {'status':<14} {'bit edge':>8} {'subframes':>9} "
             f"{'parity fail':>11} {'ephemeris':>9} {'TOW known (s)':>13}"]
    for c in s["channels"]:
        bs = c["bit_sync"]
        lines.append(f"{c['prn']:>4} {c['channel']:>3} {c['status']:<14} "
                     f"{'-' if not bs or bs['edge'] is None else bs['edge']:>8} "
                     f"{len(c['subframes']):>9} {c['parity_failures']:>11} "
                     f"{'yes' if c['ephemeris_decoded'] else 'no':>9} "
                     f"{'-' if c['tow_known_s'] is None else format(c['tow_known_s'], '.3f'):>13}")
    lines.append(f"start: {s['start']}; epochs {s['epochs']}, solutions {s['solutions']}, "
                 f"fixes {s['fixes']}; statuses {s['statuses']}")
    if s["fixes"]:
        f = s["last_fix"]
        lines.append(f"time to first fix: {s['ttff_s']:.3f} s of the recording")
        lines.append(f"last fix: {f['lat_deg']:.7f} {f['lon_deg']:.7f} {f['height_m']:.2f} m, "
                     f"{f['n_used']} satellites, PDOP {f['pdop']:.2f}, clock bias "
                     f"{f['clock_bias_m']:.2f} m")
    else:
        lines.append(f"no fix: {s['no_fix']}")
    n, j = s["navigation"], s["fix_jumps"]
    lines.append(f"navigation: {n['parity_failures']} words failed parity, {n['subframes']} "
                 f"subframes decoded, {n['subframes_withheld']} withheld; fix jumps (> "
                 f"{j['bound_m']:g} m): {j['count']}"
                 + (f" at {', '.join(f'{t:.1f}' for t in j['t_s'][:5])} s" if j["count"] else ""))
    if "error" in s and s["fixes"]:
        e = s["error"]
        lines.append(f"error vs truth: horizontal RMS {e['horizontal_m']['rms']:.2f} m, "
                     f"vertical RMS {e['vertical_m']['rms']:.2f} m, 3-D max "
                     f"{e['3d_m']['max']:.2f} m over {e['3d_m']['n']} fixes")
    return "\n".join(lines)


def _leap_seconds(run) -> int:
    for c in run.channels:
        if c.decode is not None and c.decode.utc is not None:
            return int(c.decode.utc.dtLS)
    return DEFAULT_LEAP_SECONDS


def _plots(run, rows, truth, out: Path) -> list[str]:
    from ..tools.plots import pyplot, save_figure
    plt = pyplot()
    paths = []
    valid = [r for r in rows if r["status"].startswith("fix")]
    if truth is not None and valid:
        fig, ax = plt.subplots(figsize=(7, 4))
        t = [r["t_s"] for r in valid]
        for k, lab in (("err_e_m", "east"), ("err_n_m", "north"), ("err_u_m", "up")):
            ax.plot(t, [r[k] for r in valid], marker=".", label=lab)
        ax.set_xlabel("recording time (s)")
        ax.set_ylabel("position error (m)")
        ax.legend()
        ax.grid(alpha=0.3)
        paths.append(save_figure(fig, out / "position_error.png"))
    fig = plt.figure(figsize=(5, 5))
    ax = fig.add_subplot(projection="polar")
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    last: dict = {}
    for e in run.epochs:
        last.update(e.elevation)
    for prn, (el, az) in sorted(last.items()):
        ax.plot(np.radians(az), 90 - el, "o")
        ax.annotate(str(prn), (np.radians(az), 90 - el), fontsize=8)
    ax.set_rlim(0, 90)
    ax.set_yticks([0, 30, 60, 90], ["90", "60", "30", "0"])
    ax.set_title("sky plot (elevation, azimuth)")
    paths.append(save_figure(fig, out / "skyplot.png"))
    fig, ax = plt.subplots(figsize=(7, 4))
    for c in run.channels:
        if c.win_t.size:
            ax.plot(c.win_t, c.win_cn0, label=f"PRN {c.prn}")
    ax.set_xlabel("recording time (s)")
    ax.set_ylabel("C/N0 (dB-Hz)")
    ax.legend(fontsize=6, ncol=3)
    paths.append(save_figure(fig, out / "cn0.png"))
    return paths


def write_outputs(run, out_dir, truth: dict | None = None, *, plots: bool = True,
                  jump_bound_m: float = JUMP_BOUND_M) -> dict:
    """Write the files of the module doc to ``out_dir``; return the summary with their
    paths under ``files``."""
    from ..core.validate import dumps
    from .nmea import sentences
    from .rinex_obs import RinexObsHeader, write_rinex_obs
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    s = summarise(run, truth, jump_bound_m)
    rows = fix_rows(run, truth)
    files = []
    obs = [e.obs for e in run.epochs if e.obs is not None]
    if obs:
        fixes = run.fixes
        approx = tuple(float(x) for x in fixes[-1].solution.position_ecef_m) if fixes else \
            (0.0, 0.0, 0.0)
        interval = float(np.median(np.diff([e.sample for e in run.epochs]))) / run.fs_hz \
            if len(run.epochs) > 1 else None
        write_rinex_obs(out / "obs.rnx", obs, RinexObsHeader(approx_position_m=approx,
                                                              interval_s=interval))
        files.append(str(out / "obs.rnx"))
    leap = _leap_seconds(run)
    with open(out / "fixes.nmea", "w") as fh:
        for e in run.fixes:
            fh.write("".join(x + "\r\n" for x in sentences(e.solution, leap_seconds=leap)))
    files.append(str(out / "fixes.nmea"))
    with open(out / "fixes.csv", "w", newline="") as fh:
        if rows:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    files.append(str(out / "fixes.csv"))
    if plots:
        files += _plots(run, rows, truth, out)
    s["files"] = files + [str(out / "gps.json")]
    (out / "gps.json").write_text(json.dumps(json.loads(dumps(s)), indent=1))
    return s
