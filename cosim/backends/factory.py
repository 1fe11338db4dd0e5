"""Opening a session by backend name: the one place that knows every simulator backend.

:func:`open_frontend` opens a receiver's front end (looked up in the receiver registry by
its parameters' type) on ``"model"`` (the receiver's bit-exact model session), ``"pysim"``
(:class:`cosim.backends.pysim.PysimSession`), ``"verilator"``
(:class:`cosim.backends.verilator.VerilatorSession`) or ``"icarus"``
(:class:`cosim.backends.icarus.IcarusSession`, Icarus Verilog driven by cocotb);
:func:`open_stream_session` opens any stream component on one of the three HDL simulators.
The session interface is :class:`cosim.core.session.FrontendSession`.
"""
from __future__ import annotations

from pathlib import Path

from ..core.receivers import frontend_for
from ..core.session import FrontendSession
from .pysim import PysimSession

__all__ = ["BACKENDS", "FRONTEND_TYPES", "open_frontend", "open_stream_session"]

#: The backends a front end opens on.
BACKENDS = ("model", "pysim", "verilator", "icarus")

#: Front ends :func:`open_frontend` knows besides the registered receivers' (parameter
#: class -> :class:`cosim.core.receivers.Frontend`); a receiver declares its front end in its
#: registry entry (``Receiver.frontend``), which is looked up after this dict.
FRONTEND_TYPES: dict = {}


def _frontend_entry(params):
    for cls, entry in FRONTEND_TYPES.items():
        if isinstance(params, cls):
            return entry
    return frontend_for(params)


def open_stream_session(backend: str, dut, *, name: str = "dut", inputs: dict | None = None,
                        vcd: str | Path | None = None, **kw) -> FrontendSession:
    """A session of any stream component on ``"pysim"``, ``"verilator"`` or ``"icarus"``."""
    if backend == "pysim":
        return PysimSession(dut, inputs=inputs, vcd=vcd, **kw)
    if backend == "verilator":
        if vcd is not None:
            raise NotImplementedError("waveforms of a Verilator session: use "
                                      "VerilatorStreamSim.run(trace=...) for one run")
        from .verilator import VerilatorStreamSim
        return VerilatorStreamSim(dut, name=name, **kw).open(inputs=inputs)
    if backend == "icarus":
        if vcd is not None:
            raise NotImplementedError("waveforms of an Icarus session: not supported; use "
                                      "pysim or VerilatorStreamSim.run(trace=...)")
        from .icarus import IcarusStreamSim
        return IcarusStreamSim(dut, name=name, **kw).open(inputs=inputs)
    raise ValueError(f"backend must be pysim, verilator or icarus for a component, not "
                     f"{backend!r}")


def open_frontend(backend: str, params, *, log_ranges: bool = False,
                  vcd: str | Path | None = None) -> FrontendSession:
    """A front-end session for ``params`` (an instance of a registered front end's parameter
    class, :class:`cosim.core.receivers.Frontend`) on ``backend`` (``"model"``, ``"pysim"``,
    ``"verilator"`` or ``"icarus"``), reset, with its control ports at their reset values
    (``Frontend.inputs``)."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, not {backend!r}")
    entry = _frontend_entry(params)
    if backend == "model":
        if vcd is not None:
            raise ValueError("the bit-exact model has no waveform; use pysim or verilator")
        return entry.model(params, log_ranges=log_ranges)
    return open_stream_session(backend, entry.component(params), name=entry.verilog_name,
                               inputs=entry.reset_inputs(params), vcd=vcd)
