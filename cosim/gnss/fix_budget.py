"""A generated static GPS run against its error budget, and ``python -m cosim bench gps-fix``.

:func:`fix_budget` takes a run of ``python -m cosim gps`` on a generated scenario
(:func:`cosim.gnss.gps_cli.process`: the GpsRun and the scenario with its signal) and sets
what was measured beside what the thermal noise of the tracking loops predicts
(:mod:`dsp.gnss.budget`):

* **Pseudorange noise per satellite.** At every fix epoch (receiver sample ``n``,
  receiver time ``t_rx``) the generator's exact pseudorange ``P`` at ``s = n / fs``
  (:meth:`~cosim.gnss.constellation.ConstellationSignal.truth_at`: geometric range,
  satellite clock, ionosphere, troposphere and the receiver clock, read on the generator's
  receiver time ``tow_rx``) is taken from the measured one, and ``c (t_rx - tow_rx)`` (the
  receiver's own time error, common to all channels and known exactly here) too: what is
  left is the channel's measurement error. Its mean per satellite (a code-phase bias) is
  reported and removed; its standard deviation is set against the DLL formula at the
  satellite's measured C/N0 (the linear mean of all its channel's in-lock estimates: one
  window's M2M4 estimate scatters by ~1.5 dB). The same for the range rate ``-lambda D`` against the
  generator's Doppler. Pooled over the satellites: the root of the mean of the squared
  ratios, with its statistical spread ``1 / sqrt(2 sum (n_i - 1))`` (``pooled_ratio_sigma``).
  The same at the tracking rate (``rec_*``, ``record_*_pooled``): every 5th record of each
  channel from 1 s after its start, the prompt code phase (chips, its mean removed) and the
  reported Doppler against the generator's at the record's sample -- many more samples
  than the fixes give (correlated over the loops' time constants, ~0.25 s for the DLL).
* **Position and velocity.** The fixes' east/north/up errors against the true position
  (:func:`cosim.gnss.gps_outputs.fix_rows`) and the velocities against zero (static).
  The budget at every fix: the covariance ``A R A^T`` (:func:`dsp.gnss.budget.
  predicted_errors`) with the *true* geometry (the generator's elevations and azimuths of
  the satellites used), the solver's own weights (its ``sigmas_m``) and ``R`` the budget's
  sigmas; plus the deterministic term ``A delta`` of the atmosphere the receiver did not
  remove (``delta`` = the generator's ionosphere and troposphere minus the Klobuchar /
  Saastamoinen corrections the solution lists, evaluated at the true position). The
  predicted RMS is the root of the mean over the fixes of ``|A delta|^2 + tr(A R A^T)``.
  Beside it, not part of the prediction, ``measured_code_bias_rms_3d_m``: the position
  error the measured per-satellite pseudorange biases alone would make (``A b``), and
  ``unexplained_rms_3d_m`` / ``_mps``: the RMS of the fixes' errors less ``A e + A delta``
  rebuilt from each fix's measured per-satellite errors ``e`` (the solver's linearisation:
  what the channels' measurement errors and the atmosphere term do not account for).
  ``ratio`` = measured RMS / predicted RMS; its statistical spread for this many fixes
  (Gaussian errors, independent fixes) is reported as ``ratio_sigma``. The thermal part
  alone: ``measured_std_3d_m``, the RMS of the errors about their mean over the run (the
  atmosphere term varies little over a minute), against ``predicted_noise_rms_3d_m``
  (``std_ratio_to_noise``); the mean east/north/up error against the mean ``A delta``.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from dsp.gnss.atmosphere import klobuchar_delay_m, saastamoinen_delay_m
from dsp.gnss.budget import TrackingLoops, channel_sigmas, solution_covariance
from dsp.gnss.ca_code import CHIP_RATE_HZ
from dsp.gnss.ephemeris import C_LIGHT, WEEK_S
from dsp.gnss.ephemeris import CHIP_M, L1_WAVELENGTH_M
from dsp.gnss.pvt import enu_geometry

__all__ = ["fix_budget", "loops_of", "markdown"]

def loops_of(a, p) -> TrackingLoops:
    """The loops of a ``gps`` run: parsed options ``a`` (``--tracker pll2/pll3``,
    ``--bn-hz``), channel parameters ``p`` (the E-L spacing), the DLL bandwidth of
    :class:`cosim.gnss.config.GnssRunConfig`, the FPGA channel's one-epoch latency."""
    from .config import GnssRunConfig
    if a.tracker not in ("pll2", "pll3"):
        raise ValueError(f"--tracker {a.tracker}: the budget covers the PLL trackers "
                         f"(pll2, pll3)")
    run = GnssRunConfig(tracker=a.tracker, bn_hz=a.bn_hz)
    return TrackingLoops(order=int(a.tracker[-1]), bn_hz=run.tracker_setting("bn_hz"),
                         dll_bn_hz=run.tracker_setting("dll_bn_hz"),
                         spacing_chips=p.el_spacing_samples * CHIP_RATE_HZ / p.fs_hz,
                         T_s=1e-3, latency=1)


