"""A sweep's plots and Markdown report (:func:`cosim.studies.sweep.write_report` writes them):
per parameter, the three figures of what a user sees (:mod:`cosim.studies.shown`) beside the
float golden chain's; every setting's row with its intervals and verdict; the ranges and
overflows; the proposal (and which figure decided each width) and its confirmation.
"""
from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from .proposal import failing
from .spec import SweepConfig, primary_key, sweep_model

__all__ = ["plot", "report_md", "ci_text", "proposal_record", "main"]


def ci_text(ci, fmt: str = ".3f") -> str:
    return "-" if not ci else f"{ci[0]:{fmt}}-{ci[1]:{fmt}}"


def _fmt(v, fmt):
    return "-" if v is None else format(v, fmt)


def plot(cfg: SweepConfig, rows, out: Path) -> list[str]:
    """One figure per swept parameter (the others at their reference): accuracy (RMSE of
    the valid estimates; dashed the golden chain's, dotted the CRB), availability and the
    misleading estimates, per SNR."""
    from ..tools.plots import pyplot, save_figure
    plt = pyplot()
    from cosim.core.receivers import get
    P, fig_m = primary_key(cfg.receiver), get(cfg.receiver).primary
    names = [n for n, _ in cfg.params]
    ref = cfg.reference
    files = []
    for n, vals in cfg.params:
        if len(vals) < 2:           # held fixed (e.g. detector=pulse): nothing to plot
            continue
        fig, (ax, av, mi) = plt.subplots(3, 1, figsize=(7, 8), sharex=True,
                                         gridspec_kw={"height_ratios": [2, 1, 1]})
        numeric = all(isinstance(x, (int, float)) for x in vals)
        xs = list(vals) if numeric else list(range(len(vals)))
        for ci, snr in enumerate(cfg.snr_db):
            sel = {r[n]: r for r in rows if r["snr_db"] == float(snr)
                   and all(r[m] == ref[m] for m in names if m != n)}

            def ys(key):
                return [sel[v][key] if v in sel and sel[v].get(key) is not None else np.nan
                        for v in vals]
            col = f"C{ci}"
            ax.semilogy(xs, ys(P), "o-", color=col, label=f"{snr:g} dB")
            g = [sel[v]["golden_" + P] for v in vals if v in sel and sel[v]["golden_" + P]]
            if g:
                ax.axhline(float(np.median(g)), color=col, ls="--", lw=1)
            c = [sel[v]["crb_deg"] for v in vals if v in sel and sel[v].get("crb_deg")]
            if c:
                ax.axhline(float(c[0]), color=col, ls=":", lw=1)
            av.plot(xs, ys("availability"), "o-", color=col)
            av.plot(xs, ys("golden_availability"), "--", color=col, lw=1)
            mi.plot(xs, ys("misleading"), "o-", color=col)
            mi.plot(xs, ys("golden_misleading"), "--", color=col, lw=1)
        if not numeric:
            mi.set_xticks(xs, [str(v) for v in vals])
        mi.set_xlabel(n)
        ax.set_ylabel(f"{fig_m.label}\nof valid estimates ({fig_m.unit})", fontsize=8)
        av.set_ylabel("availability\n(epochs valid)", fontsize=8)
        av.set_ylim(-0.05, 1.05)
        mi.set_ylabel("misleading\nestimates", fontsize=8)
        from matplotlib.ticker import MaxNLocator
        mi.yaxis.set_major_locator(MaxNLocator(integer=True))
        mi.set_ylim(bottom=-0.5)
        others = ", ".join(f"{m}={ref[m]}" for m in names if m != n)
        sub = "\n".join(textwrap.wrap(f"others at {others}", 95)) + "\n" if others else ""
        ax.set_title(f"{cfg.receiver.upper()}: accuracy, availability, integrity vs {n}\n{sub}"
                     "dashed: float golden (same records)   dotted: Cramer-Rao bound",
                     fontsize=8)
        for a in (ax, av, mi):
            a.grid(True, which="both", alpha=0.3)
        ax.legend(title="SNR", fontsize=8)
        fn = f"rmse_vs_{n.replace('.', '_')}.png"
        save_figure(fig, out / fn)
        files.append(fn)
    return files


