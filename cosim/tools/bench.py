"""Benchmark dispatch: ``python -m cosim bench <name>`` -- measured figures written to
``results/`` with the machine, date, command and commit (:mod:`cosim.core.provenance`).

Each receiver registers its own benchmarks (``Receiver.benchmarks`` in the receiver registry,
:mod:`cosim.core.receivers`); the generic ones (:data:`GENERIC`: the estimation library's
speed, the test suite's wall time) live in this package. :func:`benchmarks` lists them all.
"""
from __future__ import annotations

from pathlib import Path

from ..core.receivers import Benchmark, receivers

__all__ = ["GENERIC", "benchmarks", "run"]


def _estimation(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_estimation import estimation_speed
    return estimation_speed(out, quick=quick)


def _suite_time(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_suite import suite_time
    return suite_time(out, quick=quick)


#: The benchmarks of no receiver: name -> :class:`~cosim.core.receivers.Benchmark`.
GENERIC = {"estimation": Benchmark(_estimation), "suite-time": Benchmark(_suite_time)}


def benchmarks() -> dict[str, Benchmark]:
    """Every benchmark by name: the registered receivers' (in registry order), then
    :data:`GENERIC`. A name given twice is an error."""
    out: dict[str, Benchmark] = {}
    for r in receivers():
        for name, b in r.benchmarks.items():
            if name in out:
                raise ValueError(f"benchmark {name!r} of receiver {r.name!r} is already "
                                 f"registered")
            out[name] = b
    for name, b in GENERIC.items():
        if name in out:
            raise ValueError(f"benchmark {name!r} is a generic benchmark: a receiver must not "
                             f"register it")
        out[name] = b
    return out


def run(name: str, out: str = "results", quick: bool = False, jobs: int | None = None,
        scheduler: str | None = None) -> dict:
    """Run benchmark ``name``, writing under ``out``; returns its summary. ``scheduler``
    (only for a benchmark with ``Benchmark.scheduler``): where its tasks run."""
    known = benchmarks()
    if name not in known:
        raise ValueError(f"benchmark must be one of {sorted(known)}, not {name!r}")
    if scheduler is None:
        return known[name].run(Path(out), quick=quick, jobs=jobs)
    if not known[name].scheduler:
        raise ValueError(f"benchmark {name} takes no scheduler")
    return known[name].run(Path(out), quick=quick, jobs=jobs, scheduler=scheduler)