def _pool(sats, key) -> float | None:
    r = [x[key] for x in sats if key in x]
    return float(np.sqrt(np.mean(np.square(r)))) if r else None


def _rms(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x ** 2))) if x.size else float("nan")


def _applied_atmosphere(sol, tow_s, truth, i, cols, iono):
    """The corrections the solution applied (its ``corrections``), at the true position and
    the receiver time ``tow_s`` the solver was given."""
    el, az = truth.elevation_deg[i, cols], truth.azimuth_deg[i, cols]
    d = np.zeros(len(cols))
    lat, lon, h = _truth_llh(truth)
    if "klobuchar" in sol.corrections:
        d += klobuchar_delay_m(lat, lon, el, az, float(np.mod(tow_s, WEEK_S)),
                               iono.alpha, iono.beta)
    if "saastamoinen" in sol.corrections:
        d += saastamoinen_delay_m(lat, h, el)
    return d


def _truth_llh(truth):
    import pymap3d
    return pymap3d.ecef2geodetic(*truth.rx_position_m[0])


def _record_errors(run, sig, col, skip_s: float = 1.0, step: int = 5) -> dict:
    """PRN -> (code error (chips), Doppler error (Hz)) of every ``step``-th record of its
    channel from ``skip_s`` after the channel's first record: the prompt code phase and the
    Doppler the tracker reported against the generator's at the record's sample."""
    from dsp.gnss.ca_code import CODE_LENGTH
    out: dict = {}
    for c in run.channels:
        if not c.ok or int(c.prn) not in col:
            continue
        k = np.arange(int(np.searchsorted(c.g, c.g[0] + skip_s * run.fs_hz)), c.g.size, step)
        if k.size < 10:
            continue
        tt = sig.truth_at(c.g[k] / run.fs_hz)
        j = col[int(c.prn)]
        code = np.mod(c.code_phase[k] - tt.code_phase_chips[:, j] + CODE_LENGTH / 2,
                      CODE_LENGTH) - CODE_LENGTH / 2
        out.setdefault(int(c.prn), []).append((code, c.doppler[k] - tt.doppler_hz[:, j]))
    return {p: tuple(np.concatenate(x) for x in zip(*v)) for p, v in out.items()}


