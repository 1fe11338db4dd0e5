"""``python -m cosim synth --all``: the command, its record (``results/synth.json``) and
the merge of a run of some tops and seeds into it. The tools and the scheduler are in
:mod:`cosim.tools.synth`."""
from __future__ import annotations

import json
import time
from pathlib import Path

from . import synth as S

__all__ = ["all_tops", "run_all", "merge"]


def all_tops(receivers) -> dict:
    """Every registered top: each receiver's ``tops`` (Verilog name -> builder), in registry
    order (the GNSS receiver's: 1 and 12 channels, real IF and complex I/Q input)."""
    return {name: make for rx in receivers for name, make in (rx.tops or {}).items()}


def run_all(a, receivers) -> int:
    """``python -m cosim synth --all``: :func:`cosim.tools.synth.synth_all` over
    :func:`all_tops`, printed as a table; ``--results DIR`` writes ``DIR/synth.json`` (with
    ``--tops``, merged into the file there by :func:`merge`); the run's own record is in
    ``--out``/synth.json either way. Exit 1 when a run failed or a top misses the target
    at a seed."""
    from ..core.provenance import machine_info
    for flag, value in (("--top", a.top), ("--seed", a.seed), ("--channels", a.channels),
                        ("--variant", a.variant)):
        if value is not None:
            raise ValueError(f"--all builds every top at every --seeds: drop {flag}")
    try:
        seeds = [int(s) for s in a.seeds.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"--seeds takes comma-separated integers, not {a.seeds!r}") from None
    if not seeds or len(set(seeds)) != len(seeds) or min(seeds) < 0:
        raise ValueError(f"--seeds takes distinct seeds >= 0, not {a.seeds!r}")
    from ..core.validate import check_jobs
    jobs = check_jobs(a.jobs)
    tops = all_tops(receivers)
    if a.tops is not None:
        names = [n.strip() for n in a.tops.split(",") if n.strip()]
        unknown = [n for n in names if n not in tops]
        if unknown or not names:
            raise ValueError(f"--tops takes names among {', '.join(tops)}, not {a.tops!r}")
        tops = {n: tops[n] for n in tops if n in names}
    machine = machine_info()            # date and commit of the code the run starts with
    say = (lambda msg: None) if a.json else \
        (lambda msg: print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True))
    versions = S.tool_versions()

    def record(r: dict) -> dict:
        for row in r["tops"] + r["runs"]:
            row["commit"] = machine["commit"]
        n = len(tops)
        return {"benchmark": "synthesis of every top", "device": a.device,
                "netlists": r.get("netlists", {}),
                "target_mhz": a.target_mhz, "router": a.router,
                "tmg_ripup": not a.no_tmg_ripup, "seeds": r["seeds"], "jobs": r["jobs"],
                "wall_s": r["wall_s"], "tool_cpu_s": r["tool_cpu_s"],
                "complete": r["complete"],
                "all_met_at_median": len(r["tops"]) == n and
                all(t["met_at_median"] for t in r["tops"]),
                "all_met_all_seeds": len(r["tops"]) == n and
                all(t["met_all_seeds"] for t in r["tops"]),
                "tools": versions, "tops": r["tops"], "runs": r["runs"],
                "failures": r["failures"], "machine": machine}

    Path(a.out).mkdir(parents=True, exist_ok=True)
    partial = Path(a.out) / "synth.json"

    def checkpoint(r: dict) -> None:     # the runs so far, in case the run is stopped
        partial.write_text(json.dumps(record(r), indent=1) + "\n")

    r = S.synth_all(tops, seeds=seeds, jobs=jobs, out_dir=Path(a.out), device=a.device,
                  target_mhz=a.target_mhz, timeout_s=60 * a.timeout_min, router=a.router,
                  tmg_ripup=not a.no_tmg_ripup, progress=say, checkpoint=checkpoint)
    rec = record(r)
    text = json.dumps(rec, indent=1) + "\n"
    partial.write_text(text)
    if a.results:
        Path(a.results).mkdir(parents=True, exist_ok=True)
        dest = Path(a.results) / "synth.json"
        if a.tops is not None and dest.exists():
            rec = merge(json.loads(dest.read_text()), rec, all_tops(receivers))
            text = json.dumps(rec, indent=1) + "\n"
        dest.write_text(text)
    if a.json:
        print(json.dumps(rec))
    else:
        print(f"{'top':<26} {'LUT4':>6} {'FF':>6} {'MULT18':>6} {'DP16KD':>6}  "
              + " ".join(f"{'s' + str(s):>6}" for s in r["seeds"])
              + f" {'min':>6} {'median':>6}  critical path (worst seed)")
        for t in r["tops"]:
            print(f"{t['top']:<26} {t['lut4']:>6} {t['ff']:>6} {t['mult18']:>6} {t['bram']:>6}  "
                  + " ".join(f"{f:>6.1f}" if f is not None else f"{'-':>6}"
                             for f in t["fmax_mhz"] + [t["fmax_min"], t["fmax_median"]])
                  + "  "
                  f"{t['critical_from']} -> {t['critical_to']}")
        for what, why in r["failures"].items():
            print(f"FAILED {what}: {why.splitlines()[0]}")
        print(f"wall {r['wall_s']:.0f} s, tool CPU {r['tool_cpu_s']:.0f} s, {r['jobs']} jobs; "
              f"every top >= {a.target_mhz:g} MHz at every seed: "
              f"{'yes' if rec['all_met_all_seeds'] else 'NO'}")
    return 0 if rec["all_met_all_seeds"] and not r["failures"] else 1


