"""Monte Carlo study of the AUKF patent's trackers on the correlation-domain fast path.

For each true process-noise intensity ``q_true`` (multiples of the prior ``q0 = 5``) and
C/N0, one truth per trial is drawn from the jerk process
(``cosim.gnss.dynamics.aukf_patent_dynamics``, seeded per trial), and the trackers ``aukf``, ``ukf`` (fixed q = q0) and ``pll3`` run on the
*same* truth and the *same* correlator noise (the fast path's generator seeded alike).
Figures per (tracker, q_true, C/N0): Doppler RMSE (Hz: the tracker's Doppler estimate
against the truth; ``nco_doppler_rmse_hz`` is the replica Doppler in force, which also
carries the loop filter's phase-nulling term) and phase RMSE (cycles, wrapped to
the Costas lock point) over the second half of the run, cycle slips (total), divergences
(the tracker's own ``diverged`` flag for the UKFs; for every tracker also "lost": the
Doppler error's RMS over the last 100 ms above 5 Hz or a slip), and the median final q_hat.

Batching: one truth per trial (distinct seeded trajectories), stacked on the batch axis of
one ``track_fast`` run (:func:`stacked_truth`).
"""
from __future__ import annotations

import numpy as np

from hdl.gnss.params import DEFAULT_FS_HZ

from .dynamics import aukf_patent_dynamics
from .loopsim import cycle_slips, track_fast, truth_for

Q0 = 5.0


class DopplerRecorder:
    """A tracker wrapper keeping ``doppler_hz()`` after every step (the estimate for the
    epoch just dumped) and, for a tracker with a ``diverged`` flag (the UKFs), whether it
    was raised (``flagged``: what the receiver shows as not valid)."""

    def __init__(self, inner):
        self.inner, self.est, self.flagged = inner, [], []

    def step(self, *iq):
        out = self.inner.step(*iq)
        self.est.append(np.array(self.inner.doppler_hz(), float))
        d = getattr(self.inner, "diverged", None)
        if d is not None:
            self.flagged.append(np.array(d, bool).copy())
        return out

    def frequencies_hz(self, out):
        return self.inner.frequencies_hz(out)


def stacked_truth(truths):
    """One ``truth_at`` whose arrays carry the trials on the last axis (``track_fast``
    broadcasts them against its batch shape ``(n_runs,)``)."""
    def truth_at(t):
        parts = [tr(t) for tr in truths]
        return {k: np.stack([p[k] for p in parts], axis=-1) for k in parts[0]}
    return truth_at


def run_point(q_true: float, cn0_dbhz: float, trackers=("aukf", "ukf", "pll3"), n_runs: int = 100,
              duration_s: float = 10.0, seed: int = 1, arith=None, tracker_opts=None) -> dict:
    """Monte Carlo figures of each tracker at one ``(q_true, C/N0)``: ``n_runs`` truths (one
    per trial, batched), the same truths and noise seed for every tracker."""
    from dsp.gnss.loops_fixed import FLOAT
    from dsp.gnss.trackers import TrackerContext, make_tracker
    if isinstance(n_runs, bool) or not isinstance(n_runs, int) or n_runs < 1:
        raise ValueError(f"n_runs must be an integer >= 1, not {n_runs!r}")
    n = int(round(duration_s / 1e-3))
    half = n // 2
    truth = stacked_truth([truth_for(aukf_patent_dynamics(q=q_true), duration_s + 0.01,
                                     seed=seed * 100003 + i)
                           for i in range(n_runs)])
    a0 = truth(np.array([0.0]))
    out = {"q_true": q_true, "cn0_dbhz": cn0_dbhz, "n_runs": n_runs, "duration_s": duration_s}
    ctx = TrackerContext(fs_hz=DEFAULT_FS_HZ, doppler0_hz=a0["doppler_hz"][0],
                         doppler_rate0_hz_s=a0["doppler_rate_hz_s"][0], cn0_dbhz=cn0_dbhz)
    for t in trackers:
        opts = (tracker_opts or {}) if t in ("aukf", "ukf") else {}
        trk = DopplerRecorder(make_tracker(t, ctx, FLOAT if arith is None else arith, **opts))
        r = track_fast(truth, cn0_dbhz, n, shape=(n_runs,), seed=seed, tracker=trk)
        # the tracker's Doppler estimate at epoch k's midpoint against the epoch's mean
        # true frequency (= freq_err + the replica Doppler in force)
        est_err = r.freq_err_hz + r.doppler_hz - np.array(trk.est)
        df = est_err[half:]
        nco = r.freq_err_hz[half:]
        pe = r.phase_err_cycles[half:]
        pe = pe - 0.5 * np.rint(pe / 0.5)
        slips = cycle_slips(r.phase_err_cycles)
        lost = (slips > 0) | (np.sqrt(np.mean(r.freq_err_hz[-100:] ** 2, axis=0)) > 5.0)
        res = {"doppler_rmse_hz": float(np.sqrt(np.mean(df ** 2))),
               "nco_doppler_rmse_hz": float(np.sqrt(np.mean(nco ** 2))),
               "phase_rmse_cyc": float(np.sqrt(np.mean(pe ** 2))),
               "cycle_slips": int(slips.sum()), "lost": int(lost.sum()),
               "diverged": None, "q_hat_median_final": None}
        if hasattr(trk.inner, "report"):
            rep = trk.inner.report()
            res["diverged"] = rep["diverged_count"]
            res["q_hat_median_final"] = rep["q_hat"]["median_final"]
            res["q_hat_final"] = rep["q_hat"]["final"]
            res["q_hat_trajectory_median"] = rep["q_hat"]["trajectory_median"]
            res["events"] = rep["events"]
        out[t] = res
    return out


