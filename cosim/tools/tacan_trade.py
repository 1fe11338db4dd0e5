"""The TACAN sensitivity trade in one table: what the default receiver (both peak searches)
gives a user and what it costs in word lengths, beside the single-pulse receiver.

``python -m cosim.tools.tacan_trade`` reads the published results and writes
``results/tacan_trade.md``:

* ``results/tacan_sensitivity.json`` (``python -m cosim bench tacan-sensitivity``, both
  searches, golden chain): 0 dB at every bearing, and RMSE / CRB at 3-20 dB at 90 and 270 deg;
* ``results/study_default{,_pulse}/summary.csv`` (``make study``): per SNR, at the default
  12-bit ADC, the three figures of what a user sees of the fixed-point receiver (RMSE / CRB
  of the valid bearings, availability, misleading bearings) -- the same records for both;
* ``results/study_default{,_pulse}/proposal.json`` and
  ``results/study_wordlength{,_pulse}/proposal.json`` (``make study``, ``make
  study-wordlength``): the confirmed word lengths.

A missing input leaves its cells ``-`` and is named under the table.
"""
from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

__all__ = ["trade_table", "main"]

ROOT = Path(__file__).resolve().parents[2]
ADC_BITS = 12
SNRS = (0.0, 5.0, 10.0, 15.0, 20.0)
SENS_SNRS = (3.0, 6.0, 10.0, 20.0)


def _json(path: Path):
    return json.loads(path.read_text()) if path.exists() else None


def _rows(path: Path) -> dict:
    """``summary.csv`` rows at the default ADC width by SNR."""
    if not path.exists():
        return {}
    with open(path) as f:
        return {float(r["snr_db"]): r for r in csv.DictReader(f)
                if int(float(r["adc_bits"])) == ADC_BITS}


def _num(r: dict | None, k: str):
    v = (r or {}).get(k)
    return None if v in (None, "") else float(v)


def _f(v, fmt):
    return "-" if v is None else format(v, fmt)


def _confirmed(p) -> dict:
    c = (p or {}).get("confirmation") or {}
    return (c.get("params") or {}) if c.get("confirmed") else {}


def _confirmed_in_report(path: Path) -> tuple[dict, str]:
    """The confirmed widths a study's ``report.md`` states (for a study published before it
    wrote ``proposal.json``), and its first line's provenance (command, date, commit)."""
    import re
    if not path.exists():
        return {}, ""
    text = path.read_text()
    m = re.search(r"\*\*confirmed\*\*: (.*)$", text, re.M)
    if not m:
        return {}, ""
    out = {}
    for n, v in re.findall(r"`([^`]+)`=([^,\s]+)", m.group(1)):
        try:
            out[n] = int(v)
        except ValueError:
            out[n] = v
    prov = re.search(r"(\d{4}-\d\d-\d\dT[^,]*), commit (\w+(?:-dirty)?)", text)
    return out, (f"{prov.group(1)[:10]}, commit {prov.group(2)}" if prov else "")


def _widths(results: Path, name: str, need, notes: list) -> dict:
    """The confirmed widths of ``results/<name>``: its ``proposal.json``, else (named in
    ``notes``) the confirmation its ``report.md`` states."""
    p = results / name / "proposal.json"
    if p.exists():
        return _confirmed(_json(p))
    w, prov = _confirmed_in_report(results / name / "report.md")
    if w:
        notes.append(f"`results/{name}` has no `proposal.json`: its widths are the "
                     f"confirmation its `report.md` states ({prov}), a study judged by the "
                     f"RMSE of every bearing and the lock count, not yet re-run under the "
                     f"three figures")
    else:
        need(f"{name}/proposal.json")
    return w


