"""``python -m cosim bench gnss-acquisition``: detection probability of the acquisition
against C/N0, the time it takes, and its false-alarm rate on noise.

Trials (:func:`trial`): a GPS L1 C/A signal from :class:`cosim.gnss.signal.GnssSignalGenerator`
(the receiver's own sample path: real IF, white noise, the 2-bit ADC with its AGC, 50 bit/s
data), at :data:`FS_HZ` / :data:`IF_HZ`, PRN, Doppler (uniform within
``+-MAX_DOPPLER_HZ``, constant), code phase and carrier phase drawn per trial from its seed;
converted to 2.046 MS/s zero IF by :class:`dsp.gnss.dwell.Baseband` and searched by
:func:`dsp.gnss.dwell.sequential_search` with the stated ``pfa`` per search:

* the default search (:data:`dsp.gnss.dwell.DEFAULT_SCHEDULE`, limit 500 ms), its time to
  detect (signal consumed at the deciding look) and its detection probability by the end
  of each of its dwells;
* fixed dwells (:data:`FIXED`: 1 ms x 5 and 2 ms x 20, the ``gnss`` command's former
  searches).

A detection counts if it is the right one: Doppler within one bin (the dwell's bin width)
and code phase within 1 chip of the truth at the dwell's start; any other detection is a
wrong one (reported apart). Noise-only trials (the same generator with
``signal_present=False``) run every test of each search (``stop=False``); each gives
``p_min`` (:class:`dsp.gnss.dwell.SearchOutcome`), so the false-alarm rate is measured at
every ``pfa`` of :data:`PFA_CHECK` from the same trials, with its Clopper-Pearson 95 %
interval; the stated ``pfa`` is a union bound over correlated cells and looks, so the
measured rate must not exceed it (its interval's lower end <= ``pfa``).

Written to ``results/gnss_acquisition.json`` / ``.md`` (and ``.png`` if matplotlib is
there) with the machine, date, command and commit.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy import stats

from ..core.provenance import machine_info, map_jobs, write_result

#: Front end of the trials: 6.138 MS/s real, IF fs / 4, 2-bit ADC (decimated by 3 to the
#: search's 2.046 MS/s).
FS_HZ, IF_HZ, ADC_BITS = 6.138e6, 1.5345e6, 2
CN0_DBHZ = (26.0, 28.0, 30.0, 32.0, 34.0, 36.0, 38.0, 40.0)
TRIALS, QUICK_TRIALS = 100, 8
NOISE_TRIALS, QUICK_NOISE_TRIALS = 100, 6
MAX_DOPPLER_HZ = 5000.0
PFA = 1e-3
#: Fixed single dwells compared with the default search (coherent ms, sums).
FIXED = ((1, 5), (2, 20))
PFA_CHECK = (1e-3, 1e-2, 0.05, 0.1, 0.2)
#: The goal: detection probability at 30 dB-Hz within the 0.5 s limit.
GOAL_CN0_DBHZ, GOAL_PD = 30.0, 0.9
BASE_SEED = 20261205


class _Stream:
    """The trial's zero-IF samples at the search rate, converted once as the searches ask
    for more (each stretch as :meth:`dsp.gnss.dwell.Baseband.ms` gives it)."""

    def __init__(self, bb):
        self.bb, self.y = bb, np.zeros(0, np.complex128)
        self.N = int(round(bb.fs_d * 1e-3))

    def ms(self, k0, k1):
        have = self.y.size // self.N
        if k1 > have:
            self.y = np.concatenate([self.y, self.bb.ms(have, k1)])
        return self.y[k0 * self.N:k1 * self.N]


def trial(cn0_dbhz: float | None, index: int) -> dict:
    """One trial: the default search and the fixed dwells on the same signal (``cn0_dbhz``
    None: noise only, every test run). Deterministic in (``cn0_dbhz``, ``index``)."""
    from dsp.gnss.dwell import (DEFAULT_LIMIT_MS, DEFAULT_SCHEDULE, Baseband, fixed_schedule,
                                sequential_search)
    from dsp.gnss.ephemeris import L1_WAVELENGTH_M
    from .dynamics import PolynomialProfile
    from .signal import GnssSignalConfig, GnssSignalGenerator
    key = 0 if cn0_dbhz is None else int(round(cn0_dbhz * 10))
    rng = np.random.default_rng(np.random.SeedSequence(BASE_SEED, spawn_key=(key, index)))
    prn = int(rng.integers(1, 33))
    dop = float(rng.uniform(-MAX_DOPPLER_HZ, MAX_DOPPLER_HZ))
    sig = GnssSignalConfig(
        prn=prn, if_hz=IF_HZ, fs_hz=FS_HZ, adc_bits=ADC_BITS,
        cn0_dbhz=40.0 if cn0_dbhz is None else float(cn0_dbhz),
        duration_s=DEFAULT_LIMIT_MS * 1e-3 + 0.02,
        dynamics=PolynomialProfile(range_rate_mps=-dop * L1_WAVELENGTH_M),
        code_phase_chips=float(rng.uniform(0, 1023)),
        carrier_phase_cycles=float(rng.uniform(0, 1)),
        signal_present=cn0_dbhz is not None, seed=int(rng.integers(0, 2 ** 31)))
    gen = GnssSignalGenerator(sig)
    bb = Baseband(lambda a, n: gen.samples(a, n)[0].astype(np.float64), sig.n_samples,
                  sig.fs_hz, sig.digital_if_hz, sig.spectrum_inverted)
    st = _Stream(bb)
    noise = cn0_dbhz is None
    searches = {"default": DEFAULT_SCHEDULE}
    searches.update({f"{t}x{k}": fixed_schedule(t, k) for t, k in FIXED})
    out = {"prn": prn, "doppler_hz": dop}
    for name, sched in searches.items():
        r = sequential_search(st.ms, bb.fs_d, prn, sched, DEFAULT_LIMIT_MS, PFA,
                              MAX_DOPPLER_HZ, stop=not noise)
        row = {"detected": r.detected, "p_min": r.p_min, "n_tests": r.n_tests}
        if r.detected and not noise:
            tr = gen.truth_at([r.start_ms * 1e-3])
            dc = (r.code_phase_chips - tr["code_phase_chips"][0] + 511.5) % 1023 - 511.5
            row.update(right=bool(abs(r.doppler_hz - tr["doppler_hz"][0]) <= r.bin_width_hz
                                  and abs(dc) <= 1.0),
                       t_detect_s=r.t_detect_ms * 1e-3, stage=r.stage)
        out[name] = row
    return out


def _ci(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Clopper-Pearson interval of a binomial proportion."""
    a = 1 - level
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def summarise(rows: dict, noise: list, stage_ends_ms: list) -> dict:
    """The figures of the trials: per C/N0 and search, detection probability (right
    detections) with its interval, wrong detections, mean time to detect; the default
    search's probability by the end of each dwell; the false-alarm rates on noise."""
    names = list(next(iter(rows.values()))[0].keys() - {"prn", "doppler_hz"})
    names.sort(key=lambda s: (s != "default", s))
    pd_rows = []
    for cn0, trials in rows.items():
        n = len(trials)
        for name in names:
            res = [t[name] for t in trials]
            k = sum(1 for r in res if r.get("right"))
            wrong = sum(1 for r in res if r["detected"] and not r.get("right"))
            tt = [r["t_detect_s"] for r in res if r.get("right")]
            lo, hi = _ci(k, n)
            row = {"cn0_dbhz": cn0, "search": name, "trials": n, "pd": k / n, "pd_ci_lo": lo,
                   "pd_ci_hi": hi, "wrong": wrong,
                   "mean_t_detect_s": float(np.mean(tt)) if tt else None}
            if name == "default":
                for si, end in enumerate(stage_ends_ms):
                    row[f"pd_by_{end}ms"] = sum(1 for r in res if r.get("right")
                                                and r["stage"] <= si) / n
            pd_rows.append(row)
    fa_rows = []
    nn = len(noise)
    for name in names:
        for p in PFA_CHECK:
            k = sum(1 for t in noise if t[name]["p_min"] < p)
            lo, hi = _ci(k, nn)
            fa_rows.append({"search": name, "pfa_stated": p, "trials": nn, "false_alarms": k,
                            "rate": k / nn, "ci_lo": lo, "ci_hi": hi,
                            "within_ci": bool(lo <= p <= hi), "not_above": bool(lo <= p)})
    goal = next(r for r in pd_rows if r["search"] == "default"
                and r["cn0_dbhz"] == GOAL_CN0_DBHZ) if GOAL_CN0_DBHZ in rows else None
    return {"pd": pd_rows, "false_alarm": fa_rows,
            "goal": None if goal is None else {
                "cn0_dbhz": GOAL_CN0_DBHZ, "pd_target": GOAL_PD, "pd": goal["pd"],
                "met": bool(goal["pd"] >= GOAL_PD)},
            "false_alarm_not_above_stated": all(r["not_above"] for r in fa_rows)}


