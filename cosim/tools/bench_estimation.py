"""Estimation-library speed: updates/s of the 3-state Kalman loop, the 4-state UKF and the
alpha-beta tracker (:mod:`dsp.estimation`), float and fixed, one stream and batched Monte
Carlo trials (one core), against the loop rate they must beat: 1 kHz per channel x 12
channels = 12,000 updates/s.

Writes ``results/estimation_speed.json`` and ``.md`` with the machine, date, command and
commit (``python -m cosim bench estimation``).
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from dsp.jit import njit_cached

from ..core.provenance import machine_info, write_result

TARGET_UPS = 1000.0 * 12


@njit_cached
def _f_jerk(x, w, prm, q, out):
    """Carrier phase / frequency / rate / jerk model of the GNSS UKF (the AUKF patent's): prm[0] = [T,
    T^2/2, T^3/6]."""
    T, T2, T3 = prm[0, 0], prm[0, 1], prm[0, 2]
    out[0] = x[0] + T * x[1] + T2 * x[2] + T3 * x[3] + w[0]
    out[1] = x[1] + T * x[2] + T2 * x[3] + w[1]
    out[2] = x[2] + T * x[3] + w[2]
    out[3] = x[3] + w[3]


@njit_cached
def _h_iq(x, v, prm, q, out):
    out[0] = prm[0, 0] * np.cos(x[0]) + v[0]
    out[1] = prm[0, 0] * np.sin(x[0]) + v[1]


def _rate(make, z, warm, n_updates: int, reps: int) -> float:
    """Best updates/s over ``reps`` fresh filters; a first run on ``warm`` (a short slice)
    compiles or loads the kernel."""
    make().run(warm)
    best = math.inf
    for _ in range(reps):
        f = make()
        t0 = time.perf_counter()
        f.run(z)
        best = min(best, time.perf_counter() - t0)
    return n_updates / best


def estimation_speed(out: Path, quick: bool = False) -> dict:
    from dsp.estimation import (AlphaBetaFilter, AlphaBetaFormats, KalmanFilter, KalmanFormats,
                                NonlinearModel, UkfFormats, UnscentedKalmanFilter, kalata,
                                tracking_index, white_jerk)
    t_start = time.perf_counter()
    steps = 20_000 if quick else 200_000
    trials = 64 if quick else 256
    bsteps = max(steps // trials * 4, 500)
    reps = 2 if quick else 3
    rng = np.random.default_rng(2026)
    T_s = 1e-3
    rows = []

    def add(name, kind, mode, make, z, n, warm):
        ups = _rate(make, z, warm, n, reps)
        rows.append({"filter": name, "arithmetic": kind, "mode": mode, "updates": int(n),
                     "updates_per_s": ups, "vs_target": ups / TARGET_UPS})
        print(f"{name:10s} {kind:8s} {mode:8s} {ups:12,.0f} upd/s ({ups / TARGET_UPS:,.0f}x target)",
              flush=True)

    # 3-state Kalman loop (phase, frequency, rate; scalar phase measurement), the INS paper's shape
    kf_model = white_jerk(T_s, q=1e3, r=0.05)
    for kind, arith in (("float64", "float64"), ("float32", "float32"), ("fixed", KalmanFormats())):
        z1 = rng.normal(0, 0.2, (steps, 1))
        add("KF n=3", kind, "1 stream", lambda a=arith: KalmanFilter(kf_model, np.zeros(3), np.eye(3), a),
            z1, steps, z1[:16])
        zb = rng.normal(0, 0.2, (trials, bsteps, 1))
        add("KF n=3", kind, f"{trials} trials",
            lambda a=arith: KalmanFilter(kf_model, np.zeros(3), np.eye(3), a, trials=trials), zb,
            trials * bsteps, zb[:, :16])
    # 4-state UKF on I/Q (the AUKF patent's shape), additive noise
    prm = np.array([[T_s, T_s ** 2 / 2, T_s ** 3 / 6]])
    ukf_model = NonlinearModel(_f_jerk, _h_iq, np.diag([1e-8, 1e-6, 1e-4, 1e-2]), np.eye(2) * 1e-2,
                               prm_f=prm, prm_h=[[1.0]])
    for kind in ("float64", "float32"):
        usteps = steps // 4
        z1 = rng.normal(0, 0.1, (usteps, 2)) + np.array([1.0, 0.0])
        mk = lambda k=kind: UnscentedKalmanFilter(ukf_model, np.zeros(4), np.eye(4) * 0.01, alpha=1.0,
                                                  beta=2.0, kappa=0.0, arithmetic=k)
        add("UKF n=4", kind, "1 stream", mk, z1, usteps, z1[:16])
        ub = max(bsteps // 4, 200)
        zb = rng.normal(0, 0.1, (trials, ub, 2)) + np.array([1.0, 0.0])
        mkb = lambda k=kind: UnscentedKalmanFilter(ukf_model, np.zeros(4), np.eye(4) * 0.01, alpha=1.0,
                                                   beta=2.0, kappa=0.0, arithmetic=k, trials=trials)
        add("UKF n=4", kind, f"{trials} trials", mkb, zb, trials * ub, zb[:, :16])
    # 4-state UKF on I/Q with augmented noise (L = 10) and the AUKF patent's UT (alpha 1.027,
    # beta 2, kappa 0): float and fixed point (the phase model of tests/dsp/estimation/test_ukf_fixed.py)
    Fp = np.array([[0.98, 0.1, 0.005, 0.0], [0, 0.95, 0.1, 0.005], [0, 0, 0.95, 0.1], [0, 0, 0, 0.95]])
    aug_model = NonlinearModel.phase_iq(Fp, np.diag([1e-3, 1e-4, 1e-5, 1e-6]), np.eye(2) * 0.05)
    for kind, arith in (("float64", "float64"), ("float32", "float32"), ("fixed", UkfFormats())):
        usteps = steps // 8
        z1 = np.stack([np.ones(usteps), np.zeros(usteps)], 1) + rng.normal(0, 0.22, (usteps, 2))
        mk = lambda a=arith: UnscentedKalmanFilter(aug_model, np.zeros(4), np.eye(4) * 0.01, alpha=1.027,
                                                   beta=2.0, kappa=0.0, noise="augmented", arithmetic=a)
        add("UKF n=4 aug", kind, "1 stream", mk, z1, usteps, z1[:16])
        ub = max(bsteps // 8, 100)
        zb = np.stack([np.ones((trials, ub)), np.zeros((trials, ub))], 2) + rng.normal(0, 0.22, (trials, ub, 2))
        mkb = lambda a=arith: UnscentedKalmanFilter(aug_model, np.zeros(4), np.eye(4) * 0.01, alpha=1.027,
                                                    beta=2.0, kappa=0.0, noise="augmented", arithmetic=a,
                                                    trials=trials)
        add("UKF n=4 aug", kind, f"{trials} trials", mkb, zb, trials * ub, zb[:, :16])
    # alpha-beta (Kalata), fixed gains and adaptive
    a, b = kalata(tracking_index(T_s, 50.0, 0.01))
    for kind, arith in (("float64", "float64"), ("float32", "float32"), ("fixed", AlphaBetaFormats())):
        for adaptive in (False, True):
            name = "alpha-beta" + (" adaptive" if adaptive else "")
            z1 = np.cumsum(rng.normal(0, 0.01, steps))
            mk = lambda ar=arith, ad=adaptive: AlphaBetaFilter(T_s, a, b, adaptive=ad, sigma_v=0.01, arithmetic=ar)
            add(name, kind, "1 stream", mk, z1, steps, z1[:16])
            zb = np.cumsum(rng.normal(0, 0.01, (trials, bsteps)), axis=1)
            mkb = lambda ar=arith, ad=adaptive: AlphaBetaFilter(T_s, a, b, adaptive=ad, sigma_v=0.01,
                                                                arithmetic=ar, trials=trials)
            add(name, kind, f"{trials} trials", mkb, zb, trials * bsteps, zb[:, :16])
    summary = {"benchmark": "estimation-speed", "machine": machine_info(), "quick": quick,
               "elapsed_s": time.perf_counter() - t_start, "target_updates_per_s": TARGET_UPS,
               "target": "1 kHz loop x 12 channels", "cores_used": 1,
               "scenario": {"T_s": T_s, "kf": "white-jerk 3-state, scalar measurement, Joseph update",
                            "ukf": "4-state phase/frequency/rate/jerk, I/Q measurement, additive noise",
                            "ukf_aug": "4-state damped phase model, I/Q, augmented noise L = 10, the AUKF patent's UT "
                                       "(alpha 1.027, beta 2, kappa 0); float and fixed (UkfFormats)",
                            "alpha_beta": "Kalata gains, fixed and adaptive (window 4, manoeuvre estimate)",
                            "single_stream_steps": steps, "batch_trials": trials},
               "rows": rows}
    write_result(out, "estimation_speed", summary, _md(summary))
    return summary


def _md(s: dict) -> str:
    m = s["machine"]
    lines = [f"Estimation library speed (`{m['command']}`, {m['date']}, {m['cpu']}, commit "
             f"{m['commit']}, one core, {s['elapsed_s']:.0f} s)", "",
             f"Target: {s['target']} = {s['target_updates_per_s']:,.0f} updates/s.", "",
             "| filter | arithmetic | mode | updates/s | x target |", "|---|---|---|---:|---:|"]
    for r in s["rows"]:
        lines.append(f"| {r['filter']} | {r['arithmetic']} | {r['mode']} | {r['updates_per_s']:,.0f} | "
                     f"{r['vs_target']:,.0f} |")
    return "\n".join(lines) + "\n"
