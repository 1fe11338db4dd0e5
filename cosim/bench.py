"""Benchmarks: measured figures written to ``results/`` with the machine, date and command.

:data:`BENCHMARKS` names every benchmark (``python -m cosim bench <name>``); each lives with
its receiver or subsystem (the TACAN ones one per module, ``cosim.tacan.bench_accuracy``
and the other ``cosim.tacan.bench_*``; GNSS in :mod:`cosim.gnss.bench`, ...). Here: the
machine/commit record every result carries (:func:`machine_info`) and the process pool the
benchmarks share (:func:`map_jobs`).
"""
from __future__ import annotations

import datetime as _dt
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


_REPO = Path(__file__).resolve().parent.parent
_COMMIT: str | None = None


def source_commit() -> str:
    """The commit of the code this process runs: read once, when first asked (the CLI asks
    at start-up), so a long run edited meanwhile in the working tree still names the code
    it started with; ``-dirty`` when tracked files differed from it."""
    global _COMMIT
    if _COMMIT is None:
        try:
            commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                    text=True, check=False, cwd=_REPO).stdout.strip()
            dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                                   capture_output=True, text=True, check=False,
                                   cwd=_REPO).stdout.strip()
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


def map_jobs(jobs, fn, items, desc):
    """``[fn(i) for i in items]`` on ``jobs`` processes (default: one per core) with a
    progress bar."""
    jobs = jobs or os.cpu_count() or 1
    if jobs <= 1:
        return [fn(i) for i in tqdm(items, desc=desc, file=sys.stderr)]
    with ProcessPoolExecutor(max_workers=jobs) as ex:
        return list(tqdm(ex.map(fn, items, chunksize=1), total=len(items), desc=desc, file=sys.stderr))


def _dsp_speed(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_dsp import dsp_speed
    return dsp_speed(out, quick=quick)


def _dsp_hour(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_dsp import dsp_hour
    return dsp_hour(out, quick=quick)


def _sim_speed(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_sim import sim_speed
    return sim_speed(out, quick=quick)


def _estimation(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_estimation import estimation_speed
    return estimation_speed(out, quick=quick)


def _suite_time(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_suite import suite_time
    return suite_time(out, quick=quick)


def _gnss_speed(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .gnss.bench import gnss_speed
    return gnss_speed(out, quick=quick)


def _gnss_tracking(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .gnss.bench import gnss_tracking
    return gnss_tracking(out, quick=quick)


def _monopulse(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .monopulse.bench import bench as monopulse_bench
    return monopulse_bench(out, quick=quick)


def _ins(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .ins.bench import ins_bench
    return ins_bench(out, quick=quick, jobs=jobs)


def _aukf(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .gnss.study_aukf import bench as aukf_bench
    return aukf_bench(out, quick=quick)


def _aukf_convergence(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .gnss.study_aukf import bench_convergence
    return bench_convergence(out, quick=quick)


def _tacan(module: str, name: str):
    def bench(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
        from importlib import import_module
        return getattr(import_module(f".tacan.{module}", __package__), name)(
            out, quick=quick, jobs=jobs)
    bench.__name__ = name
    return bench


BENCHMARKS = {"tacan-accuracy": _tacan("bench_accuracy", "tacan_accuracy"),
              "tacan-robustness": _tacan("bench_robustness", "tacan_robustness"),
              "tacan-detector": _tacan("bench_detector", "tacan_detector"),
              "tacan-sensitivity": _tacan("bench_sensitivity", "tacan_sensitivity"),
              "tacan-confidence": _tacan("bench_confidence", "tacan_confidence"),
              "dsp-speed": _dsp_speed, "dsp-hour": _dsp_hour,
              "sim-speed": _sim_speed, "estimation": _estimation, "suite-time": _suite_time,
              "gnss-speed": _gnss_speed, "gnss-tracking": _gnss_tracking,
              "monopulse": _monopulse, "ins": _ins, "aukf": _aukf,
              "aukf-convergence": _aukf_convergence}


def run(name: str, out: str = "results", quick: bool = False, jobs: int | None = None) -> dict:
    if name not in BENCHMARKS:
        raise ValueError(f"benchmark must be one of {sorted(BENCHMARKS)}, not {name!r}")
    return BENCHMARKS[name](Path(out), quick=quick, jobs=jobs)
