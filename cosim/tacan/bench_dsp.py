"""DSP-core benchmarks: fixed-point Kalman core speed, and one simulated hour of tracking.

``dsp-speed``  updates/s of the bearing filter (the one source, :mod:`dsp.tacan.kalman`) in
               fixed point and in float: one stream, and Monte Carlo trials batched on one
               core and on all cores; plus the naive fxpmath approach (quantise every
               operation with ``Fxp`` objects) on a short run, for comparison.
``dsp-hour``   one simulated hour through the whole bit-exact chain on the streaming
               pipeline (:mod:`cosim.core.pipeline`): IF records (3 s each, a continuous
               rotation phase) -> HDL front-end model session -> FIFO model -> DSP FIFO
               receiver -> fixed-point DSP, all with carried state: bearing error per
               minute, core events, smallest eigenvalue of P, FIFO drops.

Both write ``results/<name>.json`` and ``.md`` with the machine, date and command.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..core.provenance import machine_info, write_result

TICK_HZ = 20e6


def _pulses(duration_s: float, bearings, seed: int = 1, snr_db: float = 10.0):
    from .signal import TacanSignalConfig, pulse_observations
    cfg = TacanSignalConfig(duration_s=duration_s, snr_db=snr_db, seed=seed)
    t, amps, _ = pulse_observations(cfg, np.asarray(bearings, dtype=float))
    ticks = np.round(t * TICK_HZ).astype(np.int64)
    dts = np.diff(ticks, prepend=ticks[:1])
    return dts, amps


def _best_rate(make, dts, ys, reps: int = 3) -> float:
    """Best updates/s over ``reps`` fresh filters (the first call compiles or loads)."""
    make().run(dts[:64], ys[:, :64])
    best = math.inf
    for _ in range(reps):
        kf = make()
        t0 = time.perf_counter()
        kf.run(dts, ys)
        best = min(best, time.perf_counter() - t0)
    return ys.size / best


def fxpmath_naive_rate(dts_ticks, ys, cfg=None, n_steps: int = 150) -> float:
    """Updates/s of the filter written naively with fxpmath: every matrix operation is done
    on the values and re-quantised into an ``Fxp`` of the core's format (what a first port
    of a float model with a fixed-point library looks like). Same formats as the core; no
    gate or r estimate (it only makes it slower)."""
    from fxpmath import Fxp
    from dsp.tacan.standard import F15
    from dsp.tacan.kalman_config import KalmanFixedConfig
    from dsp.tacan.standard import F135
    cfg = cfg or KalmanFixedConfig()

    def fmt(f):
        return dict(signed=True, n_word=f.width, n_frac=f.frac, overflow="saturate",
                    rounding="around")

    tx, tP, tK, tcs, ti = (fmt(getattr(cfg, n)) for n in ("x", "P", "K", "cs", "innov"))
    q_rot, q_dc = cfg.kalman.q_rates()
    H = np.array([1.0, 0, 1, 0, 1])
    x = Fxp(np.zeros(5), **tx)
    P = Fxp(np.eye(5) * cfg.kalman.p0, **tP)
    n = min(n_steps, len(dts_ticks))
    t0 = time.perf_counter()
    for k in range(n):
        dt = dts_ticks[k] / cfg.tick_hz
        a, b = 2 * np.pi * F15 * dt, 2 * np.pi * F135 * dt
        A = np.zeros((5, 5))
        A[4, 4] = 1.0
        A[0, 0], A[0, 1], A[1, 0], A[1, 1] = math.cos(a), math.sin(a), -math.sin(a), math.cos(a)
        A[2, 2], A[2, 3], A[3, 2], A[3, 3] = math.cos(b), math.sin(b), -math.sin(b), math.cos(b)
        Aq = Fxp(A, **tcs)
        xp = Fxp(Aq.get_val() @ x.get_val(), **tx)
        M = Fxp(Aq.get_val() @ P.get_val(), **tP)
        Pp = Fxp(M.get_val() @ Aq.get_val().T + np.diag([q_rot * dt] * 4 + [q_dc * dt]), **tP)
        PH = Fxp(Pp.get_val() @ H, **tP)
        S = Fxp(H @ PH.get_val() + 1.0, **tP)
        K = Fxp(PH.get_val() / S.get_val(), **tK)
        iv = Fxp(ys[0, k] - H @ xp.get_val(), **ti)
        x = Fxp(xp.get_val() + K.get_val() * iv.get_val(), **tx)
        P = Fxp(Pp.get_val() - np.outer(K.get_val(), PH.get_val()), **tP)
    return n / (time.perf_counter() - t0)


def dsp_speed(out: Path, quick: bool = False) -> dict:
    from dsp.tacan.kalman import EnvelopeKalman
    from dsp.tacan.kalman_config import KalmanConfig, KalmanFixedConfig
    import numba
    t_start = time.perf_counter()
    fcfg, kcfg = KalmanFixedConfig(), KalmanConfig()
    dur1 = 0.5 if quick else 4.0
    dts1, y1 = _pulses(dur1, [90.0])
    B = 64 if quick else 1000
    durB = 0.25 if quick else 1.0
    bearings = np.linspace(0, 360, B, endpoint=False)
    dtsB, yB = _pulses(durB, bearings, seed=2)
    threads = numba.config.NUMBA_NUM_THREADS
    rows = {
        "fixed_single": _best_rate(lambda: EnvelopeKalman(fcfg, 1), dts1, y1),
        "float_single": _best_rate(lambda: EnvelopeKalman(kcfg, 1), dts1, y1),
        "fixed_batched_1core": _best_rate(lambda: EnvelopeKalman(fcfg, B, parallel=False), dtsB, yB,
                                          reps=2),
        "fixed_batched_all_cores": _best_rate(lambda: EnvelopeKalman(fcfg, B, parallel=True), dtsB,
                                              yB, reps=2),
        "float_batched_all_cores": _best_rate(lambda: EnvelopeKalman(kcfg, B, parallel=True), dtsB,
                                              yB, reps=2),
        "fxpmath_naive_single": fxpmath_naive_rate(dts1, y1, fcfg, n_steps=60 if quick else 300),
    }
    real_time = 7200.0   # pulses/s of a beacon (3600 pairs/s)
    summary = {
        "benchmark": "dsp-speed", "machine": machine_info(), "quick": quick,
        "numba_threads": threads, "elapsed_s": None,
        "workload": {"single_stream_updates": int(y1.size), "batch_trials": B,
                     "batch_updates": int(yB.size), "snr_db": 10.0,
                     "formats": {n: str(getattr(fcfg, n)) for n in
                                 ("y", "x", "P", "K", "cs", "innov", "r")}},
        "updates_per_s": rows,
        "ratios": {
            "fixed_single_over_fxpmath": rows["fixed_single"] / rows["fxpmath_naive_single"],
            "fixed_single_over_real_time": rows["fixed_single"] / real_time,
            "float_over_fixed_single": rows["float_single"] / rows["fixed_single"],
            "all_cores_over_1core": rows["fixed_batched_all_cores"] / rows["fixed_batched_1core"],
        },
        "targets": {"fixed_single": 36_000, "fixed_batched_aggregate": 3_600_000},
    }
    summary["elapsed_s"] = time.perf_counter() - t_start
    write_result(out, "dsp_speed", summary, _speed_md(summary))
    return summary


def _speed_md(s: dict) -> str:
    m, u, r = s["machine"], s["updates_per_s"], s["ratios"]
    lines = [f"Fixed-point TACAN Kalman core speed (`{m['command']}`, {m['date']}, {m['cpu']}, "
             f"{m['cores']} cores, numba threads {s['numba_threads']}, commit {m['commit']})", "",
             "| configuration | updates/s | target |", "|---|---:|---:|",
             f"| fixed, one stream | {u['fixed_single']:,.0f} | 36,000 |",
             f"| float (same source), one stream | {u['float_single']:,.0f} | |",
             f"| fixed, {s['workload']['batch_trials']} trials, one core | "
             f"{u['fixed_batched_1core']:,.0f} | |",
             f"| fixed, {s['workload']['batch_trials']} trials, all cores | "
             f"{u['fixed_batched_all_cores']:,.0f} | 3,600,000 |",
             f"| float, {s['workload']['batch_trials']} trials, all cores | "
             f"{u['float_batched_all_cores']:,.0f} | |",
             f"| naive fxpmath (quantise every operation), one stream | "
             f"{u['fxpmath_naive_single']:,.0f} | |", "",
             f"Fixed core: {r['fixed_single_over_fxpmath']:,.0f}x the naive fxpmath filter, "
             f"{r['fixed_single_over_real_time']:,.0f}x real time (7200 pulses/s); "
             f"all cores / one core: {r['all_cores_over_1core']:.2f}."]
    return "\n".join(lines) + "\n"


def _if_block(k: int, block_s: float, bearing: float, snr_db: float) -> np.ndarray:
    """ADC codes of block ``k`` (worker process): an independent 3 s record whose main
    references continue the rotation of the blocks before it (an integer number of 15 Hz
    periods per block), so the blocks play back as one continuous beacon."""
    from .signal import TacanSignalConfig, generate
    cfg = TacanSignalConfig(duration_s=block_s, snr_db=snr_db, seed=10_000 + k,
                            bearing_deg=bearing)
    return generate(cfg).samples


class _TacanBatchDsp:
    """The DSP side of ``dsp-hour`` as a pipeline callback: the FIFO receiver on the words of
    every loop period (its state carried), the fixed-point DSP on each batch of
    ``batch_cycles`` (its state carried), statistics per batch. Open loop: no writes."""

    def __init__(self, params, rc, fs_hz: float, batch_cycles: int, loop_cycles: int,
                 bearing: float, t_start: float):
        self.params, self.rc, self.fs = params, rc, fs_hz
        self.batch_cycles, self.loop_cycles = batch_cycles, loop_cycles
        self.bearing, self.t_start = bearing, t_start
        self.settle = 2 * rc.kalman.kalman.memory_s
        self.rx_state = self.dsp_state = self.prev_ev = None
        self.acc_t, self.acc_a, self.rows, self.all_err = [], [], [], []
        self.t_rx = self.t_dsp = 0.0

    def __call__(self, call):
        from dsp.tacan.fifo_rx import receive_words
        p = self.params
        t0 = time.perf_counter()
        ts, amp, self.rx_state = receive_words(call.words, width=p.fifo.width,
                                               amp_width=p.peak.amp_width,
                                               ts_bits=p.peak.ts_bits, state=self.rx_state,
                                               parity=p.fifo.parity)
        self.acc_t.append(ts + np.int64(p.decimation - 1))
        self.acc_a.append(amp)
        self.t_rx += time.perf_counter() - t0
        if ((call.index + 1) * self.loop_cycles) % self.batch_cycles == 0:
            self._batch(call.session)
        return ()

    def _batch(self, session):
        from dsp.tacan.bearing import wrap_deg
        from dsp.tacan.receiver import amplitude_codes, process_peaks
        p, rc = self.params, self.rc
        t3 = time.perf_counter()
        ticks = np.concatenate(self.acc_t)
        y = amplitude_codes(np.concatenate(self.acc_a), p.scale_to_fs, rc.kalman.y)
        self.acc_t, self.acc_a = [], []
        tr = process_peaks(ticks / self.fs, y, rc, ticks=ticks, state=self.dsp_state)
        self.dsp_state = tr.state
        self.t_dsp += time.perf_counter() - t3
        keep = tr.times_s >= self.settle
        err = wrap_deg(tr.bearing_deg[0, keep] - self.bearing)
        self.all_err.append(err)
        kf = self.dsp_state.kf
        P = kf.P_float()[0]
        ev = {k2: int(v[0]) for k2, v in tr.events.items()}
        prev = self.prev_ev
        new_ev = ev if prev is None else {k2: ev[k2] - prev[k2] for k2 in ev}
        self.prev_ev = ev
        self.rows.append({"minute": len(self.rows) + 1, "bearings": int(err.size),
                          "rmse_deg": float(np.sqrt(np.mean(err ** 2))) if err.size else None,
                          "max_abs_error_deg": float(np.abs(err).max()) if err.size else None,
                          "P_min_eig": float(np.linalg.eigvalsh(P).min()),
                          "P_symmetric": bool((kf.P[0] == kf.P[0].T).all()),
                          "fifo_dropped": int(session.read("overflow_count")),
                          "events": {k2: v for k2, v in new_ev.items() if v}})
        r = self.rows[-1]
        rmse = "-" if r["rmse_deg"] is None else f"{r['rmse_deg']:.3f}"
        print(f"batch {len(self.rows)}: {r['bearings']} bearings, RMSE {rmse} deg, P min eig "
              f"{r['P_min_eig']:.3g}, {time.perf_counter() - self.t_start:.0f} s", flush=True)


def dsp_hour(out: Path | None, quick: bool = False, *, simulated_s: float | None = None,
             block_s: float = 3.0, batch_s: float = 60.0, loop_s: float = 0.1) -> dict:
    """One simulated hour through the whole bit-exact chain, on the streaming pipeline
    (:class:`cosim.core.pipeline.Pipeline` with the front-end model session): IF blocks of
    ``block_s`` -> front end + FIFO (default DSP service) -> the FIFO receiver every
    ``loop_s`` -> the fixed-point DSP every ``batch_s`` (a "minute" row each).

    ``quick``: one minute. ``simulated_s`` overrides the length (a whole number of blocks
    and of batches; the tests run a few seconds). ``out=None`` writes no files.
    """
    from concurrent.futures import ProcessPoolExecutor
    from dsp.tacan.kalman_config import KalmanConfig, KalmanFixedConfig
    from dsp.tacan.receiver import ReceiverConfig
    from hdl.tacan.params import TacanFrontendParams
    from ..core.link import DspServiceConfig
    from ..core.pipeline import Pipeline
    from ..backends.factory import open_frontend
    from .signal import TacanSignalConfig
    from dsp.tacan.frontend import FrontendConfig

    t_start = time.perf_counter()
    simulated_s = (60.0 if quick else 3600.0) if simulated_s is None else float(simulated_s)
    n_blocks = int(round(simulated_s / block_s))
    bearing, snr = 90.0, 10.0
    sig0 = TacanSignalConfig(duration_s=block_s, snr_db=snr, bearing_deg=bearing)
    params = TacanFrontendParams(config=FrontendConfig.for_signal(sig0), adc_bits=sig0.adc_bits)
    svc = DspServiceConfig()
    rc = ReceiverConfig(kalman=KalmanFixedConfig(kalman=KalmanConfig(tick_hz=sig0.fs_hz)))
    fs, n_blk = sig0.fs_hz, sig0.n_samples
    batch_cycles = int(round(batch_s * fs))
    spc = int(round(loop_s * fs)) // svc.period_cycles
    loop_cycles = spc * svc.period_cycles
    if (n_blocks < 1 or abs(n_blocks * block_s - simulated_s) > 1e-9 or spc < 1
            or batch_cycles % loop_cycles or (n_blocks * n_blk) % batch_cycles):
        raise ValueError(f"dsp-hour needs a whole number of {block_s} s blocks, of "
                         f"{batch_s} s batches and of {loop_s} s loop periods (whole DSP "
                         f"services) in {simulated_s} s")
    dsp = _TacanBatchDsp(params, rc, fs, batch_cycles, loop_cycles, bearing, t_start)
    t_feed = 0.0
    with open_frontend("model", params) as fe, ProcessPoolExecutor(max_workers=1) as pool:
        pipe = Pipeline(fe, svc, dsp, services_per_call=spc, keep_words=False)
        fut = pool.submit(_if_block, 0, block_s, bearing, snr)
        for k in range(n_blocks):
            x = fut.result()
            if k + 1 < n_blocks:     # generate the next block while this one is processed
                fut = pool.submit(_if_block, k + 1, block_s, bearing, snr)
            t0 = time.perf_counter()
            pipe.feed(x)
            t_feed += time.perf_counter() - t0
            del x
        res = pipe.result()
        n_peaks = fe.n_peaks
    err = np.concatenate(dsp.all_err)
    ev_total = dsp.prev_ev or {}
    rows, dsp_state = dsp.rows, dsp.dsp_state
    totals = {"peaks": int(n_peaks), "fifo_words": int(res.n_words),
              "fifo_dropped": int(res.overflow_count), "rx": dict(dsp.rx_state.stats)}
    simulated = n_blocks * block_s
    elapsed = time.perf_counter() - t_start
    summary = {
        "benchmark": "dsp-hour", "machine": machine_info(), "quick": quick,
        "elapsed_s": elapsed,
        "scenario": {"simulated_s": simulated, "block_s": block_s, "batch_s": batch_s,
                     "loop_s": loop_s, "snr_db": snr,
                     "bearing_deg": bearing, "mode": "X", "dsp": "fixed",
                     "chain": f"IF signal ({block_s:g} s records played back to back) -> "
                              f"streaming pipeline: bit-exact HDL front-end model session -> "
                              f"FIFO model (default DSP service) -> DSP FIFO receiver every "
                              f"{loop_s:g} s (32-bit timestamps unwrapped) -> fixed-point "
                              f"DSP ({batch_s:g} s batches)"},
        "updates": int(dsp_state.kf.n_updates),
        "bearings": int(err.size),
        "rmse_deg": float(np.sqrt(np.mean(err ** 2))) if err.size else None,
        "max_abs_error_deg": float(np.abs(err).max()) if err.size else None,
        "P_min_eig_min": min(r["P_min_eig"] for r in rows),
        "P_always_symmetric": all(r["P_symmetric"] for r in rows),
        "events_total": ev_total,
        "totals": totals,
        "digest": res.digest,
        "timestamp_wraps": int(simulated * fs / 2 ** params.peak.ts_bits),
        "seconds": {"frontend_model": t_feed - dsp.t_rx - dsp.t_dsp, "link_and_rx": dsp.t_rx,
                    "dsp": dsp.t_dsp},
        "diverged": bool(ev_total.get("reinit", 0) or ev_total.get("p_neg", 0)),
        "minutes": rows,
    }
    if out is not None:
        write_result(out, "dsp_hour", summary, _hour_md(summary))
    return summary


def _f3(v) -> str:
    return "-" if v is None else f"{v:.3f}"


def _hour_md(s: dict) -> str:
    m = s["machine"]
    ev = ", ".join(f"{k} {v}" for k, v in s["events_total"].items() if v) or "none"
    sec = s["seconds"]
    sim_s = s["scenario"]["simulated_s"]
    what = "One simulated hour" if sim_s == 3600 else f"{sim_s:g} simulated seconds"
    return (f"{what} through the bit-exact chain (`{m['command']}`, {m['date']}, "
            f"{m['cpu']}, commit {m['commit']}, {s['elapsed_s']:.0f} s wall)\n\n"
            f"{s['scenario']['chain']}; SNR {s['scenario']['snr_db']:g} dB, bearing "
            f"{s['scenario']['bearing_deg']:g} deg.\n\n"
            f"{s['scenario']['simulated_s']:.0f} s simulated ({s['timestamp_wraps']} timestamp "
            f"wraps), {s['totals']['peaks']:,} peaks, {s['updates']:,} Kalman updates, "
            f"{s['bearings']:,} bearings: RMSE {_f3(s['rmse_deg'])} deg, worst "
            f"{_f3(s['max_abs_error_deg'])} deg; FIFO drops {s['totals']['fifo_dropped']}; "
            f"smallest eigenvalue of P over the run {s['P_min_eig_min']:.3g} (> 0: positive "
            f"definite), P symmetric: {s['P_always_symmetric']}; core events: {ev}; "
            f"diverged: {s['diverged']}. Time: front-end and FIFO models "
            f"{sec['frontend_model']:.0f} s, "
            f"FIFO receiver {sec['link_and_rx']:.0f} s, DSP {sec['dsp']:.0f} s (the IF "
            f"generation runs in a second process).\n")
