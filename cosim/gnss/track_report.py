"""What a multi-channel run (:func:`cosim.gnss.multichannel.track_file`) gives the user, per
PRN: the JSON (:func:`summarise`), the terminal table (:func:`table`) and the plots
(:func:`write_plots`).

Per assignment (a PRN on a channel, :class:`cosim.gnss.multichannel.Assignment`):

* ``doppler_hz``: the tracker's Doppler averaged over the last lock window;
  ``doppler_rate_hz_s``: the slope of a straight line through the tracker's Doppler over the
  records of the windows in lock (all records up to the last window if none was);
* ``code_phase_chips``: the prompt's code phase at the recording's last 1 ms grid sample
  before the last record (the acquisition's convention: the code phase at a whole ms of the
  recording's clock), that sample's time ``code_phase_at_s``;
* ``cn0_dbhz``: M2M4 (:func:`dsp.gnss.cn0.cn0_m2m4`, data-insensitive) on the prompts of
  the windows in lock, at most the last :data:`CN0_RECORDS`; ``windows``: per lock window
  its time, PLI, C/N0 and the phase and C/N0 locks; ``locked_at_end``: both locks in the
  last window; ``tail_cn0_dbhz``: M2M4 on the records after the last window (the end of
  the recording; None if fewer than :data:`MIN_TAIL`), which shows a loss too recent for a
  window to have judged it;
* ``lock_time_s``: from the hand-over to the window that confirmed lock;
* ``nav_bits``: the navigation-bit transitions seen in the windows in lock: bit synchronisation by the
  histogram of prompt sign changes over the record index mod 20 (the bit edge is where most
  changes fall), then the sign of each whole 20-record bit; a transition is a sign change
  between consecutive bits (its time: the boundary between them). Too few sign changes to
  place the edge (< :data:`MIN_EDGE_CHANGES`) gives ``synchronised: false``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dsp.gnss.ca_code import CODE_PERIOD_S

__all__ = ["summarise", "table", "write_plots", "nav_bits", "CN0_RECORDS", "MIN_EDGE_CHANGES",
           "MIN_TAIL"]

#: Prompts the final C/N0 is estimated on (at most; the last ones of the windows in lock).
CN0_RECORDS = 1000
#: Records after the last lock window needed to report their C/N0 (``tail_cn0_dbhz``).
MIN_TAIL = 10
#: Sign changes needed at the winning position mod 20 to declare bit synchronisation.
MIN_EDGE_CHANGES = 2


def nav_bits(t, ip) -> dict:
    """Bit synchronisation and transitions of prompt in-phase values ``ip`` at times ``t``
    (one per 1 ms record, in order; module doc)."""
    ip = np.asarray(ip, float)
    t = np.asarray(t, float)
    if ip.size < 40:
        return {"synchronised": False, "count": 0, "times_s": [], "edge_phase": None}
    s = np.sign(ip)
    ch = np.nonzero(s[1:] != s[:-1])[0] + 1            # record index starting a new sign
    hist = np.bincount(ch % 20, minlength=20)
    k = int(np.argmax(hist))
    if hist[k] < MIN_EDGE_CHANGES:
        return {"synchronised": False, "count": 0, "times_s": [], "edge_phase": None}
    first = k
    nb = (ip.size - first) // 20
    bits = np.sign(ip[first:first + 20 * nb].reshape(nb, 20).sum(axis=1))
    tr = np.nonzero(bits[1:] != bits[:-1])[0] + 1
    times = [float(t[first + 20 * j]) for j in tr]
    return {"synchronised": True, "count": int(tr.size), "times_s": times,
            "edge_phase": k, "bits": int(nb), "edge_changes": int(hist[k]),
            "sign_changes": int(ch.size)}


def _one(a, fs_hz: float) -> dict:
    from dsp.gnss.cn0 import cn0_m2m4
    n_ms = int(round(fs_hz * CODE_PERIOD_S))
    t = np.asarray(a.t)
    dop = np.asarray(a.doppler)
    prompt = np.asarray(a.ip) + 1j * np.asarray(a.qp)
    # the records of the lock windows that had both locks, and those after the last window
    edges = [-np.inf] + list(a.win_t)
    good = np.zeros(t.size, bool)
    for k, ok in enumerate(np.logical_and(a.win_phase_lock, a.win_cn0_lock)):
        if ok:
            good |= (t > edges[k]) & (t <= edges[k + 1])
    tail = t > edges[-1]
    use = good if good.sum() >= 2 else ~tail
    rate = float(np.polyfit(t[use], dop[use], 1)[0]) if use.sum() >= 2 else None
    last_w = (t > edges[-2]) & (t <= edges[-1]) if a.win_t else np.ones(t.size, bool)
    p_cn0 = prompt[use][-CN0_RECORDS:]
    c = a.candidate
    out = {
        "prn": a.prn, "channel": a.channel, "status": a.status, "end_reason": a.end_reason,
        "start_s": a.start_sample / fs_hz,
        "end_s": None if a.end_sample is None else a.end_sample / fs_hz,
        "lock_time_s": None if a.lock_sample is None else
        (a.lock_sample - a.start_sample) / fs_hz,
        "locked_at_s": None if a.lock_sample is None else a.lock_sample / fs_hz,
        "handover": {"source": c.source, "doppler_hz": c.doppler_hz,
                     "code_phase_chips": c.code_phase_chips, "cn0_dbhz": c.cn0_dbhz,
                     "ref_sample": c.n_ref},
        "n_records": int(t.size),
        "doppler_hz": float(dop[last_w].mean()) if last_w.any() else None,
        "doppler_rate_hz_s": rate,
        "code_phase_chips": float(a.code_phase[-1]) if a.code_phase else None,
        "code_phase_at_s": (int(round(t[-1] * fs_hz)) // n_ms) * n_ms / fs_hz
        if t.size else None,
        "cn0_dbhz": float(cn0_m2m4(p_cn0, CODE_PERIOD_S)) if p_cn0.size >= 2 else None,
        "tail_records": int(tail.sum()),
        "tail_cn0_dbhz": float(cn0_m2m4(prompt[tail], CODE_PERIOD_S))
        if tail.sum() >= MIN_TAIL else None,
        "pli": a.win_pli[-1] if a.win_pli else None,
        "phase_lock": a.win_phase_lock[-1] if a.win_phase_lock else False,
        "cn0_lock": a.win_cn0_lock[-1] if a.win_cn0_lock else False,
        "windows": {"t_s": a.win_t, "pli": a.win_pli, "cn0_dbhz": a.win_cn0,
                    "phase_lock": a.win_phase_lock, "cn0_lock": a.win_cn0_lock,
                    "doppler_hz": [float(dop[(t > t0) & (t <= t1)].mean())
                                   for t0, t1 in zip([-np.inf] + a.win_t[:-1], a.win_t)]},
        "nav_bits": nav_bits(t[good], np.asarray(a.ip)[good]),
    }
    out["locked_at_end"] = bool(out["phase_lock"] and out["cn0_lock"])
    return out


def summarise(m, recording: dict | None = None, acquisition: dict | None = None) -> dict:
    """The JSON of a :class:`cosim.gnss.multichannel.MultiTrack` (module doc)."""
    asg = [_one(a, m.fs_hz) for a in m.assignments]
    dur = m.n_samples / m.fs_hz
    pres = m.pipeline
    return {
        "recording": recording, "acquisition": acquisition,
        "channels": m.channels, "backend": m.backend, "tracker": m.tracker, "dsp": m.dsp,
        "duration_s": dur, "n_samples": m.n_samples,
        "tracked": sorted({a["prn"] for a in asg if a["status"] == "tracked"}),
        "dropped": sorted({a["prn"] for a in asg if a["status"] == "dropped"}),
        "lost": sorted({a["prn"] for a in asg if a["status"] == "lost"}),
        "assignments": asg, "reacquisitions": m.reacquisitions,
        "fifo_dropped": int(pres.overflow_count or 0),
        "dropped_reported": int(m.rx_stats.get("dropped_reported", 0)),
        "broken_records": int(m.rx_stats.get("broken_records", 0)),
        "wall_s": round(m.wall_s, 2),
        "channel_samples_per_s": m.channels * m.n_samples / m.wall_s if m.wall_s else None,
        "real_time_factor": dur / m.wall_s if m.wall_s else None,
        "digest": pres.digest,
    }


def table(s: dict) -> str:
    """The terminal table of a :func:`summarise` result."""
    lines = [f"{s['channels']} channels, backend {s['backend']}, tracker {s['tracker']} "
             f"({s['dsp']}), {s['duration_s'] * 1e3:.1f} ms in {s['wall_s']:.1f} s "
             f"({s['real_time_factor']:.3g} x real time)",
             f"{'PRN':>4} {'ch':>3} {'status':>8} {'Doppler Hz':>11} {'rate Hz/s':>10} "
             f"{'code chips':>11} {'C/N0':>6} {'PLI':>6} {'lock':>5} {'lock s':>7} "
             f"{'bits':>5}"]
    for a in s["assignments"]:
        f = (lambda v, fmt: "-" if v is None else format(v, fmt))
        lk = ("P" if a["phase_lock"] else "-") + ("C" if a["cn0_lock"] else "-")
        nb = a["nav_bits"]
        lines.append(f"{a['prn']:>4} {a['channel']:>3} {a['status']:>8} "
                     f"{f(a['doppler_hz'], '.1f'):>11} {f(a['doppler_rate_hz_s'], '.1f'):>10} "
                     f"{f(a['code_phase_chips'], '.3f'):>11} {f(a['cn0_dbhz'], '.1f'):>6} "
                     f"{f(a['pli'], '.2f'):>6} {lk:>5} {f(a['lock_time_s'], '.3f'):>7} "
                     f"{(str(nb['count']) if nb['synchronised'] else '-'):>5}"
                     + (f"  {a['end_reason']}" if a["end_reason"] else "")
                     + (f"  (last {a['tail_records']} records, after the last window: C/N0 "
                        f"{a['tail_cn0_dbhz']:.1f})" if a["tail_cn0_dbhz"] is not None else ""))
    lines.append(f"tracked {len(s['tracked'])}: {s['tracked']}; dropped {s['dropped']}; "
                 f"lost {s['lost']}; re-acquisitions {len(s['reacquisitions'])}; FIFO dropped "
                 f"{s['fifo_dropped']}; digest {s['digest']['all']}")
    return "\n".join(lines)


def write_plots(m, out_dir) -> list[str]:
    """Doppler and C/N0 against time per PRN and the prompt I/Q scatter, as PNG files in
    ``out_dir``; returns their paths."""
    from ..tools.plots import pyplot, save_figure
    plt = pyplot()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    asg = [a for a in m.assignments if a.t]
    n = max(1, len(asg))
    cols = min(4, n)
    rows = -(-n // cols)
    paths = []
    fig, ax = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.4 * rows), squeeze=False)
    for k, a in enumerate(asg):
        x = ax[k // cols][k % cols]
        x.plot(a.t, a.doppler, lw=0.8)
        x.set_title(f"PRN {a.prn} (ch {a.channel})", fontsize=8)
        x.set_xlabel("t (s)", fontsize=7)
        x.set_ylabel("Doppler (Hz)", fontsize=7)
        x.tick_params(labelsize=6)
    paths.append(save_figure(fig, out / "doppler.png"))
    fig, x = plt.subplots(figsize=(7, 4))
    for a in asg:
        if a.win_t:
            x.plot(a.win_t, a.win_cn0, marker="o", ms=3, label=f"PRN {a.prn}")
    x.set_xlabel("t (s)")
    x.set_ylabel("C/N0 (dB-Hz, M2M4 per lock window)")
    x.legend(fontsize=6, ncol=3)
    paths.append(save_figure(fig, out / "cn0.png"))
    fig, ax = plt.subplots(rows, cols, figsize=(2.6 * cols, 2.6 * rows), squeeze=False)
    for k, a in enumerate(asg):
        x = ax[k // cols][k % cols]
        x.plot(a.ip, a.qp, ".", ms=1.5)
        x.set_title(f"PRN {a.prn} prompt I/Q", fontsize=8)
        x.set_aspect("equal", "datalim")
        x.tick_params(labelsize=6)
    paths.append(save_figure(fig, out / "prompt_iq.png"))
    return paths