def fix_budget(run, scenario, loops: TrackingLoops) -> dict:
    """The measured errors of ``run`` (a :class:`cosim.gnss.gps_receiver.GpsRun` on the
    generated ``scenario``) beside the budget (module doc)."""
    from .gps_outputs import fix_rows
    fixes = run.fixes
    if len(fixes) < 2:
        raise ValueError(f"the run has {len(fixes)} fixes: the budget needs at least 2")
    sig, truth0 = scenario["signal"], scenario["truth"]
    s = np.array([e.sample / run.fs_hz for e in fixes])
    tr = sig.truth_at(s)
    col = {int(p): j for j, p in enumerate(tr.prns)}
    # per satellite: pseudorange and range-rate errors at every fix epoch
    pr_err: dict = {}
    rr_err: dict = {}
    cn0s: dict = {}
    at: list = []                      # per fix: PRN -> (pseudorange, range-rate error)
    for i, e in enumerate(fixes):
        o = e.obs
        rx = np.mod(e.tow_s - tr.tow_rx[i] + WEEK_S / 2, WEEK_S) - WEEK_S / 2
        at.append({})
        for j, prn in enumerate(o.prns):
            c = col[int(prn)]
            pr_err.setdefault(int(prn), []).append(
                o.pseudorange_m[j] - tr.pseudorange_m[i, c] - C_LIGHT * rx)
            rr_err.setdefault(int(prn), []).append(
                -L1_WAVELENGTH_M * (o.doppler_hz[j] - tr.doppler_hz[i, c]))
            cn0s.setdefault(int(prn), []).append(o.cn0_dbhz[j])
            at[-1][int(prn)] = (pr_err[int(prn)][-1], rr_err[int(prn)][-1])
    sats = []
    cn0_mean = {}
    windows: dict = {}
    for c in run.channels:
        if c.ok and c.win_t.size:
            windows.setdefault(int(c.prn), []).append(np.asarray(c.win_cn0)[c.win_ok])
    recs = _record_errors(run, sig, col)
    for prn in sorted(pr_err):
        w = np.concatenate(windows[prn]) if prn in windows else np.asarray(cn0s[prn])
        c_lin = np.mean(10 ** (w / 10))
        cn0_mean[prn] = float(10 * np.log10(c_lin))
        pr_s, rr_s = channel_sigmas(cn0_mean[prn], loops)
        x, v = np.asarray(pr_err[prn]), np.asarray(rr_err[prn])
        sats.append({"prn": prn, "epochs": int(x.size), "cn0_dbhz": round(cn0_mean[prn], 2),
                     "elevation_deg": round(float(tr.elevation_deg[0, col[prn]]), 1),
                     "pr_bias_m": float(x.mean()), "pr_std_m": float(x.std(ddof=1)),
                     "pr_formula_m": float(pr_s),
                     "pr_ratio": float(x.std(ddof=1) / pr_s),
                     "rr_bias_mps": float(v.mean()), "rr_std_mps": float(v.std(ddof=1)),
                     "rr_formula_mps": float(rr_s),
                     "rr_ratio": float(v.std(ddof=1) / rr_s)})
        if prn in recs:
            code, dop = recs[prn]
            sats[-1].update(records=int(code.size),
                            rec_pr_std_m=float(code.std() * CHIP_M),
                            rec_pr_ratio=float(code.std() * CHIP_M / pr_s),
                            rec_rr_std_mps=float(dop.std() * L1_WAVELENGTH_M),
                            rec_rr_ratio=float(dop.std() * L1_WAVELENGTH_M / rr_s))
    # the budget at every fix
    rows = {r["t_s"]: r for r in fix_rows(run, truth0)}
    iono = scenario["iono"]
    vel_ms, pos_var2, vel_var2, recon_p, recon_v = [], [], [], [], []
    noise_ms, bias_ms, pdops, code_bias_ms = [], [], [], []
    pr_bias = {x["prn"]: x["pr_bias_m"] for x in sats}
    enu_pred = np.zeros(3)
    enu_vpred = np.zeros(3)
    bias_enu = []
    for i, e in enumerate(fixes):
        sol = e.solution
        cols = np.array([col[int(p)] for p in sol.used_prns])
        g = enu_geometry(tr.elevation_deg[i, cols], tr.azimuth_deg[i, cols])
        prs, rrs = channel_sigmas(np.array([cn0_mean[int(p)] for p in sol.used_prns]), loops)
        cp = solution_covariance(g, sol.sigmas_m, prs)
        cv = solution_covariance(g, sol.sigmas_m, rrs)
        w = 1.0 / np.asarray(sol.sigmas_m) ** 2
        a = np.linalg.solve(g.T @ (w[:, None] * g), (g * w[:, None]).T)
        delta = tr.iono_m[i, cols] + tr.tropo_m[i, cols] - \
            _applied_atmosphere(sol, e.tow_s, tr, i, cols, iono)
        b = a @ delta
        cb = a @ np.array([pr_bias[int(p)] for p in sol.used_prns])
        code_bias_ms.append(float(cb[:3] @ cb[:3]))
        bias_enu.append(b[:3])
        recon_p.append(a @ np.array([at[i][int(p)][0] for p in sol.used_prns]) + b)
        recon_v.append(a @ np.array([at[i][int(p)][1] for p in sol.used_prns]))
        noise_ms.append(np.trace(cp[:3, :3]))
        bias_ms.append(float(b[:3] @ b[:3]))
        pos_var2.append(2 * np.trace(cp[:3, :3] @ cp[:3, :3]))
        vel_ms.append(np.trace(cv[:3, :3]))
        vel_var2.append(2 * np.trace(cv[:3, :3] @ cv[:3, :3]))
        enu_pred += np.diag(cp)[:3] + b[:3] ** 2
        enu_vpred += np.diag(cv)[:3]
        pdops.append(sol.dop.pdop)
    n = len(fixes)
    r = [rows[e.sample / run.fs_hz] for e in fixes]
    err = np.array([[x["err_e_m"], x["err_n_m"], x["err_u_m"]] for x in r])
    vel = np.array([[x["vel_e_mps"], x["vel_n_mps"], x["vel_u_mps"]] for x in r])
    pos_pred = float(np.sqrt(np.mean(np.add(noise_ms, bias_ms))))
    vel_pred = float(np.sqrt(np.mean(vel_ms)))
    pos_meas = _rms(np.linalg.norm(err, axis=1))
    # the fixes rebuilt from the measured per-satellite errors: what is left is not from
    # the channels' measurements or the atmosphere term
    left_p = _rms(np.linalg.norm(err - np.array(recon_p)[:, :3], axis=1))
    left_v = _rms(np.linalg.norm(vel - np.array(recon_v)[:, :3], axis=1))
    # the fluctuation about the run's mean against the thermal noise alone (the slowly
    # varying atmosphere term removed with the mean; n - 1 degrees of freedom)
    fluct = err - err.mean(axis=0)
    pos_std = float(np.sqrt(np.sum(fluct ** 2) / (n - 1)))
    noise_rms = float(np.sqrt(np.mean(noise_ms)))
    vel_meas = _rms(np.linalg.norm(vel, axis=1))
    # relative spread of an RMS over n independent fixes: half that of the mean square
    pos_spread = 0.5 * np.sqrt(np.sum(pos_var2)) / np.sum(np.add(noise_ms, bias_ms))
    pos_spread_noise = 0.5 * np.sqrt(np.sum(pos_var2)) / np.sum(noise_ms)
    vel_spread = 0.5 * np.sqrt(np.sum(vel_var2)) / np.sum(vel_ms)
    axes = ("east", "north", "up")
    pr_pool = np.sqrt(np.mean([x["pr_std_m"] ** 2 / x["pr_formula_m"] ** 2 for x in sats]))
    rr_pool = np.sqrt(np.mean([x["rr_std_mps"] ** 2 / x["rr_formula_mps"] ** 2 for x in sats]))
    return {
        "ttff_s": run.ttff_s, "fixes": n, "fix_span_s": float(s[-1] - s[0]),
        "first_fix_s": float(s[0]), "satellites_used": sorted({p for e in fixes
                                                               for p in e.solution.used_prns}),
        "pdop_mean": float(np.mean(pdops)),
        "loops": {"order": loops.order, "bn_hz": loops.bn_hz, "dll_bn_hz": loops.dll_bn_hz,
                  "spacing_chips": loops.spacing_chips, "T_s": loops.T_s,
                  "latency": loops.latency},
        "position": {
            "measured_rms_3d_m": pos_meas, "predicted_rms_3d_m": pos_pred,
            "predicted_noise_rms_3d_m": noise_rms,
            "measured_std_3d_m": pos_std, "std_ratio_to_noise": pos_std / noise_rms,
            "std_ratio_sigma": float(pos_spread_noise),
            "predicted_atmosphere_rms_3d_m": float(np.sqrt(np.mean(bias_ms))),
            "ratio": pos_meas / pos_pred, "ratio_sigma": float(pos_spread),
            "measured_code_bias_rms_3d_m": float(np.sqrt(np.mean(code_bias_ms))),
            "unexplained_rms_3d_m": left_p,
            "measured_mean_enu_m": err.mean(axis=0).tolist(),
            "predicted_mean_enu_m": np.mean(bias_enu, axis=0).tolist(),
            "measured_rms_enu_m": {k: _rms(err[:, j]) for j, k in enumerate(axes)},
            "predicted_rms_enu_m": {k: float(np.sqrt(enu_pred[j] / n))
                                    for j, k in enumerate(axes)}},
        "velocity": {
            "measured_rms_3d_mps": vel_meas, "predicted_rms_3d_mps": vel_pred,
            "ratio": vel_meas / vel_pred, "ratio_sigma": float(vel_spread),
            "unexplained_rms_3d_mps": left_v,
            "measured_mean_enu_mps": vel.mean(axis=0).tolist(),
            "measured_rms_enu_mps": {k: _rms(vel[:, j]) for j, k in enumerate(axes)},
            "predicted_rms_enu_mps": {k: float(np.sqrt(enu_vpred[j] / n))
                                      for j, k in enumerate(axes)}},
        "pseudorange_ratio_pooled": float(pr_pool), "range_rate_ratio_pooled": float(rr_pool),
        "pooled_ratio_sigma": float(1 / np.sqrt(2 * sum(x["epochs"] - 1 for x in sats))),
        "record_pseudorange_ratio_pooled": _pool(sats, "rec_pr_ratio"),
        "record_range_rate_ratio_pooled": _pool(sats, "rec_rr_ratio"),
        "satellites": sats, "chip_m": CHIP_M}


