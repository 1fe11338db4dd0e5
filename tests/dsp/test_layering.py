"""The DSP stands alone: no module of ``dsp`` imports the HDL (``hdl``) or the
co-simulation / signal generator (``cosim``); the generator takes the standard from
``dsp.tacan.standard``."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = """
import importlib, pkgutil, sys
import dsp
for m in pkgutil.walk_packages(dsp.__path__, "dsp."):
    importlib.import_module(m.name)
bad = sorted(m for m in sys.modules if m.split(".")[0] in ("hdl", "cosim"))
print(" ".join(bad))
"""


def test_dsp_imports_neither_hdl_nor_cosim():
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "", f"dsp imports {out.stdout.strip()}"


def test_generator_uses_the_dsp_standard():
    import cosim.tacan.signal as gen
    import dsp.tacan.standard as std
    for name in ("F15", "F135", "PULSE_WIDTH_S", "burst_offsets", "pair_spacing_s"):
        assert getattr(gen, name) is getattr(std, name), name