def study(q_factors=(0.1, 1.0, 10.0), cn0s=(32.0, 36.0, 40.0), **kw) -> list:
    return [run_point(f * Q0, c, **kw) for c in cn0s for f in q_factors]


def plot_doppler_error(path, q_factor: float = 10.0, cn0_dbhz: float = 32.0, n_runs: int = 20,
                       duration_s: float = 10.0, seed: int = 1):
    """The patent's figure 3 as a plot: RMS over runs of the Doppler-estimate error vs time,
    UKF (fixed q0) and AUKF, truth with ``q_true = q_factor q0``."""
    from ..tools.plots import pyplot, save_figure
    plt = pyplot()
    from dsp.gnss.loops_fixed import FLOAT
    from dsp.gnss.trackers import TrackerContext, make_tracker
    n = int(round(duration_s / 1e-3))
    truth = stacked_truth([truth_for(aukf_patent_dynamics(q=q_factor * Q0), duration_s + 0.01,
                                     seed=seed * 100003 + i)
                           for i in range(n_runs)])
    a0 = truth(np.array([0.0]))
    ctx = TrackerContext(fs_hz=DEFAULT_FS_HZ, doppler0_hz=a0["doppler_hz"][0],
                         doppler_rate0_hz_s=a0["doppler_rate_hz_s"][0], cn0_dbhz=cn0_dbhz)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for t in ("ukf", "aukf"):
        trk = DopplerRecorder(make_tracker(t, ctx, FLOAT))
        r = track_fast(truth, cn0_dbhz, n, shape=(n_runs,), seed=seed, tracker=trk)
        err = r.freq_err_hz + r.doppler_hz - np.array(trk.est)
        w = 50
        rms = np.sqrt(np.convolve(np.mean(err ** 2, axis=1), np.ones(w) / w, mode="same"))
        ax.plot(r.t_s, rms, label=t.upper())
    ax.set_xlabel("time (s)")
    ax.set_ylabel("Doppler error RMS (Hz)")
    ax.set_title(f"q_true = {q_factor:g} q0, {cn0_dbhz:g} dB-Hz, {n_runs} runs")
    ax.legend()
    save_figure(fig, path, dpi=100)


