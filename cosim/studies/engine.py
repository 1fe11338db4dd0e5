"""The studies' task engine: independent tasks ``fn(task)`` run on the local process pool
or a Dask cluster, the one engine of the sweeps (:mod:`cosim.studies.sweep`) and of the
INS paper's Table 2 (:mod:`cosim.ins.table2_bench`).

``scheduler``: ``"local"`` (a process pool of ``jobs`` workers, default one per core;
``jobs`` 1: in this process), ``"dask"`` (a local Dask cluster of ``jobs`` single-threaded
worker processes) or a Dask scheduler's address (``"tcp://host:8786"``: the cluster's
workers, ``jobs`` unused; :func:`check_scheduler` refuses one that does not answer). ``fn`` and the tasks must pickle (a module-level function,
plain data); each task is self-contained (its own seeds), so the results do not depend on
the scheduler, the number of workers or the order the tasks finish in.
"""
from __future__ import annotations

import os
import re

__all__ = ["run_tasks", "check_scheduler", "SCHEDULERS"]

#: The named schedulers (besides a Dask scheduler address).
SCHEDULERS = ("local", "dask")
_ADDRESS = re.compile(r"(tcp|tls|ucx|inproc)://[^\s]+|[^\s:/]+:\d+")


def check_scheduler(scheduler: str, jobs=None, *, flag: str = "scheduler",
                    reach: bool = False, timeout_s: float = 5.0) -> str:
    """``scheduler`` as given, or ``ValueError`` (one line, naming ``flag``) when it is
    neither a named scheduler nor a Dask scheduler address (``tcp://HOST:PORT`` or
    ``HOST:PORT``), when ``jobs`` is given with an address (the cluster has its own
    workers), or (``reach``) when no Dask scheduler answers at the address within
    ``timeout_s`` -- before any work."""
    if not isinstance(scheduler, str) or (
            scheduler not in SCHEDULERS and not _ADDRESS.fullmatch(scheduler)):
        raise ValueError(f"{flag} must be local, dask or a Dask scheduler address "
                         f"(tcp://HOST:PORT), not {scheduler!r}")
    if scheduler in SCHEDULERS:
        return scheduler
    if jobs is not None:
        raise ValueError(f"--jobs sizes the local pool or cluster; a remote Dask scheduler "
                         f"({flag} ADDRESS) has its own workers")
    if reach:
        _reach(scheduler, flag, timeout_s)
    return scheduler


def _reach(address: str, flag: str, timeout_s: float) -> None:
    """A TCP connection to a ``tcp://`` or bare address (refused at once when nothing
    listens), then a Dask client's handshake."""
    import socket
    m = re.fullmatch(r"(?:tcp://)?\[?([^\s/\]]+?)\]?:(\d+)", address)
    if m is not None:
        try:
            socket.create_connection((m.group(1), int(m.group(2))), timeout=timeout_s).close()
        except OSError as e:
            raise ValueError(f"{flag} {address}: cannot connect ({e.strerror or e}); is the "
                             f"Dask scheduler running?") from None
    try:
        from distributed import Client
    except ImportError:
        raise ValueError(f"{flag} {address}: a Dask scheduler needs the distributed "
                         f"package") from None
    try:
        Client(address, timeout=timeout_s).close()
    except Exception as e:          # noqa: BLE001 (any failure: the one-line refusal)
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ValueError(f"{flag} {address}: no Dask scheduler answers there ({msg})") from None


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