def _one(item):
    return trial(*item)


def gnss_acquisition(out: Path, quick: bool = False, jobs: int | None = 1) -> dict:
    """Run the benchmark (module docstring) on ``jobs`` processes and write its results to
    ``out``."""
    from dsp.gnss.dwell import DEFAULT_LIMIT_MS, DEFAULT_SCHEDULE, schedule_within
    n_sig = QUICK_TRIALS if quick else TRIALS
    n_noise = QUICK_NOISE_TRIALS if quick else NOISE_TRIALS
    t0 = time.time()
    items = [(c, i) for c in CN0_DBHZ for i in range(n_sig)] + \
        [(None, i) for i in range(n_noise)]
    res_all = map_jobs(jobs or 1, _one, items, "gnss-acquisition trials")
    rows = {c: res_all[j * n_sig:(j + 1) * n_sig] for j, c in enumerate(CN0_DBHZ)}
    noise = res_all[len(CN0_DBHZ) * n_sig:]
    ends, used = [], 0
    for d in schedule_within(DEFAULT_SCHEDULE, DEFAULT_LIMIT_MS):
        used += d.span_ms()
        ends.append(used)
    res = {"machine": machine_info(), "benchmark": "gnss-acquisition", "quick": quick,
           "front_end": {"fs_hz": FS_HZ, "if_hz": IF_HZ, "adc_bits": ADC_BITS,
                         "search_rate_hz": 2.046e6, "nav_data": True},
           "pfa_per_search": PFA, "max_doppler_hz": MAX_DOPPLER_HZ,
           "limit_ms": DEFAULT_LIMIT_MS,
           "default_schedule": [str(d) for d in DEFAULT_SCHEDULE],
           "default_dwell_ends_ms": ends, "fixed_dwells": [f"{t} ms x {k}" for t, k in FIXED],
           "signal_trials_per_cn0": n_sig, "noise_trials": n_noise,
           **summarise(rows, noise, ends), "jobs": jobs or 1,
           "wall_s": round(time.time() - t0, 1)}
    out = Path(out)
    write_result(out, "gnss_acquisition", res, _markdown(res))
    _plot(res, out / "gnss_acquisition.png")
    return res