# -- the benchmark: python -m cosim bench aukf ------------------------------------------------
def step_rate(tracker: str, arith, batch: int = 1, n_steps: int = 2000, cn0_dbhz: float = 32.0,
              seed: int = 5) -> float:
    """Tracker epochs per second (trial-epochs/s for ``batch`` > 1), the tracker alone on
    synthetic correlations (unit noise, amplitude ``sqrt(2 T C/N0)``, a 0.3 rad residual),
    after an untimed warm-up of ``n_steps`` (numba compilation, the slave's table)."""
    import time
    from dsp.gnss.trackers import TrackerContext, make_tracker
    rng = np.random.default_rng(seed)
    A = np.sqrt(2e-3 * 10 ** (cn0_dbhz / 10))
    ctx = TrackerContext(fs_hz=DEFAULT_FS_HZ, doppler0_hz=np.zeros(batch), doppler_rate0_hz_s=np.zeros(batch),
                         cn0_dbhz=cn0_dbhz)
    w = A * np.exp(0.3j) + rng.normal(size=(n_steps, 3, batch)) + 1j * rng.normal(size=(n_steps, 3, batch))

    def go(t):
        for k in range(n_steps):
            e, p, l_ = w[k]
            t.step(e.real, e.imag, p.real, p.imag, l_.real, l_.imag)

    go(make_tracker(tracker, ctx, arith))
    t = make_tracker(tracker, ctx, arith)
    t0 = time.perf_counter()
    go(t)
    return n_steps * batch / (time.perf_counter() - t0)


def _table(points, columns) -> str:
    rows = ["| C/N0 dB-Hz | q_true / q0 | tracker | arithmetic | Doppler RMSE Hz | phase RMSE cyc | "
            "slips | lost | diverged | median q_hat |", "|---|---|---|---|---|---|---|---|---|---|"]
    for (c, f) in columns:
        for ar in ("golden", "fixed"):
            p = points[(ar, c, f)]
            for t in ("aukf", "ukf", "pll3"):
                r = p[t]
                qh = "-" if r["q_hat_median_final"] is None else f"{r['q_hat_median_final']:.3g}"
                dv = "-" if r["diverged"] is None else str(r["diverged"])
                rows.append(f"| {c:g} | {f:g} | {t} | {ar} | {r['doppler_rmse_hz']:.4f} | "
                            f"{r['phase_rmse_cyc']:.4f} | {r['cycle_slips']} | {r['lost']}/{p['n_runs']} | "
                            f"{dv} | {qh} |")
    return "\n".join(rows) + "\n"


def bench(out, quick: bool = False) -> dict:
    """``python -m cosim bench aukf``: the AUKF patent's Monte Carlo table (golden and fixed,
    PLL beside), the simulation cost and the patent's figure 3; ``results/aukf.{md,json}`` and
    ``results/aukf_doppler_error.png``."""
    import json
    import time
    from pathlib import Path
    from dsp.gnss.aukf_master import AukfFormats
    from dsp.gnss.loops_fixed import FLOAT, FixedArith
    from ..core.provenance import machine_info
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    n_runs, dur = (10, 2.0) if quick else (100, 10.0)
    cn0s = (32.0,) if quick else (32.0, 36.0, 28.0)
    factors = (0.1, 1.0, 10.0)
    t0 = time.perf_counter()
    points, cols = {}, []
    for c in cn0s:
        for f in factors:
            cols.append((c, f))
            for ar, arith in (("golden", None), ("fixed", FixedArith())):
                points[(ar, c, f)] = run_point(f * Q0, c, n_runs=n_runs, duration_s=dur, seed=1,
                                               arith=arith)
    mc_s = time.perf_counter() - t0
    cost = []
    for t in ("aukf", "ukf", "pll3"):
        for ar, arith in (("float64", FLOAT), ("fixed", FixedArith())):
            cost.append({"tracker": t, "arithmetic": ar,
                         "one_stream": step_rate(t, arith, 1, 500 if quick else 2000),
                         "batch_100": step_rate(t, arith, 100, 200 if quick else 1000)})
    fig = out / "aukf_doppler_error.png"
    plot_doppler_error(fig, n_runs=5 if quick else 20, duration_s=dur)
    m = machine_info()
    res = {"benchmark": "aukf", "machine": m, "quick": quick, "n_runs": n_runs, "duration_s": dur,
           "monte_carlo_wall_s": mc_s, "formats": repr(AukfFormats()),
           "points": [{"arith": k[0], **v} for k, v in points.items()], "cost": cost,
           "figure": fig.name}
    (out / "aukf.json").write_text(json.dumps(res, indent=1, default=float))
    (out / "aukf.md").write_text(_bench_markdown(res, points, cols))
    return res