def _rule(cfg: SweepConfig) -> str:
    return (f"accuracy: the paired RMSE of the estimates shown valid within "
            f"{100 * cfg.target_rel:g} % of the golden chain's; availability: the fraction of "
            f"epochs with a valid estimate not below the golden chain's by more than "
            f"{cfg.availability_margin:g}; integrity: no misleading estimate the golden chain "
            f"does not also make on the same record; and no more filter re-initialisations "
            f"than the golden filter")


def _decided_by(cfg: SweepConfig, rows, n, v) -> str:
    """What the next smaller swept value of ``n`` below the proposal ``v`` failed on."""
    names = [m for m, _ in cfg.params]
    ref = cfg.reference
    smaller = sorted(x for x in dict(cfg.params)[n] if x < v)
    if not smaller:
        return ""
    below = smaller[-1]
    figs = []
    for r in rows:
        if r[n] == below and all(r[m] == ref[m] for m in names if m != n):
            for f in failing(r, cfg.target_rel, cfg.availability_margin):
                if f not in figs:
                    figs.append(f)
    return f" ({below} fails: {', '.join(figs)})" if figs else ""


def report_md(cfg: SweepConfig, s: dict, plots: list[str]) -> str:
    m = s["machine"]
    P = primary_key(cfg.receiver)
    names = [n for n, _ in cfg.params]
    f = _fmt
    model = sweep_model(cfg.receiver)
    lines = [f"# {model.title}", "",
             f"`{m['command']}` on {m['cpu']} ({m['cores']} cores), {m['date']}, commit "
             f"{m['commit']}: {s['n_points']} points in {s['elapsed_s']:.0f} s"
             + (f" ({s['from_cache']} of them read from the cache of an earlier run)"
                if s.get("from_cache") else "") + ".", "",
             f"Swept: " + "; ".join(f"`{n}` = {', '.join(map(str, v))}" for n, v in cfg.params) +
             f"; SNR {', '.join(f'{x:g}' for x in cfg.snr_db)} dB; {cfg.trials} trials of "
             f"{cfg.duration_s:g} s (filter memory {cfg.memory_s:g} s). {model.description}",
             "",
             "Every point is judged as a user sees it, beside the float golden chain on the "
             "same records: **accuracy** (RMSE and mean error of the estimates shown valid, "
             "after settling), **availability** (the fraction of display epochs after "
             "settling whose latest estimate is valid; time to first valid estimate), "
             "**integrity** (misleading estimates: shown valid and beyond the receiver's "
             f"error bound). {model.shown_note}", ""]
    for p in plots:
        lines += [f"![{p}]({p})", ""]
    lines += ["## Every setting", "",
              "Valid: trials with a valid estimate after settling (golden). Ratio: paired "
              "RMSE ratio to the golden chain, with its 95 % bootstrap interval over the "
              "trials. Avail.: mean fraction of epochs valid (golden), and the paired "
              "difference's 95 % interval. First valid: median time to the first valid "
              "estimate. Misleading: count (golden) and the rate per valid estimate's 95 % "
              "Wilson interval. Verdict: the figures the point fails (proposal's test).", "",
              "| " + " | ".join(names) + " | SNR dB | valid | RMSE | golden RMSE | ratio | "
              "ratio 95 % CI | mean err | CRB | avail. | avail. diff CI | first valid s | "
              "misleading | rate CI | ADC clipped | FIFO drops | DSP saturations | verdict |",
              "|" + "---|" * (len(names) + 17)]
    for r in s["rows"]:
        sat = sum(v for k, v in r["dsp_events"].items() if k.startswith("sat_"))
        inv = f" ({r['invalid']})" if r["invalid"] else ""
        fails = failing(r, cfg.target_rel, cfg.availability_margin)
        lines.append(
            "| " + " | ".join(str(r[n]) for n in names) +
            f" | {r['snr_db']:g} | {r['locked']}/{r['trials']} ({r['golden_locked']}){inv} | "
            f"{f(r[P], '.4f')} | {f(r['golden_' + P], '.4f')} | "
            f"{f(r['ratio_to_golden'], '.3f')} | {ci_text(r.get('ratio_ci95'))} | "
            f"{f(r['mean_error'], '+.4f')} | {f(r['crb_deg'], '.4f')} | "
            f"{f(r['availability'], '.3f')} ({f(r['golden_availability'], '.3f')}) | "
            f"{ci_text(r.get('availability_diff_ci95'), '+.3f')} | "
            f"{f(r['first_valid_s'], '.3f')} | {f(r['misleading'], 'd')} "
            f"({f(r['golden_misleading'], 'd')}) | "
            f"{ci_text(r.get('misleading_rate_ci95'), '.2g')} | {r['adc_clipped']} | "
            f"{r['fifo_dropped']} | {sat} | {'pass' if not fails else ', '.join(fails)} |")
    lines += ["", "## Ranges and overflows (all points)", "",
              "Smallest and largest value each signal took over every point (front end `fe.*` "
              "as a fraction of its word's full scale (FS); fixed-point DSP `dsp.*` in real "
              "units, before saturation), the word's range and the least headroom (unused "
              "MSBs) over the points, and the overflow/saturation count (`fe.adc`: samples "
              "clipped).", "",
              "| signal | min | max | unit | word range | least headroom bits | "
              "overflows/saturations |", "|---|---:|---:|---|---:|---:|---:|"]
    for k, v in sorted(s["ranges"].items()):
        rng = "-" if v["lo"] is None else f"[{v['lo']:.4g}, {v['hi']:.4g}]"
        lines.append(f"| {k} | {f(v['min'], '.4g')} | {f(v['max'], '.4g')} | {v['unit']} | "
                     f"{rng} | {f(v['headroom_bits'], '.1f')} | {v['overflows']} |")
    lines += ["", "## Word-length proposal", "",
              f"Smallest value of each parameter (the others at their largest swept value) "
              f"such that it and every larger value meet, at every SNR, {_rule(cfg)}. The "
              f"accuracy ratio may also be not significantly above its target (the lower end "
              f"of its 95 % bootstrap interval is); accuracy, availability and re-inits are "
              f"judged where the golden chain shows a valid estimate on >= 80 % of the "
              f"trials, integrity everywhere. In brackets: what the next smaller value "
              f"failed on.", ""]
    lows = {n: min(v) for n, v in cfg.params if all(isinstance(x, (int, float)) for x in v)}
    for n, v in s["proposal"].items():
        note = ""
        if v is not None and v == lows.get(n):
            note = " (the smallest value swept: the true minimum may be lower, extend the range)"
        elif v is not None:
            note = _decided_by(cfg, s["rows"], n, v)
        lines.append(f"- `{n}`: {v if v is not None else 'none in the swept range'}{note}")
    lines += _confirmation_md(cfg, s, P)
    cr = (s.get("confirmation") or {}).get("recheck")
    if s["rechecks"] or cr:
        lines += ["", "## Cycle-accurate re-checks", ""]
    if cr:
        lines.append(f"- the confirmed combination {cr['combo']}: {cr.get('backend')} on "
                     f"{cr.get('samples', 0)} samples, {cr.get('words', 0)} FIFO words, same "
                     f"bits: {cr.get('same_bits')}" + (f" ({cr['error']})" if cr.get("error")
                                                       else ""))
    for c in s["rechecks"]:
        lines.append(f"- {c['combo']}: {c.get('backend')} on {c.get('samples', 0)} samples, "
                     f"{c.get('words', 0)} FIFO words, same bits: {c.get('same_bits')}"
                     + (f" ({c['error']})" if c.get("error") else ""))
    return "\n".join(lines) + "\n"


