"""dsp.jit.njit_cached: the on-disk numba cache is keyed on the package sources, so a
kernel is recompiled when a callee it inlines from another module changes."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from dsp.jit import njit_cached, source_hash

ROOT = Path(__file__).resolve().parents[2]

CALLER = '''
from dsp.jit import njit_cached
from .callee import step


@njit_cached(nogil=True)
def kernel(x):
    return step(x)
'''

SCRIPT = '''
import json, sys
sys.path.insert(0, sys.argv[1])
from tpkg.caller import kernel
v = kernel(1)
print(json.dumps({"value": int(v), "hits": sum(kernel.stats.cache_hits.values()),
                  "path": kernel.stats.cache_path}))
'''


def _callee(delta: int) -> str:
    return textwrap.dedent(f'''
        import numba


        @numba.njit(inline="always")
        def step(x):
            return x + {delta}
    ''')


def _run(pkg_root: Path, cache: Path) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache),
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(pkg_root)], env=env, cwd=pkg_root,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_changed_callee_in_another_module_recompiles(tmp_path):
    """Fresh processes on one cache: first compile, then a cache hit, then -- after the
    inlined callee (another file) changes -- a recompile with the new arithmetic (numba's
    own ``cache=True`` would load the stale kernel: its stamp is the caller's file only)."""
    pkg = tmp_path / "src" / "tpkg"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "caller.py").write_text(CALLER)
    (pkg / "callee.py").write_text(_callee(1))
    cache = tmp_path / "cache"
    first = _run(tmp_path / "src", cache)
    assert (first["value"], first["hits"]) == (2, 0)
    again = _run(tmp_path / "src", cache)
    assert (again["value"], again["hits"]) == (2, 1) and again["path"] == first["path"]
    (pkg / "callee.py").write_text(_callee(2))
    changed = _run(tmp_path / "src", cache)
    assert (changed["value"], changed["hits"]) == (3, 0)
    assert changed["path"] != first["path"]
    # Under NUMBA_CACHE_DIR (the suite's bounds-checked kernels stay apart from the others).
    assert Path(changed["path"]).is_relative_to(cache)
    assert Path(changed["path"]).relative_to(cache).parts[0].startswith("kfnav-")


def test_source_hash_covers_contents_and_names(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n")
    h1 = source_hash((str(tmp_path),))
    source_hash.cache_clear()
    (tmp_path / "a.py").write_text("x = 2\n")
    h2 = source_hash((str(tmp_path),))
    source_hash.cache_clear()
    (tmp_path / "a.py").rename(tmp_path / "b.py")
    h3 = source_hash((str(tmp_path),))
    source_hash.cache_clear()
    assert len({h1, h2, h3}) == 3


def test_cache_option_refused():
    with pytest.raises(ValueError, match=r"njit_cached always caches \(keyed on the sources\): "
                                         r"drop cache=True"):
        njit_cached(cache=True)


def test_concurrent_first_compiles_share_one_cache(tmp_path):
    """Two processes compiling the same kernel into an empty cache at once (pytest-xdist
    workers after a source edit) both succeed, and a third loads the kernel from the cache
    (numba writes index and data files under temporary names and renames them)."""
    pkg = tmp_path / "src" / "tpkg"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "caller.py").write_text(CALLER)
    (pkg / "callee.py").write_text(_callee(5))
    cache = tmp_path / "cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache),
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    procs = [subprocess.Popen([sys.executable, "-c", SCRIPT, str(tmp_path / "src")], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    for p in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        assert json.loads(out.strip().splitlines()[-1])["value"] == 6
    third = _run(tmp_path / "src", cache)
    assert (third["value"], third["hits"]) == (6, 1)
