"""Benchmark ``suite-time``: ``make test`` wall time of a baseline commit and of HEAD, measured
one after the other on this machine, each in a fresh clone (so each pays its own ``make setup``:
``.venv``, pip packages, numba caches, Verilator builds), as CI does.

The baseline is :data:`BASELINE` (the commit before the closed-loop core, issue 12, whose
``make test`` the issue set the target against), or ``SUITE_BASELINE=<ref>`` in the
environment. Timings on a shared host are noisy: the figure to quote is the ratio measured in
one run. ``--quick`` times only ``make setup`` + one small test file in each clone (a smoke
test of the procedure, written to ``build/bench_quick``).
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import tempfile
import time
from pathlib import Path

from ..core.provenance import REPO_ROOT, machine_info

#: The reference commit (``a2c3ba2``: the last commit before the closed-loop core).
BASELINE = "a2c3ba2"
_QUICK_TARGET = "tests/dsp/test_fixed.py"


def _time_clone(ref: str, root: Path, quick: bool) -> dict:
    work = root / ref.replace("/", "_")
    subprocess.run(["git", "clone", "-q", str(REPO_ROOT), str(work)], check=True)
    subprocess.run(["git", "checkout", "-q", ref], cwd=work, check=True)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=work, check=True,
                            capture_output=True, text=True).stdout.strip()
    cmd = (["make", "setup"] if quick else ["make", "test"])
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=work, capture_output=True, text=True)
    if quick and p.returncode == 0:
        p = subprocess.run([str(work / ".venv/bin/python"), "-m", "pytest", "-q",
                            "-p", "no:cacheprovider", _QUICK_TARGET],
                           cwd=work, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    tail = (p.stdout + p.stderr).strip().splitlines()
    summary = next((ln for ln in reversed(tail) if re.search(r"\d+ (passed|failed)", ln)), "")
    m = re.search(r"in ([\d.]+)s", summary)
    shown = " ".join(cmd) + (f" + pytest {_QUICK_TARGET}" if quick else "")
    return {"ref": ref, "commit": commit, "command": shown, "returncode": p.returncode,
            "wall_s": round(wall, 1), "pytest_s": float(m.group(1)) if m else None,
            "summary": summary.strip("= ")}


def suite_time(out: Path, quick: bool = False) -> dict:
    baseline = os.environ.get("SUITE_BASELINE", BASELINE)
    with tempfile.TemporaryDirectory(prefix="suite_time_") as tmp:
        runs = [_time_clone(ref, Path(tmp), quick) for ref in (baseline, "HEAD")]
    failed = [r for r in runs if r["returncode"] != 0]
    s = {"benchmark": "suite-time", "machine": machine_info(), "quick": quick, "runs": runs,
         "ratio_head_over_baseline": round(runs[1]["wall_s"] / runs[0]["wall_s"], 3)}
    out.mkdir(parents=True, exist_ok=True)
    (out / "suite_time.json").write_text(json.dumps(s, indent=2) + "\n")
    (out / "suite_time.md").write_text(markdown(s))
    if failed:
        raise RuntimeError("suite-time: " + "; ".join(
            f"{r['ref']} exited {r['returncode']} ({r['summary'] or 'no pytest summary'})"
            for r in failed))
    return s


def markdown(s: dict) -> str:
    m = s["machine"]
    lines = ["# `make test` wall time, baseline vs HEAD (fresh clones, one after the other)", "",
             f"{m['date']} on {m['host']} ({m['cpu']}, {m['cores']} cores), "
             f"`{m['command']}` at {m['commit']}.", "",
             "| ref | commit | command | wall (s) | pytest (s) | result |", "|---|---|---|---|---|---|"]
    for r in s["runs"]:
        pt = "" if r["pytest_s"] is None else f"{r['pytest_s']:.0f}"
        lines.append(f"| {r['ref']} | {r['commit']} | `{r['command']}` | {r['wall_s']:.0f} | "
                     f"{pt} | {r['summary']} |")
    lines += ["", f"HEAD / baseline wall time: **{s['ratio_head_over_baseline']:.2f}**", ""]
    return "\n".join(lines)
