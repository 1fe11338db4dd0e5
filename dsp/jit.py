"""One decorator for every cached numba kernel of the project: :func:`njit_cached`.

``numba.njit(cache=True)`` keys a cached kernel on the source of the file that defines it
only. A kernel that inlines a function from another module (``inline="always"``, or any
jitted callee: numba compiles callees into the caller) keeps running the *old* callee
after that module changes, until its own file changes -- a stale kernel that loses bits
silently. :func:`njit_cached` keys the cache on a hash of every ``.py`` file of the project
packages (``hdl``, ``dsp``, ``cosim``) and of the package that defines the kernel: the
cache lives in a directory named after that hash, and the same hash is the index's source
stamp. Any source edit therefore recompiles every kernel once (a few tens of seconds),
never runs a stale one.

Where: ``$NUMBA_CACHE_DIR/kfnav-<hash>/...`` when ``NUMBA_CACHE_DIR`` is set (the test suite
sets it to keep its bounds-checked kernels apart: ``tests/conftest.py``), else
``<package>/__pycache__/kfnav-<hash>/`` next to the source, else the user-wide numba cache
directory. Old hash directories are not pruned (``make clean`` removes ``build/``).

Concurrent processes (pytest-xdist workers, parallel sweeps) are safe: numba writes each
index and data file to a temporary name and renames it into place.
"""
from __future__ import annotations

import functools
import hashlib
import inspect
import os
import sys
from pathlib import Path

import numba
from numba.core import config
from numba.core.caching import (CompileResultCacheImpl, FunctionCache, _CacheLocator,
                                _SourceFileBackedLocatorMixin)

__all__ = ["njit_cached", "source_hash"]

#: Top-level packages whose sources key every kernel (this file is in one of them).
PROJECT_ROOT = Path(__file__).resolve().parents[1]
PROJECT_PACKAGES = ("hdl", "dsp", "cosim")


@functools.lru_cache(maxsize=None)
def source_hash(package_dirs: tuple[str, ...]) -> str:
    """SHA-256 (hex) of the relative paths and contents of every ``.py`` file under the
    given package directories, in sorted order."""
    h = hashlib.sha256()
    for d in sorted(set(package_dirs)):
        base = Path(d)
        for f in sorted(base.rglob("*.py")):
            if "__pycache__" in f.parts:
                continue
            h.update(f"{base.name}/{f.relative_to(base).as_posix()}".encode())
            h.update(b"\0")
            h.update(f.read_bytes())
            h.update(b"\0")
    return h.hexdigest()


def _package_dir(py_file: str) -> str:
    """The top-level package directory containing ``py_file`` (its own directory if it is
    not in a package)."""
    d = Path(py_file).resolve().parent
    while (d.parent / "__init__.py").exists():
        d = d.parent
    return str(d)


def _key_dirs(py_file: str) -> tuple[str, ...]:
    own = [str(PROJECT_ROOT / p) for p in PROJECT_PACKAGES if (PROJECT_ROOT / p).is_dir()]
    return tuple(sorted({*own, _package_dir(py_file)}))


class _SourceHashLocator(_SourceFileBackedLocatorMixin, _CacheLocator):
    """Cache directory ``<base>/kfnav-<hash16>/<file subpath>``, source stamp = the hash."""

    def __init__(self, py_func, py_file):
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        self._hash = source_hash(_key_dirs(py_file))
        self._cache_path = os.path.join(self._base(py_file), f"kfnav-{self._hash[:16]}",
                                        self.get_suitable_cache_subpath(py_file))

    @staticmethod
    def _base(py_file: str) -> str:
        if config.CACHE_DIR:
            return config.CACHE_DIR
        return os.path.join(os.path.dirname(py_file), "__pycache__")

    def get_cache_path(self):
        return self._cache_path

    def get_source_stamp(self):
        return self._hash


class _UserWideSourceHashLocator(_SourceHashLocator):
    """Fallback when the source tree is not writable (an installed package)."""

    @staticmethod
    def _base(py_file: str) -> str:
        from numba.misc.appdirs import AppDirs
        return AppDirs(appname="numba", appauthor=False).user_cache_dir


class _SourceHashCacheImpl(CompileResultCacheImpl):
    _locator_classes = [_SourceHashLocator, _UserWideSourceHashLocator]


class _SourceHashFunctionCache(FunctionCache):
    _impl_class = _SourceHashCacheImpl


def njit_cached(func=None, **options):
    """``numba.njit(**options)`` with the on-disk cache keyed on the project's sources.

    Use as ``@njit_cached`` or ``@njit_cached(nogil=True, parallel=True)``; ``cache`` is
    implied (passing it is an error, so that no kernel falls back to numba's own cache).
    """
    if "cache" in options:
        raise ValueError(f"njit_cached always caches (keyed on the sources): drop cache="
                         f"{options['cache']!r}")

    def wrap(f):
        disp = numba.njit(**options)(f)
        # What numba.njit(cache=True) does (Dispatcher.enable_caching), with our cache class.
        disp._cache = _SourceHashFunctionCache(disp.py_func)
        return disp

    return wrap if func is None else wrap(func)
