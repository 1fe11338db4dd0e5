"""The figures of docs/explanation/gps_constellation_signal.md.

Run from the repository root: ``PYTHONPATH=. python docs/examples/constellation_figures.py``. It prints
markdown tables: the sky of a static receiver at a RINEX file's epoch, the interpolation
error of the sample kernel against the exact geometry (static receiver with an OCXO and
atmosphere models; the INS paper's trajectory), the prompt correlation of the stream at the
truth, and the generation speed.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from cosim.gnss.constellation import L1_WAVELENGTH_M, ConstellationConfig, ConstellationSignal
from cosim.gnss.constellation_geometry import ReceiverClock, StaticReceiver, \
    along_track_receiver
from cosim.gnss.rinex_nav import read_rinex_nav
from cosim.ins.trajectory import PaperTrajectory
from dsp.gnss.ca_code import CHIP_RATE_HZ, L1_HZ, ca_code_levels

ROOT = Path(__file__).resolve().parents[2]
WEEK, TOW = 1865, 259200.0 + 12 * 3600 + 100.0
ZURICH = (47.3769, 8.5417, 500.0)


def scenario(nav, **kw):
    base = dict(ephemerides=nav.ephemerides, week=WEEK, tow_s=TOW,
                receiver=StaticReceiver.geodetic(*ZURICH), fs_hz=4.092e6, if_hz=0.0,
                duration_s=2.0, klobuchar=nav.iono)
    base.update(kw)
    return ConstellationConfig(**base)


def sky(nav):
    sig = ConstellationSignal(scenario(nav, clock=ReceiverClock(2.5e-4, 3e-7)))
    tr = sig.truth_at([0.0])
    print("| PRN | el (deg) | az (deg) | C/N0 (dB-Hz) | range (m) | pseudorange (m) | "
          "Doppler (Hz) | code phase (chips) |")
    print("|---|---|---|---|---|---|---|---|")
    for j, prn in enumerate(sig.prns):
        print(f"| {prn} | {tr.elevation_deg[0, j]:.1f} | {tr.azimuth_deg[0, j]:.1f} | "
              f"{tr.cn0_dbhz[0, j]:.1f} | {tr.geometric_range_m[0, j]:.3f} | "
              f"{tr.pseudorange_m[0, j]:.3f} | {tr.doppler_hz[0, j]:.3f} | "
              f"{tr.code_phase_chips[0, j]:.4f} |")


def interpolation(nav):
    cases = {
        "static, OCXO, iono 5 m/sin el, tropo 2.4 m/sin el": (
            scenario(nav, clock=ReceiverClock(1e-4, 1e-6, "ocxo"), duration_s=2.2,
                     iono=lambda la, lo, az, el, tow: 5.0 / np.sin(np.radians(el)),
                     tropo=lambda el, h: 2.4 / np.sin(np.radians(el))),
            np.linspace(0.0, 2.2, 4001) + 0.3e-3 / 7),
        "INS paper trajectory (jerk ramps, 50 g hold), OCXO, seed 3": (
            scenario(nav, receiver=along_track_receiver(PaperTrajectory(), 30.0, 10.0, 200.0,
                                                        90.0),
                     duration_s=40.0, tow_s=TOW - 2 * 3600,
                     clock=ReceiverClock(oscillator="ocxo"), seed=3),
            np.concatenate([np.linspace(a, a + 1, 2003) for a in (4.5, 14.6, 21.5, 31.5)])),
    }
    print("| scenario | satellites | points | max code-range error (m) | "
          "max carrier error (cycles) |")
    print("|---|---|---|---|---|")
    for name, (cfg, s) in cases.items():
        sig = ConstellationSignal(cfg)
        got = sig.interpolated_ranges(s)
        tr = sig.truth_at(s)
        e_code = np.abs(got[..., 0] - tr.pseudorange_m).max()
        e_cyc = np.abs(-got[..., 1] / L1_WAVELENGTH_M - tr.carrier_phase_cycles).max()
        print(f"| {name} | {len(sig.prns)} | {s.size} | {e_code:.2e} | {e_cyc:.2e} |")


def correlation(nav):
    cfg = scenario(nav, noise=False, if_hz=0.25e6, duration_s=0.4)
    sig = ConstellationSignal(cfg)
    fs = cfg.fs_hz
    print("| PRN | prompt / A (whole stream) | prompt / A (own signal) | "
          "early 1/2 chip / A (own) |")
    print("|---|---|---|---|")
    for prn in sig.prns:
        one = ConstellationSignal(cfg.replace(prns=(prn,)))
        j = sig.prns.index(prn)
        tr = sig.truth_at([0.2])
        rate = CHIP_RATE_HZ * (1 + tr.doppler_hz[0, j] / L1_HZ)
        n0 = int(np.ceil((0.2 + (1023 - tr.code_phase_chips[0, j]) / rate + 2e-6) * fs))
        n = int(0.98e-3 * fs)
        t0 = sig.truth_at([n0 / fs])
        a = np.sqrt(10 ** (t0.cn0_dbhz[0, j] / 10) * 2 / fs) * t0.nav_bit[0, j]
        t = np.arange(n) / fs

        def rep(off):
            fd = t0.doppler_hz[0, j]
            ch = t0.code_phase_chips[0, j] + off + CHIP_RATE_HZ * (1 + fd / L1_HZ) * t
            ph = cfg.if_hz * (t + n0 / fs) + t0.carrier_phase_cycles[0, j] + fd * t
            return ca_code_levels(prn)[np.floor(ch).astype(np.int64) % 1023] * \
                np.exp(2j * np.pi * ph)

        x, x1 = sig.analog(n0, n), one.analog(n0, n)
        p = np.vdot(rep(0.0), x) / n / a
        p1 = np.vdot(rep(0.0), x1) / n / a
        e1 = np.vdot(rep(0.5), x1) / n / a
        print(f"| {prn} | {p.real:+.4f} {p.imag:+.4f}j | {p1.real:+.6f} {p1.imag:+.6f}j | "
              f"{abs(e1):.4f} |")


def speed(nav):
    cfg = scenario(nav, fs_hz=2.048e6, duration_s=1.0)
    sig = ConstellationSignal(cfg)
    sig.analog(0, 1000)                     # compile
    t0 = time.perf_counter()
    n = 0
    for b in sig.blocks(1 << 18):
        n += b.size
    dt = time.perf_counter() - t0
    print(f"{len(sig.prns)} satellites, {n} complex samples at 2.048 MS/s in {dt:.2f} s: "
          f"{n * len(sig.prns) / dt / 1e6:.1f} M satellite-samples/s")


if __name__ == "__main__":
    nav = read_rinex_nav(ROOT / "tests" / "data" / "gnss" / "brdc2800.15n")
    for f in (sky, interpolation, correlation, speed):
        print(f"\n## {f.__name__}\n")
        f(nav)
