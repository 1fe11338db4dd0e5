"""The studies' task engine: independent tasks ``fn(task)`` run on the local process pool
or a Dask cluster, the one engine of the sweeps (:mod:`cosim.studies.sweep`) and of the
INS paper's Table 2 (:mod:`cosim.ins.table2_bench`).

``scheduler``: ``"local"`` (a process pool of ``jobs`` workers, default one per core;
``jobs`` 1: in this process), ``"dask"`` (a local Dask cluster of ``jobs`` single-threaded
worker processes) or a Dask scheduler's address (``"tcp://host:8786"``: the cluster's
workers, ``jobs`` unused). ``fn`` and the tasks must pickle (a module-level function,
plain data); each task is self-contained (its own seeds), so the results do not depend on
the scheduler, the number of workers or the order the tasks finish in.
"""
from __future__ import annotations

import os
import re

__all__ = ["run_tasks", "check_scheduler", "SCHEDULERS"]

#: The named schedulers (besides a Dask scheduler address).
SCHEDULERS = ("local", "dask")


def check_scheduler(scheduler: str) -> str:
    """``scheduler`` as given, or ``ValueError`` naming it (module doc)."""
    if not isinstance(scheduler, str) or (
            scheduler not in SCHEDULERS
            and not re.fullmatch(r"(tcp|tls|ucx|inproc)://[^\s]+", scheduler)):
        raise ValueError(f"scheduler must be local, dask or a Dask scheduler address "
                         f"(tcp://host:port), not {scheduler!r}")
    return scheduler


def run_tasks(fn, tasks, *, jobs: int | None = None, scheduler: str = "local",
              on_done=None) -> list:
    """``[fn(t) for t in tasks]`` on the ``scheduler`` (module doc), in the tasks' order;
    ``on_done()`` is called as each task finishes."""
    from cosim.core.validate import check_jobs
    check_scheduler(scheduler)
    tasks = list(tasks)
    jobs = check_jobs(jobs, "jobs")
    jobs = jobs or os.cpu_count() or 1
    out = [None] * len(tasks)
    if scheduler == "local":
        if jobs <= 1 or len(tasks) <= 1:
            for i, t in enumerate(tasks):
                out[i] = fn(t)
                if on_done is not None:
                    on_done()
            return out
        from concurrent.futures import ProcessPoolExecutor, as_completed
        with ProcessPoolExecutor(max_workers=min(jobs, len(tasks))) as ex:
            futs = {ex.submit(fn, t): i for i, t in enumerate(tasks)}
            for fu in as_completed(futs):
                out[futs[fu]] = fu.result()
                if on_done is not None:
                    on_done()
        return out
    from distributed import Client, LocalCluster, as_completed as dask_completed
    cluster = None
    if scheduler == "dask":
        cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        futs = client.map(fn, tasks, pure=False)
        index = {f.key: i for i, f in enumerate(futs)}
        for fu in dask_completed(futs):
            out[index[fu.key]] = fu.result()
            if on_done is not None:
                on_done()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return out
