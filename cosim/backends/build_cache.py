"""A build cache shared by the compiled simulators (:mod:`cosim.backends.verilator`,
:mod:`cosim.backends.icarus`): one directory per key, built once.

:func:`cached_build` returns ``<root>/<key>`` when it holds the build's ``marker`` file;
otherwise it takes a lock on ``<root>/<key>.lock`` (one build per key at a time: parallel
pytest-xdist workers or sweeps wait and then reuse the finished build), builds into a fresh
temporary directory beside it and renames that into place (:func:`publish`), so a build cut
short never leaves a directory that looks finished.
"""
from __future__ import annotations

import fcntl
import shutil
import tempfile
from pathlib import Path
from typing import Callable

__all__ = ["cached_build", "publish", "temp_dir_beside"]


def temp_dir_beside(out: Path, prefix: str | None = None) -> Path:
    """A new empty directory in ``out``'s parent (created if needed), for a build that
    :func:`publish` then moves to ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=prefix or out.name[:16] + ".tmp-", dir=out.parent))


def publish(tmp: Path, out: Path, marker: str | None = None) -> None:
    """Rename the finished build ``tmp`` to ``out``. If ``out`` exists already (a concurrent
    build of the same key got there first: its ``marker`` file is there, or with
    ``marker=None`` the directory itself), ``tmp`` is removed instead; any other failure to
    rename is raised."""
    try:
        tmp.rename(out)
    except OSError:
        done = (out / marker).exists() if marker is not None else out.is_dir()
        shutil.rmtree(tmp, ignore_errors=True)
        if not done:
            raise


def cached_build(root: Path, key: str, marker: str,
                 build: Callable[[Path], None]) -> tuple[Path, bool]:
    """``<root>/<key>``, built by ``build(tmp)`` unless it holds ``marker`` already.

    ``build`` writes the build's files into the empty directory ``tmp`` (``marker`` among
    them) or raises; on success ``tmp`` becomes ``<root>/<key>``, on failure it is removed.
    Returns the directory and whether this call built it.
    """
    out = Path(root) / key
    if (out / marker).exists():
        return out, False
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out.parent / f"{out.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if (out / marker).exists():
            return out, False
        tmp = temp_dir_beside(out)
        try:
            build(tmp)
            if not (tmp / marker).exists():
                raise RuntimeError(f"the build of {out.name} did not write {marker}")
            publish(tmp, out, marker)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
    return out, True