def _markdown(r: dict) -> str:
    m = r["machine"]
    fe = r["front_end"]
    lines = ["# GNSS acquisition: detection probability, time to detect, false alarms", "",
             f"Measured {m['date']} on {m['host']} ({m['cpu']}, {m['cores']} cores, shared), "
             f"commit {m['commit']}, command `{m['command']}`; {r['wall_s']:g} s.", "",
             f"Trials: generated IF at {fe['fs_hz'] / 1e6:g} MS/s (IF {fe['if_hz'] / 1e6:g} "
             f"MHz, {fe['adc_bits']}-bit ADC, 50 bit/s data), random PRN, Doppler (+-"
             f"{r['max_doppler_hz']:g} Hz), code and carrier phase; searched at "
             f"{fe['search_rate_hz'] / 1e6:g} MS/s, pfa {r['pfa_per_search']:g} per search. "
             f"{r['signal_trials_per_cn0']} trials per C/N0, {r['noise_trials']} noise-only.",
             "", f"Default search: {'; '.join(r['default_schedule'])} (limit {r['limit_ms']} "
             f"ms; dwells end at {', '.join(str(e) for e in r['default_dwell_ends_ms'])} ms). "
             f"Fixed dwells: {', '.join(r['fixed_dwells'])}.", ""]
    if r.get("goal"):
        g = r["goal"]
        lines += [f"Goal: Pd >= {g['pd_target']} at {g['cn0_dbhz']:g} dB-Hz within the limit: "
                  f"Pd {g['pd']:.2f} ({'met' if g['met'] else 'NOT met'}).", ""]
    lines += ["| C/N0 dB-Hz | search | Pd | 95 % CI | wrong | mean time to detect (s) |",
              "|---|---|---|---|---|---|"]
    for x in r["pd"]:
        t = "-" if x["mean_t_detect_s"] is None else f"{x['mean_t_detect_s']:.3f}"
        lines.append(f"| {x['cn0_dbhz']:g} | {x['search']} | {x['pd']:.2f} | "
                     f"{x['pd_ci_lo']:.2f}-{x['pd_ci_hi']:.2f} | {x['wrong']} | {t} |")
    lines += ["", "False alarms on noise (a search reports the absent PRN), by stated pfa:", "",
              "| search | pfa stated | false alarms / trials | rate | 95 % CI | not above |",
              "|---|---|---|---|---|---|"]
    for x in r["false_alarm"]:
        lines.append(f"| {x['search']} | {x['pfa_stated']:g} | {x['false_alarms']} / "
                     f"{x['trials']} | {x['rate']:.3f} | {x['ci_lo']:.3f}-{x['ci_hi']:.3f} | "
                     f"{'yes' if x['not_above'] else 'NO'} |")
    return "\n".join(lines) + "\n"


def _plot(r: dict, path: Path) -> None:
    try:
        from ..tools.plots import pyplot, save_figure
        plt = pyplot()
    except ImportError:
        return
    fig, ax = plt.subplots(figsize=(6, 4))
    for name in dict.fromkeys(x["search"] for x in r["pd"]):
        xs = [x for x in r["pd"] if x["search"] == name]
        ax.plot([x["cn0_dbhz"] for x in xs], [x["pd"] for x in xs], "o-", label=name)
    ax.axhline(GOAL_PD, color="gray", lw=0.5)
    ax.set_xlabel("C/N0 (dB-Hz)")
    ax.set_ylabel(f"detection probability (pfa {r['pfa_per_search']:g} per search)")
    ax.legend()
    ax.grid(alpha=0.3)
    save_figure(fig, path, dpi=100)


__all__ = ["gnss_acquisition", "trial", "summarise", "CN0_DBHZ", "FIXED", "PFA"]