def trade_table(results: Path) -> tuple[list[str], list[str]]:
    """The table's lines, and the inputs it found missing with notes on the widths read
    from a report (those start with a backquote)."""
    missing = []

    def need(rel):
        p = results / rel
        if not p.exists():
            missing.append(rel)
        return p
    sens = _json(need("tacan_sensitivity.json"))
    both, pulse = (_rows(need(f"study_default{s}/summary.csv")) for s in ("", "_pulse"))
    notes: list = []
    for name, rows in (("study_default", both), ("study_default_pulse", pulse)):
        if rows and "availability" not in next(iter(rows.values())):
            notes.append(f"`results/{name}/summary.csv` predates the three figures: its RMSE "
                         f"is over every bearing after settling, flagged ones included, and it "
                         f"has no availability or misleading column")
    adc = [_widths(results, f"study_default{s}", need, notes) for s in ("", "_pulse")]
    wl = [_widths(results, f"study_wordlength{s}", need, notes) for s in ("", "_pulse")]
    L = ["| figure | both searches (default) | single pulse | both - single |",
         "|---|---|---|---|"]
    b0 = (sens or {}).get("bearing_sweep_if_0db")
    if b0:
        L.append(f"| 0 dB, every bearing ({b0['step_deg']} deg steps, {b0['duration_s']:g} s, "
                 f"golden chain): bearings given, sector slips, misleading, RMSE / CRB | "
                 f"{b0['locked']}/{b0['trials']}, {b0['sector_slips']}, "
                 f"{b0['misleading_bearings']}, {b0['rmse_over_crb']:.2f}x | - | |")
    for snr in SENS_SNRS:
        rs = [r for r in (sens or {}).get("snr_sweep", []) if r["snr_db"] == snr]
        if rs:
            L.append(f"| {snr:g} dB at " + " / ".join(f"{r['bearing_deg']:g}" for r in rs)
                     + " deg (golden chain): RMSE / CRB | "
                     + " / ".join(f"{r['rmse_over_crb']:.2f}x" for r in rs) + " | - | |")
    first = next(iter({**pulse, **both}.values()), {})
    which = "valid" if "availability" in first else "(every)"
    for snr in SNRS:
        a, b = both.get(snr), pulse.get(snr)

        def cell(r):
            if r is None:
                return "-"
            crb, rm = _num(r, "crb_deg"), _num(r, "rmse_deg")
            ratio = rm / crb if rm is not None and crb else None
            return (f"{_f(ratio, '.2f')}x, {_f(_num(r, 'availability'), '.3f')}, "
                    f"{_f(_num(r, 'misleading'), '.0f')}")
        n = _f(_num(a or b, "trials"), ".0f")
        L.append(f"| {snr:g} dB, ADC {ADC_BITS} bits, fixed point ({n} "
                 f"records): RMSE / CRB of the {which} bearings, availability, misleading | "
                 f"{cell(a)} | {cell(b)} | |")
    if adc[0] or adc[1]:
        x, y = adc[0].get("adc_bits"), adc[1].get("adc_bits")
        d = f"{x - y:+d}" if x is not None and y is not None else ""
        L.append(f"| ADC bits confirmed (0-20 dB, 20 records) | {_f(x, 'd')} | {_f(y, 'd')} "
                 f"| {d} |")
    names = [n for n in (wl[0] or wl[1]) if n != "detector"]
    tot = [0, 0]
    for n in names:
        x, y = wl[0].get(n), wl[1].get(n)
        d = f"{x - y:+d}" if x is not None and y is not None else ""
        if d:
            tot[0] += x
            tot[1] += y
        L.append(f"| `{n}` confirmed (5/10/20 dB, 10 records) | {_f(x, 'd')} | {_f(y, 'd')} "
                 f"| {d} |")
    if names:
        L.append(f"| sum of the confirmed widths | {tot[0]} | {tot[1]} | {tot[0] - tot[1]:+d} |")
    return L, missing + notes


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m cosim.tools.tacan_trade",
                                 description="write results/tacan_trade.md from the results")
    ap.add_argument("--results", type=Path, default=ROOT / "results")
    a = ap.parse_args(argv)
    a.results.mkdir(parents=True, exist_ok=True)
    lines, missing = trade_table(a.results)
    text = ["# TACAN sensitivity trade: both peak searches vs the single-pulse receiver", "",
            "Generated by `python -m cosim.tools.tacan_trade` from the published results "
            "(the module's doc names them). The default receiver runs both peak searches in "
            "the FPGA and gives a bearing at every bearing at 0 dB; the rows below set what "
            "that gives a user -- accuracy, availability, integrity -- beside what it costs "
            "in word lengths, against the single-pulse receiver (`detector=pulse`). Study "
            "rows: RMSE / CRB of the bearings shown valid, mean fraction of display epochs "
            "with a valid bearing, bearings shown valid more than 20 deg off.", "", *lines]
    absent = [m for m in missing if not m.startswith("`")]
    notes = [m for m in missing if m.startswith("`")]
    if absent:
        text += ["", "Not found (cells '-'): " + ", ".join(f"`results/{m}`" for m in absent)]
    text += [f"\n{n}." for n in notes]
    out = a.results / "tacan_trade.md"
    out.write_text("\n".join(text) + "\n")
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
