"""The architecture's import rules (docs/explanation/architecture.md), read from the source with ``ast``.

* ``dsp`` imports neither ``hdl`` nor ``cosim``; ``hdl`` does not import ``cosim``.
* Inside ``cosim`` the layers are ordered core < backends < tools < receivers < cli: a module
  imports only modules of its own layer or of a lower one.
* No import circle between the modules of ``dsp``, ``hdl`` and ``cosim``.
* No module imports a private name (``_name``) of another module of the three packages or
  reaches one through a module it imported under a name.

Every import counts, those inside functions included. The checker runs on the repository and,
to show that it reports what it must, on small synthetic packages with a wrong import. The
DSP's independence is also checked at run time (importing every ``dsp`` module loads no
``hdl`` or ``cosim`` module), and the TACAN signal generator takes the standard from
``dsp.tacan.standard``.
"""
from __future__ import annotations

import ast
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Packages that must not import the packages named.
FORBIDDEN = {"dsp": ("hdl", "cosim"), "hdl": ("cosim",)}

#: The layers of ``cosim``, lowest first: layer name -> the modules / packages in it. A
#: sub-package of ``cosim`` named in none of them is a receiver.
COSIM_LAYERS = (
    ("core", ("cosim.core",)),
    ("backends", ("cosim.backends",)),
    ("tools", ("cosim.tools", "cosim.studies", "cosim.testing")),
    ("receivers", ()),
    ("cli", ("cosim.cli", "cosim.__main__", "cosim")),
)


@dataclass(frozen=True)
class Import:
    """One imported module (``target``) and the names taken from it."""

    source: str
    target: str
    names: tuple
    line: int