def merge(old: dict, new: dict, order) -> dict:
    """``new`` (a ``synth --all --tops`` run) merged into ``old`` run by run, keyed by top
    and seed.

    A top ``new`` did not build keeps its rows. For a top it built, a run of ``new`` replaces
    ``old``'s run at the same seed, and ``old``'s runs at other seeds are kept only when
    they placed the same netlist (the same :func:`cosim.tools.synth.netlist_id`; runs
    without one are dropped), so the seeds of a top can be placed by several invocations
    but never mix two designs. ``seeds`` is the union; every row keeps its ``commit``;
    ``invocations`` lists the runs the file is made of (command, commit, date, tops, seeds,
    wall and CPU time; one none of whose rows is left is dropped) and ``wall_s`` /
    ``tool_cpu_s`` are their sums. Refused when the
    two differ in device, target, router or rip-up (their rows would not compare)."""
    keys = ("device", "target_mhz", "router", "tmg_ripup")
    if any(old.get(k) != new.get(k) for k in keys):
        raise ValueError(f"--tops: {', '.join(keys)} differ from the existing synth.json's "
                         f"({[old.get(k) for k in keys]} vs {[new.get(k) for k in keys]}): "
                         f"run every top, or write elsewhere (--results)")
    nets = {t["top"]: t.get("netlist") for t in new["tops"]}
    nets.update({n: h for n, h in new.get("netlists", {}).items() if h})
    built = set(nets) | {k.split(" seed ")[0] for k in new["failures"]}
    redone = {(r["top"], r["seed"]) for r in new["runs"]} | {
        (k.split(" seed ")[0], int(k.split(" seed ")[1])) for k in new["failures"]
        if " seed " in k}

    def same(top, seed, netlist):           # an old run (or failure) still stands
        if top not in built:
            return True
        return (top, seed) not in redone and netlist is not None and netlist == nets.get(top)

    runs = [r for r in old.get("runs", []) if same(r["top"], r["seed"], r.get("netlist"))]
    from_old = {r["top"] for r in runs}
    runs += new["runs"]
    old_nets = {t["top"]: t.get("netlist") for t in old.get("tops", [])}
    fails = {k: v for k, v in old.get("failures", {}).items()
             if " seed " in k and same(k.split(" seed ")[0], int(k.split(" seed ")[1]),
                                       old_nets.get(k.split(" seed ")[0]))
             or " seed " not in k and k not in built}
    seeds = sorted(set(old.get("seeds", [])) | set(new["seeds"]))
    rank = {n: i for i, n in enumerate(order)}
    runs.sort(key=lambda r: (rank.get(r["top"], len(rank)), r["seed"]))
    base = {t["top"]: t for t in old.get("tops", [])}
    base.update({t["top"]: t for t in new["tops"]})
    tops = []
    for name in sorted({r["top"] for r in runs}, key=lambda x: rank.get(x, len(rank))):
        mine = [r for r in runs if r["top"] == name]
        b = base[name]
        row = S.top_row(name, seeds, mine, new["target_mhz"],
                        {k: b.get(k) for k in ("netlist", "lut4", "ff", "mult18", "bram",
                                               "yosys_s")})
        row["commit"] = ", ".join(dict.fromkeys(r.get("commit") for r in mine
                                                if r.get("commit")))
        tops.append(row)
    inv = old.get("invocations") or [_invocation(old)]
    # an invocation is listed while a row of it is left: a run of a top it placed, at its
    # commit, or a failure of such a top
    inv = [i for i in inv + [_invocation(new)]
           if any(r["top"] in (i.get("tops") or []) and r.get("commit") == i.get("commit")
                  for r in runs)
           or any(k.split(" seed ")[0] in (i.get("tops") or [])
                  for k in {**fails, **new["failures"]})]
    n = len(order)
    done = {(r["top"], r["seed"]) for r in runs} | {
        (k.split(" seed ")[0], int(k.split(" seed ")[1])) for k in fails if " seed " in k}
    return dict(new, seeds=seeds, tops=tops, runs=runs, failures={**fails, **new["failures"]},
                invocations=inv, wall_s=round(sum(i["wall_s"] or 0 for i in inv), 1),
                tool_cpu_s=round(sum(i["tool_cpu_s"] or 0 for i in inv), 1),
                complete=all((t, s) in done for t in order for s in seeds)
                and not any(k in order for k in fails),
                all_met_at_median=len(tops) == n and all(t["met_at_median"] for t in tops),
                all_met_all_seeds=len(tops) == n and all(t["met_all_seeds"] for t in tops),
                merged=sorted(from_old, key=lambda x: rank.get(x, n)))


def _invocation(rec: dict) -> dict:
    m = rec.get("machine", {})
    return {"command": m.get("command"), "commit": m.get("commit"), "date": m.get("date"),
            "tops": [t["top"] for t in rec.get("tops", [])], "seeds": rec.get("seeds"),
            "jobs": rec.get("jobs"), "wall_s": rec.get("wall_s"),
            "tool_cpu_s": rec.get("tool_cpu_s"), "complete": rec.get("complete")}