# -- python -m cosim bench aukf-convergence: A4 (q_hat at the end of the run) vs run length ----
CONVERGENCE_S = (10.0, 30.0, 60.0)


def bench_convergence(out, quick: bool = False) -> dict:
    """``python -m cosim bench aukf-convergence``: how far the slave's ``q_hat`` has come from
    the prior ``q0`` at the end of runs of 10, 30 and 60 s (100 runs, 32 dB-Hz, q_true = 0.1,
    1 and 10 q0, golden and fixed, ``aukf`` beside the fixed-q ``ukf``), with A2/A3 on the
    same runs; ``results/aukf_convergence.{md,json}``.

    Why the run length matters: per 0.5 s block the slave's measurement carries ~0.065
    nats^2 of Fisher information on ln q at q = 0.5 (the noise floor dominates; docs/explanation/gnss_aukf.md)
    against the prior's precision 1, so after 10 s the posterior still keeps ~45 % of
    ln q0 - ln q_true; the prior is outweighed only after tens of seconds."""
    import json
    import time
    from pathlib import Path
    from dsp.gnss.loops_fixed import FixedArith
    from ..core.provenance import machine_info
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    n_runs, durs = (10, (2.0, 4.0)) if quick else (100, CONVERGENCE_S)
    factors = (0.1, 1.0, 10.0)
    rows = []
    t0 = time.perf_counter()
    for dur in durs:
        for f in factors:
            for ar, arith in (("golden", None), ("fixed", FixedArith())):
                p = run_point(f * Q0, 32.0, trackers=("aukf", "ukf"), n_runs=n_runs,
                              duration_s=dur, seed=1, arith=arith)
                a, u = p["aukf"], p["ukf"]
                qf = np.asarray(a["q_hat_final"], float).ravel()
                rows.append({"duration_s": dur, "q_factor": f, "q_true": f * Q0, "arith": ar,
                             "aukf_doppler_rmse_hz": a["doppler_rmse_hz"],
                             "ukf_doppler_rmse_hz": u["doppler_rmse_hz"],
                             "q_hat_median": float(np.median(qf)),
                             "q_hat_q25": float(np.percentile(qf, 25)),
                             "q_hat_q75": float(np.percentile(qf, 75)),
                             "diverged": a["diverged"] + u["diverged"],
                             "slips": a["cycle_slips"] + u["cycle_slips"]})
    wall = time.perf_counter() - t0
    res = {"benchmark": "aukf-convergence", "machine": machine_info(), "quick": quick,
           "n_runs": n_runs, "cn0_dbhz": 32.0, "q0": Q0, "wall_s": wall, "rows": rows}
    (out / "aukf_convergence.json").write_text(json.dumps(res, indent=1, default=float))
    (out / "aukf_convergence.md").write_text(_convergence_markdown(res))
    return res