def modules(root: Path, package: str) -> dict[str, Path]:
    """Every module of ``package`` under ``root``: dotted name -> file."""
    out = {}
    for p in sorted((root / package).rglob("*.py")):
        parts = list(p.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def imports(name: str, path: Path, known: set[str]) -> tuple[list[Import], list[tuple]]:
    """The imports of module ``name`` (any depth: function-level ones too), each resolved
    to an absolute module name (``from pkg import mod`` to ``pkg.mod`` when that is a module
    of ``known``), and the attribute uses ``alias._name`` of a module imported under a name
    (``(alias target, attribute, line)``)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_pkg = path.name == "__init__.py"
    out, aliases = [], {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                out.append(Import(name, a.name, (), node.lineno))
                if a.asname:
                    aliases[a.asname] = a.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_pkg else name.split(".")[:-1]
                base = base[:len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module
            names = []
            for a in node.names:
                sub = f"{mod}.{a.name}"
                if sub in known:
                    out.append(Import(name, sub, (), node.lineno))
                    aliases[a.asname or a.name] = sub
                else:
                    names.append(a.name)
            if names or not node.names:
                out.append(Import(name, mod, tuple(names), node.lineno))
    attrs = [(aliases[n.value.id], n.attr, n.lineno) for n in ast.walk(tree)
             if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name)
             and n.value.id in aliases and _private(n.attr)]
    return out, attrs


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _top(module: str) -> str:
    return module.split(".")[0]


def layer_of(module: str, subpackages=(), layers=COSIM_LAYERS) -> int:
    """Index of ``module``'s layer in ``layers``: that of the longest prefix naming it or its
    package (the package itself names only itself); a module of a sub-package (one of
    ``subpackages``) named nowhere is in the layer without prefixes (the receivers); -1 when
    it is in none."""
    root = module.split(".")[0]
    best, best_len = -1, -1
    for i, (_, prefixes) in enumerate(layers):
        for pre in prefixes:
            hit = module == pre if pre == root else \
                (module == pre or module.startswith(pre + "."))
            if hit and len(pre) > best_len:
                best, best_len = i, len(pre)
    if best >= 0:
        return best
    parts = module.split(".")
    if len(parts) >= 2 and parts[1] in subpackages:
        return next((i for i, (_, prefixes) in enumerate(layers) if not prefixes), -1)
    return -1


def subpackages(mods: dict[str, Path], package: str) -> set[str]:
    """The names of ``package``'s direct sub-packages among ``mods``."""
    return {m.split(".")[1] for m, p in mods.items()
            if p.name == "__init__.py" and m.count(".") == 1 and _top(m) == package}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles of ``graph`` (module -> modules it imports): its strongly
    connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def check(root: Path, packages=("dsp", "hdl", "cosim"), forbidden=FORBIDDEN,
          layered: str = "cosim", layers=COSIM_LAYERS) -> list[str]:
    """Every violation of the rules (module doc) in ``packages`` under ``root``, one line
    each (empty: the code keeps them). The layers are checked inside ``layered``; circles and
    private names in every package; ``forbidden`` between the packages."""
    mods = {}
    for pkg in packages:
        if (root / pkg).is_dir():
            mods.update(modules(root, pkg))
    known = set(mods)
    subs = subpackages(mods, layered)
    bad = []
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for name, path in mods.items():
        imps, attrs = imports(name, path, known)
        here = _top(name)
        for imp in imps:
            there = _top(imp.target)
            where = f"{path.relative_to(root)}:{imp.line}"
            if there in forbidden.get(here, ()):
                bad.append(f"{where}: {name} imports {imp.target} ({here} must not import "
                           f"{there})")
            if imp.target in known and imp.target != name:
                graph[name].add(imp.target)
                for n in imp.names:
                    if _private(n):
                        bad.append(f"{where}: {name} imports the private {n} of {imp.target}")
            if here != layered or there != layered:
                continue
            src, dst = layer_of(name, subs, layers), layer_of(imp.target, subs, layers)
            for m, li in ((name, src), (imp.target, dst)):
                if li < 0:
                    bad.append(f"{where}: {m} is in no layer of {layered}")
            if src >= 0 and dst > src:
                bad.append(f"{where}: {name} ({layers[src][0]}) imports {imp.target} "
                           f"({layers[dst][0]}), a higher layer")
        for target, attr, line in attrs:
            if target in known and target != name:
                bad.append(f"{path.relative_to(root)}:{line}: {name} reaches the private "
                           f"{attr} of {target}")
    for comp in cycles(graph):
        bad.append(f"import circle: {' <-> '.join(comp)}")
    return sorted(set(bad))


# -- the repository --------------------------------------------------------------------------
def test_the_repository_keeps_the_import_rules():
    bad = check(ROOT)
    assert not bad, "\n".join(bad)


def test_every_cosim_module_is_in_a_layer():
    mods = modules(ROOT, "cosim")
    subs = subpackages(mods, "cosim")
    assert [m for m in mods if layer_of(m, subs) < 0] == []
    names = {m: COSIM_LAYERS[layer_of(m, subs)][0] for m in
             ("cosim.tacan.run", "cosim.core.session", "cosim.testing", "cosim.studies.sweep",
              "cosim.backends.factory", "cosim.cli", "cosim")}
    assert names == {"cosim.tacan.run": "receivers", "cosim.core.session": "core",
                     "cosim.testing": "tools", "cosim.studies.sweep": "tools",
                     "cosim.backends.factory": "backends", "cosim.cli": "cli", "cosim": "cli"}


_DSP_IMPORTS = """
import importlib, pkgutil, sys
import dsp
for m in pkgutil.walk_packages(dsp.__path__, "dsp."):
    importlib.import_module(m.name)
bad = sorted(m for m in sys.modules if m.split(".")[0] in ("hdl", "cosim"))
print(" ".join(bad))
"""


def test_importing_dsp_loads_neither_hdl_nor_cosim():
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    env = dict(os.environ, PYTHONPATH=path)
    out = subprocess.run([sys.executable, "-c", _DSP_IMPORTS], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "", f"dsp imports {out.stdout.strip()}"


def test_generator_uses_the_dsp_standard():
    import cosim.tacan.signal as gen
    import dsp.tacan.standard as std
    for name in ("F15", "F135", "PULSE_WIDTH_S", "burst_offsets", "pair_spacing_s"):
        assert getattr(gen, name) is getattr(std, name), name


# -- the checker reports what it must ------------------------------------------------------
def _package(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        p = tmp_path / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return tmp_path


_CLEAN = {
    "dsp/__init__.py": "", "dsp/filt.py": "import numpy\nfrom .taps import W\n",
    "dsp/taps.py": "W = 1\n",
    "hdl/__init__.py": "", "hdl/block.py": "from dsp.filt import numpy\n",
    "cosim/__init__.py": "", "cosim/cli.py": "from .tacan import run\n",
    "cosim/core/__init__.py": "", "cosim/core/session.py": "X = 1\n",
    "cosim/core/pipeline.py": "from .session import X\n",
    "cosim/backends/__init__.py": "", "cosim/backends/pysim.py": "from ..core.session import X\n",
    "cosim/tools/__init__.py": "", "cosim/tools/bench.py": "from cosim.backends import pysim\n",
    "cosim/tacan/__init__.py": "",
    "cosim/tacan/run.py": "def f():\n    from ..tools.bench import pysim\n    return pysim\n",
}


def test_a_clean_synthetic_package_passes(tmp_path):
    assert check(_package(tmp_path, _CLEAN)) == []


@pytest.mark.parametrize("rel, text, want", [
    ("cosim/core/session.py", "def f():\n    from ..backends import pysim\n",
     "cosim.core.session (core) imports cosim.backends.pysim (backends), a higher layer"),
    ("cosim/backends/pysim.py", "from cosim.tacan.run import f\n",
     "cosim.backends.pysim (backends) imports cosim.tacan.run (receivers), a higher layer"),
    ("cosim/tools/bench.py", "import cosim.cli\n",
     "cosim.tools.bench (tools) imports cosim.cli (cli), a higher layer"),
    ("dsp/filt.py", "def f():\n    import hdl.block\n", "dsp must not import hdl"),
    ("dsp/filt.py", "from cosim.core import session\n", "dsp must not import cosim"),
    ("hdl/block.py", "from cosim.core.session import X\n", "hdl must not import cosim"),
    ("cosim/core/session.py", "from .pipeline import Y\nX = 1\n",
     "import circle: cosim.core.pipeline <-> cosim.core.session"),
    ("cosim/tacan/run.py", "from ..core.session import _hidden\n",
     "cosim.tacan.run imports the private _hidden of cosim.core.session"),
    ("cosim/tacan/run.py", "from ..core import session as s\ny = s._hidden\n",
     "cosim.tacan.run reaches the private _hidden of cosim.core.session"),
    ("cosim/stray.py", "from .core.session import X\n", "cosim.stray is in no layer of cosim"),
    ("dsp/filt.py", "from .taps import _window\n", "dsp.filt imports the private _window of dsp.taps"),
    ("dsp/taps.py", "from .filt import numpy\nW = 1\n", "import circle: dsp.filt <-> dsp.taps"),
])
def test_a_wrong_import_is_reported(tmp_path, rel, text, want):
    root = _package(tmp_path, {**_CLEAN, rel: text})
    bad = check(root)
    assert any(want in b for b in bad), bad