def markdown(r: dict) -> str:
    m, p, v = r["machine"], r["position"], r["velocity"]
    sc = r["scenario"]
    lines = ["# GPS static fix against its thermal-noise error budget", "",
             f"Measured {m['date']} on {m['host']} ({m['cpu']}, {m['cores']} cores, shared), "
             f"commit {m['commit']}, command `{m['command']}`.", "",
             f"Scenario: {sc['start']} start, {sc['duration_s']:g} s, {sc['cn0_dbhz']:g} dB-Hz "
             f"on every satellite, {sc['constellation']} constellation, {sc['receiver']}; "
             f"{sc['channel']}.", "",
             f"Time to first fix {r['ttff_s']:.1f} s; {r['fixes']} fixes over "
             f"{r['fix_span_s']:.0f} s with PRNs {r['satellites_used']}, mean PDOP "
             f"{r['pdop_mean']:.2f}.", "",
             "| quantity | measured RMS | budget RMS | ratio | ratio 1-sigma spread |",
             "|---|---|---|---|---|",
             f"| 3-D position (m) | {p['measured_rms_3d_m']:.3f} | {p['predicted_rms_3d_m']:.3f} "
             f"| {p['ratio']:.3f} | {p['ratio_sigma']:.3f} |",
             f"| 3-D velocity (m/s) | {v['measured_rms_3d_mps']:.4f} | "
             f"{v['predicted_rms_3d_mps']:.4f} | {v['ratio']:.3f} | {v['ratio_sigma']:.3f} |",
             f"| 3-D position about its mean (m) vs thermal noise | {p['measured_std_3d_m']:.3f} "
             f"| {p['predicted_noise_rms_3d_m']:.3f} | {p['std_ratio_to_noise']:.3f} | "
             f"{p['std_ratio_sigma']:.3f} |",
             "", f"Position budget: thermal noise {p['predicted_noise_rms_3d_m']:.3f} m, "
             f"atmosphere left uncorrected {p['predicted_atmosphere_rms_3d_m']:.3f} m; the "
             f"measured per-satellite pseudorange biases alone would give "
             f"{p['measured_code_bias_rms_3d_m']:.3f} m (not in the budget). The fixes rebuilt "
             f"from the measured per-satellite errors leave {p['unexplained_rms_3d_m']:.4f} m "
             f"and {v['unexplained_rms_3d_mps']:.5f} m/s unexplained.", "",
             "| PRN | C/N0 (dB-Hz) | el (deg) | PR bias (m) | PR std (m) | DLL formula (m) | "
             "ratio | RR std (m/s) | PLL formula (m/s) | ratio | per record: PR ratio | "
             "RR ratio |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in r["satellites"]:
        lines.append(f"| {s['prn']} | {s['cn0_dbhz']:.1f} | {s['elevation_deg']:.0f} | "
                     f"{s['pr_bias_m']:.2f} | {s['pr_std_m']:.3f} | {s['pr_formula_m']:.3f} | "
                     f"{s['pr_ratio']:.2f} | {s['rr_std_mps']:.4f} | "
                     f"{s['rr_formula_mps']:.4f} | {s['rr_ratio']:.2f} | "
                     f"{s.get('rec_pr_ratio', float('nan')):.2f} | "
                     f"{s.get('rec_rr_ratio', float('nan')):.2f} |")
    lines += ["", f"Pooled over the satellites: pseudorange std / formula "
                  f"{r['pseudorange_ratio_pooled']:.3f}, range rate "
                  f"{r['range_rate_ratio_pooled']:.3f} (1-sigma spread "
                  f"{r['pooled_ratio_sigma']:.3f}); at the tracking rate "
                  f"{r['record_pseudorange_ratio_pooled']:.3f} and "
                  f"{r['record_range_rate_ratio_pooled']:.3f}.", ""]
    return "\n".join(lines)