def _convergence_markdown(res) -> str:
    m = res["machine"]
    L = ["# The AUKF patent's tracker: q_hat at the end of the run vs run length (A4)", "",
         f"Machine: {m['cpu']} ({m['cores']} cores, shared), {m['host']}; date {m['date']}; "
         f"commit {m['commit']}; command `{m['command']}` ({res['wall_s']:.0f} s wall).", "",
         f"{res['n_runs']} runs per row, {res['cn0_dbhz']:g} dB-Hz, q0 = {res['q0']:g}, the fast path "
         "and truths of `python -m cosim bench aukf` (one jerk-process truth per run, R from C/N0, "
         "RMSEs over the second half of each run); A4 = median final q_hat within x2 of q_true; "
         "A2 = AUKF Doppler RMSE < UKF's (0.1 and 10 q0); A3 = AUKF <= 1.1 x UKF (q0).", "",
         "| run s | q_true / q0 | arithmetic | median q_hat (25-75 %) | q_hat / q_true | A4 | "
         "AUKF Doppler RMSE Hz | UKF Hz | AUKF/UKF | A2/A3 | diverged | slips |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        ratio = r["q_hat_median"] / r["q_true"]
        a4 = "met" if 0.5 <= ratio <= 2.0 else "not met"
        rr = r["aukf_doppler_rmse_hz"] / r["ukf_doppler_rmse_hz"]
        a23 = ("met" if rr <= 1.1 else "not met") if r["q_factor"] == 1.0 else \
              ("met" if rr < 1.0 else "not met")
        L.append(f"| {r['duration_s']:g} | {r['q_factor']:g} | {r['arith']} | {r['q_hat_median']:.3g} "
                 f"({r['q_hat_q25']:.3g}-{r['q_hat_q75']:.3g}) | {ratio:.2f} | {a4} | "
                 f"{r['aukf_doppler_rmse_hz']:.4f} | {r['ukf_doppler_rmse_hz']:.4f} | {rr:.3f} | {a23} | "
                 f"{r['diverged']} | {r['slips']} |")
    L += ["", "At 0.1 q0 the slave's measurement is dominated by its noise floor (~0.065 nats^2 of "
          "information on ln q per 0.5 s block against the prior's 1, docs/explanation/gnss_aukf.md), so q_hat "
          "leaves q0 slowly: compare the rows of one q_true across run lengths.", ""]
    return "\n".join(L)


def _bench_markdown(res, points, cols) -> str:
    m = res["machine"]
    L = ["# The AUKF patent's trackers: Monte Carlo on the correlation-domain fast path", "",
         f"Machine: {m['cpu']} ({m['cores']} cores, shared), {m['host']}; date {m['date']}; "
         f"commit {m['commit']}; command `{m['command']}` (Monte Carlo {res['monte_carlo_wall_s']:.0f} s "
         "wall under `nice -n 19`).", "",
         f"{res['n_runs']} runs x {res['duration_s']:g} s per point, one jerk-process truth per run "
         "(aukf_patent_dynamics(q = q_true), alpha 0.1/s, x0 = 1000 m/s, 1 g), the same truths and noise for every "
         "tracker and arithmetic: aukf, ukf (q fixed at q0 = 5), pll3 (Bn 15 Hz); golden = float64, "
         f"fixed = `AukfFormats()` word lengths for the UKFs (`{res['formats']}`) and the "
         "fixed-point `ChannelCore` for pll3; R from C/N0; RMSEs over the second half of each run "
         "(Doppler: the tracker's estimate vs the epoch's mean true frequency); lost = a slip or the "
         "last 100 ms Doppler RMS > 5 Hz (truth-based); diverged = the tracker's own rule "
         "(docs/explanation/gnss_aukf.md: phase test + narrow/wide-band frequency test). Phase RMSE wrapped to the "
         "Costas lock point (count the slips).", "",
         _table(points, cols), "",
         "Fixed vs golden, largest relative difference of the Doppler RMSE over the points: " + ", ".join(
             f"{t} {max(abs(points[('fixed',) + k][t]['doppler_rmse_hz'] / points[('golden',) + k][t]['doppler_rmse_hz'] - 1) for k in cols):.1e}"
             for t in ("aukf", "ukf", "pll3")) + "; Cholesky failures / P not PD / saturations "
         "in the fixed UKFs (all points): " + ", ".join(
             f"{t} {sum(points[('fixed',) + k][t]['events'][e] for k in cols)}" for t in ("aukf", "ukf")
             for e in ("chol_fail",)) + " / " + ", ".join(
             f"{t} {sum(points[('fixed',) + k][t]['events']['s_not_pd'] for k in cols)}/"
             f"{sum(points[('fixed',) + k][t]['events']['saturations'] for k in cols)}" for t in ("aukf", "ukf")) + ".", "",
         "## Cost of one tracker step (epochs/s; trial-epochs/s batched)", "",
         "The tracker alone on synthetic correlations, after an untimed warm-up (numba, the slave's "
         "table); a machine shared with other jobs: indicative.", "",
         "| tracker | arithmetic | 1 stream | batch 100 |", "|---|---|---|---|"]
    for r in res["cost"]:
        L.append(f"| {r['tracker']} | {r['arithmetic']} | {r['one_stream']:,.0f} | {r['batch_100']:,.0f} |")
    L += ["", "## Figure 3 of the patent", "",
          f"`{res['figure']}`: RMS over runs (50-epoch moving window) of the Doppler-estimate error vs "
          "time, UKF (q fixed at q0) and AUKF, q_true = 10 q0, 32 dB-Hz, golden.", ""]
    return "\n".join(L)