def _confirmation_md(cfg: SweepConfig, s: dict, P: str) -> list[str]:
    c = s.get("confirmation")
    if not c:
        return []
    f = _fmt
    lines = ["", f"Confirmation re-run (fresh seeds, all values together; stricter: the "
                 f"measured accuracy ratio itself within {100 * cfg.target_rel:g} %, and as "
                 f"in the proposal availability within {cfg.availability_margin:g} of the "
                 f"golden chain's, no misleading estimate it does not also make, no more "
                 f"filter re-initialisations; on failure each parameter alone one swept step "
                 f"wider, the nearest kept for the next round; last, every parameter at its "
                 f"widest): **{'confirmed' if c['confirmed'] else 'NOT confirmed'}**"
             + (f" ({c.get('reason')})" if c.get("reason") else "")
             + (": " + ", ".join(f"`{n}`={v}" for n, v in c["params"].items())
                if c.get("confirmed") else "")]
    for i, a in enumerate(c.get("attempts", [])):
        w = a.get("widened")
        how = "" if w is None else (" (every parameter at its widest)" if w == "all"
                                    else f" (`{w}` one step wider)")
        lines += ["", f"Attempt {i + 1}{how}: " + ", ".join(f"`{n}`={v}" for n, v in
                                                            a["params"].items())
                  + f" -- {'confirmed' if a['confirmed'] else 'not confirmed'}"]
        for r in a["rows"]:
            ev = r.get("dsp_events") or {}
            fails = failing(r, cfg.target_rel, cfg.availability_margin, strict=True)
            lines.append(
                f"- SNR {r['snr_db']:g} dB: accuracy {f(r[P], '.4f')} vs golden "
                f"{f(r['golden_' + P], '.4f')} (ratio {f(r['ratio_to_golden'], '.3f')}, "
                f"95 % CI {ci_text(r.get('ratio_ci95'))}); availability "
                f"{f(r['availability'], '.3f')} vs {f(r['golden_availability'], '.3f')} "
                f"(diff CI {ci_text(r.get('availability_diff_ci95'), '+.3f')}); misleading "
                f"{f(r['misleading'], 'd')} vs {f(r['golden_misleading'], 'd')} (beyond "
                f"golden {r['excess_misleading']}); re-inits {ev.get('reinit', 0)} (golden "
                f"{r.get('golden_reinit', 0)})" + (f" -- fails {', '.join(fails)}"
                                                   if fails else ""))
    return lines


