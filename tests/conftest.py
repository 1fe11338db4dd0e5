"""Suite-wide settings, applied before any test module imports numba.

The numba kernels (front-end models, FIFO model, fixed-point DSP core) run in the suite with
bounds checking on, the way C code is tested under AddressSanitizer: an index out of range
raises ``IndexError`` at the faulty access instead of silently writing past an array. (A test
that handed an operator an event array without its range-log slots once corrupted the heap
and crashed the run minutes later, in unrelated code or at interpreter exit.) The checked
kernels compute the same bits; benchmarks and ``make run`` use the unchecked ones. Their
compile cache lives in its own directory so that checked and unchecked builds never mix.
Set ``NUMBA_BOUNDSCHECK=0`` to run the suite on the unchecked kernels. Every kernel is cached
with :func:`dsp.jit.njit_cached`, under ``NUMBA_CACHE_DIR/kfnav-<hash of the sources>/``.
"""
import os
from pathlib import Path

_ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("NUMBA_BOUNDSCHECK", "1")
if os.environ["NUMBA_BOUNDSCHECK"] == "1":
    os.environ.setdefault("NUMBA_CACHE_DIR", str(_ROOT / "build" / "numba-boundscheck"))


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """The simulators the suite ran on and their versions (Verilator, Icarus, cocotb), at the
    end of the output (shown under ``-q`` too, as ``make test`` runs it)."""
    from cosim.tools.toolversions import versions_line
    terminalreporter.write_line(f"simulators: {versions_line()}")
