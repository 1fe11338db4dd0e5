"""``python -m cosim bench gps-fast``: speed of the GPS receiver on the correlation-domain
fast path (:mod:`cosim.gnss.gps_fast`) beside the IF path on the bit-exact model, and the
statistical comparison of the two (:mod:`cosim.gnss.gps_fast_check`).

Speed: the whole receiver (tracking of every channel, observables, fixes at 1 Hz), pll3 in
fixed point, on two static scenarios -- the ``gps`` command's (nominal constellation, 8
satellites) and 12 satellites (the broadcast ephemerides ``tests/data/gnss/brdc2800.15n`` 11
h after their first toe at 52 N 4.4 E, 5 degree mask, 12 channels) -- for 1 and for 20
Monte Carlo trials, after an untimed warm-up: seconds of signal per second of wall time
(times the trials: the Monte Carlo throughput), and of the tracking alone. The IF path's
figure is that of its multi-channel tracking on the model (the comparison's runs).

Comparison: :func:`cosim.gnss.gps_fast_check.compare` at 45 and 35 dB-Hz (3 s, 8
satellites, 20 fast trials, 10 Hz epochs). Written to ``results/gps_fast.json`` and ``.md``
with the machine, date, command and commit.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

from ..core.provenance import REPO_ROOT, machine_info, write_result
from .gps_receiver import GpsConfig

#: The 12-satellite scenario's navigation file (in the repository's test data).
NAV_12 = REPO_ROOT / "tests" / "data" / "gnss" / "brdc2800.15n"


def _scenario_12(duration_s: float):
    from .constellation import ConstellationSignal
    from .gps_scenario import ScenarioSpec, scenario_config
    from .rinex_nav import read_rinex_nav
    e0 = min(read_rinex_nav(NAV_12).ephemerides, key=lambda e: (e.week, e.toe))
    cfg, _ = scenario_config(ScenarioSpec(duration_s=duration_s, nav_file=str(NAV_12),
                                          tow_s=e0.toe + 11 * 3600.0))
    return ConstellationSignal(cfg.replace(mask_deg=5.0))


def _scenario_8(duration_s: float):
    from .constellation import ConstellationSignal
    from .gps_fast_check import scenario
    from .gps_scenario import scenario_config
    return ConstellationSignal(scenario_config(scenario(45.0, duration_s))[0])


def speed(duration_s: float, trials=(1, 20)) -> list[dict]:
    """Seconds of signal per second on the fast path (module doc), one row per scenario and
    trial count."""
    from .gps_fast import run_fast
    rows = []
    for name, make in (("nominal, 8 satellites", _scenario_8),
                       ("brdc2800.15n, 12 satellites", _scenario_12)):
        sig = make(duration_s + 0.2)
        run_fast(sig.cfg, signal=sig, trials=1, duration_s=1.05)      # warm-up, not timed
        for n in trials:
            r = run_fast(sig.cfg, signal=sig, trials=n, duration_s=duration_s, seed=1)
            rows.append({"scenario": name, "satellites": len(r.prns), "trials": n,
                         "signal_s": r.signal_s, "wall_s": r.wall_s,
                         "track_wall_s": r.track_wall_s,
                         "signal_s_per_s": r.signal_s * n / r.wall_s,
                         "tracking_signal_s_per_s": r.signal_s * n / r.track_wall_s,
                         "fixes": int(sum(len(g.fixes) for g in r.runs))})
    return rows


def gps_fast(out, quick: bool = False) -> dict:
    from .gps_fast_check import compare, scenario
    out = Path(out)
    t0 = time.perf_counter()
    rows = speed(2.0 if quick else 10.0, (1, 4) if quick else (1, 20))
    comps = []
    for cn0 in ((45.0,) if quick else (45.0, 35.0)):
        with tempfile.TemporaryDirectory() as tmp:
            c = compare(scenario(cn0, 2.0 if quick else 3.0), tmp, gps=GpsConfig(rate_hz=10.0),
                        trials=4 if quick else 20)
        c["if"]["signal_s_per_s"] = c["duration_s"] / c["if"]["wall_s"]
        comps.append(c)
    res = {"machine": machine_info(), "benchmark": "gps-fast", "quick": quick,
           "scenario": "static receiver 52 N 4.4 E; pll3 fixed point, Bn 15 Hz, DLL 1 Hz; "
                       "2-bit ADC at 5 MS/s (IF path) / its loss (fast path)",
           "speed": rows, "comparison": comps,
           "if_model_signal_s_per_s": comps[0]["if"]["signal_s_per_s"],
           "all_comparisons_pass": all(c["all_pass"] for c in comps),
           "wall_s": time.perf_counter() - t0}
    write_result(out, "gps_fast", res, _markdown(res))
    return res


def _markdown(r: dict) -> str:
    m = r["machine"]
    lines = ["# GPS receiver on the fast path: speed and agreement with the IF path", "",
             f"Measured {m['date']} on {m['host']} ({m['cpu']}, {m['cores']} cores, shared), "
             f"commit {m['commit']}, command `{m['command']}`.", "",
             f"Scenario: {r['scenario']}.", "",
             "| scenario | satellites | trials | signal s / s | tracking only |",
             "|---|---|---|---|---|"]
    for x in r["speed"]:
        lines.append(f"| {x['scenario']} | {x['satellites']} | {x['trials']} | "
                     f"{x['signal_s_per_s']:.2f} | {x['tracking_signal_s_per_s']:.2f} |")
    lines += ["", f"IF path (bit-exact model, 8 channels): "
              f"{r['if_model_signal_s_per_s']:.3f} s of signal per second.", "",
              "| C/N0 | figure | IF | fast | test | pass |", "|---|---|---|---|---|---|"]
    for c in r["comparison"]:
        for key, test in (("range_rms_m", "range_ms"), ("doppler_rms_hz", "doppler_ms"),
                          ("position_rms_m", "position_ms"), ("cn0_mean_dbhz", "cn0_mean")):
            t = c["tests"][test]
            what = f"ratio {t['ratio']:.3f} in [{t['interval'][0]:.3f}, {t['interval'][1]:.3f}]" \
                if "ratio" in t else f"diff {t['difference_db']:.2f} dB within " \
                                     f"+-{t['interval'][1]:.2f}"
            lines.append(f"| {c['cn0_dbhz']:g} | {key} | {c['if'][key]:.4g} | "
                         f"{c['fast'][key]:.4g} | {what} | {'yes' if t['pass'] else 'no'} |")
    return "\n".join(lines) + "\n"