#: The figures of a row :func:`proposal_record` keeps (the three of what a user sees).
RECORD_KEYS = ("snr_db", "trials", "locked", "golden_locked", "ratio_to_golden", "ratio_ci95",
               "availability", "golden_availability", "availability_diff", "first_valid_s",
               "misleading", "golden_misleading", "excess_misleading", "crb_deg")


def proposal_record(s: dict) -> dict:
    """The published summary of a study (``proposal.json``, beside its report): the command,
    the proposal, the confirmation's verdict and widths with its rows' three figures -- what
    the tables that compare studies read (:mod:`cosim.tools.tacan_trade`)."""
    from cosim.core.receivers import get
    cfg = s["config"]
    P = get(cfg["receiver"]).primary.key
    keep = lambda r: {**{k: r.get(k) for k in RECORD_KEYS}, "accuracy": r.get(P),
                      "golden_accuracy": r.get("golden_" + P)}
    c = s.get("confirmation") or {}
    m = s["machine"]
    return {"receiver": cfg["receiver"], "command": m["command"], "commit": m["commit"],
            "date": m["date"], "elapsed_s": s["elapsed_s"], "primary": P,
            "params": cfg["params"], "target_rel": cfg["target_rel"],
            "availability_margin": cfg.get("availability_margin"),
            "proposal": s["proposal"],
            "confirmation": {"confirmed": c.get("confirmed"), "params": c.get("params"),
                             "reason": c.get("reason"),
                             "attempts": len(c.get("attempts", [])),
                             "rows": [keep(r) for r in c.get("rows", [])]} if c else None,
            "rows": [{**{n: r[n] for n, _ in cfg["params"]}, **keep(r)} for r in s["rows"]]}


def main(argv=None) -> int:
    """``python -m cosim.studies.report DIR``: (re)write ``DIR/proposal.json`` from the
    study's ``DIR/summary.json``."""
    import argparse
    import json
    from cosim.core.validate import dumps
    ap = argparse.ArgumentParser(prog="python -m cosim.studies.report", description=main.__doc__)
    ap.add_argument("dir", type=Path)
    a = ap.parse_args(argv)
    s = json.loads((a.dir / "summary.json").read_text())
    (a.dir / "proposal.json").write_text(dumps(proposal_record(s), indent=1))
    print(a.dir / "proposal.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
