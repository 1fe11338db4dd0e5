"""Provenance of measured results: the machine/commit record every result carries
(:func:`machine_info`, :func:`source_commit`), the repository root (:data:`REPO_ROOT`),
the JSON + Markdown pair a benchmark writes (:func:`write_result`) and the process pool the
benchmarks share (:func:`map_jobs`). The benchmarks themselves are dispatched by
:mod:`cosim.tools.bench`.
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from tqdm import tqdm


def _command_line() -> str:
    if not sys.argv:
        return ""
    prog = Path(sys.argv[0])
    head = ["python -m cosim"] if prog.name == "__main__.py" and prog.parent.name == "cosim" else [prog.name]
    return " ".join(head + sys.argv[1:])


#: Root of the repository; generated files default to ``<repo>/build/...``, published results
#: go to ``<repo>/results``.
REPO_ROOT = Path(__file__).resolve().parents[2]
_COMMIT: str | None = None


def source_commit() -> str:
    """The commit of the code this process runs: read once, when first asked (the CLI asks
    at start-up), so a long run edited meanwhile in the working tree still names the code
    it started with; ``-dirty`` when tracked files differed from it."""
    global _COMMIT
    if _COMMIT is None:
        try:
            commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                    text=True, check=False, cwd=REPO_ROOT).stdout.strip()
            dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                                   capture_output=True, text=True, check=False,
                                   cwd=REPO_ROOT).stdout.strip()
            if commit and dirty:
                commit += "-dirty"      # the results come from uncommitted code
        except OSError:
            commit = ""
        _COMMIT = commit
    return _COMMIT


def machine_info() -> dict:
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    commit = source_commit()
    return {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "host": platform.node(), "cpu": cpu, "cores": os.cpu_count(),
            "python": platform.python_version(), "numpy": np.__version__,
            "command": _command_line(),
            "commit": commit}


def write_result(out: Path, stem: str, summary: dict, md: str) -> None:
    """Write a benchmark's ``summary`` to ``<out>/<stem>.json`` and its Markdown report
    ``md`` to ``<out>/<stem>.md`` (``out`` created if needed)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{stem}.json").write_text(json.dumps(summary, indent=1))
    (out / f"{stem}.md").write_text(md)


def map_jobs(jobs, fn, items, desc):
    """``[fn(i) for i in items]`` on ``jobs`` processes (default: one per core) with a
    progress bar."""
    jobs = jobs or os.cpu_count() or 1
    if jobs <= 1:
        return [fn(i) for i in tqdm(items, desc=desc, file=sys.stderr)]
    with ProcessPoolExecutor(max_workers=jobs) as ex:
        return list(tqdm(ex.map(fn, items, chunksize=1), total=len(items), desc=desc, file=sys.stderr))
